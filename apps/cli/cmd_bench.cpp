// SPDX-License-Identifier: Apache-2.0
// `texcache bench rays`: the AO integrator's ray throughput against a raw Embree loop
// (rtcIntersect1 + rtcOccluded1) over exactly the same rays, measured in the same process and
// interleaved so that a noisy shared machine affects both alike.
#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>

#include <embree3/rtcore.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include "cli_util.h"
#include "commands.h"
#include "renderer/image/metrics.h"
#include "renderer/integrators/sampling.h"
#include "renderer/render.h"
#include "renderer/scene/camera.h"
#include "renderer/scene/scene_loader.h"

namespace texcache::cli {

namespace {

struct BenchArgs {
    std::string scene = std::string(TEXCACHE_SCENES_DIR) + "/car.json";
    std::string resolution = "640x360";
    int aoSamples = 4;
    int spp = 1;
    int repeats = 5;
    int threads = 0;
};

/// Every ray the AO integrator casts (renderer's RecordAoRays: the same sampling code, seeds and
/// order), in Embree's layout.
void RecordRtcAoRays(const RenderScene& rs, const RenderOptions& opt, std::vector<RTCRay>* cam,
                     std::vector<RTCRay>* occ) {
    auto toRtc = [](const Ray& r) {
        RTCRay q{};
        q.org_x = r.org.x, q.org_y = r.org.y, q.org_z = r.org.z;
        q.dir_x = r.dir.x, q.dir_y = r.dir.y, q.dir_z = r.dir.z;
        q.tnear = r.tnear, q.tfar = r.tfar, q.time = r.time, q.mask = 0xFFFFFFFFu;
        return q;
    };
    std::vector<Ray> c, o;
    RecordAoRays(rs, opt, &c, &o);
    cam->reserve(c.size()), occ->reserve(o.size());
    for (const Ray& r : c) cam->push_back(toRtc(r));
    for (const Ray& r : o) occ->push_back(toRtc(r));
}

/// Traces the recorded rays with the plain Embree API, parallel over the same TBB scheduler.
double RawLoop(RTCScene scene, const std::vector<RTCRay>& cam, const std::vector<RTCRay>& occ) {
    const double t0 = NowSeconds();
    std::atomic<unsigned> sink{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, cam.size(), 1024), [&](const auto& r) {
        _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
        _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        unsigned hits = 0;
        for (size_t i = r.begin(); i < r.end(); ++i) {
            RTCRayHit rh;
            rh.ray = cam[i];
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, &ctx, &rh);
            hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        }
        sink += hits;
    });
    tbb::parallel_for(tbb::blocked_range<size_t>(0, occ.size(), 1024), [&](const auto& r) {
        _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
        _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        unsigned blocked = 0;
        for (size_t i = r.begin(); i < r.end(); ++i) {
            RTCRay q = occ[i];
            rtcOccluded1(scene, &ctx, &q);
            blocked += q.tfar < 0.0f;
        }
        sink += blocked;
    });
    return NowSeconds() - t0;
}

/// AO render options shared by the benchmarks, checked like the render command's.
RenderOptions AoBenchOptions(const Scene& scene, const std::string& resolution, int spp,
                             int aoSamples, int repeats) {
    RenderOptions o;
    o.integrator = IntegratorKind::AO;
    ParseResolution(resolution, &o.width, &o.height);
    o.spp = CheckRange("--spp", spp, 1, 4096);
    o.aoSamples = CheckRange("--ao-samples", aoSamples, 1, 1024);
    o.aoDistance = scene.settings.aoDistance;
    o.seed = scene.settings.seed;
    o.frameTime = scene.settings.time;
    o.progress = false;
    // The raw loop traces every camera ray: so does the integrator here, even where it could
    // tell that a tile's rays miss (RenderOptions::cullMissingPixels).
    o.cullMissingPixels = false;
    CheckRange("--repeats", repeats, 1, 100);
    return o;
}

