// SPDX-License-Identifier: Apache-2.0
// `texcache render`: render a scene file or a bare OBJ to EXR (+ a tone-mapped PNG beside it).
// This file declares the command's options, in the groups its --help shows, and sends a parsed
// command to the kind of render it asks for (render_command.h lists the files of each kind).
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "job.h"
#include "render_command.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/integrators/product_sampling.h"
#include "renderer/scene/scene_loader.h"
#include "texcache/error.h"

namespace texcache::cli {

namespace {

/// Everything a render does before it renders (the scene read, the options checked, the outputs
/// planned), and then the render to run.
std::function<int()> PrepareRender(const RenderArgs& a) {
    std::vector<std::string> warnings;
    const double tLoad = NowSeconds();
    if (InjectedFailure("read")) throw InputError(a.scene, "cannot read (TEXCACHE_FAIL_RANK)");
    const auto owned = std::make_shared<Scene>(LoadSceneOrObj(a.scene, &warnings));
    Scene& scene = *owned;
    const double loadSeconds = NowSeconds() - tLoad;
    if (Job().Rank() == 0)
        for (const std::string& w : warnings)
            std::fprintf(stderr, "texcache: warning: %s\n", internal::OneLine(w).c_str());
    const bool ranks = Job().Size() > 1;

    // Command-line values override the scene's render settings.
    RenderSettings& s = scene.settings;
    ApplySettings(a, &s, scene.unitScale);
    if (a.demodulate && a.noDemodulate)
        throw InputError("--no-demodulate", "contradicts --demodulate: give one of them");
    if ((a.demodulate || a.noDemodulate) && a.denoise.empty())
        throw InputError(a.demodulate ? "--demodulate" : "--no-demodulate",
                         "applies to the screen-space stage: give --denoise");
    CheckStereoOptions(a);
    WarnIfNothingVisible(a, scene);
    WarnIfUnlit(
        scene, !a.frameBuffers.empty() || !a.denoise.empty() ? IntegratorKind::Path : s.integrator);
    const RenderOptions common = RenderOptionsFrom(s);
    if (!a.frameBuffers.empty() || !a.denoise.empty()) {
        if (ranks && (!a.frameBuffers.empty() || a.frames.empty()))
            throw InputError(a.frameBuffers.empty() ? "--denoise" : "--frame-buffers",
                             a.frameBuffers.empty()
                                 ? "on many ranks splits --frames: give them, or run one rank"
                                 : "runs on one rank: launch it without mpirun");
        if (const std::string why = FrameBufferCameraProblem(scene.camera); !why.empty())
            throw InputError(a.frameBuffers.empty() ? "--denoise" : "--frame-buffers",
                             scene.path + ": " + why);
        // Frame buffers are always the path tracer's split, whatever the scene's integrator, and
        // exactly spp samples (no time budget).
        RenderOptions fbo = common;
        fbo.integrator = IntegratorKind::Path;
        fbo.seconds = 0.0f;
        fbo.texture = ParseTextureOptions(a, LightKinds{});  // the stage's split: direct per hit
        // The frame buffers' renderer caches on the grid only (its caches must not be sized
        // for hits, which never fill them).
        fbo.texture.samples = TextureSamples::Grid;
        SizeCaches(a, &fbo, 1);
        CheckMaterialFilters(scene, fbo);
        CheckRenderMemory(fbo, 1, true, MemoryBudget(a));
        fbo.progress = false;
        int first = 0, last = 0;
        if (!a.frames.empty()) ParseFrames(a.frames, &first, &last);
        const float fps = CheckRange("--fps", a.fps, 1e-3f, 1e4f);
        if (!a.denoise.empty())
            return [=, &a] {
                return RunDenoised(a, *owned, fbo, !a.frames.empty(), first, last, fps);
            };
        return [=, &a] { return RunFrameBuffers(a, *owned, fbo, first, last, fps); };
    }
    RenderOptions opt = common;
    opt.hitSamples = CheckRange("--hit-samples", a.hitSamples, 1, 1 << 16);
    opt.aovs = ParseAovs(a.aovs);
    const VisibilityFilterKind visibility =
        ParseVisibilityFilter(a.visibilityFilter, "--visibility-filter");
    opt.texture = ParseTextureOptions(a, SceneLightKinds(scene));
    SizeCaches(a, &opt, a.stereo ? 2 : 1);
    ParseLightSamplingOptions(a, scene, &opt);
    CheckOptionsUsed(a, opt);
    CheckMaterialFilters(scene, opt);
    CheckRenderMemory(opt, a.stereo ? 2 : 1, false, MemoryBudget(a));
    opt.progress = !a.quiet;
    int first = 0, last = 0;
    float fps = 0.0f;
    if (!a.frames.empty()) {
        ParseFrames(a.frames, &first, &last);
        fps = CheckRange("--fps", a.fps, 1e-3f, 1e4f);
        if (a.overshading) throw InputError("--overshading", "renders one frame: drop --frames");
    }
    if (ranks && (a.stereo || a.overshading))
        throw InputError(a.stereo ? "--stereo" : "--overshading",
                         "runs on one rank: launch it without mpirun");
    if (a.stereo) {
        if (visibility != VisibilityFilterKind::None)
            throw InputError("--visibility-filter", "not with --stereo (yet): drop one of them");
        return [=, &a] { return RunStereo(a, *owned, opt); };
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

    return [=, &a]() mutable {
        const std::unique_ptr<tbb::global_control> limit = ThreadLimit(a.threads);
        if (!a.frames.empty())
            return RunAnimation(a, *owned, opt, visibility, outs, first, last, fps);
        return RunImage(a, *owned, opt, visibility, outs.front(), loadSeconds);
    };
}

int RunRender(const RenderArgs& a) {
    // Over many ranks every rank prepares, and a failure on any (a scene one cannot read) ends
    // the job before anything renders, in one line naming the rank.
    std::function<int()> render;
    OnEveryRank([&] { render = PrepareRender(a); });
    return render();
}

}  // namespace

void AddRenderCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<RenderArgs>();
    CLI::App* cmd = app.add_subcommand("render", "Render a scene file (.json) or a bare OBJ cage");
    cmd->add_option("scene", args->scene, "Scene file (.json) or OBJ control cage (.obj)")
        ->required();
    // Options take the group set last (option_defaults): --help lists them group by group.
    auto group = [cmd](const char* name) { cmd->option_defaults()->group(name); };

