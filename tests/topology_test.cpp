// SPDX-License-Identifier: Apache-2.0
// Ptex adjacency and footprints on every bundled mesh: symmetry, round trips across edges
// (including quad <-> n-gon half edges), geometric continuity against OpenSubdiv's limit
// surface, and footprints around extraordinary vertices.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <set>

#include <opensubdiv/far/stencilTableFactory.h>

#include "../libtexcache/src/osd_refiner.h"  // the reference's refiner
#include "libtexcache/topology_checks.h"
#include "test_util.h"
#include "testing/cages.h"
#include "texcache/footprint.h"
#include "texcache/topology.h"

namespace texcache {
namespace {

class TopologyTest : public ::testing::TestWithParam<std::string> {};

// A bundled mesh, or one of the cages past Embree's limits (testing/cages.h).
ControlCage Cage(const std::string& name) {
    const auto& beyond = test::BeyondEmbreeCages();
    if (std::find(beyond.begin(), beyond.end(), name) != beyond.end())
        return test::BeyondEmbreeCage(name);
    return test::LoadMesh(name);
}

TEST_P(TopologyTest, AdjacencyIsSymmetricAndRoundTrips) {
    const ControlCage cage = Cage(GetParam());
    const PtexTopology topo(cage);
    test::ExpectSymmetricAdjacency(topo, GetParam());
    int links = 0;
    for (int f = 0; f < topo.NumPtexFaces(); ++f)
        for (int e = 0; e < 4; ++e) {
            links += topo.Edge(f, e).count;
            for (float along : {0.2f, 0.5f, 0.8f}) {
                int g, ge, f2, e2;
                float u, v, s, u2, v2, s2, a2, in2, a3, in3;
                if (!topo.Cross(f, e, along, 0.0f, &g, &u, &v, &ge, &s)) continue;
                UvToEdge(ge, u, v, &a2, &in2);
                ASSERT_TRUE(topo.Cross(g, ge, a2, 0.0f, &f2, &u2, &v2, &e2, &s2));
                ASSERT_EQ(f2, f);
                UvToEdge(e2, u2, v2, &a3, &in3);
                EXPECT_NEAR(a3, along, 1e-5f);
            }
        }
    EXPECT_GT(links, 0);
}

// A point on a shared edge is the same limit point seen from either face: checks that the
// adjacency's edge numbering and orientation (and the half-edge scale) match the surface.
// Tolerance 5e-4 of the bounding-box diagonal (OpenSubdiv's end caps near extraordinary
// vertices; elsewhere ~1e-6).
TEST_P(TopologyTest, SharedEdgesAreContinuousOnTheLimitSurface) {
    const ControlCage cage = Cage(GetParam());
    const PtexTopology topo(cage);
    const LimitSurface osd(cage, 8);
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const auto& p : cage.positions)
        lo = glm::min(lo, glm::vec3(p[0], p[1], p[2])),
        hi = glm::max(hi, glm::vec3(p[0], p[1], p[2]));
    const float tol = 5e-4f * glm::length(hi - lo);
    for (int f = 0; f < topo.NumPtexFaces(); ++f)
        for (int e = 0; e < 4; ++e)
            for (float along : {0.25f, 0.5f, 0.75f}) {
                int g, ge;
                float u, v, s, fu, fv;
                if (!topo.Cross(f, e, along, 0.0f, &g, &u, &v, &ge, &s)) continue;
                EdgeToUv(e, along, 0.0f, &fu, &fv);
                LimitPoint a, b;
                if (!osd.Eval(f, fu, fv, &a) || !osd.Eval(g, u, v, &b)) continue;
                const float d =
                    glm::length(glm::vec3(a.P[0] - b.P[0], a.P[1] - b.P[1], a.P[2] - b.P[2]));
                ASSERT_LE(d, tol) << GetParam() << " face " << f << " edge " << e << " -> " << g;
            }
}

// Footprints at every corner of every face (where extraordinary vertices and n-gon centres
// sit): each sample once, all finite, inside their faces.
TEST_P(TopologyTest, FootprintsAtEveryCornerAreWellFormed) {
    const ControlCage cage = Cage(GetParam());
    const MeshGrids grids(cage, 0.01f, 7);
    std::vector<FootprintSample> fp;
    for (int f = 0; f < grids.NumFaces(); ++f)
        for (int mip : {0, 2, 100}) {
            const int m = grids.ClampMip(f, mip), res = grids.Res(f, m);
            for (auto [iu, iv] : {std::pair{0, 0}, std::pair{res - 1, 0}, std::pair{0, res - 1},
                                  std::pair{res - 1, res - 1}}) {
                GatherFootprint(grids, f, m, iu, iv, 6, &fp);
                ASSERT_FALSE(fp.empty());
                ASSERT_LE(fp.size(), 169u);
                std::set<uint64_t> keys;
                for (const auto& s : fp) {
                    ASSERT_TRUE(keys.insert(s.key.Pack()).second) << GetParam() << " face " << f;
                    ASSERT_TRUE(s.u > 0.0f && s.u < 1.0f && s.v > 0.0f && s.v < 1.0f);
                    ASSERT_LT(s.key.face - 7, uint32_t(grids.NumFaces()));
                    ASSERT_LT(int(s.key.iu), grids.Res(int(s.key.face) - 7, s.key.mip));
                }
            }
        }
}

// One refinement for both (BuildCageTopology) gives what each constructor alone gives: the same
// links across every edge and bit for bit the same regular-patch evaluation.
TEST_P(TopologyTest, OneRefinerBuildsWhatTwoDid) {
    const ControlCage cage = Cage(GetParam());
    const CageTopology both = BuildCageTopology(cage);
    const PtexTopology topo(cage);
    const RegularPatches regular(cage);
    ASSERT_EQ(both.ptex.NumPtexFaces(), topo.NumPtexFaces());
    EXPECT_EQ(both.regular.Coverage(), regular.Coverage());
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        for (int e = 0; e < 4; ++e) {
            const PtexTopology::EdgeLink a = both.ptex.Edge(f, e), b = topo.Edge(f, e);
            ASSERT_EQ(a.count, b.count);
            for (int j = 0; j < a.count; ++j) {
                EXPECT_EQ(a.face[j], b.face[j]);
                EXPECT_EQ(a.edge[j], b.edge[j]);
            }
        }
        ASSERT_EQ(both.regular.Has(f), regular.Has(f));
        if (!regular.Has(f)) continue;
        float p[2][3], du[2][3], dv[2][3];
        both.regular.Eval(f, 0.3f, 0.8f, p[0], du[0], dv[0]);
        regular.Eval(f, 0.3f, 0.8f, p[1], du[1], dv[1]);
        for (int k = 0; k < 3; ++k) {
            EXPECT_EQ(p[0][k], p[1][k]);
            EXPECT_EQ(du[0][k], du[1][k]);
            EXPECT_EQ(dv[0][k], dv[1][k]);
        }
    }
}

