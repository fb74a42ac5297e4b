// SPDX-License-Identifier: Apache-2.0
// Embree's subdivision hits and limit evaluation against OpenSubdiv (the independent reference),
// on every bundled mesh.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <thread>
#include <vector>

#include "renderer/scene/render_scene.h"
#include "renderer/texture_space/ptex_mapping.h"
#include "test_util.h"
#include "texcache/error.h"
#include "texcache/topology.h"

namespace texcache {
namespace {

float BBoxDiagonal(const ControlCage& c) {
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const auto& p : c.positions) {
        lo = glm::min(lo, glm::vec3(p[0], p[1], p[2]));
        hi = glm::max(hi, glm::vec3(p[0], p[1], p[2]));
    }
    return glm::length(hi - lo);
}

glm::vec3 V(const std::array<float, 3>& a) {
    return {a[0], a[1], a[2]};
}

class PtexMappingTest : public ::testing::TestWithParam<std::string> {};

TEST_P(PtexMappingTest, EncodeDecodeRoundTrip) {
    const ControlCage cage = test::LoadMesh(GetParam());
    const PtexTopology topo(cage);
    std::mt19937 gen(1);
    std::uniform_real_distribution<float> U01(0.0f, 1.0f);
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        const PtexCoord c{f, U01(gen), U01(gen)};
        unsigned prim;
        float U, V;
        PtexToEmbree(topo, c, &prim, &U, &V);
        const PtexCoord back = EmbreeToPtex(topo, prim, U, V);
        ASSERT_EQ(back.face, c.face);
        EXPECT_NEAR(back.u, c.u, 1e-6f);  // a few ulps of the +0.5 shift
        EXPECT_NEAR(back.v, c.v, 1e-6f);
    }
}

// rtcInterpolate (through our Ptex -> Embree mapping) must agree with OpenSubdiv's Far limit
// evaluation, including creases, corners, holes and boundaries. Both libraries approximate the
// limit near extraordinary vertices (OSD with Gregory end caps at isolation level 6), where they
// differ most: measured worst 2.5e-4 of the bounding-box diagonal (bishop's valence-24 pole),
// 1e-7 on the simple shapes. Tolerance: 5e-4 of the diagonal. (Derivatives are checked against
// each library's own finite differences below: near extraordinary vertices the two libraries'
// patch approximations differ by up to 30% in derivatives while agreeing in position.)
TEST_P(PtexMappingTest, LimitPositionsAgreeWithOpenSubdiv) {
    ControlCage cage = test::WithoutFractionalSharpness(test::LoadMesh(GetParam()));
    const float diag = BBoxDiagonal(cage);
    const float tol = 5e-4f * diag;
    // Isolation level 10: OSD's end caps round infinitely sharp corners by ~2^-level.
    const LimitSurface osd(cage, 10);
    Scene scene = test::OneObjectScene(cage);
    RenderSceneOptions ro;
    ro.needLights = false;
    RenderScene rs(scene, ro);
    const PtexTopology& topo = rs.Topology(0);
    std::mt19937 gen(7);
    std::uniform_real_distribution<float> U01(0.0f, 1.0f);
    int evaluated = 0;
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        for (int k = 0; k < 4; ++k) {
            const PtexCoord c{f, U01(gen), U01(gen)};
            LimitPoint ref;
            if (!osd.Eval(f, c.u, c.v, &ref)) continue;  // hole
            SurfaceSample s;
            ASSERT_TRUE(rs.EvalSurface(0, c, 0.0f, &s));
            ASSERT_LE(glm::length(s.P - V(ref.P)), tol)
                << GetParam() << " ptex face " << f << " (" << c.u << "," << c.v << ")";
            ++evaluated;
        }
    }
    EXPECT_GT(evaluated, 0);
}

