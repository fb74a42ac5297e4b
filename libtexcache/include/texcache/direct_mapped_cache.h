// SPDX-License-Identifier: Apache-2.0
// A fixed-size, direct-mapped, lock-free cache of caller-defined payloads keyed by TexelKey.
//
// Design note — ownership and threading
// -------------------------------------
// The cache is an array of slots, each {seq, key, payload}. It owns all memory, allocated once
// at construction: capacityBytes / sizeof(Slot) slots, never more (the byte budget is a hard
// bound). Payloads are stored as atomic 64-bit words, so concurrent readers and writers
// never race in the C++ sense (ThreadSanitizer-clean) and a reader can never see a torn payload
// it would accept.
//
// Each slot is a seqlock whose odd phase doubles as the "being shaded" state of Munkberg et al.
// (Sec. 5): an entry is EMPTY (key == kEmpty, seq even), READY (key valid, seq even) or BUSY (seq
// odd: the claiming thread is shading it; `key` says for which key).
//   - Acquire(key): read seq (acquire). Odd -> Pending if the slot is busy with our key (another
//     thread is shading it: defer and come back), else Conflict (shade without caching; we never
//     wait for an unrelated key). Even and key matches -> copy the payload (acquire loads) and
//     re-read seq: unchanged means the copy is one consistent publication of *this* key (Hit);
//     changed means a writer intervened: retry. Even and key differs -> CAS seq to odd; winning
//     it claims the slot (evicting what was there) and the caller must Publish or Abandon.
//   - Publish: store payload words (release), then seq+1 (release): readers that saw the new even
//     seq see the whole payload; readers that saw any new word also see the odd seq and retry.
//     The claimed key is stored with release too. Abandon: key = kEmpty, seq+1.
// So the hit path is two atomic loads of seq, one of key and the payload words: no lock, no
// allocation, no virtual call. Synchronisation happens only when a thread claims a slot.
//
// Three choices (optional): a key may also live in a second and a third, hashed slot. Acquire
// reads all three (each with the seqlock check above) and, on a miss, claims an idle one (an
// empty one first; an empty first slot is claimed without reading the others). Two threads
// missing the same key may claim one slot each, and so may a key in another slot whose first
// slot was emptied later: both copies then hold the same key's payload, which is harmless. A
// colliding key still evicts, never aliases. With two slots a frame's own texels still evicted
// each other every frame wherever three of them shared both of their slots; a third slot makes
// that four sharing all three. Direct mapping (the paper's) is the one-choice case.
//
// Lifetime: the cache lives as long as its owner (e.g. across frames); Invalidate* evict entries
// explicitly when the scene changes. Invalidation must not run while the same keys are being
// shaded (call it between frames); it is still memory-safe if it does.
//
// Invalidating everything is O(1) most of the time: keys are 60 bits (TexelKey::Pack), and a
// slot stores its key with the cache's current tag in the top 4 bits. InvalidateAll moves to the
// next tag, and an entry of an older tag reads as empty (a miss, then a claim that evicts
// nothing). Only every 15th InvalidateAll, when the tags would come round again, sweeps the
// slots. Progressive passes and the preview's refinement invalidate both caches every pass, and
// a sweep of 2 x 64 MB each time (with page faults on slots never touched) would be a large
// share of a small progressive render.
#pragma once
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <type_traits>

#include "texcache/error.h"
#include "texcache/huge_pages.h"
#include "texcache/prefetch.h"
#include "texcache/texel_key.h"

namespace texcache {

/// Outcome of DirectMappedCache::Acquire.
enum class AcquireResult : uint8_t {
    Hit,       ///< payload copied out
    Claimed,   ///< the slot is now ours (busy with our key): Publish or Abandon it
    Pending,   ///< another thread is shading this key: defer, retry later
    Conflict,  ///< the slot is busy with another key: shade without caching
};

/// Proof of a claimed slot, returned by Acquire and consumed by Publish/Abandon.
struct SlotTicket {
    size_t slot = ~size_t(0);
    uint64_t seq = 0;      ///< the odd sequence number we set
    bool evicted = false;  ///< the claim replaced another key's entry
};

__extension__ typedef unsigned __int128 Uint128;  // GCC/Clang: the 64x64->128 multiply

template <typename T>
class DirectMappedCache {
    static_assert(std::is_trivially_copyable_v<T>, "cache payloads are copied word by word");
    static constexpr size_t kWords = (sizeof(T) + 7) / 8;

    struct Slot {
        std::atomic<uint64_t> seq{0};
        std::atomic<uint64_t> key{TexelKey::kEmpty};
        std::atomic<uint64_t> words[kWords];
    };

public:
    /// Bytes one entry costs (the unit of the capacity).
    static constexpr size_t kSlotBytes = sizeof(Slot);

