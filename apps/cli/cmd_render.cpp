// SPDX-License-Identifier: Apache-2.0
// `texcache render`: render a scene file or a bare OBJ to EXR (+ a tone-mapped PNG beside it).
#include <sys/resource.h>

#include <charconv>
#include <climits>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <set>
#include <string_view>

#include <tbb/global_control.h>

#include "cli_util.h"
#include "commands.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/integrators/product_sampling.h"
#include "renderer/render.h"
#include "renderer/scene/scene_loader.h"
#include "renderer/texture_space/stereo.h"
#include "renderer/texture_space/texture_space.h"
#include "renderer/texture_space/visibility_pass.h"
#include "screen_space/screen_denoiser.h"
#include "texcache/enum_names.h"
#include "texcache/error.h"

namespace texcache::cli {

namespace {

struct RenderArgs {
    std::string scene;
    std::string output = "out/render.exr";
    // Options not given keep the scene's settings (Given(); no value of the type means "unset",
    // so a NaN or -1 on the command line is checked like any other value).
    std::set<std::string> given;
    bool Given(const std::string& option) const { return given.count(option) > 0; }
    int spp = 0;
    float seconds = 0.0f;
    std::string resolution;
    int threads = 0;
    long long seed = 0;
    std::string integrator;
    int maxDepth = 0;
    int aoSamples = 0;
    float aoDistance = 0.0f;
    float tessellationRate = 0.0f;
    float time = 0.0f;
    std::vector<std::string> aovs;
    float exposure = 0.0f;
    bool quiet = false;
    bool noPng = false;
    // Texture-space shading (libtexcache).
    std::string shading = "hit";
    std::string filter = "normal";
    int filterRadius = -1;  // not given: the filter's own default (DefaultFilterRadius)
    std::string footprint = "auto";
    std::string tsSamples = "auto";
    int shadowSamples = 4;
    float temporalAlpha = 0.0f;
    int passSpp = TextureSpaceOptions{}.passSpp;
    // Animation: frames "A:B" (inclusive) or "N" (frames 0..N-1) at fps.
    std::string frames;
    float fps = 24.0f;
    double sampleCacheMb = 64.0, texelCacheMb = 64.0;
    float lodBias = 0.0f;
    bool referenceCache = false;
    bool overshading = false;
    bool directMapped = false;
    int indirectSamples = 1;
    int hitSamples = 1;
    std::string cachedLight = "auto";
    std::string lightSampling = "mis";
    double psrCacheMb = double(RenderOptions{}.psrCacheBytes) / (1 << 20);
    float psrLodBias = RenderOptions{}.psrLodBias;
    std::string statsFile;
    // Screen-space frame buffers: one multi-layer EXR per frame in this directory.
    std::string frameBuffers;
    // Screen-space stage on the frame buffers, written as images.
    std::string denoise;
    bool demodulate = false;
    bool cachedVisibility = false;
    int visibilityRadius = TextureSpaceOptions{}.visibilityRadius;
    // Stereo: both eyes through one texture-space cache (renderer/texture_space/stereo.h).
    bool stereo = false;
    float eyeSeparation = 0.0f, convergence = 0.0f;
    std::string stereoReuse = "neighbour";
    std::string visibilityFilter = "none";
};

/// The texture-space options of the command line. `lightsSoft`: the scene's direct light has no
/// delta light (distant lights), so `--cached-light auto` may cache it (see below).
TextureSpaceOptions ParseTextureOptions(const RenderArgs& a, bool lightsSoft) {
    TextureSpaceOptions t;
    if (a.shading != "hit" && a.shading != "texture")
        throw InputError("--shading", "unknown mode '" + a.shading + "' (valid: hit, texture)");
    t.enabled = a.shading == "texture";
    t.filter = ParseTextureFilter(a.filter, "--filter");
    if (a.Given("--filter-radius")) CheckFilterRadius(a.filterRadius, "--filter-radius");
    t.radius = a.Given("--filter-radius") ? a.filterRadius : -1;
    t.footprint = ParseFootprintMode(a.footprint, "--footprint");
    // auto: AO and path-traced diffuse light shade at the hits, unless something only the grid
    // has is asked for.
    bool gridAsked = a.temporalAlpha != 0.0f;
    for (const char* o : {"--filter", "--filter-radius", "--footprint", "--stereo", "--overshading",
                          "--reference-cache", "--direct-mapped", "--sample-cache-mb",
                          "--texel-cache-mb", "--indirect-samples"})
        gridAsked = gridAsked || a.Given(o);
    t.samples = a.tsSamples == "auto" ? (gridAsked ? TextureSamples::Grid : TextureSamples::Hits)
                                      : ParseTextureSamples(a.tsSamples, "--ts-samples");
    if (t.samples == TextureSamples::Hits && a.temporalAlpha != 0.0f)
        throw InputError("--ts-samples",
                         "hits has no temporal accumulation (--temporal-alpha): "
                         "use grid");
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
    t.cache.texelTwoChoices = t.cache.sampleTwoChoices = !a.directMapped;
    t.indirectSamples = CheckRange("--indirect-samples", a.indirectSamples, 1, 1 << 16);
    if (a.cachedLight != "all" && a.cachedLight != "indirect" && a.cachedLight != "auto")
        throw InputError("--cached-light",
                         "unknown value '" + a.cachedLight + "' (valid: auto, all, indirect)");
    // auto: direct light too when it is soft (an environment, area lights) and shaded at the
    // hits, where its bins beat per-hit direct light at equal time (the car under its courtyard
    // map, 480x270, 4 spp, 1 path per hit: relMSE 0.316 binning all of it against 1.028 with
    // direct light per hit; per hit 1.037); a distant light's sharp shadows stay per hit.
    t.cacheDirect = a.cachedLight == "all" ||
                    (a.cachedLight == "auto" && lightsSoft && t.samples == TextureSamples::Hits);
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
    t.cache.Validate();
    return t;
}

std::string StatsJson(const RenderStats& s, const RenderScene& rs, const TextureSpaceCache* cache,
                      const RenderOptions& opt, double overshading) {
    const CacheStats& c = s.cache;
    std::string json = "{\n";
    auto add = [&](const char* k, double v, bool last = false) {
        char buf[128];
        std::snprintf(buf, sizeof buf, "  \"%s\": %.10g%s\n", k, v, last ? "" : ",");
        json += buf;
    };
    add("seconds", s.seconds);
    add("cpu_seconds", s.cpuSeconds);  // all threads: on a shared machine, the figure to compare
    add("spp", s.sppDone);
    add("rays", double(s.TotalRays()));
    add("camera_rays_culled", double(s.cameraRaysCulled));
    add("lookups", double(c.lookups));
    add("texel_hits", double(c.texelHits));
    add("texel_misses", double(c.texelMisses));
    add("texel_hit_rate", c.TexelHitRate());
    add("texel_evictions", double(c.texelEvictions));
    add("texels_uncached", double(c.texelUncached));
    add("sample_lookups", double(c.sampleLookups));
    add("sample_hits", double(c.sampleHits));
    add("samples_shaded", double(c.samplesShaded));
    add("sample_evictions", double(c.sampleEvictions));
    add("samples_uncached", double(c.samplesUncached));
    add("sample_memo_hits", double(c.sampleMemoHits));
    add("taps_unseen", double(c.tapsUnseen));
    add("texels_prefiltered", double(c.texelsPrefiltered));
    add("deferrals", double(c.deferrals));
    add("waits", double(c.waits));
    add("reference_mode", opt.texture.cache.referenceMode ? 1.0 : 0.0);
    if (overshading >= 0.0) add("overshading", overshading);
    add("psr_lookups", double(s.psr.lookups));
    add("psr_hits", double(s.psr.hits));
    add("psr_built", double(s.psr.built));
    add("psr_uncached", double(s.psr.uncached));
    add("psr_evictions", double(s.psr.evictions));
    add("psr_cache_bytes", double(s.psrBytes));
    add("sample_cache_bytes", cache ? double(cache->SampleCacheBytes()) : 0.0);
    add("texel_cache_bytes", cache ? double(cache->TexelCacheBytes()) : 0.0);
    add("hit_bin_bytes", double(s.hitBinBytes));  // shading at the hits (--ts-samples hits)
    add("hit_bins_dropped", double(s.hitBinsDropped));
    add("bytes_used", (cache ? double(cache->BytesUsed()) : 0.0) + double(s.psrBytes));
    // The scene: its size and the meshes Embree could not take (embree_mesh.cpp's design note).
    const RenderScene::TessellationStats t = rs.LimitTessellated();
    add("ptex_faces", double(rs.NumPtexFaces()));
    add("cage_faces_beyond_embree", double(t.beyondEmbree));
    add("limit_tessellated_meshes", double(t.meshes));
    add("limit_tessellated_cage_faces", double(t.cageFaces), true);
    json += "}\n";
    return json;
}

/// The scene's size, and the meshes Embree could not take (embree_mesh.cpp's design note).
void PrintSceneStats(const RenderScene& rs) {
    const size_t objects = rs.scene().objects.size();
    std::printf("scene: %zu object%s, %zu Ptex faces; %s\n", objects, objects == 1 ? "" : "s",
                rs.NumPtexFaces(), RenderScene::Describe(rs.LimitTessellated()).c_str());
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

/// Frame range of --frames: "A:B" (inclusive) or "N" (0..N-1); from_chars, so that
/// "0:4294967296" is an error rather than one frame.
void ParseFrames(const std::string& s, int* first, int* last) {
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

/// Output name of frame f: the run of '#' in the name replaced by the zero-padded number, or
/// "_NNNN" inserted before the extension.
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

/// --frame-buffers DIR: each frame's screen-space buffers as DIR/frame_NNNN.exr (+ the composed
/// image as a PNG), 1 spp unless --spp; the texture-space cache (if any) lives across frames.
/// One frame of an animation: the scene posed at `start + f / fps`, the texture-space cache (made
/// on the first frame, kept across frames) told that a frame begins, and the frame's options
/// (its time, fresh noise per frame).
struct AnimationFrame {
    std::optional<RenderScene> rs;
    RenderOptions options;

    void Pose(const Scene& scene, RenderSceneOptions* ro, const RenderOptions& opt, float start,
              int f, float fps, std::unique_ptr<TextureSpaceCache>* cache) {
        ro->frameTime = start + float(f) / fps;
        rs.emplace(scene, *ro);
        if (opt.texture.enabled && !*cache)
            *cache = std::make_unique<TextureSpaceCache>(*rs, opt.texture);
        if (*cache) (*cache)->BeginFrame(uint32_t(f));
        options = opt;
        options.frameTime = ro->frameTime;
        options.seed = opt.seed + uint64_t(f) * 0x9E3779B9ull;
    }
};

/// The checks shared by the outputs of the path tracer's decomposition (--frame-buffers,
/// --denoise): options that make no sense for it are errors naming `opt`.
void CheckDecompositionOptions(const RenderArgs& a, const char* opt, const char* aovReason) {
    if (a.Given("--integrator") && a.integrator != "path")
        throw InputError(
            opt, "renders the path tracer's decomposition: drop --integrator " + a.integrator);
    if (a.Given("--seconds")) throw InputError(opt, "renders --spp samples: drop --seconds");
    if (!a.aovs.empty()) throw InputError(opt, std::string(aovReason) + ": drop --aov");
    if (a.overshading) throw InputError(opt, "cannot be combined with --overshading");
    if (a.Given("--stats")) throw InputError(opt, "cannot be combined with --stats");
    if (a.Given("--light-sampling"))
        throw InputError(opt, "samples lights as MIS does: drop --light-sampling");
    if (a.Given("--visibility-filter"))
        throw InputError(opt, "cannot be combined with --visibility-filter");
}

/// --light-sampling and its record cache: product sampling needs an environment light and an
/// integrator that samples lights (errors name the option and the problem).
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

/// TBB's thread limit for --threads N (none for 0).
std::unique_ptr<tbb::global_control> ThreadLimit(int threads) {
    if (threads <= 0) return nullptr;
    return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                 threads);
}

/// Renders the frame buffers of frames first..last (the texture-space cache, if any, kept across
/// them) and hands each to `body(f, options, stats, buffers)`; returns the seconds spent.
template <class Body>
double ForEachFrameBuffers(const RenderArgs& a, const Scene& scene, const RenderOptions& opt,
                           int first, int last, float fps, Body&& body) {
    const std::unique_ptr<tbb::global_control> limit = ThreadLimit(a.threads);
    RenderSceneOptions ro;
    ro.threads = a.threads;
    std::unique_ptr<TextureSpaceCache> cache;
    screen::FrameBuffers fb;
    AnimationFrame frame;
    double total = 0.0;
    for (int f = first; f <= last; ++f) {
        const double tf = NowSeconds();
        frame.Pose(scene, &ro, opt, opt.frameTime, f, fps, &cache);
        const RenderOptions& fo = frame.options;
        const RenderStats st =
            RenderFrameBuffers(*frame.rs, fo, fo.frameTime - 1.0f / fps, &fb, cache.get());
        body(f, fo, st, fb, tf);
        total += NowSeconds() - tf;
    }
    return total;
}

/// Checks the planned outputs against each other and against every file the scene reads, and
/// that each can be written, before anything renders (FileSet).
void CheckFiles(const Scene& scene, const std::vector<OutputPaths>& outs,
                const std::string& statsFile = "") {
    FileSet files;
    files.SceneInputs(scene);
    for (const OutputPaths& o : outs) AddOutputs(files, o);
    if (!statsFile.empty()) files.Output(statsFile, "--stats");
    files.Check();
}

int RunFrameBuffers(const RenderArgs& a, const Scene& scene, RenderOptions opt, bool sppGiven,
                    int first, int last, float fps) {
    const char* opt_ = "--frame-buffers";
    CheckDecompositionOptions(a, opt_, "writes every buffer already");
    if (a.Given("--output")) throw InputError(opt_, "names the output directory: drop -o/--output");
    if (!sppGiven) opt.spp = 1;  // the real-time setting the buffers are for
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::create_directories(a.frameBuffers, ec);
    if (!fs::is_directory(a.frameBuffers))
        throw InputError(opt_, "cannot create directory '" + a.frameBuffers + "'" +
                                   (ec ? ": " + ec.message() : ""));
    // Each frame: the buffers' EXR (+ the composed image's PNG), checked before rendering.
    std::vector<OutputPaths> outs;
    for (int f = first; f <= last; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d", f);
        const fs::path stem = fs::path(a.frameBuffers) / name;
        OutputPaths o;
        o.exr = stem.string() + ".exr";
        if (!a.noPng) o.png = stem.string() + ".png";
        outs.push_back(o);
    }
    CheckFiles(scene, outs);

    const double total = ForEachFrameBuffers(
        a, scene, opt, first, last, fps,
        [&](int f, const RenderOptions& fo, const RenderStats& st, const screen::FrameBuffers& fb,
            double tf) {
            const OutputPaths& out = outs[size_t(f - first)];
            AtomicFiles group;
            WriteFrameBuffers(out.exr, fb, &group);
            if (!out.png.empty())
                WriteImage(out.png, ToImage(fb.Compose(), fb.width, fb.height), {}, a.exposure,
                           &group);
            group.Commit();
            std::printf(
                "frame %d (%d of %d, t = %.3f): %.3f s render (%.2f Mrays/s), %.3f s total -> %s\n",
                f, f - first + 1, last - first + 1, fo.frameTime, st.seconds,
                double(st.TotalRays()) / std::max(st.seconds, 1e-9) * 1e-6, NowSeconds() - tf,
                out.exr.c_str());
            std::fflush(stdout);
        });
    std::printf("wrote frame buffers of %d frames of %s in %.2f s (%dx%d, %d spp) to %s\n",
                last - first + 1, scene.path.c_str(), total, opt.width, opt.height, opt.spp,
                a.frameBuffers.c_str());
    return 0;
}

/// --denoise: each frame's buffers rendered in memory (RenderFrameBuffers, 1 spp unless --spp),
/// denoised by one ScreenSpaceDenoiser that keeps its history across the frames, and written as
/// images (numbered with --frames, like a plain animation; temporary file + rename).
int RunDenoised(const RenderArgs& a, const Scene& scene, RenderOptions opt, bool sppGiven,
                bool animated, int first, int last, float fps) {
    const char* opt_ = "--denoise";
    const screen::Method method = screen::ParseMethodKey(a.denoise, "--denoise");
    CheckDecompositionOptions(a, opt_, "writes the denoised image only");
    if (!a.frameBuffers.empty()) throw InputError(opt_, "cannot be combined with --frame-buffers");
    if (!animated && method != screen::Method::SpatialOnly)
        throw InputError(opt_, "method '" + a.denoise +
                                   "' reuses the previous frame: give --frames A:B (or use "
                                   "--denoise spatial for a single frame)");
    if (!sppGiven) opt.spp = 1;  // the real-time setting the stage is for
    // Plan and check every frame's outputs first: a bad name fails before anything renders.
    std::vector<OutputPaths> outs;
    for (int f = first; f <= last; ++f)
        outs.push_back(PlanOutputs(animated ? FramePath(a.output, f) : a.output, !a.noPng));
    CheckFiles(scene, outs);

    const screen::Demodulation demod =
        a.demodulate ? screen::Demodulation::On : screen::Demodulation::Off;
    screen::ScreenSpaceDenoiser denoiser;
    std::vector<glm::vec3> denoised;
    const double total = ForEachFrameBuffers(
        a, scene, opt, first, last, fps,
        [&](int f, const RenderOptions& fo, const RenderStats& st, const screen::FrameBuffers& fb,
            double) {
            denoiser.Denoise(fb, method, demod, &denoised);
            OutputPaths& out = outs[size_t(f - first)];
            AtomicFiles group;
            WriteOutputs(out, ToImage(denoised, fb.width, fb.height), {}, a.exposure, group);
            group.Commit();
            std::printf("frame %d (%d of %d, t = %.3f): %.3f s render, %.1f ms %s%s -> %s\n", f,
                        f - first + 1, last - first + 1, fo.frameTime, st.seconds,
                        denoiser.Timings().total, screen::MethodName(method),
                        a.demodulate ? " (demodulated)" : "", out.written.front().c_str());
            std::fflush(stdout);
        });
    std::printf("denoised %d frame%s of %s in %.2f s (%dx%d, %d spp, %s%s)\n", last - first + 1,
                last > first ? "s" : "", scene.path.c_str(), total, opt.width, opt.height, opt.spp,
                screen::MethodName(method), a.demodulate ? ", demodulated" : "");
    return 0;
}

/// The cache sizes of a render of `opt`: those given, else sized to the frame (`views` images:
/// SizeCachesToFrame). Both must fit in this machine's memory: the caches are allocated and
/// zeroed up front, and a size the machine cannot hold would end in bad_alloc or the OOM killer
/// mid-render.
void SizeCaches(const RenderArgs& a, RenderOptions* opt, int views) {
    TextureSpaceOptions& t = opt->texture;
    if (!t.enabled || t.cache.referenceMode) return;
    CacheSettings fit = t.cache;
    // --cached-visibility keeps a second term per texel under keys of its own (texture_space.h):
    // sized as a second view.
    const int terms = t.cachedVisibility ? 2 : 1;
    SizeCachesToFrame(&fit, opt->width, opt->height, views * terms, opt->integrator, t.footprint);
    // Shading at the hits keeps its bins beside the grid caches, which it never fills: they take
    // a token 64 KiB each instead of tens of MiB zeroed for nothing.
    if (ShadesAtHits(*opt)) fit.sampleCacheBytes = fit.texelCacheBytes = size_t(64) << 10;
    if (!a.Given("--sample-cache-mb")) t.cache.sampleCacheBytes = fit.sampleCacheBytes;
    if (!a.Given("--texel-cache-mb")) t.cache.texelCacheBytes = fit.texelCacheBytes;
    const double mib = 1.0 / double(1 << 20);
    const double sample = double(t.cache.sampleCacheBytes) * mib,
                 texel = double(t.cache.texelCacheBytes) * mib, have = PhysicalMemoryMiB();
    if (sample + texel > have)
        throw InputError("--sample-cache-mb/--texel-cache-mb",
                         "the caches (" + std::to_string(llround(sample)) + " + " +
                             std::to_string(llround(texel)) +
                             " MiB) do not fit in this machine's " + std::to_string(llround(have)) +
                             " MiB of memory");
}

/// The texture-space cache of `rs`, its allocation failure reported as the options' fault.
std::unique_ptr<TextureSpaceCache> MakeCache(const RenderScene& rs, const TextureSpaceOptions& t) {
    try {
        return std::make_unique<TextureSpaceCache>(rs, t);
    } catch (const std::bad_alloc&) {
        throw InputError("--sample-cache-mb/--texel-cache-mb",
                         "cannot allocate the texture-space caches (" +
                             std::to_string(t.cache.sampleCacheBytes >> 20) + " + " +
                             std::to_string(t.cache.texelCacheBytes >> 20) + " MiB)");
    }
}

/// Options that only mean something together with others are errors when they would be ignored.
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
}

/// --stereo's rig: the scene camera's, with --eye-separation / --convergence on top; without
/// either, the eyes are 1/30 of the convergence distance apart (the stereographers' rule).
StereoRig StereoRigFrom(const RenderArgs& a, const Camera& camera) {
    StereoRig rig = StereoRigOf(camera);
    if (a.Given("--convergence")) {
        rig.convergence = a.convergence;
        CheckStereoRig({0.0f, rig.convergence}, "--convergence");
    }
    if (a.Given("--eye-separation")) {
        rig.eyeSeparation = a.eyeSeparation;
        CheckStereoRig({rig.eyeSeparation, 1.0f}, "--eye-separation");
    } else if (rig.eyeSeparation == 0.0f) {
        rig.eyeSeparation = rig.convergence / 30.0f;
    }
    CheckStereoRig(rig, camera.convergence > 0.0f ? "camera.stereo" : "--convergence");
    return rig;
}

/// The options --stereo cannot honour (yet) are errors, as are the rig's options without it.
void CheckStereoOptions(const RenderArgs& a) {
    if (!a.stereo) {
        for (const char* o : {"--eye-separation", "--convergence", "--stereo-reuse"})
            if (a.Given(o)) throw InputError(o, "applies to stereo renders: give --stereo");
        return;
    }
    if (!a.frameBuffers.empty())
        throw InputError("--stereo", "cannot be combined with --frame-buffers (not supported yet)");
    if (!a.denoise.empty())
        throw InputError("--stereo", "cannot be combined with --denoise (not supported yet)");
    if (!a.frames.empty()) throw InputError("--stereo", "renders one frame: drop --frames");
    if (a.overshading) throw InputError("--stereo", "cannot be combined with --overshading");
}

StereoReuse ParseStereoReuse(const std::string& name) {
    if (name == "texels") return StereoReuse::Texels;
    if (name == "neighbour") return StereoReuse::Neighbour;
    throw InputError("--stereo-reuse",
                     "unknown value '" + Excerpt(name) + "' (valid: texels, neighbour)");
}

/// One eye's figures for --stats (the cache counters are what this eye shaded anew).
std::string EyeJson(const char* name, const RenderStats& s, bool last) {
    const CacheStats& c = s.cache;
    char buf[512];
    std::snprintf(
        buf, sizeof buf,
        "    \"%s\": {\"seconds\": %.10g, \"cpu_seconds\": %.10g, \"spp\": %d, \"rays\": %llu, "
        "\"camera_rays\": %llu, \"lookups\": %llu, \"texel_hit_rate\": %.10g, "
        "\"texels_shaded\": %llu, \"samples_shaded\": %llu}%s\n",
        name, s.seconds, s.cpuSeconds, s.sppDone, (unsigned long long)s.TotalRays(),
        (unsigned long long)s.cameraRays, (unsigned long long)c.lookups, c.TexelHitRate(),
        (unsigned long long)c.texelMisses, (unsigned long long)c.samplesShaded, last ? "" : ",");
    return buf;
}

/// --stereo: NAME_left.exr and NAME_right.exr (+ PNGs), both eyes through one cache.
int RunStereo(const RenderArgs& a, const Scene& scene, const RenderOptions& opt) {
    const StereoRig rig = StereoRigFrom(a, scene.camera);
    const std::filesystem::path o(a.output);
    std::vector<OutputPaths> outs;
    for (const char* eye : {"_left", "_right"})
        outs.push_back(PlanOutputs(
            (o.parent_path() / (o.stem().string() + eye + o.extension().string())).string(),
            !a.noPng));
    CheckCombinations(a, scene.settings, opt, outs.front());
    CheckFiles(scene, outs, a.statsFile);
    const std::unique_ptr<tbb::global_control> limit = ThreadLimit(a.threads);
    RenderSceneOptions ro;
    ro.frameTime = scene.settings.time;
    ro.threads = a.threads;
    ro.needLights = IntegratorUsesLights(opt.integrator);
    ro.needEnvironment = ro.needLights;
    ro.needTextures = true;
    const RenderScene rs(scene, ro);
    std::unique_ptr<TextureSpaceCache> cache;
    if (opt.texture.enabled) cache = MakeCache(rs, opt.texture);
    StereoResult r = RenderStereo(rs, opt, rig, cache.get(), ParseStereoReuse(a.stereoReuse));

    AtomicFiles group;
    WriteOutputs(outs[0], r.left.beauty, r.left.aovs, a.exposure, group);
    WriteOutputs(outs[1], r.right.beauty, r.right.aovs, a.exposure, group);
    if (!a.statsFile.empty()) {
        std::string json = StatsJson(BothEyes(r), rs, cache.get(), opt, -1.0);
        json.resize(json.size() - 3);  // "\n}\n": the eyes follow
        char rigJson[160];
        std::snprintf(rigJson, sizeof rigJson,
                      ",\n  \"stereo\": {\"eye_separation\": %.10g, \"convergence\": %.10g,\n",
                      rig.eyeSeparation, rig.convergence);
        json += rigJson + EyeJson("left", r.left.stats, false) +
                EyeJson("right", r.right.stats, true) + "  }\n}\n";
        WriteText(a.statsFile, json, group);
        outs[1].written.push_back(a.statsFile);
    }
    group.Commit();

    std::printf(
        "rendered %s in stereo: %dx%d per eye, %d spp, integrator %s, eye separation %g, "
        "convergence %g\n",
        scene.path.c_str(), opt.width, opt.height, r.left.stats.sppDone,
        IntegratorName(opt.integrator), rig.eyeSeparation, rig.convergence);
    const RenderStats& L = r.left.stats;
    for (const auto& [name, st] : {std::pair{"left", &r.left.stats}, {"right", &r.right.stats}}) {
        std::printf("%s eye: %.3f s (%.3f s cpu), %llu rays, %llu samples and %llu texels shaded",
                    name, st->seconds, st->cpuSeconds, (unsigned long long)st->TotalRays(),
                    (unsigned long long)st->cache.samplesShaded,
                    (unsigned long long)st->cache.texelMisses);
        if (st != &L)
            std::printf(
                " (%.1f%% of the left eye's time, %.1f%% of its samples, %.1f%% of its "
                "texels)",
                100.0 * st->seconds / std::max(L.seconds, 1e-9),
                100.0 * double(st->cache.samplesShaded) /
                    std::max(double(L.cache.samplesShaded), 1.0),
                100.0 * double(st->cache.texelMisses) / std::max(double(L.cache.texelMisses), 1.0));
        std::printf("\n");
    }
    std::printf("peak memory: %.1f MiB\n", PeakMemoryMiB());
    for (const OutputPaths& out : outs)
        for (const std::string& f : out.written) std::printf("wrote %s\n", f.c_str());
    return 0;
}

int RunRender(const RenderArgs& a) {
    std::vector<std::string> warnings;
    const double tLoad = NowSeconds();
    Scene scene = LoadSceneOrObj(a.scene, &warnings);
    const double loadSeconds = NowSeconds() - tLoad;
    for (const std::string& w : warnings)
        std::fprintf(stderr, "texcache: warning: %s\n", internal::OneLine(w).c_str());

    // Command-line values override the scene's render settings.
    RenderSettings& s = scene.settings;
    if (a.Given("--spp")) s.spp = CheckRange("--spp", a.spp, 1, 1 << 20);
    if (a.Given("--seconds")) s.seconds = CheckRange("--seconds", a.seconds, 0.0f, 1e6f);
    if (a.Given("--resolution")) ParseResolution(a.resolution, &s.width, &s.height);
    if (a.Given("--seed"))
        s.seed = uint64_t(CheckRange("--seed", a.seed, 0LL, std::numeric_limits<long long>::max()));
    if (a.Given("--integrator")) s.integrator = ParseIntegrator(a.integrator, "--integrator");
    if (a.Given("--max-depth")) s.maxDepth = CheckRange("--max-depth", a.maxDepth, 0, 1000);
    if (a.Given("--ao-samples")) s.aoSamples = CheckRange("--ao-samples", a.aoSamples, 1, 1 << 16);
    if (a.Given("--ao-distance"))
        s.aoDistance = CheckRange("--ao-distance", a.aoDistance, 1e-6f, 1e30f);
    if (a.Given("--tessellation-rate"))
        s.tessellationRate = CheckRange("--tessellation-rate", a.tessellationRate, 1.0f, 64.0f);
    if (a.Given("--time")) s.time = CheckRange("--time", a.time, -1e6f, 1e6f);
    CheckRange("--threads", a.threads, 0, 4096);
    CheckRange("--exposure", a.exposure, -64.0f, 64.0f);  // stops: 2^64 is far beyond any scene

    if (a.demodulate && a.denoise.empty())
        throw InputError("--demodulate", "applies to the screen-space stage: give --denoise");
    CheckStereoOptions(a);
    const RenderOptions common = RenderOptionsFrom(s);
    if (!a.frameBuffers.empty() || !a.denoise.empty()) {
        if (const std::string why = FrameBufferCameraProblem(scene.camera); !why.empty())
            throw InputError(a.frameBuffers.empty() ? "--denoise" : "--frame-buffers",
                             scene.path + ": " + why);
        // Frame buffers are always the path tracer's split, whatever the scene's integrator, and
        // exactly spp samples (no time budget).
        RenderOptions fbo = common;
        fbo.integrator = IntegratorKind::Path;
        fbo.seconds = 0.0f;
        fbo.texture = ParseTextureOptions(a, false);  // the stage's split: direct per hit
        // The frame buffers' renderer caches on the grid only (its caches must not be sized
        // for hits, which never fill them).
        fbo.texture.samples = TextureSamples::Grid;
        SizeCaches(a, &fbo, 1);
        fbo.progress = false;
        int first = 0, last = 0;
        if (!a.frames.empty()) ParseFrames(a.frames, &first, &last);
        const float fps = CheckRange("--fps", a.fps, 1e-3f, 1e4f);
        if (!a.denoise.empty())
            return RunDenoised(a, scene, fbo, a.Given("--spp"), !a.frames.empty(), first, last,
                               fps);
        return RunFrameBuffers(a, scene, fbo, a.Given("--spp"), first, last, fps);
    }
    RenderOptions opt = common;
    opt.hitSamples = CheckRange("--hit-samples", a.hitSamples, 1, 1 << 16);
    opt.aovs = ParseAovs(a.aovs);
    const VisibilityFilterKind visibility =
        ParseVisibilityFilter(a.visibilityFilter, "--visibility-filter");
    opt.texture = ParseTextureOptions(a, scene.distantLights.empty());
    SizeCaches(a, &opt, a.stereo ? 2 : 1);
    ParseLightSamplingOptions(a, scene, &opt);
    opt.progress = !a.quiet;
    int first = 0, last = 0;
    float fps = 0.0f;
    if (!a.frames.empty()) {
        ParseFrames(a.frames, &first, &last);
        fps = CheckRange("--fps", a.fps, 1e-3f, 1e4f);
        if (a.overshading) throw InputError("--overshading", "renders one frame: drop --frames");
    }
    if (a.stereo) {
        if (visibility != VisibilityFilterKind::None)
            throw InputError("--visibility-filter", "not with --stereo (yet): drop one of them");
        return RunStereo(a, scene, opt);
    }
    // Plan and check every output first: a bad or dangerous name fails before anything renders.
    std::vector<OutputPaths> outs;
    if (a.frames.empty()) {
        outs.push_back(PlanOutputs(a.output, !a.noPng));
    } else {
        for (int f = first; f <= last; ++f)
            outs.push_back(PlanOutputs(FramePath(a.output, f), !a.noPng));
    }
    CheckCombinations(a, s, opt, outs.front());
    CheckFiles(scene, outs, a.statsFile);

    const std::unique_ptr<tbb::global_control> limit = ThreadLimit(a.threads);

    const double t0 = NowSeconds();
    RenderSceneOptions ro;
    ro.frameTime = s.time;
    ro.threads = a.threads;
    ro.needLights = IntegratorUsesLights(opt.integrator);
    ro.needEnvironment = ro.needLights;
    ro.needTextures = true;
    if (!a.frames.empty()) {
        std::unique_ptr<TextureSpaceCache> cache;
        AnimationFrame frame;
        double total = 0.0;
        for (int f = first; f <= last; ++f) {
            // Scene geometry and lights are posed per frame; the cache (and its temporal
            // history) persists, keyed by each object's own grids.
            const double tf = NowSeconds();
            frame.Pose(scene, &ro, opt, s.time, f, fps, &cache);
            RenderOptions& fo = frame.options;
            fo.progress = false;
            RenderResult r = Render(*frame.rs, fo, cache.get());
            ApplyVisibilityFilter(visibility, *frame.rs, fo, &r.beauty);
            OutputPaths& out = outs[size_t(f - first)];
            AtomicFiles group;
            WriteOutputs(out, r.beauty, r.aovs, a.exposure, group);
            group.Commit();
            total += NowSeconds() - tf;
            std::printf("frame %d (%d of %d, t = %.3f): %.3f s, %.1f%% texel hits -> %s\n", f,
                        f - first + 1, last - first + 1, fo.frameTime, r.stats.seconds,
                        100.0 * r.stats.cache.TexelHitRate(), out.written.front().c_str());
            std::fflush(stdout);
        }
        std::printf("rendered %d frames of %s in %.2f s (%dx%d, %d spp, integrator %s)\n",
                    last - first + 1, scene.path.c_str(), total, opt.width, opt.height, opt.spp,
                    IntegratorName(s.integrator));
        return 0;
    }
    OutputPaths& out = outs.front();
    RenderScene rs(scene, ro);
    const double buildSeconds = NowSeconds() - t0;

    // Overshading: samples shaded beyond what an unbounded cache shades for the same frame.
    double overshading = -1.0;
    uint64_t referenceShaded = 0;
    if (a.overshading) {
        if (!opt.texture.enabled) throw InputError("--overshading", "needs --shading texture");
        RenderOptions ref = opt;
        ref.texture.cache.referenceMode = true;
        ref.progress = false;
        referenceShaded = Render(rs, ref).stats.cache.samplesShaded;
    }
    std::unique_ptr<TextureSpaceCache> cache;
    const double tCache = NowSeconds();
    if (opt.texture.enabled) cache = MakeCache(rs, opt.texture);
    const double cacheSeconds = NowSeconds() - tCache;
    RenderResult r = Render(rs, opt, cache.get());
    const double visibilitySeconds = ApplyVisibilityFilter(visibility, rs, opt, &r.beauty);
    if (a.overshading && referenceShaded > 0)
        overshading = double(r.stats.cache.samplesShaded) / double(referenceShaded) - 1.0;
    // Every output into one group, renamed only once all are complete.
    AtomicFiles group;
    WriteOutputs(out, r.beauty, r.aovs, a.exposure, group);
    if (!a.statsFile.empty()) {
        WriteText(a.statsFile, StatsJson(r.stats, rs, cache.get(), opt, overshading), group);
        out.written.push_back(a.statsFile);
    }
    group.Commit();

    std::printf("rendered %s: %dx%d, %d spp, integrator %s\n", scene.path.c_str(), opt.width,
                opt.height, r.stats.sppDone, IntegratorName(s.integrator));
    std::printf("time: %.3f s render + %.3f s scene build; %.2f Mrays/s (%llu rays)\n",
                r.stats.seconds, buildSeconds, double(r.stats.TotalRays()) / r.stats.seconds * 1e-6,
                (unsigned long long)r.stats.TotalRays());
    if (visibilitySeconds > 0.0) std::printf("visibility filter: %.3f s\n", visibilitySeconds);
    const RenderScene::BuildSeconds b = rs.BuildTimes();
    std::printf(
        "scene build: OpenSubdiv %.3f s, Embree geometry %.3f s, Embree BVH %.3f s, other %.3f s; "
        "%.3f s reading the scene%s",
        b.opensubdiv, b.embreeGeometry, b.embreeBvh, b.other, loadSeconds, cache ? "" : "\n");
    if (cache) std::printf(", %.3f s making the texture-space cache\n", cacheSeconds);
    std::printf(
        "scene memory: Embree %.1f MiB (%.1f MiB at most while building), Ptex topology and "
        "patches %.1f MiB\n",
        double(rs.EmbreeBytes()) / (1 << 20), double(rs.EmbreePeakBytes()) / (1 << 20),
        double(rs.MeshBytes()) / (1 << 20));
    PrintSceneStats(rs);
    if (cache) {
        const CacheStats& c = r.stats.cache;
        std::printf(
            "texture-space cache: %llu lookups, %.1f%% texel hits, %llu samples shaded "
            "(%llu evictions, %llu deferrals), %.1f MiB\n",
            (unsigned long long)c.lookups, 100.0 * c.TexelHitRate(),
            (unsigned long long)c.samplesShaded, (unsigned long long)c.sampleEvictions,
            (unsigned long long)c.deferrals, double(cache->BytesUsed()) / (1 << 20));
        if (r.stats.hitBinBytes > 0)
            std::printf(
                "hit bins (shading at the camera hits): %.1f MiB, %llu hits left out "
                "(no room)\n",
                double(r.stats.hitBinBytes) / (1 << 20),
                (unsigned long long)r.stats.hitBinsDropped);
        if (overshading >= 0.0)
            std::printf("overshading: %.2f%% more samples than an unbounded cache (%llu)\n",
                        100.0 * overshading, (unsigned long long)referenceShaded);
    }
    if (r.stats.psrBytes > 0) {
        const RecordStats& p = r.stats.psr;
        std::printf(
            "product sampling records: %llu lookups, %.1f%% hits, %llu built (%llu evictions), "
            "%.1f MiB\n",
            (unsigned long long)p.lookups,
            p.lookups ? 100.0 * double(p.hits) / double(p.lookups) : 0.0,
            (unsigned long long)p.built, (unsigned long long)p.evictions,
            double(r.stats.psrBytes) / (1 << 20));
    }
    std::printf("peak memory: %.1f MiB\n", PeakMemoryMiB());
    for (const std::string& f : out.written) std::printf("wrote %s\n", f.c_str());
    return 0;
}

}  // namespace

void AddRenderCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<RenderArgs>();
    CLI::App* cmd = app.add_subcommand("render", "Render a scene file (.json) or a bare OBJ cage");
    cmd->add_option("scene", args->scene, "Scene file (.json) or OBJ control cage (.obj)")
        ->required();
    cmd->add_option("-o,--output", args->output,
                    "Output image (.exr writes a .png beside it; .png only)")
        ->capture_default_str();
    cmd->add_option("--spp", args->spp, "Samples per pixel (a cap when --seconds is given)");
    cmd->add_option("--seconds", args->seconds, "Time budget in seconds (progressive passes)");
    cmd->add_option("--resolution", args->resolution, "Image size WxH, e.g. 1280x720");
    cmd->add_option("--threads", args->threads, "Worker threads (0 = all cores)");
    cmd->add_option("--seed", args->seed, "Random seed (same seed, same image for any --threads)");
    cmd->add_option("--integrator", args->integrator, std::string("One of: ") + IntegratorNames());
    cmd->add_option("--max-depth", args->maxDepth, "Path tracer bounce limit");
    cmd->add_option("--ao-samples", args->aoSamples, "AO rays per camera sample");
    cmd->add_option("--ao-distance", args->aoDistance, "AO ray length (world units)");
    cmd->add_option("--tessellation-rate", args->tessellationRate,
                    "Embree subdivision tessellation rate");
    cmd->add_option("--time", args->time, "Scene time of the frame (shutter open)");
    cmd->add_option("--aov", args->aovs,
                    "Extra EXR layers: albedo, normal, depth, ptex, motion, all")
        ->delimiter(',');
    cmd->add_option("--exposure", args->exposure, "PNG exposure in stops");
    cmd->add_flag("-q,--quiet", args->quiet, "No progress bar");
    cmd->add_flag("--no-png", args->noPng, "Do not write a PNG beside an EXR output");
    cmd->add_option("--shading", args->shading,
                    "hit: shade every hit; texture: cache AO / diffuse indirect in texture space")
        ->capture_default_str();
    cmd->add_option("--filter", args->filter,
                    std::string("Texture-space filter: ") + TextureFilterNames())
        ->capture_default_str();
    cmd->add_option("--filter-radius", args->filterRadius,
                    "Footprint radius r: (2r+1)^2 samples (default: the paper's for the filter: "
                    "none 0, normal 6, gaussian 10, regression 8, softshadow 8)");
    cmd->add_option(
           "--ts-samples", args->tsSamples,
           "Where texture-space AO and diffuse light (path, or direct with "
           "--cached-light all) shade: hits (at the camera's hits, binned per texel of a "
           "coarser level and read back bilinearly), grid (the paper's samples at texel "
           "centres, reconstructed by --filter) or auto (hits unless an option of the grid's "
           "cache is given: --filter, --filter-radius, --footprint, "
           "--temporal-alpha, --stereo, --overshading, --reference-cache, "
           "--direct-mapped, --sample-cache-mb, --texel-cache-mb, --indirect-samples)")
        ->capture_default_str();
    cmd->add_option("--footprint", args->footprint,
                    "Filter footprints: visible (only texels the camera rays reach, marked by a "
                    "prepass), all (every texel of the window, as the paper) or auto (visible "
                    "for AO, all for direct and path)")
        ->capture_default_str();
    cmd->add_option("--shadow-samples", args->shadowSamples,
                    "Shadow rays per cached visibility sample (--filter softshadow, "
                    "--cached-visibility)")
        ->capture_default_str();
    cmd->add_option("--pass-spp", args->passSpp,
                    "Progressive texture space: camera samples per pass; each further pass "
                    "re-shades the cache (fresh random numbers, jittered sample positions, "
                    "smaller footprints) so error keeps falling with --spp/--seconds (0: one pass, "
                    "the cache shaded once)")
        ->capture_default_str();
    cmd->add_option("--temporal-alpha", args->temporalAlpha,
                    "Temporal accumulation of texels across --frames: c = (1-A) c + A c_prev "
                    "(paper: 0.7; 0 = off)")
        ->capture_default_str();
    cmd->add_option("--frames", args->frames,
                    "Animation: render frames A:B (inclusive) or N (0..N-1) at --fps; outputs "
                    "are numbered (a run of # in -o, else name_NNNN.ext)");
    cmd->add_option("--fps", args->fps, "Frames per second of --frames")->capture_default_str();
    cmd->add_option("--sample-cache-mb", args->sampleCacheMb,
                    "Sample cache size (MiB; default: sized to the frame, 4 to 64)");
    cmd->add_option("--texel-cache-mb", args->texelCacheMb,
                    "Texel cache size (MiB; default: sized to the frame, 4 to 64)");
    cmd->add_option("--lod-bias", args->lodBias, "Shading LOD bias in mip levels (> 0: coarser)")
        ->capture_default_str();
    cmd->add_option("--hit-samples", args->hitSamples,
                    "Direct/path: light paths continued from each camera hit (same camera rays, "
                    "more shading: isolates shading error)")
        ->capture_default_str();
    cmd->add_option("--indirect-samples", args->indirectSamples,
                    "Paths (and NEE samples) per cached diffuse sample")
        ->capture_default_str();
    cmd->add_option(
           "--cached-light", args->cachedLight,
           "Path (and direct) integrator, which diffuse light is cached (diffuse "
           "materials, and the diffuse base of glossy ones; specular lobes stay per "
           "hit): indirect (direct light stays per hit; the direct integrator then "
           "caches its shadows on the grid), all (direct light cached and filtered too: for soft "
           "lighting; blurs hard shadows) or auto (all when shaded at the hits and the "
           "scene has no distant light, else indirect)")
        ->capture_default_str();
    cmd->add_flag("--reference-cache", args->referenceCache,
                  "Unbounded caches (the overshading baseline)");
    cmd->add_flag(
        "--direct-mapped", args->directMapped,
        "Strictly direct-mapped texel and sample caches (the paper's; default: two choices per "
        "entry)");
    cmd->add_flag(
        "--overshading", args->overshading,
        "Also render with unbounded caches and report the extra shading of the bounded ones");
    cmd->add_option("--light-sampling", args->lightSampling,
                    "Environment light at camera hits on metals: mis (light + BSDF sampling), "
                    "pis (product importance sampling per hit) or cpis (product records cached "
                    "per texel); pis and cpis need an environment light")
        ->capture_default_str();
    cmd->add_option("--psr-cache-mb", args->psrCacheMb,
                    "cpis: product record cache size (MiB; a record takes " +
                        std::to_string(RecordCache<ProductRecord>::kSlotBytes) + " bytes)")
        ->capture_default_str();
    cmd->add_option("--psr-lod-bias", args->psrLodBias,
                    "cpis: mip levels above the pixel-sized texel at which records are cached "
                    "(plus one per doubling of the lobe's width past GGX alpha 0.1)")
        ->capture_default_str();
    cmd->add_option("--stats", args->statsFile, "Write cache statistics as JSON to FILE");
    cmd->add_option("--frame-buffers", args->frameBuffers,
                    "Screen-space stage input: write each frame's buffers (components, guides, "
                    "motion-vector inputs, cones) as DIR/frame_NNNN.exr (+ the composed image as "
                    ".png) instead of an image; 1 spp unless --spp; with --frames/--fps, 'prev' "
                    "buffers are at t - 1/fps")
        ->type_name("DIR");
    cmd->add_option("--denoise", args->denoise,
                    "Render each frame's buffers in memory (1 spp unless --spp) and write the "
                    "screen-space stage's denoised image instead: spatial (no history; a single "
                    "frame is fine), baseline (SVGF), clamp (SVGF + neighbourhood clamping) or "
                    "reliable (Zeng et al. 2021); the last three need --frames")
        ->type_name("METHOD");
    cmd->add_flag("--demodulate", args->demodulate,
                  "With --denoise: filter glossy and diffuse indirect light divided by their "
                  "pre-integrated BRDF / albedo (Zhuang et al. 2021)");
    cmd->add_flag("--cached-visibility", args->cachedVisibility,
                  "With --shading texture and --denoise / --frame-buffers: also cache the direct "
                  "light's visibility in texture space (--shadow-samples rays per sample) and "
                  "let the stage take it where it has no history (disocclusions)");
    cmd->add_option("--visibility-radius", args->visibilityRadius,
                    "With --cached-visibility: its filter's footprint radius (-1: --filter-radius)")
        ->capture_default_str();
    cmd->add_flag("--stereo", args->stereo,
                  "Both eyes of the camera's stereo rig (scene camera 'stereo'), sharing one "
                  "texture-space cache: writes NAME_left and NAME_right (.exr + .png)");
    cmd->add_option("--eye-separation", args->eyeSeparation,
                    "--stereo: distance between the eyes (scene units; default: the scene's, "
                    "else 1/30 of the convergence distance)");
    cmd->add_option("--convergence", args->convergence,
                    "--stereo: distance of the zero-parallax plane (default: the scene's, else "
                    "the distance to the look-at point)");
    cmd->add_option("--stereo-reuse", args->stereoReuse,
                    "--stereo: what the second eye takes from the first eye's cache: texels "
                    "(those it looks up) or neighbour (also a cached texel beside a missing one)")
        ->capture_default_str();
    cmd->add_option("--visibility-filter", args->visibilityFilter,
                    "Primary-visibility filter after shading, for the noise of defocus and "
                    "motion blur: none or layered (filters/visibility_filter.h)")
        ->capture_default_str();
    cmd->callback([args, cmd, &exitCode] {
        for (const CLI::Option* o : cmd->get_options())
            if (o->count() > 0) args->given.insert(o->get_name());
        exitCode = RunRender(*args);
    });
}

}  // namespace texcache::cli
