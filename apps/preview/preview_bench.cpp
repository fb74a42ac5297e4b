// SPDX-License-Identifier: Apache-2.0
// `texcache preview SCENE --bench`: the preview's frame rate while orbiting. With the stage off
// (`--denoise off`), texture-space AO with the trivial filter and a cache kept across frames
// against per-hit AO at the same relMSE; with the stage on (the default for path-traced scenes,
// RunStageBench), its frames with texture-space against per-hit indirect light. Both run the same
// orbit in the same process; relMSE is measured at the orbit's last view against a high-sample
// per-hit reference of that view.
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iterator>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "preview.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/image/metrics.h"
#include "renderer/preview/orbit_camera.h"
#include "renderer/render.h"
#include "renderer/scene/render_scene.h"
#include "renderer/texture_space/texture_space.h"
#include "texcache/error.h"

namespace texcache::preview {

namespace {

struct OrbitRun {
    double fps = 0.0, seconds = 0.0;
    double hitRate = 0.0;  ///< texel hit rate over the timed frames
    uint64_t samplesShaded = 0;
    Image last;  ///< the last view's image
};

/// The bench's scene at its time and the orbit's views: view 0 at the scene camera, view n
/// `orbitDegrees` around it (where relMSE is measured).
struct BenchOrbit {
    Scene scene;  // the RenderScene keeps a reference: SetView's camera edits are seen
    float time = 0.0f;
    int n = 1;
    float degrees = 0.0f;
    OrbitCamera home;
    std::unique_ptr<RenderScene> rs;

    BenchOrbit(const Scene& in, const PreviewSettings& s, const PreviewArgs& args, int frames,
               bool lights)
        : scene(in), time(in.settings.time), n(frames), degrees(args.orbitDegrees) {
        scene.settings.tessellationRate = s.tessellationRate;
        RenderSceneOptions ro;
        ro.frameTime = time;
        ro.tessellateAll = s.limitQuads;
        ro.needLights = ro.needEnvironment = lights;
        rs = std::make_unique<RenderScene>(scene, ro);
        home.FromScene(scene, time);
    }
    void SetView(int i) {
        OrbitCamera c = home;
        c.Orbit(degrees * float(i) / float(n), 0.0f);
        c.ToCamera(&scene.camera);
    }
};

// Per hit's most samples a pixel when it looks for texture space's error (--bench-equal-error),
// doubling them from the preview's.
constexpr int kMaxEqualErrorSpp = 8;

double CpuSeconds() {
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + double(t.tv_nsec) * 1e-9;
}

// The stage's passes as the bench lists them.
constexpr double screen::StageTimings::*kPasses[] = {
    &screen::StageTimings::prepare,        &screen::StageTimings::traditionalMotion,
    &screen::StageTimings::reliableMotion, &screen::StageTimings::temporal,
    &screen::StageTimings::spatial,        &screen::StageTimings::cleanup,
    &screen::StageTimings::compose};
constexpr const char* kPassNames[] = {"prepare", "motion",  "reliable-motion", "temporal",
                                      "a-trous", "cleanup", "compose"};

/// One configuration of the stage bench: frame buffers (texture-space indirect or per hit) and
/// the stage on them, with its times summed over the timed frames.
struct StageRun {
    const char* name;
    bool textureSpace;
    TextureSamples fbCache;                 ///< texture space: the store (Hits) or the grid
    const RenderScene* geometry = nullptr;  ///< another geometry's scene; null: the bench's
    std::unique_ptr<TextureSpaceCache> cache;
    screen::ScreenSpaceDenoiser denoiser;  // the preview's settings (StageSettingsFor)
    screen::FrameBuffers fb;
    std::vector<glm::vec3> image;
    double renderWall = 0.0, renderCpu = 0.0, stageWall = 0.0, stageCpu = 0.0;
    double maxStageWall = 0.0;
    screen::StageTimings passCpu;  ///< each pass's CPU ms, summed over the timed frames
    CacheStats cacheStats;
    std::vector<std::pair<int, double>> stillErrors;  ///< --bench-still: (frames, relMSE)

