// SPDX-License-Identifier: Apache-2.0
// The vectorized row kernels of the screen-space stage (see planes.h for the layout).
//
// Design note. A pass is processed in chunks of kChunk pixels of one row. Per-pixel centre data
// (depth, normal, tolerances) is staged in small arrays, then the tap loop runs outside and the
// pixel loop inside, so the innermost loop is a straight-line, branch-free sweep over contiguous
// floats that GCC turns into AVX2 code; the accumulators stay in L1. Every edge-stopping factor is
// folded into one exponent so a tap costs one Exp2Neg:
//     w = h_t * valid_q * 2^-(|z_q - z_p| cz_t idz_p + kn (1 - n_p.n_q) + |l_q - l_p| il_p
//                            + off_t^2 s_p)
// (the depth, normal, luminance and clean-up-Gaussian terms of SVGF's a-trous and of a joint
// bilateral filter), all in log2 units.
#include <algorithm>
#include <bit>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "filters/screen_space/planes.h"

namespace texcache::screen::detail {

void Guides::Resize(int w, int h) {
    for (Plane* p : {&px, &py, &pz, &nx, &ny, &nz, &depth, &invDzX, &invDzY}) p->Resize(w, h);
    objectId.Resize(w, h, -2);
    valid.Resize(w, h, 0);
}

namespace {

constexpr int kChunk = 256;
constexpr float kLog2e = 1.44269504f;

enum class Mode { Bilateral, Atrous, Cleanup };

template <int NC, Mode M>
inline __attribute__((always_inline)) void FilterRowImpl(const PassArgs& a, int y) {
    const Guides& g = *a.g;
    const int w = g.depth.Width(), h = g.depth.Height();
    const float kn = a.normalPower * kLog2e;
    const Plane* invDz = a.vertical ? &g.invDzY : &g.invDzX;

    alignas(64) float zc[kChunk], nxc[kChunk], nyc[kChunk], nzc[kChunk], idz[kChunk];
    alignas(64) float lc[kChunk], il[kChunk], sc[kChunk];
    alignas(64) float acc[NC][kChunk], wsum[kChunk], vacc[kChunk];

    float cz[33];
    for (int t = 0; t < a.taps; ++t)
        cz[t] = a.offset[t] == 0 ? 0.0f : kLog2e / (a.depthSigma * float(std::abs(a.offset[t])));

    for (int x0 = 0; x0 < w; x0 += kChunk) {
        const int n = std::min(kChunk, w - x0);
        {
            const float* z = g.depth.Row(y) + x0;
            const float* nx = g.nx.Row(y) + x0;
            const float* ny = g.ny.Row(y) + x0;
            const float* nz = g.nz.Row(y) + x0;
            const float* iz = invDz->Row(y) + x0;
            for (int i = 0; i < n; ++i) {
                zc[i] = z[i], nxc[i] = nx[i], nyc[i] = ny[i], nzc[i] = nz[i], idz[i] = iz[i];
                wsum[i] = 0.0f, vacc[i] = 0.0f;
            }
            for (int c = 0; c < NC; ++c)
                for (int i = 0; i < n; ++i) acc[c][i] = 0.0f;
            if constexpr (M == Mode::Atrous) {
                const float* ilr = a.invLum->Row(y) + x0;
                if constexpr (NC == 3) {
                    const float* r = a.in[0]->Row(y) + x0;
                    const float* gg = a.in[1]->Row(y) + x0;
                    const float* b = a.in[2]->Row(y) + x0;
                    for (int i = 0; i < n; ++i) lc[i] = Luma(r[i], gg[i], b[i]);
                } else {
                    const float* v = a.in[0]->Row(y) + x0;
                    for (int i = 0; i < n; ++i) lc[i] = v[i];
                }
                for (int i = 0; i < n; ++i) il[i] = ilr[i] * kLog2e;
            }
            if constexpr (M == Mode::Cleanup) {
                const float* s = a.sigma->Row(y) + x0;
                float smax = 0.0f;
                for (int i = 0; i < n; ++i) {
                    // 1 / (2 sigma^2); a huge finite value below ~0.05 px keeps only the centre.
                    sc[i] = s[i] > 0.05f ? kLog2e / (2.0f * s[i] * s[i]) : 1e30f;
                    smax = std::max(smax, s[i]);
                }
                if (smax <= 0.05f) {  // nothing to clean up in this chunk: copy
                    for (int c = 0; c < NC; ++c)
                        std::copy_n(a.in[c]->Row(y) + x0, n, a.out[c]->Row(y) + x0);
                    continue;
                }
            }
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
            const float ht = a.weight[t];
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
            const float* varq = M == Mode::Atrous ? a.var->Row(yq) + xs : in0;
            for (int i = 0; i < n; ++i) {
                const float dot = nxc[i] * nxq[i] + nyc[i] * nyq[i] + nzc[i] * nzq[i];
                float e = std::fabs(zq[i] - zc[i]) * idz[i] * czt + kn * (1.0f - dot);
                float lq = 0.0f;
                if constexpr (M == Mode::Atrous) {
                    lq = NC == 3 ? Luma(in0[i], in1[i], in2[i]) : in0[i];
                    e += std::fabs(lq - lc[i]) * il[i];
                }
                if constexpr (M == Mode::Cleanup) e += off2 * sc[i];
                float wt = (M == Mode::Cleanup ? 1.0f : ht) * vq[i] * Exp2Neg(-e);
                wsum[i] += wt;
                acc[0][i] += wt * in0[i];
                if constexpr (NC == 3) {
                    acc[1][i] += wt * in1[i];
                    acc[2][i] += wt * in2[i];
                }
                if constexpr (M == Mode::Atrous) vacc[i] += wt * wt * varq[i];
            }
        }
        for (int c = 0; c < NC; ++c) {
            float* o = a.out[c]->Row(y) + x0;
            for (int i = 0; i < n; ++i) o[i] = wsum[i] > 0.0f ? acc[c][i] / wsum[i] : 0.0f;
        }
        if constexpr (M == Mode::Atrous) {
            float* ov = a.outVar->Row(y) + x0;
            for (int i = 0; i < n; ++i)
                ov[i] = wsum[i] > 0.0f ? vacc[i] / (wsum[i] * wsum[i]) : 0.0f;
        }
        if (a.outValid) {
            float* ov = a.outValid->Row(y) + x0;
            for (int i = 0; i < n; ++i) ov[i] = wsum[i] > 0.0f ? 1.0f : 0.0f;
        }
    }
}

// One clone per ISA of each instantiation; the loader picks one (ifunc) at start-up.
#define TEXCACHE_KERNEL(name, NC, M)                                                         \
    __attribute__((target_clones("arch=x86-64-v3", "default"))) void name(const PassArgs& a, \
                                                                          int y0, int y1) {  \
        for (int y = y0; y < y1; ++y) FilterRowImpl<NC, M>(a, y);                            \
    }
TEXCACHE_KERNEL(Bilateral1, 1, Mode::Bilateral)
TEXCACHE_KERNEL(Bilateral3, 3, Mode::Bilateral)
TEXCACHE_KERNEL(Atrous1, 1, Mode::Atrous)
TEXCACHE_KERNEL(Atrous3, 3, Mode::Atrous)
TEXCACHE_KERNEL(Cleanup1, 1, Mode::Cleanup)
TEXCACHE_KERNEL(Cleanup3, 3, Mode::Cleanup)
#undef TEXCACHE_KERNEL

}  // namespace

void FilterRows(const PassArgs& a, int y0, int y1) {
    const bool three = a.nc == 3;
    if (a.sigma)
        three ? Cleanup3(a, y0, y1) : Cleanup1(a, y0, y1);
    else if (a.var)
        three ? Atrous3(a, y0, y1) : Atrous1(a, y0, y1);
    else
        three ? Bilateral3(a, y0, y1) : Bilateral1(a, y0, y1);
}

void FilterPlanes(const PassArgs& a) {
    const int h = a.g->depth.Height();
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4),
                      [&](const tbb::blocked_range<int>& r) { FilterRows(a, r.begin(), r.end()); });
}