// The reference's derivatives are those of its own positions (central differences, h = 1e-3,
// tolerance 2% of the derivative's size): this pins the n-gon sub-face derivative scale.
TEST_P(PtexMappingTest, OpenSubdivDerivativesMatchFiniteDifferences) {
    const ControlCage cage = test::LoadMesh(GetParam());
    const LimitSurface osd(cage);
    const PtexTopology topo(cage);
    const float h = 1e-3f;
    for (int f = 0; f < topo.NumPtexFaces(); f += 3) {
        LimitPoint p, pu0, pu1, pv0, pv1;
        const float u = 0.37f, v = 0.61f;
        if (!osd.Eval(f, u, v, &p) || !osd.Eval(f, u + h, v, &pu1) ||
            !osd.Eval(f, u, v + h, &pv1) || !osd.Eval(f, u - h, v, &pu0) ||
            !osd.Eval(f, u, v - h, &pv0))
            continue;
        const glm::vec3 fdU = (V(pu1.P) - V(pu0.P)) / (2 * h),
                        fdV = (V(pv1.P) - V(pv0.P)) / (2 * h);
        // Plus float rounding of the positions amplified by 1/h (faces with tiny derivatives).
        const glm::vec3 P = V(p.P);
        const float pmag = std::max({1.0f, std::abs(P.x), std::abs(P.y), std::abs(P.z)});
        const float scale = glm::length(fdU) + glm::length(fdV) + 50.0f * 1.2e-7f * pmag / h;
        EXPECT_LE(glm::length(fdU - V(p.dPdu)), 2e-2f * scale) << GetParam() << " face " << f;
        EXPECT_LE(glm::length(fdV - V(p.dPdv)), 2e-2f * scale) << GetParam() << " face " << f;
    }
}

// A LimitSurface built for some cage faces evaluates them as the whole cage's does (positions
// within 1e-6 of the diagonal, derivatives within 1e-4 of their size: the selection changes
// which faces are refined, not the rules), and no other face; a face out of range is an error.
TEST_P(PtexMappingTest, SelectedFacesEvaluateAsTheWholeCage) {
    const ControlCage cage = test::LoadMesh(GetParam());
    const float diag = BBoxDiagonal(cage);
    std::vector<int> odd;
    for (int f = 1; f < cage.numFaces(); f += 2) odd.push_back(f);
    const LimitSurface all(cage), some(cage, 6, odd);
    const PtexTopology topo(cage);
    int checked = 0;
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        LimitPoint a, b;
        const bool selected = topo.CoarseFace(f) % 2 == 1;
        const bool inAll = all.Eval(f, 0.3f, 0.8f, &a);
        EXPECT_EQ(some.Eval(f, 0.3f, 0.8f, &b), selected && inAll) << GetParam() << " " << f;
        if (!selected || !inAll) continue;
        const float scale = glm::length(V(a.dPdu)) + glm::length(V(a.dPdv));
        EXPECT_LE(glm::length(V(a.P) - V(b.P)), 1e-6f * diag) << GetParam() << " " << f;
        EXPECT_LE(glm::length(V(a.dPdu) - V(b.dPdu)), 1e-4f * scale) << GetParam() << " " << f;
        EXPECT_LE(glm::length(V(a.dPdv) - V(b.dPdv)), 1e-4f * scale) << GetParam() << " " << f;
        ++checked;
    }
    EXPECT_GT(checked, 0) << GetParam();
    EXPECT_THROW(LimitSurface(cage, 6, std::vector<int>{cage.numFaces()}), InputError);
    EXPECT_THROW(LimitSurface(cage, 6, std::vector<int>{-1}), InputError);
}

