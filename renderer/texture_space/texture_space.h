// SPDX-License-Identifier: Apache-2.0
// The renderer's use of libtexcache: one cache mesh per scene object (shading depends on where
// the object is), samples of ShadedSample, texels of filtered RGB.
//
// Progressive texture space (why the cache keeps converging). The paper shades each cached
// sample once, so a larger budget only buys camera rays: the shading noise the filter leaves
// and the filter's bias stay, and the error stalls (docs/texture-space.md, "Progressive passes").
// Here a render of more than options.passSpp camera samples
// runs passes of passSpp samples (the renderer's RunPasses) and every pass k > 0 begins with
// BeginPass(k):
//   * every sample and texel is evicted and shaded again from random streams of (key, k), so
//     the passes are independent estimates and the image, their mean, loses variance as 1/K;
//   * a sample of pass k > 0 sits at a uniform point of its texel instead of the centre, so the
//     mean over passes is the texel's mean shading (the centre's value is biased by the shading's
//     curvature over the texel);
//   * footprints shrink as r_k = round(r_0 (k + 1)^(-1/6)). A filter of radius r averages a
//     smooth signal with a bias of O(r^2) and divides the noise variance by O(r^2) taps, so over
//     K passes bias^2 ~ r^4 ~ K^(-2/3) and variance ~ 1 / (K r^2) ~ K^(-2/3): both vanish, at
//     the rate that balances them (progressive photon mapping's radius reduction, alpha = 2/3).
//
// Hit binning (TextureSamples::Hits) takes the same route with bins for footprints, in one pass
// (below): it shades every camera hit as per-hit shading would (AO rays; or, for the path
// integrator, the light a diffuse hit receives, its albedo applied after) and adds the result to
// the bins of its point at two levels above its texel's (HitBinLevels); each camera sample then
// reads the 2x2 bins around it at each level, bilinearly, and combines the two (below). Bins of
// side h average a smooth signal with a bias of O(h^2) and hold O(h^2 n) rays for n rays per pixel,
// so with h ~ n^(-k): bias^2 ~ n^(-4k) and variance ~ n^(2k-1), and both vanish for any 0 < k < 1/2
// (k = 1/6 balances them asymptotically). We take k = 1/3 from 2.5 levels at 4 rays per pixel: at
// the budgets speed-vs-error measures the bias of the coarser bins dominates sooner than the
// asymptotic rate assumes (docs/texture-space.md, "Hit bins", has the figures). AO's noise is
// about the same on any scene (a ray escapes or not); a path's estimate of diffuse light is not:
// its variance for its mean ranges over 100x from a clay object under a white sky to a glossy
// car under a courtyard map, and the best level with it. A fixed level tuned on the scenes/
// cases leaves a clay object under a white sky (OpenSubdiv's bishop) near per hit's error,
// where two levels finer give several times less. So a pass of diffuse light first shades
// every hit, measures V, the variance of the binned light among each pixel's camera samples over
// their mean squared (summed over the pixels), and bins at 3.6 + log2(V) / 4 - log2(n / 4) / 3
// levels (HitLightLevels; n = camera samples per pixel so far; V already falls with the paths per
// hit). A slope of 1/5 or 1/3 instead of 1/4 changes little. The direct integrator's light keeps
// AO's levels: its best level does not follow V (chess soft shadows and the bishop are both best
// near 2.5-3 levels up).
//
// Combining the two levels. The schedule's level b is fractional; the bins lie floor(b) and
// floor(b) + 1 levels up. Reading one of the two at random (the coarser with probability
// frac(b)) would blend them whatever the data say. Instead a sample reads both and moves from
// the finer estimate f towards the coarser c by alpha (the renderer's Reconstruct):
// f + alpha (c - f). A fine bin holds about a quarter of its coarse bin's samples, so with s^2
// f's variance, Var(c) ~ cov(f, c) ~ s^2 / 4, and for a coarse bias B = E[c - f] the MSE of
// f + alpha (c - f) is s^2 - 1.5 alpha s^2 + alpha^2 (0.75 s^2 + B^2), least at
// alpha = 0.75 s^2 / E[(c - f)^2]. With the observed (c - f)^2 for its expectation, alpha =
// min(1, k s^2 / (c - f)^2) (CoarseWeight): the coarse bins where the levels agree within the
// noise (a flat region), the fine ones where they do not (a crease, a contact shadow's edge).
// AO's s^2 is binomial from the bins' counts, k = 3/4. The light's comes from the pass's V (one
// relative variance for the whole image, which underestimates it where the light changes
// fastest): k = 4, best among 0.3-8 (all of 2-8 beat the random pick). The bins' level is then
// floor(b) (half a level finer on average than the random pick; floor(b) + 1/2 loses on every
// case). The combination beats the random pick on every case of speed-vs-error and the bishop
// (docs/texture-space.md, "Combining the two levels"). alpha stays in [0, 1], so the estimate
// lies between two consistent ones and stays consistent. Picking one level per sample from six
// (the intersection of confidence intervals, variances from the bins' second moments) loses to
// the schedule on the torus tests: a hard choice among many noisy levels, where this one
// shrinks between two neighbours.
//
// The pixels' own samples, the finest level. The bins' bias vanishes only until they reach
// level 0 (texels of texelFraction of the object's size), where it stays, and per hit, unbiased,
// would overtake them at a large budget. So the hierarchy goes on below level 0 with each
// pixel's own per-hit estimates, which the binning phase computes anyway: every pixel sums its
// samples' own estimates O beside their reconstructions R, and the squared luminance of each
// sample's O - R. At the end (CombineWithOwnSamples) it takes O + alpha (R - O) with alpha =
// min(1, k Var / d^2) (CoarseWeight again): d the mean difference, Var its variance. With R
// biased by B and O unbiased, the MSE is least at alpha = Var / (Var + B^2) = Var / E[d^2].
// Var comes from the per-sample differences rather than the own samples' spread, because the
// camera's noise (antialiasing, the lens) is in both and cancels in d. Var and d^2 are summed
// over a 5x5 window, so that a dark or few-sample pixel does not trust an own mean that happens
// to lie close, and k = 16 / n (within [1, 8]) leans to the bins while those sums are noisy and
// the own mean's variance, what a wrong weight costs, is large (OwnWeightK). One sample a pixel
// measures no Var: the image is the bins'. alpha in [0, 1]
// keeps the estimate between a consistent and an unbiased one, and as the budget grows alpha
// falls wherever the bias shows, so the error falls at per hit's rate.
//
// One pass. Binning shades nothing on the grids, so passes would buy it nothing and cost its
// stratification: a pass's first bounces are a net of its own (PixelSequence), and passes of 4
// samples would leave a pixel 16 nets of 4 instead of one of 64. A render without a time budget
// bins all its samples in one pass (split only where their records would pass 256 MiB); with a
// budget, passes start at one sample and grow to what is left, as per hit's do. The bins' level
// follows all the samples so far. The bins hold integer counts, whose sums do not depend on the
// order of the adds (see texcache/hit_bins.h), and each pixel sums its own samples in order, so
// the image is the same for any thread count.
//
// A material's filter on the bins. The schedule and the two-level combination above are the
// normal filter's, which every object without a "filter" key gets. An object whose material
// sets another filter bins its hits at a level of its own and reads them through that filter
// (bin_reconstruction.cpp, FilteredReconstruct): none bins at the hit's texel and reads the
// hit's bin alone; gaussian and regression bin at a level whose bins are between a quarter and
// half the radius wide, so that the window of radius r texels is a few bins wide, and filter
// the bins around each bin centre (Gaussian weights of sigma r / 2 texels times the counts, or
// a count-weighted plane fit), which the sample reads bilinearly. The radius shrinks with the
// passes as the grid's footprints do. The bins and the filtered bin centres are the two levels
// of one store (texcache/texture_store.h, AoStore and LightStore): the sample level the hits
// fill, the texel level the filters fill once for every thread. Softshadow needs occluder distances
// the bins do not hold: the command line refuses it here (CheckMaterialFilters).
//
// The passes are deterministic (streams of key and pass, whatever thread shades a sample), so
// the same seed still gives the same image for any thread count. Temporal accumulation
// (--temporal-alpha) accumulates over frames instead and keeps one pass per frame.
//
// Temporal accumulation at the hits. The store is not emptied between frames: its sums and
// counts are scaled by alpha (eq. 6's weight of the history, in 1/65536) and the frame's hits
// added, an exponential moving average of the bins kept in the objects' own texture space, so
// that it follows rigidly moving objects as the grid's history does. The scaling is integer
// (texcache/hit_bins.h, Scale), so the image stays the same for any thread count; each hit adds
// HitUnit() = 256 units of count so that rounding a decayed count costs a fraction of a percent
// instead of half a count. The bins' level is chosen once, at the first frame, for the
// 1 / (1 - alpha) frames of samples the bins hold (a level that moved would orphan the history).
#pragma once
#include <algorithm>
#include <climits>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include <glm/glm.hpp>