    group("Output");
    cmd->add_option("-o,--output", args->output,
                    "Output image (.exr writes a .png beside it; .png only)")
        ->capture_default_str();
    cmd->add_option("--resolution", args->resolution, "Image size WxH, e.g. 1280x720");
    cmd->add_option("--max-memory-mb", args->maxMemoryMb,
                    "Refuse a render expected to need more memory (MiB; default 2048, or "
                    "TEXCACHE_MAX_MEMORY_MB; never more than the memory available)");
    cmd->add_option("--aov", args->aovs,
                    "Extra EXR layers: albedo, normal, depth, ptex, motion, all")
        ->delimiter(',');
    cmd->add_option("--exposure", args->exposure, "PNG exposure in stops");
    cmd->add_flag("--no-png", args->noPng, "Do not write a PNG beside an EXR output");
    cmd->add_flag("-q,--quiet", args->quiet, "No progress bar");
    cmd->add_option("--time", args->time, "Scene time of the frame (shutter open)");
    cmd->add_option("--frames", args->frames,
                    "Animation: render frames A:B (inclusive) or N (0..N-1) at --fps; outputs "
                    "are numbered (a run of # in -o, else name_NNNN.ext)");
    cmd->add_option("--fps", args->fps, "Frames per second of --frames")->capture_default_str();
    cmd->add_option("--warmup-frames", args->warmupFrames,
                    "Over many MPI ranks (each renders a contiguous chunk of --frames): frames "
                    "rendered, not written, before a chunk to rebuild the temporal history (-1: "
                    "enough for the history left out to weigh under 1% at --temporal-alpha)")
        ->capture_default_str();

