// SPDX-License-Identifier: Apache-2.0
// Temporal accumulation (eq. 6): the blend over frames, no double blending within a frame, and
// concurrent blends of colliding keys never mixing keys (run under ThreadSanitizer by
// scripts/test.sh).
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

#include "texcache/temporal_history.h"

namespace texcache {
namespace {

// Eq. 6 over frames; a second reconstruction in the same frame restarts from the stored
// previous value instead of blending twice.
TEST(TemporalHistory, FollowsEquationSix) {
    TemporalHistory<float> h(1 << 16, 0.7f);
    const TexelKey k{5, 1, 3, 4};
    EXPECT_EQ(h.Blend(k, 0, 1.0f), 1.0f);
    const float f1 = h.Blend(k, 1, 0.0f);
    EXPECT_NEAR(f1, 0.7f, 1e-6f);
    EXPECT_NEAR(h.Blend(k, 1, 0.0f), 0.7f, 1e-6f);  // same frame again
    EXPECT_NEAR(h.Blend(k, 2, 0.0f), 0.49f, 1e-6f);
    EXPECT_THROW(TemporalHistory<float>(1 << 16, 1.0f), InputError);
    EXPECT_THROW(TemporalHistory<float>(1 << 16, NAN), InputError);
}

// Threads blending colliding keys into a tiny table: every result is a blend of that key's own
// values (each key blends only the constant `key id`), never another key's.
TEST(TemporalHistory, ConcurrentBlendsNeverMixKeys) {
    TemporalHistory<float> h(4096, 0.5f);  // ~100 slots for 2000 keys: constant collisions
    std::vector<std::thread> threads;
    std::atomic<int> bad{0};
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            for (uint32_t frame = 0; frame < 20; ++frame)
                for (int i = 0; i < 2000; ++i) {
                    const int id = (i * 7 + t * 13) % 2000;
                    const TexelKey k{uint32_t(id), 0, 0, 0};
                    const float v = h.Blend(k, frame, float(id));
                    if (v != float(id)) ++bad;
                }
        });
    for (auto& th : threads) th.join();
    EXPECT_EQ(bad.load(), 0);
}

}  // namespace
}  // namespace texcache
