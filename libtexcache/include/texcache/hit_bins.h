// SPDX-License-Identifier: Apache-2.0
// Texel bins of shading estimates computed at the camera's own hits, added up per texel of a grid
// level, for a reconstruction that reads bins instead of shading samples of its own: binary
// estimates (ambient occlusion: rays that escape out of rays traced, HitBins) and radiance
// (diffuse light: RGB sums in fixed point and their count, RadianceBins).
//
// Design note — concurrency and determinism
// -----------------------------------------
// Render threads add to the bins during one phase of a pass and read them in the next; the two
// phases are separated by the renderer (a barrier: every Add happens before any Find). So:
//   * Add is lock-free and wait-free but for the insertion of a new block: a block is claimed by
//     one compare-and-swap of its key from kEmpty; a thread that loses the race to the same key
//     adds to the winner's block, one that loses to another key probes on (linear probing).
//   * A bin is made of 64-bit words updated by compare-and-swap loops that saturate: a count bin
//     is one word, (trials << 32) | successes, each half saturating at 2^32 - 1; a radiance bin
//     is four, R, G and B in fixed point (RadianceBin::kScale units per unit) and the count,
//     each saturating at 2^64 - 1. Integer sums do not depend on the order of the adds (a
//     saturating sum of non-negative terms is min(total, cap) in any order), so the bins, and
//     every image read from them, are the same for any thread count and schedule: float
//     atomics would not be.
//   * The table is fixed-size (the blocks given at construction, never more). An Add that finds
//     no free block within kMaxProbes is dropped and counted (Dropped()); the renderer keeps the
//     table at most half full (BlocksUsed()) and bins a pass again into a larger table when an
//     add was dropped, up to a byte budget.
//   * Find is a plain read (relaxed atomics: the phase barrier orders it after every Add), and
//     never returns another key's bin: keys are compared in full.
// Bins are grouped in blocks of 4x4 of one face and level (136 bytes with the key for counts, 520
// for radiance), so the 2x2 bins a bilinear reconstruction reads mostly share one block.
#pragma once
#include <algorithm>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>
#include <vector>

#include "texcache/huge_pages.h"
#include "texcache/prefetch.h"
#include "texcache/texel_key.h"