    group("Sampling");
    cmd->add_option("--spp", args->spp, "Samples per pixel (a cap when --seconds is given)");
    cmd->add_option("--seconds", args->seconds, "Time budget in seconds (progressive passes)");
    cmd->add_option("--integrator", args->integrator, std::string("One of: ") + IntegratorNames());
    cmd->add_option("--max-depth", args->maxDepth, "Path tracer bounce limit");
    cmd->add_option("--ao-samples", args->aoSamples, "AO rays per camera sample");
    cmd->add_option("--ao-distance", args->aoDistance, "AO ray length (world units)");
    cmd->add_option("--hit-samples", args->hitSamples,
                    "Direct/path: light paths continued from each camera hit (same camera rays, "
                    "more shading: isolates shading error)")
        ->capture_default_str();
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
    cmd->add_option("--seed", args->seed,
                    "Random seed, an integer in [0, 18446744073709551615] (same seed, same image "
                    "for any --threads)");
    cmd->add_option("--threads", args->threads, "Worker threads (0 = all cores)");
    cmd->add_option("--tessellation-rate", args->tessellationRate,
                    "Embree subdivision tessellation rate");
    cmd->add_option("--geometry", args->geometry,
                    "subdivision: Embree's subdivision surfaces (grids built per face); quads: "
                    "every mesh as quads on its limit surface, tessellated up front at the "
                    "tessellation rate (the same surface; cheaper rays on irregular cages, about "
                    "twice the memory on huge ones)")
        ->check(CLI::IsMember({"subdivision", "quads"}))
        ->capture_default_str();

    group("Texture space");
    cmd->add_option("--shading", args->shading,
                    "hit: shade every hit; texture: cache AO / diffuse indirect in texture space")
        ->capture_default_str();
    cmd->add_option(
           "--ts-samples", args->tsSamples,
           "Where texture-space AO and diffuse light (path, or direct with "
           "--cached-light all) shade: hits (at the camera's hits, binned per texel of a "
           "coarser level and read back bilinearly), grid (the paper's samples at texel "
           "centres, reconstructed by --filter) or auto (hits unless an option of the grid's "
           "cache is given: --filter, --filter-radius, --footprint, "
           "--temporal-alpha, --stereo-reuse, --overshading, --reference-cache, "
           "--direct-mapped, --sample-cache-mb, --texel-cache-mb, --indirect-samples)")
        ->capture_default_str();
    cmd->add_option(
           "--cached-light", args->cachedLight,
           "Path (and direct) integrator, which diffuse light is cached (diffuse "
           "materials, and the diffuse base of glossy ones; specular lobes stay per "
           "hit): indirect (direct light stays per hit; the direct integrator then "
           "caches its shadows on the grid), all (direct light cached and filtered too: for soft "
           "lighting; blurs hard shadows) or auto (when shaded at the hits: soft lights' "
           "direct light cached too, delta lights' (points, spots and distant lights of no "
           "size: sharp shadows) per hit; on the grid: indirect)")
        ->capture_default_str();
    cmd->add_option("--filter", args->filter,
                    std::string("Texture-space filter: ") + TextureFilterNames())
        ->capture_default_str();
    cmd->add_option("--filter-radius", args->filterRadius,
                    "Footprint radius r: (2r+1)^2 samples (default: the paper's for the filter: "
                    "none 0, normal 6, gaussian 10, regression 8, softshadow 8)");
    cmd->add_option("--footprint", args->footprint,
                    "Filter footprints: visible (only texels the camera rays reach, marked by a "
                    "prepass), all (every texel of the window, as the paper) or auto (visible "
                    "for AO, all for direct and path)")
        ->capture_default_str();
    cmd->add_option("--shadow-samples", args->shadowSamples,
                    "Shadow rays per cached visibility sample (--filter softshadow, "
                    "--cached-visibility)")
        ->capture_default_str();
    cmd->add_option("--indirect-samples", args->indirectSamples,
                    "Paths (and NEE samples) per cached diffuse sample")
        ->capture_default_str();
    cmd->add_option("--pass-spp", args->passSpp,
                    "Progressive texture space: camera samples per pass; each further pass "
                    "re-shades the cache (fresh random numbers, jittered sample positions, "
                    "smaller footprints) so error keeps falling with --spp/--seconds (0: one pass, "
                    "the cache shaded once; samples at the hits, --ts-samples hits, bin a "
                    "render in one pass)")
        ->capture_default_str();
    cmd->add_option("--temporal-alpha", args->temporalAlpha,
                    "Temporal accumulation of texels across --frames: c = (1-A) c + A c_prev "
                    "(paper: 0.7; 0 = off)")
        ->capture_default_str();
    cmd->add_option("--lod-bias", args->lodBias, "Shading LOD bias in mip levels (> 0: coarser)")
        ->capture_default_str();
    cmd->add_option("--sample-cache-mb", args->sampleCacheMb,
                    "Sample cache size (MiB; default: sized to the frame, 4 to 64)");
    cmd->add_option("--texel-cache-mb", args->texelCacheMb,
                    "Texel cache size (MiB; default: sized to the frame, 4 to 64)");
    cmd->add_flag(
        "--direct-mapped", args->directMapped,
        "Strictly direct-mapped texel and sample caches (the paper's; default: three choices per "
        "entry)");