// The derivatives alone (a ray hit's evaluation) are Eval's bit for bit, holes included, on every
// Ptex face at its corners, edges and inside: regular, boundary, single-crease, end-cap and n-gon
// sub-face patches alike. Exact equality: the two share one code path, without the position.
TEST_P(TopologyTest, DerivativesAloneAreEvalsBitForBit) {
    const ControlCage cage = Cage(GetParam());
    const LimitSurface surface(cage);
    const PtexTopology topo(cage);
    const float st[] = {0.0f, 0.25f, 0.5f, 0.999f, 1.0f};
    int evaluated = 0;
    for (int f = 0; f < topo.NumPtexFaces(); ++f)
        for (float u : st)
            for (float v : st) {
                LimitPoint lp;
                float du[3], dv[3];
                const bool full = surface.Eval(f, u, v, &lp);
                ASSERT_EQ(surface.EvalDerivatives(f, u, v, du, dv), full)
                    << "face " << f << " (" << u << "," << v << ")";
                if (!full) continue;  // a hole
                ++evaluated;
                for (int k = 0; k < 3; ++k) {
                    ASSERT_TRUE(std::isfinite(du[k]) && std::isfinite(dv[k]));
                    ASSERT_EQ(std::memcmp(&du[k], &lp.dPdu[k], sizeof(float)), 0)
                        << "face " << f << " (" << u << "," << v << ") dPdu[" << k << "]";
                    ASSERT_EQ(std::memcmp(&dv[k], &lp.dPdv[k], sizeof(float)), 0)
                        << "face " << f << " (" << u << "," << v << ") dPdv[" << k << "]";
                }
            }
    EXPECT_GT(evaluated, 0);
    // Out of range: false from both, nothing written.
    float du[3] = {7.0f, 7.0f, 7.0f}, dv[3] = {7.0f, 7.0f, 7.0f};
    EXPECT_FALSE(surface.EvalDerivatives(-1, 0.5f, 0.5f, du, dv));
    EXPECT_FALSE(surface.EvalDerivatives(topo.NumPtexFaces(), 0.5f, 0.5f, du, dv));
    EXPECT_EQ(du[0], 7.0f);
    EXPECT_EQ(dv[2], 7.0f);
}

