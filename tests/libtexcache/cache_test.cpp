// SPDX-License-Identifier: Apache-2.0
// libtexcache on its own: keys, eq. 1/2, the lock-free direct-mapped cache (collisions, byte
// budget, concurrent stress), Ptex adjacency and footprints on synthetic cages, and the two-level
// ShadingCache (reference mode shades each sample once).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <mutex>
#include <new>
#include <random>
#include <set>
#include <thread>
#include <tuple>
#include <unordered_map>

#include <unistd.h>

#include "libtexcache/topology_checks.h"
#include "testing/cages.h"
#include "texcache/direct_mapped_cache.h"
#include "texcache/footprint.h"
#include "texcache/shading_cache.h"
#include "texcache/texel_key.h"
#include "texcache/topology.h"
#include "texcache/visible_texels.h"

// Counts heap allocations in this test binary (for the no-allocation-per-lookup test). GCC warns
// that free() does not match new: it does here, this is the replacement of both.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
static std::atomic<uint64_t> gAllocations{0};
void* operator new(size_t n) {
    ++gAllocations;
    if (void* p = std::malloc(n ? n : 1)) return p;
    throw std::bad_alloc();
}
void operator delete(void* p) noexcept {
    std::free(p);
}
void operator delete(void* p, size_t) noexcept {
    std::free(p);
}

namespace texcache {
namespace {

TEST(TexelKey, PackUnpackRoundTripsAtTheLimits) {
    for (TexelKey k : {TexelKey{0, 0, 0, 0}, TexelKey{TexelKey::kMaxFaces - 1, 15, 16383, 16383},
                       TexelKey{12345, 7, 100, 9000}}) {
        const TexelKey back = TexelKey::Unpack(k.Pack());
        EXPECT_EQ(back.face, k.face);
        EXPECT_EQ(back.mip, k.mip);
        EXPECT_EQ(back.iu, k.iu);
        EXPECT_EQ(back.iv, k.iv);
        EXPECT_NE(k.Pack(), TexelKey::kEmpty);
    }
}

// ComputeMip's exponent from the float's bits is std::ilogb's for every positive finite float
// kind: subnormal, normal, each power of two and its neighbours, the largest.
TEST(Addressing, FloatExponentMatchesIlogb) {
    for (float x = std::numeric_limits<float>::denorm_min(); std::isfinite(x);
         x = std::max(x * 1.37f, std::nextafter(x, INFINITY)))  // subnormals round x * 1.37 to x
        for (float y : {x, std::nextafter(x, 0.0f), std::nextafter(x, INFINITY)})
            if (y > 0.0f && std::isfinite(y)) {
                ASSERT_EQ(FloatExponent(y), std::ilogb(y)) << y;
            }
    for (int p = -149; p <= 127; ++p) {
        const float x = std::ldexp(1.0f, p);
        ASSERT_EQ(FloatExponent(x), p);
        if (p > -149) {
            ASSERT_EQ(FloatExponent(std::nextafter(x, 0.0f)), p - 1);
        }
    }
    EXPECT_EQ(FloatExponent(std::numeric_limits<float>::max()), 127);
}

TEST(Addressing, MipFromDifferentialsFollowsEquation1) {
    // 256-texel face; a pixel covering 1/64 of the face in x and 1/16 in y: min(4, 16) -> log2 4
    // = 2.
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 16, 0.0f), 2);
    // Grazing: huge footprint along y, small along x: eq. 1 takes the min (higher resolution).
    EXPECT_EQ(ComputeMip(8, 1.0f / 256, 0.0f, 0.0f, 50.0f, 0.0f), 0);
    // Tiny footprint: finest level; huge footprint: coarsest level (1x1).
    EXPECT_EQ(ComputeMip(8, 1e-9f, 0.0f, 0.0f, 1e-9f, 0.0f), 0);
    EXPECT_EQ(ComputeMip(8, 1e9f, 0.0f, 0.0f, 1e9f, 0.0f), 8);
    EXPECT_EQ(ComputeMip(8, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f), 0);
    EXPECT_EQ(ComputeMip(8, INFINITY, 0.0f, 0.0f, INFINITY, 0.0f), 8);
    EXPECT_EQ(ComputeMip(8, NAN, 0.0f, 0.0f, 1.0f, 0.0f), 0);
    // Floored (towards higher resolution): log2(3.9) = 1.96 -> 1.
    EXPECT_EQ(ComputeMip(8, 3.9f / 256, 0.0f, 0.0f, 3.9f / 256, 0.0f), 1);
    // LOD bias shifts, and a bias beyond the chain clamps to it.
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 64, 1.0f), 3);
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 64, 100.0f), 8);
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 64, -100.0f), 0);
    EXPECT_EQ(ComputeMip(0, 1.0f, 0.0f, 0.0f, 1.0f, 0.0f), 0);
}

TEST(Addressing, QuantizationFollowsEquation2AndIsRobust) {
    EXPECT_EQ(QuantizeCoord(0.0f, 16), 0);
    EXPECT_EQ(QuantizeCoord(-4e-10f, 16), 0);  // Embree's slightly negative u
    EXPECT_EQ(QuantizeCoord(1.0f, 16), 15);
    EXPECT_EQ(QuantizeCoord(1.00001f, 16), 15);
    EXPECT_EQ(QuantizeCoord(0.5f, 16), 8);
    EXPECT_EQ(QuantizeCoord(NAN, 16), 0);
    EXPECT_EQ(QuantizeCoord(1e30f, 16), 15);
    EXPECT_FLOAT_EQ(TexelCenter(8, 16), 8.5f / 16.0f);
}