int RunBench(const BenchArgs& a) {
    std::vector<std::string> warnings;
    Scene scene = LoadSceneOrObj(a.scene, &warnings);
    const RenderOptions opt = AoBenchOptions(scene, a.resolution, a.spp, a.aoSamples, a.repeats);
    std::unique_ptr<tbb::global_control> limit;
    if (a.threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      CheckRange("--threads", a.threads, 1, 4096));
    RenderSceneOptions ro;
    ro.needLights = ro.needEnvironment = false;
    ro.threads = a.threads;
    RenderScene rs(scene, ro);

    std::vector<RTCRay> cam, occ;
    RecordRtcAoRays(rs, opt, &cam, &occ);
    const double rays = double(cam.size() + occ.size());
    std::printf("scene %s, %dx%d, %d spp, %d AO rays per hit: %zu camera + %zu occlusion rays\n",
                a.scene.c_str(), opt.width, opt.height, opt.spp, opt.aoSamples, cam.size(),
                occ.size());

    Render(rs, opt);                                             // warm-up
    RawLoop(static_cast<RTCScene>(rs.EmbreeScene()), cam, occ);  // warm-up
    double bestIntegrator = 1e30, bestRaw = 1e30;
    for (int i = 0; i < a.repeats; ++i) {
        const RenderResult r = Render(rs, opt);
        if (double(r.stats.TotalRays()) != rays)
            std::fprintf(stderr, "bench: warning: integrator cast %llu rays, recording has %.0f\n",
                         (unsigned long long)r.stats.TotalRays(), rays);
        bestIntegrator = std::min(bestIntegrator, r.stats.seconds);
        bestRaw = std::min(bestRaw, RawLoop(static_cast<RTCScene>(rs.EmbreeScene()), cam, occ));
    }
    const double integratorRate = rays / bestIntegrator * 1e-6, rawRate = rays / bestRaw * 1e-6;
    std::printf("AO integrator      : %8.3f Mrays/s (best of %d: %.4f s)\n", integratorRate,
                a.repeats, bestIntegrator);
    std::printf("raw Embree loop    : %8.3f Mrays/s (best of %d: %.4f s)\n", rawRate, a.repeats,
                bestRaw);
    std::printf("integrator / raw   : %8.1f %% (goal >= 70 %%)\n",
                100.0 * integratorRate / rawRate);
    return 0;
}

struct CacheBenchArgs {
    std::string scene = std::string(TEXCACHE_SCENES_DIR) + "/car.json";
    std::string resolution = "640x360";
    int aoSamples = 4;
    int spp = 4;
    int referenceSpp = 512;
    int repeats = 3;
    double texelCacheMb = 64.0;
    bool warmOnly = false;
    std::string out = "out/bench_cache";
};

