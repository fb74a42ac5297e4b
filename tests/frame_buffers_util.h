// SPDX-License-Identifier: Apache-2.0
// What the frame-buffer tests (frame_buffers*_test.cpp) share: a small scene in which every
// component of the screen-space stage's input is non-zero somewhere, frame options, and checks.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <type_traits>
#include <vector>

#include "renderer/render.h"
#include "renderer/scene/scene.h"
#include "test_util.h"

namespace texcache::test {

inline bool Finite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
inline bool AllNaN(glm::vec3 v) {
    return std::isnan(v.x) && std::isnan(v.y) && std::isnan(v.z);
}

inline RenderOptions FrameOptions(int w, int h, uint64_t seed = 0) {
    RenderOptions o;
    o.width = w;
    o.height = h;
    o.spp = 1;
    o.seed = seed;
    o.maxDepth = 4;
    o.progress = false;
    return o;
}

/// Frame options with diffuse indirect light from the texture-space cache (4 paths per cached
/// sample, `filter` with `radius`).
inline RenderOptions CachedFrameOptions(int w, int h, TextureFilterKind filter, int radius) {
    RenderOptions o = FrameOptions(w, h);
    o.texture.enabled = true;
    o.texture.filter = filter;
    o.texture.radius = radius;
    o.texture.indirectSamples = 4;
    // Indirect light only in the cache (the scene is soft-lit: with the diffuse lobe's direct
    // light cached too, `indirect` would hold it; TextureSpaceCacheHoldsTheDiffuseLight).
    o.texture.cacheDiffuseLayer = false;
    return o;
}

/// A 4x4 ground plane, a glossy torus on it, a diffuse occluder above it, a quad light and a dim
/// sky: every component is non-zero somewhere.
inline Scene TestScene() {
    Scene s;
    s.meshes.push_back(test::PlaneCage(2.0f));
    s.meshes.push_back(test::LoadMesh("catmark_torus"));
    s.meshes.push_back(test::LoadMesh("catmark_cube"));
    Material ground;
    ground.albedo.value = glm::vec3(0.6f, 0.55f, 0.5f);
    Material glossy;
    glossy.type = Material::Type::GGX;
    glossy.albedo.value = glm::vec3(0.3f, 0.4f, 0.6f);
    glossy.roughness.value = 0.4f;
    glossy.specular.value = glm::vec3(0.3f);
    Material occluder;
    occluder.albedo.value = glm::vec3(0.7f, 0.3f, 0.2f);
    s.materials = {ground, glossy, occluder};
    auto object = [&](int mesh, int material, glm::vec3 t, float scale) {
        Object o;
        o.mesh = mesh;
        o.material = material;
        Keyframe k;
        k.translation = t;
        k.scale = glm::vec3(scale);
        o.transform.keys = {k};
        s.objects.push_back(o);
    };
    object(0, 0, glm::vec3(0.0f), 1.0f);
    object(1, 1, glm::vec3(-0.4f, 0.18f, 0.2f), 0.5f);
    object(2, 2, glm::vec3(0.5f, 0.9f, -0.2f), 0.2f);
    QuadLight q;
    q.corner = glm::vec3(-0.3f, 1.8f, -0.6f);
    q.edge1 = glm::vec3(0.6f, 0.0f, 0.0f);
    q.edge2 = glm::vec3(0.0f, 0.0f, 0.6f);  // edge1 x edge2 points down
    q.radiance = glm::vec3(12.0f);
    s.quadLights.push_back(q);
    EnvironmentLight env;
    env.constant = glm::vec3(0.15f, 0.17f, 0.2f);
    s.environments.push_back(env);
    s.camera.pose.keys = {test::LookAt({0.3f, 2.2f, 3.2f}, {0.0f, 0.2f, 0.0f})};
    s.camera.fovYDegrees = 40.0f;
    return s;
}

/// Makes object `o` move by `delta` per second (keys at t = 0 and 1 from its static pose).
inline void Translate(Scene* s, int o, glm::vec3 delta) {
    Keyframe k0 = s->objects[o].transform.keys.at(0), k1 = k0;
    k0.time = 0.0f;
    k1.time = 1.0f;
    k1.translation += delta;
    s->objects[o].transform.keys = {k0, k1};
}

/// The frame-buffer tests' directory in the test's temporary tree.
inline std::filesystem::path TempDir() {
    const std::filesystem::path d =
        std::filesystem::path(::testing::TempDir()) / "texcache_frame_buffers";
    std::filesystem::create_directories(d);
    return d;
}

/// NaN-aware equality of two buffers.
template <typename T>
inline void ExpectSameBuffer(const std::vector<T>& a, const std::vector<T>& b, const char* name) {
    ASSERT_EQ(a.size(), b.size()) << name;
    for (size_t i = 0; i < a.size(); ++i) {
        if constexpr (std::is_same_v<T, glm::vec3>) {
            for (int k = 0; k < 3; ++k)
                ASSERT_TRUE(a[i][k] == b[i][k] || (std::isnan(a[i][k]) && std::isnan(b[i][k])))
                    << name << " " << i;
        } else {
            ASSERT_TRUE(a[i] == b[i] || (std::isnan(float(a[i])) && std::isnan(float(b[i]))))
                << name << " " << i;
        }
    }
}

}  // namespace texcache::test