#include "filters/regression_filter.h"
#include "filters/soft_shadow_filter.h"
#include "filters/texture_filters.h"
#include "renderer/render_options.h"
#include "renderer/scene/render_scene.h"
#include "texcache/hit_bins.h"
#include "texcache/huge_pages.h"
#include "texcache/shading_cache.h"
#include "texcache/temporal_history.h"
#include "texcache/texture_store.h"
#include "texcache/visible_texels.h"

namespace texcache {

using RenderShadingCache = ShadingCache<ShadedSample, glm::vec3>;

/// Bounding box of a cage's control points (object space).
void CageBounds(const ControlCage& cage, glm::vec3* lo, glm::vec3* hi);
/// Mip-0 texel size of the shading grids of a cage of bounds [lo, hi]: `texelFraction` of the
/// box's diagonal (TextureSpaceOptions::texelFraction; eq. 1 then picks the level whose texels
/// are about a pixel).
float MipZeroTexelSize(glm::vec3 lo, glm::vec3 hi, float texelFraction = 1.0f / 4096.0f);

/// The frame buffers' bound on a hit's light (BoundBrightHits): at most this many times the
/// reference luminance around it.
inline constexpr float kStoreBoundRatio = 16.0f;
/// BoundBrightHits' window (radius in pixels) and the fewest other hits in it that make a
/// reference.
inline constexpr int kStoreBoundRadius = 4;
inline constexpr int kStoreBoundMinOthers = 3;
/// Bounds the bright outliers among one frame's traced hits before they are added to a store
/// whose bins many pixels read for many frames (a path that finds a highlight or the sun would
/// otherwise reach all of them), and spreads what it takes off over the hit's neighbours, so that
/// the frame's light is kept. Per pixel of a width x height frame: `light` (RGB) of its traced hit
/// (NaN, infinite or negative: none, left as it is), `group` (hits are compared within a group: a
/// mesh), `prior` (a reference luminance from earlier frames, 0: none; may be null). A hit's
/// reference is the median luminance of the other hits of its group within kStoreBoundRadius
/// pixels (their mean where the median is 0; none below kStoreBoundMinOthers of them) or its
/// prior, whichever is larger; a hit above ratio x its reference is scaled down to that and the
/// rest is shared equally by those other hits. Where there is no reference, unchanged. Returns
/// how many hits it bounded. The same for any thread count.
size_t BoundBrightHits(int width, int height, glm::vec3* light, const int32_t* group,
                       const float* prior, float ratio);

/// A shading cache for a scene: lives as long as its owner wants (e.g. across frames). The one
/// door between the renderer and libtexcache: it picks each hit's texel and each object's
/// filter, and blends texels over frames; nothing else touches the ShadingCache inside.
namespace internal {
/// A camera sample of a pass as the visibility prepass saw it (see render_internal.h's PassTexels).
struct PassTexel {
    uint64_t key;     ///< TexelKey::Pack()
    int32_t mesh;     ///< the texel's cache mesh, or a PassTexels marker (< 0)
    glm::vec3 found;  ///< the texel's value, when the prepass found it cached
};
/// A camera sample of a pass of hit-binned AO (hit_binning.cpp, AoHitsBin): where it hit, for the
/// reconstruction that reads the bins around it. 12 bytes: a pass's records are written once and
/// read once, and 1920x1080 at 4 spp holds 8.3M of them.
struct HitRecord {
    static constexpr float kUvScale = 65536.0f;
    uint16_t u, v;       ///< the hit's face (u,v) in 1/65536 (the finest bins are 1/16384)
    int32_t mesh;        ///< its cache mesh, or a PassTexels marker (< 0)
    uint32_t faceLevel;  ///< the mesh's local Ptex face << 4 | the level its reconstruction reads
    int Face() const { return int(faceLevel >> 4); }
    int Level() const { return int(faceLevel & 15u); }
    float U() const { return (float(u) + 0.5f) / kUvScale; }
    float V() const { return (float(v) + 0.5f) / kUvScale; }
    static uint16_t Quantize(float x) {
        if (!(x > 0.0f)) return 0;  // NaN too
        return uint16_t(std::min(x * kUvScale, kUvScale - 1.0f));
    }
};
/// A binned diffuse hit of a pass of hit-binned light (hit_binning.cpp, PathHitsTrace): the light
/// it bins, the albedo its reconstruction is multiplied by, and the level of its texel (its bins
/// lie levels above it, chosen once the pass's noise is known).
struct BinnedHit {
    glm::vec3 light, albedo;
    int32_t texelLevel;
    /// The frame buffers' traced hits: the luminance the store held at the hit before the frame
    /// (0: too few samples), BoundStoreHits' reference; read while shading, where the hit's bins
    /// are in the caches already.
    float prior = 0.0f;
};
/// BoundStoreHits' frame-sized arrays, kept with the cache from frame to frame: a frame's bound
/// allocates nothing (fresh pages were a visible share of its time).
struct StoreBoundScratch {
    std::vector<glm::vec3> light, share;
    std::vector<float> prior, luminance;
    std::vector<int32_t> group;
    size_t Bytes() const {
        return (light.capacity() + share.capacity()) * sizeof(glm::vec3) +
               (prior.capacity() + luminance.capacity()) * sizeof(float) +
               group.capacity() * sizeof(int32_t);
    }
};
/// A material filter's value at a bin centre (bin_reconstruction.cpp, FilterAt): `weight` is the
/// count behind it, 0 where its window holds no bin. The texel level of the hit stores.
struct FilteredValue {
    glm::vec3 value{0.0f};
    float weight = 0.0f;
};
/// Hit binning's reconstruction (the note at the top): how far a sample's estimate moves from
/// its bins' level towards the level above, given the two estimates' (luminance) difference `d`
/// and the finer one's variance `fineVariance`: alpha = min(1, k fineVariance / d^2), 1 when
/// they agree exactly or the variance is not a number. Always in [0, 1], so the estimate stays
/// between the two levels'.
inline double CoarseWeight(double d, double fineVariance, double k) {
    const double d2 = d * d;
    const double v = k * fineVariance;
    if (!(v >= 0.0)) return 1.0;  // NaN or negative: no evidence either way
    return d2 > v ? v / d2 : 1.0;
}
/// k of CoarseWeight for AO, whose fine variance is binomial from the bins' counts: 3/4, the
/// MSE-optimal weight for a finer bin holding a quarter of the coarser one's samples (note at
/// the top).
constexpr double kAoCoarseWeightK = 0.75;
/// k for binned light (the path and direct integrators), whose fine variance comes from the
/// pass's mean relative variance V:
/// best near 4 (2-8 all beat the fixed blend; note at the top).
constexpr double kLightCoarseWeightK = 4.0;

/// k of CoarseWeight for the step from the bins to the pixels' own samples at `n` samples a
/// pixel (CombineWithOwnSamples): 16 / n within [1, 8]. The MSE-optimal weight is
/// Var(mean difference) / E[d^2], k = 1 for exact estimates; at few samples the window's
/// estimates are noisy and a weight wrongly given to the own mean costs its variance, ~1/n: k
/// leans to the bins in proportion.
inline double OwnWeightK(int n) {
    return std::clamp(16.0 / double(std::max(n, 1)), 1.0, 8.0);
}
/// The window over which CombineWithOwnSamples sums its estimates: (2R + 1)^2 pixels, so that a
/// dark or few-sample pixel does not trust an own mean that happens to agree with itself.
constexpr int kOwnWindowRadius = 2;
/// CombineWithOwnSamples' per-pixel arrays, kept by its caller from render to render.
struct CombineScratch {
    std::vector<double> var, d2, tmp;
    std::vector<uint8_t> odd;
};
/// Hit binning's finest level, each pixel's own samples (the note at the top): for rows [y0, y1)
/// of a frame `width` pixels wide, each pixel's mean of its `n` reconstructed samples (`rgb`, 3
/// sums a pixel) moved towards the mean of their own per-hit estimates (`own`, 4 a pixel: 3
/// sums, and the sum of the squared luminance of own minus reconstruction, sample by sample) by
/// 1 - CoarseWeight of their difference and of the variance of its mean, both summed over a
/// window; written to `out` (3 a pixel). Writes nothing for n < 2 (no spread to weigh: `out`
/// keeps the reconstruction) and the reconstruction where the result is not finite.
/// `scratch`: its arrays (null: its own).
void CombineWithOwnSamples(const double* rgb, const double* own, int width, int y0, int y1, int n,
                           float* out, CombineScratch* scratch = nullptr);

/// A frame-buffer pixel's own diffuse light over the frames of a still view (the frame buffers'
/// store, frame_buffers_render.h): the mean of its traced paths' light, the sum of the squared
/// deviations of their luminance from it (Welford's update, stable; in double: a bright path's
/// square overflows a float) and their count; beside it the frame's read-back of the store there
/// and the two terms BlendWithOwnLight weighs it by (scratch, rewritten every frame). 48 bytes a
/// pixel.
struct PixelOwnLight {
    double m2 = 0.0;
    glm::vec3 mean{0.0f};
    uint32_t n = 0;
    glm::vec3 bin{0.0f};  ///< the store's reconstruction this frame
    float var = 0.0f;     ///< the variance of the own mean (luminance); 0: no own estimate
    float d2 = 0.0f;      ///< the squared luminance difference of the own mean and `bin`
};
/// Adds one traced path's light to a pixel's own samples; NaN or infinite light is dropped.
void AddOwnLight(PixelOwnLight& px, glm::vec3 light);
/// Sets `px.bin` to the store's reconstruction `bin` and the pixel's var and d2 from its own
/// samples (both 0 with fewer than two: no spread to weigh).
void PrepareOwnLight(PixelOwnLight& px, glm::vec3 bin);
/// The frame buffers' store's finest level, as CombineWithOwnSamples is hit binning's: pixel
/// (x, y)'s read-back of the store moved towards the mean of its own samples by 1 - CoarseWeight
/// of their difference and of the own mean's variance, both summed over the window around it
/// (`px` a width x height frame after PrepareOwnLight); the read-back where that is not finite.
glm::vec3 BlendWithOwnLight(const PixelOwnLight* px, int width, int height, int x, int y);

/// What a render at the hits keeps from render to render (render.cpp): the visibility prepass's
/// record of a pass for its shading pass (the renderer's PassTexels), and the per-pixel and
/// per-sample arrays of hit binning. A warm frame (an animation's, an experiment's next budget)
/// then writes pages it has, where fresh arrays would be faulted in and zeroed by the kernel
/// again each render.
struct PassScratch {
    std::vector<PassTexel> texels;       ///< per camera sample of the pass
    std::vector<uint32_t> added;         ///< per pixel: its first samples the prepass added itself
    std::vector<glm::dvec3> perHit;      ///< per pixel: hit-binned light's per-hit part of a pass
    std::vector<glm::dvec2> pixelNoise;  ///< per pixel: its binned light's noise (PathHitsTrace)
    std::vector<float> ownAo;            ///< per camera sample: hit-binned AO's own estimate
    std::vector<double> own[2];          ///< each eye's FrameSums::own, lent to a render
    CombineScratch combine;              ///< CombineWithOwnSamples' arrays
    size_t Bytes() const {
        size_t n = texels.capacity() * sizeof(PassTexel) + added.capacity() * sizeof(uint32_t) +
                   perHit.capacity() * sizeof(glm::dvec3) +
                   pixelNoise.capacity() * sizeof(glm::dvec2) + ownAo.capacity() * sizeof(float) +
                   combine.odd.capacity();
        for (const std::vector<double>* v :
             {&own[0], &own[1], &combine.var, &combine.d2, &combine.tmp})
            n += v->capacity() * sizeof(double);
        return n;
    }
};
}  // namespace internal

/// The one texture-space store of hit shading (texcache/texture_store.h): AO's counts, or the
/// path and direct integrators' diffuse light, at the sample level; the material filters' values
/// at bin centres at the texel level.
using AoHitStore = TextureStore<CountBin, internal::FilteredValue>;
using LightHitStore = TextureStore<RadianceBin, internal::FilteredValue>;

class TextureSpaceCache {
public:
    /// Registers every object of the scene; throws InputError on impossible settings. The grid
    /// cache's storage (and the temporal history of its texels) is allocated by PrepareGrid, so
    /// that a render shading at its camera hits spends no memory on the grid it never uses.
    TextureSpaceCache(const RenderScene& rs, const TextureSpaceOptions& options);
    /// Allocates the grid cache's storage and texel history if not yet: every renderer that
    /// looks up texels on the grid calls it before its threads start (Lookup needs it).
    void PrepareGrid();
    /// Whether PrepareGrid ran.
    bool GridPrepared() const { return cache_.Allocated(); }