namespace texcache {

/// A bin of binary estimates: successes (e.g. AO rays that escape) out of trials (rays traced),
/// one word: (trials << 32) | successes, each half saturating.
struct CountBin {
    struct Value {
        uint32_t successes = 0, trials = 0;
    };
    static constexpr int kWords = 1;
    static void Accumulate(Value* a, const Value& b) {
        a->successes = SatAdd(a->successes, b.successes);
        a->trials = SatAdd(a->trials, b.trials);
    }
    static void AddTo(std::atomic<uint64_t>* w, const Value& v) {
        uint64_t old = w->load(std::memory_order_relaxed), next;
        do {
            next = (uint64_t(SatAdd(uint32_t(old >> 32), v.trials)) << 32) |
                   SatAdd(uint32_t(old), v.successes);
        } while (!w->compare_exchange_weak(old, next, std::memory_order_relaxed));
    }
    static Value Load(const std::atomic<uint64_t>* w) {
        const uint64_t x = w->load(std::memory_order_relaxed);
        return {uint32_t(x), uint32_t(x >> 32)};
    }
    /// A word of the bin scaled by keep / 2^16 (keep <= 2^16), each half rounded to nearest.
    static uint64_t ScaleWord(uint64_t x, uint32_t keep) {
        const uint64_t s = (uint32_t(x) * uint64_t(keep) + 0x8000u) >> 16;
        const uint64_t t = ((x >> 32) * uint64_t(keep) + 0x8000u) >> 16;
        return (t << 32) | s;
    }
    static uint32_t SatAdd(uint32_t a, uint32_t b) {
        const uint32_t s = a + b;
        return s < a ? UINT32_MAX : s;
    }
};

/// A bin of radiance estimates: the sums of R, G and B in fixed point (kScale units per unit of
/// radiance, rounded to nearest) and how many estimates they hold, four words each saturating
/// at 2^64 - 1. An estimate is clamped to kMaxValue per channel (2^24: far above any radiance a
/// scene's diffuse light reaches, so nothing real is clipped) so that 2^20 of them fit before a
/// sum can saturate; the resolution, 2^-20, is a millionth of a white surface's light.
struct RadianceBin {
    struct Value {
        uint64_t sum[3] = {0, 0, 0};
        uint64_t count = 0;
    };
    static constexpr int kWords = 4;
    static constexpr double kScale = double(1 << 20);
    static constexpr double kMaxValue = double(1 << 24);
    /// One estimate in fixed point; false (nothing to add) for a NaN, infinite or negative one,
    /// which would otherwise poison every read of the bin.
    static bool FromRadiance(const float rgb[3], Value* v) {
        for (int k = 0; k < 3; ++k) {
            const float x = rgb[k];
            if (!(x >= 0.0f) || !(x <= 3.0e38f)) return false;  // NaN, -x, +inf
            v->sum[k] = uint64_t(std::min(double(x), kMaxValue) * kScale + 0.5);
        }
        v->count = 1;
        return true;
    }
    static void Accumulate(Value* a, const Value& b) {
        for (int k = 0; k < 3; ++k) a->sum[k] = SatAdd(a->sum[k], b.sum[k]);
        a->count = SatAdd(a->count, b.count);
    }
    static void AddTo(std::atomic<uint64_t>* w, const Value& v) {
        for (int k = 0; k < 4; ++k) {
            const uint64_t add = k < 3 ? v.sum[k] : v.count;
            if (add == 0) continue;
            uint64_t old = w[k].load(std::memory_order_relaxed);
            while (!w[k].compare_exchange_weak(old, SatAdd(old, add), std::memory_order_relaxed)) {
            }
        }
    }
    static Value Load(const std::atomic<uint64_t>* w) {
        Value v;
        for (int k = 0; k < 3; ++k) v.sum[k] = w[k].load(std::memory_order_relaxed);
        v.count = w[3].load(std::memory_order_relaxed);
        return v;
    }
    /// A word of the bin scaled by keep / 2^16 (keep <= 2^16), rounded to nearest.
    static uint64_t ScaleWord(uint64_t x, uint32_t keep) {
        // x keep / 2^16 = (x >> 16) keep + (x & 0xFFFF) keep / 2^16, each term within 64 bits.
        return (x >> 16) * keep + (((x & 0xFFFFu) * keep + 0x8000u) >> 16);
    }
    static uint64_t SatAdd(uint64_t a, uint64_t b) {
        const uint64_t s = a + b;
        return s < a ? UINT64_MAX : s;
    }
};

namespace internal {
/// A number no earlier call returned, process-wide (every kind of table draws from it).
inline uint64_t NextGeneration() {
    static std::atomic<uint64_t> last{0};
    return last.fetch_add(1, std::memory_order_relaxed) + 1;
}
}  // namespace internal

/// A fixed-size, lock-free table of bins (see the design note above), keyed by TexelKey, of one
/// kind: CountBin (HitBins) or RadianceBin (RadianceBins).
template <typename Bin>
class BinTable {
public:
    using Value = typename Bin::Value;
    static constexpr int kMaxProbes = 32;

    /// A table of `minBlocks` blocks of 4x4 bins or more (a power of two, at least 8):
    /// BytesFor(NumBlocks()) bytes, allocated once.
    explicit BinTable(size_t minBlocks) {
        const size_t blocks = BlocksFor(minBlocks);
        blocks_ = blocks;
        shift_ = 64 - std::countr_zero(blocks);
        bins_.reset(static_cast<Block*>(AllocateHugePages(blocks * sizeof(Block))));
        for (size_t i = 0; i < blocks; ++i) new (&bins_[i]) Block;
        Clear();
    }

    /// The blocks of a table of at least `minBlocks`: a power of two, at least 8.
    static constexpr size_t BlocksFor(size_t minBlocks) {
        size_t blocks = 8;
        while (blocks < minBlocks) blocks *= 2;
        return blocks;
    }

