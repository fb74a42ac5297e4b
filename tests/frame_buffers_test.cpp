// SPDX-License-Identifier: Apache-2.0
// The screen-space stage's input (renderer/frame_buffers_render.h): the camera projects the
// guides onto pixel centres, "prev" points follow their own object's (or light's) motion, the
// shadow ray's blocker exists exactly where the light sample is blocked, the split composes to
// the path tracer's image, the animated scenes render, and the EXR files and the CLI round-trip.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "cli_run.h"
#include "renderer/frame_buffers_render.h"
#include "renderer/metrics.h"
#include "renderer/scene_loader.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;
using screen::FrameBuffers;

bool Finite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
bool AllNaN(glm::vec3 v) {
    return std::isnan(v.x) && std::isnan(v.y) && std::isnan(v.z);
}

RenderOptions FrameOptions(int w, int h, uint64_t seed = 0) {
    RenderOptions o;
    o.width = w;
    o.height = h;
    o.spp = 1;
    o.seed = seed;
    o.maxDepth = 4;
    o.progress = false;
    return o;
}

/// A 4x4 ground plane, a glossy torus on it, a diffuse occluder above it, a quad light and a dim
/// sky: every component is non-zero somewhere.
Scene TestScene() {
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
    glossy.specular = glm::vec3(0.3f);
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
void Translate(Scene* s, int o, glm::vec3 delta) {
    Keyframe k0 = s->objects[o].transform.keys.at(0), k1 = k0;
    k0.time = 0.0f;
    k1.time = 1.0f;
    k1.translation += delta;
    s->objects[o].transform.keys = {k0, k1};
}

// Projecting `position` with `camera` lands on the pixel centre (within 1e-3 px) for a wide and
// a tall raster, and a moving, rotated camera.
TEST(FrameBuffers, PositionProjectsToPixelCentre) {
    for (glm::ivec2 size : {glm::ivec2(40, 24), glm::ivec2(17, 31)}) {
        Scene s = TestScene();
        s.camera.fovYDegrees = size.x > size.y ? 40.0f : 65.0f;
        Keyframe k1 = test::LookAt({-1.0f, 1.2f, 2.0f}, {0.2f, 0.0f, -0.3f});
        k1.time = 2.0f;
        s.camera.pose.keys.push_back(k1);
        RenderSceneOptions ro;
        ro.frameTime = 0.7f;
        RenderScene rs(s, ro);
        RenderOptions o = FrameOptions(size.x, size.y);
        o.frameTime = 0.7f;
        FrameBuffers fb;
        RenderFrameBuffers(rs, o, 0.6f, &fb);
        ASSERT_NO_THROW(fb.Validate("test"));
        int checked = 0;
        for (int y = 0; y < size.y; ++y)
            for (int x = 0; x < size.x; ++x) {
                const glm::vec3 p = fb.position[size_t(y) * size.x + x];
                if (!Finite(p)) continue;
                glm::vec2 r;
                ASSERT_TRUE(fb.camera.Project(p, &r));
                EXPECT_NEAR(r.x, x + 0.5f, 1e-3f) << x << "," << y;
                EXPECT_NEAR(r.y, y + 0.5f, 1e-3f) << x << "," << y;
                ++checked;
            }
        EXPECT_GT(checked, size.x * size.y / 2);
        EXPECT_NEAR(glm::distance(fb.camera.position,
                                  glm::vec3(s.camera.pose.Eval(0.7f)[3])),
                    0.0f, 1e-5f);
        EXPECT_EQ(fb.time, 0.7f);
    }
}

// The primary hit of a translating object moves back by its translation over the frame
// interval; static objects' points stay; a rotating object's normal rotates back.
TEST(FrameBuffers, PrevPositionFollowsObjectMotion) {
    Scene s = TestScene();
    const glm::vec3 velocity(0.8f, 0.0f, -0.4f);  // per second
    Translate(&s, 1, velocity);
    // The occluder spins about +Y at 90 degrees per second.
    Keyframe r0 = s.objects[2].transform.keys[0], r1 = r0;
    r1.time = 1.0f;
    r1.rotation = glm::angleAxis(glm::radians(90.0f), glm::vec3(0, 1, 0));
    s.objects[2].transform.keys = {r0, r1};
    const float t = 0.5f, prev = t - 1.0f / 8.0f;
    RenderSceneOptions ro;
    ro.frameTime = t;
    RenderScene rs(s, ro);
    RenderOptions o = FrameOptions(48, 32);
    o.frameTime = t;
    FrameBuffers fb;
    RenderFrameBuffers(rs, o, prev, &fb);
    const glm::mat3 back(glm::angleAxis(glm::radians(-90.0f * (t - prev)), glm::vec3(0, 1, 0)));
    int moving = 0, still = 0, spinning = 0;
    for (size_t i = 0; i < fb.NumPixels(); ++i) {
        const glm::vec3 p = fb.position[i], pp = fb.prevPosition[i];
        switch (fb.objectId[i]) {
            case 1:  // translating torus: exactly the translation (1e-5 of the scene's size)
                EXPECT_NEAR(glm::distance(pp, p - velocity * (t - prev)), 0.0f, 1e-5f) << i;
                EXPECT_NEAR(glm::distance(fb.prevNormal[i], fb.normal[i]), 0.0f, 1e-5f) << i;
                ++moving;
                break;
            case 0:
                EXPECT_NEAR(glm::distance(pp, p), 0.0f, 1e-5f) << i;
                ++still;
                break;
            case 2: {
                const glm::vec3 c = s.objects[2].transform.keys[0].translation;
                EXPECT_NEAR(glm::distance(pp, c + back * (p - c)), 0.0f, 1e-5f) << i;
                EXPECT_NEAR(glm::distance(fb.prevNormal[i], back * fb.normal[i]), 0.0f, 1e-5f);
                ++spinning;
                break;
            }
            default:
                EXPECT_TRUE(AllNaN(pp)) << i;
        }
    }
    EXPECT_GT(moving, 20);
    EXPECT_GT(still, 100);
    EXPECT_GT(spinning, 5);
}

// At 1 spp, visibility is 0 or 1; blocker, light sample and their prev points are NaN exactly
// where it is 1 and finite where it is 0; the blocker lies on the segment from the shading
// point to the light point, which lies on the quad light.
TEST(FrameBuffers, BlockerExactlyWhereShadowed) {
    Scene s = TestScene();
    s.environments.clear();  // one light: every light sample is a point on the quad
    RenderScene rs(s, {});
    FrameBuffers fb;
    RenderFrameBuffers(rs, FrameOptions(64, 48, 7), -1.0f / 24.0f, &fb);
    const QuadLight& q = s.quadLights[0];
    int shadowed = 0, lit = 0;
    for (size_t i = 0; i < fb.NumPixels(); ++i) {
        const float v = fb.visibility[i];
        ASSERT_TRUE(v == 0.0f || v == 1.0f) << i << ": " << v;
        const glm::vec3 pts[] = {fb.blocker[i], fb.prevBlocker[i], fb.lightSample[i],
                                 fb.prevLightSample[i]};
        if (v == 1.0f) {
            for (glm::vec3 p : pts) EXPECT_TRUE(AllNaN(p)) << i;
            lit += fb.objectId[i] >= 0;
            continue;
        }
        ++shadowed;
        for (glm::vec3 p : pts) ASSERT_TRUE(Finite(p)) << i;
        const glm::vec3 P = fb.position[i], B = fb.blocker[i], L = fb.lightSample[i];
        // On the segment: collinear within 1e-3 of its length, and between the two ends.
        const float len = glm::distance(P, L);
        EXPECT_LT(glm::length(glm::cross(B - P, (L - P) / len)), 1e-3f * len) << i;
        EXPECT_GT(glm::dot(B - P, L - P), 0.0f) << i;
        EXPECT_LT(glm::distance(P, B), len) << i;
        // On the light: the quad's plane and parallelogram.
        const glm::vec3 d = L - q.corner;
        EXPECT_NEAR(d.y, 0.0f, 1e-5f) << i;
        EXPECT_GE(d.x, -1e-5f);
        EXPECT_LE(d.x, 0.6f + 1e-5f);
        EXPECT_GE(d.z, -1e-5f);
        EXPECT_LE(d.z, 0.6f + 1e-5f);
        // Nothing moves in this scene.
        EXPECT_NEAR(glm::distance(fb.prevBlocker[i], B), 0.0f, 1e-5f);
        EXPECT_NEAR(glm::distance(fb.prevLightSample[i], L), 0.0f, 1e-5f);
    }
    EXPECT_GT(shadowed, 100);
    EXPECT_GT(lit, 300);
}

// The blocker of a moving occluder moves back by its translation, the light point of a moving
// light by the light's; a spinning distant light's far point turns with it.
TEST(FrameBuffers, PrevBlockerAndLightFollowTheirOwnMotion) {
    Scene s = TestScene();
    s.environments.clear();
    const glm::vec3 occluderVelocity(1.0f, 0.0f, 0.5f), lightVelocity(0.0f, 0.0f, 0.6f);
    Translate(&s, 2, occluderVelocity);
    // The torus, the only other possible blocker of the ground, leaves the scene.
    s.objects.erase(s.objects.begin() + 1);
    Keyframe l0, l1;
    l1.time = 1.0f;
    l1.translation = lightVelocity;
    s.quadLights[0].transform.keys = {l0, l1};
    const float t = 0.25f, prev = t - 0.1f;
    RenderSceneOptions ro;
    ro.frameTime = t;
    RenderScene rs(s, ro);
    RenderOptions o = FrameOptions(64, 48, 3);
    o.frameTime = t;
    FrameBuffers fb;
    RenderFrameBuffers(rs, o, prev, &fb);
    int checked = 0;
    for (size_t i = 0; i < fb.NumPixels(); ++i) {
        if (fb.visibility[i] != 0.0f || fb.objectId[i] != 0) continue;  // shadows on the ground
        EXPECT_NEAR(glm::distance(fb.prevBlocker[i], fb.blocker[i] - occluderVelocity * 0.1f),
                    0.0f, 1e-5f)
            << i;
        EXPECT_NEAR(
            glm::distance(fb.prevLightSample[i], fb.lightSample[i] - lightVelocity * 0.1f), 0.0f,
            1e-5f)
            << i;
        ++checked;
    }
    EXPECT_GT(checked, 30);

    // A distant light turning about +Z by 20 degrees per second: the far light point is along
    // the light's direction from the blocker, now and (turned back) in the previous frame.
    Scene d = TestScene();
    d.environments.clear();
    d.quadLights.clear();
    DistantLight sun;
    sun.direction = glm::normalize(glm::vec3(0.3f, -1.0f, 0.1f));
    sun.irradiance = glm::vec3(3.0f);
    Keyframe k1;
    k1.time = 1.0f;
    k1.rotation = glm::angleAxis(glm::radians(20.0f), glm::vec3(0, 0, 1));
    sun.transform.keys = {Keyframe{}, k1};
    d.distantLights.push_back(sun);
    RenderScene rsd(d, ro);
    RenderFrameBuffers(rsd, o, prev, &fb);
    const glm::vec3 towardsNow = -glm::normalize(glm::mat3(sun.transform.Eval(t)) * sun.direction);
    const glm::vec3 towardsPrev =
        -glm::normalize(glm::mat3(sun.transform.Eval(prev)) * sun.direction);
    checked = 0;
    for (size_t i = 0; i < fb.NumPixels(); ++i) {
        if (fb.visibility[i] != 0.0f) continue;
        EXPECT_LT(glm::distance(glm::normalize(fb.lightSample[i] - fb.blocker[i]), towardsNow),
                  1e-4f);
        EXPECT_LT(glm::distance(glm::normalize(fb.prevLightSample[i] - fb.prevBlocker[i]),
                                towardsPrev),
                  1e-4f);
        ++checked;
    }
    EXPECT_GT(checked, 30);
}

}  // namespace
}  // namespace texcache