    StageRun(const char* n, bool tex, int height, TextureSamples fb = TextureSamples::Hits)
        : name(n), textureSpace(tex), fbCache(fb), denoiser(StageSettingsFor(height)) {}
    double Fps(int frames) const { return double(frames) / (renderWall + 1e-3 * stageWall); }
    /// CPU seconds of the timed frames, render and stage.
    double CpuSeconds() const { return renderCpu + 1e-3 * stageCpu; }
};

/// `--bench --denoise METHOD`: the preview's stage frames while orbiting, texture-space shading
/// from a warm cache refreshed frame by frame as the preview does (RefreshParts, eq. 6) against
/// per-hit, each frame rendered as the stage's buffers and denoised; interleaved frame by frame,
/// relMSE of the last view against a path-traced reference. `--bench-still`: the last view for
/// all frames instead (the cache's refresh a running mean), relMSE at 1, 2, 4, ... frames.
int RunStageBench(const Scene& sceneIn, const PreviewSettings& s, const PreviewArgs& args,
                  const BenchArgs& b) {
    BenchOrbit orbit(sceneIn, s, args, b.frames, true);
    const Scene& scene = orbit.scene;
    const RenderScene& rs = *orbit.rs;
    const float time = orbit.time;
    const int n = b.frames;
    auto setView = [&](int i) { orbit.SetView(i); };
    const screen::Method method = s.denoiseMethod;
    const screen::Demodulation demod =
        s.demodulate ? screen::Demodulation::On : screen::Demodulation::Off;
    std::printf(
        "preview bench: %s, %dx%d, path tracer's split + %s stage%s, %s %.1f degrees in %d "
        "frames\n",
        scene.path.c_str(), s.width, s.height, screen::MethodName(method),
        s.demodulate ? " (demodulated)" : "",
        !b.still             ? "orbit of"
        : b.stageRunningMean ? "still view (running mean) at"
                             : "still view (fixed alpha) at",
        args.orbitDegrees, n);

    RenderOptions base;
    base.integrator = IntegratorKind::Path;
    base.width = s.width, base.height = s.height;
    base.spp = s.sppPerFrame;
    base.maxDepth = s.maxDepth;
    base.frameTime = time;
    base.progress = false;
    // As the preview: cones only for a stage that reads them.
    base.frameBufferCones = StageSettingsFor(s.height).indirectCones;
    base.frameBufferShadowPoints =
        StageSettingsFor(s.height).reliableVisibilityOrder == screen::VisibilityOrder::Zeng;
    base.frameBufferPrevPoints = false;

    setView(n);
    RenderOptions refOpt = base;
    refOpt.spp = b.referenceSpp;
    refOpt.seed = 0xC0FFEE;
    refOpt.progress = true;
    const RenderResult ref = Render(rs, refOpt);
    std::printf("reference       : path traced, %d spp, %.1f s\n", refOpt.spp, ref.stats.seconds);

    TextureSpaceOptions tex = TextureOptionsOf(s);
    tex.enabled = true;
    if (b.specularSamples > 0) tex.specularLightSamples = b.specularSamples;
    // Orbit: view 0 untimed (cold cache, lazy tessellation, the BRDF table), then views 1..n in
    // turn. Still: the last view for frames 0..n-1, frame 0 untimed.
    const int last = b.still ? n - 1 : n;
    // One pass: texture space and per hit (at `hitSpp` samples a pixel) frame by frame in turn,
    // so that load from other processes on a shared machine slows both alike.
    // The texture-space runs (the settings' cache first, the other one too with bothCaches),
    // then per hit.
    using Runs = std::vector<std::unique_ptr<StageRun>>;
    // --geometry both: the settings' cache on Embree's subdivision geometry too, the same
    // scene and camera (RenderScene reads the orbit's scene).
    std::unique_ptr<RenderScene> subdivision;
    if (b.bothGeometries) {
        RenderSceneOptions ro;
        ro.frameTime = time;
        ro.tessellateAll = false;
        subdivision = std::make_unique<RenderScene>(scene, ro);
    }
    auto makeRuns = [&] {
        Runs runs;
        const TextureSamples other =
            s.fbCache == TextureSamples::Hits ? TextureSamples::Grid : TextureSamples::Hits;
        for (const TextureSamples fb : {s.fbCache, other}) {
            if (fb == other && !b.bothCaches) continue;
            runs.push_back(std::make_unique<StageRun>(fb == TextureSamples::Hits ? "store" : "grid",
                                                      true, s.height, fb));
        }
        if (subdivision) {
            const bool store = s.fbCache == TextureSamples::Hits;
            runs.push_back(std::make_unique<StageRun>(store ? "store subdiv" : "grid subdiv", true,
                                                      s.height, s.fbCache));
            runs.back()->geometry = subdivision.get();
        }
        runs.push_back(std::make_unique<StageRun>("per hit", false, s.height));
        return runs;
    };
    auto runPass = [&](Runs& runs, int hitSpp) {
        for (auto& r : runs) {
            if (!r->textureSpace) continue;
            TextureSpaceOptions t = tex;
            t.frameBufferSamples = r->fbCache;
            r->cache = std::make_unique<TextureSpaceCache>(r->geometry ? *r->geometry : rs, t);
        }
        for (int i = 0; i <= last; ++i) {
            setView(b.still ? n : i);
            for (auto& run : runs) {
                StageRun& r = *run;
                RenderOptions o = base;
                o.seed = uint64_t(i);
                if (r.textureSpace) {
                    o.texture = r.cache->options();
                    const bool still = b.still && i > 0;
                    r.cache->Refresh(uint32_t(i + 1), RefreshParts(still), still);
                } else {
                    o.spp = hitSpp;
                }
                const double c0 = CpuSeconds();
                const RenderStats st = RenderFrameBuffers(r.geometry ? *r.geometry : rs, o, time,
                                                          &r.fb, r.cache.get());
                const double c1 = CpuSeconds();
                // As the preview does: texture-space frames only (progressive_renderer.cpp).
                r.denoiser.SetStillView(b.still && b.stageRunningMean && r.textureSpace && i > 0);
                r.denoiser.Denoise(r.fb, method, demod, &r.image);
                const int frames = i + 1;
                if (b.still && (frames & (frames - 1)) == 0)
                    r.stillErrors.emplace_back(
                        frames, RelMSE(ToImage(r.image, s.width, s.height), ref.beauty));
                if (i == 0) continue;
                r.renderWall += st.seconds, r.renderCpu += c1 - c0;
                const screen::StageTimings& t = r.denoiser.Timings();
                const screen::StageTimings& tc = r.denoiser.CpuTimings();
                r.stageWall += t.total, r.stageCpu += tc.total;
                for (double screen::StageTimings::*pass : kPasses) r.passCpu.*pass += tc.*pass;
                r.maxStageWall = std::max(r.maxStageWall, t.total);
                r.cacheStats.Merge(st.cache);
            }
        }
    };
    Runs runs = makeRuns();
    runPass(runs, base.spp);
    const int timed = last;  // frames 1..last
    for (const auto& run : runs) {
        const StageRun& r = *run;
        const Image noisy = ToImage(r.fb.Compose(), s.width, s.height);
        const Image img = ToImage(r.image, s.width, s.height);
        std::printf(
            "  %-13s: %5.1f fps (%.1f ms/frame): render %.1f ms (%.1f ms cpu) + stage %.1f ms "
            "(%.1f ms cpu, %.0f %% of the frame, slowest %.1f ms)%s; relMSE %.5f denoised, %.5f "
            "undenoised\n",
            r.name, r.Fps(timed), 1e3 / r.Fps(timed), 1e3 * r.renderWall / timed,
            1e3 * r.renderCpu / timed, r.stageWall / timed, r.stageCpu / timed,
            100.0 * 1e-3 * r.stageWall / (r.renderWall + 1e-3 * r.stageWall), r.maxStageWall,
            r.textureSpace
                ? (", hit rate " +
                   std::to_string(int(std::lround(100.0 * r.cacheStats.TexelHitRate()))) + " %")
                      .c_str()
                : "",
            RelMSE(img, ref.beauty), RelMSE(noisy, ref.beauty));
        std::printf("  %-13s  stage passes, ms cpu a frame:", "");
        for (size_t k = 0; k < std::size(kPasses); ++k)
            std::printf(" %s %.1f", kPassNames[k], r.passCpu.*kPasses[k] / timed);
        std::printf("\n");
        if (b.still) {
            std::printf("  %-13s  denoised relMSE after frames:", "");
            for (const auto& [frames, e] : r.stillErrors) std::printf(" %d: %.5f", frames, e);
            std::printf("\n");
        }
        const std::string stem = b.out + (!r.textureSpace                     ? "_stage_hit"
                                          : r.fbCache == TextureSamples::Grid ? "_stage_grid"
                                                                              : "_stage_texture");
        WriteImage(stem + (r.geometry ? "_subdivision" : "") + ".png", img);
    }
    WriteImage(b.out + "_stage_ref.png", ref.beauty);
    const StageRun& t = *runs.front();
    const StageRun& h = *runs.back();
    if (b.still) {
        for (const auto& r : runs) {
            const double first = r->stillErrors.front().second;
            const double lastErr = r->stillErrors.back().second;
            std::printf(
                "%s still view: denoised relMSE after %d frames / after 1: %.3f (goal <= "
                "0.125) %s\n",
                r->name, r->stillErrors.back().first, lastErr / first,
                lastErr <= first / 8.0 ? "ok" : "MISSED");
        }
    }
    const double frameCpu = t.CpuSeconds(), hitCpu = h.CpuSeconds();
    std::printf(
        "CPU a frame, render + stage: %s %.1f ms, per hit %.1f ms: %.2f of per "
        "hit (goal <= 0.33 at equal denoised relMSE)\n",
        t.name, 1e3 * frameCpu / timed, 1e3 * hitCpu / timed, frameCpu / hitCpu);
    for (const auto& run : runs) {
        if (!run->geometry) continue;
        const StageRun& g = *run;
        std::printf(
            "geometry: %s render CPU a frame %.1f ms on limit quads, %.1f ms on Embree's "
            "subdivision surfaces: %.3f of it; denoised relMSE %.5f and %.5f\n",
            t.name, 1e3 * t.renderCpu / timed, 1e3 * g.renderCpu / timed, t.renderCpu / g.renderCpu,
            RelMSE(ToImage(t.image, s.width, s.height), ref.beauty),
            RelMSE(ToImage(g.image, s.width, s.height), ref.beauty));
    }
    if (b.equalError) {
        const double eTex = RelMSE(ToImage(t.image, s.width, s.height), ref.beauty);
        double eHit = RelMSE(ToImage(h.image, s.width, s.height), ref.beauty);
        double ratio = frameCpu / hitCpu;
        if (eHit <= eTex) {
            std::printf(
                "equal error: per hit at %d spp is at or below texture space's denoised relMSE "
                "already (%.5f against %.5f): texture space costs %.2f of per hit at a higher "
                "error\n",
                base.spp, eHit, eTex, ratio);
        } else {
            // Per hit with twice the samples a pixel until its denoised error reaches texture
            // space's; each pass times both again, and its ratio is the one to compare (the
            // passes may run under different load).
            int spp = base.spp;
            double prevErr = eHit, prevRatio = ratio;
            while (eHit > eTex && spp < kMaxEqualErrorSpp) {
                spp *= 2;
                Runs pass = makeRuns();
                runPass(pass, spp);
                const StageRun& pt = *pass.front();
                const StageRun& ph = *pass.back();
                prevErr = eHit, prevRatio = ratio;
                eHit = RelMSE(ToImage(ph.image, s.width, s.height), ref.beauty);
                ratio = pt.CpuSeconds() / ph.CpuSeconds();
                std::printf(
                    "  per hit at %2d spp: %.1f ms cpu a frame (render + stage), denoised relMSE "
                    "%.5f; texture space in the same pass %.1f ms cpu, %.5f: %.2f of per hit\n",
                    spp, 1e3 * ph.CpuSeconds() / timed, eHit, 1e3 * pt.CpuSeconds() / timed,
                    RelMSE(ToImage(pt.image, s.width, s.height), ref.beauty), ratio);
                std::fflush(stdout);
            }
            if (eHit > eTex) {
                std::printf(
                    "equal error: per hit at %d spp is still above texture space's denoised "
                    "relMSE (%.5f against %.5f): texture space costs %.2f of per hit at %d spp, "
                    "at a lower error (goal <= 0.33 at equal error) %s\n",
                    spp, eHit, eTex, ratio, spp, ratio <= 0.33 ? "ok" : "MISSED");
            } else {
                // Between the last two passes, the ratio at texture space's error exactly: the
                // error taken as a power of the cost (log-log), as noise falls with samples.
                const double f = std::log(eTex / prevErr) / std::log(eHit / prevErr);
                const double atEqual = prevRatio * std::pow(ratio / prevRatio, f);
                std::printf(
                    "equal error: per hit reaches texture space's denoised relMSE %.5f between "
                    "%d and %d spp; texture space costs %.2f of per hit there (%.2f at %d spp) "
                    "(goal <= 0.33) %s\n",
                    eTex, spp / 2, spp, atEqual, ratio, spp, atEqual <= 0.33 ? "ok" : "MISSED");
            }
        }
    }
    std::printf("warm texture-space frame + %s stage: %.1f fps (goal >= 10) %s\n",
                screen::MethodName(method), t.Fps(timed), t.Fps(timed) >= 10.0 ? "ok" : "MISSED");
    std::printf("stage passes: %.1f ms a frame (goal < 25) %s\n", t.stageWall / timed,
                t.stageWall / timed < 25.0 ? "ok" : "MISSED");
    std::printf("wrote %s_stage_{ref,texture,grid,hit%s}.png\n", b.out.c_str(),
                !b.bothGeometries                   ? ""
                : s.fbCache == TextureSamples::Grid ? ",grid_subdivision"
                                                    : ",texture_subdivision");
    return 0;
}

}  // namespace

int RunPreviewBench(const Scene& sceneIn, const PreviewSettings& s, const PreviewArgs& args,
                    const BenchArgs& b) {
    if (const auto dir = std::filesystem::path(b.out).parent_path(); !dir.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(dir, ec);
        if (ec) throw InputError("--bench-out", "cannot create '" + dir.string() + "'");
    }
    if (s.denoise) return RunStageBench(sceneIn, s, args, b);
    BenchOrbit orbitViews(sceneIn, s, args, b.frames, false);
    const Scene& scene = orbitViews.scene;
    const RenderScene& rs = *orbitViews.rs;
    const float time = orbitViews.time;
    const int n = b.frames;
    auto setView = [&](int i) { orbitViews.SetView(i); };

    RenderOptions base;
    base.integrator = IntegratorKind::AO;
    base.width = s.width, base.height = s.height;
    base.spp = 1;
    base.aoSamples = s.aoSamples;
    base.aoDistance = s.aoDistance;
    base.frameTime = time;
    base.progress = false;

    std::printf("preview bench: %s, %dx%d, AO, orbit of %.1f degrees in %d frames\n",
                scene.path.c_str(), base.width, base.height, args.orbitDegrees, n);

    setView(n);
    RenderOptions refOpt = base;
    refOpt.spp = b.referenceSpp;
    refOpt.aoSamples = b.referenceAoSamples;
    refOpt.seed = 0xC0FFEE;  // independent of the tested frames' seeds
    refOpt.progress = true;
    const RenderResult ref = Render(rs, refOpt);
    std::printf("reference       : per-hit AO, %d spp x %d rays, %.1f s\n", refOpt.spp,
                refOpt.aoSamples, ref.stats.seconds);

    // Views 1..n after a cold frame at view 0; frame i gets seed i, as the preview's frames do.
    auto orbit = [&](const RenderOptions& o, TextureSpaceCache* cache) {
        OrbitRun run;
        setView(0);
        Render(rs, o, cache);  // texture space: the cold frame; per hit: warms code and BVH
        CacheStats total;
        for (int i = 1; i <= n; ++i) {
            setView(i);
            RenderOptions f = o;
            f.seed = o.seed + uint64_t(i);
            RenderResult r = Render(rs, f, cache);
            run.seconds += r.stats.seconds;
            total.Merge(r.stats.cache);
            if (i == n) run.last = std::move(r.beauty);
        }
        run.fps = double(n) / run.seconds;
        run.hitRate = total.TexelHitRate();
        run.samplesShaded = total.samplesShaded / uint64_t(n);
        return run;
    };

    // Texture space: the preview's settings (trivial filter by default), one cache for the orbit.
    RenderOptions texOpt = base;
    texOpt.texture = TextureOptionsOf(s);
    texOpt.texture.enabled = true;
    TextureSpaceCache cache(rs, texOpt.texture);
    const OrbitRun tex = orbit(texOpt, &cache);
    const double eTex = RelMSE(tex.last, ref.beauty);
    std::printf(
        "texture space (sets the relMSE to match): filter %s r=%d, %d rays/sample, 1 spp: "
        "%.1f fps (%.1f ms/frame), "
        "hit rate %.2f %%, %llu samples shaded/frame, relMSE %.5f\n",
        args.filterName.c_str(), s.radius, s.aoSamples, tex.fps, 1e3 / tex.fps, 100.0 * tex.hitRate,
        (unsigned long long)tex.samplesShaded, eTex);

    // Per hit: the fewest AO rays per hit (1 spp: a camera ray shared by all of them is the
    // cheapest way to buy AO quality) whose relMSE at the last view is no worse.
    setView(n);
    auto hitError = [&](int rays) {
        RenderOptions o = base;
        o.aoSamples = rays;
        o.seed = uint64_t(n);
        return RelMSE(Render(rs, o).beauty, ref.beauty);
    };
    int hi = 1;
    double eHi = hitError(hi);
    while (eHi > eTex && hi < 4096) eHi = hitError(hi *= 2);
    int lo = hi / 2;  // relMSE(lo) > eTex (or lo == 0)
    while (hi - lo > 1 && hi > 8) {
        const int mid = (lo + hi) / 2;
        if (hitError(mid) <= eTex)
            hi = mid;
        else
            lo = mid;
        if (hi - lo <= std::max(1, hi / 16)) break;  // within ~6%: fine enough for a rate
    }
    RenderOptions hitOpt = base;
    hitOpt.aoSamples = hi;

    // The timed run: both orbits frame by frame in turn (a fresh cache, cold frame untimed), so
    // load from other processes on a shared machine slows both alike.
    OrbitRun tex2, hit;
    {
        TextureSpaceCache fresh(rs, texOpt.texture);
        setView(0);
        Render(rs, texOpt, &fresh);
        Render(rs, hitOpt);
        CacheStats total;
        for (int i = 1; i <= n; ++i) {
            setView(i);
            RenderOptions t = texOpt, h = hitOpt;
            t.seed = h.seed = uint64_t(i);
            RenderResult rt = Render(rs, t, &fresh);
            RenderResult rh = Render(rs, h);
            tex2.seconds += rt.stats.seconds;
            hit.seconds += rh.stats.seconds;
            total.Merge(rt.stats.cache);
            if (i == n) tex2.last = std::move(rt.beauty), hit.last = std::move(rh.beauty);
        }
        tex2.fps = double(n) / tex2.seconds;
        hit.fps = double(n) / hit.seconds;
        tex2.hitRate = total.TexelHitRate();
        tex2.samplesShaded = total.samplesShaded / uint64_t(n);
    }
    const double eTex2 = RelMSE(tex2.last, ref.beauty);
    const double eHit = RelMSE(hit.last, ref.beauty);
    std::printf("interleaved run (%d frames each):\n", n);
    std::printf("  texture space : %6.1f fps (%.1f ms/frame), hit rate %.2f %%, relMSE %.5f\n",
                tex2.fps, 1e3 / tex2.fps, 100.0 * tex2.hitRate, eTex2);
    std::printf("  per hit       : %6.1f fps (%.1f ms/frame), %d rays/hit, relMSE %.5f\n", hit.fps,
                1e3 / hit.fps, hi, eHit);
    const double ratio = tex2.fps / hit.fps;
    std::printf("texture space / per hit frame rate at equal relMSE: %.2f x (goal >= 3) %s\n",
                ratio, ratio >= 3.0 ? "ok" : "MISSED");
    std::printf("warm texture-space frame rate: %.1f fps (goal >= 10) %s\n", tex2.fps,
                tex2.fps >= 10.0 ? "ok" : "MISSED");
    WriteImage(b.out + "_ref.png", ref.beauty);
    WriteImage(b.out + "_texture.png", tex2.last);
    WriteImage(b.out + "_hit.png", hit.last);
    std::printf("wrote %s_{ref,texture,hit}.png\n", b.out.c_str());
    return 0;
}

}  // namespace texcache::preview
