// SPDX-License-Identifier: Apache-2.0
// The screen-space stage's input (renderer/frame_buffers/frame_buffers_render.h): the camera
// projects the guides onto pixel centres, "prev" points follow their own object's (or light's)
// motion, the shadow ray's blocker exists exactly where the light sample is blocked, the split
// composes to the path tracer's image, the unshadowed shading is low in noise, the diffuse rays'
// radiance lands in the cones, and the buffers do not depend on the thread count.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "frame_buffers_util.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/image/metrics.h"
#include "renderer/integrators/bsdf.h"
#include "screen_space/brdf_table.h"
#include "test_util.h"

namespace texcache {
namespace {

using screen::FrameBuffers;
using test::AllNaN;
using test::Finite;
using test::FrameOptions;
using test::TestScene;
using test::Translate;

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
        EXPECT_NEAR(glm::distance(fb.camera.position, glm::vec3(s.camera.pose.Eval(0.7f)[3])), 0.0f,
                    1e-5f);
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
            case 0:  // still: its previous normal is its normal, bit for bit
                EXPECT_NEAR(glm::distance(pp, p), 0.0f, 1e-5f) << i;
                EXPECT_EQ(fb.prevNormal[i], fb.normal[i]) << i;
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
    // Objects move: the stage must compute the shadow vectors (FrameBuffers::shadowsStill);
    // without the motion, only the camera could have moved, and it need not.
    EXPECT_FALSE(fb.shadowsStill);
    Scene staticScene = TestScene();
    RenderScene staticRs(staticScene, {});
    RenderFrameBuffers(staticRs, FrameOptions(48, 32), -1.0f / 8.0f, &fb);
    EXPECT_TRUE(fb.shadowsStill);
}

// At 1 spp, visibility is 0 where the shadow ray was blocked and positive where not (1 on the
// glossy torus, whose shading is light samples; the ratio of the light samples to the closed
// form on the diffuse ground and occluder); blocker, light sample and their prev points are NaN
// exactly where it is positive and finite where it is 0; the blocker lies on the segment from
// the shading point to the light point, which lies on the quad light.
TEST(FrameBuffers, BlockerExactlyWhereShadowed) {
    Scene s = TestScene();
    s.environments.clear();  // one light: every light sample is a point on the quad
    RenderScene rs(s, {});
    FrameBuffers fb;
    RenderFrameBuffers(rs, FrameOptions(64, 48, 7), -1.0f / 24.0f, &fb);
    const QuadLight& q = s.quadLights[0];
    int shadowed = 0, lit = 0, withoutRay = 0;
    for (size_t i = 0; i < fb.NumPixels(); ++i) {
        const float v = fb.visibility[i];
        ASSERT_TRUE(std::isfinite(v) && v >= 0.0f) << i << ": " << v;
        if (fb.objectId[i] == 1) {
            ASSERT_TRUE(v == 0.0f || v == 1.0f) << i << ": " << v;
        }
        const glm::vec3 pts[] = {fb.blocker[i], fb.prevBlocker[i], fb.lightSample[i],
                                 fb.prevLightSample[i]};
        if (v > 0.0f) {
            for (glm::vec3 p : pts) EXPECT_TRUE(AllNaN(p)) << i;
            lit += fb.objectId[i] >= 0;
            continue;
        }
        if (AllNaN(fb.blocker[i])) {
            // No shadow ray: every light sample fell where the BSDF is 0 (below the geometric
            // normal), which the closed form does not see; rare.
            for (glm::vec3 p : pts) EXPECT_TRUE(AllNaN(p)) << i;
            ++withoutRay;
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
    EXPECT_LT(withoutRay, 30) << "of " << fb.NumPixels();
    std::printf("visibility 0 without a shadow ray: %d pixels\n", withoutRay);
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
        EXPECT_NEAR(glm::distance(fb.prevBlocker[i], fb.blocker[i] - occluderVelocity * 0.1f), 0.0f,
                    1e-5f)
            << i;
        EXPECT_NEAR(glm::distance(fb.prevLightSample[i], fb.lightSample[i] - lightVelocity * 0.1f),
                    0.0f, 1e-5f)
            << i;
        ++checked;
    }
    EXPECT_GT(checked, 30);

    // A distant light turning about +Z by 20 degrees per second: the far light point is along
    // the light's direction from the blocker, now and (turned back) in the previous frame,
    // within the sun's angular radius (0.27 degrees: 4.6e-3; the turn is 2 degrees). A sun of
    // some size: a delta light's shadows are not in these buffers (DeltaLightIsExact).
    Scene d = TestScene();
    d.environments.clear();
    d.quadLights.clear();
    DistantLight sun;
    sun.direction = glm::normalize(glm::vec3(0.3f, -1.0f, 0.1f));
    sun.irradiance = glm::vec3(3.0f);
    sun.angleDegrees = 0.53f;
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
                  5e-3f);
        EXPECT_LT(
            glm::distance(glm::normalize(fb.prevLightSample[i] - fb.prevBlocker[i]), towardsPrev),
            5e-3f);
        ++checked;
    }
    EXPECT_GT(checked, 30);
}

