// SPDX-License-Identifier: Apache-2.0
// What the frame loop (render.cpp) shares with the stages it runs over the tiles of a pass: the
// camera samples of a tile (their rays, made and traced in blocks, and the random streams that
// continue after them), the frame's per-pixel sums, and the stages themselves:
//   integrators/camera_shading.cpp        each camera sample shaded where it hits (ShadeTile);
//   integrators/ao_two_phase.cpp          AO as camera rays first, then AO rays (AoTileTwoPhase);
//   texture_space/visibility_prepass.cpp  the texels the camera samples see, marked before
//                                         a texture-space pass shades (MarkVisibleTexels);
//   texture_space/hit_binning.cpp         shading at the camera's hits, added to bins (phase 1);
//   texture_space/bin_reconstruction.cpp  the bins read back at each hit (phase 2).
// The helpers every stage calls once per camera sample are inline or templates here, so that
// each stage's loop keeps them inlined. Internal to renderer/.
#pragma once
#include <algorithm>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <tbb/blocked_range2d.h>

#include "renderer/image/image.h"
#include "renderer/render.h"
#include "renderer/texture_space/cached_shading.h"

namespace texcache::internal {

/// What a pixel's camera samples add to its AOV layers (AovLayers takes their means).
struct PixelAovs {
    glm::vec3 albedo{0.0f}, normal{0.0f}, ptex{0.0f};
    float depth = 0.0f;
    glm::vec2 motion{0.0f};
    int hits = 0;
};

/// The mean of `hitSamples` estimates `li(rng, h)` from one camera hit: the first (h = 0)
/// continues the camera sample's own random stream (so hitSamples = 1 is the plain path tracer),
/// the others get streams of their own; h is also the path's point in the pass's PixelSequence.
template <typename LiFn>
glm::vec3 SplitAtHit(const Context& c, int x, int y, int s, Rng& rng, LiFn&& li) {
    const int n = std::max(c.opt.hitSamples, 1);
    glm::vec3 sum = li(rng, 0);
    if (n == 1) return sum;  // the common case: no division on every camera sample
    for (int h = 1; h < n; ++h) {
        Rng split(MixBits(PixelSeed(c.opt.seed, x, y, c.opt.width) ^ (uint64_t(h) << 40)),
                  uint64_t(s));
        sum += li(split, h);
    }
    return sum / float(n);
}

/// The camera ray of pixel sample (x, y, s); `rng` continues the sample's random stream after it.
/// Every pass that traces a sample (the visibility prepass, the shading pass) gets the same ray.
inline void CameraRay(const Context& c, int x, int y, int s, Rng* rng, Ray* ray,
                      RayDifferentials* diff) {
    *rng = Rng(PixelSeed(c.opt.seed, x, y, c.opt.width), uint64_t(s));
    glm::vec2 jitter = rng->Next2D();
    if (c.opt.pixelCentre) jitter = glm::vec2(0.5f);  // drawn anyway: same streams either way
    const glm::vec2 lens = rng->Next2D();
    const float time = c.shutterLength > 0.0f ? rng->Next1D() : 0.0f;
    c.camera.Generate(float(x) + jitter.x, float(y) + jitter.y, lens, ray, diff);
    if (c.cameraMoves) {
        // Camera motion blur: blend the rays of the open and close poses (rigid, short shutter).
        const Ray r1 =
            c.cameraClose->Generate(float(x) + jitter.x, float(y) + jitter.y, lens, nullptr);
        ray->org = glm::mix(ray->org, r1.org, time);
        ray->dir = glm::normalize(glm::mix(ray->dir, r1.dir, time));
    }
    ray->time = time;
}

/// A camera sample between its ray and its shading: the ray, its closest hit and the random
/// stream that continues after the ray's numbers.
struct CameraSample {
    Ray ray;
    Hit hit;
    Rng rng{0, 0};
    RayDifferentials diff;
    bool found = false;
};

/// Traces the camera rays of samples[0, n) (anything with .ray, .hit, .found) 16 at a time:
/// rays of neighbouring pixels share most of their BVH nodes (RenderScene::Intersect16). With
/// `culled` (their tile lies outside Context::hitRect) every ray misses and none is traced.
template <typename CameraSampleT>
void IntersectCameraRays(const Context& c, CameraSampleT* samples, size_t n, RayCounts& rays,
                         bool culled = false) {
    if (culled) {
        for (size_t i = 0; i < n; ++i) samples[i].found = false;
        rays.cameraCulled += n;
        return;
    }
    Ray packet[16];
    Hit hits[16];
    bool found[16];
    for (size_t i = 0; i < n; i += 16) {
        const int m = int(std::min<size_t>(16, n - i));
        for (int j = 0; j < m; ++j) packet[j] = samples[i + j].ray;
        c.rs.Intersect16(packet, m, hits, found);
        for (int j = 0; j < m; ++j) samples[i + j].hit = hits[j], samples[i + j].found = found[j];
    }
    rays.camera += n;
}

/// (x, y, s) of a tile's samples [s0, s1) in the single-ray loop's order: pixels row by row,
/// each pixel's samples in turn, stepped rather than divided out of a flat index (three integer
/// divisions per sample cost more than the shading of a sky sample).
struct Cursor {
    int x, y, s;
    Cursor(const tbb::blocked_range2d<int>& r, int s0)
        : x(r.cols().begin()), y(r.rows().begin()), s(s0) {}
    void Next(const tbb::blocked_range2d<int>& r, int s0, int s1) {
        if (++s < s1) return;
        s = s0;
        if (++x < r.cols().end()) return;
        x = r.cols().begin();
        ++y;
    }
};

/// Camera samples are traced in blocks of this many consecutive (pixel, sample) pairs, 16 rays
/// at a time (IntersectCameraRays).
constexpr size_t kCameraBlock = 64;

/// The surface interactions of camera samples [0, n) that hit an object, into `points` (with
/// the samples' ray differentials when `differentials`), in a loop of their own: what a caller
/// computes from an interaction (a texel key, a bin, AO ray directions) then reads it from
/// memory the call wrote long before. Read right after the call returned it, its fields came
/// through store forwarding from the call's last stores and the reads waited on them (a
/// visible part of a warm texture-space frame and of hit-binned AO; results/bench_cache.md).
template <typename CameraSampleT>
void InteractAll(const Context& c, const CameraSampleT* samples, size_t n,
                 SurfaceInteraction* points, bool differentials = false) {
    for (size_t i = 0; i < n; ++i) {
        const CameraSampleT& p = samples[i];
        if (p.found && p.hit.object >= 0)
            points[i] = c.rs.Interact(p.ray, p.hit, differentials ? &p.diff : nullptr);
    }
}

/// CameraRay for the n <= kCameraBlock samples from `gen` on (advancing it), for a pinhole
/// camera that does not move, without differentials: the same rays and random streams bit for
/// bit, with the directions made together (CameraModel::GeneratePinhole).
template <typename Sample>
void PinholeCameraRays(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                       Cursor& gen, Sample* block, size_t n) {
    // Zeroed: GCC's sanitizer builds cannot tell that GeneratePinhole reads only the first n.
    float px[kCameraBlock] = {}, py[kCameraBlock] = {}, time[kCameraBlock];
    uint64_t seed = 0;
    for (size_t i = 0; i < n; ++i, gen.Next(r, s0, s1)) {
        if (i == 0 || gen.s == s0) seed = PixelSeed(c.opt.seed, gen.x, gen.y, c.opt.width);
        Rng& rng = block[i].rng;
        rng = Rng(seed, uint64_t(gen.s));
        glm::vec2 jitter = rng.Next2D();
        if (c.opt.pixelCentre) jitter = glm::vec2(0.5f);
        rng.Next2D();  // the lens sample, drawn as CameraRay draws it: the streams agree
        time[i] = c.shutterLength > 0.0f ? rng.Next1D() : 0.0f;
        px[i] = float(gen.x) + jitter.x, py[i] = float(gen.y) + jitter.y;
    }
    c.camera.GeneratePinhole(px, py, n, [&](size_t i) -> Ray& { return block[i].ray; });
    for (size_t i = 0; i < n; ++i) block[i].ray.time = time[i];
}

/// The AO rays of many hits, traced 16 at a time across hits (full packets: 4 rays of one hit
/// fill a quarter of one), and the rays that escape counted per hit.
struct AoRayBatch {
    std::vector<Ray> rays;
    std::vector<uint32_t> owner;  // the hit of each ray