struct Payload {
    uint64_t a, b, c, d;  // all derived from the key: a torn or aliased read shows up
    static Payload Of(uint64_t k) { return {k, k * 3 + 1, ~k, k ^ 0x5555555555555555ull}; }
    bool Matches(uint64_t k) const {
        const Payload p = Of(k);
        return a == p.a && b == p.b && c == p.c && d == p.d;
    }
};

TEST(DirectMappedCache, CollidingKeyEvictsAndNeverAliases) {
    DirectMappedCache<Payload> cache(DirectMappedCache<Payload>::kSlotBytes);  // exactly one slot
    ASSERT_EQ(cache.NumSlots(), 1u);
    Payload out;
    SlotTicket t;
    ASSERT_EQ(cache.Acquire(1, 1, &out, &t), AcquireResult::Claimed);
    EXPECT_FALSE(t.evicted);
    cache.Publish(t, Payload::Of(1));
    ASSERT_EQ(cache.Acquire(1, 1, &out, &t), AcquireResult::Hit);
    EXPECT_TRUE(out.Matches(1));
    // Key 2 maps to the same (only) slot: it evicts key 1 instead of returning its data.
    ASSERT_EQ(cache.Acquire(2, 2, &out, &t), AcquireResult::Claimed);
    EXPECT_TRUE(t.evicted);
    // While key 2 is being shaded: key 2 is pending, key 1 conflicts.
    EXPECT_EQ(cache.Acquire(2, 2, &out, &t), AcquireResult::Pending);
    SlotTicket t1;
    EXPECT_EQ(cache.Acquire(1, 1, &out, &t1), AcquireResult::Conflict);
    cache.Publish(t, Payload::Of(2));
    EXPECT_FALSE(cache.Find(1, 1, &out));
    ASSERT_TRUE(cache.Find(2, 2, &out));
    EXPECT_TRUE(out.Matches(2));
    // Abandon leaves the slot empty; invalidation evicts.
    ASSERT_EQ(cache.Acquire(3, 3, &out, &t), AcquireResult::Claimed);
    cache.Abandon(t);
    EXPECT_FALSE(cache.Find(3, 3, &out));
    ASSERT_EQ(cache.Acquire(4, 4, &out, &t), AcquireResult::Claimed);
    cache.Publish(t, Payload::Of(4));
    cache.InvalidateAll();
    EXPECT_FALSE(cache.Find(4, 4, &out));
    // The invalidated entry's slot reads as empty: claiming it evicts nothing.
    ASSERT_EQ(cache.Acquire(5, 5, &out, &t), AcquireResult::Claimed);
    EXPECT_FALSE(t.evicted);
    cache.Abandon(t);
}

// InvalidateAll moves to a new tag instead of sweeping (direct_mapped_cache.h): over many
// invalidations, across the tags coming round again (every 15th sweeps), an entry of an earlier
// epoch is never found, never counted as an eviction, and its key's new entry is the new value;
// an entry kept past InvalidateIf of other keys stays. Both one and two choices.
TEST(DirectMappedCache, InvalidatedEntriesNeverComeBack) {
    for (bool twoChoices : {false, true}) {
        DirectMappedCache<Payload> cache(DirectMappedCache<Payload>::kSlotBytes * 8, twoChoices);
        Payload out;
        SlotTicket t;
        for (uint64_t epoch = 0; epoch < 50; ++epoch) {
            for (uint64_t k = 1; k <= 4; ++k) {
                ASSERT_FALSE(cache.Find(k, k, &out)) << "epoch " << epoch << ", key " << k;
                ASSERT_EQ(cache.Acquire(k, k, &out, &t), AcquireResult::Claimed);
                EXPECT_FALSE(t.evicted) << "epoch " << epoch;
                cache.Publish(t, Payload::Of(k + 100 * epoch));
            }
            ASSERT_TRUE(cache.Find(3, 3, &out));
            EXPECT_TRUE(out.Matches(3 + 100 * epoch));
            EXPECT_EQ(cache.InvalidateIf([](uint64_t k) { return k == 2; }), 1u);
            EXPECT_FALSE(cache.Find(2, 2, &out));
            ASSERT_TRUE(cache.Find(1, 1, &out));
            EXPECT_TRUE(out.Matches(1 + 100 * epoch));
            cache.InvalidateAll();
        }
    }
}

// With two choices, two keys whose first slots coincide both stay cached (when their second
// slots differ), and lookups still never alias.
TEST(DirectMappedCache, TwoChoicesKeepCollidingKeys) {
    DirectMappedCache<Payload> direct(DirectMappedCache<Payload>::kSlotBytes * 64, false);
    DirectMappedCache<Payload> two(DirectMappedCache<Payload>::kSlotBytes * 64, true);
    Payload out;
    SlotTicket t;
    int keptDirect = 0, keptTwo = 0;
    for (uint64_t k = 1; k <= 40; ++k) {
        // Every key hashes to the same first slot (hash 7).
        if (direct.Acquire(k, 7, &out, &t) == AcquireResult::Claimed)
            direct.Publish(t, Payload::Of(k));
        if (two.Acquire(k, 7, &out, &t) == AcquireResult::Claimed) two.Publish(t, Payload::Of(k));
    }
    for (uint64_t k = 1; k <= 40; ++k) {
        if (direct.Find(k, 7, &out)) {
            EXPECT_TRUE(out.Matches(k));
            ++keptDirect;
        }
        if (two.Find(k, 7, &out)) {
            EXPECT_TRUE(out.Matches(k));
            ++keptTwo;
        }
    }
    EXPECT_EQ(keptDirect, 1);  // direct mapped: the last key only
    EXPECT_EQ(keptTwo, 2);     // the last two: one in the shared slot, one in its own second slot
}