// OpenSubdiv's patches for the faces off the regular fast path (RenderSceneOptions::
// irregularPatches, the default) evaluate Embree's surface: against rtcInterpolate on every Ptex
// face, positions within 5e-4 of the diagonal (the two libraries' measured worst: see
// LimitPositionsAgreeWithOpenSubdiv) and shading normals within TOL degrees.
TEST_P(PtexMappingTest, IrregularPatchesMatchRtcInterpolate) {
    const ControlCage cage = test::WithoutFractionalSharpness(test::LoadMesh(GetParam()));
    const float diag = BBoxDiagonal(cage);
    Scene scene = test::OneObjectScene(cage);
    RenderSceneOptions ro;
    ro.needLights = false;
    const RenderScene patches(scene, ro);
    ro.irregularPatches = false;
    const RenderScene embree(scene, ro);
    const PtexTopology& topo = patches.Topology(0);
    float worstP = 0.0f, worstDeg = 0.0f;
    int n = 0, off = 0;
    for (int f = 0; f < topo.NumPtexFaces(); ++f)
        for (float u : {0.02f, 0.5f, 0.97f})
            for (float v : {0.03f, 0.45f, 1.0f}) {
                SurfaceSample a, b;
                if (!embree.EvalSurface(0, {f, u, v}, 0.0f, &b)) continue;  // hole
                ASSERT_TRUE(patches.EvalSurface(0, {f, u, v}, 0.0f, &a)) << f;
                ASSERT_TRUE(std::isfinite(a.N.x + a.N.y + a.N.z)) << f;
                worstP = std::max(worstP, glm::length(a.P - b.P));
                const float c = std::clamp(glm::dot(a.N, b.N), -1.0f, 1.0f);
                const float deg = glm::degrees(std::acos(c));
                worstDeg = std::max(worstDeg, deg);
                off += deg > 10.0f;
                ++n;
            }
    std::printf(
        "%s: worst position %.3g of the diagonal, worst normal %.3g degrees, %d of %d "
        "normals more than 10 degrees off\n",
        GetParam().c_str(), worstP / diag, worstDeg, off, n);
    EXPECT_LE(worstP, 5e-4f * diag) << GetParam();
    EXPECT_LE(off, n / 200) << GetParam();
}

// Queries of the faces off the fast path (OpenSubdiv's patches, in parts built in parallel at
// load) from many threads at once give what queries one at a time give, bit for bit; run under
// ThreadSanitizer as well.
TEST_P(PtexMappingTest, IrregularPatchesUnderConcurrentQueries) {
    const ControlCage cage = test::LoadMesh(GetParam());
    Scene scene = test::OneObjectScene(cage);
    RenderSceneOptions ro;
    ro.needLights = false;
    const RenderScene serial(scene, ro), parallel(scene, ro);
    const int n = parallel.Topology(0).NumPtexFaces();
    std::vector<SurfaceSample> want(static_cast<size_t>(n)), got(static_cast<size_t>(n));
    std::vector<char> okWant(static_cast<size_t>(n)), okGot(static_cast<size_t>(n));
    for (int f = 0; f < n; ++f) okWant[f] = serial.EvalSurface(0, {f, 0.4f, 0.7f}, 0.0f, &want[f]);
    // std::threads, not TBB: ThreadSanitizer reads TBB's work stealing as races of its own.
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            for (int f = t; f < n; f += 4)
                okGot[f] = parallel.EvalSurface(0, {f, 0.4f, 0.7f}, 0.0f, &got[f]);
        });
    for (std::thread& t : threads) t.join();
    for (int f = 0; f < n; ++f) {
        ASSERT_EQ(okGot[f], okWant[f]) << f;
        if (!okWant[f]) continue;
        ASSERT_EQ(got[f].P, want[f].P) << GetParam() << " " << f;
        ASSERT_EQ(got[f].N, want[f].N) << GetParam() << " " << f;
        ASSERT_EQ(got[f].dPdu, want[f].dPdu) << GetParam() << " " << f;
    }
}

// Rays that hit the mesh: the decoded Ptex location's limit point lies near the tessellated hit
// (at tessellation rate 8 the surfaces differ by well under 1% of the diagonal).
TEST_P(PtexMappingTest, RayHitsDecodeToTheirPtexLocation) {
    ControlCage cage = test::WithoutFractionalSharpness(test::LoadMesh(GetParam()));
    const float diag = BBoxDiagonal(cage);
    const LimitSurface osd(cage);
    Scene scene = test::OneObjectScene(cage);
    scene.settings.tessellationRate = 8.0f;
    RenderSceneOptions ro;
    ro.needLights = false;
    RenderScene rs(scene, ro);
    const auto hits = test::DecodeHits(rs, osd, test::RaysAround(cage, 400, 3, 0.2f));
    for (const test::DecodedHit& h : hits) {
        ASSERT_GE(h.offLimit, 0.0f) << GetParam() << " ray " << h.ray;
        EXPECT_LE(h.offLimit, 1e-2f * diag) << GetParam() << " ray " << h.ray;
        EXPECT_TRUE(std::isfinite(h.N.x + h.N.y + h.N.z));
        EXPECT_NEAR(glm::length(h.N), 1.0f, 1e-4f);
    }
    EXPECT_GT(hits.size(), 20u) << GetParam();
}

