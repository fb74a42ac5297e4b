// SPDX-License-Identifier: Apache-2.0
// `texcache render`'s arguments turned into RenderOptions, each value checked where it is read,
// and the checks across them: options that would be ignored, outputs that would clash with
// inputs. The decisions themselves (texture-space `auto` choices, cache sizes) are the
// renderer's (renderer/render_policy.h); this file maps the options onto them.
#include <algorithm>
#include <charconv>
#include <climits>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string_view>

#include "render_command.h"
#include "renderer/integrators/product_sampling.h"
#include "renderer/render_policy.h"
#include "renderer/scene/envmap.h"
#include "renderer/scene/scene_units.h"

namespace texcache::cli {

void ApplySettings(const RenderArgs& a, RenderSettings* settings, double unitScale) {
    RenderSettings& s = *settings;
    if (a.Given("--spp")) s.spp = CheckRange("--spp", a.spp, 1, 1 << 20);
    if (a.Given("--seconds")) s.seconds = CheckRange("--seconds", a.seconds, 0.0f, 1e6f);
    if (a.Given("--resolution")) ParseResolution(a.resolution, &s.width, &s.height);
    if (a.Given("--seed")) {
        const char* end = a.seed.data() + a.seed.size();
        const auto r = std::from_chars(a.seed.data(), end, s.seed);
        if (a.seed.empty() || r.ec != std::errc() || r.ptr != end)
            throw InputError("--seed",
                             "'" + a.seed + "' is not an integer in [0, 18446744073709551615]");
    }
    if (a.Given("--integrator")) s.integrator = ParseIntegrator(a.integrator, "--integrator");
    if (a.Given("--max-depth")) s.maxDepth = CheckRange("--max-depth", a.maxDepth, 0, 1000);
    if (a.Given("--ao-samples")) s.aoSamples = CheckRange("--ao-samples", a.aoSamples, 1, 1 << 16);
    if (a.Given("--ao-distance"))
        s.aoDistance = float(std::min(
            double(CheckRange("--ao-distance", a.aoDistance, 1e-6f, 1e30f)) * unitScale, 1e30));
    if (a.Given("--tessellation-rate"))
        s.tessellationRate = CheckRange("--tessellation-rate", a.tessellationRate, 1.0f, 64.0f);
    if (a.Given("--time")) s.time = CheckRange("--time", a.time, -1e6f, 1e6f);
    CheckRange("--threads", a.threads, 0, 4096);
    CheckRange("--exposure", a.exposure, -64.0f, 64.0f);  // stops: 2^64 is far beyond any scene
}

void WarnIfNothingVisible(const RenderArgs& a, const Scene& scene) {
    const RenderSettings& s = scene.settings;
    std::vector<float> times{s.time};
    if (!a.frames.empty()) {
        // Up to 1000 frames spread over the range: the check costs a few projections each.
        int first = 0, last = 0;
        ParseFrames(a.frames, &first, &last);
        const float fps = CheckRange("--fps", a.fps, 1e-3f, 1e4f);
        const int step = std::max(1, (last - first + 1) / 1000);
        times.clear();
        for (int f = first; f <= last; f += step)
            times.push_back(AnimationFrameTime(s.time, f, fps));
    }
    std::string problem;
    for (const float t : times) {
        problem = CameraViewProblem(scene, t, s.width, s.height);
        if (problem.empty()) return;
    }
    std::fprintf(stderr, "texcache: warning: %s: %s%s\n", scene.path.c_str(), problem.c_str(),
                 times.size() > 1 ? " (in every frame)" : "");
}

void WarnIfUnlit(const Scene& scene, IntegratorKind integrator) {
    // The first environment is the one used; a map is read here (and kept for the render), so
    // that its repairs are reported and a bad file fails before anything renders.
    std::shared_ptr<const EnvironmentMap> map;
    if (!scene.environments.empty() && !scene.environments[0].path.empty()) {
        const EnvironmentLight& e = scene.environments[0];
        map = EnvironmentMap::Shared(e.path, e.intensity, e.rotationDegrees);
        if (!map->Repairs().empty())
            std::fprintf(stderr, "texcache: warning: %s: environment map has %s\n", e.path.c_str(),
                         map->Repairs().c_str());
    }
    if (!IntegratorUsesLights(integrator)) return;
    const auto bright = [](glm::vec3 c) { return std::max({c.x, c.y, c.z}) > 0.0f; };
    bool lights = false, lit = false;
    for (const QuadLight& q : scene.quadLights) lights = true, lit = lit || bright(q.radiance);
    for (const DistantLight& d : scene.distantLights)
        lights = true, lit = lit || bright(d.irradiance);
    if (!scene.environments.empty()) {
        const EnvironmentLight& e = scene.environments[0];
        lights = true;
        lit = lit || bright(map ? map->AverageRadiance() : e.constant * e.intensity);
    }
    if (lights && !lit)
        std::fprintf(stderr,
                     "texcache: warning: %s: every light is black (zero radiance): the '%s' "
                     "integrator will render black\n",
                     scene.path.c_str(), IntegratorName(integrator));
}

TextureSpaceOptions ParseTextureOptions(const RenderArgs& a, LightKinds lights) {
    TextureSpaceOptions t;
    if (a.shading != "hit" && a.shading != "texture")
        throw InputError("--shading", "unknown mode '" + a.shading + "' (valid: hit, texture)");
    t.enabled = a.shading == "texture";
    t.filter = ParseTextureFilter(a.filter, "--filter");
    if (a.Given("--filter-radius")) CheckFilterRadius(a.filterRadius, "--filter-radius");
    t.radius = a.Given("--filter-radius") ? a.filterRadius : -1;
    t.footprint = ParseFootprintMode(a.footprint, "--footprint");
    // auto: at the hits, unless something only the grid has is asked for.
    bool gridAsked = false;
    for (const char* o : {"--filter", "--filter-radius", "--footprint", "--stereo-reuse",
                          "--overshading", "--reference-cache", "--direct-mapped",
                          "--sample-cache-mb", "--texel-cache-mb", "--indirect-samples"})
        gridAsked = gridAsked || a.Given(o);
    t.samples = a.tsSamples == "auto" ? AutoTextureSamples(gridAsked)
                                      : ParseTextureSamples(a.tsSamples, "--ts-samples");
    t.shadowSamples = CheckRange("--shadow-samples", a.shadowSamples, 1, 1 << 16);
    if (a.temporalAlpha != 0.0f) {
        if (!(a.temporalAlpha > 0.0f && a.temporalAlpha < 1.0f))
            throw InputError("--temporal-alpha",
                             "must be in [0, 1) (the weight of the history; "
                             "the paper uses 0.7), got " +
                                 std::to_string(a.temporalAlpha));
        if (!t.enabled) throw InputError("--temporal-alpha", "needs --shading texture");
        if (a.frames.empty())
            throw InputError("--temporal-alpha", "accumulates across frames: give --frames");
    }
    t.temporalAlpha = a.temporalAlpha;
    t.passSpp = CheckRange("--pass-spp", a.passSpp, 0, 1 << 20);
    auto bytes = [](const char* opt, double mb) {
        CheckRange(opt, mb, 1.0 / 1024.0, 1024.0 * 1024.0);
        return size_t(mb * 1024.0 * 1024.0);
    };
    t.cache.sampleCacheBytes = bytes("--sample-cache-mb", a.sampleCacheMb);
    t.cache.texelCacheBytes = bytes("--texel-cache-mb", a.texelCacheMb);
    t.cache.lodBias = CheckRange("--lod-bias", a.lodBias, -16.0f, 16.0f);
    t.cache.referenceMode = a.referenceCache;
    t.cache.texelThreeChoices = t.cache.sampleThreeChoices = !a.directMapped;
    t.indirectSamples = CheckRange("--indirect-samples", a.indirectSamples, 1, 1 << 16);
    const CachedDirect direct =
        CachedDirectLight(ParseCachedLight(a.cachedLight, "--cached-light"), lights, t.samples);
    t.cacheDirect = direct.cacheDirect;
    t.deltaDirectPerHit = direct.deltaDirectPerHit;
    if (a.cachedVisibility && (!t.enabled || (a.frameBuffers.empty() && a.denoise.empty())))
        throw InputError("--cached-visibility",
                         "fills the screen-space frame buffers: needs --shading texture and "
                         "--denoise or --frame-buffers");
    t.cachedVisibility = a.cachedVisibility;
    if (a.Given("--visibility-radius")) {
        if (!a.cachedVisibility)
            throw InputError("--visibility-radius", "applies to --cached-visibility");
        if (a.visibilityRadius != -1) CheckFilterRadius(a.visibilityRadius, "--visibility-radius");
    }
    t.visibilityRadius = a.visibilityRadius;
    if (!t.enabled)
        for (const char* o :
             {"--ts-samples", "--cached-light", "--filter", "--filter-radius", "--footprint",
              "--shadow-samples", "--indirect-samples", "--pass-spp", "--lod-bias",
              "--sample-cache-mb", "--texel-cache-mb", "--direct-mapped", "--reference-cache"})
            if (a.Given(o))
                throw InputError(o, "applies to texture-space shading: give --shading texture");
    t.cache.Validate();
    return t;
}

void SizeCaches(const RenderArgs& a, RenderOptions* opt, int views) {
    SizeTextureCaches(opt, views, {a.Given("--sample-cache-mb"), a.Given("--texel-cache-mb")},
                      kCacheSizeOptions);
}

double MemoryBudget(const RenderArgs& a) {
    if (!a.Given("--max-memory-mb")) return MemoryBudgetMiB(0.0);
    return MemoryBudgetMiB(
        CheckRange("--max-memory-mb", a.maxMemoryMb, 1.0, 1024.0 * 1024.0 * 1024.0));
}

void ParseLightSamplingOptions(const RenderArgs& a, const Scene& scene, RenderOptions* opt) {
    opt->lightSampling = ParseLightSampling(a.lightSampling, "--light-sampling");
    const double mb = CheckRange("--psr-cache-mb", a.psrCacheMb, 1.0 / 1024.0, 1024.0 * 1024.0);
    opt->psrCacheBytes = size_t(mb * 1024.0 * 1024.0);
    opt->psrLodBias = CheckRange("--psr-lod-bias", a.psrLodBias, -16.0f, 16.0f);
    if (opt->lightSampling == LightSampling::Mis) return;
    const std::string what = std::string("--light-sampling ") + a.lightSampling;
    if (opt->integrator != IntegratorKind::Direct && opt->integrator != IntegratorKind::Path)
        throw InputError(what, std::string("samples light for the direct and path integrators "
                                           "only (the integrator is ") +
                                   IntegratorName(opt->integrator) + ")");
    if (scene.environments.empty())
        throw InputError(what, scene.path +
                                   " has no environment light (product sampling draws "
                                   "directions from the BSDF times an environment map)");
    if (opt->lightSampling == LightSampling::Cpis &&
        opt->psrCacheBytes < RecordCache<ProductRecord>::kSlotBytes)
        throw InputError("--psr-cache-mb",
                         "holds no record (one takes " +
                             std::to_string(RecordCache<ProductRecord>::kSlotBytes) + " bytes)");
}

AovFlags ParseAovs(const std::vector<std::string>& names) {
    AovFlags f;
    for (const std::string& n : names) {
        if (n == "albedo")
            f.albedo = true;
        else if (n == "normal")
            f.normal = true;
        else if (n == "depth")
            f.depth = true;
        else if (n == "ptex")
            f.ptex = true;
        else if (n == "motion")
            f.motion = true;
        else if (n == "all")
            f.albedo = f.normal = f.depth = f.ptex = f.motion = true;
        else
            throw InputError("--aov", "unknown layer '" + n +
                                          "' (valid: albedo, normal, depth, ptex, motion, all)");
    }
    return f;
}

void ParseFrames(const std::string& s, int* first, int* last) {
    // from_chars, so that "0:4294967296" is an error rather than one frame.
    const auto number = [&](std::string_view t, long long* v) {
        const auto r = std::from_chars(t.data(), t.data() + t.size(), *v);
        return !t.empty() && r.ec == std::errc() && r.ptr == t.data() + t.size();
    };
    const size_t colon = s.find(':');
    long long a = 0, b = 0;
    bool ok;
    if (colon == std::string::npos) {
        ok = number(s, &b) && b >= 1;
        b -= 1;  // N frames: 0..N-1
    } else {
        ok = number(std::string_view(s).substr(0, colon), &a) &&
             number(std::string_view(s).substr(colon + 1), &b);
    }
    if (!ok)
        throw InputError("--frames",
                         "expected A:B (first and last frame) or N, got '" + Excerpt(s) + "'");
    if (a < 0 || b < a || b - a >= 100000 || b > INT_MAX - 1)
        throw InputError("--frames",
                         "'" + Excerpt(s) + "' is not a range of 1 to 100000 frames from 0");
    *first = int(a);
    *last = int(b);
}

std::string FramePath(const std::string& output, int f) {
    const size_t hash = output.find('#');
    char num[32];
    if (hash != std::string::npos) {
        size_t end = hash;
        while (end < output.size() && output[end] == '#') ++end;
        std::snprintf(num, sizeof num, "%0*d", int(end - hash), f);
        return output.substr(0, hash) + num + output.substr(end);
    }
    const std::filesystem::path p(output);
    std::snprintf(num, sizeof num, "_%04d", f);
    return (p.parent_path() / (p.stem().string() + num + p.extension().string())).string();
}

void CheckCombinations(const RenderArgs& a, const RenderSettings& s, const RenderOptions& opt,
                       const OutputPaths& out) {
    if (a.Given("--filter") && opt.texture.filter == TextureFilterKind::SoftShadow &&
        s.integrator != IntegratorKind::Direct)
        throw InputError("--filter", std::string("softshadow filters area-light visibility, which "
                                                 "only the direct integrator caches (the "
                                                 "integrator is ") +
                                         IntegratorName(s.integrator) + ")");
    if (!a.aovs.empty() && out.exr.empty())
        throw InputError("--aov", "AOV layers are written to EXR files only: give -o NAME.exr");
    if (a.Given("--stats") && !a.frames.empty())
        throw InputError("--stats", "reports one frame: drop --frames");
    if (a.noPng && out.exr.empty())
        throw InputError("--no-png", "the output is a PNG: drop --no-png, or give -o NAME.exr");
    if (a.Given("--exposure") && out.png.empty())
        throw InputError("--exposure", "sets the PNG's exposure, and --no-png writes none");
}

void CheckOptionsUsed(const RenderArgs& a, const RenderOptions& opt) {
    const auto integrator = [&](const char* o, const char* which) {
        throw InputError(o, std::string("applies to the ") + which + " (the integrator is " +
                                IntegratorName(opt.integrator) + ")");
    };
    const IntegratorKind k = opt.integrator;
    if (a.Given("--max-depth") && k != IntegratorKind::Path)
        integrator("--max-depth", "path integrator");
    if (a.Given("--hit-samples") && k != IntegratorKind::Direct && k != IntegratorKind::Path)
        integrator("--hit-samples", "direct and path integrators");
    for (const char* o : {"--ao-samples", "--ao-distance"})
        if (a.Given(o) && k != IntegratorKind::AO) integrator(o, "ao integrator");
    for (const char* o : {"--psr-cache-mb", "--psr-lod-bias"})
        if (a.Given(o) && opt.lightSampling != LightSampling::Cpis)
            throw InputError(o, "applies to --light-sampling cpis");
    if (a.Given("--fps") && a.frames.empty())
        throw InputError("--fps", "sets the frame rate of an animation: give --frames");
}

void CheckFiles(const Scene& scene, const std::vector<OutputPaths>& outs,
                const std::string& statsFile) {
    FileSet files;
    files.SceneInputs(scene);
    for (const OutputPaths& o : outs) AddOutputs(files, o);
    if (!statsFile.empty()) files.Output(statsFile, "--stats");
    files.Check();
}

std::unique_ptr<tbb::global_control> ThreadLimit(int threads) {
    if (threads <= 0) return nullptr;
    return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                 threads);
}

RenderSceneOptions SceneOptionsFor(const RenderArgs& a, const RenderOptions& opt, float time) {
    RenderSceneOptions ro;
    ro.frameTime = time;
    ro.threads = a.threads;
    ro.needLights = IntegratorUsesLights(opt.integrator);
    ro.needEnvironment = ro.needLights;
    ro.needTextures = true;
    ro.tessellateAll = a.geometry == "quads";
    return ro;
}

}  // namespace texcache::cli
