// SPDX-License-Identifier: Apache-2.0
// Google Benchmark of RenderScene::Interact, the shading point made of each ray hit (limit
// derivatives, shading normal, Ptex location, footprint), per camera hit: on the default scene
// and on bundled cages with extraordinary vertices, n-gons, creases and boundaries, on Embree's
// subdivision surfaces and on the limit quads the preview traces (InteractQuads). The hits are
// traced once in the fixture; the loop times Interact alone.
#include <benchmark/benchmark.h>

#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "renderer/scene/camera.h"
#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene_loader.h"

namespace {

using namespace texcache;

struct CameraHit {
    Ray ray;
    RayDifferentials diff;
    Hit hit;
};

// A scene file's camera hits on objects over a 320x180 grid of pixel centres.
struct Hits {
    Scene scene;
    std::unique_ptr<RenderScene> rs;
    std::vector<CameraHit> hits;
    Hits(const std::string& file, bool quads) {
        const std::string dir = TEXCACHE_SOURCE_DIR "/scenes/";
        scene = LoadSceneFile(dir + file, "", nullptr);
        RenderSceneOptions o;
        o.needEnvironment = false;
        o.tessellateAll = quads;
        rs = std::make_unique<RenderScene>(scene, o);
        constexpr int kW = 320, kH = 180;
        const CameraModel cam(scene.camera, 0.0f, kW, kH);
        for (int y = 0; y < kH; ++y)
            for (int x = 0; x < kW; ++x) {
                CameraHit h;
                h.ray = cam.Generate(float(x) + 0.5f, float(y) + 0.5f, glm::vec2(0.5f), &h.diff);
                if (rs->Intersect(h.ray, &h.hit) && h.hit.object >= 0) hits.push_back(h);
            }
    }
};

Hits& Shared(const std::string& file, bool quads) {
    static std::map<std::pair<std::string, bool>, std::unique_ptr<Hits>> scenes;
    auto& h = scenes[{file, quads}];
    if (!h) h = std::make_unique<Hits>(file, quads);
    return *h;
}

void BM_Interact(benchmark::State& state, const std::string& file, bool withDiff, bool quads) {
    const Hits& h = Shared(file, quads);
    if (h.hits.empty()) {
        state.SkipWithError("no camera hits");
        return;
    }
    size_t i = 0;
    float sink = 0.0f;
    for (auto _ : state) {
        const CameraHit& c = h.hits[i];
        const SurfaceInteraction si = h.rs->Interact(c.ray, c.hit, withDiff ? &c.diff : nullptr);
        sink += si.N.x + si.dudx;
        if (++i == h.hits.size()) i = 0;
    }
    benchmark::DoNotOptimize(sink);
    state.SetItemsProcessed(state.iterations());
    state.counters["hits"] = double(h.hits.size());
}

const char* const kScenes[] = {"car.json",
                               "meshes/catmark_xord_interior.obj",
                               "meshes/catmark_nonquads.obj",
                               "meshes/catmark_bishop.obj",
                               "meshes/catmark_cube_creases1.obj",
                               "meshes/catmark_tent_creases1.obj",
                               "meshes/catmark_hole_test1.obj"};

[[maybe_unused]] const bool kRegistered = [] {
    for (const char* file : kScenes) {
        const std::string name = std::string(file).substr(std::string(file).rfind('/') + 1);
        benchmark::RegisterBenchmark(("Interact/" + name).c_str(), BM_Interact, file, false, false);
        benchmark::RegisterBenchmark(("InteractDiff/" + name).c_str(), BM_Interact, file, true,
                                     false);
        benchmark::RegisterBenchmark(("InteractQuads/" + name).c_str(), BM_Interact, file, false,
                                     true);
    }
    return true;
}();

}  // namespace

BENCHMARK_MAIN();
