// SPDX-License-Identifier: Apache-2.0
// Render tests with analytic answers (white furnace, open-plane AO, a distant light's cosine law),
// ray differentials against finite differences, and determinism across thread counts.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include <tbb/global_control.h>

#include "renderer/image/metrics.h"
#include "renderer/integrators/sampling.h"
#include "renderer/render.h"
#include "renderer/scene/camera.h"
#include "test_util.h"

namespace texcache {
namespace {

RenderOptions SmallOptions(IntegratorKind k, int spp) {
    RenderOptions o;
    o.integrator = k;
    o.width = 48;
    o.height = 32;
    o.spp = spp;
    o.progress = false;
    return o;
}

double Mean(const Image& img) {
    double s = 0.0;
    for (float v : img.data) s += v;
    return s / double(img.data.size());
}

// Albedo-1 diffuse blob (subdivided cube, convex) under a constant white environment: every pixel,
// object or background, has expected radiance exactly 1. 64 spp x 1536 pixels, depth 64 with
// Russian roulette: the image mean is within 1% (measured ~0.2%), single pixels within 25%.
TEST(Render, WhiteFurnace) {
    Scene s = test::OneObjectScene(test::LoadMesh("catmark_cube"), glm::vec3(1.0f));
    s.camera.pose.keys = {test::LookAt({2.0f, 1.5f, 2.5f}, {0, 0, 0})};
    s.camera.fovYDegrees = 30.0f;
    // A 6-face cage at the default rate 2 is a coarse polyhedron whose geometric normals differ
    // from the limit normals by ~20 degrees; rate 8 keeps this a test of the integrator.
    s.settings.tessellationRate = 8.0f;
    EnvironmentLight env;
    env.constant = glm::vec3(1.0f);
    s.environments.push_back(env);
    RenderScene rs(s, {});
    RenderOptions o = SmallOptions(IntegratorKind::Path, 64);
    o.maxDepth = 64;
    const RenderResult r = Render(rs, o);
    EXPECT_NEAR(Mean(r.beauty), 1.0, 0.01);
    for (float v : r.beauty.data) EXPECT_NEAR(v, 1.0f, 0.25f);
}

// The same furnace for direct lighting only: an albedo-1 convex object sees only sky, so one
// bounce already gives exactly 1 in expectation.
TEST(Render, WhiteFurnaceDirect) {
    Scene s = test::OneObjectScene(test::LoadMesh("catmark_cube"), glm::vec3(1.0f));
    s.camera.pose.keys = {test::LookAt({2.0f, 1.5f, 2.5f}, {0, 0, 0})};
    s.settings.tessellationRate = 8.0f;
    EnvironmentLight env;
    env.constant = glm::vec3(1.0f);
    s.environments.push_back(env);
    RenderScene rs(s, {});
    const RenderResult r = Render(rs, SmallOptions(IntegratorKind::Direct, 64));
    EXPECT_NEAR(Mean(r.beauty), 1.0, 0.01);
}

// Ambient occlusion of an open plane is exactly 1 everywhere it is seen.
TEST(Render, AmbientOcclusionOfOpenPlaneIsOne) {
    Scene s = test::OneObjectScene(test::PlaneCage(10.0f));
    s.camera.pose.keys = {test::LookAt({0.0f, 3.0f, 2.0f}, {0, 0, 0})};
    RenderSceneOptions ro;
    ro.needLights = false;
    RenderScene rs(s, ro);
    RenderOptions o = SmallOptions(IntegratorKind::AO, 4);
    o.aoSamples = 8;
    const RenderResult r = Render(rs, o);
    for (float v : r.beauty.data) ASSERT_EQ(v, 1.0f);
}

// A diffuse plane lit by a distant light of irradiance E at angle theta: L = albedo/pi E
// cos(theta). Deterministic (one delta light, no occluder): tolerance 1e-4 relative.
TEST(Render, DistantLightCosineLaw) {
    for (float thetaDeg : {0.0f, 30.0f, 60.0f, 85.0f}) {
        Scene s = test::OneObjectScene(test::PlaneCage(10.0f), glm::vec3(0.5f));
        s.camera.pose.keys = {test::LookAt({0.0f, 3.0f, 0.5f}, {0, 0, 0})};
        DistantLight d;
        const float th = glm::radians(thetaDeg);
        d.direction = -glm::vec3(std::sin(th), std::cos(th), 0.0f);
        d.irradiance = glm::vec3(2.0f);
        s.distantLights.push_back(d);
        RenderScene rs(s, {});
        const RenderResult r = Render(rs, SmallOptions(IntegratorKind::Direct, 1));
        const float expected = 0.5f / 3.14159265f * 2.0f * std::cos(th);
        for (float v : r.beauty.data) ASSERT_NEAR(v, expected, 1e-4f * 2.0f) << thetaDeg;
    }
}

// Ray differentials: the Ptex-space footprint predicted at a pixel matches the difference of the
// (u,v) hit by the neighbouring pixels' rays. On a plane (u linear in world) within 2%; on the
// torus's curved faces within 10% (second-order terms over a pixel).
void CheckDifferentials(const ControlCage& cage, glm::vec3 eye, float tolerance, int* checked) {
    Scene s = test::OneObjectScene(cage);
    s.camera.pose.keys = {test::LookAt(eye, {0, 0, 0})};
    s.camera.fovYDegrees = 40.0f;
    RenderSceneOptions ro;
    ro.needLights = false;
    s.settings.tessellationRate = 16.0f;
    RenderScene rs(s, ro);
    const int W = 256, H = 256;
    const CameraModel cam(s.camera, 0.0f, W, H);
    for (int y = 8; y < H - 8; y += 16)
        for (int x = 8; x < W - 8; x += 16) {
            RayDifferentials diff;
            const Ray r0 = cam.Generate(x + 0.5f, y + 0.5f, {0.5f, 0.5f}, &diff);
            // Central differences of the neighbours' hits (second-order accurate, like the
            // tangent-plane differentials are to first order).
            const Ray rx0 = cam.Generate(x - 0.5f, y + 0.5f, {0.5f, 0.5f}, nullptr);
            const Ray rx1 = cam.Generate(x + 1.5f, y + 0.5f, {0.5f, 0.5f}, nullptr);
            const Ray ry0 = cam.Generate(x + 0.5f, y - 0.5f, {0.5f, 0.5f}, nullptr);
            const Ray ry1 = cam.Generate(x + 0.5f, y + 1.5f, {0.5f, 0.5f}, nullptr);
            Hit h0, hx0, hx1, hy0, hy1;
            if (!rs.Intersect(r0, &h0) || !rs.Intersect(rx0, &hx0) || !rs.Intersect(rx1, &hx1) ||
                !rs.Intersect(ry0, &hy0) || !rs.Intersect(ry1, &hy1))
                continue;
            const SurfaceInteraction s0 = rs.Interact(r0, h0, &diff);
            const SurfaceInteraction sx0 = rs.Interact(rx0, hx0), sx1 = rs.Interact(rx1, hx1);
            const SurfaceInteraction sy0 = rs.Interact(ry0, hy0), sy1 = rs.Interact(ry1, hy1);
            const int f = s0.ptex.face;
            if (sx0.ptex.face != f || sx1.ptex.face != f || sy0.ptex.face != f ||
                sy1.ptex.face != f)
                continue;
            // Grazing pixels have huge footprints where second-order terms dominate: skip them.
            if (std::abs(glm::dot(s0.N, r0.dir)) < 0.3f) continue;
            const float fdudx = 0.5f * (sx1.ptex.u - sx0.ptex.u),
                        fdvdx = 0.5f * (sx1.ptex.v - sx0.ptex.v);
            const float fdudy = 0.5f * (sy1.ptex.u - sy0.ptex.u),
                        fdvdy = 0.5f * (sy1.ptex.v - sy0.ptex.v);
            const float sx_ = std::hypot(fdudx, fdvdx), sy_ = std::hypot(fdudy, fdvdy);
            EXPECT_NEAR(s0.dudx, fdudx, tolerance * sx_ + 1e-6f) << x << "," << y;
            EXPECT_NEAR(s0.dvdx, fdvdx, tolerance * sx_ + 1e-6f) << x << "," << y;
            EXPECT_NEAR(s0.dudy, fdudy, tolerance * sy_ + 1e-6f) << x << "," << y;
            EXPECT_NEAR(s0.dvdy, fdvdy, tolerance * sy_ + 1e-6f) << x << "," << y;
            ++*checked;
        }
}

TEST(Render, RayDifferentialsMatchNeighbourHitsOnPlane) {
    int checked = 0;
    CheckDifferentials(test::PlaneCage(2.0f), {0.3f, 2.5f, 1.5f}, 0.02f, &checked);
    EXPECT_GT(checked, 50);
}

TEST(Render, RayDifferentialsMatchNeighbourHitsOnTorus) {
    int checked = 0;
    CheckDifferentials(test::LoadMesh("catmark_torus"), {0.5f, 2.5f, 2.5f}, 0.10f, &checked);
    EXPECT_GT(checked, 20);
}

/// A grey pawn under a bluish sky, seen from the front: a small scene with edges and shading.
Scene PawnUnderSky() {
    Scene s = test::OneObjectScene(test::LoadMesh("catmark_pawn"), glm::vec3(0.7f));
    s.camera.pose.keys = {test::LookAt({0.0f, 3.0f, 8.0f}, {0, 1.5f, 0})};
    EnvironmentLight env;
    env.constant = glm::vec3(0.8f, 0.9f, 1.0f);
    s.environments.push_back(env);
    return s;
}

// CameraModel::GeneratePinhole makes Generate's rays bit for bit (the renderer's pinhole camera
// rays come from it), for any count (chunks of 64 and a rest), a centred camera and a stereo eye.
TEST(Render, PinholeRaysInBulkAreGenerateBitForBit) {
    Scene s = PawnUnderSky();
    CameraModel cam(s.camera, 0.0f, 640, 480);
    std::mt19937 gen(3);
    std::uniform_real_distribution<float> X(0.0f, 640.0f), Y(0.0f, 480.0f);
    for (int eye = 0; eye < 2; ++eye) {
        if (eye) cam.SetEye(0.3f, 9.0f);
        std::vector<float> px(150), py(150);
        for (size_t i = 0; i < px.size(); ++i) px[i] = X(gen), py[i] = Y(gen);
        std::vector<Ray> bulk(px.size());
        cam.GeneratePinhole(px.data(), py.data(), px.size(),
                            [&](size_t i) -> Ray& { return bulk[i]; });
        for (size_t i = 0; i < px.size(); ++i) {
            const Ray one = cam.Generate(px[i], py[i], {0.5f, 0.5f}, nullptr);
            ASSERT_EQ(one.org, bulk[i].org) << i;
            ASSERT_EQ(one.dir, bulk[i].dir) << i;
            ASSERT_EQ(one.tnear, bulk[i].tnear);
            ASSERT_EQ(one.tfar, bulk[i].tfar);
            ASSERT_EQ(one.time, bulk[i].time);
        }
    }
}

// Camera samples of pixels outside the projection of the scene's bounds are not traced
// (RenderOptions::cullMissingPixels): the image is bit for bit the one with every ray traced, for
// the per-hit path, AO (two-phase tiles) and debug integrators and a stereo eye; with a lens, or
// a camera inside the bounds, nothing is culled.
TEST(Render, CulledSkyPixelsLookTheSame) {
    Scene s = PawnUnderSky();
    s.camera.pose.keys = {test::LookAt({0.0f, 3.0f, 14.0f}, {1.0f, 1.5f, 0})};  // pawn off-centre
    auto check = [&](const Scene& scene, RenderOptions o, bool expectCulled) {
        RenderScene rs(scene, {});
        o.width = 96, o.height = 64;
        const RenderResult culled = Render(rs, o);
        o.cullMissingPixels = false;
        const RenderResult all = Render(rs, o);
        EXPECT_EQ(all.stats.cameraRaysCulled, 0u);
        EXPECT_EQ(culled.stats.cameraRays + culled.stats.cameraRaysCulled, all.stats.cameraRays);
        EXPECT_EQ(culled.stats.cameraRaysCulled > 0, expectCulled)
            << culled.stats.cameraRaysCulled << " of " << all.stats.cameraRays;
        ASSERT_EQ(culled.beauty.data.size(), all.beauty.data.size());
        for (size_t i = 0; i < all.beauty.data.size(); ++i)
            ASSERT_EQ(culled.beauty.data[i], all.beauty.data[i]) << i;
    };
    for (IntegratorKind k : {IntegratorKind::Path, IntegratorKind::AO, IntegratorKind::Normal})
        check(s, SmallOptions(k, 2), true);
    RenderOptions eye = SmallOptions(IntegratorKind::Path, 2);
    eye.eyeOffset = 0.3f, eye.eyeConvergence = 14.0f;
    check(s, eye, true);
    Scene lens = s;
    lens.camera.lensRadius = 0.2f, lens.camera.focusDistance = 14.0f;
    check(lens, SmallOptions(IntegratorKind::Path, 2), false);
    Scene inside = s;
    // In the pawn's bounding box (x 1.59-1.90, y -1.43 to -1.12, z 0.03-0.52).
    inside.camera.pose.keys = {test::LookAt({1.75f, -1.27f, 0.27f}, {3.0f, -1.27f, 0.27f})};
    check(inside, SmallOptions(IntegratorKind::Path, 2), false);
}

// Same seed, same image, for 1 and 2 threads (bit-exact: every pixel sums its own samples in
// sample order whatever thread runs it).
TEST(Render, DeterministicAcrossThreadCounts) {
    const Scene s = PawnUnderSky();
    RenderScene rs(s, {});
    RenderOptions o = SmallOptions(IntegratorKind::Path, 4);
    o.seed = 42;
    Image one, two;
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
        one = Render(rs, o).beauty;
    }
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
        two = Render(rs, o).beauty;
    }
    ASSERT_EQ(one.data.size(), two.data.size());
    for (size_t i = 0; i < one.data.size(); ++i) ASSERT_EQ(one.data[i], two.data[i]) << i;
    o.seed = 43;
    const Image other = Render(rs, o).beauty;
    EXPECT_NE(other.data, one.data);  // and the seed matters
}

