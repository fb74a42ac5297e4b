// SPDX-License-Identifier: Apache-2.0
// `texcache render --frame-buffers DIR` and `--denoise METHOD`: the path tracer's decomposition
// for the screen-space stage, rendered frame by frame (1 spp unless --spp, the texture-space
// cache kept across frames), either written as multi-layer EXRs (DIR/frame_NNNN.exr, + the
// composed image as a PNG) or denoised in memory by one ScreenSpaceDenoiser that keeps its
// history across the frames and written as images (numbered with --frames, like a plain
// animation). Outputs go to temporary files renamed once complete.
#include <cstdio>
#include <filesystem>

#include "render_command.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/render_policy.h"
#include "screen_space/screen_denoiser.h"

namespace texcache::cli {

namespace {

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

/// Renders the frame buffers of frames first..last (the texture-space cache, if any, kept across
/// them) and hands each to `body(f, options, stats, buffers)`; returns the seconds spent.
template <class Body>
double ForEachFrameBuffers(const RenderArgs& a, const Scene& scene, const RenderOptions& opt,
                           int first, int last, float fps, Body&& body) {
    const std::unique_ptr<tbb::global_control> limit = ThreadLimit(a.threads);
    RenderSceneOptions ro;
    ro.threads = a.threads;
    AnimationFrames frames(scene, ro, opt, fps, kCacheSizeOptions);
    screen::FrameBuffers fb;
    double total = 0.0;
    for (int f = first; f <= last; ++f) {
        const double tf = NowSeconds();
        frames.Pose(f);
        const RenderOptions& fo = frames.Options();
        const RenderStats st =
            RenderFrameBuffers(frames.PosedScene(), fo, frames.PreviousTime(), &fb, frames.Cache());
        body(f, fo, st, fb, tf);
        total += NowSeconds() - tf;
    }
    return total;
}

}  // namespace

int RunFrameBuffers(const RenderArgs& a, const Scene& scene, RenderOptions opt, int first, int last,
                    float fps) {
    const char* opt_ = "--frame-buffers";
    CheckDecompositionOptions(a, opt_, "writes every buffer already");
    if (a.Given("--output")) throw InputError(opt_, "names the output directory: drop -o/--output");
    if (!a.Given("--spp")) opt.spp = 1;  // the real-time setting the buffers are for
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

int RunDenoised(const RenderArgs& a, const Scene& scene, RenderOptions opt, bool animated,
                int first, int last, float fps) {
    const char* opt_ = "--denoise";
    const screen::Method method = screen::ParseMethodKey(a.denoise, "--denoise");
    CheckDecompositionOptions(a, opt_, "writes the denoised image only");
    if (!a.frameBuffers.empty()) throw InputError(opt_, "cannot be combined with --frame-buffers");
    if (!animated && method != screen::Method::SpatialOnly)
        throw InputError(opt_, "method '" + a.denoise +
                                   "' reuses the previous frame: give --frames A:B (or use "
                                   "--denoise spatial for a single frame)");
    if (!a.Given("--spp")) opt.spp = 1;  // the real-time setting the stage is for
    // Plan and check every frame's outputs first: a bad name fails before anything renders.
    std::vector<OutputPaths> outs;
    for (int f = first; f <= last; ++f)
        outs.push_back(PlanOutputs(animated ? FramePath(a.output, f) : a.output, !a.noPng));
    CheckFiles(scene, outs);

    const screen::Demodulation demod =
        a.noDemodulate ? screen::Demodulation::Off : screen::Demodulation::On;
    screen::ScreenSpaceDenoiser denoiser;
    std::vector<glm::vec3> denoised;
    // Over many ranks each denoises a contiguous chunk of the frames after warm-up frames that
    // rebuild both histories: the stage's (its temporal blend keeps 1 - alpha of the history)
    // and the texture-space cache's (--temporal-alpha).
    const int warm = a.warmupFrames >= 0
                         ? a.warmupFrames
                         : std::max(WarmUpFrames(1.0f - screen::DenoiserSettings{}.alpha),
                                    WarmUpFrames(opt.texture.temporalAlpha));
    const FrameChunk chunk = ChunkOfFrames(first, last, warm);
    const double total = ForEachFrameBuffers(
        a, scene, opt, chunk.from, chunk.last, fps,
        [&](int f, const RenderOptions& fo, const RenderStats& st, const screen::FrameBuffers& fb,
            double) {
            denoiser.Denoise(fb, method, demod, &denoised);
            if (f < chunk.first) return;  // a warm-up frame
            OutputPaths& out = outs[size_t(f - first)];
            AtomicFiles group;
            WriteOutputs(out, ToImage(denoised, fb.width, fb.height), {}, a.exposure, group);
            group.Commit();
            std::printf("frame %d (%d of %d, t = %.3f): %.3f s render, %.1f ms %s%s -> %s\n", f,
                        f - first + 1, last - first + 1, fo.frameTime, st.seconds,
                        denoiser.Timings().total, screen::MethodName(method),
                        a.noDemodulate ? "" : " (demodulated)", out.written.front().c_str());
            std::fflush(stdout);
        });
    std::printf("denoised %d frame%s of %s in %.2f s (%dx%d, %d spp, %s%s)\n", last - first + 1,
                last > first ? "s" : "", scene.path.c_str(), total, opt.width, opt.height, opt.spp,
                screen::MethodName(method), a.noDemodulate ? "" : ", demodulated");
    return 0;
}

}  // namespace texcache::cli
