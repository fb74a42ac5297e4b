// SPDX-License-Identifier: Apache-2.0
// Embedding the cache in your own shader: a toon shader whose ambient occlusion term is shaded,
// filtered and cached in texture space by libtexcache, while the key light stays per hit.
//   embed_cache [scene.json] [out.png]
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cstdio>

#include "renderer/image/image.h"
#include "renderer/integrators/sampling.h"
#include "renderer/scene/camera.h"
#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene_loader.h"
#include "texcache/shading_cache.h"

using namespace texcache;

struct AoSample {  // what a sample stores: the shaded term and the normal the filter compares
    float ao;
    glm::vec3 n;
};

int main(int argc, char** argv) try {
    std::vector<std::string> warnings;
    const Scene scene = LoadScene(argc > 1 ? argv[1] : TEXCACHE_SCENES_DIR "/car.json", &warnings);
    RenderSceneOptions ro;
    ro.needLights = false;
    const RenderScene rs(scene, ro);

    // 1. A cache with one mesh per object (texels of 1/2048 of the object's size at mip 0).
    ShadingCache<AoSample, float> cache(CacheSettings{});
    for (const Object& o : scene.objects) cache.AddMesh(scene.meshes[o.mesh], 1.0f / 2048.0f);

    // 2. The sample shader: 16 AO rays from the limit surface at a texel centre.
    auto shadeAo = [&](const SampleRequest& r) {
        SurfaceSample s;
        rs.EvalSurface(r.mesh, {r.face, r.u, r.v}, 0.0f, &s);
        Rng rng(r.key.Pack(), 0);
        const Frame f = Frame::FromZ(s.N);
        int open = 0;
        for (int i = 0; i < 16; ++i) {
            Ray ray{s.P + 1e-3f * s.N, f.FromLocal(SampleCosineHemisphere(rng.Next2D()))};
            open += !rs.Occluded(ray);
        }
        return AoSample{open / 16.0f, s.N};
    };
    // 3. The filter: average the footprint's samples whose normals are within cos > 0.9.
    auto filter = [](const FilterInput<AoSample>& in) {
        float sum = 0.0f, n = 0.0f;
        for (const AoSample& s : in.samples)
            if (glm::dot(s.n, in.samples[in.centre].n) > 0.9f) sum += s.ao, n += 1.0f;
        return sum / n;
    };

    // 4. The shader at each camera hit: per-hit key light times the cached AO.
    const int W = 640, H = 360;
    const CameraModel camera(scene.camera, 0.0f, W, H);
    Image image(W, H, 3);
    tbb::enumerable_thread_specific<CacheStats> stats;
    const glm::vec3 toLight = glm::normalize(glm::vec3(0.4f, 1.0f, 0.6f));
    tbb::parallel_for(0, H, [&](int y) {
        for (int x = 0; x < W; ++x) {
            RayDifferentials diff;
            const Ray ray = camera.Generate(x + 0.5f, y + 0.5f, {0.5f, 0.5f}, &diff);
            Hit hit;
            if (!rs.Intersect(ray, &hit) || hit.object < 0) continue;
            const SurfaceInteraction si = rs.Interact(ray, hit, &diff);
            const CacheHit h{hit.object, si.ptex.face, si.ptex.u, si.ptex.v,
                             si.dudx,    si.dvdx,      si.dudy,   si.dvdy};
            const float ao = cache.Lookup(h, 6, shadeAo, filter, stats.local());
            const float toon = glm::dot(si.N, toLight) > 0.3f ? 1.0f : 0.55f;  // two-band key light
            const glm::vec3 c = rs.Albedo(si) * toon * (0.3f + 0.7f * ao);
            for (int k = 0; k < 3; ++k) image.At(x, y)[k] = c[k];
        }
    });

    CacheStats total;
    for (const CacheStats& s : stats) total.Merge(s);
    const std::string out = argc > 2 ? argv[2] : "embed_cache.png";
    WriteImage(out, image);
    std::printf("wrote %s: %.1f%% texel hits, %llu samples shaded\n", out.c_str(),
                100.0 * total.TexelHitRate(), (unsigned long long)total.samplesShaded);
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "embed_cache: error: %s\n", e.what());
    return 2;
}
