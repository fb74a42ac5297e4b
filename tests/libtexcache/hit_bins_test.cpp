// SPDX-License-Identifier: Apache-2.0
// HitBins (texcache/hit_bins.h): exact integer sums per key under concurrent adds, whatever the
// order; never another key's counts; saturation instead of wrap-around; a full table drops and
// counts, never overwrites; and a thread's Batch adds what one-by-one adds would. RadianceBins:
// the same table of fixed-point RGB sums, exact under concurrency, NaN/Inf/negative estimates
// refused, huge ones clamped, sums saturating.
#include "texcache/hit_bins.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <thread>
#include <vector>

namespace texcache {
namespace {

TexelKey Key(uint32_t face, int mip, int iu, int iv) {
    return {face, uint8_t(mip), uint16_t(iu), uint16_t(iv)};
}

TEST(HitBins, SizeIsAPowerOfTwoAndBounded) {
    const HitBins bins(1000);
    EXPECT_EQ(bins.NumBlocks(), 1024u);
    EXPECT_EQ(bins.BytesUsed(), HitBins::BytesFor(1024));
    EXPECT_EQ(HitBins(0).NumBlocks(), 8u);  // the smallest table
}

TEST(HitBins, AddsAndFindsPerBinWithinABlock) {
    HitBins bins(64);
    // 4x4 bins of one block, each its own counts; a bin never added reads zero.
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) ASSERT_TRUE(bins.Add(Key(7, 2, u, v), {uint32_t(u), 4}));
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) {
            const HitBins::Value n = bins.Find(Key(7, 2, u, v));
            EXPECT_EQ(n.successes, uint32_t(u));
            EXPECT_EQ(n.trials, 4u);
        }
    EXPECT_EQ(bins.BlocksUsed(), 1u);
    EXPECT_EQ(bins.Find(Key(7, 2, 4, 0)).trials, 0u);  // next block
    EXPECT_EQ(bins.Find(Key(7, 3, 0, 0)).trials, 0u);  // other level
    EXPECT_EQ(bins.Find(Key(8, 2, 0, 0)).trials, 0u);  // other face
    bins.Clear();
    EXPECT_EQ(bins.Find(Key(7, 2, 1, 1)).trials, 0u);
    EXPECT_EQ(bins.BlocksUsed(), 0u);
}

// Generation names a table's contents: a new number at each Clear, never one another table or
// earlier contents had, so a reader may keep what it read while it stays the same.
TEST(HitBins, GenerationChangesAtEachClearAndDiffersBetweenTables) {
    HitBins a(8);
    RadianceBins b(8);
    const uint64_t a0 = a.Generation(), b0 = b.Generation();
    EXPECT_NE(a0, 0u);
    EXPECT_NE(a0, b0);
    ASSERT_TRUE(a.Add(Key(1, 0, 0, 0), {1, 1}));
    EXPECT_EQ(a.Generation(), a0);  // adds do not change it (readers run after every add)
    a.Clear();
    EXPECT_NE(a.Generation(), a0);
    EXPECT_NE(a.Generation(), b0);
    const HitBins c(8);
    EXPECT_NE(c.Generation(), a.Generation());
}

// Concurrent adds from 4 threads into keys that share blocks and probe chains (a table of 64
// blocks for 40 blocks' keys): every bin ends with exactly the sum of its adds, whichever
// thread claimed its block. Run under ThreadSanitizer by scripts/test.sh (label "cache").
TEST(HitBins, ConcurrentAddsSumExactly) {
    HitBins bins(64);
    constexpr int kThreads = 4, kRounds = 200;
    auto work = [&](int t) {
        HitBins::Batch batch(bins);
        for (int r = 0; r < kRounds; ++r)
            for (uint32_t f = 0; f < 40; ++f) {
                bins.Add(Key(f, 1, r % 4, 0), {1, 2});       // direct
                batch.Add(Key(f, 1, 0, 1 + t % 3), {1, 1});  // batched, flushed on collisions
            }
    };
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) threads.emplace_back(work, t);
    for (auto& t : threads) t.join();
    EXPECT_EQ(bins.Dropped(), 0u);
    EXPECT_EQ(bins.BlocksUsed(), 40u);
    for (uint32_t f = 0; f < 40; ++f) {
        for (int u = 0; u < 4; ++u) {
            const HitBins::Value n = bins.Find(Key(f, 1, u, 0));
            EXPECT_EQ(n.successes, uint32_t(kThreads * kRounds / 4));
            EXPECT_EQ(n.trials, uint32_t(2 * kThreads * kRounds / 4));
        }
        // Threads 0 and 3 add to row 1, 1 to row 2, 2 to row 3.
        EXPECT_EQ(bins.Find(Key(f, 1, 0, 1)).trials, uint32_t(2 * kRounds));
        EXPECT_EQ(bins.Find(Key(f, 1, 0, 2)).trials, uint32_t(kRounds));
        EXPECT_EQ(bins.Find(Key(f, 1, 0, 3)).trials, uint32_t(kRounds));
    }
}