// A delta light's light is exact at the pixel centre: a sun of no size and a point light of
// radius 0 light the ground and the occluder through `emitted` (FrameLights), the same for any
// seed (bit for bit: no sample is random), with visibility 1 and shading 0 everywhere (no other
// light) and no blocker. On the ground it is 0 in the occluder's shadow and elsewhere the
// diffuse term R / pi (E cos + I cos / d^2) of the lights it sees, within 1e-4 of the sum of
// both; the ground has pixels lit by both and pixels in a shadow.
TEST(FrameBuffers, DeltaLightIsExact) {
    Scene d = TestScene();
    d.environments.clear();
    d.quadLights.clear();
    d.objects.erase(d.objects.begin() + 1);  // the glossy torus: the ground's only other blocker
    DistantLight sun;
    sun.direction = glm::normalize(glm::vec3(0.3f, -1.0f, 0.1f));
    sun.irradiance = glm::vec3(3.0f);
    d.distantLights.push_back(sun);
    PointLight lamp;
    lamp.position = glm::vec3(-1.0f, 2.0f, 1.0f);
    lamp.intensity = glm::vec3(2.0f);
    d.pointLights.push_back(lamp);
    RenderScene rs(d, {});
    FrameBuffers a, b;
    RenderFrameBuffers(rs, FrameOptions(64, 48, 1), -0.04f, &a);
    RenderFrameBuffers(rs, FrameOptions(64, 48, 2), -0.04f, &b);
    const glm::vec3 R = d.materials[size_t(d.objects[0].material)].albedo.value;
    int lit = 0, shadowed = 0;
    for (size_t i = 0; i < a.NumPixels(); ++i) {
        ASSERT_EQ(a.emitted[i], b.emitted[i]) << i;
        if (a.objectId[i] < 0) continue;
        EXPECT_EQ(a.visibility[i], 1.0f) << i;
        EXPECT_EQ(a.shading[i], glm::vec3(0.0f)) << i;
        EXPECT_TRUE(AllNaN(a.blocker[i])) << i;
        if (a.objectId[i] != 0) continue;  // the ground
        const glm::vec3 P = a.position[i], N = a.normal[i];
        const glm::vec3 toLamp = lamp.position - P;
        const float d2 = glm::dot(toLamp, toLamp);
        const glm::vec3 open =
            R * 0.31830988f *
            (sun.irradiance * std::max(glm::dot(-sun.direction, N), 0.0f) +
             lamp.intensity * std::max(glm::dot(toLamp, N) / std::sqrt(d2), 0.0f) / d2);
        // Lit by both lights, one of them or none: the value is one of the four sums.
        const glm::vec3 bySun =
            R * 0.31830988f * sun.irradiance * std::max(glm::dot(-sun.direction, N), 0.0f);
        const glm::vec3 want[4] = {open, bySun, open - bySun, glm::vec3(0.0f)};
        int which = -1;
        for (int k = 0; k < 4; ++k)
            if (glm::length(a.emitted[i] - want[k]) <= 1e-4f * glm::length(open)) which = k;
        EXPECT_GE(which, 0) << i << ": " << a.emitted[i].x;
        (which == 0 ? lit : shadowed) += 1;
    }
    std::printf("ground pixels lit by both lights %d, in a shadow %d\n", lit, shadowed);
    EXPECT_GT(lit, 300);
    EXPECT_GT(shadowed, 10);
}

