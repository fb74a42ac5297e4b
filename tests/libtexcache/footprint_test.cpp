// SPDX-License-Identifier: Apache-2.0
// Ptex adjacency and footprints on small cages built in code (topology.h, footprint.h): adjacency
// is symmetric, windows are complete inside a face and take each texel once around extraordinary
// vertices, pads continue windows past a face's edges, visible-texel sets restrict footprints,
// and grid resolutions follow area.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <thread>
#include <tuple>
#include <vector>

#include "libtexcache/topology_checks.h"
#include "testing/cages.h"
#include "texcache/error.h"
#include "texcache/footprint.h"
#include "texcache/topology.h"
#include "texcache/visible_texels.h"

namespace texcache {
namespace {

TEST(Topology, AdjacencyIsSymmetricIncludingHalfEdgesAndBoundaries) {
    for (const ControlCage& c : {test::GridCage(3), test::CubeCage(), test::FanCage(5),
                                 test::FanCage(12), test::PentagonCage()}) {
        const PtexTopology topo(c);
        test::ExpectSymmetricAdjacency(topo, c.sourcePath);
    }
    // Cube: closed, every Ptex edge has exactly one neighbour.
    const PtexTopology cube(test::CubeCage());
    for (int f = 0; f < 6; ++f)
        for (int e = 0; e < 4; ++e) EXPECT_EQ(cube.Edge(f, e).count, 1);
    // Pentagon + quad + triangle: 5 + 1 + 3 Ptex faces; the quad's edge on the pentagon meets two
    // sub-faces, each covering half of it; the grid's outer edges have no neighbour.
    const PtexTopology pent(test::PentagonCage());
    ASSERT_EQ(pent.NumPtexFaces(), 9);
    const int quad = pent.FirstPtexFace(1);
    EXPECT_EQ(pent.Edge(quad, 0).count, 2);
    EXPECT_FLOAT_EQ(pent.Edge(quad, 0).segLength[0], 0.5f);
    const PtexTopology grid(test::GridCage(3));
    EXPECT_EQ(grid.Edge(0, 0).count + grid.Edge(0, 3).count, 0);
}

TEST(Topology, CrossingAnEdgeAndBackReturnsToTheStart) {
    for (const ControlCage& c : {test::CubeCage(), test::PentagonCage(), test::FanCage(7)}) {
        const PtexTopology topo(c);
        for (int f = 0; f < topo.NumPtexFaces(); ++f)
            for (int e = 0; e < 4; ++e)
                for (float along : {0.1f, 0.3f, 0.5f, 0.77f}) {
                    int g, ge;
                    float u, v, s;
                    if (!topo.Cross(f, e, along, 0.0f, &g, &u, &v, &ge, &s)) continue;
                    float a2, in2;
                    UvToEdge(ge, u, v, &a2, &in2);
                    EXPECT_NEAR(in2, 0.0f, 1e-6f);
                    int f2, e2;
                    float u2, v2, s2;
                    ASSERT_TRUE(topo.Cross(g, ge, a2, 0.0f, &f2, &u2, &v2, &e2, &s2));
                    EXPECT_EQ(f2, f);
                    EXPECT_EQ(e2, e);
                    float a3, in3;
                    UvToEdge(e2, u2, v2, &a3, &in3);
                    EXPECT_NEAR(a3, along, 1e-5f);
                    EXPECT_NEAR(s * s2, 1.0f, 1e-6f);
                }
    }
}

void ExpectWellFormedFootprint(const MeshGrids& g, int face, int mip, int iu, int iv, int r) {
    std::vector<FootprintSample> fp;
    GatherFootprint(g, face, mip, iu, iv, r, &fp);
    ASSERT_FALSE(fp.empty());
    ASSERT_LE(fp.size(), size_t((2 * r + 1) * (2 * r + 1)));
    std::set<uint64_t> keys;
    bool centre = false;
    for (const auto& s : fp) {
        EXPECT_TRUE(keys.insert(s.key.Pack()).second) << "sample returned twice";
        EXPECT_TRUE(std::isfinite(s.u) && s.u > 0.0f && s.u < 1.0f);
        EXPECT_TRUE(std::isfinite(s.v) && s.v > 0.0f && s.v < 1.0f);
        EXPECT_LE(std::abs(s.dx), r);
        EXPECT_LE(std::abs(s.dy), r);
        EXPECT_LT(s.key.face - g.FaceOffset(), uint32_t(g.NumFaces()));
        centre |= s.dx == 0 && s.dy == 0;
    }
    EXPECT_TRUE(centre);
}

TEST(Footprint, InteriorWindowIsComplete) {
    const MeshGrids g(test::GridCage(4), 1.0f / 16.0f, 0);
    std::vector<FootprintSample> fp;
    GatherFootprint(g, 5, 0, 8, 8, 3, &fp);
    EXPECT_EQ(fp.size(), 49u);
    // Across an interior edge the window continues into the neighbours with no loss.
    GatherFootprint(g, 5, 0, 0, 8, 3, &fp);
    EXPECT_EQ(fp.size(), 49u);
    // At the mesh boundary the window is truncated.
    GatherFootprint(g, 0, 0, 0, 0, 3, &fp);
    EXPECT_EQ(fp.size(), 16u);
}

TEST(Footprint, AroundExtraordinaryVerticesEachSampleOnce) {
    for (int valence : {3, 5, 8, 16}) {
        const ControlCage c = valence == 3 ? test::CubeCage() : test::FanCage(valence);
        const MeshGrids g(c, 0.05f, 100);
        for (int f = 0; f < g.NumFaces(); ++f)
            for (int mip = 0; mip < g.NumLevels(f); ++mip) {
                const int res = g.Res(f, mip);
                for (int r : {0, 1, 6, 10}) {
                    ExpectWellFormedFootprint(g, f, mip, 0, 0, r);
                    ExpectWellFormedFootprint(g, f, mip, res - 1, res - 1, r);
                    ExpectWellFormedFootprint(g, f, mip, res / 2, 0, r);
                }
            }
    }
    const MeshGrids pent(test::PentagonCage(), 0.05f, 0);
    for (int f = 0; f < pent.NumFaces(); ++f)
        for (int r : {1, 4, 8}) ExpectWellFormedFootprint(pent, f, 0, 0, 0, r);
}

// Pads (footprint.cpp) continue a window past its face as a walk from the centre would when the
// neighbours' grids have the face's size: then both give the same taps, offsets and unseen
// counts, with and without a visible set, around valence-3 and valence-5 vertices and mesh
// boundaries.
TEST(Footprint, PadsMatchTheWalkOnGridsOfOneSize) {
    for (const ControlCage& c : {test::CubeCage(), test::GridCage(3), test::FanCage(5)}) {
        const MeshGrids g(c, 0.1f, 7);
        VisibleTexels vis(1 << 14);
        std::mt19937 rng(3);
        for (int f = 0; f < g.NumFaces(); ++f) {
            ASSERT_EQ(g.Log2Res(f), g.Log2Res(0)) << "the comparison needs one grid size";
            for (int mip = 0; mip < g.NumLevels(f); ++mip)
                for (int v = 0; v < g.Res(f, mip); ++v)
                    for (int u = 0; u < g.Res(f, mip); ++u)
                        if (rng() % 3 != 0)
                            vis.Mark({g.FaceOffset() + uint32_t(f), uint8_t(mip), uint16_t(u),
                                      uint16_t(v)});
        }
        std::vector<FootprintSample> padded, walked;
        auto sorted = [](const std::vector<FootprintSample>& fp) {
            std::vector<std::tuple<uint64_t, int, int, float, float>> t;
            for (const FootprintSample& s : fp) t.emplace_back(s.key.Pack(), s.dx, s.dy, s.u, s.v);
            std::sort(t.begin(), t.end());
            return t;
        };
        int compared = 0;
        for (int f = 0; f < g.NumFaces(); ++f)
            for (int mip = 0; mip < g.NumLevels(f); ++mip) {
                const int res = g.Res(f, mip);
                for (int r : {1, 3, 10})
                    for (int iv = 0; iv < res; iv += 3)
                        for (int iu = 0; iu < res; iu += 2)
                            for (const VisibleTexels* visible : {(VisibleTexels*)nullptr, &vis})
                                for (bool symmetric : {false, true}) {
                                    const int a = internal::GatherFootprint(
                                        g, f, mip, iu, iv, r, &padded, visible, symmetric, true);
                                    const int b = internal::GatherFootprint(
                                        g, f, mip, iu, iv, r, &walked, visible, symmetric, false);
                                    ASSERT_EQ(a, b) << "face " << f << " mip " << mip;
                                    ASSERT_EQ(sorted(padded), sorted(walked))
                                        << "face " << f << " mip " << mip << " texel " << iu << ","
                                        << iv << " r " << r;
                                    ++compared;
                                }
            }
        EXPECT_GT(compared, 1000);
    }
}

// Where neighbours' grids differ (n-gon sub-faces beside a quad, at two texel sizes), pads keep the
// footprint's promises: each texel once (a coarser neighbour's texel under several positions
// counts once), valid keys, the centre, and only visible taps whose mirrored offset is kept.
TEST(Footprint, MixedGridsKeepTheFootprintsPromises) {
    for (float texelSize : {0.03f, 0.011f}) {
        const MeshGrids g(test::PentagonCage(), texelSize, 0);
        VisibleTexels vis(1 << 14);
        std::mt19937 rng(5);
        bool mixed = false;
        for (int f = 0; f < g.NumFaces(); ++f) {
            mixed |= g.Log2Res(f) != g.Log2Res(0);
            for (int v = 0; v < g.Res(f, 1); ++v)
                for (int u = 0; u < g.Res(f, 1); ++u)
                    if (rng() & 1) vis.Mark({uint32_t(f), 1, uint16_t(u), uint16_t(v)});
        }
        EXPECT_TRUE(mixed) << "the mesh should have grids of several sizes";
        std::vector<FootprintSample> fp;
        for (int f = 0; f < g.NumFaces(); ++f) {
            const int res = g.Res(f, 1);
            for (int r : {2, 10})
                for (auto [iu, iv] : {std::pair{0, 0}, {res - 1, res / 2}, {res / 2, res - 1}}) {
                    GatherFootprint(g, f, 1, iu, iv, r, &fp, &vis, true);
                    std::set<uint64_t> keys;
                    std::set<std::pair<int, int>> offsets;
                    for (const FootprintSample& t : fp) {
                        EXPECT_TRUE(keys.insert(t.key.Pack()).second) << "texel twice";
                        offsets.insert({t.dx, t.dy});
                        EXPECT_TRUE((t.dx == 0 && t.dy == 0) || vis.Contains(t.key));
                        EXPECT_LT(t.key.face, uint32_t(g.NumFaces()));
                        EXPECT_LT(t.key.iu, g.Res(int(t.key.face), t.key.mip));
                        EXPECT_LE(std::abs(t.dx), r);
                        EXPECT_LE(std::abs(t.dy), r);
                    }
                    EXPECT_TRUE(offsets.count({0, 0}));
                    for (auto [dx, dy] : offsets) EXPECT_TRUE(offsets.count({-dx, -dy}));
                }
        }
    }
}

// Faces among grids of other sizes read every window from the face and its pad: a tap at
// (iu + dx, iv + dy) is that texel of the face when it lies on the face, else the pad's texel at
// that position, whatever the centre (which is what lets ShadingCache::FilterBlock reconstruct
// a whole block from one tile). Windows whose columns stay on the face still give the walk's
// taps (the walk leaves the face along v at its edge row, where the pad's walk starts); windows
// crossing the sides into a grid of another size differ from it, and both cases must occur.
TEST(Footprint, MixedGridsReadThePad) {
    for (float texelSize : {0.03f, 0.011f}) {
        const MeshGrids g(test::PentagonCage(), texelSize, 0);
        VisibleTexels vis(1 << 14);
        std::mt19937 rng(9);
        for (int f = 0; f < g.NumFaces(); ++f)
            for (int mip = 0; mip < g.NumLevels(f); ++mip)
                for (int v = 0; v < g.Res(f, mip); ++v)
                    for (int u = 0; u < g.Res(f, mip); ++u)
                        if (rng() % 3 != 0)
                            vis.Mark({uint32_t(f), uint8_t(mip), uint16_t(u), uint16_t(v)});
        auto sorted = [](const std::vector<FootprintSample>& fp) {
            std::vector<std::tuple<uint64_t, int, int, float, float>> t;
            for (const FootprintSample& s : fp) t.emplace_back(s.key.Pack(), s.dx, s.dy, s.u, s.v);
            std::sort(t.begin(), t.end());
            return t;
        };
        std::vector<FootprintSample> read, walked;
        int compared = 0, columnsOnFace = 0, differFromWalk = 0;
        for (int f = 0; f < g.NumFaces(); ++f)
            for (int mip = 0; mip < g.NumLevels(f); ++mip) {
                const int res = g.Res(f, mip);
                for (int r : {1, 10}) {
                    ASSERT_NE(internal::PaddedRun(g, f, mip, r, -1, -1), nullptr);
                    for (int iv = 0; iv < res; iv += std::max(3, res / 5))
                        for (int iu = 0; iu < res; iu += std::max(2, res / 7))
                            for (const VisibleTexels* visible : {(VisibleTexels*)nullptr, &vis})
                                for (bool symmetric : {false, true}) {
                                    internal::GatherFootprint(g, f, mip, iu, iv, r, &read, visible,
                                                              symmetric, true);
                                    for (const FootprintSample& t : read) {
                                        const int x = iu + t.dx, y = iv + t.dy;
                                        if (x >= 0 && x < res && y >= 0 && y < res) {
                                            const TexelKey own{g.FaceOffset() + uint32_t(f),
                                                               uint8_t(mip), uint16_t(x),
                                                               uint16_t(y)};
                                            ASSERT_EQ(t.key.Pack(), own.Pack());
                                            continue;
                                        }
                                        const internal::PaddedTexel* p =
                                            internal::PaddedRun(g, f, mip, r, x, y);
                                        ASSERT_TRUE(p->flags & internal::PaddedTexel::kReached);
                                        ASSERT_EQ(t.key.Pack(), p->key)
                                            << "face " << f << " mip " << mip << " texel " << iu
                                            << "," << iv << " r " << r;
                                        ASSERT_EQ(t.u, p->u);
                                        ASSERT_EQ(t.v, p->v);
                                    }
                                    internal::GatherFootprint(g, f, mip, iu, iv, r, &walked,
                                                              visible, symmetric, false);
                                    const bool onFace = iu >= r && iu + r < res;
                                    if (onFace) {
                                        ASSERT_EQ(sorted(read), sorted(walked))
                                            << "face " << f << " mip " << mip << " texel " << iu
                                            << "," << iv << " r " << r;
                                        ++columnsOnFace;
                                    } else {
                                        differFromWalk += sorted(read) != sorted(walked);
                                    }
                                    ++compared;
                                }
                }
            }
        EXPECT_GT(columnsOnFace, 50);
        EXPECT_GT(differFromWalk, 50) << "windows crossing into grids of other sizes";
        EXPECT_GT(compared, 1000);
    }
}

// ---- Visible texels (visible_texels.h) ----

TEST(VisibleTexels, NeverMissesAMarkAndRarelyInventsOne) {
    // 20000 random texels in a 64 KB table (8192 words): a marked texel is always found; an
    // unmarked one only where its 8x8 block shares a word with a marked block.
    VisibleTexels vis(64 << 10);
    EXPECT_EQ(vis.Bytes(), size_t(64) << 10);
    std::mt19937 rng(7);
    auto randomKey = [&] {
        return TexelKey{uint32_t(rng() % 5000), uint8_t(rng() % 8), uint16_t(rng() % 4096),
                        uint16_t(rng() % 4096)};
    };
    std::set<uint64_t> marked;
    for (int i = 0; i < 20000; ++i) {
        const TexelKey k = randomKey();
        vis.Mark(k);
        marked.insert(k.Pack());
    }
    for (uint64_t k : marked) ASSERT_TRUE(vis.Contains(TexelKey::Unpack(k)));
    int falsePositives = 0, tested = 0;
    for (int i = 0; i < 20000; ++i) {
        const TexelKey k = randomKey();
        if (marked.count(k.Pack())) continue;
        ++tested, falsePositives += vis.Contains(k);
    }
    // ~20000 of 8192 words hold a mark (most words): a random texel of an unmarked block hits a
    // set bit with probability about 1 - exp(-20000 / 8192 / 64) = 3.7%.
    EXPECT_LT(double(falsePositives) / tested, 0.08);
    vis.Clear();
    for (uint64_t k : marked) ASSERT_FALSE(vis.Contains(TexelKey::Unpack(k)));
}

TEST(VisibleTexels, ConcurrentMarksAreAllKept) {
    // Four threads mark interleaved texels of the same blocks (the same words): fetch_or keeps
    // every bit. Run under ThreadSanitizer by scripts/test.sh (label `cache`).
    VisibleTexels vis(4096);
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            for (int i = t; i < 64 * 64; i += 4)
                vis.Mark({3, 2, uint16_t(i % 64), uint16_t(i / 64)});
        });
    for (auto& th : threads) th.join();
    for (int i = 0; i < 64 * 64; ++i)
        ASSERT_TRUE(vis.Contains({3, 2, uint16_t(i % 64), uint16_t(i / 64)})) << i;
}