    const TextureSpaceOptions& options() const { return options_; }

    /// The texel a shading point maps to (eq. 1 and 2) in its object's front or back grids.
    SampleRequest TexelOf(const SurfaceInteraction& si) const {
        return cache_.TexelAt({MeshOf(si.object, si.backFacing), si.ptex.face, si.ptex.u, si.ptex.v,
                               si.dudx, si.dvdx, si.dudy, si.dvdy});
    }
    /// The texel of a shading point in its object's visibility grids (options.cachedVisibility:
    /// a second set of grids per object, so that the cached visibility and the cached light of
    /// one texel are different keys of the one cache).
    SampleRequest VisibilityTexelOf(const SurfaceInteraction& si) const {
        const size_t o = size_t(si.object);
        const int mesh =
            si.backFacing && visBackMeshOf_[o] >= 0 ? visBackMeshOf_[o] : visMeshOf_[o];
        return cache_.TexelAt(
            {mesh, si.ptex.face, si.ptex.u, si.ptex.v, si.dudx, si.dvdx, si.dudy, si.dvdy});
    }
    /// TexelOf's key alone (no texel centre), and its cache mesh in `mesh`.
    TexelKey TexelKeyOf(const SurfaceInteraction& si, int* mesh) const {
        *mesh = MeshOf(si.object, si.backFacing);
        return cache_.TexelKeyAt(
            {*mesh, si.ptex.face, si.ptex.u, si.ptex.v, si.dudx, si.dvdx, si.dudy, si.dvdy});
    }
    /// A texel's packed key and slot hash, for Prefetch and FindTexel.
    TexelAddress AddressOf(const TexelKey& key) const { return cache_.AddressOf(key); }
    /// TexelOf's result for a texel key of cache mesh `mesh` (see ShadingCache::RequestOf).
    SampleRequest RequestOf(int mesh, const TexelKey& key) const {
        return cache_.RequestOf(mesh, key);
    }
    /// Starts fetching a texel's slot into the CPU cache (see ShadingCache::Prefetch): for a
    /// batch of texels before their lookups.
    void Prefetch(const SampleRequest& texel) const { cache_.Prefetch(texel); }
    void Prefetch(const TexelAddress& texel) const { cache_.Prefetch(texel); }
    void PrefetchOtherSlots(const TexelAddress& texel) const { cache_.PrefetchOtherSlots(texel); }
    /// The texel's value when the texel cache holds it right now: read-only (never shades,
    /// claims or counts), and the value a Lookup hit would return.
    bool FindTexel(const SampleRequest& texel, glm::vec3* value) const {
        return cache_.FindTexel(texel, value);
    }
    bool FindTexel(const TexelAddress& texel, glm::vec3* value) const {
        return cache_.FindTexel(texel, value);
    }

