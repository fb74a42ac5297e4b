// SPDX-License-Identifier: Apache-2.0
// Hostile and careless input, class by class (issue 47): cost that must stay near-linear in the
// input, scenes at any scale, rays Embree must never see, light and textures that are not finite,
// renders that cannot show anything. The command line's side of the same classes (flags that
// would do nothing, sizes the machine cannot hold, outputs, one-line errors) is in
// tests/robustness_cli_test.cpp.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <random>

#include "renderer/scene/obj_loader.h"
#include "renderer/scene/render_scene.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

double PeakRssMiB() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_maxrss) / 1024.0;
}

/// An n-gon on the unit circle, its rim waving by `wave` in y (0: planar).
ControlCage NGon(int n, float wave) {
    ControlCage c;
    for (int i = 0; i < n; ++i) {
        const float a = 6.2831853f * float(i) / float(n);
        c.positions.push_back({std::cos(a), wave * std::sin(3.0f * a), std::sin(a)});
        c.faceVertexIndices.push_back(i);
    }
    c.faceVertexCounts = {n};
    c.sourcePath = "ngon";
    return c;
}

// ---- Cost that grows with the square of a face -------------------------------------------------

// OpenSubdiv's patches around an n-gon's centre took n^2 stencil weights: an 8,000-gon took
// about 2.5 GB and several seconds to build. Now the large face is shaded from the limit
// tessellation and the build is near-linear: measured about 0.15 s and 30 MB (peak RSS of the
// whole test process) in Release; the bounds leave room for sanitizer builds.
TEST(LargeFaces, BuildInLinearTimeAndMemory) {
    for (const bool fan : {false, true}) {
        ControlCage cage;
        const int n = 8000;
        if (fan) {  // a vertex of valence n
            cage = NGon(n, 0.0f);
            cage.positions.push_back({0.0f, 0.3f, 0.0f});
            cage.faceVertexCounts.assign(size_t(n), 3);
            cage.faceVertexIndices.clear();
            for (int i = 0; i < n; ++i)
                for (int v : {i, n, (i + 1) % n}) cage.faceVertexIndices.push_back(v);
        } else {
            cage = NGon(n, 0.0f);
        }
        const auto t0 = std::chrono::steady_clock::now();
        Scene scene = test::OneObjectScene(cage);
        const RenderScene rs(scene, RenderSceneOptions{});
        EXPECT_LT(Seconds(t0), 20.0) << (fan ? "fan" : "n-gon");
        EXPECT_LT(PeakRssMiB(), 400.0) << (fan ? "fan" : "n-gon");
        // The planar disc is hit from above with the normal straight up.
        Ray ray;
        ray.org = {0.3f, 2.0f, 0.2f};
        ray.dir = {0.0f, -1.0f, 0.0f};
        Hit hit;
        ASSERT_TRUE(rs.Intersect(ray, &hit));
        const SurfaceInteraction si = rs.Interact(ray, hit);
        if (!fan) {
            EXPECT_GT(si.N.y, 0.9999f);
        }
        EXPECT_TRUE(std::isfinite(si.N.x + si.N.y + si.N.z));
    }
}

// A face too large for OpenSubdiv's patches is evaluated on the limit tessellation's quads: at
// the tessellation's vertices exactly on the limit surface (OpenSubdiv's patches, affordable for
// a 300-gon in a test), between them within the tessellation's error (rate 16: 8x8 quads per
// sub-face; measured 2.6% of the diagonal on this wavy face, whose sub-faces are slivers), and
// wherever a ray hits the face, at the hit point with the hit's normal (the Ptex location of a
// hit finds its own quad, parametrized as Embree does).
TEST(LargeFaces, FacetEvaluationFollowsTheLimitSurface) {
    const ControlCage cage = NGon(300, 0.2f);
    const float diagonal = 2.0f;
    Scene scene = test::OneObjectScene(cage);
    scene.settings.tessellationRate = 16.0f;
    const RenderScene rs(scene, RenderSceneOptions{});
    const LimitSurface exact(cage);
    std::mt19937 gen(47);
    std::uniform_real_distribution<float> U(0.0f, 1.0f);
    float worstVertex = 0.0f, worstBetween = 0.0f;
    for (int i = 0; i < 4000; ++i) {
        const bool vertex = i % 2 == 0;
        PtexCoord c{int(gen() % 300), U(gen), U(gen)};
        if (vertex) c.u = std::floor(c.u * 8.0f) / 8.0f, c.v = std::floor(c.v * 8.0f) / 8.0f;
        SurfaceSample s;
        LimitPoint ref;
        ASSERT_TRUE(rs.EvalSurface(0, c, 0.0f, &s));
        ASSERT_TRUE(exact.Eval(c.face, c.u, c.v, &ref));
        const float d = glm::length(s.P - glm::vec3(ref.P[0], ref.P[1], ref.P[2]));
        (vertex ? worstVertex : worstBetween) = std::max(vertex ? worstVertex : worstBetween, d);
    }
    RecordProperty("worstAtVertices", std::to_string(worstVertex / diagonal));
    RecordProperty("worstBetween", std::to_string(worstBetween / diagonal));
    EXPECT_LT(worstVertex, 1e-5f * diagonal);
    EXPECT_LT(worstBetween, 0.05f * diagonal);

    int hits = 0;
    for (int i = 0; i < 2000; ++i) {
        Ray ray;
        ray.org = {1.6f * U(gen) - 0.8f, 2.0f, 1.6f * U(gen) - 0.8f};
        ray.dir = glm::normalize(glm::vec3(0.2f * U(gen) - 0.1f, -1.0f, 0.2f * U(gen) - 0.1f));
        Hit hit;
        if (!rs.Intersect(ray, &hit)) continue;
        ++hits;
        const SurfaceInteraction si = rs.Interact(ray, hit);
        SurfaceSample s;
        ASSERT_TRUE(rs.EvalSurface(0, si.ptex, 0.0f, &s));
        EXPECT_LT(glm::length(s.P - si.P), 1e-5f * diagonal) << i;
        EXPECT_GT(std::abs(glm::dot(si.N, glm::normalize(hit.Ng))), 0.9999f) << i;
    }
    EXPECT_GT(hits, 1000);
}

// OpenSubdiv takes faces and valences of up to 65535: beyond, the OBJ reader says so on the
// face's line instead of OpenSubdiv's anonymous rejection after the whole file is read.
TEST(LargeFaces, PastOpenSubdivsLimitIsOneClearError) {
    const int n = 65536;
    std::string text, face = "f";
    for (int i = 0; i < n; ++i) {
        text += "v " + std::to_string(i) + " 0 0\n";
        face += " " + std::to_string(i + 1);
    }
    try {
        ParseObj(text + face + "\n", "big.obj", nullptr);
        FAIL() << "a 65536-gon loaded";
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()),
                  "big.obj:65537: face has 65536 vertices; OpenSubdiv takes at most 65535");
    }
}

}  // namespace
}  // namespace texcache
