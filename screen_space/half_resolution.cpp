// SPDX-License-Identifier: Apache-2.0
// The stage on half the pixels (DenoiserSettings::halfResolutionRows): the frame is reduced to
// one sample per 2x2 block, a second denoiser runs every pass that keeps history or reads
// neighbours on it, and its demodulated results come back through a joint-bilateral upsample
// over the full frame's guides. The factors that carry texture and edges (shading, albedo,
// F_beta) stay at full resolution: only the slowly varying, noisy ratios are filtered coarse.
//
// Design note. A block's representative is its depth medoid among samples of one object: at a
// silhouette it is a sample of the surface that covers most of the block, never a blend of two.
// The block's noisy components are the mean of the samples on that surface (same object, depth
// and normal close), so the half frame holds up to four samples a pixel and its noise is lower;
// indirect is averaged demodulated and remodulated with the representative's albedo, so a
// texture edge inside the block does not leak into the ratio. The upsample takes the 2x2
// half-resolution samples around a pixel, bilinear weights times SVGF's normal and depth terms,
// and only samples of the pixel's own object: colour never crosses an objectId boundary. A pixel
// no sample of its surface reaches (a feature one pixel thin) keeps its own noisy input.
#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "screen_space/denoiser_state.h"
#include "screen_space/internal.h"