// What the topology of a large cage keeps: the Ptex adjacency is two packed words per Ptex edge
// (whole EdgeLinks would take 144 bytes per Ptex face: 144 MB for a 1,000,000-quad cage) and a
// regular patch its 16 vertex indices (its 16 points would take 192 bytes). Exact byte counts
// the structures report, bounded per Ptex face and cage vertex.
TEST(CageTopology, BytesPerFaceAreBounded) {
    for (const ControlCage& cage : {test::GridCage(100), test::LoadMesh("catmark_car")}) {
        const CageTopology t = BuildCageTopology(cage);
        const size_t faces = size_t(t.ptex.NumPtexFaces()), coarse = size_t(cage.numFaces()),
                     verts = size_t(cage.numVertices());
        const size_t patches = size_t(std::lround(t.regular.Coverage() * float(faces)));
        EXPECT_GT(patches, faces / 4) << cage.sourcePath;
        // Ids and valences (4 bytes each) + 8 link words per Ptex face.
        EXPECT_LE(t.ptex.Bytes(), 4 * (coarse + 1 + faces + verts) + 32 * faces) << cage.sourcePath;
        // Patch index per Ptex face, 16 indices per patch, the cage's points.
        EXPECT_LE(t.regular.Bytes(), 4 * faces + 64 * patches + 12 * verts) << cage.sourcePath;
    }
}

