// SPDX-License-Identifier: Apache-2.0
// Texture-space shading in the path tracer: the samples the cache shades (ambient occlusion,
// diffuse light, area-light visibility, each at a point of the limit surface) and the cached term
// at a camera hit, looked up through TextureSpaceCache. Internal to renderer/.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>

#include "renderer/integrators/path_tracer.h"
#include "renderer/texture_space/texture_space.h"

namespace texcache::internal {

/// The counters of a thread's CacheStats that a pixel's heat-map counts are the change of.
struct CacheSnapshot {
    uint64_t lookups = 0, texelHits = 0, samplesShaded = 0;
    CacheSnapshot() = default;
    explicit CacheSnapshot(const CacheStats& s)
        : lookups(s.lookups), texelHits(s.texelHits), samplesShaded(s.samplesShaded) {}
};

/// Adds what a pixel's lookups counted (the thread's stats after them minus `before`) to its
/// counts. Exact because the lookups run on one thread whose CacheStats nothing else touches
/// meanwhile: shading only traces rays, and Embree's queries spawn no TBB tasks that could run
/// another tile on this thread in between.
inline void AddPixelCounts(PixelCacheCounts* px, const CacheSnapshot& before,
                           const CacheStats& after) {
    px->lookups += uint32_t(after.lookups - before.lookups);
    px->texelHits += uint32_t(after.texelHits - before.texelHits);
    px->samplesShaded += uint32_t(after.samplesShaded - before.samplesShaded);
}

/// Ambient occlusion at a cache sample: the fraction of opt.aoSamples cosine-distributed rays
/// from its point that escape (up to opt.aoDistance).
ShadedSample ShadeAoSample(const Context& c, const SampleRequest& r, RayCounts& rays);

/// Diffuse light at a cache sample, as (1/pi) * integral of L cos (the hit multiplies it by its
/// albedo). Indirect: cosine-sampled paths, whose first ray does not count emission (light
/// seen directly is NEE's). With `direct`, each of the n iterations also takes one NEE sample
/// (light sampling, shadow ray): (1/pi) Le V cos / pdf; otherwise direct light stays NEE's job
/// at the hit. `paths`: n, or opt.texture.indirectSamples when < 1.
ShadedSample ShadeDiffuseSample(const Context& c, const SampleRequest& r, bool direct,
                                RayCounts& rays, int paths = 0);

/// One estimate of diffuse light (1/pi integral of L cos) from the cosine-sampled ray `ray`
/// leaving a point of normal `N`: the light its path brings back, whose first hit's emission
/// is not counted (NEE's) unless `direct`, which adds one light sample with its shadow ray and
/// that emission. What a cache sample's rays (ShadeDiffuseSample) and a camera hit's diffuse
/// ray for the frame buffers' store each estimate; `cached` may end the path at its first hit
/// with a cached term there (LiPath). Not checked for NaN or infinity.
template <typename Cached = NoCachedTerm>
glm::vec3 DiffuseRayLight(const Context& c, const Ray& ray, glm::vec3 N, bool direct, Rng& rng,
                          RayCounts& rays, const Cached& cached = Cached()) {
    glm::vec3 Ld(0.0f);
    LightSample ls;
    if (direct && c.SampleLight(ray.org, N, rng.Next1D(), rng.Next2D(), &ls)) {
        const float cosi = glm::dot(ls.wi, N);
        if (cosi > 0.0f) {
            Ray shadow;
            shadow.org = ray.org;
            shadow.dir = ls.wi;
            shadow.tfar = std::isinf(ls.dist) ? INFINITY : ls.dist * (1.0f - 1e-4f);
            ++rays.shadow;
            if (!c.rs.Occluded(shadow))
                Ld = ls.Li * (ls.delta ? cosi : cosi / ls.pdf) * (1.0f / kPiF);
        }
    }
    ++rays.bounce;
    Hit hit;
    const bool found = c.rs.Intersect(ray, &hit);
    // Emitting surfaces are not sampled as lights: with the direct part cached, the first ray
    // is what finds them (a cosine-weighted estimate of their light, 1/pi integral of Le cos).
    if (direct && found) Ld += c.SurfaceEmission(hit);
    return Ld +
           LiPath(c, ray, hit, found, rng, std::max(c.opt.maxDepth - 1, 0), rays, false, cached);
}

/// Visibility of the scene's area lights from a cache sample (Mehta et al.'s soft-shadow input):
/// the fraction of shadow rays towards uniform points on the quad lights that reach them, and the
/// smallest blur std sigma_l * t / (d - t) the blocked rays allow (see soft_shadow_filter.h).
ShadedSample ShadeShadowSample(const Context& c, const SampleRequest& r, RayCounts& rays);

/// Visibility of all the scene's lights from a cache sample (the screen-space frame buffers'
/// cachedVisibility): shadowed over unshadowed irradiance, the ratio sum c_k V_k / sum c_k of
/// opt.texture.shadowSamples light samples (c_k their cosine-weighted irradiance luminance,
/// V_k the 0/1 of their shadow rays), in every channel; 1 when no light reaches the sample's
/// hemisphere. View-independent: the diffuse lobe's visibility.
ShadedSample ShadeVisibilitySample(const Context& c, const SampleRequest& r, RayCounts& rays);

/// Direct lighting with area-light visibility from the texture-space cache (the soft-shadow
/// filter). Per hit, each quad light's unshadowed light is estimated from `shadowSamples` points
/// on it (no rays: the cheap, low-noise part) and multiplied by the texel's filtered visibility;
/// other lights (environment, distant) get one NEE sample with its shadow ray. No MIS with BSDF
/// sampling: a BSDF ray that finds the light would bring back unfiltered visibility. Objects whose
/// material uses another filter get the plain per-hit estimator.
glm::vec3 LiDirectCachedShadows(const Context& c, const Ray& ray, const Hit& hit, bool found,
                                Rng& rng, const RayDifferentials& diff, RayCounts& rays);

/// The cached term at a camera hit: the texel-cache lookup of `si`'s texel (or of `texel`,
/// already chosen with TextureSpaceCache::TexelOf) with its material's filter; a constant when
/// opt.texture.constantTerm is set (the benchmark baseline). `raysPerSample` is the number of
/// rays behind each cached sample (the regression's n); callers with many lookups pass their
/// thread's `stats` in (enumerable_thread_specific::local() hashes the thread id).
template <typename ShadeFn>
glm::vec3 CachedLookup(const Context& c, const SurfaceInteraction& si, ShadeFn&& shade,
                       int raysPerSample, CacheStats* stats = nullptr,
                       const SampleRequest* texel = nullptr) {
    if (c.opt.texture.constantTerm >= 0.0f) return glm::vec3(c.opt.texture.constantTerm);
    const SampleRequest h = texel ? *texel : c.tsc->TexelOf(si);
    CacheStats& st = stats ? *stats : c.cacheStats->local();
    return c.tsc->Lookup(h, si.object, shade, raysPerSample, st);
}

/// The texture-space cache of one frame, when it shades anything: the caller's or one made for
/// this frame, attached to the frame's Context. With a visibility prepass (Render's), footprints
/// keep the visible texels only (opt.texture.footprint) for as long as the frame renders,
/// whatever way it ends.
class FrameCache {
public:
    enum class Prepass { Allowed, None };
    FrameCache(Context& ctx, const RenderOptions& opt, TextureSpaceCache* cache, Prepass prepass) {
        const IntegratorKind k = opt.integrator;
        const bool cached =
            k == IntegratorKind::AO || k == IntegratorKind::Path || k == IntegratorKind::Direct;
        if (!opt.texture.enabled || !cached) return;
        if (!cache) {
            own_ = std::make_unique<TextureSpaceCache>(ctx.rs, opt.texture);
            cache = own_.get();
        }
        ctx.tsc = cache_ = cache;
        ctx.cacheStats = &stats_;
        // Footprints of visible texels only: the prepass of each pass marks them. Shading at
        // the hits has no footprints (hit_binning.cpp: AoHitsBin, PathHitsTrace; a render with AOVs
        // shades on the grid).
        const bool hits = ShadesAtHits(opt);
        // The grid is looked up by renders that do not shade at the hits, and by the frame
        // buffers (the ones without a prepass) when it caches their diffuse light or their
        // lights' visibility; with the store (TextureSamples::Hits) they read neither.
        const bool frameGrid =
            opt.texture.frameBufferSamples == TextureSamples::Grid || opt.texture.cachedVisibility;
        if (prepass == Prepass::None ? frameGrid : !hits) cache->PrepareGrid();
        if (prepass == Prepass::Allowed && !hits && VisibleOnly(opt.texture.footprint, k) &&
            opt.texture.constantTerm < 0.0f && cache->AnyFootprint()) {
            visible_ = &cache->Visibility(opt.width, opt.height,
                                          opt.visibilityPrepass == VisibilityPrepass::Own);
            cache->RestrictFootprints(visible_);
        }
    }
    ~FrameCache() {
        if (visible_) cache_->RestrictFootprints(nullptr);
    }
    FrameCache(const FrameCache&) = delete;
    FrameCache& operator=(const FrameCache&) = delete;

    /// The set the visibility prepass marks, or null when footprints are not restricted.
    VisibleTexels* Visible() const { return visible_; }
    tbb::enumerable_thread_specific<CacheStats>& Stats() { return stats_; }

private:
    std::unique_ptr<TextureSpaceCache> own_;
    TextureSpaceCache* cache_ = nullptr;
    VisibleTexels* visible_ = nullptr;
    tbb::enumerable_thread_specific<CacheStats> stats_;
};

}  // namespace texcache::internal
