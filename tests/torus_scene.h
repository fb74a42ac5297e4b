// SPDX-License-Identifier: Apache-2.0
// What the texture-space and hit-binning tests (texture_space_test.cpp, hit_binning_test.cpp)
// share: a torus on a plane, rendered small with ambient occlusion or path tracing, and a check
// of the images' range.
#pragma once
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "renderer/render.h"
#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene.h"
#include "test_util.h"

namespace texcache::test {

inline Scene TorusOnPlane() {
    Scene s = OneObjectScene(LoadMesh("catmark_torus"));
    s.meshes.push_back(PlaneCage(4.0f));
    Object plane;
    plane.mesh = 1;
    plane.transform.keys.push_back({});
    plane.transform.keys[0].translation = glm::vec3(0.0f, -0.55f, 0.0f);
    s.objects.push_back(plane);
    s.camera.pose.keys = {LookAt({1.6f, 2.2f, 2.6f}, {0, -0.2f, 0})};
    s.camera.fovYDegrees = 45.0f;
    return s;
}

inline RenderOptions AoOptions(int spp, int aoSamples) {
    RenderOptions o;
    o.integrator = IntegratorKind::AO;
    o.width = 64;
    o.height = 48;
    o.spp = spp;
    o.aoSamples = aoSamples;
    o.aoDistance = 1.0f;
    o.progress = false;
    return o;
}

// AO cached in texture space with filter f.
inline RenderOptions CachedAo(int spp, int aoSamples, TextureFilterKind f) {
    RenderOptions o = AoOptions(spp, aoSamples);
    o.texture.enabled = true;
    o.texture.filter = f;
    return o;
}

// The cages with the hard features hit binning (and its material filters) must survive: a boundary
// and a hole (no neighbour across an edge), n-gons (sub-faces and their adjacency), creases,
// extraordinary vertices.
inline const char* const kHardCages[] = {"catmark_hole_test1", "catmark_nonquads",
                                         "catmark_cube_creases1", "catmark_cubes_infsharp"};

// AO shaded at the camera's hits and binned (TextureSamples::Hits; render.cpp, AoHitsBin).
inline RenderOptions HitsAo(int spp, int aoSamples) {
    RenderOptions o = AoOptions(spp, aoSamples);
    o.texture.enabled = true;
    o.texture.samples = TextureSamples::Hits;
    return o;
}

// The path integrator (2 bounces) with `hitSamples` paths per hit, at the hits' bins when `hits`
// (all of the light binned with `cacheDirect`), on an image `scale` times AoOptions' size.
inline RenderOptions PathOptions(int spp, int hitSamples, bool hits, bool cacheDirect,
                                 int scale = 1) {
    RenderOptions o = AoOptions(spp, 1);
    o.width *= scale, o.height *= scale;
    o.integrator = IntegratorKind::Path;
    o.maxDepth = 2;
    o.hitSamples = hitSamples;
    o.texture.enabled = hits;
    o.texture.samples = TextureSamples::Hits;
    o.texture.cacheDirect = cacheDirect;
    return o;
}

// TorusOnPlane() ready for AO (no lights), built once for the tests that only render it.
inline const RenderScene& TorusAo() {
    static const Scene scene = TorusOnPlane();
    static const RenderScene rs(scene, [] {
        RenderSceneOptions ro;
        ro.needLights = false;
        return ro;
    }());
    return rs;
}

// The image of a render limited to `threads` TBB threads.
inline Image RenderOnThreads(const RenderScene& rs, const RenderOptions& o, int threads) {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, threads);
    return Render(rs, o).beauty;
}

// TorusOnPlane's plane as GGX red paint (roughness 0.3, F0 0.04).
inline void MakePlaneGlossy(Scene* s) {
    Material m;
    m.type = Material::Type::GGX;
    m.albedo.value = glm::vec3(0.5f, 0.1f, 0.05f);
    m.roughness.value = 0.3f;
    s->materials.push_back(m);
    s->objects[1].material = int(s->materials.size()) - 1;
}

/// Whether every channel of every pixel lies in [lo, hi] (the first one that does not, named).
inline ::testing::AssertionResult AllFiniteIn(const Image& img, float lo, float hi) {
    for (size_t i = 0; i < img.data.size(); ++i)
        if (!(img.data[i] >= lo && img.data[i] <= hi))
            return ::testing::AssertionFailure()
                   << "pixel " << i / img.channels << " = " << img.data[i] << " outside [" << lo
                   << ", " << hi << "]";
    return ::testing::AssertionSuccess();
}

}  // namespace texcache::test