// Splitting at the camera hit (--hit-samples): 1 split is the plain path tracer bit for bit; more
// splits keep the camera rays and converge to the reference with the same camera rays (spp 2,
// 256 splits): the error of 16 splits against it is at most 1/4 of 1 split's (variance ~1/16,
// leaving room for the reference's own noise and the sampling of the error itself).
TEST(Render, HitSamplesShareCameraRaysAndConverge) {
    const Scene s = PawnUnderSky();
    RenderScene rs(s, {});
    RenderOptions o = SmallOptions(IntegratorKind::Path, 2);
    o.seed = 7;
    const Image plain = Render(rs, o).beauty;
    o.hitSamples = 1;
    EXPECT_EQ(Render(rs, o).beauty.data, plain.data);
    o.hitSamples = 256;
    const Image ref = Render(rs, o).beauty;
    o.hitSamples = 16;
    const double e16 = RelMSE(Render(rs, o).beauty, ref);
    const double e1 = RelMSE(plain, ref);
    EXPECT_GT(e1, 0.0);
    EXPECT_LT(e16, 0.25 * e1) << "1 split " << e1 << ", 16 splits " << e16;
    // The camera rays are shared: a reference with other camera rays keeps the edge noise.
    RenderOptions other = o;
    other.seed = 8;
    other.hitSamples = 256;
    EXPECT_GT(RelMSE(Render(rs, other).beauty, ref), e16);
}

