// SPDX-License-Identifier: Apache-2.0
// The limit tessellation (texcache/limit_tessellation.h) against OpenSubdiv's patch evaluation
// (LimitSurface), on cages with n-gons and valences past Embree's limits.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "testing/cages.h"
#include "texcache/limit_tessellation.h"
#include "texcache/topology.h"

namespace texcache {
namespace {

float Diagonal(const ControlCage& c) {
    std::array<float, 3> lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
    for (const auto& p : c.positions)
        for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], p[k]), hi[k] = std::max(hi[k], p[k]);
    return std::hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
}

ControlCage CageNamed(const std::string& name) {
    if (name == "pentagon") return test::PentagonCage();
    if (name == "cube") return test::CubeCage();
    return test::BeyondEmbreeCage(name);
}

class LimitTessellationTest : public ::testing::TestWithParam<std::string> {};

// Every vertex is the limit point of the Ptex location its quads' squares give it: checks the
// refinement's face order and orientation (a wrong quadrant is off by a face's size) and
// OpenSubdiv's limit masks against its patches, whose end caps near extraordinary vertices
// approximate the limit (isolation level 10 here). Measured: at most 1.1e-6 of the diagonal
// (pole65), so the bound is 1e-5.
TEST_P(LimitTessellationTest, VerticesAreOpenSubdivLimitPoints) {
    const ControlCage cage = CageNamed(GetParam());
    const LimitSurface osd(cage, 10);
    const PtexTopology topo(cage);
    const float tol = 1e-5f * Diagonal(cage);
    const LimitTessellation t = TessellateLimitSurface(cage, 2, false);
    ASSERT_EQ(t.squares.size(), t.quads.size());
    EXPECT_TRUE(t.cornerUvs.empty());
    // The squares tile every Ptex face exactly once.
    std::map<int, double> area;
    for (const auto& s : t.squares) area[s.face] += double(s.size) * s.size;
    ASSERT_EQ(int(area.size()), topo.NumPtexFaces());
    for (const auto& [face, a] : area) EXPECT_NEAR(a, 1.0, 1e-9) << "ptex face " << face;
    float worst = 0.0f;
    for (size_t q = 0; q < t.quads.size(); ++q) {
        const LimitTessellation::Square& s = t.squares[q];
        const float cu[4] = {0, 1, 1, 0}, cv[4] = {0, 0, 1, 1};
        for (int k = 0; k < 4; ++k) {
            LimitPoint ref;
            ASSERT_TRUE(osd.Eval(s.face, s.u0 + s.size * cu[k], s.v0 + s.size * cv[k], &ref));
            const auto& p = t.positions[t.quads[q][k]];
            const float d = std::hypot(p[0] - ref.P[0], p[1] - ref.P[1], p[2] - ref.P[2]);
            worst = std::max(worst, d);
            ASSERT_LE(d, tol) << GetParam() << " quad " << q << " corner " << k;
        }
    }
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.2e", worst / Diagonal(cage));
    RecordProperty("worstOverDiagonal", buf);
}

INSTANTIATE_TEST_SUITE_P(Cages, LimitTessellationTest,
                         ::testing::Values("cube", "pentagon", "prism16", "prism20", "fan70",
                                           "pole65", "flower10x15"),
                         [](const auto& info) { return info.param; });

// Holes get no quads; the rest of the cage keeps its 4^level quads per quad.
TEST(LimitTessellation, HolesHaveNoQuads) {
    ControlCage cage = test::GridCage(3);
    cage.holes = {4};
    const LimitTessellation t = TessellateLimitSurface(cage, 3, false);
    EXPECT_EQ(t.quads.size(), size_t(8 * 64));
    for (const auto& s : t.squares) EXPECT_NE(s.face, 4);
}

// Face-varying uvs follow the quads' corners: on a flat grid whose uvs are its x and z (over the
// grid's size), Catmull-Clark reproduces the linear function in positions and in uvs (linear
// along boundaries), so every corner's uv is its own position's (x, z) / n to float precision.
TEST(LimitTessellation, CornerUvsAreTheLimitUvsOfTheirCorners) {
    const int n = 3;
    ControlCage cage = test::GridCage(n);
    for (const auto& p : cage.positions) cage.uvs.push_back({p[0] / n, p[2] / n});
    cage.faceUvIndices = cage.faceVertexIndices;
    const LimitTessellation t = TessellateLimitSurface(cage, 2, true);
    ASSERT_EQ(t.cornerUvs.size(), 4 * t.quads.size());
    for (size_t q = 0; q < t.quads.size(); ++q)
        for (int k = 0; k < 4; ++k) {
            const auto& p = t.positions[t.quads[q][k]];
            const auto& uv = t.cornerUvs[4 * q + k];
            ASSERT_NEAR(uv[0], p[0] / n, 1e-5f) << "quad " << q << " corner " << k;
            ASSERT_NEAR(uv[1], p[2] / n, 1e-5f) << "quad " << q << " corner " << k;
        }
}

}  // namespace
}  // namespace texcache