    void Clear() { rays.clear(), owner.clear(); }
    /// Queues hit `hit`'s AO rays (ForEachAoRay: its points of the pass's sequence from `first`).
    void Queue(const Context& c, const Ray& ray, const SurfaceInteraction& si,
               const PixelSequence& seq, uint64_t first, uint32_t hit) {
        ForEachAoRay(c, ray, si, seq, first, [&]() -> Ray& {
            owner.push_back(hit);
            return rays.emplace_back();
        });
    }
    /// Traces the queued rays; open[hit] += the hit's rays that escape.
    void Trace(const Context& c, uint32_t* open, RayCounts& counts) const {
        bool blocked[16];
        for (size_t i = 0; i < rays.size(); i += 16) {
            const int m = int(std::min<size_t>(16, rays.size() - i));
            c.rs.Occluded16(&rays[i], m, blocked);
            for (int k = 0; k < m; ++k) open[owner[i + size_t(k)]] += !blocked[k];
        }
        counts.shadow += rays.size();
    }
};

/// The texel each camera sample of a pass lands on, as the visibility prepass found it, for a
/// shading pass that needs nothing else of its camera samples (texture-space AO): that pass
/// then looks the texels up without tracing the camera rays and evaluating their hits again,
/// which would make a warm-cache frame cost about twice a frame without lookups (`texcache
/// bench cache` times both). sizeof(PassTexel) (24 bytes) per camera sample of the pass, in storage
/// the texture space cache keeps between renders.
///
/// The prepass adds a pixel's samples to the frame itself while they need no lookup (a sky, a
/// light, a texel it found cached), up to the first that does: `added` counts them per pixel,
/// and the shading pass adds the rest, in order, so each pixel's sum is the same as if one
/// pass had added them all. In a warm frame it then has nearly nothing left to read.
struct PassTexels {
    static constexpr int32_t kMiss = -1;   ///< in `mesh`: the ray left the scene
    static constexpr int32_t kLight = -2;  ///< in `mesh`: the ray hit a light
    static constexpr int32_t kFound = -3;  ///< in `mesh`: the prepass found the texel cached
    static constexpr size_t kBytesPerSample = sizeof(PassTexel);
    PassTexel* at = nullptr;
    uint32_t* added = nullptr;  ///< per pixel (y * width + x)
    double* sum = nullptr;      ///< the frame's sums, 3 per pixel
    /// Per image row: whether the prepass left any of its samples to the shading pass, which
    /// then skips the others (a warm frame leaves a handful of rows, and reading every pixel's
    /// `added` again was a visible part of its cost). Zero at the start of the pass.
    std::atomic<uint8_t>* rowLeft = nullptr;
    int width = 0, s0 = 0, s1 = 0;
    /// Nothing to find: the pass began by emptying the cache, or it holds no texels yet.
    bool cacheEmptied = false;