    /// The cached term of scene object `object` at `texel` (from TexelOf): a texel-cache hit,
    /// or on a miss the object's filter over its footprint, with the missing samples shaded by
    /// `shade(const SampleRequest&) -> ShadedSample` and the result blended into the texel's
    /// temporal history. `raysPerSample` is the number of rays behind each sample (the
    /// regression's n). Inlined: no virtual call or allocation per lookup.
    template <typename ShadeFn>
    glm::vec3 Lookup(const SampleRequest& texel, int object, ShadeFn&& shade, int raysPerSample,
                     CacheStats& stats);

    /// Texels a side of a sample's face grid at its level.
    int Resolution(const SampleRequest& r) const { return cache_.Mesh(r.mesh).Res(r.face, r.mip); }
    /// Footprints keep only the texels of `visible` until the next call (null: every texel);
    /// see ShadingCache::RestrictFootprints. Never while lookups run.
    void RestrictFootprints(const VisibleTexels* visible) { cache_.RestrictFootprints(visible); }
    /// Stereo's second eye (renderer/texture_space/stereo.h): while on, a lookup whose texel is not
    /// cached takes the mean of the cached texels among its 8 neighbours (same face and level)
    /// before filtering anew; such a lookup counts as a texel hit. Never while lookups run.
    void ReuseNeighbourTexels(bool on) { neighbourReuse_ = on; }
    /// Evicts every sample and texel (not the temporal history): the next lookups shade anew.
    /// Every way of emptying the caches (BeginFrame, a new pass, Reconfigure) comes here.
    void Invalidate() {
        cache_.InvalidateAll();
        mayHoldTexels_ = false;
    }
    /// False when no lookups ran since the caches were last emptied: a renderer may then skip
    /// asking for texels it knows cannot be there (the visibility prepass of a first pass would
    /// otherwise probe the empty texel table once per camera sample). Renderers call
    /// NoteLookups() after lookups; forgetting it only costs those probes.
    bool MayHoldTexels() const { return mayHoldTexels_; }
    void NoteLookups() { mayHoldTexels_ = true; }