// Counts saturate at 2^32 - 1 instead of wrapping (a wrapped count would turn a bright bin
// dark), each half on its own, so the result does not depend on the order of the adds.
TEST(HitBins, CountsSaturate) {
    HitBins bins(8);
    bins.Add(Key(1, 0, 0, 0), {UINT32_MAX - 5, UINT32_MAX - 2});
    bins.Add(Key(1, 0, 0, 0), {10, 10});
    const HitBins::Value n = bins.Find(Key(1, 0, 0, 0));
    EXPECT_EQ(n.successes, UINT32_MAX);
    EXPECT_EQ(n.trials, UINT32_MAX);
    HitBins::Batch batch(bins);
    batch.Add(Key(2, 0, 0, 0), {UINT32_MAX, UINT32_MAX});
    batch.Add(Key(2, 0, 0, 0), {1, 1});
    batch.Flush();
    EXPECT_EQ(bins.Find(Key(2, 0, 0, 0)).trials, UINT32_MAX);
}

// More blocks than the table holds: the adds that find no room are dropped and counted; every
// key that found room reads exactly its own counts, every other reads zero (never another
// key's).
TEST(HitBins, AFullTableDropsAndNeverAliases) {
    HitBins bins(8);
    std::map<uint32_t, bool> stored;
    for (uint32_t f = 0; f < 100; ++f) stored[f] = bins.Add(Key(f, 0, 0, 0), {f, f + 1});
    EXPECT_EQ(bins.BlocksUsed(), 8u);
    EXPECT_EQ(bins.Dropped(), 92u);
    for (const auto& [f, ok] : stored) {
        const HitBins::Value n = bins.Find(Key(f, 0, 0, 0));
        if (ok) {
            EXPECT_EQ(n.successes, f);
            EXPECT_EQ(n.trials, f + 1);
        } else {
            EXPECT_EQ(n.trials, 0u) << f;
        }
    }
}

// A Batch gives the sums of the same adds made one by one, whatever collides in its local table.
TEST(HitBins, BatchMatchesDirectAdds) {
    HitBins direct(8192), batched(8192);  // room for every block (at most 2048 here)
    {
        HitBins::Batch batch(batched);
        uint64_t x = 12345;
        for (int i = 0; i < 20000; ++i) {
            x = x * 6364136223846793005ull + 1442695040888963407ull;
            const TexelKey k =
                Key(uint32_t(x >> 58), int(x >> 40) & 1, int(x >> 30) & 15, int(x >> 20) & 15);
            const uint32_t s = uint32_t(x >> 10) & 3;
            direct.Add(k, {s, 4});
            batch.Add(k, {s, 4});
        }
    }  // flushed here
    uint64_t y = 12345;
    for (int i = 0; i < 20000; ++i) {
        y = y * 6364136223846793005ull + 1442695040888963407ull;
        const TexelKey k =
            Key(uint32_t(y >> 58), int(y >> 40) & 1, int(y >> 30) & 15, int(y >> 20) & 15);
        const HitBins::Value a = direct.Find(k), b = batched.Find(k);
        ASSERT_EQ(a.successes, b.successes);
        ASSERT_EQ(a.trials, b.trials);
    }
    EXPECT_EQ(direct.Dropped(), 0u);
    EXPECT_EQ(batched.Dropped(), 0u);
}

RadianceBin::Value Radiance(float r, float g, float b) {
    const float rgb[3] = {r, g, b};
    RadianceBin::Value v;
    EXPECT_TRUE(RadianceBin::FromRadiance(rgb, &v));
    return v;
}

// Fixed point: 2^20 units per unit of radiance, rounded to nearest (error at most 2^-21).
TEST(RadianceBins, FixedPointRoundsToNearest) {
    const RadianceBin::Value v = Radiance(0.5f, 1.0f / 3.0f, 0.0f);
    EXPECT_EQ(v.sum[0], uint64_t(1) << 19);
    EXPECT_NEAR(double(v.sum[1]) / RadianceBin::kScale, 1.0 / 3.0, 0.5 / RadianceBin::kScale);
    EXPECT_EQ(v.sum[2], 0u);
    EXPECT_EQ(v.count, 1u);
}

// A NaN, infinite or negative estimate is refused (it would poison the bin for good); a huge
// finite one is clamped to kMaxValue, not wrapped.
TEST(RadianceBins, RefusesNonFiniteAndClampsHuge) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    RadianceBin::Value v;
    for (const float bad : {nan, inf, -inf, -1e-3f}) {
        const float rgb[3] = {0.5f, bad, 0.5f};
        EXPECT_FALSE(RadianceBin::FromRadiance(rgb, &v)) << bad;
    }
    const RadianceBin::Value big = Radiance(3e38f, 1e30f, 1.0f);
    EXPECT_EQ(big.sum[0], uint64_t(RadianceBin::kMaxValue * RadianceBin::kScale));
    EXPECT_EQ(big.sum[1], big.sum[0]);
    EXPECT_EQ(big.sum[2], uint64_t(RadianceBin::kScale));
}