    PassTexel& operator[](size_t k) const { return at[k]; }
    size_t Index(int x, int y, int s) const {
        return (size_t(y) * size_t(width) + size_t(x)) * size_t(s1 - s0) + size_t(s - s0);
    }
};

/// A frame's per-pixel sums while its passes run.
struct FrameSums {
    std::vector<double> rgb;      // 3 per pixel
    std::vector<PixelAovs> aovs;  // empty unless AOVs were asked for
    // Hit binning: 4 per pixel, the sum of its samples' own per-hit estimates (RGB) and of the
    // squared luminance of each one's own estimate minus its reconstruction (see
    // CombineWithOwnSamples); empty unless shading at the hits.
    std::vector<double> own;
    uint64_t hitBinsDropped = 0;  // see RenderStats
    size_t hitBinBytes = 0;
    int passes = 0;
};

// The stages of a pass, each over one tile `r` (rows x columns of pixels) and samples [s0, s1)
// of its pixels. Their design notes are at their definitions.

/// Each camera sample shaded where it hits (the integrator's Li), added to `sums` pixel by pixel;
/// `pixelStats`: the thread's cache counters, read around each pixel for its heat-map counts.
void ShadeTile(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
               FrameSums& sums, CacheStats* pixelStats, RayCounts& rays);

/// AO of rows [y0, y1) x columns [x0, x1): every camera ray first, then the AO rays of every hit
/// (or the texture-space lookups), added to the frame's sums `sum`.
void AoTileTwoPhase(const Context& c, int y0, int y1, int x0, int x1, int s0, int s1,
                    std::vector<double>& sum, RayCounts& rays);

/// The visibility prepass: marks in `visible` the texel each camera sample lands on, and keeps
/// them in `out` if given (looking up those already cached).
void MarkVisibleTexels(const Context& c, VisibleTexels& visible, const tbb::blocked_range2d<int>& r,
                       int s0, int s1, PassTexels* out, RayCounts& rays);

/// Texture-space AO from the texels the tile's prepass kept, without tracing its camera rays.
void AoTileFromPrepass(const Context& c, const tbb::blocked_range2d<int>& r, const PassTexels& pt,
                       RayCounts& rays);

/// Hit-binned AO, phase 1: AO at each camera hit, added to its bins `bias` and `bias` + 1 levels
/// above its texel; `records` keep where each camera sample hit, `ownAo` its own AO estimate.
void AoHitsBin(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1, int bias,
               HitRecord* records, float* ownAo, HitBins& bins, RayCounts& rays);

/// Hit-binned diffuse light, phase 1: each camera sample path traced, the light of its diffuse
/// hit kept in `binnedHits` for binning, the rest summed per pixel into `perHit`, and each
/// pixel's noise into `noise`.
void PathHitsTrace(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                   HitRecord* records, BinnedHit* binnedHits, glm::dvec3* perHit, glm::dvec2* noise,
                   RayCounts& rays);

/// Hit binning under a material's filter (the note at the top of texture_space.h): how many
/// levels above a hit's texel the bins of an object with filter `kind` and pass radius `radius`
/// lie, or -1 for the schedule's (the normal filter, and softshadow, which the bins cannot
/// serve). Gaussian and regression: bins of side 2^L in (r / 4, r / 2] texels, so that the
/// window of radius r is 2-4 bins either side.
inline int HitFilterLevels(TextureFilterKind kind, int radius) {
    switch (kind) {
        case TextureFilterKind::None:
            return 0;
        case TextureFilterKind::Gaussian:
        case TextureFilterKind::Regression:
            return radius < 4 ? 0 : std::bit_width(unsigned(radius)) - 2;
        default:
            return -1;
    }
}

/// The frame buffers' store's bins of an object whose material sets filter `kind` (pass
/// radius `radius`): HitFilterLevels', but for the trivial filter the schedule's two levels
/// (-1), read bilinearly. The store gets one path for every frameBufferBudget pixels a frame, so
/// a bin at the hit's own texel (about a pixel and a half on the car) holds one or two paths,
/// and each pixel would read a single path's noise back.
inline int StoreFilterLevels(TextureFilterKind kind, int radius) {
    return kind == TextureFilterKind::None ? -1 : HitFilterLevels(kind, radius);
}

/// Hit-binned diffuse light, phase 1 continued: the traced hits added to their bins (with
/// `frameStore`, the frame buffers' store's: StoreFilterLevels).
void PathHitsAdd(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1, int bias,
                 float blend, HitRecord* records, const BinnedHit* binnedHits, RadianceBins& bins,
                 bool frameStore = false);

/// What BoundStoreHits did to a frame's traced hits: how many there were, how many it bounded,
/// and the share of their summed luminance it kept.
struct StoreHitBounds {
    uint64_t traced = 0, bounded = 0;
    double keptLight = 1.0;
};
/// The frame buffers' traced hits (records[p], binned[p].light finite) bounded before they are
/// added to the store (BoundBrightHits, texture_space.h), each against the other traced hits of
/// its mesh around it and its prior (binned[p].prior: what the store, as the earlier frames left
/// it, held at its record). Its arrays are the cache's (TextureSpaceCache::BoundScratch).
StoreHitBounds BoundStoreHits(const Context& c, const HitRecord* records, float ratio,
                              BinnedHit* binned);
/// BoundBrightHits (texture_space.h) with its arrays in `scratch`.
size_t BoundBrightHits(int width, int height, glm::vec3* light, const int32_t* group,
                       const float* prior, float ratio, StoreBoundScratch& scratch);

/// A frame-buffer pixel's camera hit `si` at distance `t` as hit binning records it: its record
/// (`h`, reading the finer of its bins at `bias` levels above its texel until PathHitsAdd sets
/// the level it reads) and its texel's level (`texelLevel`, for BinnedHit).
void FrameHitRecord(const Context& c, const SurfaceInteraction& si, float t, int bias, HitRecord* h,
                    int* texelLevel);
/// The samples (in HitUnit counts) behind the store's bilinear reconstruction at record `h`'s
/// level: what a frame reads to tell whether the store holds enough there already.
double StoreCountAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h);
/// The store's diffuse light at record `h` (irradiance / pi): hit binning's reconstruction at
/// the level its record names, by the calling thread's memo of the store's generation.
glm::vec3 StoreLightAt(const TextureSpaceCache& tsc, const LightHitStore& store,
                       const HitRecord& h);

