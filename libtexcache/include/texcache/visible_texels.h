// SPDX-License-Identifier: Apache-2.0
// The texels a frame's camera rays land on, so that filter footprints shade only what is seen.
//
// Why. A texel-cache miss shades every sample of its (2r+1)^2 footprint (Munkberg et al. 2016,
// Sec. 4). Many of those texels are never seen: they lie behind an occluder, face away, or fall
// between the sparse texels a few camera samples per pixel reach (eq. 1 puts 1-4 texels under a
// pixel). The paper measures the cost (Fig. 14: 21x21 doubles the render) and leaves reducing it
// to future work. A prepass that traces the camera rays and marks their texels lets the filter
// keep only visible taps: a footprint then shades little more than the unfiltered render. The
// kept taps are made point-symmetric about the centre (GatherFootprint): the visible part of a
// window is one-sided where a surface disappears behind another, and a one-sided average of a
// shading gradient is biased (docs/texture-space.md, "Visible footprints", has the figures).
//
// Design note (concurrency and memory). A fixed table of 64-bit words; a word holds the 8x8
// block of texels (face, mip, iu/8, iv/8) hashes to, one bit per texel. Marking is an atomic
// fetch_or, testing a relaxed load: lock-free and wait-free. The marking pass finishes before
// the lookups start (the renderer joins its threads in between), which orders every mark before
// every test, so relaxed atomics are enough. Blocks that hash to the same word share it: a test
// may then answer "visible" for a texel that is not (a false positive: that tap is shaded, as
// without the set), never the reverse. So the table's size is a memory bound, not a correctness
// one (the renderer gives two words per pixel; a test bounds the false positives).
// A footprint's taps fall in a handful of blocks, so a test touches few cache lines.
#pragma once
#include <algorithm>
#include <atomic>
#include <bit>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

#include "texcache/huge_pages.h"
#include "texcache/prefetch.h"
#include "texcache/texel_key.h"

namespace texcache {

class VisibleTexels {
public:
    /// A table of `bytes` rounded down to a power of two words (at least 8: one cache line, at
    /// most 2^32: a Probe's low 32 bits then address every word).
    explicit VisibleTexels(size_t bytes)
        : words_(std::bit_floor(std::clamp<size_t>(bytes / sizeof(uint64_t), 8, size_t(1) << 32))),
          bits_(AllocateWords(words_)) {}

    /// Forgets every mark (not concurrently with Mark or Contains).
    void Clear() {
        for (size_t i = 0; i < words_; ++i) bits_[i].store(0, std::memory_order_relaxed);
    }
    /// Marks a texel as seen (thread-safe).
    void Mark(const TexelKey& k) { MarkAt(Probe(k), Bit(k)); }
    /// Mark() for a texel given by its Probe and Bit.
    void MarkAt(uint32_t probe, uint64_t bit) {
        // Read first: a pixel's camera samples mostly land on one texel, and a locked RMW on a
        // line the other threads read too costs far more than a load.
        std::atomic<uint64_t>& w = bits_[probe & (words_ - 1)];
        if (!(w.load(std::memory_order_relaxed) & bit)) w.fetch_or(bit, std::memory_order_relaxed);
    }
    /// Starts loading the word of a texel given by its Probe, ahead of a MarkAt or ContainsAt.
    void PrefetchAt(uint32_t probe) const { PrefetchLine(&bits_[probe & (words_ - 1)]); }
    /// Whether a texel was marked (or shares its word with a marked texel of another block).
    bool Contains(const TexelKey& k) const { return (BlockBits(k) & Bit(k)) != 0; }
    /// The marks of the 8x8 block holding texel k (bit Bit(k) is k's): a caller testing the
    /// texels of a window loads each block once.
    uint64_t BlockBits(const TexelKey& k) const {
        return bits_[Word(k)].load(std::memory_order_relaxed);
    }
    static uint64_t Bit(const TexelKey& k) { return uint64_t(1) << ((k.iv & 7) * 8 + (k.iu & 7)); }
    size_t Bytes() const { return words_ * sizeof(uint64_t); }

    /// The table's words, for combining the marks of tables of one size (other processes'
    /// marks of one frame): a word's marks and the marks to add to it (not concurrently with
    /// Contains).
    size_t NumWords() const { return words_; }
    uint64_t WordAt(size_t i) const { return bits_[i].load(std::memory_order_relaxed); }
    void MarkWord(size_t i, uint64_t marks) { bits_[i].fetch_or(marks, std::memory_order_relaxed); }

    /// Where texel k's mark lives, independent of the table's size: a caller that tests the same
    /// texels often (the footprint pads of footprint.cpp) keeps it instead of hashing again.
    static uint32_t Probe(const TexelKey& k) {
        // The 8 blocks of a 64-texel run along u share a cache line (8 words); runs are
        // scattered. A footprint row then reads one or two lines, and the rows of a block row
        // the same ones.
        uint64_t x = (uint64_t(k.face) << 4 | k.mip) * 0x9E3779B97F4A7C15ull;
        x ^= (uint64_t(k.iv >> 3) << 32 | uint64_t(k.iu >> 6)) * 0xC2B2AE3D27D4EB4Full;
        x ^= x >> 29;
        const uint64_t line = x * 0xBF58476D1CE4E5B9ull >> 20;
        return uint32_t(line << 3 | uint64_t((k.iu >> 3) & 7));
    }
    /// Contains() for a texel given by its Probe and Bit.
    bool ContainsAt(uint32_t probe, uint64_t bit) const {
        return (bits_[probe & (words_ - 1)].load(std::memory_order_relaxed) & bit) != 0;
    }

private:
    size_t Word(const TexelKey& k) const { return size_t(Probe(k)) & (words_ - 1); }

    // The words are on huge pages like the caches' slots (texcache/huge_pages.h): a frame marks
    // and prefetches words at random in a table of a few MB, and on 4 KB pages each of those
    // is a TLB miss, which a virtual machine makes dear and a prefetch waits for.
    struct Free {
        void operator()(std::atomic<uint64_t>* p) const { std::free(p); }
    };
    static std::atomic<uint64_t>* AllocateWords(size_t n) {
        static_assert(std::is_trivially_destructible_v<std::atomic<uint64_t>>);
        auto* words = static_cast<std::atomic<uint64_t>*>(AllocateHugePages(n * sizeof(uint64_t)));
        for (size_t i = 0; i < n; ++i) new (&words[i]) std::atomic<uint64_t>(0);
        return words;
    }

    size_t words_;
    std::unique_ptr<std::atomic<uint64_t>[], Free> bits_;
};

}  // namespace texcache
