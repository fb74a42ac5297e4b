// SPDX-License-Identifier: Apache-2.0
// The lock-free direct-mapped cache (direct_mapped_cache.h) that holds both levels of the shading
// cache: colliding keys never alias, invalidations never come back, one or two slots per key, the
// byte budget, prefetches the optimizer keeps, and threads that never see another key's data.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include "texcache/direct_mapped_cache.h"
#include "texcache/error.h"

namespace texcache {
namespace {

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
// an entry kept past InvalidateIf of other keys stays. Both one and three choices.
TEST(DirectMappedCache, InvalidatedEntriesNeverComeBack) {
    for (bool threeChoices : {false, true}) {
        DirectMappedCache<Payload> cache(DirectMappedCache<Payload>::kSlotBytes * 8, threeChoices);
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

// With three choices, three keys whose first slots coincide all stay cached (when their other
// slots differ), and lookups still never alias.
TEST(DirectMappedCache, ThreeChoicesKeepCollidingKeys) {
    DirectMappedCache<Payload> direct(DirectMappedCache<Payload>::kSlotBytes * 64, false);
    DirectMappedCache<Payload> three(DirectMappedCache<Payload>::kSlotBytes * 64, true);
    Payload out;
    SlotTicket t;
    int keptDirect = 0, keptThree = 0;
    for (uint64_t k = 1; k <= 40; ++k) {
        // Every key hashes to the same first slot (hash 7).
        if (direct.Acquire(k, 7, &out, &t) == AcquireResult::Claimed)
            direct.Publish(t, Payload::Of(k));
        if (three.Acquire(k, 7, &out, &t) == AcquireResult::Claimed)
            three.Publish(t, Payload::Of(k));
    }
    for (uint64_t k = 1; k <= 40; ++k) {
        if (direct.Find(k, 7, &out)) {
            EXPECT_TRUE(out.Matches(k));
            ++keptDirect;
        }
        if (three.Find(k, 7, &out)) {
            EXPECT_TRUE(out.Matches(k));
            ++keptThree;
        }
    }
    EXPECT_EQ(keptDirect, 1);  // direct mapped: the last key only
    EXPECT_EQ(keptThree, 3);   // the last three, one in each of the three slots they share
}

// An empty first slot is claimed without reading the second (a cold cache's fills). The one case
// where that differs from reading all: the key sits in its second slot and its first slot was
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
    // Key 3 takes the third slot; a key that misses all its slots, held by live keys, still
    // evicts rather than aliasing.
    ASSERT_EQ(cache.Acquire(3, 7, &out, &t), AcquireResult::Claimed);
    EXPECT_FALSE(t.evicted);
    cache.Publish(t, Payload::Of(3));
    ASSERT_EQ(cache.Acquire(4, 7, &out, &t), AcquireResult::Claimed);
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
// deletes the calls to it, which leaves the renderer without a single prefetch instruction
// (PrefetchLine says how the cache avoids it). The test reads the caller's machine code back: the
// call (or the prefetch, if the compiler inlines it after all) must still be there.
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
                             return info.param ? "ThreeChoices" : "DirectMapped";
                         });

}  // namespace
}  // namespace texcache
