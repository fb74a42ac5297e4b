// SPDX-License-Identifier: Apache-2.0
// RecordCache: a record per texel (kilobytes, not a colour) built once and shared by the hits of
// its texel, within its byte budget, never another key's record, across threads.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

#include "testing/cages.h"
#include "texcache/record_cache.h"

namespace texcache {
namespace {

// 1 KB of payload that names its key in every word, so a torn or foreign record shows.
struct BigRecord {
    uint64_t words[128];
};

void Build(const SampleRequest& r, BigRecord* out) {
    for (uint64_t& w : out->words) w = r.key.Pack();
}

CacheHit HitAt(int mesh, int face, float u, float v, float footprint) {
    return {mesh, face, u, v, footprint, 0.0f, 0.0f, footprint};
}

TEST(RecordCache, BuildsEachTexelOnceAndSharesIt) {
    RecordCache<BigRecord> cache(size_t(1) << 20);
    const int mesh = cache.AddMesh(test::GridCage(4), 1.0f / 64.0f);
    RecordStats st;
    BigRecord r;
    // Hits of one coarse texel (LOD bias 2: 4x4 pixel-sized texels) share its record.
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            const SampleRequest t = cache.TexelAt(
                HitAt(mesh, 0, (i + 0.5f) / 64.0f, (j + 0.5f) / 64.0f, 1.0f / 64.0f), 2.0f);
            cache.Lookup(t, Build, &r, st);
            EXPECT_EQ(r.words[127], t.key.Pack());
        }
    EXPECT_EQ(st.lookups, 16u);
    EXPECT_EQ(st.built, 1u);
    EXPECT_EQ(st.hits, 15u);
    EXPECT_LE(cache.BytesUsed(), size_t(1) << 20);
    EXPECT_EQ(cache.BytesUsed(), cache.Capacity() * RecordCache<BigRecord>::kSlotBytes);
    cache.InvalidateAll();
    cache.Lookup(cache.TexelAt(HitAt(mesh, 0, 0.01f, 0.01f, 1.0f / 64.0f), 2.0f), Build, &r, st);
    EXPECT_EQ(st.built, 2u);
}

// Four threads look up random texels of a cache of 8 slots (constant eviction): every record
// they get is the one of their own key, whole.
TEST(RecordCache, ConcurrentLookupsNeverSeeAnotherKeysRecord) {
    RecordCache<BigRecord> cache(8 * RecordCache<BigRecord>::kSlotBytes);
    const int mesh = cache.AddMesh(test::GridCage(4), 1.0f / 64.0f);
    std::atomic<int> bad{0};
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            RecordStats st;
            BigRecord r;
            uint32_t x = 12345u + uint32_t(t);
            for (int i = 0; i < 20000; ++i) {
                x = x * 1664525u + 1013904223u;
                const float u = float(x >> 8 & 63) / 64.0f, v = float(x >> 16 & 63) / 64.0f;
                const SampleRequest req =
                    cache.TexelAt(HitAt(mesh, int(x >> 24) % 16, u, v, 1.0f / 64.0f), 0.0f);
                cache.Lookup(req, Build, &r, st);
                for (uint64_t w : r.words)
                    if (w != req.key.Pack()) ++bad;
            }
        });
    for (std::thread& th : threads) th.join();
    EXPECT_EQ(bad.load(), 0);
}

}  // namespace
}  // namespace texcache