// Embree's derivatives (what ray differentials and the cache's surface query use) are those of
// its own positions: central differences, h = 1e-3, within 2% of the derivative's size.
TEST_P(PtexMappingTest, EmbreeDerivativesMatchFiniteDifferences) {
    const ControlCage cage = test::LoadMesh(GetParam());
    Scene scene = test::OneObjectScene(cage);
    RenderSceneOptions ro;
    ro.needLights = false;
    RenderScene rs(scene, ro);
    const PtexTopology& topo = rs.Topology(0);
    const float h = 1e-3f;
    int checked = 0;
    for (int f = 0; f < topo.NumPtexFaces(); f += 3) {
        SurfaceSample p, pu0, pu1, pv0, pv1;
        const float u = 0.37f, v = 0.61f;
        rs.EvalSurface(0, {f, u, v}, 0, &p);
        rs.EvalSurface(0, {f, u - h, v}, 0, &pu0);
        rs.EvalSurface(0, {f, u + h, v}, 0, &pu1);
        rs.EvalSurface(0, {f, u, v - h}, 0, &pv0);
        rs.EvalSurface(0, {f, u, v + h}, 0, &pv1);
        const glm::vec3 fdU = (pu1.P - pu0.P) / (2 * h), fdV = (pv1.P - pv0.P) / (2 * h);
        // Plus float rounding of the positions amplified by 1/h (faces with tiny derivatives).
        const float pmag = std::max({1.0f, std::abs(p.P.x), std::abs(p.P.y), std::abs(p.P.z)});
        const float scale = glm::length(fdU) + glm::length(fdV) + 50.0f * 1.2e-7f * pmag / h;
        EXPECT_LE(glm::length(fdU - p.dPdu), 2e-2f * scale) << GetParam() << " face " << f;
        EXPECT_LE(glm::length(fdV - p.dPdv), 2e-2f * scale) << GetParam() << " face " << f;
        ++checked;
    }
    EXPECT_GT(checked, 0);
}

// The regular-patch fast path evaluates the same surface as OpenSubdiv (and so Embree):
// positions within 1e-5 of the diagonal, derivatives within 1e-3 of their size.
TEST_P(PtexMappingTest, RegularPatchFastPathMatchesOpenSubdiv) {
    const ControlCage cage = test::LoadMesh(GetParam());
    const RegularPatches fast(cage);
    const LimitSurface osd(cage);
    const float diag = BBoxDiagonal(cage);
    const PtexTopology topo(cage);
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        if (!fast.Has(f)) continue;
        for (float u : {0.0f, 0.3f, 1.0f})
            for (float v : {0.0f, 0.6f, 1.0f}) {
                float P[3], du[3], dv[3];
                fast.Eval(f, u, v, P, du, dv);
                LimitPoint ref;
                ASSERT_TRUE(osd.Eval(f, u, v, &ref));
                const float scale = glm::length(V(ref.dPdu)) + glm::length(V(ref.dPdv));
                ASSERT_LE(glm::length(glm::vec3(P[0], P[1], P[2]) - V(ref.P)), 1e-5f * diag) << f;
                ASSERT_LE(glm::length(glm::vec3(du[0], du[1], du[2]) - V(ref.dPdu)), 1e-3f * scale)
                    << f;
                ASSERT_LE(glm::length(glm::vec3(dv[0], dv[1], dv[2]) - V(ref.dPdv)), 1e-3f * scale)
                    << f;
            }
    }
    if (GetParam() == "catmark_torus") {
        EXPECT_EQ(fast.Coverage(), 1.0f);  // fully regular
    }
    if (GetParam() == "catmark_cube") {
        EXPECT_EQ(fast.Coverage(), 0.0f);  // every face touches a valence-3 vertex
    }
}

