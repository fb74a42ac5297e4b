// SPDX-License-Identifier: Apache-2.0
// What the screen-space stage's tests (screen_space*_test.cpp) share: the methods, one BRDF table,
// and synthetic scenes (testing/screen_space_scene.h) of a ground, boxes, a sphere and walls.
#pragma once
#include <memory>
#include <vector>

#include "screen_space/brdf_table.h"
#include "screen_space/screen_denoiser.h"
#include "testing/screen_space_scene.h"

namespace texcache::test {

inline constexpr screen::Method kAllMethods[] = {
    screen::Method::SpatialOnly, screen::Method::Baseline, screen::Method::BaselineClamp,
    screen::Method::Reliable};
inline constexpr screen::Method kTemporal[] = {
    screen::Method::Baseline, screen::Method::BaselineClamp, screen::Method::Reliable};

inline std::shared_ptr<const screen::BrdfPreintegration> SharedBrdf() {
    static auto table = std::make_shared<const screen::BrdfPreintegration>();
    return table;
}

inline SynthObject Ground(int id = 0, glm::vec3 albedo = glm::vec3(0.6f)) {
    SynthObject o;
    o.kind = SynthObject::Kind::Plane;
    o.id = id;
    o.a = glm::vec3(0.0f), o.b = glm::vec3(0.0f, 1.0f, 0.0f);
    o.albedo = albedo;
    return o;
}
inline SynthObject Box(int id, glm::vec3 lo, glm::vec3 hi, glm::vec3 velocity = glm::vec3(0.0f)) {
    SynthObject o;
    o.kind = SynthObject::Kind::Box;
    o.id = id, o.a = lo, o.b = hi, o.velocity = velocity;
    o.albedo = glm::vec3(0.8f, 0.3f, 0.2f);
    return o;
}

// A camera looking straight down -z at a wall (plane z = 0) from z = d.
inline SynthScene WallScene(int w, int h) {
    SynthScene sc;
    sc.width = w, sc.height = h;
    sc.eye = glm::vec3(0.0f, 0.0f, 5.0f), sc.target = glm::vec3(0.0f, 0.0f, 0.0f);
    SynthObject wall;
    wall.kind = SynthObject::Kind::Plane;
    wall.id = 0, wall.a = glm::vec3(0.0f), wall.b = glm::vec3(0.0f, 0.0f, 1.0f);
    sc.objects.push_back(wall);
    sc.glossy = sc.indirect = false;
    return sc;
}

inline SynthScene FullScene(int w, int h) {
    SynthScene sc;
    sc.width = w, sc.height = h;
    sc.lightRadius = 0.3f;
    sc.objects.push_back(Ground(0));
    SynthObject floorGloss = Ground(0);
    sc.objects[0].f0 = glm::vec3(0.6f);
    sc.objects[0].roughness = 0.1f, sc.objects[0].roughness2 = 0.5f;
    sc.objects.push_back(Box(1, glm::vec3(-1.5f, 0.0f, -0.5f), glm::vec3(-0.5f, 1.0f, 0.5f),
                             glm::vec3(0.05f, 0.0f, 0.0f)));
    SynthObject sph;
    sph.kind = SynthObject::Kind::Sphere;
    sph.id = 2, sph.a = glm::vec3(1.0f, 0.7f, 0.0f), sph.b = glm::vec3(0.7f, 0.0f, 0.0f);
    sph.albedo = glm::vec3(0.2f, 0.7f, 0.3f);
    sc.objects.push_back(sph);
    SynthObject back = Ground(3, glm::vec3(0.7f));
    back.a = glm::vec3(0.0f, 0.0f, -3.0f), back.b = glm::vec3(0.0f, 0.0f, 1.0f);
    sc.objects.push_back(back);
    sc.eyeVelocity = glm::vec3(0.02f, 0.0f, 0.0f);
    sc.lightVelocity = glm::vec3(0.05f, 0.0f, 0.0f);
    (void)floorGloss;
    return sc;
}

inline std::vector<char> GeometryMask(const FrameBuffers& f) {
    std::vector<char> m(f.NumPixels());
    for (size_t i = 0; i < m.size(); ++i) m[i] = f.objectId[i] >= 0;
    return m;
}

}  // namespace texcache::test
