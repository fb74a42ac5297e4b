// SPDX-License-Identifier: Apache-2.0
// The two-level ShadingCache (shading_cache.h): footprints restricted to visible texels, block
// reconstruction equal to per-texel filtering, reference mode shading each sample once, threads
// that agree with one thread, lookups that never allocate, invalidation, and the tap memo.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <new>
#include <random>
#include <set>
#include <thread>
#include <unordered_map>
#include <vector>

#include "testing/cages.h"
#include "texcache/shading_cache.h"
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

// A cache made without its storage (a renderer that shades at its camera hits and may never look
// anything up) holds no bytes and answers read-only queries "absent"; Allocate gives it exactly
// the configured budget, once.
TEST(ShadingCache, StorageIsAllocatedOnlyWhenAsked) {
    CacheSettings s;
    s.sampleCacheBytes = size_t(1) << 20;
    s.texelCacheBytes = size_t(1) << 19;
    ShadingCache<AoSample, float> cache(s, /*allocate=*/false);
    const int mesh = cache.AddMesh(test::GridCage(2), 1.0f / 8.0f);
    EXPECT_FALSE(cache.Allocated());
    EXPECT_EQ(cache.BytesUsed(), 0u);
    const size_t slots = cache.SampleSlots();  // the budget's, as if allocated
    const SampleRequest texel = cache.TexelAt({mesh, 0, 0.5f, 0.5f, 0.1f, 0.0f, 0.0f, 0.1f});
    float v = 0.0f;
    EXPECT_FALSE(cache.FindTexel(texel, &v));
    EXPECT_FALSE(cache.ContainsSample(texel.key));
    cache.InvalidateAll();  // nothing to evict, and no crash
    cache.InvalidateMesh(mesh);
    cache.Allocate();
    cache.Allocate();  // idempotent
    EXPECT_TRUE(cache.Allocated());
    EXPECT_EQ(cache.SampleSlots(), slots);
    EXPECT_LE(cache.BytesUsed(), s.sampleCacheBytes + s.texelCacheBytes);
    EXPECT_GT(cache.BytesUsed(), (s.sampleCacheBytes + s.texelCacheBytes) / 2);
    CacheStats st;
    auto shade = [](const SampleRequest&) { return AoSample{0.25f, {0, 0, 1}}; };
    auto centre = [](const FilterInput<AoSample>& in) { return in.samples[in.centre].value; };
    EXPECT_EQ(cache.LookupTexel(texel, 0, shade, centre, st), 0.25f);
    EXPECT_TRUE(cache.FindTexel(texel, &v));
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
    for (bool threeChoices : {false, true}) {
        CacheSettings s;
        s.sampleCacheBytes = 64 * 1024;
        s.texelCacheBytes = 8 * 1024;
        s.texelThreeChoices = threeChoices;
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

// TexelKeyAt is TexelAt's key, and a lookup through a texel's address (its key and slot hash,
// computed once for its prefetches and the lookup) finds what FindTexel of its request finds:
// its own texel's value or nothing, also in a cache so small that texels evict each other.
TEST(ShadingCache, AddressedLookupsFindTheirOwnTexel) {
    CacheSettings s;
    s.texelCacheBytes = 1024;
    ShadingCache<AoSample, float> cache(s);
    const int mesh = cache.AddMesh(test::GridCage(4), 0.1f);
    auto valueOf = [](const TexelKey& k) { return float(k.Pack() % 1000003); };
    auto shade = [&](const SampleRequest& r) { return AoSample{valueOf(r.key), {0, 1, 0}}; };
    auto centreOnly = [](const FilterInput<AoSample>& in) { return in.samples[in.centre].value; };
    std::vector<CacheHit> hits;
    for (int face = 0; face < 16; ++face)
        for (float u : {0.05f, 0.3f, 0.5f, 0.95f})
            for (float d : {0.001f, 0.02f, 0.3f}) hits.push_back({mesh, face, u, 0.6f, d, 0, 0, d});
    CacheStats st;
    for (const CacheHit& h : hits) {
        EXPECT_EQ(cache.TexelKeyAt(h), cache.TexelAt(h).key);
        cache.Lookup(h, 1, shade, centreOnly, st);
    }
    size_t found = 0;
    for (const CacheHit& h : hits) {
        const SampleRequest req = cache.TexelAt(h);
        const TexelAddress a = cache.AddressOf(cache.TexelKeyAt(h));
        cache.Prefetch(a);
        float byAddress = -1.0f, byRequest = -1.0f;
        const bool hit = cache.FindTexel(a, &byAddress);
        ASSERT_EQ(hit, cache.FindTexel(req, &byRequest));
        if (!hit) continue;
        EXPECT_EQ(byAddress, valueOf(req.key));
        EXPECT_EQ(byRequest, byAddress);
        ++found;
    }
    EXPECT_GT(found, 0u);
    EXPECT_LT(found, hits.size());  // some were evicted
}

}  // namespace
}  // namespace texcache
