// SPDX-License-Identifier: Apache-2.0
// Google Benchmark of the screen-space stage at 1920x1080 at full resolution (and Reliable at half
// resolution, the default from 1080 rows, and at 640x360 with the preview's 3 a-trous levels): a
// synthetic frame pair (a glossy floor
// with a roughness checkerboard, a diffuse back wall, a moving box, a sphere, a moving soft light,
// a panning camera; every component and motion-vector input filled, cones included) is denoised
// frame 0 -> frame 1 per method, and the time of the frame-1 step is reported with its per-pass
// breakdown (wall ms, as counters; cpu_* the same in process CPU time, all threads: on a shared
// machine the wall time depends on what the other processes leave us, the CPU time much less) and
// the share of the new motion vectors in both.
//
//     build/bin/screen_space_benchmark [--benchmark_filter=reliable]
//
// --smoke runs every benchmark once on frames an eighth of the size (240x135, 80x45): CTest's check
// that the benchmark still runs (its times then mean nothing).
//
//     build/bin/screen_space_benchmark --quality [--width 1920] [--frames 8] [--reference-spp 32]
//
// --quality measures what the stage's settings cost in error instead: the synthetic scene's frames
// 0..frames-1 at 1 spp go through Reliable (demodulation on) once per setting of a fixed list, and
// each line gives the last frame's relMSE and RMSE against a many-sample render of it and the
// stage's mean process CPU ms over the frames after the first (a-trous and temporal apart). It
// exits 1 if a setting leaves more than half the noisy input's relMSE (the stage then does not
// denoise; CTest runs it small as a check).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "screen_space/brdf_table.h"
#include "screen_space/screen_denoiser.h"
#include "testing/screen_space_scene.h"

