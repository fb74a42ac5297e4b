// SPDX-License-Identifier: Apache-2.0
// TextureStore (texcache/texture_store.h): a texel is filtered once and reused by every thread
// while the sample level stays; never another key's value, even in a texel level of a few slots;
// both levels within their byte budgets; a new epoch after Clear and Decay; and the decay's
// fixed-point scaling exact and the same whatever the order of the adds. The concurrent tests
// run under ThreadSanitizer in scripts/test.sh (label "cache").
#include "texcache/texture_store.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

namespace texcache {
namespace {

struct Texel {
    double value = 0.0;
    uint64_t count = 0;
};
using Store = TextureStore<CountBin, Texel>;

TexelKey Key(uint32_t face, int mip, int iu, int iv) {
    return {face, uint8_t(mip), uint16_t(iu), uint16_t(iv)};
}

// A filter over the sample level: the count-weighted mean of the bin and its right neighbour.
// A pure function of the sample level, as the renderer's FilterAt is.
Texel Filter(const Store& s, const TexelKey& k) {
    const CountBin::Value a = s.Samples().Find(k),
                          b = s.Samples().Find(Key(k.face, k.mip, k.iu + 1, k.iv));
    const uint64_t n = uint64_t(a.trials) + b.trials;
    return {n ? double(a.successes + b.successes) / double(n) : 0.0, n};
}

void Fill(Store& s, uint32_t faces, int side) {
    for (uint32_t f = 0; f < faces; ++f)
        for (int v = 0; v < side; ++v)
            for (int u = 0; u <= side; ++u)
                ASSERT_TRUE(s.Samples().Add(Key(f, 1, u, v), {uint32_t((u + v + f) % 5), 4}));
}

TEST(TextureStore, FiltersOnceAndReusesWhileTheSamplesStay) {
    Store s(256, 64 * Store::kTexelBytes);
    Fill(s, 1, 4);
    int calls = 0;
    auto get = [&](int u, int v) {
        const TexelKey k = Key(0, 1, u, v);
        return s.Filtered(k, 4, [&] { return ++calls, Filter(s, k); });
    };
    const Texel t = get(1, 2);
    EXPECT_EQ(calls, 1);
    EXPECT_EQ(get(1, 2).value, t.value);
    EXPECT_EQ(calls, 1);  // the texel level's
    EXPECT_EQ(t.count, 8u);
    // A new pass: the texel is filtered again, from the new sums.
    s.Clear();
    ASSERT_TRUE(s.Samples().Add(Key(0, 1, 1, 2), {4, 4}));
    const Texel u = get(1, 2);
    EXPECT_EQ(calls, 2);
    EXPECT_EQ(u.value, 1.0);
    EXPECT_EQ(u.count, 4u);
    // A decay between frames: again.
    s.Decay(1 << 15);
    EXPECT_EQ(get(1, 2).count, 2u);
    EXPECT_EQ(calls, 3);
}

// A texel level of two slots for 64 keys: texels evict each other, and every read is its own
// key's value.
TEST(TextureStore, AFullTexelLevelEvictsAndNeverAliases) {
    Store s(256, 2 * Store::kTexelBytes);
    EXPECT_LE(s.TexelBytes(), 2 * Store::kTexelBytes);
    Fill(s, 4, 4);
    for (int round = 0; round < 3; ++round)
        for (uint32_t f = 0; f < 4; ++f)
            for (int v = 0; v < 4; ++v)
                for (int u = 0; u < 4; ++u) {
                    const TexelKey k = Key(f, 1, u, v);
                    const Texel t = s.Filtered(k, 4, [&] { return Filter(s, k); });
                    const Texel want = Filter(s, k);
                    ASSERT_EQ(t.value, want.value);
                    ASSERT_EQ(t.count, want.count);
                }
}

TEST(TextureStore, StaysWithinItsByteBudget) {
    for (size_t texelBytes : {size_t(1), size_t(1000), size_t(1 << 20)}) {
        const Store s(1000, texelBytes);
        EXPECT_LE(s.TexelBytes(), std::max(texelBytes, Store::kTexelBytes));
        EXPECT_EQ(s.BytesUsed(), Store::SampleLevel::BytesFor(1024) + s.TexelBytes());
    }
    EXPECT_EQ(Store::SampleLevel::BlocksFor(1000), 1024u);
    EXPECT_EQ(Store::SampleLevel::BlocksFor(0), 8u);
}

// Four threads read the same 512 texels in different orders, from a texel level that holds a
// quarter of them (eviction under contention) and from one that holds them all: every value is
// its key's, whichever thread filtered it, and in the large one most are filtered only once.
TEST(TextureStore, ConcurrentReadersSeeOneValuePerKey) {
    for (size_t slots : {size_t(128), size_t(8192)}) {
        Store s(1024, slots * Store::kTexelBytes);
        Fill(s, 8, 8);
        std::vector<Texel> want;
        for (uint32_t f = 0; f < 8; ++f)
            for (int v = 0; v < 8; ++v)
                for (int u = 0; u < 8; ++u) want.push_back(Filter(s, Key(f, 1, u, v)));
        std::atomic<int> calls{0}, wrong{0};
        constexpr int kThreads = 4, kRounds = 20;
        auto work = [&](int t) {
            for (int r = 0; r < kRounds; ++r)
                for (size_t n = 0; n < want.size(); ++n) {
                    const size_t i = (n * size_t(2 * t + 1) + size_t(r)) % want.size();
                    const TexelKey k = Key(uint32_t(i / 64), 1, int(i % 8), int(i / 8 % 8));
                    const Texel got = s.Filtered(k, 8, [&] {
                        calls.fetch_add(1, std::memory_order_relaxed);
                        return Filter(s, k);
                    });
                    if (got.value != want[i].value || got.count != want[i].count)
                        wrong.fetch_add(1, std::memory_order_relaxed);
                }
        };
        std::vector<std::thread> threads;
        for (int t = 0; t < kThreads; ++t) threads.emplace_back(work, t);
        for (auto& th : threads) th.join();
        EXPECT_EQ(wrong.load(), 0) << slots << " slots";
        // Each thread's first round may filter every texel (the threads' claims race); later
        // ones find them, but for texels sharing a slot.
        if (slots > 1024) {
            EXPECT_LT(calls.load(), 2 * kThreads * int(want.size()));
        }
    }
    // One reader, the same texels warm: each filtered at most once while they fit.
    Store small(64, 64 * Store::kTexelBytes);
    Fill(small, 1, 4);
    int once = 0;
    for (int r = 0; r < 3; ++r)
        for (int u = 0; u < 4; ++u) {
            const TexelKey k = Key(0, 1, u, 0);
            small.Filtered(k, 4, [&] { return ++once, Filter(small, k); });
        }
    EXPECT_EQ(once, 4);
}

// The decay scales each count to nearest in fixed point: exact integers, and the same sums
// whichever order (and thread) added them; blocks that fall to zero are released.
TEST(TextureStore, DecayIsExactAndOrderIndependent) {
    Store a(64, Store::kTexelBytes), b(64, Store::kTexelBytes);
    const TexelKey k = Key(3, 0, 1, 1), gone = Key(9, 0, 0, 0);
    ASSERT_TRUE(a.Samples().Add(gone, {0, 1}));
    std::thread t1([&] {
        for (int i = 0; i < 1000; ++i) a.Samples().Add(k, {uint32_t(i % 3), 5});
    });
    std::thread t2([&] {
        for (int i = 999; i >= 0; --i) b.Samples().Add(k, {uint32_t(i % 3), 5});
    });
    t1.join(), t2.join();
    ASSERT_TRUE(b.Samples().Add(gone, {0, 1}));
    for (Store* s : {&a, &b}) {
        s->Decay(45875);  // 0.7 in 1/65536
        const CountBin::Value n = s->Samples().Find(k);
        EXPECT_EQ(n.trials, uint32_t((5000ull * 45875 + 32768) >> 16));
        EXPECT_EQ(n.successes, uint32_t((999ull * 45875 + 32768) >> 16));
        EXPECT_EQ(s->Samples().Find(gone).trials, 1u);  // 0.7 rounds to 1
        s->Decay(1 << 14);                              // 1/4: it falls to zero
        EXPECT_EQ(s->Samples().Find(gone).trials, 0u);
        EXPECT_EQ(s->Samples().BlocksUsed(), 1u);
        EXPECT_EQ(s->Samples().Dropped(), 0u);
    }
    // Radiance: each 64-bit word scaled exactly, however large.
    EXPECT_EQ(RadianceBin::ScaleWord(UINT64_MAX, 1 << 16), UINT64_MAX);
    EXPECT_EQ(RadianceBin::ScaleWord(uint64_t(1) << 62, 1 << 15), uint64_t(1) << 61);
    EXPECT_EQ(RadianceBin::ScaleWord(3, 1 << 15), 2u);  // 1.5 to nearest, half up
    EXPECT_EQ(CountBin::ScaleWord((uint64_t(7) << 32) | 5, 1 << 15), (uint64_t(4) << 32) | 3);
}

}  // namespace
}  // namespace texcache
