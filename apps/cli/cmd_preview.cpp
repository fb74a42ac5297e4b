// SPDX-License-Identifier: Apache-2.0
// `texcache preview`: command-line options -> PreviewSettings, then the window, the headless
// test mode or the benchmark.
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>

#include "cli_util.h"
#include "commands.h"
#include "preview.h"
#include "renderer/render.h"
#include "renderer/render_policy.h"
#include "renderer/scene/scene_loader.h"
#include "renderer/scene/scene_units.h"
#include "renderer/texture_space/stereo.h"
#include "renderer/texture_space/texture_space.h"

namespace texcache::cli {

namespace {

struct PreviewCliArgs {
    std::string scene;
    int frames = 0;
    std::string screenshot;
    float orbit = 20.0f;
    std::string resolution;
    std::string integrator;  // empty: the scene's
    std::string shading = "texture";
    std::string filter = "none";
    int filterRadius = 0;
    std::string footprint = "auto";
    int aoSamples = 32;
    int spp = 1;
    float lodBias = 1.0f;  // half the shading rate (Sec. 6.2): ~1 texel per pixel, high reuse
    double sampleCacheMb = 64.0, texelCacheMb = 64.0;
    double maxMemoryMb = 0.0;  // 0: MemoryBudgetMiB's default
    float exposure = 0.0f;
    std::string view = "beauty";
    float time = NAN;  // NAN: the scene's render.time
    bool play = false;
    float fps = 24.0f;
    bool fpsGiven = false;  ///< --fps on the command line
    std::string benchOnly;  ///< a bench option given on the command line (empty: none)
    bool saveCamera = false;
    std::string denoise = "auto";
    bool demodulate = false, noDemodulate = false;  ///< given on the command line
    bool cachedVisibility = false;
    std::string fbCache;  ///< empty: store (the bench: both)
    int fbBudget = 8;
    std::string geometry = "auto";
    std::string motion = "traditional";
    bool bench = false;
    int benchFrames = 36;
    bool benchStill = false;
    bool benchFixedAlpha = false;
    bool benchEqualError = false;
    int specularSamples = 0;
    int referenceSpp = 0;  // 0: 32 (AO, x 16 rays) or 128 (--denoise: path traced)
    std::string benchOut = "out/preview_bench";
    bool stereo = false;
    std::optional<float> eyeSeparation;  // none: the scene camera's, else 1/30 of the orbit's
    bool noReshade = false;
};

/// Refuses a preview whose buffers and caches would not fit (render's CheckRenderMemory: the
/// preview's frames are the render's, with the stage's buffers when it denoises).
void CheckPreviewMemory(const preview::PreviewSettings& s, double maxMemoryMb) {
    RenderOptions o;
    o.width = s.width;
    o.height = s.height;
    o.texture.enabled = s.textureSpace;
    o.texture.cache.sampleCacheBytes = size_t(double(s.sampleCacheMb) * (1 << 20));
    o.texture.cache.texelCacheBytes = size_t(double(s.texelCacheMb) * (1 << 20));
    const double budget =
        MemoryBudgetMiB(maxMemoryMb == 0.0 ? 0.0
                                           : CheckRange("--max-memory-mb", maxMemoryMb, 1.0,
                                                        1024.0 * 1024.0 * 1024.0));
    CheckRenderMemory(o, s.stereo ? 2 : 1, s.denoise, budget);
}

int RunPreview(const PreviewCliArgs& a) {
    std::vector<std::string> warnings;
    Scene scene = LoadSceneOrObj(a.scene, &warnings);
    for (const std::string& w : warnings)
        std::fprintf(stderr, "texcache: warning: %s\n", w.c_str());

    preview::PreviewSettings s;
    s.integrator = a.integrator.empty() ? scene.settings.integrator
                                        : ParseIntegrator(a.integrator, "--integrator");
    if (a.shading != "hit" && a.shading != "texture")
        throw InputError("--shading", "unknown mode '" + a.shading + "' (valid: hit, texture)");
    s.textureSpace = a.shading == "texture";
    s.filter = ParseTextureFilter(a.filter, "--filter");
    CheckFilterRadius(a.filterRadius, "--filter-radius");
    s.radius = a.filterRadius;
    s.footprint = ParseFootprintMode(a.footprint, "--footprint");
    s.aoSamples = CheckRange("--ao-samples", a.aoSamples, 1, 4096);
    s.sppPerFrame = CheckRange("--spp", a.spp, 1, 4096);
    s.lodBias = CheckRange("--lod-bias", a.lodBias, -16.0f, 16.0f);
    s.sampleCacheMb = float(CheckRange("--sample-cache-mb", a.sampleCacheMb, 1.0, 65536.0));
    s.texelCacheMb = float(CheckRange("--texel-cache-mb", a.texelCacheMb, 1.0, 65536.0));
    s.exposure = CheckRange("--exposure", a.exposure, -32.0f, 32.0f);
    s.view = preview::ParseViewMode(a.view, "--view");
    s.refineCacheWhenStill = !a.noReshade;
    s.denoise = a.denoise != "off" && a.denoise != "auto";
    if (s.denoise) {
        try {
            s.denoiseMethod = screen::ParseMethodKey(a.denoise, "--denoise");
        } catch (const InputError&) {
            throw InputError("--denoise", "unknown method '" + a.denoise + "' (valid: auto, off, " +
                                              screen::MethodKeys() + ")");
        }
    }
    s.motionKind = preview::ParseMotionKind(a.motion, "--motion");
    s.stereo = a.stereo;
    if (a.eyeSeparation) {
        if (!a.stereo) throw InputError("--eye-separation", "sets the stereo rig: give --stereo");
        CheckStereoRig({*a.eyeSeparation, 1.0f}, "--eye-separation");
        // In the scene file's units; the preview works in render units (scene_units.h).
        s.eyeSeparation = float(std::min(double(*a.eyeSeparation) * scene.unitScale, 1e30));
        CheckSceneReach(scene, 0.5f * s.eyeSeparation, "--eye-separation");
    } else if (scene.camera.eyeSeparation > 0.0f) {
        s.eyeSeparation = scene.camera.eyeSeparation;
    }
    if (a.stereo && s.denoise)
        throw InputError("--stereo", "cannot be combined with --denoise (not supported yet)");
    if (a.stereo && a.bench) throw InputError("--stereo", "cannot be combined with --bench");
    if (!std::isnan(a.time)) scene.settings.time = CheckRange("--time", a.time, -1e6f, 1e6f);
    // The scene's settings that the preview keeps (its size, spp and AO rays are its own).
    const RenderOptions fromScene = RenderOptionsFrom(scene.settings);
    s.time = fromScene.frameTime;
    s.aoDistance = fromScene.aoDistance;
    s.maxDepth = fromScene.maxDepth;
    s.seed = fromScene.seed;
    s.tessellationRate = scene.settings.tessellationRate;
    s.limitQuads =
        a.geometry == "auto" ? preview::LimitQuadsFit(scene) : a.geometry != "subdivision";
    if (a.geometry == "both" && !(a.bench && s.denoise))
        throw InputError("--geometry",
                         "'both' compares the two in the stage's bench: give --bench --denoise, "
                         "or quads or subdivision");
    // The preview's default is the benchmark's 512x512, not the scene's final-render size.
    s.width = s.height = 512;
    if (!a.resolution.empty()) ParseResolution(a.resolution, &s.width, &s.height);
    // auto: the scene as it renders, cleaned up by the stage, where the stage has something to
    // clean (the path tracer's split) and keeps up with the frame rate.
    if (a.denoise == "auto")
        s.denoise = s.integrator == IntegratorKind::Path && !a.stereo &&
                    preview::StageKeepsUp(s.width, s.height);
    if (a.demodulate && a.noDemodulate)
        throw InputError("--no-demodulate", "contradicts --demodulate: give one of them");
    s.demodulate = !a.noDemodulate;
    if ((a.demodulate || a.noDemodulate) && !s.denoise)
        throw InputError(a.demodulate ? "--demodulate" : "--no-demodulate",
                         "applies to the screen-space stage: give --denoise");
    s.cachedVisibility = a.cachedVisibility;
    const bool bothCaches = a.fbCache == "both";
    if (bothCaches && !a.bench)
        throw InputError("--fb-cache", "'both' compares the two in --bench: give grid or store");
    if (!a.fbCache.empty() && !bothCaches) {
        if (a.fbCache != "grid" && a.fbCache != "store")
            throw InputError("--fb-cache",
                             "unknown cache '" + a.fbCache + "' (valid: store, grid, both)");
        s.fbCache = a.fbCache == "grid" ? TextureSamples::Grid : TextureSamples::Hits;
    }
    s.fbBudget = CheckRange("--fb-budget", a.fbBudget, 1, 16);
    if ((s.fbBudget & (s.fbBudget - 1)) != 0)
        throw InputError("--fb-budget", "one pixel in 1, 2, 4, 8 or 16 a frame, got " +
                                            std::to_string(s.fbBudget));
    CheckPreviewMemory(s, a.maxMemoryMb);
    if (a.cachedVisibility && (!s.denoise || !s.textureSpace))
        throw InputError("--cached-visibility",
                         "applies to the screen-space stage with texture space: give --denoise "
                         "and --shading texture");

    preview::PreviewArgs p;
    p.scenePath = a.scene;
    p.frames = CheckRange("--frames", a.frames, 0, 100000);
    p.screenshot = a.screenshot;
    p.orbitDegrees = CheckRange("--orbit", a.orbit, -3600.0f, 3600.0f);
    p.filterName = a.filter;
    p.saveCamera = a.saveCamera;
    p.play = a.play;
    p.fps = CheckRange("--fps", a.fps, 1e-3f, 1e4f);
    if (a.play && p.frames == 0)
        throw InputError("--play", "needs --frames N (the window has a timeline for it)");
    if (a.saveCamera && p.frames == 0)
        throw InputError("--save-camera", "needs --frames N (the window has a button for it)");
    if (a.saveCamera && std::filesystem::path(a.scene).extension() != ".json")
        throw InputError("--save-camera", "needs a .json scene file, got '" + a.scene + "'");
    if (!a.screenshot.empty() && p.frames == 0)
        throw InputError("--screenshot", "needs --frames N (the headless test mode)");
    if (a.fpsGiven && p.frames == 0)
        throw InputError("--fps", "sets the pace of the timeline of --frames: give --frames");
    if (a.bench && p.frames > 0)
        throw InputError("--frames",
                         "sets the window's timeline, which --bench has not: drop it "
                         "(--bench-frames sets the timed frames)");
    // The window would ignore them: say so rather than open it.
    if (!a.bench && !a.benchOnly.empty()) throw InputError(a.benchOnly, "applies to --bench");
    if (a.bench) {
        preview::BenchArgs b;
        b.frames = CheckRange("--bench-frames", a.benchFrames, 1, 10000);
        b.referenceSpp = a.referenceSpp == 0
                             ? (s.denoise ? 128 : 32)
                             : CheckRange("--reference-spp", a.referenceSpp, 1, 1 << 16);
        b.out = a.benchOut;
        b.still = a.benchStill;
        b.stageRunningMean = !a.benchFixedAlpha;
        if (a.benchFixedAlpha && !b.still)
            throw InputError("--bench-fixed-alpha", "applies to --bench-still only");
        if (b.still && b.frames < 2)
            throw InputError("--bench-frames", "--bench-still needs at least 2 frames, got " +
                                                   std::to_string(b.frames));
        if (b.still && !s.denoise)
            throw InputError("--bench-still", "measures the stage's frames: give --denoise");
        b.equalError = a.benchEqualError;
        // Both by default: the store and the grid against per hit, frame by frame in turn.
        b.bothCaches = a.fbCache.empty() || bothCaches;
        b.bothGeometries = a.geometry == "both";
        if (b.equalError && (!s.denoise || b.still))
            throw InputError("--bench-equal-error",
                             "measures the stage's frames while orbiting: give --denoise and "
                             "drop --bench-still");
        if (a.specularSamples != 0)
            b.specularSamples = CheckRange("--specular-samples", a.specularSamples, 1, 32);
        return preview::RunPreviewBench(scene, s, p, b);
    }
    return preview::RunPreviewWindow(std::move(scene), s, p);
}

}  // namespace

void AddPreviewCommand(CLI::App& app, int& exitCode) {
    auto a = std::make_shared<PreviewCliArgs>();
    CLI::App* cmd = app.add_subcommand(
        "preview",
        "Interactive progressive preview (GLFW + OpenGL window), headless test mode, "
        "frame-rate benchmark");
    cmd->add_option("scene", a->scene, "Scene file (.json) or OBJ control cage (.obj)")->required();
    // Options take the group set last (option_defaults): --help lists them group by group.
    auto group = [cmd](const char* name) { cmd->option_defaults()->group(name); };

    group("View");
    cmd->add_option("--resolution", a->resolution, "Render size WxH (default 512x512)");
    cmd->add_option("--max-memory-mb", a->maxMemoryMb,
                    "Refuse a preview expected to need more memory (MiB; default 2048, or "
                    "TEXCACHE_MAX_MEMORY_MB; never more than the memory available)");
    cmd->add_option("--integrator", a->integrator,
                    std::string("One of: ") + IntegratorNames() + " (default: the scene's)");
    cmd->add_option("--spp", a->spp, "Camera samples per pixel per frame")->capture_default_str();
    cmd->add_option("--ao-samples", a->aoSamples, "AO rays per hit / per cached sample")
        ->capture_default_str();
    cmd->add_option("--view", a->view,
                    "What the window shows: beauty, faceid, mip, texels, hitmiss (texel-cache hits "
                    "and misses of the frame), overshading (samples shaded per pixel), motion (the "
                    "screen-space stage's motion vectors, --motion)")
        ->capture_default_str();
    cmd->add_option("--exposure", a->exposure, "Display exposure in stops")->capture_default_str();
    cmd->add_option("--time", a->time, "Scene time to render (seconds; default: the scene's)");
    cmd->add_option("--fps", a->fps, "Frames per second of --play and of the timeline's steps")
        ->capture_default_str();

    group("Texture space");
    cmd->add_option("--shading", a->shading, "hit or texture (cache AO / diffuse indirect)")
        ->capture_default_str();
    cmd->add_option("--filter", a->filter,
                    std::string("Texture-space filter: ") + TextureFilterNames())
        ->capture_default_str();
    cmd->add_option("--filter-radius", a->filterRadius, "Footprint radius r: (2r+1)^2 samples")
        ->capture_default_str();
    cmd->add_option("--footprint", a->footprint,
                    "Filter footprints: visible (texels the frame's camera rays reach), all, or "
                    "auto (visible for AO, all for direct and path)")
        ->capture_default_str();
    cmd->add_option("--lod-bias", a->lodBias, "Shading LOD bias (> 0: coarser)")
        ->capture_default_str();
    cmd->add_option("--sample-cache-mb", a->sampleCacheMb, "Sample cache size (MiB)")
        ->capture_default_str();
    cmd->add_option("--texel-cache-mb", a->texelCacheMb, "Texel cache size (MiB)")
        ->capture_default_str();
    cmd->add_flag("--no-reshade", a->noReshade,
                  "Keep the first frame's cache while the view is still (by default every "
                  "accumulated frame re-shades it, so texture-space noise converges too)");

    group("Screen-space stage");
    cmd->add_option("--denoise", a->denoise,
                    "The screen-space stage on the preview's frames (the path tracer's split, "
                    "diffuse indirect light from the cache with --shading texture): off, spatial, "
                    "baseline, clamp or reliable; auto: reliable for the path integrator at sizes "
                    "where the stage keeps up (up to twice 640x360's pixels), else off")
        ->type_name("METHOD")
        ->capture_default_str();
    cmd->add_flag("--demodulate", a->demodulate,
                  "With --denoise (the default): filter glossy and diffuse indirect light "
                  "divided by their pre-integrated BRDF / albedo, so that the filters do not "
                  "blur textures");
    cmd->add_flag("--no-demodulate", a->noDemodulate,
                  "With --denoise: filter glossy and diffuse indirect light as they are");
    cmd->add_flag("--cached-visibility", a->cachedVisibility,
                  "With --denoise and --shading texture: cache the direct light's visibility in "
                  "texture space too; the stage takes it where it has no history");
    cmd->add_option("--fb-cache", a->fbCache,
                    "With --denoise and texture space: the frame buffers' cached diffuse light "
                    "from the store the camera hits fill (store, the default) or from the "
                    "paper's lazily shaded grid samples (grid); the bench compares both "
                    "unless one is given")
        ->type_name("CACHE");
    cmd->add_option("--fb-budget", a->fbBudget,
                    "With --fb-cache store: one pixel in this many (1, 2, 4, 8, 16) traces its "
                    "diffuse path into the store each frame where the store holds many samples; "
                    "more where it holds few, every pixel where it holds none")
        ->capture_default_str();
    cmd->add_option("--geometry", a->geometry,
                    "quads: every mesh as quads on its limit surface, tessellated up front "
                    "(faster rays on irregular cages, more memory); subdivision: Embree's "
                    "subdivision surfaces, as `texcache render` traces them; auto: quads unless "
                    "they would be over a million; both: --bench --denoise times the "
                    "texture-space frames on each, frame by frame in turn")
        ->check(CLI::IsMember({"auto", "subdivision", "quads", "both"}))
        ->capture_default_str();
    cmd->add_option("--motion", a->motion,
                    "Motion vectors the 'motion' view shows: " + preview::MotionKindKeys())
        ->capture_default_str();

    group("Stereo");
    cmd->add_flag("--stereo", a->stereo,
                  "Both eyes side by side, the right eye from the left eye's texture-space cache "
                  "(converging at the orbit pivot)");
    cmd->add_option("--eye-separation", a->eyeSeparation,
                    "--stereo: distance between the eyes (default: the scene camera's, else 1/30 "
                    "of the distance to the pivot)");

    group("Headless test mode");
    cmd->add_option("--frames", a->frames,
                    "Headless test mode: render N frames along a scripted orbit, then exit");
    cmd->add_option("--screenshot", a->screenshot,
                    "Headless: write what the window shows after the last frame (PNG)");
    cmd->add_flag("--save-camera", a->saveCamera,
                  "Headless: write the camera after the orbit back into the scene file");
    cmd->add_option("--orbit", a->orbit, "Degrees the scripted camera orbits (headless, bench)")
        ->capture_default_str();
    cmd->add_flag("--play", a->play,
                  "Headless: advance the scene time by 1/fps per frame (animated scenes)");

    group("Benchmark");
    cmd->add_flag("--bench", a->bench,
                  "Benchmark (no window): with the stage on (--denoise; auto turns it on for "
                  "path-traced scenes), its frames while orbiting (texture-space vs per-hit "
                  "indirect light, render and stage times, relMSE); with --denoise off, warm "
                  "texture-space AO vs per-hit AO at equal relMSE");
    cmd->add_option("--bench-frames", a->benchFrames, "Bench: timed orbit frames")
        ->capture_default_str();
    cmd->add_flag("--bench-still", a->benchStill,
                  "Bench with the stage: a still view for --bench-frames frames instead of the "
                  "orbit, its denoised relMSE frame by frame (texture space against per hit)");
    cmd->add_flag("--bench-fixed-alpha", a->benchFixedAlpha,
                  "With --bench-still: the stage keeps a moving view's temporal blend (alpha) "
                  "instead of a still view's running mean, to compare the two");
    cmd->add_flag("--bench-equal-error", a->benchEqualError,
                  "Bench with the stage, orbiting: per hit again with 2, 4, 8 spp until its "
                  "denoised relMSE reaches texture space's, and the CPU ratio there");
    cmd->add_option("--specular-samples", a->specularSamples,
                    "Bench with the stage: light samples a pixel of the specular lobe where the "
                    "cache lights the diffuse base (1-32; default 8)");
    cmd->add_option("--reference-spp", a->referenceSpp,
                    "Bench: spp of the reference (default 32 per-hit AO x 16 rays; with --denoise "
                    "128 path traced)");
    cmd->add_option("--bench-out", a->benchOut, "Bench: prefix of the images written")
        ->capture_default_str();
    cmd->callback([a, cmd, &exitCode] {
        a->fpsGiven = cmd->count("--fps") > 0;
        for (const char* o :
             {"--bench-frames", "--bench-still", "--bench-fixed-alpha", "--bench-equal-error",
              "--specular-samples", "--reference-spp", "--bench-out"})
            if (cmd->count(o) > 0) a->benchOnly = o;
        exitCode = RunPreview(*a);
    });
}

}  // namespace texcache::cli