// The split is unbiased: Compose() averaged over frames of a static scene (1 spp each, fresh
// seeds) matches the path tracer (same pixel-centre rays). The scene has every component (area
// light with soft shadows, sky, glossy and diffuse materials, light seen directly). The split
// has more variance than the path tracer (direct light only from its one light sample: relMSE
// ~4x at equal samples, up to 40x on the occluder's underside), so bias is judged against the
// noise: per pixel and channel z = (mean - reference) / sqrt(se_mean^2 + se_reference^2), both
// standard errors estimated (the reference's from 16 independent chunks). Unbiased, z^2 averages
// about 1: measured 0.93-1.06 over all objects and 1.1-1.3 on the glossy torus (heavier tails)
// for 1024-4096 frames. Tolerances: mean z^2 < 1.2 over all object pixels and < 1.6 over each
// object's with >= 300 values (fewer are too noisy: the occluder's 11 pixels gave 0.5-2.0
// across seeds); the sky seen directly within 1e-5; the image means within 1.5%. Each of these
// bugs fails it: the glossy ray's light hits counted without MIS (torus 9.8), the diffuse ray's
// light hits counted (all ~20, image mean +61%), a diffuse ray where the shading normal faces
// away from the camera, whose BSDF is 0 (torus 1.9).
/// Composed frames of `s` (each its own seed) average to the path tracer's image: per pixel, z^2
/// of the difference over both standard errors, averaged per object (< groupZ2 where an object
/// has 300 values or more) and over all objects (< allZ2), and the image's mean within meanTol.
void ExpectComposeUnbiased(const Scene& s, int frames, double groupZ2, double allZ2,
                           double meanTol) {
    RenderScene rs(s, {});
    const int W = 48, H = 32, chunks = 16;
    const size_t n = size_t(W) * H;
    // The reference in chunks of independent seeds, for its own standard error.
    RenderOptions ref = FrameOptions(W, H);
    ref.integrator = IntegratorKind::Path;
    ref.pixelCentre = true;
    ref.spp = 256;
    std::vector<double> rs1(3 * n, 0.0), rs2(3 * n, 0.0);
    for (int c = 0; c < chunks; ++c) {
        ref.seed = 1000 + uint64_t(c);
        const Image chunk = Render(rs, ref).beauty;
        for (size_t i = 0; i < 3 * n; ++i) {
            rs1[i] += chunk.data[i];
            rs2[i] += double(chunk.data[i]) * chunk.data[i];
        }
    }
    std::vector<double> sum(3 * n, 0.0), sum2(3 * n, 0.0);
    FrameBuffers fb;
    for (int f = 0; f < frames; ++f) {
        RenderFrameBuffers(rs, FrameOptions(W, H, uint64_t(f)), -1.0f / 30.0f, &fb);
        const std::vector<glm::vec3> c = fb.Compose();
        for (size_t p = 0; p < n; ++p)
            for (int k = 0; k < 3; ++k) {
                sum[3 * p + k] += c[p][k];
                sum2[3 * p + k] += double(c[p][k]) * c[p][k];
            }
    }
    // Mean z^2 per object id (index id + 1) and over all objects (last).
    const int groups = int(s.objects.size()) + 2;
    std::vector<double> z2(groups, 0.0);
    std::vector<int> count(groups, 0);
    double meanSplit = 0.0, meanRef = 0.0;
    for (size_t i = 0; i < 3 * n; ++i) {
        const double m = sum[i] / frames, r = rs1[i] / chunks;
        meanSplit += m;
        meanRef += r;
        const double var = std::max(sum2[i] / frames - m * m, 0.0) / (frames - 1);
        const double refVar = std::max(rs2[i] / chunks - r * r, 0.0) / (chunks - 1);
        const int id = fb.objectId[i / 3];
        if (id < 0) {
            EXPECT_NEAR(m, r, 1e-5) << "sky at pixel " << i / 3;
            continue;
        }
        const double z = (m - r) / std::sqrt(var + refVar + 1e-20);
        for (int g : {id + 1, groups - 1}) {
            z2[g] += z * z;
            ++count[g];
        }
    }
    for (int g = 1; g < groups; ++g) {
        z2[g] /= std::max(count[g], 1);
        const bool all = g == groups - 1;
        if (count[g] >= 300 || all) {
            EXPECT_LT(z2[g], all ? allZ2 : groupZ2)
                << (all ? std::string("all objects") : "object " + std::to_string(g - 1)) << ", "
                << count[g] << " values";
        }
    }
    std::printf("mean z^2 over all objects %.3f, torus %.3f; image mean / reference %.4f\n",
                z2[groups - 1], z2[2], meanSplit / meanRef);
    EXPECT_GT(count[1], 300);  // ground
    EXPECT_GT(count[2], 300);  // glossy torus
    EXPECT_NEAR(meanSplit / meanRef, 1.0, meanTol);
}