    /// Starts pass `pass` of a progressive render (see the note at the top): evicts every
    /// sample and texel unless `pass` is the current one, and sets the filter radii of the pass.
    void BeginPass(uint32_t pass);
    /// Back to pass 0 (its footprints, its random streams) for a new accumulation, keeping
    /// what is cached: each sample and texel is an estimate of its own, whichever pass shaded
    /// it. The preview calls it when the view moves after a still view re-shaded the cache for
    /// many passes: the moving view would otherwise keep the last pass's shrunken footprints.
    void RestartPasses() { BeginPassRadii(0); }
    /// The current pass: 0 for a new cache, after Reconfigure and after BeginFrame.
    uint32_t Pass() const { return pass_; }
    /// Whether renders through this cache run progressive passes (options.passSpp > 0, no
    /// temporal accumulation).
    bool Progressive() const { return options_.passSpp > 0 && options_.temporalAlpha == 0.0f; }
    /// The footprint radius of pass `pass` for a material radius `radius`:
    /// round(radius (pass + 1)^(-1/6)), the schedule the note at the top argues for.
    static int PassRadius(int radius, uint32_t pass);
    /// What hit binning bins: AO rays or direct light (one visibility ray per sample: the
    /// direct integrator's light takes AO's levels), or a path tracer's diffuse light.
    enum class HitTerm { Ao, Light };
    /// Hit binning (TextureSamples::Hits): how many levels above a hit's texel its bins lie,
    /// for `raysPerHit` AO rays or light paths per hit, `passSpp` camera samples a pass and pass
    /// `pass`: c - log2(n / 4) / 3 for n = raysPerHit * passSpp * (pass + 1) rays per pixel (see
    /// the note at the top), c = 2.5 for AO (and the direct integrator's light) and 3.5 for
    /// diffuse light whose noise was not measured (HitLightLevels). For an offset b the bins
    /// lie floor(b) and floor(b) + 1 levels above the texel's, and a sample combines the two by
    /// their noise (the note at the top); light whose noise was not measured reads one of them,
    /// the coarser with probability frac(b).
    static float HitBinLevels(int raysPerHit, int passSpp, uint32_t pass,
                              HitTerm term = HitTerm::Ao);
    /// The same for a path tracer's diffuse light, from the pass's noise: `noiseVar` / `noiseMean2`
    /// is the relative variance of one camera sample's binned light (the variance among each
    /// pixel's samples over their mean squared, summed over the pixels); see the note at the top.
    /// Without a measure (fewer than two binned samples a pixel) HitBinLevels(HitTerm::Light).
    static float HitLightLevels(double noiseVar, double noiseMean2, int pathsPerHit, int passSpp,
                                uint32_t pass);
    /// Cache mesh id of a scene object's front side, or of its back side (open surfaces are
    /// seen from both sides and shade differently on each; closed ones have no back mesh).
    int MeshOf(int object, bool backFacing = false) const {
        return backFacing && backMeshOf_[object] >= 0 ? backMeshOf_[object] : meshOf_[object];
    }
    /// The object a cache mesh belongs to, and whether it is that object's back side.
    int ObjectOfMesh(int mesh) const { return meshObject_[mesh]; }
    bool IsBackMesh(int mesh) const { return meshIsBack_[mesh]; }
    /// Whether a cache mesh's samples lie on the side opposite to the limit normal
    /// cross(dPdu, dPdv): the back side of an open surface, or the outside of a closed one whose
    /// limit normals point inward in world space (a cage wound inward, or a mirroring transform).
    bool SamplesAgainstNormal(int mesh) const { return meshAgainstNormal_[mesh]; }
    /// The filter of an object's material (its override, else the render's default).
    TextureFilterKind FilterOf(int object) const { return filterOf_[object]; }
    /// Footprint radius of an object's material (its override, else the render's default), as
    /// of pass 0.
    int RadiusOf(int object) const { return radiusOf_[object]; }
    /// RadiusOf shrunk for the current pass (PassRadius).
    int PassRadiusOf(int object) const { return passRadiusOf_[object]; }
    /// Whether any object uses a filter (e.g. to skip what only that filter needs).
    bool Uses(TextureFilterKind kind) const;
    /// Whether any object's filter reads more than its centre texel.
    bool AnyFootprint() const;
    /// The visibility set for a render of width x height pixels, empty: about two words per
    /// pixel (see visible_texels.h), between 32 KB and 16 MB; kept from render to
    /// render and only reallocated when the size changes. With `clear` false, the marks of the
    /// previous render of this size are kept (stereo: both eyes mark one set).
    VisibleTexels& Visibility(int width, int height, bool clear = true);
    /// What the visibility prepass found for each camera sample of a pass (render.cpp), kept
    /// here from render to render like the visibility set: a warm frame then reuses its pages
    /// instead of faulting in 24 bytes per camera sample again. Empty until a render uses it.
    internal::PassScratch& PassTexelScratch() { return passTexels_; }
    /// Hit-binned AO's store: a sample level of at least `minBlocks` blocks, kept from pass to
    /// pass and render to render (it only grows), its texel level sized to it (StoreTexelBytes).
    AoHitStore& AoStore(size_t minBlocks) { return StoreOf(aoStore_, minBlocks); }
    /// Hit-binned diffuse light's store (the path and direct integrators), kept as AoStore's.
    LightHitStore& LightStore(size_t minBlocks) { return StoreOf(lightStore_, minBlocks); }
    /// The light store as it is, or null before the first LightStore.
    LightHitStore* LightStoreIfAny() { return lightStore_.get(); }
    /// Temporal accumulation at the hits (--temporal-alpha with TextureSamples::Hits; the note
    /// at the top): each hit adds HitUnit() units of count, so that the decay of the stores'
    /// sums between frames (alpha in fixed point) rounds a few counts by a fraction of a percent
    /// rather than by half a count; 1 without temporal accumulation.
    uint32_t HitUnit() const { return options_.temporalAlpha > 0.0f ? 256u : 1u; }
    /// The frame whose hits the stores hold, for temporal accumulation (-1: none, or stale).
    int64_t HitStoreFrame() const { return hitStoreFrame_; }
    void SetHitStoreFrame(int64_t frame) { hitStoreFrame_ = frame; }
    /// The bins' level offset temporal accumulation keeps from its first frame (INT_MIN: not
    /// chosen): a level that moved between frames would leave the history at the old one.
    int& TemporalHitBias() { return temporalHitBias_; }
    /// At least `n` records on huge pages (uninitialised; kept from render to render).
    internal::HitRecord* HitRecords(size_t n) {
        if (n > hitRecordCount_) {
            hitRecords_.reset(static_cast<internal::HitRecord*>(
                AllocateHugePages(n * sizeof(internal::HitRecord))));
            hitRecordCount_ = n;
        }
        return hitRecords_.get();
    }
    /// At least `n` binned diffuse hits' light and albedo, beside their records (as HitRecords).
    internal::BinnedHit* BinnedHits(size_t n) {
        if (n > hitAlbedoCount_) {
            hitAlbedos_.reset(AllocateHugePages(n * sizeof(internal::BinnedHit)));
            hitAlbedoCount_ = n;
        }
        return static_cast<internal::BinnedHit*>(hitAlbedos_.get());
    }
    /// Each pixel's own diffuse light over a still view of a width x height frame (the frame
    /// buffers' store): null while the view moves (the last Refresh said so), and then released;
    /// while it is still, kept from frame to frame, and empty again after a move, a resize, a new
    /// frame of an animation (BeginFrame) or an edit (InvalidateObject).
    internal::PixelOwnLight* StillOwnLight(int width, int height);
    /// BoundStoreHits' arrays (kept as HitRecords).
    internal::StoreBoundScratch& BoundScratch() { return boundScratch_; }
    /// The grids of a cache mesh (resolutions, Ptex adjacency).
    const MeshGrids& Grids(int mesh) const { return cache_.Mesh(mesh); }
    /// Ptex faces of all cache meshes.
    size_t NumFaces() const {
        size_t n = 0;
        for (int m = 0; m < cache_.NumMeshes(); ++m) n += size_t(cache_.Mesh(m).NumFaces());
        return n;
    }