// An empty first slot is claimed without reading the second (a cold cache's fills). The one case
// where that differs from reading both: the key sits in its second slot and its first slot was
// emptied since. It then gets a second copy of its own payload, never another key's, and the
// other key of the pair still misses.
TEST(DirectMappedCache, AnEmptiedFirstSlotGivesTheSameKeyASecondCopy) {
    DirectMappedCache<Payload> cache(DirectMappedCache<Payload>::kSlotBytes * 64, true);
    Payload out;
    SlotTicket t;
    ASSERT_EQ(cache.Acquire(1, 7, &out, &t), AcquireResult::Claimed);  // key 1: first slot
    cache.Publish(t, Payload::Of(1));
    ASSERT_EQ(cache.Acquire(2, 7, &out, &t), AcquireResult::Claimed);  // key 2: second slot
    EXPECT_FALSE(t.evicted);
    cache.Publish(t, Payload::Of(2));
    EXPECT_EQ(cache.InvalidateIf([](uint64_t k) { return k == 1; }), 1u);
    ASSERT_EQ(cache.Acquire(2, 7, &out, &t), AcquireResult::Claimed);  // the emptied first slot
    EXPECT_FALSE(t.evicted);
    cache.Publish(t, Payload::Of(2));
    for (int i = 0; i < 2; ++i) {
        ASSERT_EQ(cache.Acquire(2, 7, &out, &t), AcquireResult::Hit);
        EXPECT_TRUE(out.Matches(2));
        ASSERT_TRUE(cache.Find(2, 7, &out));
        EXPECT_TRUE(out.Matches(2));
    }
    EXPECT_FALSE(cache.Find(1, 7, &out));
    // A key that misses both slots, held by live keys, still evicts rather than aliasing.
    ASSERT_EQ(cache.Acquire(3, 7, &out, &t), AcquireResult::Claimed);
    EXPECT_TRUE(t.evicted);
}

TEST(DirectMappedCache, StaysWithinItsByteBudget) {
    for (size_t bytes : {size_t(100), size_t(1000), size_t(4096), size_t(1) << 20, size_t(16) << 20,
                         (size_t(16) << 20) + 17}) {
        DirectMappedCache<Payload> cache(bytes);
        EXPECT_LE(cache.BytesUsed(), bytes);
        EXPECT_GT(cache.BytesUsed() + DirectMappedCache<Payload>::kSlotBytes,
                  bytes);  // and uses it
    }
    EXPECT_THROW(DirectMappedCache<Payload>(0), InputError);
    EXPECT_THROW(DirectMappedCache<Payload>(DirectMappedCache<Payload>::kSlotBytes - 1),
                 InputError);
}

#if defined(__x86_64__) && defined(__linux__)
// A function whose only effect is a cache's Prefetch, out of line, and a caller. GCC's IPA
// pure-const pass finds such a function "const" when its prefetch is __builtin_prefetch, and
// deletes the calls to it: that had left the renderer without a single prefetch instruction
// (see PrefetchLine). The test reads the caller's machine code back: the call (or the prefetch,
// if the compiler inlines it after all) must still be there.
extern "C" __attribute__((noinline)) void TexcachePrefetchProbe(
    const DirectMappedCache<Payload>* cache, uint64_t hash) {
    cache->Prefetch(hash);
}
extern "C" __attribute__((noinline)) void TexcachePrefetchCaller(
    const DirectMappedCache<Payload>* cache, uint64_t hash) {
    TexcachePrefetchProbe(cache, hash);
}