// The glossy torus (F0 0.3 over a blue base) traces its glossy ray with a probability of about
// one half to one (FrameGlossySample's roulette by the lobe's share): without the ray's 1 / p
// weight its mean z^2 is above 100 here.
TEST(FrameBuffers, ComposeIsUnbiased) {
    ExpectComposeUnbiased(TestScene(), 1024, 1.6, 1.2, 0.015);
}

// The same under an environment map beside the quad light: its light samples come from the
// frame's shared table of map samples (EnvironmentSamples in frame_buffers_render.cpp), whose
// entries are each distributed as the map's sampling and drawn anew each frame, so the frames
// still average to the path tracer's image. 256 frames: measured mean z^2 1.14 over all objects
// (1.13 with each candidate sampling the map itself: the map's tails), 0.96 on the torus, image
// mean 1.001 of the reference; map samples whose density is 25% too high give 12.8 and 0.945.
// Tolerances: z^2 < 1.3 over all objects, < 1.6 per object, the mean within 3%.
TEST(FrameBuffers, ComposeIsUnbiasedUnderAnEnvironmentMap) {
    Scene s = TestScene();
    s.environments[0].path = test::SceneDir() + "/envmaps/studio.exr";
    s.environments[0].intensity = 0.3f;
    ExpectComposeUnbiased(s, 256, 1.6, 1.3, 0.03);
}