    /// Takes new options and starts empty, keeping the cache storage when its layout is the same
    /// (sizes, LOD bias, texel size; no temporal history): a renderer comparing settings then
    /// clears 2 x 64 MB instead of having the kernel map and zero them again for every render
    /// (mapping and zeroing costs more CPU than the shading of a 480x270 render, such as those
    /// of `texcache experiment speed-vs-error`). Returns false, and changes nothing, when the
    /// storage does not match: build a new cache then.
    bool Reconfigure(const RenderScene& rs, const TextureSpaceOptions& options);

    /// Starts a frame of an animation: shading changes when objects move, so samples and texels
    /// are re-shaded, while the temporal history (if any) carries over.
    void BeginFrame(uint32_t frame);
    uint32_t Frame() const { return frame_; }
    /// Frame-to-frame reuse (the preview; docs/texture-space.md, "The cache from frame to
    /// frame"): starts frame `frame` keeping what is cached, and evicts one part in `parts` of the
    /// samples and texels (by key hash, the part refreshed longest ago), which the next lookups
    /// shade anew from streams of (key, frame) and blend into their temporal history: eq. 6 while
    /// the view moves, a running mean while it is `still` (so a still view converges). Texels
    /// never shaded are shaded on their first lookup, before any refresh. Between frames.
    void Refresh(uint32_t frame, uint32_t parts, bool still);
    /// Forgets everything cached for scene object `object`, on each of its grids: samples,
    /// texels and temporal history, and its bins in the hit stores (the object moved, or its
    /// material changed what its cached term holds). Between frames.
    void InvalidateObject(int object);
    /// What the frame buffers' store keeps of its sums at the next frame, in 1/65536 (the
    /// store's Decay), when one pixel in `budget` adds to it a frame: all of them while the last
    /// Refresh said the view is still, or while nothing in the scene moves (`sceneMoves` false:
    /// no object or light has moved since the last frame): a running mean, which converges. The
    /// store holds diffuse light, which does not depend on the view, so while only the camera
    /// moves every sample it holds stays an estimate of the light now, and forgetting it would
    /// only bring its noise back (and cost a pass over the table a frame). While something moves,
    /// eq. 6's weight temporalAlpha per pixel's sample, 1 - (1 - alpha) / budget a frame, so that
    /// a bin holds 1 / (1 - alpha) of its pixels' samples as the grid's texels hold that many
    /// frames and the shadows and bounce light of what moved fade from the bins that keep them.
    /// None without temporal accumulation.
    uint32_t FrameStoreKeep(int budget, bool sceneMoves) const {
        if (storeStill_) return 1u << 16;
        const double alpha = std::clamp(double(options_.temporalAlpha), 0.0, 1.0);
        if (!(alpha > 0.0)) return 0;
        if (!sceneMoves) return 1u << 16;
        return uint32_t(
            std::lround((1.0 - (1.0 - alpha) / double(std::max(budget, 1))) * double(1u << 16)));
    }
    /// This frame's filtered value of a texel blended into its history (eq. 6); `value` as is
    /// when temporal accumulation is off.
    glm::vec3 Accumulate(const TexelKey& key, glm::vec3 value) {
        return history_ ? history_->Blend(key, frame_, value) : value;
    }
    /// Bytes of all cache storage (sample and texel caches, temporal history, visibility set).
    size_t BytesUsed() const {
        return cache_.BytesUsed() + (history_ ? history_->BytesUsed() : 0) +
               (visible_ ? visible_->Bytes() : 0) + passTexels_.Bytes() +
               (aoStore_ ? aoStore_->BytesUsed() : 0) +
               (lightStore_ ? lightStore_->BytesUsed() : 0) +
               hitRecordCount_ * sizeof(internal::HitRecord) +
               hitAlbedoCount_ * sizeof(internal::BinnedHit) +
               ownLight_.capacity() * sizeof(internal::PixelOwnLight) + boundScratch_.Bytes();
    }
    size_t SampleCacheBytes() const { return cache_.SampleCacheBytes(); }
    size_t TexelCacheBytes() const { return cache_.TexelCacheBytes(); }
    size_t SampleSlots() const { return cache_.SampleSlots(); }

private:
    void AssignFilters(const Scene& scene);
    /// A store's texel level for a sample level of `blocks` blocks: a texel for one bin in four
    /// when an object's material filters its bins (FilterAt's values), else a token one.
    size_t StoreTexelBytes(size_t blocks) const;
    template <typename Store>
    Store& StoreOf(std::unique_ptr<Store>& store, size_t minBlocks) {
        // A texel level too small for the filters of the current settings (Reconfigure) would
        // be correct but filter its texels again and again: a new store then too.
        const size_t texelBytes = StoreTexelBytes(Store::SampleLevel::BlocksFor(minBlocks));
        if (!store || store->Samples().NumBlocks() < minBlocks ||
            store->TexelBytes() + Store::kTexelBytes <= texelBytes)
            store = std::make_unique<Store>(minBlocks, texelBytes);
        return *store;
    }
    /// Sets the pass and its filter radii (BeginPass without the eviction).
    void BeginPassRadii(uint32_t pass);
    /// The mean of the cached texels among the 8 around `texel` on its face and level; false
    /// when none is cached (see ReuseNeighbourTexels).
    bool FindNeighbourTexel(const SampleRequest& texel, glm::vec3* value) const;

