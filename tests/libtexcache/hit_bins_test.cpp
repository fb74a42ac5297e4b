// SPDX-License-Identifier: Apache-2.0
// HitBins (texcache/hit_bins.h): exact integer sums per key under concurrent adds, whatever the
// order; never another key's counts; saturation instead of wrap-around; a full table drops and
// counts, never overwrites; and a thread's Batch adds what one-by-one adds would.
#include "texcache/hit_bins.h"

#include <gtest/gtest.h>

#include <cstdint>
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
        for (int u = 0; u < 4; ++u) ASSERT_TRUE(bins.Add(Key(7, 2, u, v), uint32_t(u), 4));
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) {
            const HitBins::Counts n = bins.Find(Key(7, 2, u, v));
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
                bins.Add(Key(f, 1, r % 4, 0), 1, 2);       // direct
                batch.Add(Key(f, 1, 0, 1 + t % 3), 1, 1);  // batched, flushed on collisions
            }
    };
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) threads.emplace_back(work, t);
    for (auto& t : threads) t.join();
    EXPECT_EQ(bins.Dropped(), 0u);
    EXPECT_EQ(bins.BlocksUsed(), 40u);
    for (uint32_t f = 0; f < 40; ++f) {
        for (int u = 0; u < 4; ++u) {
            const HitBins::Counts n = bins.Find(Key(f, 1, u, 0));
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
    bins.Add(Key(1, 0, 0, 0), UINT32_MAX - 5, UINT32_MAX - 2);
    bins.Add(Key(1, 0, 0, 0), 10, 10);
    const HitBins::Counts n = bins.Find(Key(1, 0, 0, 0));
    EXPECT_EQ(n.successes, UINT32_MAX);
    EXPECT_EQ(n.trials, UINT32_MAX);
    HitBins::Batch batch(bins);
    batch.Add(Key(2, 0, 0, 0), UINT32_MAX, UINT32_MAX);
    batch.Add(Key(2, 0, 0, 0), 1, 1);
    batch.Flush();
    EXPECT_EQ(bins.Find(Key(2, 0, 0, 0)).trials, UINT32_MAX);
}

// More blocks than the table holds: the adds that find no room are dropped and counted; every
// key that found room reads exactly its own counts, every other reads zero (never another
// key's).
TEST(HitBins, AFullTableDropsAndNeverAliases) {
    HitBins bins(8);
    std::map<uint32_t, bool> stored;
    for (uint32_t f = 0; f < 100; ++f) stored[f] = bins.Add(Key(f, 0, 0, 0), f, f + 1);
    EXPECT_EQ(bins.BlocksUsed(), 8u);
    EXPECT_EQ(bins.Dropped(), 92u);
    for (const auto& [f, ok] : stored) {
        const HitBins::Counts n = bins.Find(Key(f, 0, 0, 0));
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
            direct.Add(k, s, 4);
            batch.Add(k, s, 4);
        }
    }  // flushed here
    uint64_t y = 12345;
    for (int i = 0; i < 20000; ++i) {
        y = y * 6364136223846793005ull + 1442695040888963407ull;
        const TexelKey k =
            Key(uint32_t(y >> 58), int(y >> 40) & 1, int(y >> 30) & 15, int(y >> 20) & 15);
        const HitBins::Counts a = direct.Find(k), b = batched.Find(k);
        ASSERT_EQ(a.successes, b.successes);
        ASSERT_EQ(a.trials, b.trials);
    }
    EXPECT_EQ(direct.Dropped(), 0u);
    EXPECT_EQ(batched.Dropped(), 0u);
}

}  // namespace
}  // namespace texcache
