// SPDX-License-Identifier: Apache-2.0
// Temporal accumulation (eq. 6): the blend over frames, no double blending within a frame, and
// concurrent blends of colliding keys never mixing keys (run under ThreadSanitizer by
// scripts/test.sh).
#include <gtest/gtest.h>

#include <algorithm>
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

// A still view (SetRunningMean): the history's weight is n / (n + 1) for n estimates, never
// below alpha, so over many frames the texel is their mean and converges; going back to eq. 6
// weights the history by alpha again. InvalidateIf forgets the texels it names only.
TEST(TemporalHistory, RunningMeanWhileStillAndForgetsWhatItIsTold) {
    TemporalHistory<float> h(1 << 16, 0.7f);
    h.SetRunningMean(true);
    const TexelKey k{5, 1, 3, 4}, other{9, 1, 3, 4};
    float v = 0.0f, expected = 0.0f;
    for (uint32_t f = 0; f < 100; ++f) {
        v = h.Blend(k, f, float(f % 10));
        const float a = f == 0 ? 0.0f : std::max(0.7f, float(f) / float(f + 1));
        expected = (1.0f - a) * float(f % 10) + a * expected;
    }
    EXPECT_NEAR(v, expected, 1e-4f);
    EXPECT_NEAR(v, 4.5f, 0.1f);                   // near the mean of the estimates
    EXPECT_NEAR(h.Blend(k, 99, 9.0f), v, 1e-5f);  // the same frame again: no double count
    h.SetRunningMean(false);
    EXPECT_NEAR(h.Blend(k, 100, 0.0f), 0.7f * v, 1e-5f);
    h.Blend(other, 10, 2.0f);
    h.InvalidateIf([&](uint64_t key) { return key == k.Pack(); });
    EXPECT_EQ(h.Blend(k, 11, 1.0f), 1.0f);               // forgotten: starts anew
    EXPECT_NEAR(h.Blend(other, 11, 0.0f), 1.4f, 1e-5f);  // kept
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