TEST(DirectMappedCache, PrefetchSurvivesTheOptimizer) {
    DirectMappedCache<Payload> cache(DirectMappedCache<Payload>::kSlotBytes * 64);
    TexcachePrefetchCaller(&cache, 12345);  // and it is safe to call
    char self[4096];
    const ssize_t n = readlink("/proc/self/exe", self, sizeof(self) - 1);
    ASSERT_GT(n, 0);
    self[n] = 0;
    // objdump comes with binutils, which the compiler itself needs.
    const std::string command = std::string(
                                    "objdump -d --no-show-raw-insn "
                                    "--disassemble=TexcachePrefetchCaller '") +
                                self + "' 2>&1";
    FILE* pipe = popen(command.c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    std::string text;
    char buf[4096];
    for (size_t got; (got = fread(buf, 1, sizeof(buf), pipe)) > 0;) text.append(buf, got);
    ASSERT_EQ(pclose(pipe), 0) << text;
    const size_t body = text.find("<TexcachePrefetchCaller>:");
    ASSERT_NE(body, std::string::npos) << text;
    const std::string code = text.substr(body + 25);
    EXPECT_TRUE(code.find("prefetch") != std::string::npos ||
                code.find("TexcachePrefetchProbe") != std::string::npos)
        << "the prefetch was deleted:\n"
        << text;
}
#endif

// Threads hammer overlapping keys through a small cache (many evictions): every hit must carry
// exactly the payload of the key asked for. Run under ThreadSanitizer by the `tsan` build.
class ConcurrentStress : public ::testing::TestWithParam<bool> {};
TEST_P(ConcurrentStress, NeverReturnsAnotherKeysData) {
    DirectMappedCache<Payload> cache(DirectMappedCache<Payload>::kSlotBytes * 97, GetParam());
    std::atomic<uint64_t> bad{0}, hits{0}, claims{0};
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            uint64_t x = 88172645463325252ull + uint64_t(t);
            for (int i = 0; i < 200000; ++i) {
                x ^= x << 13, x ^= x >> 7, x ^= x << 17;
                const uint64_t key = x % 500;
                Payload out;
                SlotTicket ticket;
                switch (cache.Acquire(key, key * 2654435761u, &out, &ticket)) {
                    case AcquireResult::Hit:
                        ++hits;
                        if (!out.Matches(key)) ++bad;
                        break;
                    case AcquireResult::Claimed:
                        ++claims;
                        cache.Publish(ticket, Payload::Of(key));
                        break;
                    default:
                        break;
                }
            }
        });
    for (auto& th : threads) th.join();
    EXPECT_EQ(bad.load(), 0u);
    EXPECT_GT(hits.load(), 1000u);
    EXPECT_GT(claims.load(), 1000u);
}
INSTANTIATE_TEST_SUITE_P(DirectMappedCache, ConcurrentStress, ::testing::Values(false, true),
                         [](const auto& info) {
                             return info.param ? "TwoChoices" : "DirectMapped";
                         });

// --- topology and footprints on synthetic cages -------------------------------------------------

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

// --- the two-level cache ------------------------------------------------------------------------

struct AoSample {
    float value;
    float n[3];
};

TEST(ShadingCache, RestrictedFootprintsShadeOnlyVisibleSamples) {
    ShadingCache<AoSample, float> cache(CacheSettings{});
    const int mesh = cache.AddMesh(test::GridCage(4), 1.0f / 16.0f);
    VisibleTexels vis(1 << 12);
    // Visible: a 3x3 block around texel (8, 8) of face 5, a pair of texels mirrored about it,
    // (3, 14) and (13, 2), and a texel whose mirror is not seen, (10, 4).
    const uint32_t face = cache.Mesh(mesh).FaceOffset() + 5;
    for (int dv = -1; dv <= 1; ++dv)
        for (int du = -1; du <= 1; ++du) vis.Mark({face, 0, uint16_t(8 + du), uint16_t(8 + dv)});
    vis.Mark({face, 0, 3, 14});
    vis.Mark({face, 0, 13, 2});
    vis.Mark({face, 0, 10, 4});
    std::set<uint64_t> shaded;
    auto shade = [&](const SampleRequest& r) {
        shaded.insert(r.key.Pack());
        return AoSample{1.0f, {0, 0, 1}};
    };
    size_t taps = 0;
    auto filter = [&](const FilterInput<AoSample>& in) {
        taps = in.samples.size();
        return in.samples[in.centre].value;
    };
    cache.RestrictFootprints(&vis);
    CacheStats st;
    const SampleRequest centre{mesh, 5, 0, (8.5f) / 16.0f, 8.5f / 16.0f, {face, 0, 8, 8}};
    cache.LookupTexel(centre, 6, shade, filter, st);
    EXPECT_EQ(taps, 11u);  // the 3x3 block and the pair, all within the 13x13 window
    EXPECT_EQ(shaded.size(), 11u);
    EXPECT_EQ(st.tapsUnseen, 169u - 11u);
    // Without the restriction the same window shades all of it.
    cache.RestrictFootprints(nullptr);
    cache.InvalidateAll();
    shaded.clear();
    cache.LookupTexel(centre, 6, shade, filter, st);
    EXPECT_EQ(taps, 169u);
    EXPECT_EQ(shaded.size(), 169u);
}

// A filter with a block (tile) form: a miss reconstructs the visible texels of its 8x8 block
// (its windows continued past the face by its pad), and every texel gets the value per-texel
// filtering gives it (same samples, same taps). Both caches look up every visible texel of a
// mesh in the same order.
struct OffsetWeightedMean {
    float operator()(const FilterInput<AoSample>& in) const {
        float sum = 0.0f, wsum = 0.0f;
        for (size_t i = 0; i < in.samples.size(); ++i) {
            const float w = 1.0f + 0.03f * float(in.taps[i].dx) + 0.01f * float(in.taps[i].dy);
            sum += w * in.samples[i].value, wsum += w;
        }
        return sum / wsum;
    }
};
struct OffsetWeightedMeanWithTiles : OffsetWeightedMean {
    using OffsetWeightedMean::operator();
    float operator()(const SampleTile<AoSample>& t, int cx, int cy, int r,
                     const SampleRequest&) const {
        float sum = 0.0f, wsum = 0.0f;
        t.ForEachTap(cx, cy, r, [&](int i, int dx, int dy) {
            const float w = 1.0f + 0.03f * float(dx) + 0.01f * float(dy);
            sum += w * t.samples[i].value, wsum += w;
        });
        return sum / wsum;
    }
};