// Runs `test(rs, camera, radius)` on the car (many small faces), a cage with holes and one with
// n-gons, each alone and seen from above one corner at 2.2 times its bounding radius.
template <typename Fn>
void OnFramedCages(int W, int H, Fn&& test) {
    for (const char* name : {"catmark_car", "catmark_hole_test1", "catmark_nonquads"}) {
        SCOPED_TRACE(name);
        Scene s = test::OneObjectScene(test::LoadMesh(name));
        glm::vec3 lo(1e30f), hi(-1e30f);
        for (const auto& p : s.meshes[0].positions)
            for (int k = 0; k < 3; ++k)
                lo[k] = std::min(lo[k], p[k]), hi[k] = std::max(hi[k], p[k]);
        const glm::vec3 centre = 0.5f * (lo + hi);
        const float radius = 0.5f * glm::length(hi - lo);
        s.camera.pose.keys = {test::LookAt(
            centre + 2.2f * radius * glm::normalize(glm::vec3(0.6f, 0.5f, 0.8f)), centre)};
        RenderSceneOptions ro;
        ro.needLights = false;
        const RenderScene rs(s, ro);
        test(rs, CameraModel(s.camera, 0.0f, W, H), radius);
    }
}

// Camera rays go to Embree 16 at a time (RenderScene::Intersect16, hinted coherent) while the
// path continues with single rays: both must find the same surface. Embree's packet and
// single-ray kernels differ in their float evaluation order, so a ray grazing an edge between
// two patches may pick either; everywhere else the hits agree to float precision. Measured on
// these cages: every found flag, primID and object identical, t and (U, V) within 1e-5.
TEST(Render, PacketHitsMatchSingleRayHits) {
    const int W = 48, H = 48;
    OnFramedCages(W, H, [&](const RenderScene& rs, const CameraModel& cam, float) {
        Rng rng(7, 0);
        int hits = 0, mismatches = 0;
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; x += 4) {
                Ray rays[16];
                for (int i = 0; i < 16; ++i)  // 4 pixels x 4 jittered samples, as a tile's block
                    rays[i] = cam.Generate(float(x + i / 4) + rng.Next1D(), float(y) + rng.Next1D(),
                                           {0.5f, 0.5f}, nullptr);
                const int n = 16 - (x + y) % 3;  // partly filled packets too
                Hit packet[16];
                bool found[16];
                rs.Intersect16(rays, n, packet, found);
                for (int i = 0; i < n; ++i) {
                    Hit single;
                    const bool f = rs.Intersect(rays[i], &single);
                    if (f != found[i]) {
                        ++mismatches;
                        continue;
                    }
                    if (!f) continue;
                    ++hits;
                    EXPECT_EQ(single.object, packet[i].object);
                    if (single.primID != packet[i].primID) {
                        ++mismatches;
                        continue;
                    }
                    EXPECT_NEAR(single.t, packet[i].t, 1e-5f * single.t);
                    EXPECT_NEAR(single.U, packet[i].U, 1e-5f);
                    EXPECT_NEAR(single.V, packet[i].V, 1e-5f);
                    EXPECT_NEAR(glm::length(single.Ng - packet[i].Ng), 0.0f,
                                1e-5f * glm::length(single.Ng));
                }
            }
        EXPECT_GT(hits, 200);
        EXPECT_EQ(mismatches, 0);
    });
}