// `shading` is the unshadowed direct light, so the stage can pass it through unfiltered (Zeng et
// al. take it as noise-free): in closed form on the diffuse ground and occluder (exact up to
// float rounding), from kShadingCandidates (32) light samples without shadow rays on the glossy
// torus (a GGX lobe under a quad light has no closed form here). At 1 spp, per pixel, the
// luminance's relative error against a 64-spp estimate of the TestScene (quad light + sky).
// Measured RMS 0.010 and 99th percentile 0.054 over the pixels with shading above 1% of the
// brightest (all of it the torus; light samples everywhere give 0.055 and 0.23). Tolerances:
// RMS < 0.08, 99th percentile < 0.35 (what light samples alone meet).
TEST(FrameBuffers, ShadingIsLowNoise) {
    const Scene s = TestScene();
    RenderScene rs(s, {});
    const int W = 48, H = 32;
    FrameBuffers one, many;
    RenderFrameBuffers(rs, FrameOptions(W, H, 7), -1.0f / 30.0f, &one);
    RenderOptions hi = FrameOptions(W, H, 99);
    hi.spp = 64;
    RenderFrameBuffers(rs, hi, -1.0f / 30.0f, &many);
    float peak = 0.0f;
    for (const glm::vec3& c : many.shading) peak = std::max(peak, Luminance(c));
    std::vector<double> rel;
    for (size_t p = 0; p < many.shading.size(); ++p) {
        const float ref = Luminance(many.shading[p]);
        if (many.objectId[p] < 0 || !(ref > 0.01f * peak)) continue;
        rel.push_back(std::abs(Luminance(one.shading[p]) - ref) / ref);
    }
    ASSERT_GT(rel.size(), 600u);
    double sq = 0.0;
    for (double r : rel) sq += r * r;
    const double rms = std::sqrt(sq / double(rel.size()));
    std::sort(rel.begin(), rel.end());
    const double p99 = rel[size_t(0.99 * double(rel.size() - 1))];
    std::printf("shading relative error: RMS %.4f, 99th percentile %.4f over %zu pixels\n", rms,
                p99, rel.size());
    EXPECT_LT(rms, 0.08);
    EXPECT_LT(p99, 0.35);
}

// Where `shading` has a closed form (diffuse surfaces under a quad light and a constant sky),
// the light samples agree with it: on an unoccluded plane the visibility, their ratio to it,
// averages to 1 (64 samples of 8 light samples per pixel; measured mean 0.993, the quad hiding
// ~3% of the sky, and per-pixel RMS of (v - 1) 0.014; tolerances: mean within 1%, RMS < 4%).
TEST(FrameBuffers, ClosedFormShadingMatchesTheLightSamples) {
    Scene s = TestScene();
    // The ground alone: nothing casts a shadow but the quad light on the sky behind it (0.2% of
    // the light at most).
    s.objects.resize(1);
    RenderScene rs(s, {});
    RenderOptions o = FrameOptions(32, 24, 3);
    o.spp = 64;
    FrameBuffers fb;
    RenderFrameBuffers(rs, o, -0.04f, &fb);
    double sum = 0.0, sq = 0.0;
    int n = 0;
    for (size_t p = 0; p < fb.NumPixels(); ++p) {
        if (fb.objectId[p] != 0) continue;
        ASSERT_GT(Luminance(fb.shading[p]), 0.0f) << p;
        const double d = fb.visibility[p] - 1.0;
        sum += d, sq += d * d, ++n;
    }
    ASSERT_GT(n, 300);
    std::printf("visibility ratio on an unoccluded plane: mean %.4f, RMS of (v - 1) %.4f\n",
                1.0 + sum / n, std::sqrt(sq / n));
    EXPECT_NEAR(sum / n, 0.0, 0.01);
    EXPECT_LT(std::sqrt(sq / n), 0.04);
}