// Both evaluate the same B-spline patch in float, summing in different orders: they agree to
// rounding, within 1e-6 of the cage's largest coordinate in every component of the position and
// of both derivatives (measured: up to 4e-7 of it, on the car and the rook), over a 7x7 grid
// of each regular face, boundaries included.
TEST_P(PtexMappingTest, RegularPatchFastPathMatchesOpenSubdivToRounding) {
    const ControlCage cage = test::LoadMesh(GetParam());
    const RegularPatches fast(cage);
    const LimitSurface osd(cage);
    float extent = 0.0f;
    for (const auto& p : cage.positions)
        for (float x : p) extent = std::max(extent, std::abs(x));
    const float tol = 1e-6f * extent;
    const PtexTopology topo(cage);
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        if (!fast.Has(f)) continue;
        for (int i = 0; i <= 6; ++i)
            for (int j = 0; j <= 6; ++j) {
                const float u = float(i) / 6.0f, v = float(j) / 6.0f;
                float P[3], du[3], dv[3];
                fast.Eval(f, u, v, P, du, dv);
                LimitPoint ref;
                ASSERT_TRUE(osd.Eval(f, u, v, &ref));
                for (int k = 0; k < 3; ++k) {
                    ASSERT_NEAR(P[k], ref.P[k], tol) << "face " << f << " u " << u << " v " << v;
                    ASSERT_NEAR(du[k], ref.dPdu[k], tol)
                        << "face " << f << " u " << u << " v " << v;
                    ASSERT_NEAR(dv[k], ref.dPdv[k], tol)
                        << "face " << f << " u " << u << " v " << v;
                }
            }
    }
}

// Fractional sharpness is where the two libraries part: OpenSubdiv blends crease and smooth
// rules for sharpness < 1, Embree does not reproduce that (measured: up to 0.2 units on
// catmark_cube_creases1's 0.1 crease, 6% of its size). We render with Embree; this test pins
// the size of the difference so a change in either library shows up.
TEST(PtexMapping, FractionalCreasesDifferBetweenEmbreeAndOpenSubdiv) {
    const ControlCage cage = test::LoadMesh("catmark_cube_creases1");
    const LimitSurface osd(cage);
    Scene scene = test::OneObjectScene(cage);
    RenderSceneOptions ro;
    ro.needLights = false;
    RenderScene rs(scene, ro);
    float worst = 0.0f;
    for (int f = 0; f < 6; ++f) {
        LimitPoint ref;
        SurfaceSample s;
        ASSERT_TRUE(osd.Eval(f, 0.5f, 0.5f, &ref));
        ASSERT_TRUE(rs.EvalSurface(0, {f, 0.5f, 0.5f}, 0.0f, &s));
        worst = std::max(worst, glm::length(s.P - V(ref.P)));
    }
    EXPECT_TRUE(std::isfinite(worst));
    EXPECT_LT(worst, 0.1f * BBoxDiagonal(cage));
}

// Rays through a hole face pass through it; no hit decodes to it.
TEST(PtexMapping, HoleFacesAreNeverHit) {
    const ControlCage cage = test::LoadMesh("catmark_hole_test1");
    ASSERT_EQ(cage.holes.size(), 1u);
    Scene scene = test::OneObjectScene(cage);
    RenderSceneOptions ro;
    ro.needLights = false;
    RenderScene rs(scene, ro);
    const PtexTopology& topo = rs.Topology(0);
    int hits = 0;
    for (int i = 0; i < 2000; ++i) {
        const float a = 6.2831853f * float(i) / 2000.0f,
                    b = 3.14159f * float((i * 37) % 100) / 100.0f;
        const glm::vec3 d(std::sin(b) * std::cos(a), std::cos(b), std::sin(b) * std::sin(a));
        Ray ray;
        ray.org = -4.0f * d;
        ray.dir = d;
        Hit hit;
        if (!rs.Intersect(ray, &hit)) continue;
        ++hits;
        ASSERT_NE(topo.CoarseFace(EmbreeToPtex(topo, hit.primID, hit.U, hit.V).face),
                  cage.holes[0]);
    }
    EXPECT_GT(hits, 1000);
}

INSTANTIATE_TEST_SUITE_P(BundledMeshes, PtexMappingTest, ::testing::ValuesIn(test::BundledMeshes()),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace texcache