namespace {

using namespace texcache;
using namespace texcache::screen;

bool gSmoke = false;  // --smoke

test::SynthScene Scene(int width, int height) {
    test::SynthScene sc;
    sc.width = gSmoke ? width / 8 : width, sc.height = gSmoke ? height / 8 : height;
    sc.eye = glm::vec3(0.0f, 2.0f, 6.0f);
    sc.lightRadius = 0.3f;
    sc.lightVelocity = glm::vec3(0.05f, 0.0f, 0.0f);
    sc.eyeVelocity = glm::vec3(0.02f, 0.0f, 0.0f);
    test::SynthObject floor;
    floor.kind = test::SynthObject::Kind::Plane;
    floor.id = 0, floor.b = glm::vec3(0.0f, 1.0f, 0.0f);
    floor.albedo = glm::vec3(0.6f), floor.f0 = glm::vec3(0.5f);
    floor.roughness = 0.1f, floor.roughness2 = 0.4f, floor.checkerPeriod = 0.5f;
    sc.objects.push_back(floor);
    test::SynthObject wall = floor;
    wall.id = 1, wall.a = glm::vec3(0.0f, 0.0f, -3.0f), wall.b = glm::vec3(0.0f, 0.0f, 1.0f);
    wall.f0 = glm::vec3(0.0f), wall.roughness2 = -1.0f;
    sc.objects.push_back(wall);
    test::SynthObject box;
    box.kind = test::SynthObject::Kind::Box;
    box.id = 2, box.a = glm::vec3(-1.5f, 0.0f, -0.5f), box.b = glm::vec3(-0.5f, 1.0f, 0.5f);
    box.velocity = glm::vec3(0.05f, 0.0f, 0.0f), box.albedo = glm::vec3(0.8f, 0.3f, 0.2f);
    sc.objects.push_back(box);
    test::SynthObject sphere;
    sphere.kind = test::SynthObject::Kind::Sphere;
    sphere.id = 3, sphere.a = glm::vec3(1.0f, 0.7f, 0.0f), sphere.b = glm::vec3(0.7f, 0.0f, 0.0f);
    sphere.albedo = glm::vec3(0.2f, 0.7f, 0.3f);
    sc.objects.push_back(sphere);
    return sc;
}

struct Frames {
    FrameBuffers f0, f1;
    std::shared_ptr<const BrdfPreintegration> brdf = std::make_shared<BrdfPreintegration>();
    Frames(int width, int height) {
        const test::SynthScene sc = Scene(width, height);
        f0 = test::SynthRender(sc, 0, 1);
        f1 = test::SynthRender(sc, 1, 1);
    }
};
const Frames& Shared(int width) {
    if (width == 640) {
        static const Frames small(640, 360);
        return small;
    }
    static const Frames f(1920, 1080);
    return f;
}

void Add(StageTimings* sum, const StageTimings& t) {
    sum->prepare += t.prepare, sum->traditionalMotion += t.traditionalMotion;
    sum->reliableMotion += t.reliableMotion, sum->temporal += t.temporal;
    sum->spatial += t.spatial, sum->cleanup += t.cleanup, sum->compose += t.compose;
    sum->total += t.total;
}

// Per-iteration means of every pass (ms) and the new motion vectors' share of the total.
void Report(benchmark::State& state, const std::string& prefix, const StageTimings& sum) {
    using C = benchmark::Counter;
    auto set = [&](const char* name, double v) {
        state.counters[prefix + name] = C(v, C::kAvgIterations);
    };
    set("prepare_ms", sum.prepare);
    set("tradMV_ms", sum.traditionalMotion);
    set("newMV_ms", sum.reliableMotion);
    set("temporal_ms", sum.temporal);
    set("spatial_ms", sum.spatial);
    set("cleanup_ms", sum.cleanup);
    set("compose_ms", sum.compose);
    set("total_ms", sum.total);
    state.counters[prefix + "newMV_share_%"] =
        sum.total > 0.0 ? 100.0 * sum.reliableMotion / sum.total : 0.0;
}

void BM_Stage(benchmark::State& state, Method method, Demodulation demod, int width,
              int atrousLevels, int halfResolutionRows) {
    const Frames& fr = Shared(width);
    DenoiserSettings settings;
    settings.atrousLevels = atrousLevels;
    settings.halfResolutionRows = halfResolutionRows;
    ScreenSpaceDenoiser dn(settings, fr.brdf);
    std::vector<glm::vec3> img;
    // Warm-up: allocates (and first-touches) both sets of guides and histories.
    dn.Denoise(fr.f0, method, demod, &img);
    dn.Denoise(fr.f1, method, demod, &img);
    StageTimings sum, cpu;
    for (auto _ : state) {
        dn.Denoise(fr.f0, method, demod, &img);
        dn.Denoise(fr.f1, method, demod, &img);
        benchmark::DoNotOptimize(img.data());
        state.SetIterationTime(dn.Timings().total * 1e-3);
        Add(&sum, dn.Timings());
        Add(&cpu, dn.CpuTimings());
    }
    Report(state, "", sum);
    Report(state, "cpu_", cpu);
}

// The pre-integrated BRDF table (256x256 entries, 1024 samples each), built once per denoiser.
void BM_BrdfTable(benchmark::State& state) {
    for (auto _ : state) {
        BrdfPreintegration table;
        benchmark::DoNotOptimize(table.Samples());
    }
}

void Register() {
    auto* table = benchmark::RegisterBenchmark("brdf_table/build", BM_BrdfTable)
                      ->Unit(benchmark::kMillisecond);
    if (gSmoke) table->Iterations(1);
    for (Method m :
         {Method::SpatialOnly, Method::Baseline, Method::BaselineClamp, Method::Reliable})
        for (Demodulation d : {Demodulation::Off, Demodulation::On}) {
            const std::string name = std::string("stage/") + MethodName(m) +
                                     (d == Demodulation::On ? "/demod" : "/no-demod");
            auto* b = benchmark::RegisterBenchmark(name.c_str(), BM_Stage, m, d, 1920, 4, 0)
                          ->UseManualTime()
                          ->Unit(benchmark::kMillisecond);
            gSmoke ? b->Iterations(1) : b->MinTime(3.0);
        }
    // Reliable at 1920x1080 with 3 a-trous levels: the level count's share of the 1080p stage
    // (--quality gives what it costs in error).
    auto* levels3 = benchmark::RegisterBenchmark("stage/reliable/demod/3levels", BM_Stage,
                                                 Method::Reliable, Demodulation::On, 1920, 3, 0)
                        ->UseManualTime()
                        ->Unit(benchmark::kMillisecond);
    gSmoke ? levels3->Iterations(1) : levels3->MinTime(3.0);
    // Reliable at 1920x1080 on half the pixels (DenoiserSettings::halfResolutionRows).
    auto* half = benchmark::RegisterBenchmark("stage/reliable/demod/half", BM_Stage,
                                              Method::Reliable, Demodulation::On, 1920, 4, 1)
                     ->UseManualTime()
                     ->Unit(benchmark::kMillisecond);
    gSmoke ? half->Iterations(1) : half->MinTime(3.0);
    auto* small = benchmark::RegisterBenchmark("stage/reliable/demod/640x360", BM_Stage,
                                               Method::Reliable, Demodulation::On, 640, 3, 0)
                      ->UseManualTime()
                      ->Unit(benchmark::kMillisecond);
    gSmoke ? small->Iterations(1) : small->MinTime(3.0);
}

struct QualityCase {
    const char* name;
    DenoiserSettings settings;
};

std::vector<QualityCase> QualityCases() {
    std::vector<QualityCase> cases;
    DenoiserSettings d;
    d.halfResolutionRows = 0;  // full resolution at every size
    cases.push_back({"full resolution, 4 levels (the default below 1080 rows)", d});
    d.atrousLevels = 3;
    cases.push_back({"3 levels", d});
    d.atrousLevels = 2;
    cases.push_back({"2 levels", d});
    d.atrousLevels = DenoiserSettings{}.atrousLevels;
    d.halfResolutionRows = 1;
    cases.push_back({"half resolution (4 levels: 3 at half)", d});
    d.atrousLevels = 3;
    cases.push_back({"half resolution, 3 levels (2 at half)", d});
    return cases;
}

int RunQuality(int width, int frames, int referenceSpp) {
    const test::SynthScene sc = Scene(width, width * 9 / 16);
    std::vector<FrameBuffers> in;
    for (int f = 0; f < frames; ++f) in.push_back(test::SynthRender(sc, f, 3));
    const std::vector<glm::vec3> ref =
        test::SynthRender(sc, frames - 1, 99, referenceSpp).Compose();
    const auto brdf = std::make_shared<BrdfPreintegration>();
    const double inputRel = test::RelMse(in.back().Compose(), ref);
    std::printf("%dx%d, %d frames, reference %d spp; input relMSE %.5f\n", sc.width, sc.height,
                frames, referenceSpp, inputRel);
    std::printf("| setting | relMSE | RMSE | stage cpu ms | a-trous | temporal | wall ms |\n");
    std::printf("|---|---|---|---|---|---|---|\n");
    int failed = 0;
    for (const QualityCase& qc : QualityCases()) {
        ScreenSpaceDenoiser dn(qc.settings, brdf);
        std::vector<glm::vec3> img;
        StageTimings cpu, wall;
        for (int f = 0; f < frames; ++f) {
            dn.Denoise(in[size_t(f)], Method::Reliable, Demodulation::On, &img);
            if (f > 0) Add(&cpu, dn.CpuTimings()), Add(&wall, dn.Timings());
        }
        const double n = std::max(1, frames - 1), rel = test::RelMse(img, ref);
        std::printf("| %s | %.5f | %.5f | %.1f | %.1f | %.1f | %.1f |\n", qc.name, rel,
                    test::Rmse(img, ref), cpu.total / n, cpu.spatial / n, cpu.temporal / n,
                    wall.total / n);
        std::fflush(stdout);
        if (!(rel <= 0.5 * inputRel)) {
            std::fprintf(stderr,
                         "screen_space_benchmark: %s leaves relMSE %.5f of the input's %.5f\n",
                         qc.name, rel, inputRel);
            ++failed;
        }
    }
    return failed ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    for (int i = 1; i < argc; ++i)
        if (std::string_view(argv[i]) == "--quality") {
            int width = 1920, frames = 8, spp = 32;
            for (int j = 1; j + 1 < argc; ++j) {
                const std::string_view k = argv[j];
                if (k == "--width") width = std::atoi(argv[j + 1]);
                if (k == "--frames") frames = std::atoi(argv[j + 1]);
                if (k == "--reference-spp") spp = std::atoi(argv[j + 1]);
            }
            if (width < 16 || frames < 1 || spp < 1) {
                std::fprintf(stderr,
                             "screen_space_benchmark: --quality needs --width >= 16, --frames >= 1 "
                             "and --reference-spp >= 1, got %d, %d, %d\n",
                             width, frames, spp);
                return 2;
            }
            return RunQuality(width, frames, spp);
        }
    // --smoke (see the top of this file); Google Benchmark parses the other arguments.
    char** end = std::remove_if(argv + 1, argv + argc,
                                [](const char* a) { return std::string_view(a) == "--smoke"; });
    gSmoke = end != argv + argc;
    argc = int(end - argv);
    Register();
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