// At 1 spp, a pixel with a diffuse ray has six finite cones, at most one of them non-zero, and
// indirect = albedo * ShadeCones(cones) (to float rounding); pixels without one (sky) have none.
// Glossy is 0 on diffuse materials; the guides give the material's alpha and F0.
TEST(FrameBuffers, ConesHoldTheDiffuseRaysRadiance) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    FrameBuffers fb;
    RenderFrameBuffers(rs, FrameOptions(40, 30, 11), -0.04f, &fb);
    int withRay = 0, lit = 0;
    for (size_t p = 0; p < fb.NumPixels(); ++p) {
        int finite = 0, nonZero = 0;
        for (int k = 0; k < screen::kNumCones; ++k) {
            const glm::vec3 c = fb.cones[p * screen::kNumCones + k];
            if (AllNaN(c)) continue;
            ASSERT_TRUE(Finite(c)) << p;
            ++finite;
            nonZero += c != glm::vec3(0.0f);
        }
        const int id = fb.objectId[p];
        if (id < 0) {
            EXPECT_EQ(finite, 0) << p;
            continue;
        }
        ASSERT_LE(nonZero, 1) << p;
        const bool facing = glm::dot(fb.normal[p], fb.camera.position - fb.position[p]) > 0.0f;
        EXPECT_EQ(finite, facing ? screen::kNumCones : 0) << p;
        withRay += finite > 0;
        if (finite == 0) continue;
        const glm::vec3 expected =
            fb.albedo[p] * screen::ShadeCones(&fb.cones[p * screen::kNumCones]);
        EXPECT_NEAR(glm::distance(fb.indirect[p], expected), 0.0f,
                    1e-6f * (1.0f + glm::length(expected)))
            << p;
        lit += Luminance(fb.indirect[p]) > 0.0f;
        if (id == 1) {  // GGX: alpha = roughness^2, F0, diffuse base (1 - max F0) * albedo
            EXPECT_NEAR(fb.roughness[p], 0.16f, 1e-6f);
            EXPECT_EQ(fb.specular[p], glm::vec3(0.3f));
            EXPECT_NEAR(glm::distance(fb.albedo[p], 0.7f * s.materials[1].albedo.value), 0.0f,
                        1e-6f);
        } else {
            EXPECT_EQ(fb.roughness[p], 0.0f);
            EXPECT_EQ(fb.specular[p], glm::vec3(0.0f));
            EXPECT_EQ(fb.glossy[p], glm::vec3(0.0f));
            EXPECT_TRUE(AllNaN(fb.glossyHit[p]));
        }
    }
    EXPECT_GT(withRay, 600);
    EXPECT_GT(lit, 30);
}

// With several samples per pixel, visibility is the shading-weighted fraction of unblocked
// shadow rays on the glossy torus (fractions occur in the penumbra), where blocker points are
// still NaN exactly where it is 1; on the diffuse objects (closed-form shading) it is the mean
// ratio, 0 where every sample was blocked, and blocker points are NaN where none was.
TEST(FrameBuffers, SeveralSamplesPerPixel) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    RenderOptions o = FrameOptions(40, 30, 5);
    o.spp = 8;
    FrameBuffers fb;
    RenderFrameBuffers(rs, o, -0.04f, &fb);
    int fractional = 0;
    for (size_t p = 0; p < fb.NumPixels(); ++p) {
        const float v = fb.visibility[p];
        ASSERT_GE(v, 0.0f);
        ASSERT_TRUE(std::isfinite(v));
        if (fb.objectId[p] == 1) {
            ASSERT_LE(v, 1.0f);
            fractional += v > 0.0f && v < 1.0f;
            EXPECT_EQ(AllNaN(fb.blocker[p]), v == 1.0f) << p;
            EXPECT_EQ(AllNaN(fb.lightSample[p]), v == 1.0f) << p;
        } else if (v == 0.0f) {
            EXPECT_TRUE(Finite(fb.blocker[p])) << p;
        }
        int cones = 0;
        for (int k = 0; k < screen::kNumCones; ++k)
            cones += Finite(fb.cones[p * screen::kNumCones + k]);
        EXPECT_LE(cones, 6);
    }
    EXPECT_GT(fractional, 10);
}