// Sums saturate at 2^64 - 1 instead of wrapping to small values, in the table and in a batch.
TEST(RadianceBins, SumsSaturate) {
    RadianceBins bins(8);
    RadianceBin::Value nearFull;
    nearFull.sum[0] = UINT64_MAX - 10, nearFull.sum[1] = 5, nearFull.sum[2] = 0;
    nearFull.count = UINT64_MAX - 1;
    bins.Add(Key(3, 0, 1, 1), nearFull);
    bins.Add(Key(3, 0, 1, 1), Radiance(1.0f, 1.0f, 1.0f));
    bins.Add(Key(3, 0, 1, 1), Radiance(1.0f, 1.0f, 1.0f));
    const RadianceBin::Value v = bins.Find(Key(3, 0, 1, 1));
    EXPECT_EQ(v.sum[0], UINT64_MAX);
    EXPECT_EQ(v.sum[1], 5 + 2 * uint64_t(RadianceBin::kScale));
    EXPECT_EQ(v.count, UINT64_MAX);
    RadianceBin::Value a = nearFull;
    RadianceBin::Accumulate(&a, nearFull);
    EXPECT_EQ(a.sum[0], UINT64_MAX);
    EXPECT_EQ(a.count, UINT64_MAX);
}

// Concurrent adds of radiance, direct and batched, from 4 threads into keys sharing blocks: the
// sums are exact (integers), so the same for any thread count. Under ThreadSanitizer in CI.
TEST(RadianceBins, ConcurrentAddsSumExactly) {
    RadianceBins bins(64);
    constexpr int kThreads = 4, kRounds = 100;
    auto work = [&](int t) {
        RadianceBins::Batch batch(bins);
        for (int r = 0; r < kRounds; ++r)
            for (uint32_t f = 0; f < 40; ++f) {
                bins.Add(Key(f, 1, r % 4, 0), Radiance(0.25f, 0.5f, 2.0f));
                batch.Add(Key(f, 1, 0, 1 + t % 3), Radiance(1.0f, 0.0f, 0.125f));
            }
    };
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) threads.emplace_back(work, t);
    for (std::thread& th : threads) th.join();
    EXPECT_EQ(bins.Dropped(), 0u);
    const double k = RadianceBin::kScale;
    for (uint32_t f = 0; f < 40; ++f) {
        for (int u = 0; u < 4; ++u) {
            const RadianceBin::Value v = bins.Find(Key(f, 1, u, 0));
            const uint64_t n = uint64_t(kThreads * kRounds / 4);
            ASSERT_EQ(v.count, n);
            ASSERT_EQ(v.sum[0], n * uint64_t(0.25 * k));
            ASSERT_EQ(v.sum[2], n * uint64_t(2.0 * k));
        }
        // Row 1 is threads 0 and 3; row 2 thread 1 (sum[0] = 1 each); row 3 thread 2 (sum[1] = 0).
        EXPECT_EQ(bins.Find(Key(f, 1, 0, 1)).count, uint64_t(2 * kRounds));
        EXPECT_EQ(bins.Find(Key(f, 1, 0, 2)).sum[0], uint64_t(kRounds) * uint64_t(k));
        EXPECT_EQ(bins.Find(Key(f, 1, 0, 3)).sum[1], 0u);
    }
}

// FindBlock sums the 16 bins of the block that holds a key (4x4 bins of one face and level,
// aligned on multiples of 4), whichever of its bins the key names; never a neighbouring block's,
// another level's or another face's; a block never added reads zero. Prefetch changes nothing.
TEST(HitBins, FindBlockSumsTheKeysBlockOnly) {
    RadianceBins bins(64);
    for (int v = 0; v < 8; ++v)
        for (int u = 0; u < 8; ++u)
            ASSERT_TRUE(bins.Add(Key(7, 2, u, v), Radiance(1.0f, 0.0f, float(u))));
    ASSERT_TRUE(bins.Add(Key(7, 3, 1, 1), Radiance(100.0f, 0.0f, 0.0f)));  // other level
    ASSERT_TRUE(bins.Add(Key(8, 2, 1, 1), Radiance(100.0f, 0.0f, 0.0f)));  // other face
    const double k = RadianceBin::kScale;
    for (int v = 0; v < 8; ++v)
        for (int u = 0; u < 8; ++u) {
            bins.Prefetch(Key(7, 2, u, v));
            const RadianceBin::Value b = bins.FindBlock(Key(7, 2, u, v));
            ASSERT_EQ(b.count, 16u) << u << " " << v;
            ASSERT_EQ(b.sum[0], uint64_t(16 * k));
            // Columns 0-3 or 4-7, four rows each.
            const uint64_t first = u < 4 ? 0 : 4;
            ASSERT_EQ(b.sum[2], uint64_t(4 * (4 * first + 6) * k)) << u;
        }
    EXPECT_EQ(bins.FindBlock(Key(7, 2, 8, 0)).count, 0u);  // a block never added
    EXPECT_EQ(bins.FindBlock(Key(7, 3, 0, 0)).count, 1u);
    EXPECT_EQ(bins.FindBlock(Key(8, 2, 3, 3)).sum[0], uint64_t(100 * k));
}

}  // namespace
}  // namespace texcache