    TextureSpaceOptions options_;
    RenderShadingCache cache_;
    std::vector<int> meshOf_, backMeshOf_;
    std::vector<int> visMeshOf_, visBackMeshOf_;  ///< visibility grids (empty unless cached)
    int firstVisMesh_ = INT_MAX;                  ///< cache meshes from here on are those
    std::vector<int> meshObject_;
    std::vector<char> meshIsBack_, meshAgainstNormal_;
    std::vector<TextureFilterKind> filterOf_;
    std::vector<int> radiusOf_;
    std::vector<int> passRadiusOf_;  ///< radiusOf_ shrunk for the current pass
    std::unique_ptr<TemporalHistory<glm::vec3>> history_;
    std::unique_ptr<VisibleTexels> visible_;
    internal::PassScratch passTexels_;
    std::unique_ptr<AoHitStore> aoStore_;
    struct Free {
        void operator()(void* p) const { std::free(p); }
    };
    std::unique_ptr<internal::HitRecord[], Free> hitRecords_;
    size_t hitRecordCount_ = 0;
    std::unique_ptr<LightHitStore> lightStore_;
    std::unique_ptr<void, Free> hitAlbedos_;
    size_t hitAlbedoCount_ = 0;
    std::vector<internal::PixelOwnLight> ownLight_;  ///< see StillOwnLight
    int ownWidth_ = 0, ownHeight_ = 0;
    bool ownStale_ = true;  ///< ownLight_ holds another view's samples
    internal::StoreBoundScratch boundScratch_;
    uint32_t frame_ = 0;
    uint32_t pass_ = 0;
    int64_t hitStoreFrame_ = -1;
    int temporalHitBias_ = INT_MIN;
    bool mayHoldTexels_ = false;  ///< see MayHoldTexels
    bool storeStill_ = false;     ///< see FrameStoreKeep
    bool neighbourReuse_ = false;
};

namespace internal {
/// A texture filter whose results pass through the temporal blend; it offers the block (tile)
/// form of ShadingCache::LookupTexel exactly when the filter does and `Blocks` is true (false:
/// a miss filters its own texel alone).
template <typename Filter, bool Blocks = true>
struct Accumulating {
    TextureSpaceCache* cache;
    const Filter& filter;