// Every buffer of `one` and `two` the same, bytes rather than values (NaN entries must match
// too); with `cones` false, every one but the cones.
void ExpectSameBuffers(const FrameBuffers& one, const FrameBuffers& two, bool cones = true,
                       bool shadowPoints = true) {
    auto same = [](const auto& a, const auto& b, const char* name) {
        ASSERT_EQ(a.size(), b.size()) << name;
        // An empty buffer's data() may be null, which memcmp must not be given.
        if (!a.empty()) {
            EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])), 0) << name;
        }
    };
    same(one.emitted, two.emitted, "emitted");
    same(one.shading, two.shading, "shading");
    same(one.visibility, two.visibility, "visibility");
    same(one.glossy, two.glossy, "glossy");
    same(one.indirect, two.indirect, "indirect");
    same(one.position, two.position, "position");
    same(one.normal, two.normal, "normal");
    same(one.depth, two.depth, "depth");
    same(one.roughness, two.roughness, "roughness");
    same(one.albedo, two.albedo, "albedo");
    same(one.specular, two.specular, "specular");
    same(one.objectId, two.objectId, "objectId");
    same(one.prevPosition, two.prevPosition, "prevPosition");
    same(one.prevNormal, two.prevNormal, "prevNormal");
    if (shadowPoints) {
        same(one.blocker, two.blocker, "blocker");
        same(one.prevBlocker, two.prevBlocker, "prevBlocker");
        same(one.lightSample, two.lightSample, "lightSample");
        same(one.prevLightSample, two.prevLightSample, "prevLightSample");
    }
    same(one.glossyHit, two.glossyHit, "glossyHit");
    same(one.prevGlossyHit, two.prevGlossyHit, "prevGlossyHit");
    same(one.cachedVisibility, two.cachedVisibility, "cachedVisibility");
    if (cones) same(one.cones, two.cones, "cones");
}

// Same seed, same buffers, bit for bit, for 1 and 2 threads (the tiles and their ray packets are
// fixed whatever the thread count), and into buffers that held a larger frame of another seed
// before: every pixel writes all of its entries, nothing of the old frame shows through.
TEST(FrameBuffers, SameBuffersForAnyThreadCountAndReusedBuffers) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    RenderOptions o = FrameOptions(40, 30, 11);
    o.spp = 2;
    FrameBuffers one, two;
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
        RenderFrameBuffers(rs, o, -0.04f, &one);
    }
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
        RenderFrameBuffers(rs, FrameOptions(48, 32, 12), -0.04f, &two);
        RenderFrameBuffers(rs, o, -0.04f, &two);
    }
    ExpectSameBuffers(one, two);
    // The frame has background, blocked and glossy pixels: the comparison covers every branch.
    int background = 0, blocked = 0;
    for (size_t p = 0; p < one.NumPixels(); ++p) {
        background += one.objectId[p] < 0;
        blocked += Finite(one.blocker[p]);
    }
    EXPECT_GT(background, 0);
    EXPECT_GT(blocked, 0);
    EXPECT_FALSE(one.glossy.empty());
    // With indirect light from a texture-space cache (one per render): its samples are shaded
    // from streams of their keys, whichever thread shades them.
    RenderOptions t = o;
    t.texture.enabled = true;
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
        RenderFrameBuffers(rs, t, -0.04f, &one);
    }
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
        RenderFrameBuffers(rs, t, -0.04f, &two);
    }
    ExpectSameBuffers(one, two);
}

// Without cones (RenderOptions::frameBufferCones off, as the preview's stage asks) the buffer is
// empty and every other buffer is the same bit for bit: per hit (whose diffuse rays fill the
// cones otherwise), from the grid and from the store.
TEST(FrameBuffers, WithoutConesEveryOtherBufferIsTheSame) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    RenderOptions o = FrameOptions(40, 30, 11);
    o.spp = 2;
    RenderOptions grid = o, store = o;
    grid.texture.enabled = store.texture.enabled = true;
    grid.texture.frameBufferSamples = TextureSamples::Grid;
    store.texture.frameBufferSamples = TextureSamples::Hits;
    for (const RenderOptions& with : {o, grid, store}) {
        RenderOptions without = with;
        without.frameBufferCones = false;
        FrameBuffers one, two;
        RenderFrameBuffers(rs, with, -0.04f, &one);
        RenderFrameBuffers(rs, without, -0.04f, &two);
        EXPECT_EQ(one.cones.size(), one.NumPixels() * screen::kNumCones);
        EXPECT_TRUE(two.cones.empty());
        ExpectSameBuffers(one, two, /*cones=*/false);
    }
}

