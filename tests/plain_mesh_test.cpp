// SPDX-License-Identifier: Apache-2.0
// Plain meshes ("subdivision": "none", renderer/scene/plain_mesh.h): the polygons are rendered as
// they are (a quad plane stays flat, where Catmull-Clark would round it off), each Embree quad is
// one Ptex (sub-)face whose hit (u,v) is the face's (an n-gon's hits land on the right sub-face),
// the surface the cache evaluates is the one rays hit, and texture-space shading works on them.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "renderer/image/metrics.h"
#include "renderer/render.h"
#include "renderer/scene/plain_mesh.h"
#include "test_util.h"
#include "testing/cages.h"
#include "torus_scene.h"

namespace texcache {
namespace {

/// A 3x3 grid of quads whose centre vertices are raised: Catmull-Clark rounds it into a bump,
/// a plain mesh keeps its flat facets.
ControlCage BumpyGrid() {
    ControlCage c = test::GridCage(3);
    for (auto& p : c.positions)
        if (p[0] > 0.5f && p[0] < 2.5f && p[2] > 0.5f && p[2] < 2.5f) p[1] = 0.6f;
    return c;
}

Scene PlainScene(ControlCage cage) {
    Scene s = test::OneObjectScene(std::move(cage));
    s.objects[0].subdivide = false;
    return s;
}

/// The plane through triangle (a, b, c): its unit normal and offset.
struct PlaneEq {
    glm::vec3 n;
    float d;
    PlaneEq(glm::vec3 a, glm::vec3 b, glm::vec3 c)
        : n(glm::normalize(glm::cross(b - a, c - a))), d(glm::dot(n, a)) {}
    float Distance(glm::vec3 p) const { return std::abs(glm::dot(n, p) - d); }
};

// A quad plane stays flat: every hit on a 4x4-quad plain plane lies on y = 0 (within 1e-5 of
// its size) with the shading normal (0, 1, 0) exactly, and on the bumpy grid every hit lies on
// the plane of the triangle of its quad that Embree reports (within 1e-5), with the flat normal
// of that triangle; the subdivided bumpy grid does not (its limit surface curves: hits up to
// ~0.1 off the facets).
TEST(PlainMesh, PolygonsRenderFlat) {
    {
        Scene s = PlainScene(test::GridCage(4));
        const RenderScene rs(s, {});
        int hits = 0;
        for (int i = 0; i < 200; ++i) {
            Ray r;
            r.org = {0.3f + 0.017f * float(i), 2.0f, 0.2f + 0.019f * float(i % 37) * 2.0f};
            r.dir = glm::normalize(glm::vec3(0.1f, -1.0f, 0.05f));
            Hit h;
            if (!rs.Intersect(r, &h)) continue;
            ++hits;
            const SurfaceInteraction si = rs.Interact(r, h);
            EXPECT_NEAR(si.P.y, 0.0f, 4e-5f);
            EXPECT_EQ(si.N, glm::vec3(0.0f, 1.0f, 0.0f));
        }
        EXPECT_GT(hits, 150);
    }
    float curved = 0.0f;
    for (bool plain : {true, false}) {
        Scene s = PlainScene(BumpyGrid());
        s.objects[0].subdivide = !plain;
        const RenderScene rs(s, {});
        const PtexTopology& topo = rs.Topology(0);
        const auto corners = internal::PlainQuadCorners(s.meshes[0], topo, nullptr);
        auto at = [&](size_t i) { return glm::vec3(corners[i][0], corners[i][1], corners[i][2]); };
        float worst = 0.0f;
        int hits = 0;
        for (int i = 0; i < 30; ++i)
            for (int j = 0; j < 30; ++j) {
                Ray r;
                r.org = {0.05f + 0.1f * float(i), 3.0f, 0.05f + 0.1f * float(j)};
                r.dir = {0.0f, -1.0f, 0.0f};
                Hit h;
                if (!rs.Intersect(r, &h)) continue;
                ++hits;
                const SurfaceInteraction si = rs.Interact(r, h);
                // The triangle of the quad of its Ptex face that (u,v) lies in.
                const size_t q = 4 * size_t(si.ptex.face);
                const bool first = si.ptex.u + si.ptex.v <= 1.0f;
                const PlaneEq tri = first ? PlaneEq(at(q), at(q + 1), at(q + 3))
                                          : PlaneEq(at(q + 2), at(q + 3), at(q + 1));
                worst = std::max(worst, tri.Distance(si.P));
                if (plain) {
                    ASSERT_LT(tri.Distance(si.P), 1e-5f) << i << "," << j;
                    const float c = std::abs(glm::dot(si.N, tri.n));
                    ASSERT_NEAR(c, 1.0f, 1e-5f) << i << "," << j;
                }
            }
        EXPECT_EQ(hits, 900);
        if (!plain) curved = worst;
    }
    std::printf("subdivided bumpy grid: hits up to %.3f off the facets\n", curved);
    EXPECT_GT(curved, 0.05f);
}

// Every Ptex face of a plain mesh is one Embree quad: on the pentagon cage (a pentagon, a quad
// and a triangle: 5 + 1 + 3 sub-faces), a ray aimed at the point (u,v) of Ptex face f hits face f
// at (u,v) (within 1e-4), and the cache's surface query (EvalSurface) at (f, u, v) returns the
// point the ray hit (within 1e-5) with the same normal.
TEST(PlainMesh, NgonHitsMapToTheirSubFace) {
    Scene s = PlainScene(test::PentagonCage());
    const RenderScene rs(s, {});
    const PtexTopology& topo = rs.Topology(0);
    ASSERT_EQ(topo.NumPtexFaces(), 9);
    const auto corners = internal::PlainQuadCorners(s.meshes[0], topo, nullptr);
    for (int f = 0; f < topo.NumPtexFaces(); ++f)
        for (glm::vec2 uv : {glm::vec2(0.3f, 0.4f), glm::vec2(0.8f, 0.6f), glm::vec2(0.1f, 0.9f)}) {
            float c[16], P[3], du[3], dv[3];
            for (int k = 0; k < 4; ++k)
                for (int j = 0; j < 3; ++j) c[4 * k + j] = corners[4 * size_t(f) + k][j];
            internal::PlainQuadEval(c, uv.x, uv.y, P, du, dv);
            Ray r;
            r.org = {P[0], 1.0f, P[2]};
            r.dir = {0.0f, -1.0f, 0.0f};
            Hit h;
            ASSERT_TRUE(rs.Intersect(r, &h)) << f;
            const PtexCoord pc = rs.HitPtex(h);
            EXPECT_EQ(pc.face, f);
            EXPECT_NEAR(pc.u, uv.x, 1e-4f) << f;
            EXPECT_NEAR(pc.v, uv.y, 1e-4f) << f;
            SurfaceSample ss;
            ASSERT_TRUE(rs.EvalSurface(0, {f, uv.x, uv.y}, 0.0f, &ss));
            EXPECT_LT(glm::length(ss.P - (r.org + h.t * r.dir)), 1e-5f) << f;
            EXPECT_NEAR(std::abs(ss.N.y), 1.0f, 1e-5f) << f;
            // Sub-face i of the pentagon has its (0,0) corner at the pentagon's vertex i.
            if (f < 5) {
                const auto& v = s.meshes[0].positions[size_t(f)];
                EXPECT_EQ(corners[4 * size_t(f)], v);
            }
        }
}

// Texture-space shading on a plain mesh: AO of a plain bumpy grid, hit-binned and on the grid,
// converges to per hit's (relMSE at 64 samples a pixel against a 256-sample per-hit render,
// below 1e-2; measured 6e-3 for both), and every pixel is finite and in [0, 1].
TEST(PlainMesh, TextureSpaceShadingWorks) {
    Scene s = PlainScene(BumpyGrid());
    s.camera.pose.keys = {test::LookAt({1.5f, 3.0f, 5.0f}, {1.5f, 0.0f, 1.5f})};
    const RenderScene rs(s, {});
    RenderOptions o = test::AoOptions(256, 1);
    o.aoDistance = 1e30f;
    const Image ref = Render(rs, o).beauty;
    o.spp = 64;
    for (bool hits : {true, false}) {
        o.texture.enabled = true;
        o.texture.samples = hits ? TextureSamples::Hits : TextureSamples::Grid;
        const RenderResult r = Render(rs, o);
        const double e = RelMSE(r.beauty, ref);
        std::printf("AO on a plain mesh, %s: relMSE %.5f\n", hits ? "hits" : "grid", e);
        EXPECT_LT(e, 1e-2);
        EXPECT_TRUE(test::AllFiniteIn(r.beauty, 0.0f, 1.0f));
    }
}

}  // namespace
}  // namespace texcache