    /// Empties every bin (between passes; never while Add or Find run).
    void Clear() {
        for (size_t i = 0; i < blocks_; ++i) {
            bins_[i].key.store(TexelKey::kEmpty, std::memory_order_relaxed);
            for (auto& w : bins_[i].w) w.store(0, std::memory_order_relaxed);
        }
        dropped_.store(0, std::memory_order_relaxed);
        used_.store(0, std::memory_order_relaxed);
        generation_ = internal::NextGeneration();
    }

    /// Adds `v` to bin `key` (a TexelKey of the bin's face, level and coordinates). False when
    /// the table had no room (the add is dropped and counted).
    bool Add(const TexelKey& key, const Value& v) {
        Block* b = Claim(BlockKey(key));
        if (b) Bin::AddTo(&b->w[Lane(key) * Bin::kWords], v);
        return b != nullptr;
    }

    /// Words of a record of ExportBlocks: the block's key, then its 16 bins' words.
    static constexpr size_t kRecordWords = 1 + 16 * Bin::kWords;
    /// Appends every block in use as a record to `out`: what a table of the same kind in
    /// another process adds (AddBlocks) to hold the sums of both.
    void ExportBlocks(std::vector<uint64_t>* out) const {
        for (size_t i = 0; i < blocks_; ++i) {
            const uint64_t k = bins_[i].key.load(std::memory_order_relaxed);
            if (k == TexelKey::kEmpty) continue;
            out->push_back(k);
            for (const auto& w : bins_[i].w) out->push_back(w.load(std::memory_order_relaxed));
        }
    }
    /// Adds `n` records of ExportBlocks (another table's) to this one, bin by bin (the same
    /// saturating sums as Add); the number of records that found no room (dropped, counted).
    uint64_t AddBlocks(const uint64_t* records, size_t n) {
        uint64_t lost = 0;
        for (size_t r = 0; r < n; ++r, records += kRecordWords) {
            Block* b = Claim(records[0]);
            if (!b) {
                ++lost;
                continue;
            }
            for (int lane = 0; lane < 16; ++lane) {
                std::atomic<uint64_t> words[Bin::kWords];
                for (int k = 0; k < Bin::kWords; ++k)
                    words[k].store(records[1 + lane * Bin::kWords + k], std::memory_order_relaxed);
                Bin::AddTo(&b->w[lane * Bin::kWords], Bin::Load(words));
            }
        }
        return lost;
    }

    /// Scales every bin by keep / 2^16 (keep <= 2^16; Bin::ScaleWord, integer arithmetic, so the
    /// same on any machine) and releases the blocks that fall to zero: the decay of a moving
    /// average over frames, whose old blocks would otherwise fill the table. Never while Add or
    /// Find run. A new Generation.
    void Scale(uint32_t keep) {
        std::vector<uint64_t> records;
        ExportBlocks(&records);
        ScaleRecords(&records, keep);
        uint64_t dropped = Dropped();
        Clear();
        dropped += AddBlocks(records.data(), records.size() / kRecordWords);
        dropped_.store(dropped, std::memory_order_relaxed);
    }
    /// Scales every bin by keep / 2^16 as Scale does, in place: the blocks that fall to zero
    /// stay claimed (no table rebuilt), for a table decayed every frame whose blocks mostly stay
    /// in use; Scale releases them. Never while Add or Find run. A new Generation.
    void ScaleInPlace(uint32_t keep) {
        ScaleInPlace(keep, [](size_t n, auto&& body) { body(size_t(0), n); });
    }
    /// As ScaleInPlace, with the blocks split by `forRange(n, body)`, which calls body(begin,
    /// end) over ranges that cover [0, n) once, in any order or in parallel (each block is
    /// scaled on its own): a table of many blocks is a serial pass over memory between frames.
    template <typename ForRange>
    void ScaleInPlace(uint32_t keep, ForRange&& forRange) {
        forRange(blocks_, [&](size_t begin, size_t end) {
            for (size_t i = begin; i < end; ++i) {
                if (bins_[i].key.load(std::memory_order_relaxed) == TexelKey::kEmpty) continue;
                for (auto& w : bins_[i].w)
                    w.store(Bin::ScaleWord(w.load(std::memory_order_relaxed), keep),
                            std::memory_order_relaxed);
            }
        });
        generation_ = internal::NextGeneration();
    }
    /// Scales records of ExportBlocks as Scale scales the bins, and removes those that fall to
    /// zero.
    static void ScaleRecords(std::vector<uint64_t>* records, uint32_t keep) {
        size_t kept = 0;
        for (size_t r = 0; r < records->size(); r += kRecordWords) {
            uint64_t* in = records->data() + r;
            uint64_t* out = records->data() + kept;
            bool any = false;
            out[0] = in[0];
            for (size_t k = 1; k < kRecordWords; ++k) {
                out[k] = Bin::ScaleWord(in[k], keep);
                any = any || out[k] != 0;
            }
            if (any) kept += kRecordWords;
        }
        records->resize(kept);
    }