TEST(ShadingCache, BlockReconstructionGivesThePerTexelValues) {
    struct Case {
        ControlCage cage;
        float texelSize;
    };
    // A grid (boundaries), the cube (valence-3 corners: windows holding a texel twice) and the
    // pentagon (n-gon sub-faces, grids of several sizes).
    for (const Case& c :
         {Case{test::GridCage(3), 1.0f / 32.0f}, Case{test::CubeCage(), 1.0f / 24.0f},
          Case{test::PentagonCage(), 0.03f}}) {
        CacheSettings settings;
        settings.sampleCacheBytes = settings.texelCacheBytes = size_t(1) << 20;
        ShadingCache<AoSample, float> perTexel(settings), blocks(settings);
        const int mesh = perTexel.AddMesh(c.cage, c.texelSize);
        blocks.AddMesh(c.cage, c.texelSize);
        const MeshGrids& g = perTexel.Mesh(mesh);
        VisibleTexels vis(1 << 14);
        std::mt19937 rng(7);
        std::vector<TexelKey> seen;
        for (int f = 0; f < g.NumFaces(); ++f)
            for (int v = 0; v < g.Res(f, 0); ++v)
                for (int u = 0; u < g.Res(f, 0); ++u)
                    if (rng() % 5 < 3) {
                        seen.push_back({g.FaceOffset() + uint32_t(f), 0, uint16_t(u), uint16_t(v)});
                        vis.Mark(seen.back());
                    }
        std::set<uint64_t> shadedA, shadedB;
        auto shader = [](std::set<uint64_t>* shaded) {
            return [shaded](const SampleRequest& r) {
                shaded->insert(r.key.Pack());
                return AoSample{float(r.key.Pack() * 0x9E3779B97F4A7C15ull >> 40) / float(1 << 24),
                                {}};
            };
        };
        auto shadeA = shader(&shadedA), shadeB = shader(&shadedB);
        perTexel.RestrictFootprints(&vis);
        blocks.RestrictFootprints(&vis);
        for (FootprintTaps taps : {FootprintTaps::VisibleSymmetric, FootprintTaps::Visible})
            for (int radius : {2, 6, 26}) {  // 26: 8x8 blocks (16x16 tiles would pass 64 bits)
                perTexel.InvalidateAll();
                blocks.InvalidateAll();
                shadedA.clear();
                shadedB.clear();
                CacheStats a, b;
                for (const TexelKey& k : seen) {
                    const SampleRequest r = perTexel.RequestOf(mesh, k);
                    ASSERT_EQ(
                        perTexel.LookupTexel(r, radius, shadeA, OffsetWeightedMean{}, a, taps),
                        blocks.LookupTexel(r, radius, shadeB, OffsetWeightedMeanWithTiles{}, b,
                                           taps))
                        << c.cage.sourcePath << " face " << k.face << " texel " << k.iu << ","
                        << k.iv << " r " << radius;
                }
                EXPECT_EQ(a.texelsPrefiltered, 0u);
                EXPECT_GT(b.texelsPrefiltered, seen.size() / 4) << c.cage.sourcePath;
                EXPECT_GT(b.texelHits, a.texelHits);
                // The same samples (the visible ones); how often each is shaded again after an
                // eviction depends on the order of fetches, which differs.
                EXPECT_EQ(shadedA, shadedB);
            }
    }
}

// A miss in a block whose texels are cached already (a warm frame's texel lost to a conflict)
// filters its own window only: the block path would gather and fetch its whole tile again. The
// value is the per-texel path's either way.
TEST(ShadingCache, AnIsolatedMissFiltersOnlyItsOwnWindow) {
    CacheSettings settings;
    settings.sampleCacheBytes = settings.texelCacheBytes = size_t(1) << 20;
    ShadingCache<AoSample, float> cache(settings), reference(settings);
    const ControlCage cage = test::GridCage(3);
    const int mesh = cache.AddMesh(cage, 1.0f / 32.0f);
    reference.AddMesh(cage, 1.0f / 32.0f);
    const uint32_t face = cache.Mesh(mesh).FaceOffset() + 4;  // the middle face: no pads
    VisibleTexels vis(1 << 14);
    for (uint16_t v = 0; v < 16; ++v)
        for (uint16_t u = 0; u < 16; ++u)
            if (u != 9 || v != 8) vis.Mark({face, 0, u, v});
    auto shade = [](const SampleRequest& r) {
        return AoSample{float(r.key.Pack() * 0x9E3779B97F4A7C15ull >> 40) / float(1 << 24), {}};
    };
    cache.RestrictFootprints(&vis);
    reference.RestrictFootprints(&vis);
    CacheStats st, ref;
    const int r = 3;
    cache.LookupTexel(cache.RequestOf(mesh, {face, 0, 8, 8}), r, shade,
                      OffsetWeightedMeanWithTiles{}, st);
    EXPECT_EQ(st.texelsPrefiltered, 16u * 16u - 2u);  // the block's visible texels but (8,8)
    // (9,8) becomes visible: its quad partner (8,8) is cached, so it takes the per-texel path.
    vis.Mark({face, 0, 9, 8});
    const CacheStats before = st;
    const SampleRequest isolated = cache.RequestOf(mesh, {face, 0, 9, 8});
    const float value = cache.LookupTexel(isolated, r, shade, OffsetWeightedMeanWithTiles{}, st);
    EXPECT_EQ(st.texelMisses, before.texelMisses + 1);
    EXPECT_EQ(st.texelsPrefiltered, before.texelsPrefiltered);
    EXPECT_LE(st.sampleLookups - before.sampleLookups, uint64_t((2 * r + 1) * (2 * r + 1)));
    EXPECT_EQ(value, reference.LookupTexel(isolated, r, shade, OffsetWeightedMean{}, ref));
}