/// Starts loading the store's bin at record `h` (a hint for StoreCountAt / StoreLightAt: the
/// table is far larger than the caches, and a lookup stalls on memory).
void PrefetchStoreAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h);

/// Stochastic reads of the store: one bin, the one holding record `h`'s point moved by `jitter`
/// bins (each component in [-0.5, 0.5)), instead of the 2x2 bins around it. With a uniform
/// jitter a bin is read with its bilinear weight, so that over frames (a new jitter each) the
/// reads average to the bilinear reconstruction, at one lookup a read instead of four (a bin
/// past the face's edge is its neighbour's, through the Ptex adjacency, as there). A bin that holds
/// fewer than `enough` samples (HitUnit counts, at least one) falls back to the bilinear
/// reconstruction (StoreCountAt, StoreLightAt above): one bin's path or two would be noise that the
/// stage's edge stopping takes the brightest out of. So does an object whose material sets a filter
/// (its light is the filter's). The samples behind the read, its light in `light`:
double StoreCountAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                    glm::vec2 jitter, double enough, glm::vec3* light);
/// The read's light.
glm::vec3 StoreLightAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                       glm::vec2 jitter, double enough);
/// PrefetchStoreAt for the stochastic reads' bin.
void PrefetchStoreAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                     glm::vec2 jitter);
/// The store's diffuse light over the block of 4x4 bins that holds record `h`'s bin at its level
/// (the mean of their samples, in `light`; 0 without any) and the samples behind it (in HitUnit
/// counts): one lookup for light that is smooth across a block (a ray's hit, StoreTerm).
double StoreBlockAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                    glm::vec3* light);

/// Hit-binned AO, phase 2: each camera sample's reconstruction from the store, added to `sum`,
/// and its own estimate (`ownAo`) with its difference to the reconstruction added to `own`
/// (FrameSums::own).
void AoHitsResolve(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                   const HitRecord* records, const float* ownAo, const AoHitStore& store,
                   double* sum, double* own);

/// Hit-binned diffuse light, phase 2: each pixel's per-hit part plus albedo x the bins'
/// reconstruction at each binned camera sample, added to `sum`; the per-hit part plus albedo x
/// each sample's own light, with its difference to the reconstruction, added to `own`
/// (FrameSums::own).
void PathHitsResolve(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                     const HitRecord* records, const BinnedHit* binnedHits,
                     const glm::dvec3* perHit, const LightHitStore& store, double relativeVariance,
                     double* sum, double* own);

/// The requested AOV layers of a frame of W x H pixels: means over the `spp` samples of each.
std::vector<ImageLayer> AovLayers(const std::vector<PixelAovs>& aovs, const AovFlags& flags, int W,
                                  int H, int spp);

}  // namespace texcache::internal
