// SPDX-License-Identifier: Apache-2.0
// The texture-space store of shading estimated at the camera's hits: one two-level cache keyed
// by texel (TexelKey: face, level, i, j), a sample level of what the hits give and a texel level
// of what a material filter makes of it.
//
// Design note — what each level holds, who fills it, and why
// ----------------------------------------------------------
//   * The sample level is a BinTable (texcache/hit_bins.h): per texel of a bin level, the sums
//     of the shading estimates the camera's hits added there and their count (AO: escaped rays
//     out of rays traced; light: fixed-point RGB sums and how many). Render threads fill it in
//     the binning phase of a pass (Add, lock-free); it is read in the resolve phase, after a
//     barrier. Integer sums do not depend on the order of the adds, so its contents are the
//     same for any thread count and schedule.
//   * The texel level is a fixed-size DirectMappedCache of one Texel per key: a material filter's
//     value at a bin centre (a Gaussian or a plane fit over a window of sample-level entries, up
//     to 9x9 in the renderer). The resolve phase reads it; the first thread that needs a texel
//     computes it and publishes it, and every thread reuses it until the sample level changes. A
//     texel computed by one thread in one tile is the same one its neighbours in other tiles and
//     threads need: a per-thread memo would compute each tile edge's texels once per thread that
//     reads them.
//   * A filtered value is a pure function of the sample level (the caller's filter reads the
//     sample level only, in a fixed order), so it does not matter which thread computes it, or
//     whether a texel was evicted and computed again: the image is the same for any thread
//     count. A thread that finds a texel being computed by another (Pending) or its slot busy
//     with another key (Conflict) computes it itself without storing it: never a wait.
//   * Whatever changes the sample level (Clear for a new pass or frame, Decay between frames of
//     temporal accumulation) moves the texel level to a new epoch in O(1) (the cache's tags):
//     a texel is never read against sample sums other than those it was filtered from.
//   * Memory: both levels are allocated once, at construction (the sample level's blocks and
//     the texel level's byte budget); nothing is allocated per lookup. A full sample level drops
//     adds and counts them (the renderer bins the pass again into a larger store); a full
//     texel level evicts (direct mapping), never returns another key's value.
//
// Relation to the paper's grid cache (texcache/shading_cache.h, Munkberg et al. 2016, Sec. 4-5).
// The paper's two levels are the same shape: samples on a texel grid, and texels filtered from a
// footprint of samples. There, a sample is shaded lazily at its grid point the first time a
// texel's footprint needs it, so every sample costs shading rays of its own. Here the samples
// are the camera hits' own shading, which the renderer computes anyway, added to the texel they
// fall in; no sample is shaded for the store. The grid cache stays for what needs samples where
// no hit gives them (a view with no hits of its own there, the paper's experiments).
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "texcache/direct_mapped_cache.h"
#include "texcache/hit_bins.h"
#include "texcache/texel_key.h"

namespace texcache {

/// The two-level store of hit shading (see the design note): a sample level of Bin sums
/// (CountBin or RadianceBin) and a texel level of filtered values of type Texel.
template <typename Bin, typename Texel>
class TextureStore {
    static_assert(std::is_trivially_copyable_v<Texel>, "texels are stored word by word");

public:
    using SampleLevel = BinTable<Bin>;
    /// Bytes one texel of the texel level costs.
    static constexpr size_t kTexelBytes = DirectMappedCache<Texel>::kSlotBytes;

    /// A sample level of at least `minBlocks` blocks of 4x4 entries (SampleLevel's rounding) and
    /// a texel level of at most `texelBytes` bytes (at least one texel).
    TextureStore(size_t minBlocks, size_t texelBytes)
        : samples_(minBlocks), texels_(std::max(texelBytes, kTexelBytes)) {}

    /// The sample level: Add during a binning phase, Find during a resolve phase.
    SampleLevel& Samples() { return samples_; }
    const SampleLevel& Samples() const { return samples_; }