// A restricted footprint is the unrestricted one filtered by the set (plus the centre) and
// made point-symmetric, in the same order, inside a face, across edges and around extraordinary
// vertices; the return value counts what was left out.
TEST(VisibleTexels, RestrictedFootprintIsTheVisibleSubset) {
    for (int valence : {3, 4, 5, 8}) {
        const ControlCage c = valence == 3   ? test::CubeCage()
                              : valence == 4 ? test::GridCage(4)
                                             : test::FanCage(valence);
        const MeshGrids g(c, 0.02f, 10);
        VisibleTexels vis(1 << 16);
        std::mt19937 rng(valence);
        std::vector<FootprintSample> all, seen;
        for (int f = 0; f < g.NumFaces(); ++f) {
            const int mip = 0, res = g.Res(f, mip);
            // Mark a random half of the face's texels (and none of some faces).
            if (f % 3 != 2)
                for (int v = 0; v < res; ++v)
                    for (int u = 0; u < res; ++u)
                        if (rng() & 1)
                            vis.Mark({g.FaceOffset() + uint32_t(f), 0, uint16_t(u), uint16_t(v)});
        }
        for (int f = 0; f < g.NumFaces(); ++f) {
            const int res = g.Res(f, 0);
            for (int r : {0, 2, 10})
                for (auto [iu, iv] : {std::pair{0, 0}, {res / 2, res / 2}, {res - 1, 3}}) {
                    GatherFootprint(g, f, 0, iu, iv, r, &all);
                    const int unseen = GatherFootprint(g, f, 0, iu, iv, r, &seen, &vis);
                    // Seen (or the centre), and so is the tap at the mirrored offset.
                    std::set<std::pair<int, int>> seenOffsets;
                    for (const FootprintSample& t : all)
                        if ((t.dx == 0 && t.dy == 0) || vis.Contains(t.key))
                            seenOffsets.insert({t.dx, t.dy});
                    std::vector<FootprintSample> expect;
                    for (const FootprintSample& t : all)
                        if (seenOffsets.count({t.dx, t.dy}) && seenOffsets.count({-t.dx, -t.dy}))
                            expect.push_back(t);
                    ASSERT_EQ(seen.size(), expect.size()) << "face " << f << " r " << r;
                    for (size_t i = 0; i < seen.size(); ++i) {
                        EXPECT_EQ(seen[i].key, expect[i].key);
                        EXPECT_EQ(seen[i].dx, expect[i].dx);
                        EXPECT_EQ(seen[i].dy, expect[i].dy);
                        EXPECT_EQ(seen[i].u, expect[i].u);
                    }
                    // Walks that reach a texel twice are counted twice when it is unseen.
                    EXPECT_GE(unseen, int(all.size() - seen.size()));
                    EXPECT_TRUE(std::any_of(seen.begin(), seen.end(),
                                            [](auto& t) { return t.dx == 0 && t.dy == 0; }));
                }
        }
    }
}

TEST(MeshGrids, ResolutionFollowsAreaAndRejectsKeyOverflow) {
    const MeshGrids g(test::GridCage(2), 1.0f / 32.0f, 0);  // unit faces, 1/32 texels -> 32 = 2^5
    for (int f = 0; f < g.NumFaces(); ++f) EXPECT_EQ(g.Log2Res(f), 5);
    EXPECT_THROW(MeshGrids(test::GridCage(2), 0.1f, TexelKey::kMaxFaces - 2), InputError);
    EXPECT_THROW(MeshGrids(test::GridCage(2), 0.0f, 0), InputError);
    EXPECT_THROW(MeshGrids(test::GridCage(2), NAN, 0), InputError);
}

}  // namespace
}  // namespace texcache