    /// The value of bin `key` (zero when nothing was added to it).
    Value Find(const TexelKey& key) const {
        const uint64_t bk = BlockKey(key);
        size_t i = Home(bk);
        for (int p = 0; p < kMaxProbes; ++p, i = (i + 1) & (blocks_ - 1)) {
            const uint64_t k = bins_[i].key.load(std::memory_order_relaxed);
            if (k == bk) return Bin::Load(&bins_[i].w[Lane(key) * Bin::kWords]);
            if (k == TexelKey::kEmpty) break;
        }
        return {};
    }

    /// Starts loading the home slot of bin `key`'s block and the bin's words there (a hint:
    /// Find and FindBlock read them), for a caller that knows its keys ahead of its reads.
    void Prefetch(const TexelKey& key) const {
        const Block* b = &bins_[Home(BlockKey(key))];
        PrefetchLine(b);
        PrefetchLine(&b->w[Lane(key) * Bin::kWords]);
    }

    /// The sum of the 16 bins of the block that holds bin `key` (4x4 bins of one face and level,
    /// aligned on multiples of 4): a bin of the level two above read from this one's, in one
    /// lookup; empty when the block has none. A plain read, as Find.
    Value FindBlock(const TexelKey& key) const {
        const uint64_t bk = BlockKey(key);
        size_t i = Home(bk);
        for (int p = 0; p < kMaxProbes; ++p, i = (i + 1) & (blocks_ - 1)) {
            const uint64_t k = bins_[i].key.load(std::memory_order_relaxed);
            if (k == bk) {
                Value sum;
                for (int lane = 0; lane < 16; ++lane)
                    Bin::Accumulate(&sum, Bin::Load(&bins_[i].w[lane * Bin::kWords]));
                return sum;
            }
            if (k == TexelKey::kEmpty) break;
        }
        return {};
    }

    /// A thread's adds, gathered in a small local table and added to the shared bins once per
    /// bin: a tile's hits fall into a few dozen bins, and one atomic add per hit would be most of
    /// the cost of binning (`perf` on hit-binned AO). Flush (or destroy) before the bins are
    /// read. The sums are the same as adding one by one (integer sums, any order).
    class Batch {
    public:
        explicit Batch(BinTable& bins) : bins_(&bins) {
            for (Entry& e : local_) e.key = TexelKey::kEmpty;
        }
        ~Batch() { Flush(); }
        Batch(const Batch&) = delete;
        Batch& operator=(const Batch&) = delete;

        void Add(const TexelKey& key, const Value& v) {
            const uint64_t k = key.Pack();
            Entry& e = local_[(k * 0x9E3779B97F4A7C15ull) >> (64 - kLog2Local)];
            if (e.key != k) {
                if (e.key != TexelKey::kEmpty) bins_->Add(TexelKey::Unpack(e.key), e.v);
                e.key = k, e.v = Value();
            }
            Bin::Accumulate(&e.v, v);
        }
        void Flush() {
            for (Entry& e : local_)
                if (e.key != TexelKey::kEmpty) {
                    bins_->Add(TexelKey::Unpack(e.key), e.v);
                    e.key = TexelKey::kEmpty;
                }
        }