// LimitSurface evaluates a regular face with one semi-sharp creased edge as a single-crease patch
// (a closed form, no isolation of the crease). The reference is OpenSubdiv's limit stencils on a
// refiner that isolates every crease to level 10. The cage: a bumpy 8x8 grid with a crease row of
// sharpness S (integer, fractional, infinite) across it and a crease column of sharpness 2
// crossing it, so that the crossing vertex, the crease ends at the boundary and the faces next to
// them are isolated patches as before. Tolerances: positions 2e-6 of the grid's size (float
// rounding); derivatives 1e-4 of their size, 1e-3 for the infinitely sharp crease (at level 10
// the reference's last patches along it are end caps, ours 10 levels of the crease rule: two
// approximations of a one-sided derivative; measured 8e-4).
TEST(LimitSurface, SingleCreasePatchesMatchIsolatedCreases) {
    namespace Far = OpenSubdiv::Far;
    // The templated factory: the untemplated one downcasts its table (UBSan flags the header).
    using Factory = Far::LimitStencilTableFactoryReal<float>;
    struct Vertex {
        float p[3];
        void Clear(void* = nullptr) { p[0] = p[1] = p[2] = 0.0f; }
        void AddWithWeight(const Vertex& s, float w) {
            for (int k = 0; k < 3; ++k) p[k] += w * s.p[k];
        }
    };
    const int n = 8;
    for (float sharpness : {1.0f, 2.0f, 2.5f, 3.7f, 6.0f, 10.0f}) {
        ControlCage cage = test::GridCage(n);
        std::mt19937 gen(3);
        std::uniform_real_distribution<float> bump(-0.3f, 0.3f);
        for (auto& p : cage.positions) p[1] = bump(gen);
        auto vertex = [&](int i, int j) { return j * (n + 1) + i; };
        for (int i = 0; i < n; ++i) {
            cage.creaseEdges.push_back({vertex(i, 4), vertex(i + 1, 4)});
            cage.creaseWeights.push_back(sharpness);
            cage.creaseEdges.push_back({vertex(3, i), vertex(3, i + 1)});
            cage.creaseWeights.push_back(2.0f);
        }
        const LimitSurface ours(cage, 10);

        // The library's own refiner (the cage's creases and boundary rules), refined as before.
        std::unique_ptr<Far::TopologyRefiner> refiner = internal::CreateRefiner(cage);
        refiner->RefineAdaptive(Far::TopologyRefiner::AdaptiveOptions(10));  // isolates creases
        std::vector<float> st;
        for (int a = 0; a <= 4; ++a) st.push_back(float(a) / 4.0f);
        for (float x : {0.01f, 0.13f, 0.49f, 0.93f}) st.push_back(x);
        std::vector<float> us, vs;
        for (float u : st)
            for (float v : st) us.push_back(u), vs.push_back(v);
        Factory::LocationArrayVec locations;
        for (int f = 0; f < cage.numFaces(); ++f) {
            Factory::LocationArray l;
            l.ptexIdx = f;
            l.numLocations = int(us.size());
            l.s = us.data();
            l.t = vs.data();
            locations.push_back(l);
        }
        std::unique_ptr<const Far::LimitStencilTableReal<float>> stencils(
            Factory::Create(*refiner, locations));
        ASSERT_TRUE(stencils);
        std::vector<Vertex> cv(size_t(cage.numVertices()));
        for (size_t i = 0; i < cv.size(); ++i)
            for (int k = 0; k < 3; ++k) cv[i].p[k] = cage.positions[i][k];
        const size_t m = size_t(stencils->GetNumStencils());
        ASSERT_EQ(m, size_t(cage.numFaces()) * us.size());
        std::vector<Vertex> P(m), Du(m), Dv(m);
        stencils->UpdateValues(cv.data(), P.data());
        stencils->UpdateDerivs(cv.data(), Du.data(), Dv.data());

        float worstP = 0.0f, worstD = 0.0f;
        for (int f = 0; f < cage.numFaces(); ++f)
            for (size_t i = 0; i < us.size(); ++i) {
                const size_t r = size_t(f) * us.size() + i;
                LimitPoint lp;
                ASSERT_TRUE(ours.Eval(f, us[i], vs[i], &lp));
                float dP = 0.0f, dD = 0.0f, size = 1e-3f;
                for (int k = 0; k < 3; ++k) {
                    dP = std::max(dP, std::abs(lp.P[k] - P[r].p[k]));
                    dD = std::max(
                        {dD, std::abs(lp.dPdu[k] - Du[r].p[k]), std::abs(lp.dPdv[k] - Dv[r].p[k])});
                    size = std::max({size, std::abs(Du[r].p[k]), std::abs(Dv[r].p[k])});
                }
                worstP = std::max(worstP, dP);
                worstD = std::max(worstD, dD / size);
                ASSERT_LE(dP, 2e-6f * float(n)) << "sharpness " << sharpness << " face " << f
                                                << " (" << us[i] << "," << vs[i] << ")";
                ASSERT_LE(dD, (sharpness < 10.0f ? 1e-4f : 1e-3f) * size)
                    << "sharpness " << sharpness << " face " << f << " (" << us[i] << "," << vs[i]
                    << ")";
            }
        std::printf("sharpness %g: worst position %.2g, worst derivative %.2g (relative)\n",
                    double(sharpness), double(worstP), double(worstD));
    }
}

INSTANTIATE_TEST_SUITE_P(BundledMeshes, TopologyTest, ::testing::ValuesIn(test::BundledMeshes()),
                         [](const auto& info) { return info.param; });
// Large n-gons and valences past Embree's limits: adjacency and footprints come from the cage,
// whichever way the renderer tessellates it.
INSTANTIATE_TEST_SUITE_P(BeyondEmbree, TopologyTest, ::testing::ValuesIn(test::BeyondEmbreeCages()),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace texcache
