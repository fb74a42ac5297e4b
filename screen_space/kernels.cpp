// SPDX-License-Identifier: Apache-2.0
// The vectorized kernels of the screen-space stage (see planes.h for the layout).
//
// Design note. At 1920x1080 a pass over one float plane is 8 MB, so the filters are bound by
// memory traffic as much as by arithmetic; both are kept down the same way:
//   * The a-trous level is one 2D 3x3 pass for all components together (SVGF uses 5x5; 3x3 with
//     steps 1, 2, 4, 8 reaches +-15 pixels at 8 instead of 24 taps per level). Per chunk of a row,
//     the depth + normal weight of each tap is computed once into a small array (phase 1), then
//     each component sweeps the chunk with its 9 taps unrolled and its accumulators in registers
//     (phase 2). Validity travels in the variance (< 0: unusable), not in a plane of its own.
//   * Weights use max(0, 1 - x/n)^n instead of exp(-x): a multiply-add and log2(n) squarings.
//   * The separable passes (Zeng's shadow filter and clean-up: joint bilateral Gaussians of
//     per-pixel std) run tap-outer over a chunk with accumulators in L1, and skip chunks whose
//     pixels all have std 0 (most of them).
// Every innermost loop is branch-free over contiguous floats; the functions are compiled for
// x86-64-v4 (AVX-512), v3 (AVX2+FMA) and the baseline, and the loader picks one (ifunc), like
// Embree's per-ISA kernels.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "screen_space/internal.h"
#include "screen_space/planes.h"

