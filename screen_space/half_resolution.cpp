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

#include "screen_space/denoiser_state.h"
#include "screen_space/internal.h"

namespace texcache::screen::internal {
namespace {

// Samples of one block whose depths differ by more than this fraction, or whose normals by
// more than acos(kMinNormalDot), are taken to be different surfaces.
constexpr float kSameDepth = 0.05f;
constexpr float kMinNormalDot = 0.8f;

bool Usable(const FrameBuffers& f, size_t i) {
    const glm::vec3 n = f.normal[i];
    return std::isfinite(f.depth[i]) && std::isfinite(n.x) && std::isfinite(n.y) &&
           std::isfinite(n.z) && f.objectId[i] >= 0;
}

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

}  // namespace

void DownsampleFrame(const FrameBuffers& f, bool withCones, FrameBuffers* h,
                     std::vector<uint32_t>* source) {
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
    const bool hasAlbedo = !f.albedo.empty();
    std::vector<uint32_t>& reps = *source;
    reps.resize(n);
    ForRows(hh, [&](int by) {
        for (int bx = 0; bx < hw; ++bx) {
            size_t px[4] = {0, 0, 0, 0};
            int np = 0;
            for (int j = 0; j < 2; ++j)
                for (int i = 0; i < 2; ++i) {
                    const int x = 2 * bx + i, y = 2 * by + j;
                    if (x < f.width && y < f.height)
                        px[np++] = size_t(y) * size_t(f.width) + size_t(x);
                }
            bool use[4] = {false, false, false, false};
            for (int a = 0; a < np; ++a) use[a] = Usable(f, px[a]);
            // The depth medoid among usable samples, samples of other objects counting as far.
            int ra = 0;
            float best = INFINITY;
            for (int a = 0; a < np; ++a) {
                if (!use[a]) continue;
                const float za = f.depth[px[a]], inv = 1.0f / za;
                const int ida = f.objectId[px[a]];
                float cost = 0.0f;
                for (int b = 0; b < np; ++b) {
                    const bool same = use[b] && f.objectId[px[b]] == ida;
                    cost += same ? std::fabs(f.depth[px[b]] - za) * inv : 1.0f;
                }
                if (cost < best) best = cost, ra = a;
            }
            const size_t rep = px[ra];
            const size_t o = size_t(by) * size_t(hw) + size_t(bx);
            reps[o] = uint32_t(rep);
            // The samples of the representative's surface (itself included when usable).
            size_t same[4];
            int ns = 0;
            if (use[ra]) {
                const float zr = f.depth[rep];
                const glm::vec3 nr = f.normal[rep];
                for (int a = 0; a < np; ++a) {
                    const size_t p = px[a];
                    if (use[a] && f.objectId[p] == f.objectId[rep] &&
                        std::fabs(f.depth[p] - zr) <= kSameDepth * zr &&
                        glm::dot(f.normal[p], nr) >= kMinNormalDot)
                        same[ns++] = p;
                }
            }
            if (ns == 0) same[ns++] = rep;
            // Means over the finite samples; the representative's own value when none is.
            auto meanOf = [&](auto get, auto fallback) {
                decltype(fallback) sum{};
                int k = 0;
                for (int a = 0; a < ns; ++a) {
                    const auto v = get(same[a]);
                    if (Finite(glm::vec3(v))) sum += v, ++k;
                }
                return k ? sum / float(k) : fallback;
            };
            h->visibility[o] = meanOf([&](size_t p) { return f.visibility[p]; }, f.visibility[rep]);
            if (!f.cachedVisibility.empty())
                h->cachedVisibility[o] = meanOf([&](size_t p) { return f.cachedVisibility[p]; },
                                                f.cachedVisibility[rep]);
            if (!f.glossy.empty())
                h->glossy[o] = meanOf([&](size_t p) { return f.glossy[p]; }, f.glossy[rep]);
            if (!f.indirect.empty()) {
                const glm::vec3 ar = hasAlbedo ? f.albedo[rep] : glm::vec3(1.0f);
                h->indirect[o] = meanOf(
                    [&](size_t p) {
                        if (!hasAlbedo) return f.indirect[p];
                        const glm::vec3 a = f.albedo[p];
                        // Demodulated where the albedo can be divided out, as the stage does.
                        return glm::vec3(a.x > 1e-3f ? f.indirect[p].x / a.x * ar.x : kNaN,
                                         a.y > 1e-3f ? f.indirect[p].y / a.y * ar.y : kNaN,
                                         a.z > 1e-3f ? f.indirect[p].z / a.z * ar.z : kNaN);
                    },
                    f.indirect[rep]);
            }
        }
    });
    // The representative's geometry and factors: one gather per array.
    ForEachCopied(f, h, [&](const auto& src, auto& dst) {
        if (src.empty()) return;
        ForRows(hh, [&](int by) {
            const size_t o = size_t(by) * size_t(hw);
            for (int bx = 0; bx < hw; ++bx) dst[o + bx] = src[reps[o + bx]];
        });
    });
    if (!h->cones.empty())
        ForRows(hh, [&](int by) {
            for (size_t o = size_t(by) * size_t(hw); o < size_t(by + 1) * size_t(hw); ++o)
                std::copy_n(&f.cones[size_t(reps[o]) * kNumCones], kNumCones,
                            &h->cones[o * kNumCones]);
        });
}

int UpsampledPlanes(const ScreenSpaceDenoiser::State& s, const ScreenSpaceDenoiser::State& half) {
    int n = 0;
    for (int ci = 0; ci < 3; ++ci)
        if (s.comp[ci].present && half.comp[ci].res[0]) n += s.comp[ci].nc;
    return n;
}

void UpsampleRow(const ScreenSpaceDenoiser::State& s, const ScreenSpaceDenoiser::State& half, int y,
                 const float* const* own, float* const* out) {
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
    a.nx = g.nx.Row(y), a.ny = g.ny.Row(y), a.nz = g.nz.Row(y);
    a.z = g.depth.Row(y), a.invDz = g.invDz.Row(y), a.id = g.objectId.Row(y);
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