// Without shadow points (RenderOptions::frameBufferShadowPoints off, as the preview's stage
// asks in its default visibility order): a frame where only the camera moved leaves the four
// buffers empty, its shadow rays only asking whether they are blocked, and every other buffer is
// the same bit for bit (visibility included: the same rays are blocked), per hit and from the
// store. Without previous points (frameBufferPrevPoints off) it leaves prevPosition, prevNormal
// and prevGlossyHit empty, and the stage's planes for them are the current ones, which they
// equal within 1e-5 of the scene's size. A frame where an object moves fills all of them as
// with the options on.
TEST(FrameBuffers, WithoutShadowAndPrevPointsStillFramesKeepEveryOtherBuffer) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    RenderOptions o = FrameOptions(40, 30, 11);
    o.spp = 2;
    RenderOptions store = o;
    store.texture.enabled = true;
    store.texture.frameBufferSamples = TextureSamples::Hits;
    auto near = [](const std::vector<glm::vec3>& a, const std::vector<glm::vec3>& b,
                   const char* name) {
        ASSERT_EQ(a.size(), b.size()) << name;
        for (size_t i = 0; i < a.size(); ++i) {
            if (!Finite(a[i])) {
                EXPECT_TRUE(AllNaN(b[i])) << name << " " << i;
                continue;
            }
            EXPECT_LE(glm::distance(a[i], b[i]), 1e-5f) << name << " " << i;
        }
    };
    for (const RenderOptions& with : {o, store}) {
        RenderOptions without = with;
        without.frameBufferShadowPoints = false;
        without.frameBufferPrevPoints = false;
        FrameBuffers one, two;
        RenderFrameBuffers(rs, with, -0.04f, &one);
        RenderFrameBuffers(rs, without, -0.04f, &two);
        ASSERT_TRUE(one.shadowsStill && two.shadowsStill);
        int blocked = 0;
        for (const glm::vec3& b : one.blocker) blocked += Finite(b);
        EXPECT_GT(blocked, 0);  // the frame has shadows to leave out
        ASSERT_FALSE(one.glossyHit.empty());
        for (const auto* v :
             {&two.blocker, &two.prevBlocker, &two.lightSample, &two.prevLightSample,
              &two.prevPosition, &two.prevNormal, &two.prevGlossyHit})
            EXPECT_TRUE(v->empty());
        near(one.prevPosition, two.PrevPositionPlane(), "prevPosition");
        near(one.prevNormal, two.PrevNormalPlane(), "prevNormal");
        near(one.prevGlossyHit, two.PrevGlossyHitPlane(), "prevGlossyHit");
        FrameBuffers expected = one;
        expected.prevPosition.clear(), expected.prevNormal.clear();
        expected.prevGlossyHit.clear();
        ExpectSameBuffers(expected, two, /*cones=*/true, /*shadowPoints=*/false);
        EXPECT_NO_THROW(two.Validate("test"));
    }
    Scene moving = TestScene();
    Translate(&moving, 2, glm::vec3(0.5f, 0.0f, 0.0f));  // the occluder
    RenderSceneOptions ro;
    ro.frameTime = 0.5f;
    RenderScene movingRs(moving, ro);
    RenderOptions m = FrameOptions(40, 30, 11);
    m.frameTime = 0.5f;
    RenderOptions without = m;
    without.frameBufferShadowPoints = false;
    without.frameBufferPrevPoints = false;
    FrameBuffers one, two;
    RenderFrameBuffers(movingRs, m, 0.45f, &one);
    RenderFrameBuffers(movingRs, without, 0.45f, &two);
    EXPECT_FALSE(two.shadowsStill);
    EXPECT_EQ(two.prevBlocker.size(), two.NumPixels());
    EXPECT_EQ(two.prevPosition.size(), two.NumPixels());
    ExpectSameBuffers(one, two);
}

}  // namespace
}  // namespace texcache