void BoxSum(int nc, const Plane* const* in, Plane* const* out, Plane* const* tmp, int r) {
    const int w = in[0]->Width(), h = in[0]->Height();
    // Horizontal: running sums along each row (out-of-image taps are the zero padding or
    // skipped), in double so long rows do not drift.
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 8), [&](const tbb::blocked_range<int>& rr) {
        for (int y = rr.begin(); y < rr.end(); ++y)
            for (int c = 0; c < nc; ++c) {
                const float* s = in[c]->Row(y);
                float* d = tmp[c]->Row(y);
                double run = 0.0;
                for (int x = 0; x <= std::min(r, w - 1); ++x) run += s[x];
                for (int x = 0; x < w; ++x) {
                    d[x] = float(run);
                    if (x + r + 1 < w) run += s[x + r + 1];
                    if (x - r >= 0) run -= s[x - r];
                }
            }
    });
    // Vertical: a direct sum over the 2r+1 rows, vectorized across x.
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 8), [&](const tbb::blocked_range<int>& rr) {
        for (int y = rr.begin(); y < rr.end(); ++y)
            for (int c = 0; c < nc; ++c) {
                float* d = out[c]->Row(y);
                std::fill_n(d, w, 0.0f);
                for (int yy = std::max(0, y - r); yy <= std::min(h - 1, y + r); ++yy) {
                    const float* s = tmp[c]->Row(yy);
                    for (int x = 0; x < w; ++x) d[x] += s[x];
                }
            }
    });
}

}  // namespace texcache::screen::detail