namespace texcache::screen::internal {

void Guides::Resize(int w, int h) {
    for (Plane* p : {&px, &py, &pz, &nx, &ny, &nz, &depth, &invDz}) p->Resize(w, h);
    objectId.Resize(w, h, -2);
    valid.Resize(w, h, 0);
}

namespace {

constexpr int kChunk = 256;

// ---- Separable passes ------------------------------------------------------------------------

template <int NC>
inline __attribute__((always_inline)) void SeparableRow(const PassArgs& a, int y) {
    const Guides& g = *a.g;
    const int w = g.depth.Width(), h = g.depth.Height();
    alignas(64) float zc[kChunk], nxc[kChunk], nyc[kChunk], nzc[kChunk], idz[kChunk], sc[kChunk];
    alignas(64) float acc[NC][kChunk], wsum[kChunk];
    float cz[33];
    for (int t = 0; t < a.taps; ++t)
        cz[t] = a.offset[t] == 0 ? 0.0f : 1.0f / (a.depthSigma * float(std::abs(a.offset[t])));
    const float kn = a.normalPower;

    for (int x0 = 0; x0 < w; x0 += kChunk) {
        const int n = std::min(kChunk, w - x0);
        {
            const float* s = a.sigma->Row(y) + x0;
            float smax = 0.0f;
            for (int i = 0; i < n; ++i) smax = std::max(smax, s[i]);
            if (smax <= 0.05f) {  // nothing to clean up here: copy
                for (int c = 0; c < NC; ++c)
                    std::copy_n(a.in[c]->Row(y) + x0, n, a.out[c]->Row(y) + x0);
                if (a.outValid) std::copy_n(a.valid->Row(y) + x0, n, a.outValid->Row(y) + x0);
                continue;
            }
            for (int i = 0; i < n; ++i)  // 1 / (2 sigma^2); huge below 0.05 px: centre only
                sc[i] = s[i] > 0.05f ? 1.0f / (2.0f * s[i] * s[i]) : 1e30f;
        }
        {
            const float* z = g.depth.Row(y) + x0;
            const float* nx = g.nx.Row(y) + x0;
            const float* ny = g.ny.Row(y) + x0;
            const float* nz = g.nz.Row(y) + x0;
            const float* iz = g.invDz.Row(y) + x0;
            for (int i = 0; i < n; ++i) {
                zc[i] = z[i], nxc[i] = nx[i], nyc[i] = ny[i], nzc[i] = nz[i], idz[i] = iz[i];
                wsum[i] = 0.0f;
            }
            for (int c = 0; c < NC; ++c)
                for (int i = 0; i < n; ++i) acc[c][i] = 0.0f;
        }
        for (int t = 0; t < a.taps; ++t) {
            const int off = a.offset[t];
            int yq = y, xs = x0;
            if (a.vertical) {
                yq = y + off;
                if (yq < 0 || yq >= h) continue;
            } else {
                xs = x0 + off;
            }
            const float czt = cz[t];
            const float off2 = float(off) * float(off);
            const float* zq = g.depth.Row(yq) + xs;
            const float* nxq = g.nx.Row(yq) + xs;
            const float* nyq = g.ny.Row(yq) + xs;
            const float* nzq = g.nz.Row(yq) + xs;
            const float* vq = a.valid->Row(yq) + xs;
            const float* in0 = a.in[0]->Row(yq) + xs;
            const float* in1 = NC == 3 ? a.in[1]->Row(yq) + xs : in0;
            const float* in2 = NC == 3 ? a.in[2]->Row(yq) + xs : in0;
            for (int i = 0; i < n; ++i) {
                const float dot = nxc[i] * nxq[i] + nyc[i] * nyq[i] + nzc[i] * nzq[i];
                float e = std::fabs(zq[i] - zc[i]) * idz[i] * czt + kn * (1.0f - dot);
                e += off2 * sc[i];
                const float wt = vq[i] * ExpNeg16(e);
                wsum[i] += wt;
                acc[0][i] += wt * in0[i];
                if constexpr (NC == 3) {
                    acc[1][i] += wt * in1[i];
                    acc[2][i] += wt * in2[i];
                }
            }
        }
        for (int c = 0; c < NC; ++c) {
            float* o = a.out[c]->Row(y) + x0;
            for (int i = 0; i < n; ++i) o[i] = wsum[i] > 0.0f ? acc[c][i] / wsum[i] : 0.0f;
        }
        if (a.outValid) {
            float* ov = a.outValid->Row(y) + x0;
            for (int i = 0; i < n; ++i) ov[i] = wsum[i] > 0.0f ? 1.0f : 0.0f;
        }
    }
}

TEXCACHE_SCREEN_CLONES void Gaussian1(const PassArgs& a, int y0, int y1) {
    for (int y = y0; y < y1; ++y) SeparableRow<1>(a, y);
}
TEXCACHE_SCREEN_CLONES void Gaussian3(const PassArgs& a, int y0, int y1) {
    for (int y = y0; y < y1; ++y) SeparableRow<3>(a, y);
}

// ---- The fused a-trous level -----------------------------------------------------------------

// 3x3 B-spline (1 2 1)^T (1 2 1) / 16; tap t = 3 (dy + 1) + (dx + 1).
constexpr float kH[9] = {1.0f / 16, 2.0f / 16, 1.0f / 16, 2.0f / 16, 4.0f / 16,
                         2.0f / 16, 1.0f / 16, 2.0f / 16, 1.0f / 16};

template <int NC, bool Lum, bool Var>
inline __attribute__((always_inline)) void AtrousComponentChunk(const AtrousArgs& a,
                                                                const AtrousComponent& c,
                                                                const int* rows, int x0, int n,
                                                                const float (*wg)[kChunk], int y,
                                                                bool stream) {
    const int s = a.step;
    // Tap pointers (row, column offset); rows outside the image point at the centre row with a
    // zero geometric weight.
    const float* in0[9];
    const float* in1[9];
    const float* in2[9];
    const float* var[9];
    for (int t = 0; t < 9; ++t) {
        const int r = rows[t / 3], dx = (t % 3 - 1) * s;
        in0[t] = c.in[0]->Row(r) + x0 + dx;
        in1[t] = NC == 3 ? c.in[1]->Row(r) + x0 + dx : in0[t];
        in2[t] = NC == 3 ? c.in[2]->Row(r) + x0 + dx : in0[t];
        var[t] = c.var->Row(r) + x0 + dx;
    }
    // Results go to local arrays first: they cannot alias the 36 input pointers, so the loop
    // needs no run-time alias checks (which GCC gives up on beyond 10) to vectorize.
    alignas(64) float o0[kChunk], o1[kChunk], o2[kChunk], ov[kChunk];
    const float sl = a.luminanceSigma;
    for (int i = 0; i < n; ++i) {
        float lc = 0.0f, il = 0.0f;
        if constexpr (Lum) {
            lc = NC == 3 ? Luma(in0[4][i], in1[4][i], in2[4][i]) : in0[4][i];
            const float vc = var[4][i];
            // SVGF: exp(-|l - l_c| / (sigma_l sqrt(var) + eps)); no luminance stopping for an
            // unusable centre (its value is 0, not a luminance).
            il = vc >= 0.0f ? 1.0f / (sl * std::sqrt(vc) + 1e-6f) : 0.0f;
        }
        float wsum = 0.0f, a0 = 0.0f, a1 = 0.0f, a2 = 0.0f, av = 0.0f;
#pragma GCC unroll 9
        for (int t = 0; t < 9; ++t) {
            const float vq = var[t][i];
            float w = vq >= 0.0f ? wg[t][i] : 0.0f;
            const float v0 = in0[t][i];
            const float v1 = NC == 3 ? in1[t][i] : 0.0f;
            const float v2 = NC == 3 ? in2[t][i] : 0.0f;
            // The centre's own luminance weight is exp(0) = 1.
            if constexpr (Lum) {
                if (t != 4) {
                    const float lq = NC == 3 ? Luma(v0, v1, v2) : v0;
                    w *= ExpNeg8(std::fabs(lq - lc) * il);
                }
            }
            wsum += w;
            a0 += w * v0;
            if constexpr (NC == 3) a1 += w * v1, a2 += w * v2;
            // An unusable tap (vq < 0) has w = 0 and adds -0.
            if constexpr (Var) av += w * w * vq;
        }
        const float inv = wsum > 0.0f ? 1.0f / wsum : 0.0f;
        o0[i] = a0 * inv;
        if constexpr (NC == 3) o1[i] = a1 * inv, o2[i] = a2 * inv;
        if constexpr (Var) ov[i] = wsum > 0.0f ? av * inv * inv : -1.0f;
    }
    StoreRow(o0, n, c.out[0]->Row(y) + x0, stream);
    if constexpr (NC == 3) {
        StoreRow(o1, n, c.out[1]->Row(y) + x0, stream);
        StoreRow(o2, n, c.out[2]->Row(y) + x0, stream);
    }
    if constexpr (Var) StoreRow(ov, n, c.outVar->Row(y) + x0, stream);
}

// Whether any tap of the chunk's pixels has a usable sample (variance >= 0) in rows `rows`,
// columns x0 - step .. x0 + n - 1 + step. Where none has, every weight is 0 and the level's
// output is known (AtrousEmptyChunk).
inline __attribute__((always_inline)) bool AnyUsableTap(const AtrousComponent& c, const int* rows,
                                                        int x0, int n, int step) {
    int any = 0;
    for (int r = 0; r < 3; ++r) {
        if (r > 0 && rows[r] == rows[r - 1]) continue;
        const float* v = c.var->Row(rows[r]) + x0 - step;
        for (int i = 0; i < n + 2 * step; ++i) any |= v[i] >= 0.0f;
    }
    return any != 0;
}

// The output of a chunk without usable taps: 0, variance -1 (unusable).
inline void AtrousEmptyChunk(const AtrousComponent& c, int x0, int n, int y) {
    for (int k = 0; k < c.nc; ++k) std::fill_n(c.out[k]->Row(y) + x0, n, 0.0f);
    if (c.outVar) std::fill_n(c.outVar->Row(y) + x0, n, -1.0f);
}

template <int NC, bool Lum>
inline __attribute__((always_inline)) void AtrousComponentChunkVar(const AtrousArgs& a,
                                                                   const AtrousComponent& c,
                                                                   const int* rows, int x0, int n,
                                                                   const float (*wg)[kChunk], int y,
                                                                   bool stream) {
    if (c.outVar)
        AtrousComponentChunk<NC, Lum, true>(a, c, rows, x0, n, wg, y, stream);
    else
        AtrousComponentChunk<NC, Lum, false>(a, c, rows, x0, n, wg, y, stream);
}

inline __attribute__((always_inline)) void AtrousRowImpl(const AtrousArgs& a, int y) {
    const Guides& g = *a.g;
    const int w = g.depth.Width(), h = g.depth.Height();
    // Planes the level reads (the five guides, each component's values and variance) and
    // writes: the level's own reads evict what it writes long before the next level reads it
    // when they do not fit in L3 together, so the written planes' size alone is not the test.
    int planes = 5;
    for (const AtrousComponent& c : a.comp)
        if (c.nc) planes += 2 * c.nc + 1 + (c.outVar ? 1 : 0);
    const bool stream = StreamPlanes(w, h, planes);
    const int s = a.step;
    const int rows[3] = {y - s >= 0 ? y - s : y, y, y + s < h ? y + s : y};
    const bool rowOk[3] = {y - s >= 0, true, y + s < h};
    alignas(64) float wg[9][kChunk];
    const float kn = a.normalPower;
    for (int x0 = 0; x0 < w; x0 += kChunk) {
        const int n = std::min(kChunk, w - x0);
        // Components whose taps are all unusable here (background, pixels without a glossy
        // lobe) get their known output without the arithmetic.
        bool active[3] = {false, false, false};
        bool anyActive = false;
        for (int k = 0; k < 3; ++k) {
            const AtrousComponent& c = a.comp[k];
            if (!c.nc) continue;
            active[k] = AnyUsableTap(c, rows, x0, n, s);
            if (!active[k]) AtrousEmptyChunk(c, x0, n, y);
            anyActive = anyActive || active[k];
        }
        if (!anyActive) continue;
        // Phase 1: depth + normal weight of each tap (SVGF: exp(-|dz| / (sigma_z |grad z . o|))
        // * max(0, n.n')^sigma_n), times the B-spline weight. All taps of a pixel in one
        // iteration, so the centre's guides are loaded once, not once per tap.
        {
            const float* zq[9];
            const float* nxq[9];
            const float* nyq[9];
            const float* nzq[9];
            float ht[9], dist[9];
            for (int t = 0; t < 9; ++t) {
                const int r = rows[t / 3], dx = (t % 3 - 1) * s;
                zq[t] = g.depth.Row(r) + x0 + dx;
                nxq[t] = g.nx.Row(r) + x0 + dx;
                nyq[t] = g.ny.Row(r) + x0 + dx;
                nzq[t] = g.nz.Row(r) + x0 + dx;
                ht[t] = rowOk[t / 3] ? kH[t] : 0.0f;
                dist[t] = (t == 0 || t == 2 || t == 6 || t == 8) ? 0.70710678f : 1.0f;
            }
            const float* z = g.depth.Row(y) + x0;
            const float* nx = g.nx.Row(y) + x0;
            const float* ny = g.ny.Row(y) + x0;
            const float* nz = g.nz.Row(y) + x0;
            const float* iz = g.invDz.Row(y) + x0;
            const float k = 1.0f / (a.depthSigma * float(s));
            for (int i = 0; i < n; ++i) {
                const float zc = z[i], nxc = nx[i], nyc = ny[i], nzc = nz[i];
                const float tol = iz[i] * k;
#pragma GCC unroll 9
                for (int t = 0; t < 9; ++t) {
                    const float dot = nxc * nxq[t][i] + nyc * nyq[t][i] + nzc * nzq[t][i];
                    const float e = std::fabs(zq[t][i] - zc) * tol * dist[t] + kn * (1.0f - dot);
                    wg[t][i] = ht[t] * ExpNeg16(e);
                }
            }
        }
        // Phase 2: each component.
        for (int k = 0; k < 3; ++k) {
            const AtrousComponent& c = a.comp[k];
            if (!active[k]) continue;
            if (c.nc == 3) {
                if (c.luminance)
                    AtrousComponentChunkVar<3, true>(a, c, rows, x0, n, wg, y, stream);
                else
                    AtrousComponentChunkVar<3, false>(a, c, rows, x0, n, wg, y, stream);
            } else {
                if (c.luminance)
                    AtrousComponentChunkVar<1, true>(a, c, rows, x0, n, wg, y, stream);
                else
                    AtrousComponentChunkVar<1, false>(a, c, rows, x0, n, wg, y, stream);
            }
        }
    }
}

TEXCACHE_SCREEN_CLONES void AtrousRows(const AtrousArgs& a, int y0, int y1) {
    for (int y = y0; y < y1; ++y) AtrousRowImpl(a, y);
}

}  // namespace

void FilterPlanes(const PassArgs& a) {
    ForRowBlocks(a.g->depth.Height(),
                 [&](int y0, int y1) { a.nc == 3 ? Gaussian3(a, y0, y1) : Gaussian1(a, y0, y1); });
}

void AtrousLevel(const AtrousArgs& a) {
    ForRowBlocks(a.g->depth.Height(), [&](int y0, int y1) { AtrousRows(a, y0, y1); });
}

namespace {

// Horizontal box sum of one row by doubling: A_1 is the row from x - r on (the zero padding
// covers the border for r <= kPad), A_2k[i] = A_k[i] + A_k[i + k], and the window's L = 2r + 1
// taps are the A_k of L's set bits laid end to end. That is log2(L) + popcount(L) vectorized
// passes instead of the direct sum's 2r (r = 8, the shadow splat: 5 instead of 16). `a`, `b`:
// scratch of w + 2r floats each.
TEXCACHE_SCREEN_CLONES void BoxRowH(const float* s, float* __restrict d, int w, int r,
                                    float* __restrict a, float* __restrict b) {
    const int taps = 2 * r + 1;
    const float* cur = s - r;
    int len = w + 2 * r;  // entries of the current level that hold a full sum
    int offset = 0;
    float* next = a;
    for (int k = 1;; k *= 2) {
        if (taps & k) {
            const float* src = cur + offset;
            if (offset == 0)  // k = 1: the lowest bit of an odd count
                for (int x = 0; x < w; ++x) d[x] = src[x];
            else
                for (int x = 0; x < w; ++x) d[x] += src[x];
            offset += k;
        }
        if (2 * k > taps) break;
        len -= k;
        for (int i = 0; i < len; ++i) next[i] = cur[i] + cur[i + k];
        cur = next;
        next = next == a ? b : a;
    }
}
// True when a row holds only zeros (+0 or -0): such rows (most of a sparse mask's) add nothing.
TEXCACHE_SCREEN_CLONES bool ZeroRow(const float* s, int w) {
    constexpr int kC = 64;
    for (int x0 = 0; x0 < w; x0 += kC) {
        const int n = std::min(kC, w - x0);
        int nonzero = 0;
        for (int i = 0; i < n; ++i) nonzero |= s[x0 + i] != 0.0f;
        if (nonzero) return false;
    }
    return true;
}
// d += a - b over a row (a or b null: zero).
TEXCACHE_SCREEN_CLONES void AddSubRow(float* d, const float* a, const float* b, int w) {
    for (int x = 0; x < w; ++x) d[x] += (a ? a[x] : 0.0f) - (b ? b[x] : 0.0f);
}

}  // namespace

void BoxSum(int nc, const Plane* const* in, Plane* const* out, Plane* const* tmp, int r) {
    const int w = in[0]->Width(), h = in[0]->Height();
    // zero[c * h + y]: the horizontal sums of row y of plane c are all zero. They are skipped
    // (scanned, not summed) and the vertical pass neither adds nor subtracts them.
    std::vector<uint8_t> zero(size_t(nc) * size_t(h), 0);
    ForRowBlocks(h, [&](int y0, int y1) {
        std::vector<float> scratch(r <= kPad ? 2 * (size_t(w) + 2 * size_t(r)) : 0);
        for (int y = y0; y < y1; ++y)
            for (int c = 0; c < nc; ++c) {
                const float* s = in[c]->Row(y);
                float* d = tmp[c]->Row(y);
                if (ZeroRow(s, w)) {
                    zero[size_t(c) * size_t(h) + size_t(y)] = 1;
                    continue;
                }
                if (r <= kPad) {
                    BoxRowH(s, d, w, r, scratch.data(), scratch.data() + w + 2 * r);
                    continue;
                }
                // Wider than the padding: running sum (rare; not a hot path).
                double run = 0.0;
                for (int x = 0; x <= std::min(r, w - 1); ++x) run += s[x];
                for (int x = 0; x < w; ++x) {
                    d[x] = float(run);
                    if (x + r + 1 < w) run += s[x + r + 1];
                    if (x - r >= 0) run -= s[x - r];
                }
            }
    });
    // Vertical: a running sum down each block of rows, vectorized across x (the first row of a
    // block is summed directly). Counts and small sums stay exact enough in float: the inputs
    // are 0/1 masks and pixel offsets.
    ForRowBlocks(
        h,
        [&](int rowBegin, int rowEnd) {
            const tbb::blocked_range<int> rr(rowBegin, rowEnd);
            for (int c = 0; c < nc; ++c) {
                const uint8_t* zc = zero.data() + size_t(c) * size_t(h);
                auto row = [&](int yy) -> const float* {
                    return yy >= 0 && yy < h && !zc[yy] ? tmp[c]->Row(yy) : nullptr;
                };
                float* first = out[c]->Row(rr.begin());
                std::fill_n(first, w, 0.0f);
                for (int yy = rr.begin() - r; yy <= rr.begin() + r; ++yy)
                    if (const float* t = row(yy)) AddSubRow(first, t, nullptr, w);
                for (int y = rr.begin() + 1; y < rr.end(); ++y) {
                    float* d = out[c]->Row(y);
                    std::copy_n(out[c]->Row(y - 1), w, d);
                    const float *add = row(y + r), *sub = row(y - r - 1);
                    if (add || sub) AddSubRow(d, add, sub, w);
                }
            }
        },
        32);
}

}  // namespace texcache::screen::internal