    /// Allocates floor(capacityBytes / kSlotBytes) slots; at least one must fit. With
    /// `threeChoices`, a key may live in one of three slots (its scanline slot, or two hashed
    /// ones): three reads per miss instead of one, far fewer conflict misses when the cache is
    /// full.
    explicit DirectMappedCache(size_t capacityBytes, bool threeChoices = false)
        : threeChoices_(threeChoices),
          numSlots_(std::min<size_t>(capacityBytes / kSlotBytes, size_t(UINT32_MAX))),
          fastmod_(~uint64_t(0) / std::max<uint64_t>(numSlots_, 1) + 1),
          slots_(AllocateSlots(std::max<size_t>(numSlots_, 1)),
                 SlotDeleter{std::max<size_t>(numSlots_, 1)}) {
        if (numSlots_ == 0)
            throw InputError("cache", "a capacity of " + std::to_string(capacityBytes) +
                                          " bytes holds no entry (one entry takes " +
                                          std::to_string(kSlotBytes) + " bytes)");
        for (size_t i = 0; i < numSlots_; ++i)
            for (auto& w : slots_[i].words) w.store(0, std::memory_order_relaxed);
    }

    size_t NumSlots() const { return numSlots_; }
    /// Bytes held by the slot array (never more than the capacity given).
    size_t BytesUsed() const { return numSlots_ * kSlotBytes; }

    /// Slot index: the low 32 bits of `hash` modulo the slot count. Callers use a scanline hash
    /// (face/mip mixed, plus iv * res + iu) so that neighbouring texels never collide with each
    /// other. Lemire's fastmod: a multiply instead of a division on the hit path.
    size_t SlotOf(uint64_t hash) const {
        const uint64_t low = fastmod_ * uint32_t(hash);
        return size_t((static_cast<Uint128>(low) * numSlots_) >> 64);
    }

    /// Looks up `key` in slot SlotOf(hash) (and, with three choices, in its other two): see the
    /// design note for the four outcomes.
    AcquireResult Acquire(uint64_t untagged, uint64_t hash, T* out, SlotTicket* ticket) {
        const uint64_t tag = tag_.load(std::memory_order_relaxed), key = untagged | tag;
        Slot* s1 = &slots_[SlotOf(hash)];
        {
            // Hit in the first slot: touch no other cache line.
            const uint64_t q1 = s1->seq.load(std::memory_order_acquire);
            if (!(q1 & 1)) {
                const uint64_t k1 = s1->key.load(std::memory_order_acquire);
                if (k1 == key && TryRead(*s1, q1, out) == kHit) return AcquireResult::Hit;
                // An idle first slot that holds nothing live: claim it without loading the
                // other slots (the claim below would pick it too). Filling a cold cache, those
                // loads are misses to memory per entry and would be most of Acquire's time.
                // The key may sit in another slot only if this one was emptied after it got
                // there (Abandon, InvalidateIf): then it gets a second copy, see the note.
                uint64_t expected = q1;
                if (threeChoices_ && !Live(k1, tag) &&
                    s1->seq.compare_exchange_strong(expected, q1 + 1, std::memory_order_acq_rel,
                                                    std::memory_order_relaxed)) {
                    s1->key.store(key, std::memory_order_release);
                    ticket->slot = size_t(s1 - slots_.get());
                    ticket->seq = q1 + 1;
                    ticket->evicted = false;
                    return AcquireResult::Claimed;
                }
            }
        }
        Slot* const s[3] = {s1, threeChoices_ ? &slots_[SlotOf(SecondHash(hash))] : s1,
                            threeChoices_ ? &slots_[SlotOf(ThirdHash(hash))] : s1};
        for (;;) {
            uint64_t q[3], k[3];
            for (int i = 0; i < 3; ++i) {
                q[i] = s[i]->seq.load(std::memory_order_acquire);
                k[i] = s[i]->key.load(std::memory_order_acquire);
            }
            int r = kAbsent;
            for (int i = 0; i < 3 && r == kAbsent; ++i)
                if (k[i] == key) r = TryRead(*s[i], q[i], out);
            if (r == kRetry) continue;
            if (r == kHit) return AcquireResult::Hit;
            if (r == kBusy) return AcquireResult::Pending;  // our key, being shaded
            // Absent: claim an idle slot, an empty one first, else the idle one the key's bits
            // pick.
            int victim = -1;
            for (int i = 0; i < 3 && victim < 0; ++i)
                if (!(q[i] & 1) && !Live(k[i], tag)) victim = i;
            for (int n = 0; n < 3 && victim < 0; ++n) {
                const int i = int((key + uint64_t(n)) % 3);
                if (!(q[i] & 1)) victim = i;
            }
            if (victim < 0) return AcquireResult::Conflict;
            uint64_t expected = q[victim];
            if (s[victim]->seq.compare_exchange_weak(expected, q[victim] + 1,
                                                     std::memory_order_acq_rel,
                                                     std::memory_order_relaxed)) {
                s[victim]->key.store(key, std::memory_order_release);
                ticket->slot = size_t(s[victim] - slots_.get());
                ticket->seq = q[victim] + 1;
                ticket->evicted = Live(k[victim], tag);
                return AcquireResult::Claimed;
            }
        }
    }

