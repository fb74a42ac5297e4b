// SPDX-License-Identifier: Apache-2.0
// Temporal accumulation of texels across frames (Munkberg et al. 2016, Sec. 6.1, eq. 6):
//   c_i = (1 - alpha) c + alpha c_{i-1}
// where c is the texel filtered from this frame's samples and c_{i-1} what the texel had
// accumulated up to the previous frame. Samples live on the object's own grids, so a texel is the
// same surface point in every frame however the object moves rigidly.
//
// Storage: a fixed-size direct-mapped table (DirectMappedCache) of {accumulated, previous,
// frame} per texel key, separate from the texel cache, which is emptied every frame. A texel is
// normally reconstructed once per frame; if it is evicted from the texel cache and reconstructed
// again in the same frame, Blend() starts again from the stored `previous` instead of blending
// twice. Stores that collide with a concurrent store to the same slot are dropped (the texel then
// restarts its history): a lost frame of history, never a wrong value.
//
// A still view (SetRunningMean): the weight of the history grows as n / (n + 1) with the n
// estimates it holds (never below alpha), so that a texel re-shaded frame after frame is their
// mean and converges, where eq. 6's fixed alpha keeps about (1 + alpha) / (1 - alpha) frames'
// worth of noise. A moving view goes back to eq. 6: the history then lags the view less.
#pragma once
#include <algorithm>
#include <cstdint>

#include "texcache/direct_mapped_cache.h"
#include "texcache/texel_key.h"

namespace texcache {

template <typename Texel>
class TemporalHistory {
public:
    /// `alpha` in [0, 1): the weight of the history (the paper uses 0.7).
    TemporalHistory(size_t capacityBytes, float alpha) : alpha_(alpha), table_(capacityBytes) {
        if (!(alpha >= 0.0f && alpha < 1.0f))
            throw InputError("temporal alpha", "must be in [0, 1), got " + std::to_string(alpha));
    }

    /// Blends this frame's value of a texel into its history and returns the result.
    Texel Blend(const TexelKey& k, uint32_t frame, const Texel& current) {
        const uint64_t key = k.Pack();
        const uint64_t hash = Mix(key);
        Entry e;
        bool have = false;
        Texel base{};
        if (table_.Find(key, hash, &e)) {
            if (e.frame != frame) {  // last frame's result
                have = true, base = e.accumulated;
            } else if (e.hasPrevious) {  // reconstructed again this frame
                have = true, base = e.previous;
            }
        }
        uint32_t n = 0;  // estimates in `base`
        if (have) n = e.frame != frame ? e.count : e.previousCount;
        float a = alpha_;
        if (runningMean_ && n > 0) a = std::max(a, float(n) / float(n + 1));
        const Texel out = have ? (1.0f - a) * current + a * base : current;
        // Under eq. 6 the history is worth (1 + alpha) / (1 - alpha) estimates (the variance
        // of its weights), however many it saw: a still view's running mean starts from that.
        const uint32_t cap =
            runningMean_ ? kMaxCount : std::max(1u, uint32_t((1.0f + alpha_) / (1.0f - alpha_)));
        const uint32_t count = std::min(n + 1, cap);
        table_.TryStore(key, hash, Entry{out, base, frame, count, n, have});
        return out;
    }

    float Alpha() const { return alpha_; }
    /// Blends as a running mean of the texel's estimates (a still view: see the note at the
    /// top) or by eq. 6 (false, the default). Never while blends run.
    void SetRunningMean(bool on) { runningMean_ = on; }
    size_t BytesUsed() const { return table_.BytesUsed(); }
    void Clear() { table_.InvalidateAll(); }
    /// Forgets the history of every texel whose packed key satisfies `pred` (an edited object's
    /// texels). Between frames.
    template <typename Pred>
    void InvalidateIf(Pred pred) {
        table_.InvalidateIf(pred);
    }

private:
    struct Entry {
        Texel accumulated{};
        Texel previous{};
        uint32_t frame = 0;
        uint32_t count = 0;          // estimates in `accumulated`
        uint32_t previousCount = 0;  // and in `previous`
        bool hasPrevious = false;
    };
    // A running mean of more estimates than this would hardly move; the cap keeps its weight
    // below 1 so a texel still follows a slow drift.
    static constexpr uint32_t kMaxCount = 4096;
    static uint64_t Mix(uint64_t x) {
        x ^= x >> 33, x *= 0xff51afd7ed558ccdull, x ^= x >> 33;
        return x;
    }
    float alpha_;
    bool runningMean_ = false;
    DirectMappedCache<Entry> table_;
};

}  // namespace texcache