    group("Screen-space stage");
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
                  "With --denoise (the default): filter glossy and diffuse indirect light "
                  "divided by their pre-integrated BRDF / albedo (Zhuang et al. 2021), so that "
                  "the filters do not blur textures");
    cmd->add_flag("--no-demodulate", args->noDemodulate,
                  "With --denoise: filter glossy and diffuse indirect light as they are");
    cmd->add_flag("--cached-visibility", args->cachedVisibility,
                  "With --shading texture and --denoise / --frame-buffers: also cache the direct "
                  "light's visibility in texture space (--shadow-samples rays per sample) and "
                  "let the stage take it where it has no history (disocclusions)");
    cmd->add_option("--visibility-radius", args->visibilityRadius,
                    "With --cached-visibility: its filter's footprint radius (-1: --filter-radius)")
        ->capture_default_str();

    group("Stereo and blur");
    cmd->add_flag("--stereo", args->stereo,
                  "Both eyes of the camera's stereo rig (scene camera 'stereo'), sharing one "
                  "texture-space cache (at the hits: both eyes' hits binned into one store; "
                  "--ts-samples grid: the second eye from the first eye's grid cache): writes "
                  "NAME_left and NAME_right (.exr + .png)");
    cmd->add_option("--eye-separation", args->eyeSeparation,
                    "--stereo: distance between the eyes (scene units; default: the scene's, "
                    "else 1/30 of the convergence distance)");
    cmd->add_option("--convergence", args->convergence,
                    "--stereo: distance of the zero-parallax plane (default: the scene's, else "
                    "the distance to the look-at point)");
    cmd->add_option(
           "--stereo-reuse", args->stereoReuse,
           "--stereo on the grid: what the second eye takes from the first eye's cache: texels "
           "(those it looks up) or neighbour (also a cached texel beside a missing one)")
        ->capture_default_str();
    cmd->add_option("--visibility-filter", args->visibilityFilter,
                    "Primary-visibility filter after shading, for the noise of defocus and "
                    "motion blur: none or layered (filters/visibility_filter.h)")
        ->capture_default_str();

    group("Diagnostics");
    cmd->add_option("--stats", args->statsFile, "Write cache statistics as JSON to FILE");
    cmd->add_flag(
        "--overshading", args->overshading,
        "Also render with unbounded caches and report the extra shading of the bounded ones");
    cmd->add_flag("--reference-cache", args->referenceCache,
                  "Unbounded caches (the overshading baseline)");

    cmd->callback([args, cmd, &exitCode] {
        for (const CLI::Option* o : cmd->get_options())
            if (o->count() > 0) args->given.insert(o->get_name());
        exitCode = RunRender(*args);
    });
}

}  // namespace texcache::cli