    /// Read-only lookup: true and the payload on a hit; never claims.
    bool Find(uint64_t untagged, uint64_t hash, T* out) const {
        const uint64_t key = untagged | tag_.load(std::memory_order_relaxed);
        const Slot* const s1 = &slots_[SlotOf(hash)];
        // The other two slots are addressed only when the first does not hold the key: most
        // lookups end in the first (see Prefetch), and their hashes and slot indices are a
        // visible part of a warm frame's lookups. A key in no slot returns at once; only a
        // slot of our key that a writer holds or changes is read again.
        const Slot* s2 = nullptr;
        const Slot* s3 = nullptr;
        for (int attempt = 0; attempt < 4; ++attempt) {
            int r = ReadIfKey(*s1, key, out);
            if (r == kHit) return true;
            bool seen = r != kAbsent;
            if (threeChoices_) {
                if (!s2)
                    s2 = &slots_[SlotOf(SecondHash(hash))], s3 = &slots_[SlotOf(ThirdHash(hash))];
                for (const Slot* s : {s2, s3}) {
                    r = ReadIfKey(*s, key, out);
                    if (r == kHit) return true;
                    seen = seen || r != kAbsent;
                }
            }
            if (!seen) return false;
        }
        return false;
    }

    /// Overwrites the key's first slot with `value` unless another thread holds that slot
    /// (then returns false and stores nothing): for stores that may be dropped, e.g. temporal
    /// history. A seqlock write like Publish; readers never see a torn value.
    bool TryStore(uint64_t untagged, uint64_t hash, const T& value) {
        const uint64_t key = untagged | tag_.load(std::memory_order_relaxed);
        Slot& s = slots_[SlotOf(hash)];
        uint64_t seq = s.seq.load(std::memory_order_acquire);
        if ((seq & 1) || !s.seq.compare_exchange_strong(seq, seq + 1, std::memory_order_acq_rel,
                                                        std::memory_order_relaxed))
            return false;
        s.key.store(key, std::memory_order_release);
        Publish(SlotTicket{size_t(&s - slots_.get()), seq + 1, false}, value);
        return true;
    }

    /// Starts loading the first slot of `hash` into the CPU cache, ahead of an Acquire or Find.
    /// Not the others: most lookups end in the first (a warm frame of `texcache bench cache`
    /// finds most of its texels there, and a cold claim of an empty first slot never reads the
    /// others), and fetching a second line for every texel costs more than it hides
    /// (docs/cache.md, "Prefetching").
    void Prefetch(uint64_t hash) const { PrefetchLine(&slots_[SlotOf(hash)]); }
    /// Prefetch's second step, once the first slot's line has arrived: starts loading the key's
    /// other two slots unless the first holds it. A key in another slot would otherwise cost a
    /// miss to memory in Find (a warm frame's texels that live there are about one in seven).
    void PrefetchOthers(uint64_t untagged, uint64_t hash) const {
        if (!threeChoices_) return;
        const uint64_t key = untagged | tag_.load(std::memory_order_relaxed);
        if (slots_[SlotOf(hash)].key.load(std::memory_order_relaxed) == key) return;
        PrefetchLine(&slots_[SlotOf(SecondHash(hash))]);
        PrefetchLine(&slots_[SlotOf(ThirdHash(hash))]);
    }

    /// Stores the payload of a claimed slot and makes it visible.
    void Publish(const SlotTicket& t, const T& value) {
        Slot& s = slots_[t.slot];
        uint64_t buf[kWords] = {};
        std::memcpy(buf, static_cast<const void*>(&value), sizeof(T));
        for (size_t i = 0; i < kWords; ++i) s.words[i].store(buf[i], std::memory_order_release);
        s.seq.store(t.seq + 1, std::memory_order_release);
    }

    /// Releases a claimed slot empty (e.g. the shader failed).
    void Abandon(const SlotTicket& t) {
        Slot& s = slots_[t.slot];
        s.key.store(TexelKey::kEmpty, std::memory_order_release);
        s.seq.store(t.seq + 1, std::memory_order_release);
    }