TEST(ShadingCache, RejectsImpossibleSettings) {
    CacheSettings s;
    s.sampleCacheBytes = 0;
    EXPECT_THROW((ShadingCache<AoSample, float>(s)), InputError);
    s = {};
    s.texelCacheBytes = size_t(1) << 50;
    EXPECT_THROW((ShadingCache<AoSample, float>(s)), InputError);
    s = {};
    s.lodBias = 1000.0f;
    EXPECT_THROW((ShadingCache<AoSample, float>(s)), InputError);
    s = {};
    s.lodBias = NAN;
    EXPECT_THROW((ShadingCache<AoSample, float>(s)), InputError);
}

// Reference mode keeps everything: with overlapping footprints from several threads, no sample
// is ever shaded twice, and every texel is filtered exactly from its footprint.
TEST(ShadingCache, ReferenceModeShadesEachSampleOnce) {
    CacheSettings s;
    s.referenceMode = true;
    ShadingCache<AoSample, float> cache(s);
    const int mesh = cache.AddMesh(test::FanCage(5), 0.05f);
    std::mutex m;
    std::unordered_map<uint64_t, int> shadeCount;
    auto shade = [&](const SampleRequest& r) {
        {
            std::lock_guard<std::mutex> lock(m);
            ++shadeCount[r.key.Pack()];
        }
        return AoSample{r.u + r.v, {0, 1, 0}};
    };
    auto filter = [](const FilterInput<AoSample>& in) {
        float sum = 0.0f;
        for (const auto& x : in.samples) sum += x.value;
        return sum / float(in.samples.size());
    };
    std::vector<std::thread> threads;
    std::atomic<int> nonFinite{0};
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            CacheStats st;
            for (int i = 0; i < 3000; ++i) {
                const int face = (i + t) % cache.Mesh(mesh).NumFaces();
                const float u = float((i * 7 + t) % 97) / 97.0f, v = float((i * 13) % 89) / 89.0f;
                const float val =
                    cache.Lookup({mesh, face, u, v, 0.01f, 0, 0, 0.01f}, 3, shade, filter, st);
                if (!std::isfinite(val)) ++nonFinite;
            }
        });
    for (auto& th : threads) th.join();
    EXPECT_EQ(nonFinite.load(), 0);
    ASSERT_FALSE(shadeCount.empty());
    for (const auto& [key, count] : shadeCount) ASSERT_EQ(count, 1) << "sample shaded twice";
}

// Four threads call check(i, their stats) for i = 0..n-1, each in its own order, `passes`
// times; returns how many calls returned false, the threads' statistics merged into `total`.
template <typename Check>
int MismatchesInThreads(size_t n, int passes, CacheStats* total, Check check) {
    std::atomic<int> mismatches{0};
    std::vector<CacheStats> stats(4);
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            for (int pass = 0; pass < passes; ++pass)
                for (size_t k = 0; k < n; ++k)
                    if (!check((k * (2 * t + 1) + size_t(t) * 997) % n, stats[t])) ++mismatches;
        });
    for (auto& th : threads) th.join();
    for (const auto& st : stats) total->Merge(st);
    return mismatches.load();
}

// Threads filter overlapping footprints through small bounded caches (evictions, deferrals,
// conflicts all happen): every result equals the single-threaded answer. Run under
// ThreadSanitizer by scripts/test.sh (label `cache`).
TEST(ShadingCache, ConcurrentOverlappingFootprintsMatchSingleThreaded) {
    auto shade = [](const SampleRequest& r) {
        const float v = float(r.key.Pack() % 1009) / 1009.0f;
        return AoSample{v, {0, 1, 0}};
    };
    auto mean = [](const FilterInput<AoSample>& in) {
        float sum = 0.0f;
        for (const auto& x : in.samples) sum += x.value;
        return sum / float(in.samples.size());
    };
    std::vector<CacheHit> hits;
    for (int i = 0; i < 4000; ++i)
        hits.push_back({0, i % 16, float((i * 37) % 101) / 101.0f, float((i * 53) % 97) / 97.0f,
                        0.004f, 0, 0, 0.004f});
    std::vector<float> expected(hits.size());
    {
        CacheSettings s;
        s.referenceMode = true;
        ShadingCache<AoSample, float> ref(s);
        ref.AddMesh(test::GridCage(4), 0.02f);
        CacheStats st;
        for (size_t i = 0; i < hits.size(); ++i)
            expected[i] = ref.Lookup(hits[i], 3, shade, mean, st);
    }
    for (bool twoChoices : {false, true}) {
        CacheSettings s;
        s.sampleCacheBytes = 64 * 1024;
        s.texelCacheBytes = 8 * 1024;
        s.texelTwoChoices = twoChoices;
        ShadingCache<AoSample, float> cache(s);
        cache.AddMesh(test::GridCage(4), 0.02f);
        CacheStats total;
        EXPECT_EQ(MismatchesInThreads(hits.size(), 3, &total,
                                      [&](size_t i, CacheStats& st) {
                                          return cache.Lookup(hits[i], 3, shade, mean, st) ==
                                                 expected[i];
                                      }),
                  0);
        EXPECT_GT(total.sampleEvictions, 0u);
        EXPECT_GT(total.texelHits, 0u);
        EXPECT_LE(cache.BytesUsed(), s.sampleCacheBytes + s.texelCacheBytes);
    }
}