    private:
        static constexpr int kLog2Local = 8;
        // The value is left uninitialised until its key is set (a union member): zeroing all of
        // them for every batch, one per tile, would cost as much as binning a 4-spp tile's hits.
        struct Entry {
            Entry() {}
            uint64_t key;
            union {
                Value v;
            };
        };
        BinTable* bins_;
        Entry local_[1 << kLog2Local];
    };

    /// Blocks of 4x4 bins in use since the last Clear. Probes stay short while at most half
    /// the blocks are: a renderer sizes the next table from this (render.cpp).
    size_t BlocksUsed() const { return used_.load(std::memory_order_relaxed); }
    /// Bytes of `blocks` blocks.
    static constexpr size_t BytesFor(size_t blocks) { return blocks * kBytesPerBlock; }
    /// What the table holds, as a number no other table's contents and no earlier contents of
    /// this one had (a new one at each Clear, process-wide): a reader may keep what it read
    /// from the table while the generation stays (the renderer's per-thread reconstruction memo).
    uint64_t Generation() const { return generation_; }
    /// A new Generation for the contents adds changed since they were last read, for a user
    /// that reads, adds and reads again between Clears (the frame buffers' store). Never while
    /// Add or Find run.
    void NewGeneration() { generation_ = internal::NextGeneration(); }
    /// Adds that found no room since the last Clear.
    uint64_t Dropped() const { return dropped_.load(std::memory_order_relaxed); }
    size_t NumBlocks() const { return blocks_; }
    size_t BytesUsed() const { return blocks_ * kBytesPerBlock; }

private:
    // The key beside its bins: a lookup touches the block's first line for the key and, for
    // most lanes, the next one or two (a separate key array would cost a second miss per lookup).
    struct Block {
        std::atomic<uint64_t> key;
        std::atomic<uint64_t> w[16 * Bin::kWords];
    };
    static constexpr size_t kBytesPerBlock = sizeof(Block);

    /// The block of key `bk`, claimed if it is new; null (the add dropped and counted) when no
    /// block within kMaxProbes is free.
    Block* Claim(uint64_t bk) {
        size_t i = Home(bk);
        for (int p = 0; p < kMaxProbes; ++p, i = (i + 1) & (blocks_ - 1)) {
            std::atomic<uint64_t>& slot = bins_[i].key;
            uint64_t k = slot.load(std::memory_order_acquire);
            if (k == TexelKey::kEmpty) {
                if (slot.compare_exchange_strong(k, bk, std::memory_order_acq_rel)) {
                    k = bk;  // claimed
                    used_.fetch_add(1, std::memory_order_relaxed);
                }  // else lost the race: `k` now holds the winner's key
            }
            if (k == bk) return &bins_[i];
        }
        dropped_.fetch_add(1, std::memory_order_relaxed);
        return nullptr;
    }
    static uint64_t BlockKey(const TexelKey& k) {
        TexelKey b = k;
        b.iu = uint16_t(k.iu >> 2), b.iv = uint16_t(k.iv >> 2);
        return b.Pack();
    }
    static int Lane(const TexelKey& k) { return (k.iv & 3) * 4 + (k.iu & 3); }
    size_t Home(uint64_t bk) const { return size_t((bk * 0x9E3779B97F4A7C15ull) >> shift_); }

    size_t blocks_ = 0;
    int shift_ = 61;
    struct Free {
        void operator()(Block* p) const { std::free(p); }  // Block is trivially destructible
    };
    std::unique_ptr<Block[], Free> bins_;
    std::atomic<uint64_t> dropped_{0};
    uint64_t generation_ = 0;
    std::atomic<size_t> used_{0};
};

/// Bins of binary estimates (hit-binned AO).
using HitBins = BinTable<CountBin>;
/// Bins of radiance estimates (hit-binned diffuse light).
using RadianceBins = BinTable<RadianceBin>;

}  // namespace texcache