// AO rays go to Embree in packets of up to 16 from one shading point (RenderScene::Occluded16:
// rtcOccluded4/8/16 by count): every packet size must agree with Occluded() ray by ray, on the
// car (many small faces), a cage with holes and one with n-gons. Measured: no disagreement.
TEST(Render, PacketOcclusionMatchesSingleRays) {
    int blocked = 0;  // over all cages: the convex-ish ones block few of their rays
    const int W = 32, H = 32;
    OnFramedCages(W, H, [&](const RenderScene& rs, const CameraModel& cam, float radius) {
        Rng rng(11, 0);
        int points = 0, mismatches = 0;
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                const Ray camRay =
                    cam.Generate(float(x) + 0.5f, float(y) + 0.5f, {0.5f, 0.5f}, nullptr);
                Hit hit;
                if (!rs.Intersect(camRay, &hit)) continue;
                const glm::vec3 p = camRay.org + hit.t * camRay.dir;
                const glm::vec3 ng = glm::normalize(hit.Ng);
                const int n = 1 + (x + y) % 16;  // every packet size
                Ray rays[16];
                for (int i = 0; i < n; ++i) {
                    glm::vec3 d = glm::normalize(
                        glm::vec3(rng.Next1D(), rng.Next1D(), rng.Next1D()) * 2.0f - 1.0f);
                    if (glm::dot(d, ng) < 0.0f) d = -d;
                    rays[i].org = p + 1e-4f * radius * ng;
                    rays[i].dir = d;
                    rays[i].tfar = (i % 2) ? 0.3f * radius : 1e30f;  // short and long rays
                }
                bool occluded[16];
                rs.Occluded16(rays, n, occluded);
                ++points;
                for (int i = 0; i < n; ++i) {
                    blocked += occluded[i];
                    mismatches += occluded[i] != rs.Occluded(rays[i]);
                }
            }
        EXPECT_GT(points, 100);
        EXPECT_EQ(mismatches, 0);
    });
    RecordProperty("blocked", std::to_string(blocked));
    EXPECT_GT(blocked, 50);  // the test exercises both outcomes
}

}  // namespace
// A time budget's progressive passes: another pass while one fits; after a first pass that
// leaves less than itself, camera samples against its cache (Extend) while one fits (one costs
// at most the pass's time over its camera samples); never after two passes; nothing once the
// budget is spent.
TEST(Render, BudgetStepsFillTheBudgetAfterOnePass) {
    using internal::BudgetStep;
    using internal::NextBudgetStep;
    EXPECT_EQ(NextBudgetStep(false, 1, 0.6, 0.5, 4), BudgetStep::Pass);
    EXPECT_EQ(NextBudgetStep(false, 1, 0.48, 0.5, 4), BudgetStep::Extend);
    EXPECT_EQ(NextBudgetStep(false, 1, 0.1, 0.5, 4), BudgetStep::Stop);  // under 0.5 / 4
    EXPECT_EQ(NextBudgetStep(false, 2, 0.48, 0.5, 4), BudgetStep::Stop);
    EXPECT_EQ(NextBudgetStep(false, 3, 0.6, 0.5, 4), BudgetStep::Pass);
    EXPECT_EQ(NextBudgetStep(true, 1, 0.05, 0.04, 1), BudgetStep::Extend);
    EXPECT_EQ(NextBudgetStep(true, 5, 0.03, 0.04, 1), BudgetStep::Stop);
    EXPECT_EQ(NextBudgetStep(false, 1, 0.0, 0.5, 4), BudgetStep::Stop);
    EXPECT_EQ(NextBudgetStep(false, 1, -1.0, 0.5, 4), BudgetStep::Stop);
    EXPECT_EQ(NextBudgetStep(false, 1, 0.3, 0.5, 0), BudgetStep::Stop);  // no samples: 0.5 per
    EXPECT_EQ(NextBudgetStep(false, 1, NAN, 0.5, 4), BudgetStep::Stop);
}

}  // namespace texcache