// The hot path allocates nothing: after a warm-up, lookups that hit and lookups that miss
// (gather a footprint across edges, shade, filter, publish) make no heap allocation. The warm-up
// visits every face once: a thread's footprint pads (footprint.cpp) are a small cache of their
// own, whose slots grow to a face's ring the first time they hold one; the caches are then
// emptied, so the measured lookups miss again.
TEST(ShadingCache, LookupsDoNotAllocate) {
    ShadingCache<AoSample, float> cache(CacheSettings{});
    const int mesh = cache.AddMesh(test::FanCage(5), 0.05f);
    auto shade = [](const SampleRequest& r) { return AoSample{r.u, {0, 1, 0}}; };
    auto mean = [](const FilterInput<AoSample>& in) {
        float s = 0.0f;
        for (const auto& x : in.samples) s += x.value;
        return s / float(in.samples.size());
    };
    CacheStats st;
    const CacheHit warm{mesh, 0, 0.01f, 0.01f, 0.05f, 0, 0, 0.05f};
    cache.Lookup(warm, 6, shade, mean, st);  // sizes the thread's scratch buffers
    float sink = 0.0f;
    auto lookups = [&] {
        for (int f = 0; f < cache.Mesh(mesh).NumFaces(); ++f)
            for (float u : {0.01f, 0.5f, 0.99f})
                sink += cache.Lookup({mesh, f, u, 0.02f, 0.05f, 0, 0, 0.05f}, 6, shade, mean, st);
    };
    lookups();
    cache.InvalidateAll();
    const uint64_t before = gAllocations.load(), missesBefore = st.texelMisses;
    lookups();
    EXPECT_EQ(gAllocations.load(), before);
    EXPECT_GT(st.texelMisses - missesBefore, 5u);
    EXPECT_TRUE(std::isfinite(sink));
}

// Block reconstruction under threads: four threads look up the visible texels of two cube faces
// (and their windows across the edges and corners) in different orders through small caches (texel
// slots busy with another thread's claim, samples evicted and deferred), and every result equals
// the single-threaded per-texel one. After a warm-up the block path allocates nothing either (its
// scratch and the pads are per thread). Run under ThreadSanitizer by scripts/test.sh (label
// `cache`).
TEST(ShadingCache, ConcurrentBlockReconstructionMatchesPerTexel) {
    const ControlCage cage = test::CubeCage();
    const float texelSize = 1.0f / 24.0f;
    VisibleTexels vis(1 << 14);
    std::vector<TexelKey> keys;
    std::vector<float> expected;
    auto shade = [](const SampleRequest& r) {
        return AoSample{float(r.key.Pack() % 1009) / 1009.0f, {0, 1, 0}};
    };
    {
        ShadingCache<AoSample, float> ref(CacheSettings{});
        const MeshGrids& g = ref.Mesh(ref.AddMesh(cage, texelSize));
        std::mt19937 rng(9);
        for (int f = 0; f < g.NumFaces(); ++f)
            for (int v = 0; v < g.Res(f, 0); ++v)
                for (int u = 0; u < g.Res(f, 0); ++u)
                    if (rng() % 4 != 0) {
                        vis.Mark({uint32_t(f), 0, uint16_t(u), uint16_t(v)});
                        if (f < 2) keys.push_back({uint32_t(f), 0, uint16_t(u), uint16_t(v)});
                    }
        ref.RestrictFootprints(&vis);
        CacheStats st;
        for (const TexelKey& k : keys)
            expected.push_back(
                ref.LookupTexel(ref.RequestOf(0, k), 4, shade, OffsetWeightedMean{}, st));
    }
    CacheSettings s;
    s.sampleCacheBytes = 64 * 1024;
    s.texelCacheBytes = 8 * 1024;
    ShadingCache<AoSample, float> cache(s);
    cache.AddMesh(cage, texelSize);
    cache.RestrictFootprints(&vis);
    CacheStats total;
    EXPECT_EQ(MismatchesInThreads(keys.size(), 1, &total,
                                  [&](size_t i, CacheStats& st) {
                                      return cache.LookupTexel(cache.RequestOf(0, keys[i]), 4,
                                                               shade, OffsetWeightedMeanWithTiles{},
                                                               st) == expected[i];
                                  }),
              0);
    EXPECT_GT(total.texelsPrefiltered, 0u);
    EXPECT_GT(total.sampleEvictions, 0u);
    // No allocation once warm: the same lookups again after an invalidation.
    cache.InvalidateAll();
    CacheStats st;
    for (size_t i = 0; i < 64; ++i)
        cache.LookupTexel(cache.RequestOf(0, keys[i]), 4, shade, OffsetWeightedMeanWithTiles{}, st);
    cache.InvalidateAll();
    const uint64_t before = gAllocations.load();
    float sink = 0.0f;
    for (size_t i = 0; i < 64; ++i)
        sink += cache.LookupTexel(cache.RequestOf(0, keys[i]), 4, shade,
                                  OffsetWeightedMeanWithTiles{}, st);
    EXPECT_EQ(gAllocations.load(), before);
    EXPECT_GT(st.texelsPrefiltered, 0u);
    EXPECT_TRUE(std::isfinite(sink));
}

