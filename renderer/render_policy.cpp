// SPDX-License-Identifier: Apache-2.0
#include "renderer/render_policy.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <new>
#include <utility>

#include "texcache/enum_names.h"
#include "texcache/error.h"

namespace texcache {

namespace {
constexpr EnumName<CachedLight> kCachedLights[] = {
    {"auto", CachedLight::Auto}, {"all", CachedLight::All}, {"indirect", CachedLight::Indirect}};
}  // namespace

float AnimationFrameTime(float start, int frame, float fps) {
    return start + float(frame) / fps;
}

uint64_t FrameSeed(uint64_t seed, uint64_t frame) {
    return seed + frame * 0x9E3779B9ull;
}

std::unique_ptr<TextureSpaceCache> MakeTextureSpaceCache(const RenderScene& rs,
                                                         const TextureSpaceOptions& t,
                                                         const std::string& where) {
    try {
        return std::make_unique<TextureSpaceCache>(rs, t);
    } catch (const std::bad_alloc&) {
        throw InputError(where, "cannot allocate the texture-space caches (" +
                                    std::to_string(t.cache.sampleCacheBytes >> 20) + " + " +
                                    std::to_string(t.cache.texelCacheBytes >> 20) + " MiB)");
    }
}

AnimationFrames::AnimationFrames(const texcache::Scene& scene,
                                 const RenderSceneOptions& sceneOptions,
                                 const RenderOptions& options, float fps, std::string cacheWhere)
    : scene_(scene),
      sceneOptions_(sceneOptions),
      base_(options),
      fps_(fps),
      cacheWhere_(std::move(cacheWhere)),
      options_(options) {}

void AnimationFrames::Pose(int frame) {
    sceneOptions_.frameTime = AnimationFrameTime(base_.frameTime, frame, fps_);
    rs_.emplace(scene_, sceneOptions_);
    if (base_.texture.enabled && !cache_)
        cache_ = MakeTextureSpaceCache(*rs_, base_.texture, cacheWhere_);
    if (cache_) cache_->BeginFrame(uint32_t(frame));
    options_ = base_;
    options_.frameTime = sceneOptions_.frameTime;
    options_.seed = FrameSeed(base_.seed, uint64_t(frame));
}

void SizeTextureCaches(RenderOptions* opt, int views, GivenCacheSizes given,
                       const std::string& where) {
    TextureSpaceOptions& t = opt->texture;
    if (!t.enabled || t.cache.referenceMode) return;
    CacheSettings fit = t.cache;
    // Cached visibility keeps a second term per texel under keys of its own (texture_space.h).
    const int terms = t.cachedVisibility ? 2 : 1;
    SizeCachesToFrame(&fit, opt->width, opt->height, views * terms, opt->integrator, t.footprint);
    if (!given.sample) t.cache.sampleCacheBytes = fit.sampleCacheBytes;
    if (!given.texel) t.cache.texelCacheBytes = fit.texelCacheBytes;
    const double mib = 1.0 / double(1 << 20);
    const double sample = double(t.cache.sampleCacheBytes) * mib,
                 texel = double(t.cache.texelCacheBytes) * mib, have = PhysicalMemoryMiB();
    if (sample + texel > have)
        throw InputError(where, "the caches (" + std::to_string(llround(sample)) + " + " +
                                    std::to_string(llround(texel)) +
                                    " MiB) do not fit in this machine's " +
                                    std::to_string(llround(have)) + " MiB of memory");
}

double PhysicalMemoryMiB() {
    return double(::sysconf(_SC_PHYS_PAGES)) * double(::sysconf(_SC_PAGESIZE)) / (1 << 20);
}

namespace {
double AvailableMemoryMiB() {
    std::ifstream in("/proc/meminfo");
    std::string key;
    double kib = 0.0;
    std::string unit;
    while (in >> key >> kib >> unit)
        if (key == "MemAvailable:") return kib / 1024.0;
    return PhysicalMemoryMiB();
}

double CacheMiB(const RenderOptions& opt, bool frameBuffers) {
    double bytes = 0.0;
    // Shading at the hits never allocates the grid caches (TextureSpaceCache::PrepareGrid); the
    // frame buffers look their diffuse light up there unless they read the store, and their
    // lights' visibility when they cache it.
    const bool frameGrid =
        opt.texture.frameBufferSamples == TextureSamples::Grid || opt.texture.cachedVisibility;
    const bool grid = frameBuffers ? frameGrid : !ShadesAtHits(opt);
    if (opt.texture.enabled && !opt.texture.cache.referenceMode && grid)
        bytes +=
            double(opt.texture.cache.sampleCacheBytes) + double(opt.texture.cache.texelCacheBytes);
    if (opt.lightSampling == LightSampling::Cpis) bytes += double(opt.psrCacheBytes);
    return bytes / double(1 << 20);
}

/// What shading at the hits holds besides the film: a record per camera sample of a pass (about
/// 40 bytes for diffuse light, 12 for AO, measured on car.json; at most 256 MiB a pass, then
/// the pass splits: render.cpp) and the store's bins and texels (16 MiB at most frame sizes).
double HitStoreMiB(const RenderOptions& opt, int views, bool frameBuffers) {
    if (!opt.texture.enabled) return 0.0;
    // The frame buffers hold a record per pixel and the store's bins when they read the store.
    if (frameBuffers ? opt.texture.frameBufferSamples != TextureSamples::Hits : !ShadesAtHits(opt))
        return 0.0;
    const double perSample = opt.integrator == IntegratorKind::AO ? 12.0 : 40.0;
    const double samples = double(std::max(opt.width, 1)) * double(std::max(opt.height, 1)) *
                           double(std::max(views, 1)) * double(std::max(opt.spp, 1));
    return std::min(samples * perSample / double(1 << 20), 256.0) + 16.0;
}

}  // namespace

double MemoryBudgetMiB(double givenMiB) {
    constexpr double kDefaultMiB = 2048.0;
    double budget = kDefaultMiB;
    if (givenMiB > 0.0) {
        budget = givenMiB;
    } else if (const char* env = std::getenv("TEXCACHE_MAX_MEMORY_MB")) {
        char* end = nullptr;
        const double v = std::strtod(env, &end);
        if (end != env && v > 0.0) budget = v;
    }
    return std::min(budget, AvailableMemoryMiB());
}

double RenderMemoryMiB(const RenderOptions& opt, int views, bool frameBuffers) {
    // Measured peaks per pixel of one view: the float film, its sRGB copy and the encoder's
    // rows take about 36 bytes; each AOV layer 12 more in the film and as many in the EXR's
    // buffers; the screen-space stage's buffers (G-buffer, split light, history) about 520.
    const AovFlags& a = opt.aovs;
    const int layers = int(a.albedo) + int(a.normal) + int(a.depth) + int(a.ptex) + int(a.motion);
    const double perPixel = (frameBuffers ? 520.0 : 36.0) + 24.0 * layers;
    const double pixels = double(std::max(opt.width, 1)) * double(std::max(opt.height, 1)) *
                          double(std::max(views, 1));
    constexpr double kBaseMiB = 32.0;  // the program, Embree and a small scene
    return kBaseMiB + pixels * perPixel / double(1 << 20) + CacheMiB(opt, frameBuffers) +
           HitStoreMiB(opt, views, frameBuffers);
}

void CheckMemoryBudget(double needMiB, double budgetMiB, const std::string& what,
                       const std::string& where, const std::string& allow) {
    if (needMiB <= budgetMiB) return;
    throw InputError(where, what + " needs about " + std::to_string(llround(needMiB)) +
                                " MiB, more than the " + std::to_string(llround(budgetMiB)) +
                                " MiB allowed (default 2048, at most the memory available): "
                                "make it smaller or allow it with " +
                                allow + std::to_string(llround(std::ceil(needMiB))));
}

void CheckRenderMemory(const RenderOptions& opt, int views, bool frameBuffers, double budgetMiB) {
    const double need = RenderMemoryMiB(opt, views, frameBuffers),
                 caches = CacheMiB(opt, frameBuffers);
    if (caches > 0.5 * need) {
        const bool psr = opt.lightSampling == LightSampling::Cpis &&
                         double(opt.psrCacheBytes) / (1 << 20) > 0.5 * caches;
        CheckMemoryBudget(
            need, budgetMiB, "a render with " + std::to_string(llround(caches)) + " MiB of caches",
            psr ? "--psr-cache-mb" : "--sample-cache-mb/--texel-cache-mb", "--max-memory-mb ");
        return;
    }
    CheckMemoryBudget(need, budgetMiB,
                      "a " + std::to_string(opt.width) + "x" + std::to_string(opt.height) +
                          (views > 1 ? " stereo" : "") + (frameBuffers ? " frame-buffer" : "") +
                          " render",
                      "--resolution", "--max-memory-mb ");
}

TextureSamples AutoTextureSamples(bool gridAsked) {
    return gridAsked ? TextureSamples::Grid : TextureSamples::Hits;
}

CachedLight ParseCachedLight(const std::string& name, const std::string& where) {
    return ParseEnum(kCachedLights, name, where, "value");
}

LightKinds SceneLightKinds(const Scene& scene) {
    LightKinds k;
    k.soft = !scene.environments.empty() || !scene.quadLights.empty();
    for (const DistantLight& d : scene.distantLights)
        (d.angleDegrees > 0.0f ? k.soft : k.delta) = true;
    for (const PointLight& p : scene.pointLights) (p.radius > 0.0f ? k.soft : k.delta) = true;
    for (const Object& o : scene.objects) k.soft |= o.Emissive();
    return k;
}

CachedDirect CachedDirectLight(CachedLight choice, LightKinds kinds, TextureSamples samples) {
    if (choice == CachedLight::All) return {true, false};
    if (choice == CachedLight::Indirect || samples != TextureSamples::Hits || !kinds.soft)
        return {false, false};
    return {true, kinds.delta};
}

void CheckMaterialFilters(const Scene& scene, const RenderOptions& opt) {
    const IntegratorKind k = opt.integrator;
    if (!opt.texture.enabled ||
        (k != IntegratorKind::AO && k != IntegratorKind::Direct && k != IntegratorKind::Path))
        return;
    const bool hits = ShadesAtHits(opt);
    const std::string here = std::string("the ") + IntegratorName(k) + " integrator" +
                             (hits ? " at the hits" : " on the grid");
    for (const Object& o : scene.objects) {
        const Material& m = scene.materials[o.material];
        if (m.cacheFilter.empty()) continue;
        const std::string where = scene.path + ": material '" + m.name + "'";
        const bool soft = ParseTextureFilter(m.cacheFilter, where) == TextureFilterKind::SoftShadow;
        if (soft && (k != IntegratorKind::Direct || hits))
            throw InputError(where,
                             "filter softshadow filters area-light visibility, which only "
                             "the direct integrator caches, with --ts-samples grid (here: " +
                                 here + ")");
        if (!soft && k == IntegratorKind::Direct && !hits)
            throw InputError(where, "filter " + m.cacheFilter +
                                        " filters cached light, which the direct integrator "
                                        "caches only at the hits (--ts-samples auto or hits, "
                                        "--cached-light all); on the grid it caches visibility "
                                        "for softshadow alone (here: " +
                                        here + ")");
    }
}

void CheckStereoShear(const StereoRig& rig, const std::string& where) {
    if (rig.eyeSeparation <= 100.0f * rig.convergence) return;
    char msg[160];
    std::snprintf(msg, sizeof msg,
                  "the eyes are %g apart but converge at %g, more than 100 times closer: their "
                  "views would not overlap",
                  double(rig.eyeSeparation), double(rig.convergence));
    throw InputError(where, msg);
}

}  // namespace texcache