namespace texcache::screen::internal {
namespace {

// Samples of one block whose depths differ by more than this fraction, or whose normals by
// more than acos(kMinNormalDot), are taken to be different surfaces.
constexpr float kSameDepth = 0.05f;
constexpr float kMinNormalDot = 0.8f;

// Every per-pixel array of the frame that the half frame takes from the representative as is:
// those the half denoiser reads. Not the shading (it composes no image) nor the blocker and
// the light sample (the shadow vectors read their previous positions only): the gather is
// memory-bound, a full-resolution array read for each array copied.
template <class Fn>
void ForEachCopied(const FrameBuffers& f, FrameBuffers* h, Fn&& fn) {
    for (auto m : {&FrameBuffers::position, &FrameBuffers::normal, &FrameBuffers::albedo,
                   &FrameBuffers::specular, &FrameBuffers::prevPosition, &FrameBuffers::prevNormal,
                   &FrameBuffers::prevBlocker, &FrameBuffers::prevLightSample,
                   &FrameBuffers::glossyHit, &FrameBuffers::prevGlossyHit})
        fn(f.*m, h->*m);
    fn(f.depth, h->depth);
    fn(f.roughness, h->roughness);
    fn(f.objectId, h->objectId);
}

// One output row of the upsample. Output pixel 2b takes half-resolution samples b - 1 and b
// (bilinear weights 1/4, 3/4: its centre is at b - 1/4), pixel 2b + 1 takes b and b + 1 (3/4,
// 1/4); the two half rows are weighted `wy`. Written per half-resolution pixel b, both of its
// output pixels in one iteration, so that the half rows are read contiguously and the full row
// as pairs (b - 1 and b + 1 fall into the planes' zero padding at the ends, where validity 0
// drops them): GCC vectorizes both with permutes, where a loop per output parity reads the full
// row with a stride of 2 and stays scalar.
struct UpRow {
    int w, hw;
    float wy[2], depthScale;
    const float *nx, *ny, *nz, *z, *invDz;  // full-resolution guides of the row
    const int* id;
    const uint8_t* ok;
    const float *hnx[2], *hny[2], *hnz[2], *hz[2];  // the two half rows' guides
    const int* hid[2];
    const uint8_t* hok[2];
    int nplanes;
    const float* res[7][2];  // the half rows of each result plane
    const float* own[7];     // this row's input (where no sample of its surface is near)
    float* out[7];           // written up to 2 hw entries (one past an odd row's end)
};

// out[2i + p] = rows[p][i] where inv[p][i] > 0 (some sample of the pixel's surface is near),
// own[2i + p] elsewhere, for i < n. With GCC's generic vectors, 8 pixel pairs at a time: the
// plain loop's stride-2 stores stay scalar and took a third of the upsample.
inline __attribute__((always_inline)) void Interleave(const float (*rows)[128],
                                                      const float (*inv)[128], int n,
                                                      const float* own, float* out) {
    using V8 = float __attribute__((vector_size(32)));
    using V8u = float __attribute__((vector_size(32), aligned(4), may_alias));
    int i = 0;
    for (; i + 8 <= n; i += 8) {
        const V8 e = *reinterpret_cast<const V8*>(&rows[0][i]);
        const V8 o = *reinterpret_cast<const V8*>(&rows[1][i]);
        const V8 ie = *reinterpret_cast<const V8*>(&inv[0][i]);
        const V8 io = *reinterpret_cast<const V8*>(&inv[1][i]);
        const V8 lo = __builtin_shufflevector(e, o, 0, 8, 1, 9, 2, 10, 3, 11);
        const V8 hi = __builtin_shufflevector(e, o, 4, 12, 5, 13, 6, 14, 7, 15);
        const V8 ilo = __builtin_shufflevector(ie, io, 0, 8, 1, 9, 2, 10, 3, 11);
        const V8 ihi = __builtin_shufflevector(ie, io, 4, 12, 5, 13, 6, 14, 7, 15);
        const V8 zero = {};
        const V8 olo = *reinterpret_cast<const V8u*>(own + 2 * i);
        const V8 ohi = *reinterpret_cast<const V8u*>(own + 2 * i + 8);
        *reinterpret_cast<V8u*>(out + 2 * i) = ilo > zero ? lo : olo;
        *reinterpret_cast<V8u*>(out + 2 * i + 8) = ihi > zero ? hi : ohi;
    }
    for (; i < n; ++i)
        for (int p = 0; p < 2; ++p) out[2 * i + p] = inv[p][i] > 0.0f ? rows[p][i] : own[2 * i + p];
}

TEXCACHE_SCREEN_CLONES void UpsampleChunks(const UpRow& args) {
    const UpRow a = args;
    constexpr int kC = 128;
    alignas(64) float wt[2][4][kC], inv[2][kC], rows[2][kC];
    for (int b0 = 0; b0 < a.hw; b0 += kC) {
        const int n = std::min(kC, a.hw - b0);
        for (int i = 0; i < n; ++i) {
            const int b = b0 + i;
#pragma GCC unroll 2
            for (int p = 0; p < 2; ++p) {
                // Taps of pixel 2b + p: half pixels b - 1 + p (weight 1/4 + p/2) and b + p.
                const float wl = p ? 0.75f : 0.25f, wr = 1.0f - wl;
                const int x = 2 * b + p;
                const float okx = float(a.ok[x]);
                float sum = 0.0f;
#pragma GCC unroll 2
                for (int j = 0; j < 2; ++j)
#pragma GCC unroll 2
                    for (int t = 0; t < 2; ++t) {
                        const int hx = b - 1 + p + t;
                        // Branch-free (validity flags are 0 / 1) so that the loop vectorizes.
                        const float use =
                            okx * float(a.hok[j][hx]) * float(a.hid[j][hx] == a.id[x] ? 1 : 0);
                        float nd = std::max(0.0f, a.nx[x] * a.hnx[j][hx] + a.ny[x] * a.hny[j][hx] +
                                                      a.nz[x] * a.hnz[j][hx]);
                        // nd^32: SVGF's normal term, softer than the a-trous's (the samples
                        // are at most a pixel and a half away), without a pow per tap.
                        nd *= nd, nd *= nd, nd *= nd, nd *= nd, nd *= nd;
                        // Depth in units of the pixel's own depth step per pixel, over the up
                        // to two pixels between it and a half-resolution sample.
                        const float dz =
                            std::fabs(a.hz[j][hx] - a.z[x]) * a.invDz[x] * a.depthScale;
                        const float wgt = use * (t ? wr : wl) * a.wy[j] * nd / (1.0f + dz * dz);
                        wt[p][2 * j + t][i] = wgt;
                        sum += wgt;
                    }
                inv[p][i] = sum > 1e-6f ? 1.0f / sum : 0.0f;
            }
        }
        for (int c = 0; c < a.nplanes; ++c) {
            const float* r0 = a.res[c][0];
            const float* r1 = a.res[c][1];
            for (int p = 0; p < 2; ++p)
                for (int i = 0; i < n; ++i) {
                    const int hx = b0 + i - 1 + p;
                    rows[p][i] = (wt[p][0][i] * r0[hx] + wt[p][1][i] * r0[hx + 1] +
                                  wt[p][2][i] * r1[hx] + wt[p][3][i] * r1[hx + 1]) *
                                 inv[p][i];
                }
            Interleave(rows, inv, n, a.own[c] + 2 * b0, a.out[c] + 2 * b0);
        }
    }
}

// One half row of the reduction, on both full rows of its blocks (row1 = row0 and pres1 = 0
// where the frame has no second row). A chunk of blocks is first unpacked into local arrays,
// one per sample k of the block (0, 1: the first row's left and right pixel; 2, 3: the
// second's) and channel, so that the choices and the means read them at unit stride, 8 blocks
// a time: read in place (a stride of two pixels of interleaved vec3 rows) and written as plain
// loops, GCC left every loop of the reduction scalar. The choices are selects over the four
// samples with a presence flag each, not loops over the samples that exist; the representative
// and the colour means use GCC's generic vectors, whose selects it does not have to if-convert.
struct ReduceRow {
    int w, hw;
    float pres1;            // 1 when the blocks' second row exists
    const float* depth[2];  // the two full rows
    const int32_t* id[2];
    const float* nrm[2];  // xyz interleaved
    const float* vis[2];
    const float* cvis[2];    // cachedVisibility, or null
    const float* glossy[2];  // or null
    const float* ind[2];     // or null
    const float* alb[2];     // or null
    uint32_t rowStart[2];    // index of each full row's first pixel in the frame
    uint32_t* rep;           // each block's representative pixel
    float* hvis;
    float* hcvis;    // or null
    float* hglossy;  // xyz interleaved, or null
    float* hind;     // or null
};

inline bool FiniteF(float v) {
    return std::fabs(v) <= std::numeric_limits<float>::max();
}

constexpr int kReduceChunk = 64;  // a multiple of 8, the lanes of V8

// GCC's generic vectors: 8 lanes of the reduction's per-block arithmetic, with selects
// (mask ? a : b) where the scalar form has branches GCC does not if-convert.
using V8 = float __attribute__((vector_size(32)));
using V8i = int32_t __attribute__((vector_size(32)));

// The functions and lambdas that take or return V8 are always inlined into the ISA clones, so
// the vector ABI GCC warns about is never used (GCC reports it for the baseline clone at the
// end of the file, hence no pop).
#pragma GCC diagnostic ignored "-Wpsabi"
inline __attribute__((always_inline)) V8 AbsV(V8 v) {
    return reinterpret_cast<V8>(reinterpret_cast<V8i>(v) & 0x7fffffff);
}
// FiniteF per lane, as a mask.
inline __attribute__((always_inline)) V8i FiniteV(V8 v) {
    return AbsV(v) <= std::numeric_limits<float>::max();
}

// 16 entries of a frame row, read unaligned.
template <class T>
struct Row16;
template <>
struct Row16<float> {
    using V = float __attribute__((vector_size(64), aligned(4), may_alias));
    using Half = V8;
};
template <>
struct Row16<int32_t> {
    using V = int32_t __attribute__((vector_size(64), aligned(4), may_alias));
    using Half = V8i;
};

// Lanes of 8 blocks' left (Off = C) or right (Off = NC + C) samples of channel C in 16 pixels
// of NC channels: entry Off + 2 NC i, i < 8. With NC = 3 they span three 16-lane loads: the
// lanes below 32 are taken from the first two, then the rest from the third.
#define TEXCACHE_J(i) (Off + 2 * NC * (i))
#define TEXCACHE_LO(i) (TEXCACHE_J(i) < 32 ? TEXCACHE_J(i) : 0)
#define TEXCACHE_HI(i) (TEXCACHE_J(i) < 32 ? (i) : TEXCACHE_J(i) - 16)
template <int NC, int Off, class T, class V = typename Row16<T>::V>
inline __attribute__((always_inline)) typename Row16<T>::Half Deinterleave(const V* a) {
    if constexpr (NC == 1) {
        return __builtin_shufflevector(a[0], a[0], TEXCACHE_J(0), TEXCACHE_J(1), TEXCACHE_J(2),
                                       TEXCACHE_J(3), TEXCACHE_J(4), TEXCACHE_J(5), TEXCACHE_J(6),
                                       TEXCACHE_J(7));
    } else {
        static_assert(NC == 3);
        const V t = __builtin_shufflevector(
            a[0], a[1], TEXCACHE_LO(0), TEXCACHE_LO(1), TEXCACHE_LO(2), TEXCACHE_LO(3),
            TEXCACHE_LO(4), TEXCACHE_LO(5), TEXCACHE_LO(6), TEXCACHE_LO(7), 0, 0, 0, 0, 0, 0, 0, 0);
        return __builtin_shufflevector(t, a[2], TEXCACHE_HI(0), TEXCACHE_HI(1), TEXCACHE_HI(2),
                                       TEXCACHE_HI(3), TEXCACHE_HI(4), TEXCACHE_HI(5),
                                       TEXCACHE_HI(6), TEXCACHE_HI(7));
    }
}
#undef TEXCACHE_J
#undef TEXCACHE_LO
#undef TEXCACHE_HI

// Sample k's entries of a chunk of n blocks from b0 on: dst[k][i] = src[row k / 2][(2 (b0 + i)
// + k % 2) * NC + C], the right pixel clamped to the row (its presence flag is 0 there). Groups
// of 8 blocks whose 16 pixels lie in the row are deinterleaved with shuffles (GCC leaves the
// strided copy scalar, and it took most of the reduction's time); the rest entry by entry.
template <int NC, int C, class T>
inline __attribute__((always_inline)) void UnpackSamples(const T* const* src, int w, int b0, int n,
                                                         T (*dst)[kReduceChunk]) {
    using V = typename Row16<T>::V;
    using H = typename Row16<T>::Half;
    const int groups = std::max(0, std::min(n, w / 2 - b0)) / 8;
#pragma GCC unroll 2
    for (int r = 0; r < 2; ++r) {
        const T* s = src[r] + size_t(2 * b0) * size_t(NC);
        for (int g = 0; g < groups; ++g) {
            V in[NC];
            for (int k = 0; k < NC; ++k) in[k] = reinterpret_cast<const V*>(s + 16 * NC * g)[k];
            *reinterpret_cast<H*>(&dst[2 * r][8 * g]) = Deinterleave<NC, C, T>(in);
            *reinterpret_cast<H*>(&dst[2 * r + 1][8 * g]) = Deinterleave<NC, NC + C, T>(in);
        }
        for (int i = 8 * groups; i < n; ++i) {
            const int xr = std::min(2 * (b0 + i) + 1, w - 1) - 2 * b0;
            dst[2 * r][i] = s[2 * NC * i + C], dst[2 * r + 1][i] = s[NC * xr + C];
        }
    }
}

TEXCACHE_SCREEN_CLONES void ReduceBlocks(const ReduceRow& args) {
    const ReduceRow a = args;
    constexpr int kC = kReduceChunk;
    // Zeroed once: a last chunk shorter than 8 blocks computes its lanes past n from them.
    alignas(64) float z[4][kC] = {}, nx[4][kC] = {}, ny[4][kC] = {}, nz[4][kC] = {},
                      same[4][kC] = {}, pres[4][kC] = {}, v[3][4][kC] = {}, al[3][4][kC] = {};
    alignas(64) int id[4][kC] = {}, ra[kC] = {};
    for (int b0 = 0; b0 < a.hw; b0 += kC) {
        const int n = std::min(kC, a.hw - b0);
        UnpackSamples<1, 0>(a.depth, a.w, b0, n, z);
        UnpackSamples<3, 0>(a.nrm, a.w, b0, n, nx);
        UnpackSamples<3, 1>(a.nrm, a.w, b0, n, ny);
        UnpackSamples<3, 2>(a.nrm, a.w, b0, n, nz);
        UnpackSamples<1, 0>(a.id, a.w, b0, n, id);
        for (int i = 0; i < n; ++i) {
            const float presR = 2 * (b0 + i) + 1 < a.w ? 1.0f : 0.0f;
            pres[0][i] = 1.0f, pres[1][i] = presR, pres[2][i] = a.pres1;
            pres[3][i] = presR * a.pres1;
        }
        // The representative (the depth medoid among usable samples, samples of other objects
        // counting as far) and the samples of its surface, 8 blocks at a time (the entries past
        // n hold an earlier chunk's values or 0 and are not stored).
        for (int i = 0; i < n; i += 8) {
            auto ld = [&](const auto& arr, int k) __attribute__((always_inline)) {
                using E = std::remove_cvref_t<decltype(arr[0][0])>;
                using V = std::conditional_t<std::is_same_v<E, float>, V8, V8i>;
                return *reinterpret_cast<const V*>(&arr[k][i]);
            };
            V8 zk[4], nxk[4], nyk[4], nzk[4], pk[4];
            V8i idk[4], use[4];
#pragma GCC unroll 4
            for (int k = 0; k < 4; ++k) {
                zk[k] = ld(z, k), nxk[k] = ld(nx, k), nyk[k] = ld(ny, k), nzk[k] = ld(nz, k);
                pk[k] = ld(pres, k), idk[k] = ld(id, k);
                use[k] = (pk[k] > 0.0f) & FiniteV(zk[k]) & FiniteV(nxk[k]) & FiniteV(nyk[k]) &
                         FiniteV(nzk[k]) & (idk[k] >= 0);
            }
            V8 best = V8{} + INFINITY;
            V8i r = V8i{};
#pragma GCC unroll 4
            for (int k = 0; k < 4; ++k) {
                const V8 inv = 1.0f / zk[k];
                V8 cost = V8{};
#pragma GCC unroll 4
                for (int m = 0; m < 4; ++m) {
                    const V8i sm = use[m] & (idk[m] == idk[k]);
                    const V8 c = sm ? AbsV(zk[m] - zk[k]) * inv : V8{} + 1.0f;
                    cost += pk[m] > 0.0f ? c : V8{};
                }
                const V8i better = use[k] & (cost < best);
                best = better ? cost : best, r = better ? V8i{} + k : r;
            }
            auto pick = [&](const auto* v) __attribute__((always_inline)) {
                return r == 0 ? v[0] : r == 1 ? v[1] : r == 2 ? v[2] : v[3];
            };
            const V8 zr = pick(zk), nxr = pick(nxk), nyr = pick(nyk), nzr = pick(nzk);
            const V8i idr = pick(idk), user = pick(use);
            V8 sk[4], ns = V8{};
#pragma GCC unroll 4
            for (int k = 0; k < 4; ++k) {
                const V8 d = nxk[k] * nxr + nyk[k] * nyr + nzk[k] * nzr;
                const V8i sm = user & use[k] & (idk[k] == idr) &
                               (AbsV(zk[k] - zr) <= kSameDepth * zr) & (d >= kMinNormalDot);
                sk[k] = sm ? V8{} + 1.0f : V8{};
                ns += sk[k];
            }
            // No usable sample of its own surface: the representative alone.
#pragma GCC unroll 4
            for (int k = 0; k < 4; ++k) {
                sk[k] = (ns == 0.0f) & (r == k) ? V8{} + 1.0f : sk[k];
                *reinterpret_cast<V8*>(&same[k][i]) = sk[k];
            }
            *reinterpret_cast<V8i*>(&ra[i]) = r;
        }
        for (int i = 0; i < n; ++i) {
            const uint32_t xl = uint32_t(2 * (b0 + i));
            const uint32_t xr = uint32_t(std::min(2 * (b0 + i) + 1, a.w - 1));
            a.rep[b0 + i] = (ra[i] >= 2 ? a.rowStart[1] : a.rowStart[0]) + ((ra[i] & 1) ? xr : xl);
        }
        // Means over the finite samples of the surface; the representative's own value when
        // none is.
        auto mean1 = [&](const float* const* src, float* dst) __attribute__((always_inline)) {
            UnpackSamples<1, 0>(src, a.w, b0, n, v[0]);
            for (int i = 0; i < n; ++i) {
                float sum = 0.0f, cnt = 0.0f, vr = 0.0f;
#pragma GCC unroll 4
                for (int k = 0; k < 4; ++k) {
                    const float x = v[0][k][i];
                    const bool m = (same[k][i] > 0.0f) & FiniteF(x);
                    sum += m ? x : 0.0f, cnt += m ? 1.0f : 0.0f;
                    vr = ra[i] == k ? x : vr;
                }
                dst[b0 + i] = cnt > 0.0f ? sum / cnt : vr;
            }
        };
        mean1(a.vis, a.hvis);
        if (a.hcvis) mean1(a.cvis, a.hcvis);
        // Colour means; with `alb`, demodulated where the albedo can be divided out and
        // remodulated with the representative's albedo, as the stage does. Without, the albedo
        // is taken as 1, which leaves every value as it is (raw / 1 * 1 = raw) and keeps the
        // loop free of branches.
        alignas(64) float out[3][kC];
        auto mean3 = [&](const float* const* src, const float* const* alb, float* dst)
            __attribute__((always_inline)) {
            UnpackSamples<3, 0>(src, a.w, b0, n, v[0]);
            UnpackSamples<3, 1>(src, a.w, b0, n, v[1]);
            UnpackSamples<3, 2>(src, a.w, b0, n, v[2]);
            if (alb) {
                UnpackSamples<3, 0>(alb, a.w, b0, n, al[0]);
                UnpackSamples<3, 1>(alb, a.w, b0, n, al[1]);
                UnpackSamples<3, 2>(alb, a.w, b0, n, al[2]);
            } else {
                std::fill_n(&al[0][0][0], 3 * 4 * kC, 1.0f);
            }
            for (int i = 0; i < n; i += 8) {
                const V8i rv = *reinterpret_cast<const V8i*>(&ra[i]);
                V8 sum[3] = {}, cnt = V8{}, vr[3] = {}, ar[3];
                for (int c = 0; c < 3; ++c) ar[c] = V8{} + 1.0f;
#pragma GCC unroll 4
                for (int k = 0; k < 4; ++k)
#pragma GCC unroll 3
                    for (int c = 0; c < 3; ++c)
                        ar[c] = rv == k ? *reinterpret_cast<const V8*>(&al[c][k][i]) : ar[c];
#pragma GCC unroll 4
                for (int k = 0; k < 4; ++k) {
                    V8 x[3];
                    V8i fin = *reinterpret_cast<const V8*>(&same[k][i]) > 0.0f;
#pragma GCC unroll 3
                    for (int c = 0; c < 3; ++c) {
                        const V8 raw = *reinterpret_cast<const V8*>(&v[c][k][i]);
                        const V8 alk = *reinterpret_cast<const V8*>(&al[c][k][i]);
                        vr[c] = rv == k ? raw : vr[c];
                        x[c] = alk > 1e-3f ? raw / alk * ar[c] : V8{} + kNaN;
                        fin = fin & FiniteV(x[c]);
                    }
#pragma GCC unroll 3
                    for (int c = 0; c < 3; ++c) sum[c] += fin ? x[c] : V8{};
                    cnt += fin ? V8{} + 1.0f : V8{};
                }
#pragma GCC unroll 3
                for (int c = 0; c < 3; ++c)
                    *reinterpret_cast<V8*>(&out[c][i]) = cnt > 0.0f ? sum[c] / cnt : vr[c];
            }
            float* d = dst + 3 * size_t(b0);
            for (int i = 0; i < n; ++i)
                d[3 * i] = out[0][i], d[3 * i + 1] = out[1][i], d[3 * i + 2] = out[2][i];
        };
        if (a.hglossy) mean3(a.glossy, nullptr, a.hglossy);
        if (a.hind) mean3(a.ind, a.alb[0] ? a.alb : nullptr, a.hind);
    }
}

}  // namespace

void DownsampleFrame(const FrameBuffers& f, bool withCones, FrameBuffers* h,
                     std::vector<uint32_t>* source, const std::function<void(int)>& fullRow) {
    const int hw = (f.width + 1) / 2, hh = (f.height + 1) / 2;
    const size_t n = size_t(hw) * size_t(hh);
    h->width = hw, h->height = hh, h->time = f.time;
    h->camera = f.camera;
    h->camera.width = hw, h->camera.height = hh;
    // Composed at full resolution only: the shading has the size a frame must have, unread.
    h->emitted.clear(), h->blocker.clear(), h->lightSample.clear();
    h->shading.resize(n);
    ForEachCopied(f, h, [&](const auto& src, auto& dst) { dst.resize(src.empty() ? 0 : n); });
    h->visibility.resize(n);
    h->cachedVisibility.resize(f.cachedVisibility.empty() ? 0 : n);
    h->glossy.resize(f.glossy.empty() ? 0 : n);
    h->indirect.resize(f.indirect.empty() ? 0 : n);
    h->cones.resize(f.cones.empty() || !withCones ? 0 : n * kNumCones);
    std::vector<uint32_t>& reps = *source;
    reps.resize(n);
    // One pass: a half row's representatives and means, then every array the half frame
    // copies from them, while the block row's full rows are still in the caches.
    ForRows(hh, [&](int by) {
        const int y0 = 2 * by, y1 = std::min(2 * by + 1, f.height - 1);
        fullRow(y0);
        if (y1 != y0) fullRow(y1);
        const size_t rows[2] = {size_t(y0) * size_t(f.width), size_t(y1) * size_t(f.width)};
        const size_t o = size_t(by) * size_t(hw);
        ReduceRow a;
        a.w = f.width, a.hw = hw, a.pres1 = 2 * by + 1 < f.height ? 1.0f : 0.0f;
        for (int r = 0; r < 2; ++r) {
            const size_t i = rows[r];
            a.rowStart[r] = uint32_t(i);
            a.depth[r] = &f.depth[i], a.id[r] = &f.objectId[i], a.nrm[r] = &f.normal[i].x;
            a.vis[r] = &f.visibility[i];
            a.cvis[r] = f.cachedVisibility.empty() ? nullptr : &f.cachedVisibility[i];
            a.glossy[r] = f.glossy.empty() ? nullptr : &f.glossy[i].x;
            a.ind[r] = f.indirect.empty() ? nullptr : &f.indirect[i].x;
            a.alb[r] = f.albedo.empty() ? nullptr : &f.albedo[i].x;
        }
        a.rep = &reps[o];
        a.hvis = &h->visibility[o];
        a.hcvis = f.cachedVisibility.empty() ? nullptr : &h->cachedVisibility[o];
        a.hglossy = f.glossy.empty() ? nullptr : &h->glossy[o].x;
        a.hind = f.indirect.empty() ? nullptr : &h->indirect[o].x;
        ReduceBlocks(a);
        ForEachCopied(f, h, [&](const auto& src, auto& dst) {
            if (src.empty()) return;
            for (int bx = 0; bx < hw; ++bx) dst[o + bx] = src[reps[o + bx]];
        });
        if (!h->cones.empty())
            for (size_t k = o; k < o + size_t(hw); ++k)
                std::copy_n(&f.cones[size_t(reps[k]) * kNumCones], kNumCones,
                            &h->cones[k * kNumCones]);
    });
}

int UpsampledPlanes(const ScreenSpaceDenoiser::State& s, const ScreenSpaceDenoiser::State& half) {
    int n = 0;
    for (int ci = 0; ci < 3; ++ci)
        if (s.comp[ci].present && half.comp[ci].res[0]) n += s.comp[ci].nc;
    return n;
}

void UpsampleRow(const ScreenSpaceDenoiser::State& s, const ScreenSpaceDenoiser::State& half, int y,
                 const GuideRowView& gv, const float* const* own, float* const* out) {
    // The half denoiser has already swapped its guide sets: its last frame's are PrevG().
    const Guides& hg = half.PrevG();
    const Guides& g = s.guides[s.cur];
    const int hh = half.h;
    // Row y's centre is half-resolution row y / 2 - 1/4 (even) or (y - 1) / 2 + 1/4 (odd).
    const int y0 = (y - 1) >> 1;
    const int sy[2] = {std::max(y0, 0), std::min(y0 + 1, hh - 1)};
    UpRow a;
    a.w = s.w, a.hw = half.w;
    a.wy[0] = (y & 1) ? 0.75f : 0.25f, a.wy[1] = 1.0f - a.wy[0];
    a.depthScale = 1.0f / (2.0f * s.set.sigmaDepth);
    a.nx = gv.nx, a.ny = gv.ny, a.nz = gv.nz;
    a.z = g.depth.Row(y), a.invDz = g.invDz.Row(y), a.id = gv.id;
    a.ok = g.valid.Row(y);
    for (int j = 0; j < 2; ++j) {
        a.hnx[j] = hg.nx.Row(sy[j]), a.hny[j] = hg.ny.Row(sy[j]);
        a.hnz[j] = hg.nz.Row(sy[j]), a.hz[j] = hg.depth.Row(sy[j]);
        a.hid[j] = hg.objectId.Row(sy[j]), a.hok[j] = hg.valid.Row(sy[j]);
    }
    a.nplanes = 0;
    for (int ci = 0; ci < 3; ++ci) {
        if (!s.comp[ci].present || !half.comp[ci].res[0]) continue;
        for (int c = 0; c < s.comp[ci].nc; ++c, ++a.nplanes) {
            for (int j = 0; j < 2; ++j) a.res[a.nplanes][j] = half.comp[ci].res[c]->Row(sy[j]);
            a.own[a.nplanes] = own[a.nplanes];
            a.out[a.nplanes] = out[a.nplanes];
        }
    }
    UpsampleChunks(a);
}

}  // namespace texcache::screen::internal