TEST(ShadingCache, InvalidationEvictsOneMeshOrAll) {
    ShadingCache<AoSample, float> cache(CacheSettings{});
    const int a = cache.AddMesh(test::GridCage(2), 0.1f), b = cache.AddMesh(test::CubeCage(), 0.1f);
    int shaded = 0;
    auto shade = [&](const SampleRequest& r) {
        ++shaded;
        return AoSample{float(r.mesh), {0, 1, 0}};
    };
    auto centre = [](const FilterInput<AoSample>& in) { return in.samples[in.centre].value; };
    CacheStats st;
    const CacheHit ha{a, 0, 0.5f, 0.5f, 0.01f, 0, 0, 0.01f},
        hb{b, 0, 0.5f, 0.5f, 0.01f, 0, 0, 0.01f};
    cache.Lookup(ha, 0, shade, centre, st);
    cache.Lookup(hb, 0, shade, centre, st);
    EXPECT_EQ(shaded, 2);
    cache.InvalidateMesh(a);
    cache.Lookup(ha, 0, shade, centre, st);  // re-shaded
    cache.Lookup(hb, 0, shade, centre, st);  // still cached
    EXPECT_EQ(shaded, 3);
    cache.InvalidateAll();
    cache.Lookup(hb, 0, shade, centre, st);
    EXPECT_EQ(shaded, 4);
}

// The per-thread tap memo in front of the sample cache never serves a sample of another cache or
// one from before an invalidation: every tap a filter sees was shaded by this cache in this epoch.
TEST(ShadingCache, TapMemoNeverServesForeignOrStaleSamples) {
    ShadingCache<AoSample, float> a(CacheSettings{}), b(CacheSettings{});
    const int ma = a.AddMesh(test::GridCage(2), 0.02f), mb = b.AddMesh(test::GridCage(2), 0.02f);
    // One shader type for both caches (a value per cache), so nothing but the memo's tags keeps
    // their samples apart.
    float generation = 1.0f, valueB = -1.0f;
    auto shadeA = [](const float* v) {
        return [v](const SampleRequest&) { return AoSample{*v, {0, 1, 0}}; };
    };
    auto shadeB = shadeA(&valueB);
    // Records the smallest and largest tap value the filter saw.
    float lo = 0.0f, hi = 0.0f;
    auto range = [&](const FilterInput<AoSample>& in) {
        lo = INFINITY, hi = -INFINITY;
        for (const AoSample& s : in.samples) lo = std::min(lo, s.value), hi = std::max(hi, s.value);
        return in.samples[in.centre].value;
    };
    CacheStats st;
    // Neighbouring texels of one face: their footprints overlap, so all but the first are served
    // mostly from this thread's memo, which both caches share (one per Sample type and thread).
    for (int i = 0; i < 4; ++i) {
        a.Lookup({ma, 0, 0.3f + 0.02f * float(i), 0.5f, 0.02f, 0, 0, 0.02f}, 3, shadeA(&generation),
                 range, st);
        EXPECT_EQ(lo, 1.0f);
        EXPECT_EQ(hi, 1.0f);
    }
    EXPECT_GT(st.sampleMemoHits, 0u);  // otherwise this test checks nothing
    // The same keys in cache b: the memo holds a's samples for exactly these taps.
    for (int i = 0; i < 4; ++i) {
        b.Lookup({mb, 0, 0.31f + 0.02f * float(i), 0.5f, 0.02f, 0, 0, 0.02f}, 3, shadeB, range, st);
        EXPECT_EQ(lo, -1.0f) << "cache b saw a sample of cache a";
        EXPECT_EQ(hi, -1.0f) << "cache b saw a sample of cache a";
    }
    a.InvalidateAll();
    generation = 2.0f;
    a.Lookup({ma, 0, 0.35f, 0.5f, 0.02f, 0, 0, 0.02f}, 3, shadeA(&generation), range, st);
    EXPECT_EQ(lo, 2.0f) << "a sample from before InvalidateAll was served";
    a.InvalidateMesh(ma);
    generation = 3.0f;
    a.Lookup({ma, 0, 0.37f, 0.5f, 0.02f, 0, 0, 0.02f}, 3, shadeA(&generation), range, st);
    EXPECT_EQ(lo, 3.0f) << "a sample from before InvalidateMesh was served";
    EXPECT_EQ(hi, 3.0f);
}

// A bounded cache far too small for the working set still returns correct values (it re-shades).
TEST(ShadingCache, TinyBoundedCacheStaysCorrect) {
    CacheSettings s;
    s.sampleCacheBytes = 4096;
    s.texelCacheBytes = 1024;
    ShadingCache<AoSample, float> cache(s);
    const int mesh = cache.AddMesh(test::GridCage(4), 0.1f);
    auto shade = [](const SampleRequest& r) {
        return AoSample{float(r.key.face) + r.u, {0, 1, 0}};
    };
    auto centreOnly = [](const FilterInput<AoSample>& in) { return in.samples[in.centre].value; };
    CacheStats st;
    for (int pass = 0; pass < 3; ++pass)
        for (int face = 0; face < 16; ++face)
            for (float u : {0.05f, 0.5f, 0.95f}) {
                const CacheHit h{mesh, face, u, 0.5f, 0.001f, 0, 0, 0.001f};
                const SampleRequest req = cache.TexelAt(h);
                const float got = cache.Lookup(h, 2, shade, centreOnly, st);
                EXPECT_FLOAT_EQ(got, float(req.key.face) + req.u);
            }
    EXPECT_GT(st.sampleEvictions + st.texelEvictions, 0u);
    EXPECT_LE(cache.BytesUsed(), 4096u + 1024u);
}

}  // namespace
}  // namespace texcache