    /// Evicts every entry whose key satisfies `pred(key)`; returns how many. Call between frames.
    template <typename Pred>
    size_t InvalidateIf(Pred pred) {
        const uint64_t tag = tag_.load(std::memory_order_relaxed);
        return Sweep([&](uint64_t k) { return Live(k, tag) && pred(k & ~kTagMask); });
    }
    /// Evicts everything: a new tag (see the design note), and a sweep of every slot when the
    /// tags come round again.
    void InvalidateAll() {
        const uint64_t next = ((tag_.load(std::memory_order_relaxed) >> kTagShift) + 1) % kTags;
        if (next == 0) Sweep([](uint64_t k) { return k != TexelKey::kEmpty; });
        tag_.store(next << kTagShift, std::memory_order_relaxed);
    }

private:
    // The slot array is 2 MB-aligned and asks for transparent huge pages: lookups land at random
    // in a table of tens of MB, and with 4 KB pages nearly every one misses the TLB, which
    // software prefetches cannot hide (`texcache bench cache` shows it). The slots take
    // numSlots * kSlotBytes (rounded to a cache line), so the budget holds.
    struct SlotDeleter {
        size_t n;
        void operator()(Slot* p) const {
            for (size_t i = 0; i < n; ++i) p[i].~Slot();
            std::free(p);
        }
    };
    static Slot* AllocateSlots(size_t n) {
        void* mem = AllocateHugePages((n * sizeof(Slot) + 63) / 64 * 64);
        Slot* slots = static_cast<Slot*>(mem);
        for (size_t i = 0; i < n; ++i) new (&slots[i]) Slot();
        return slots;
    }

    enum { kHit, kBusy, kRetry, kAbsent };
    // Seqlock read of a slot whose key matched at sequence `seq`.
    int TryRead(const Slot& s, uint64_t seq, T* out) const {
        if (seq & 1) return kBusy;
        // Acquire loads (rather than relaxed loads + an acquire fence) keep the re-read of seq
        // after the payload, and ThreadSanitizer models them (it ignores fences). Plain moves on
        // x86. Each word goes straight to `out` (which holds garbage if we then return kRetry):
        // staging the words in a local buffer and copying it out lets the compiler reload them
        // with 16-byte loads from 8-byte stores, a store-forwarding stall that dominates this
        // function in a profile (`perf record build/bin/cache_benchmark
        // --benchmark_filter=BM_TexelCacheHit`).
        char* dst = reinterpret_cast<char*>(out);
        for (size_t i = 0; i < kWords; ++i) {
            const uint64_t w = s.words[i].load(std::memory_order_acquire);
            std::memcpy(dst + 8 * i, &w, std::min<size_t>(8, sizeof(T) - 8 * i));
        }
        if (s.seq.load(std::memory_order_relaxed) != seq) return kRetry;  // a writer intervened
        return kHit;
    }
    // TryRead of a slot if it holds `key` (tagged), else kAbsent.
    int ReadIfKey(const Slot& s, uint64_t key, T* out) const {
        const uint64_t seq = s.seq.load(std::memory_order_acquire);
        if (s.key.load(std::memory_order_acquire) != key) return kAbsent;
        return TryRead(s, seq, out);
    }
    // Tags: the top 4 bits of a stored key; 15 of them, since kEmpty's top bits are 0xF.
    static constexpr int kTagShift = 60;
    static constexpr uint64_t kTagMask = uint64_t(0xF) << kTagShift, kTags = 15;
    static_assert(TexelKey::kFaceBits + TexelKey::kMipBits + 2 * TexelKey::kCoordBits <= kTagShift,
                  "packed keys must leave the tag bits free");
    /// Whether a stored key is an entry of the current tag (not empty, not invalidated).
    static bool Live(uint64_t stored, uint64_t tag) {
        return stored != TexelKey::kEmpty && (stored & kTagMask) == tag;
    }
    /// Empties every idle slot whose stored key satisfies `pred`; returns how many.
    template <typename Pred>
    size_t Sweep(Pred pred) {
        size_t n = 0;
        for (size_t i = 0; i < numSlots_; ++i) {
            Slot& s = slots_[i];
            uint64_t seq = s.seq.load(std::memory_order_acquire);
            const uint64_t k = s.key.load(std::memory_order_acquire);
            if ((seq & 1) || !pred(k)) continue;
            if (!s.seq.compare_exchange_strong(seq, seq + 1, std::memory_order_acq_rel)) continue;
            s.key.store(TexelKey::kEmpty, std::memory_order_release);
            s.seq.store(seq + 2, std::memory_order_release);
            ++n;
        }
        return n;
    }

    static uint64_t SecondHash(uint64_t h) {
        h ^= h >> 29, h *= 0xbf58476d1ce4e5b9ull, h ^= h >> 32;
        return h;
    }
    static uint64_t ThirdHash(uint64_t h) { return SecondHash(h ^ 0x9E3779B97F4A7C15ull); }

    bool threeChoices_ = false;
    std::atomic<uint64_t> tag_{0};  ///< the current tag, shifted to the top bits
    size_t numSlots_;
    uint64_t fastmod_;
    std::unique_ptr<Slot[], SlotDeleter> slots_;
};

}  // namespace texcache