int RunCacheBench(const CacheBenchArgs& a) {
    std::vector<std::string> warnings;
    Scene scene = LoadSceneOrObj(a.scene, &warnings);
    const RenderOptions o = AoBenchOptions(scene, a.resolution, a.spp, a.aoSamples, a.repeats);
    CheckRange("--reference-spp", a.referenceSpp, 1, 1 << 16);
    // The images go beside the prefix; make its directory (out/ by default) like an experiment
    // would.
    if (const auto dir = std::filesystem::path(a.out).parent_path(); !dir.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(dir, ec);
        if (ec)
            throw InputError("--out",
                             "cannot create directory '" + dir.string() + "': " + ec.message());
    }
    RenderSceneOptions ro;
    ro.needLights = ro.needEnvironment = false;
    RenderScene rs(scene, ro);
    std::printf("scene %s, %dx%d, %d spp, %d AO rays per hit / per cached sample\n",
                a.scene.c_str(), o.width, o.height, o.spp, o.aoSamples);

    // 1. Warm-cache frame against the same frame with the cached term replaced by a constant.
    RenderOptions tex = o;
    tex.texture.enabled = true;
    tex.texture.filter = TextureFilterKind::Normal;
    tex.texture.cache.texelCacheBytes =
        size_t(CheckRange("--texel-cache-mb", a.texelCacheMb, 1.0, 65536.0) * (1 << 20));
    TextureSpaceCache cache(rs, tex.texture);
    RenderResult first = Render(rs, tex, &cache);  // cold: fills the caches
    Render(rs, tex, &cache);                       // a second frame settles multi-choice placements
    RenderOptions constant = tex;
    constant.texture.constantTerm = 0.5f;
    // Interleaved, so both see the same machine noise; the ratio is of CPU time (all threads),
    // which a busy machine inflates far less than wall time.
    double tConst = 1e30, tWarm = 1e30, cpuConst = 1e30, cpuWarm = 1e30;
    RenderResult warm;
    for (int i = 0; i < a.repeats; ++i) {
        const RenderResult c = Render(rs, constant, &cache);
        tConst = std::min(tConst, c.stats.seconds),
        cpuConst = std::min(cpuConst, c.stats.cpuSeconds);
        warm = Render(rs, tex, &cache);
        tWarm = std::min(tWarm, warm.stats.seconds),
        cpuWarm = std::min(cpuWarm, warm.stats.cpuSeconds);
    }
    std::printf(
        "cold frame (fills caches)    : %8.4f s, %llu samples shaded, texel hit rate %.1f%%\n",
        first.stats.seconds, (unsigned long long)first.stats.cache.samplesShaded,
        100.0 * first.stats.cache.TexelHitRate());
    const CacheStats& ws = warm.stats.cache;
    std::printf(
        "warm frame (texel hits)      : %8.4f s (CPU %.4f s), texel hit rate %.2f%% (%llu "
        "misses, %llu evictions, %llu reconstructed beside them, %llu samples shaded)\n",
        tWarm, cpuWarm, 100.0 * ws.TexelHitRate(), (unsigned long long)ws.texelMisses,
        (unsigned long long)ws.texelEvictions, (unsigned long long)ws.texelsPrefiltered,
        (unsigned long long)ws.samplesShaded);
    std::printf("constant term (no lookup)    : %8.4f s (CPU %.4f s)\n", tConst, cpuConst);
    std::printf("warm / constant              : %8.3f x CPU, %.3f x wall (goal <= 1.15)\n",
                cpuWarm / cpuConst, tWarm / tConst);
    if (a.warmOnly) return 0;

    // 2. Equal time: texture-space AO (trivial filter, cold cache) against per-hit AO given the
    //    same wall-clock time, both against a high-sample per-hit reference.
    RenderOptions ref = o;
    ref.spp = a.referenceSpp;
    ref.progress = true;
    std::printf("reference: per-hit AO, %d spp ...\n", ref.spp);
    const RenderResult reference = Render(rs, ref);
    // Two texture-space configurations with the same world-space filter footprint: the paper's
    // 13x13 normal filter at the eq. 1 level, and a 7x7 one at half the shading rate (LOD bias 1,
    // Sec. 6.2) with more rays per sample and more camera samples (they mostly hit cached texels).
    struct Config {
        const char* name;
        int radius, aoSamples, spp;
        float lodBias;
    };
    const Config configs[] = {{"normal 13x13, lod 0", 6, o.aoSamples, o.spp, 0.0f},
                              {"normal 7x7,   lod 1", 3, 2 * o.aoSamples, 4 * o.spp, 1.0f}};
    WriteImage(a.out + "_ref.png", reference.beauty);
    int index = 0;
    for (const Config& cfg : configs) {
        RenderOptions t = tex;
        t.texture.radius = cfg.radius;
        t.aoSamples = cfg.aoSamples;
        t.spp = cfg.spp;
        t.texture.cache.lodBias = cfg.lodBias;
        RenderResult texResult;
        double tTex = 1e30;
        for (int i = 0; i < a.repeats; ++i) {
            TextureSpaceCache fresh(rs, t.texture);  // cold each time: the whole cost is counted
            RenderResult r = Render(rs, t, &fresh);
            if (r.stats.seconds < tTex) tTex = r.stats.seconds, texResult = std::move(r);
        }
        RenderOptions hit = o;
        hit.spp = 1 << 16;
        hit.seconds = float(tTex);
        const RenderResult hitResult = Render(rs, hit);
        const double eTex = RelMSE(texResult.beauty, reference.beauty);
        const double eHit = RelMSE(hitResult.beauty, reference.beauty);
        std::printf("texture-space AO (%s, %d rays/sample, %2d spp): %.4f s, relMSE %.5f\n",
                    cfg.name, cfg.aoSamples, cfg.spp, tTex, eTex);
        std::printf("per-hit AO, same time (%d rays/hit, %3d spp)          : %.4f s, relMSE %.5f\n",
                    o.aoSamples, hitResult.stats.sppDone, hitResult.stats.seconds, eHit);
        std::printf("  -> per-hit relMSE / texture-space relMSE = %.2f (> 1: texture space wins)\n",
                    eHit / eTex);
        const std::string suffix = "_" + std::to_string(index++);
        WriteImage(a.out + "_texture" + suffix + ".png", texResult.beauty);
        WriteImage(a.out + "_hit" + suffix + ".png", hitResult.beauty);
    }
    std::printf("wrote %s_ref.png, %s_{texture,hit}_{0,1}.png\n", a.out.c_str(), a.out.c_str());
    return 0;
}

}  // namespace

void AddBenchCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<BenchArgs>();
    CLI::App* bench =
        app.add_subcommand("bench", "Benchmarks (ratios against a baseline in the same run)");
    bench->require_subcommand(1);
    CLI::App* rays = bench->add_subcommand(
        "rays", "AO integrator rays/s vs a raw rtcIntersect1/rtcOccluded1 loop");
    rays->add_option("scene", args->scene, "Scene file or OBJ")->capture_default_str();
    rays->add_option("--resolution", args->resolution, "Image size WxH")->capture_default_str();
    rays->add_option("--ao-samples", args->aoSamples, "AO rays per hit")->capture_default_str();
    rays->add_option("--spp", args->spp, "Camera samples per pixel")->capture_default_str();
    rays->add_option("--repeats", args->repeats, "Timed repetitions (best is reported)")
        ->capture_default_str();
    rays->add_option("--threads", args->threads, "Worker threads (0 = all)");
    rays->callback([args, &exitCode] { exitCode = RunBench(*args); });

    auto cargs = std::make_shared<CacheBenchArgs>();
    CLI::App* cache = bench->add_subcommand(
        "cache",
        "Warm-cache frame vs a constant term, and texture-space vs per-hit AO at equal time");
    cache->add_option("scene", cargs->scene, "Scene file or OBJ")->capture_default_str();
    cache->add_option("--resolution", cargs->resolution, "Image size WxH")->capture_default_str();
    cache->add_option("--ao-samples", cargs->aoSamples, "AO rays per hit / per cached sample")
        ->capture_default_str();
    cache->add_option("--spp", cargs->spp, "Camera samples per pixel")->capture_default_str();
    cache->add_option("--reference-spp", cargs->referenceSpp, "Samples of the per-hit reference")
        ->capture_default_str();
    cache->add_option("--repeats", cargs->repeats, "Timed repetitions (best is reported)")
        ->capture_default_str();
    cache->add_flag("--warm-only", cargs->warmOnly,
                    "Only the warm-frame comparison (skips the equal-time renders and reference)");
    cache->add_option("--out", cargs->out, "Prefix of the images written")->capture_default_str();
    cache->add_option("--texel-cache-mb", cargs->texelCacheMb, "Texel cache size (MiB)")
        ->capture_default_str();
    cache->callback([cargs, &exitCode] { exitCode = RunCacheBench(*cargs); });

    AddBenchPeerCommand(*bench, exitCode);
}

}  // namespace texcache::cli