    glm::vec3 operator()(const FilterInput<ShadedSample>& in) const {
        return cache->Accumulate(in.request.key, filter(in));
    }
    glm::vec3 operator()(const SampleTile<ShadedSample>& t, int cx, int cy, int radius,
                         const SampleRequest& texel) const
        requires(Blocks&& requires { filter(t, cx, cy, radius, texel); }) {
        return cache->Accumulate(texel.key, filter(t, cx, cy, radius, texel));
    }
    auto Prepare(const SampleTile<ShadedSample>& t, int radius) const
        requires(Blocks&& requires { filter.Prepare(t, radius); }) {
        return
            [c = cache, p = filter.Prepare(t, radius)](int cx, int cy, const SampleRequest& texel) {
                return c->Accumulate(texel.key, p(cx, cy, texel));
            };
    }
};

}  // namespace internal

template <typename ShadeFn>
glm::vec3 TextureSpaceCache::Lookup(const SampleRequest& texel, int object, ShadeFn&& shade,
                                    int raysPerSample, CacheStats& stats) {
    // One branch per lookup picks the material's filter; the filters themselves are inlined. The
    // temporal blend runs once per reconstructed texel, not per lookup.
    if (!cache_.Allocated()) [[unlikely]]
        throw std::logic_error("texture-space lookup on a grid cache without PrepareGrid()");
    auto lookup = [&]<typename Filter>(int radius, const Filter& filter,
                                       FootprintTaps taps = FootprintTaps::VisibleSymmetric) {
        // Stereo's second eye (ReuseNeighbourTexels) filters a missed texel alone: its misses are
        // mostly served by neighbours, and reconstructing the blocks around its few true misses
        // would shade their samples too (on car AO about half as many new samples again).
        if (neighbourReuse_)
            return cache_.LookupTexel(texel, radius, shade,
                                      internal::Accumulating<Filter, false>{this, filter}, stats,
                                      taps);
        return cache_.LookupTexel(texel, radius, shade,
                                  internal::Accumulating<Filter>{this, filter}, stats, taps);
    };
    if (neighbourReuse_) {
        // A cached texel is read as is (a hit); a missing one tries its neighbours first.
        glm::vec3 v;
        if (cache_.FindTexel(texel, &v) || FindNeighbourTexel(texel, &v)) {
            ++stats.lookups, ++stats.texelHits;
            return v;
        }
    }
    const float cosThreshold = options_.cosThreshold;
    const int radius = texel.mesh >= firstVisMesh_ && options_.visibilityRadius >= 0
                           ? options_.visibilityRadius
                           : passRadiusOf_[object];
    switch (filterOf_[object]) {
        case TextureFilterKind::None:
            return lookup(0, CentreFilter{});
        case TextureFilterKind::Gaussian:
            // The paper's 20x20 Gaussian: sigma half the radius, same normal test.
            return lookup(radius, NormalWeightedFilter{cosThreshold, 0.5f * float(radius)});
        case TextureFilterKind::Regression:
            // A linear model fits the gradient a one-sided window sees: no symmetry needed.
            return lookup(radius, RegressionFilter{raysPerSample, false}, FootprintTaps::Visible);
        case TextureFilterKind::SoftShadow:
            return lookup(radius, SoftShadowFilter{cosThreshold});
        case TextureFilterKind::Normal:
            break;
    }
    return lookup(radius, NormalWeightedFilter{cosThreshold, 0.0f});
}

}  // namespace texcache