    /// Empties both levels (a new pass or frame; never while adds or lookups run).
    void Clear() {
        samples_.Clear();
        texels_.InvalidateAll();
    }

    /// The filtered value of texel `key`: the texel level's, or `filter()` (a pure function of
    /// the sample level) computed by this call and stored for the other threads. `side` is the
    /// key's grid side, for a scanline slot (neighbouring texels never collide). Only while no
    /// add runs (a resolve phase).
    template <typename Filter>
    Texel Filtered(const TexelKey& key, int side, Filter&& filter) const {
        const uint64_t k = key.Pack();
        const uint64_t hash = (uint64_t(key.face) * 0x9E3779B1u) ^ (uint64_t(key.mip) << 27);
        const uint64_t at = hash + uint64_t(key.iv) * uint64_t(side) + key.iu;
        Texel t;
        SlotTicket ticket;
        switch (texels_.Acquire(k, at, &t, &ticket)) {
            case AcquireResult::Hit:
                return t;
            case AcquireResult::Claimed:
                t = filter();
                texels_.Publish(ticket, t);
                return t;
            case AcquireResult::Pending:   // another thread is computing the same value
            case AcquireResult::Conflict:  // the slot is busy with another key
                break;
        }
        return filter();
    }

    /// Scales every sample-level sum and count by keep / 2^16 (rounded to nearest; keep <=
    /// 2^16), the decay of an exponential moving average over frames, and starts a new texel
    /// epoch. Integer arithmetic: the same sums on any machine and for any thread count. Between
    /// frames only.
    void Decay(uint32_t keep) {
        samples_.Scale(keep);
        texels_.InvalidateAll();
    }

    /// Empties the entries of faces [first, end) of both levels, keeping the others (an object
    /// moved, or its material changed what its light holds). Between frames only.
    void ForgetFaces(uint64_t first, uint64_t end) {
        std::vector<uint64_t> records;
        samples_.ExportBlocks(&records);
        size_t kept = 0;
        for (size_t r = 0; r < records.size(); r += SampleLevel::kRecordWords) {
            const uint64_t face = TexelKey::Unpack(records[r]).face;
            if (face >= first && face < end) continue;
            std::copy_n(records.begin() + ptrdiff_t(r), SampleLevel::kRecordWords,
                        records.begin() + ptrdiff_t(kept));
            kept += SampleLevel::kRecordWords;
        }
        samples_.Clear();
        samples_.AddBlocks(records.data(), kept / SampleLevel::kRecordWords);
        texels_.InvalidateAll();
    }

    /// After adds to a sample level that was read before them (a frame that reads the store to
    /// pick which hits to shade, then adds them): a new sample-level Generation and texel epoch,
    /// so no memo or texel of the earlier contents is read again. Never while adds or lookups
    /// run.
    void AddsDone() {
        samples_.NewGeneration();
        texels_.InvalidateAll();
    }

    /// Decay without releasing the blocks that fall to zero (BinTable::ScaleInPlace): no table
    /// rebuilt, for a store decayed every frame. Between frames only.
    void DecayInPlace(uint32_t keep) {
        samples_.ScaleInPlace(keep);
        texels_.InvalidateAll();
    }
    /// As DecayInPlace, the blocks split by `forRange` (BinTable::ScaleInPlace).
    template <typename ForRange>
    void DecayInPlace(uint32_t keep, ForRange&& forRange) {
        samples_.ScaleInPlace(keep, forRange);
        texels_.InvalidateAll();
    }

    /// Bytes of both levels (fixed at construction).
    size_t BytesUsed() const { return samples_.BytesUsed() + texels_.BytesUsed(); }
    size_t TexelBytes() const { return texels_.BytesUsed(); }

private:
    SampleLevel samples_;
    // Texels are a cache of values derived from the sample level: filling it from a const
    // lookup changes no observable state (the same value as computing it again).
    mutable DirectMappedCache<Texel> texels_;
};

}  // namespace texcache
