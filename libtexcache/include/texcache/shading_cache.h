// SPDX-License-Identifier: Apache-2.0
// The two-level texture-space shading cache of Munkberg et al. 2016 (Sec. 4-5): a texel cache of
// filtered results over a sample cache of shaded samples, on the Ptex grids of subdivision meshes.
//
// A renderer calls Lookup() at a ray hit with the hit's Ptex face, (u,v) and ray differentials,
// a sample shader and a reconstruction filter (any callables; resolved at compile time, so there is
// no virtual call or allocation per lookup), or TexelAt() first and LookupTexel() later, to
// Prefetch() a batch of texels in between (as texcache's own renderer does):
//   shade(const SampleRequest&) -> Sample      shades one sample at a texel centre
//   filter(const FilterInput<Sample>&) -> Texel  reconstructs the centre texel from its footprint
// See examples/embed_cache for a complete shader in a few dozen lines.
#pragma once
#include <algorithm>
#include <atomic>
#include <bit>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "texcache/direct_mapped_cache.h"
#include "texcache/error.h"
#include "texcache/footprint.h"
#include "texcache/visible_texels.h"

namespace texcache {

/// Settings of a ShadingCache; Validate() rejects impossible values with a clear message.
struct CacheSettings {
    size_t sampleCacheBytes = size_t(64) << 20;
    size_t texelCacheBytes = size_t(64) << 20;
    float lodBias = 0.0f;  ///< added to eq. 1's level (Sec. 6.2 shader LOD)
    bool referenceMode =
        false;  ///< unbounded caches: every sample and texel kept (overshading baseline)
    /// Let a texel live in one of three slots (see direct_mapped_cache.h): a warm frame then
    /// finds nearly all of its texels, where one slot per key loses about one in ten to conflicts
    /// and two lose about one in a thousand (docs/cache.md, "Three choices"); false is the
    /// paper's strictly direct-mapped texel cache.
    bool texelThreeChoices = true;
    /// The same for samples. On by default: in the steady state of a still or slowly moving
    /// view (the preview, an animation, the warm frame of `texcache bench cache`), the texels
    /// that miss need samples shaded frames ago, and direct mapping evicts many of them (a warm
    /// frame of car AO re-shades far fewer samples with more choices: docs/cache.md, "Three
    /// choices"). In an overfull cache it is slightly worse (a little more
    /// overshading at 4096x2304 with 16 MB in `texcache experiment cache-size`). The paper's
    /// cache is direct-mapped.
    bool sampleThreeChoices = true;

    /// Throws InputError naming the setting when a value is out of range.
    void Validate() const {
        constexpr size_t kMaxBytes = size_t(1) << 40;  // 1 TiB: anything larger is a typo
        if (sampleCacheBytes == 0 || sampleCacheBytes > kMaxBytes)
            throw InputError("sample cache size", "must be between 1 byte and 1 TiB, got " +
                                                      std::to_string(sampleCacheBytes) + " bytes");
        if (texelCacheBytes == 0 || texelCacheBytes > kMaxBytes)
            throw InputError("texel cache size", "must be between 1 byte and 1 TiB, got " +
                                                     std::to_string(texelCacheBytes) + " bytes");
        if (!(lodBias >= -float(TexelKey::kMaxMipLevels) &&
              lodBias <= float(TexelKey::kMaxMipLevels)))
            throw InputError(
                "lod bias", "must be within [-16, 16] (the mip chain has at most 16 levels), got " +
                                std::to_string(lodBias));
    }
};

/// Per-thread counters (plain integers: each render thread owns one; merge them at the end).
struct CacheStats {
    uint64_t lookups = 0, texelHits = 0, texelMisses = 0, texelEvictions = 0, texelUncached = 0;
    uint64_t sampleLookups = 0, sampleHits = 0, samplesShaded = 0, sampleEvictions = 0;
    uint64_t deferrals = 0, waits = 0, samplesUncached = 0;
    uint64_t sampleMemoHits = 0;  ///< sample hits served by the thread's tap memo (see Filter)
    /// Footprint taps left out as not visible (RestrictFootprints): per window on the per-texel
    /// path, per tile (the union of a block's windows) on the block path.
    uint64_t tapsUnseen = 0;
    uint64_t texelsPrefiltered = 0;  ///< texels a miss reconstructed besides its own (SampleTile)

    void Merge(const CacheStats& o) {
        lookups += o.lookups, texelHits += o.texelHits, texelMisses += o.texelMisses;
        texelEvictions += o.texelEvictions, texelUncached += o.texelUncached;
        sampleLookups += o.sampleLookups, sampleHits += o.sampleHits;
        samplesShaded += o.samplesShaded, sampleEvictions += o.sampleEvictions;
        deferrals += o.deferrals, waits += o.waits, samplesUncached += o.samplesUncached;
        sampleMemoHits += o.sampleMemoHits, tapsUnseen += o.tapsUnseen;
        texelsPrefiltered += o.texelsPrefiltered;
    }
    double TexelHitRate() const { return lookups ? double(texelHits) / double(lookups) : 0.0; }
};

/// How a Sample is kept in the sample cache. By default as it is; specialise it to store a compact
/// encoding (more samples per byte of cache). Filters, the tap memo and the shader only ever see
/// decoded samples; a freshly shaded sample is used as Decode(Encode(s)) too, so every texel
/// filters the same value whichever thread shaded it.
template <typename Sample>
struct SampleCodec {
    using Stored = Sample;
    static Stored Encode(const Sample& s) { return s; }
    static Sample Decode(const Stored& s) { return s; }
};

/// Where the sample shader is asked to shade: a texel centre of a mesh's Ptex face.
struct SampleRequest {
    int mesh;
    int face;  ///< the mesh's local Ptex face
    int mip;
    float u, v;  ///< texel centre, eq. 2
    TexelKey key;
};

/// A texel's packed key and slot hash (ShadingCache::AddressOf), computed once for the
/// prefetches and the lookup of one texel.
struct TexelAddress {
    uint64_t key = TexelKey::kEmpty;  ///< TexelKey::Pack()
    uint64_t hash = 0;
};

/// A ray hit as the cache sees it.
struct CacheHit {
    int mesh;
    int face;  ///< local Ptex face
    float u, v;
    float dudx, dvdx, dudy, dvdy;  ///< Ptex-space ray differentials per pixel
};

/// What a reconstruction filter gets: the footprint's samples (same order in both spans; the
/// centre texel is `centre`), and the centre's request.
template <typename Sample>
struct FilterInput {
    std::span<const FootprintSample> taps;
    std::span<const Sample> samples;
    int centre;  ///< index of the centre texel in taps/samples (always present)
    SampleRequest request;
};

/// What a block filter gets (see ShadingCache::LookupTexel): the samples of a w x h window of
/// one face grid, row-major, and which of them footprints use (`seen`: the visible texels; the
/// others hold no sample). A filter that also has
///   Texel operator()(const SampleTile<Sample>& tile, int cx, int cy, int radius,
///                    const SampleRequest& texel) const
/// reconstructs texel (cx, cy) of the tile, whose (2r+1)^2 window lies inside the tile, from it;
/// it must return what the FilterInput overload returns for that texel's footprint: the seen
/// taps of the window (and the centre), row by row, those whose mirror is seen too when
/// `symmetric`. A filter may also have
///   P Prepare(const SampleTile<Sample>& tile, int radius) const
/// returning a callable p(cx, cy, texel) with the same results as the tile form, built once per
/// tile (per-tile tables); p may use storage of the thread that stays valid until its next
/// Prepare.
template <typename Sample>
struct SampleTile {
    int w, h;
    const Sample* samples;
    const uint8_t* seen;
    bool symmetric;
    /// Optional (w <= 64): `seen` as bits, bit x of rows[y] and bit w-1-x of reversed[y].
    const uint64_t* rows = nullptr;
    const uint64_t* reversed = nullptr;

    /// Calls f(i, dx, dy) for the taps a footprint of texel (cx, cy) keeps, row by row: i indexes
    /// `samples`, and the tap is seen (the centre always is) and, when `symmetric`, so is its
    /// mirror. With the bit rows, a window row costs a few shifts and one call per kept tap.
    template <typename F>
    void ForEachTap(int cx, int cy, int r, F&& f) const {
        const int c = cy * w + cx;
        if (rows) {
            const int side = 2 * r + 1;
            const uint64_t window = side >= 64 ? ~uint64_t(0) : (uint64_t(1) << side) - 1;
            for (int dy = -r; dy <= r; ++dy) {
                uint64_t m = (rows[cy + dy] >> (cx - r)) & window;
                if (symmetric) m &= reversed[cy - dy] >> (w - 1 - cx - r);
                for (; m; m &= m - 1) {
                    const int dx = std::countr_zero(m) - r;
                    f(c + dy * w + dx, dx, dy);
                }
            }
            return;
        }
        for (int dy = -r; dy <= r; ++dy)
            for (int dx = -r; dx <= r; ++dx) {
                const int i = c + dy * w + dx;
                if (seen[i] && (!symmetric || seen[c - dy * w - dx])) f(i, dx, dy);
            }
    }
};

namespace internal {

/// The block filter of a tile: the filter's Prepare(tile, radius) when it has one, else its tile
/// form called texel by texel.
template <typename Sample, typename FilterFn>
auto PrepareTile(const FilterFn& filter, const SampleTile<Sample>& t, int radius) {
    if constexpr (requires { filter.Prepare(t, radius); })
        return filter.Prepare(t, radius);
    else
        return [&filter, &t, radius](int cx, int cy, const SampleRequest& texel) {
            return filter(t, cx, cy, radius, texel);
        };
}

/// The reference-mode store: unbounded, sharded hash maps under mutexes. Slow on purpose-free
/// paths only; it exists to count how much the bounded caches re-shade.
template <typename T>
class UnboundedCache {
public:
    AcquireResult Acquire(uint64_t key, T* out) {
        Shard& s = shards_[Mix(key) % kShards];
        std::lock_guard<std::mutex> lock(s.m);
        auto [it, inserted] = s.map.try_emplace(key);
        if (inserted) return AcquireResult::Claimed;
        if (!it->second.ready) return AcquireResult::Pending;
        *out = it->second.value;
        return AcquireResult::Hit;
    }
    void Publish(uint64_t key, const T& v) {
        Shard& s = shards_[Mix(key) % kShards];
        std::lock_guard<std::mutex> lock(s.m);
        auto& e = s.map[key];
        e.value = v;
        e.ready = true;
    }
    void Abandon(uint64_t key) {
        Shard& s = shards_[Mix(key) % kShards];
        std::lock_guard<std::mutex> lock(s.m);
        s.map.erase(key);
    }
    template <typename Pred>
    void InvalidateIf(Pred pred) {
        for (Shard& s : shards_) {
            std::lock_guard<std::mutex> lock(s.m);
            std::erase_if(s.map, [&](const auto& kv) { return pred(kv.first); });
        }
    }
    size_t Size() const {
        size_t n = 0;
        for (const Shard& s : shards_) {
            std::lock_guard<std::mutex> lock(s.m);
            n += s.map.size();
        }
        return n;
    }

private:
    static uint64_t Mix(uint64_t x) {
        x ^= x >> 33, x *= 0xff51afd7ed558ccdull, x ^= x >> 33;
        return x;
    }
    static constexpr size_t kShards = 64;
    struct Entry {
        T value{};
        bool ready = false;
    };
    struct Shard {
        mutable std::mutex m;
        std::unordered_map<uint64_t, Entry> map;
    };
    Shard shards_[kShards];
};

/// The per-thread tap memo (see ShadingCache::Filter): the samples this thread fetched last, in a
/// small direct-mapped table tagged with the cache instance and its invalidation epoch.
template <typename Sample>
struct TapMemo {
    /// 2^12 entries: a 64x64-texel window of one face maps to distinct slots, which covers the
    /// union of the footprints of a render tile's texels (8-16 pixels plus a 21x21 footprint).
    static constexpr size_t kEntries = size_t(1) << 12;
    uint64_t owner = 0, epoch = 0;
    uint64_t keys[kEntries];
    Sample values[kEntries];

    void Reset(uint64_t newOwner, uint64_t newEpoch) {
        owner = newOwner, epoch = newEpoch;
        std::fill(std::begin(keys), std::end(keys), TexelKey::kEmpty);
    }
};

inline uint64_t MixFaceMip(uint32_t face, int mip) {
    uint64_t x = (uint64_t(face) << 4) | uint64_t(mip);
    x ^= x >> 31, x *= 0x7fb5d329728ea185ull, x ^= x >> 27, x *= 0x81dadef4bc2dd44dull,
        x ^= x >> 33;
    return x;
}

/// Slot hash of a texel key: scanline order of 4x4-texel blocks (after Munkberg et al.'s
/// scanline texel order): the 16 texels of a block sit in consecutive slots (8 cache lines),
/// blocks of a block row follow each other, and block rows are scattered by an odd multiplier (a
/// power-of-two stride aliased rows onto the same slots of a 2^k-slot cache). Neighbouring pixels
/// and footprint taps then share cache lines instead of each missing to DRAM.
inline uint64_t TexelSlotHash(const TexelKey& k) {
    const uint64_t block = uint64_t(k.iv >> 2) * 2654435761u + uint64_t(k.iu >> 2);
    return MixFaceMip(k.face, k.mip) + block * 16u + uint64_t(k.iv & 3) * 4u + (k.iu & 3);
}

}  // namespace internal

/// The key of the texel of mesh grids `g` a hit maps to: eq. 1 (floored, plus `lodBias`) and
/// eq. 2.
inline TexelKey TexelKeyOfHit(const MeshGrids& g, const CacheHit& h, float lodBias) {
    const int mip = ComputeMip(g.Log2Res(h.face), h.dudx, h.dvdx, h.dudy, h.dvdy, lodBias);
    const int res = g.Res(h.face, mip);
    return {g.FaceOffset() + uint32_t(h.face), uint8_t(mip), uint16_t(QuantizeCoord(h.u, res)),
            uint16_t(QuantizeCoord(h.v, res))};
}

/// The texel of mesh grids `g` a hit maps to, with its centre (TexelKeyOfHit).
inline SampleRequest TexelOfHit(const MeshGrids& g, const CacheHit& h, float lodBias) {
    const TexelKey k = TexelKeyOfHit(g, h, lodBias);
    const int res = g.Res(h.face, k.mip);
    return {h.mesh, h.face, k.mip, TexelCenter(k.iu, res), TexelCenter(k.iv, res), k};
}

template <typename Sample, typename Texel>
class ShadingCache {
    using Codec = SampleCodec<Sample>;
    using Stored = typename Codec::Stored;

public:
    /// Allocates both caches (or the unbounded reference stores), or with `allocate` false
    /// only on Allocate(): a user that may never look anything up (a renderer shading at its
    /// camera hits) registers its meshes and spends no memory on the caches. Throws InputError
    /// on bad settings.
    explicit ShadingCache(const CacheSettings& settings, bool allocate = true)
        : settings_(settings), id_(NextInstanceId()) {
        settings.Validate();
        if (allocate) Allocate();
    }
    /// Allocates both caches if they are not yet (the configured sizes). Not concurrent with
    /// anything else on this cache: call it before the threads that look up start.
    void Allocate() {
        if (Allocated()) return;
        if (settings_.referenceMode) {
            refSamples_ = std::make_unique<internal::UnboundedCache<Stored>>();
            refTexels_ = std::make_unique<internal::UnboundedCache<Texel>>();
        } else {
            samples_ = std::make_unique<DirectMappedCache<Stored>>(settings_.sampleCacheBytes,
                                                                   settings_.sampleThreeChoices);
            texels_ = std::make_unique<DirectMappedCache<Texel>>(settings_.texelCacheBytes,
                                                                 settings_.texelThreeChoices);
        }
    }
    /// Whether the caches are allocated: lookups need them, the read-only queries below
    /// (ContainsTexel, FindTexel, ...) answer "absent" without them.
    bool Allocated() const { return samples_ || refSamples_; }

    /// Registers a mesh with texels of about `texelSize` world units at mip 0; returns its id.
    /// With `topology` (the cage's, e.g. the renderer's or another mesh's of the same cage) the
    /// mesh shares it instead of building its own.
    int AddMesh(const ControlCage& cage, float texelSize,
                std::shared_ptr<const PtexTopology> topology = nullptr) {
        return AppendMeshGrids(meshes_, cage, texelSize, std::move(topology));
    }
    const MeshGrids& Mesh(int mesh) const { return *meshes_[mesh]; }
    int NumMeshes() const { return int(meshes_.size()); }
    const CacheSettings& Settings() const { return settings_; }

    /// The texel a hit maps to: eq. 1 (floored, plus the LOD bias) and eq. 2.
    SampleRequest TexelAt(const CacheHit& h) const {
        return TexelOfHit(*meshes_[h.mesh], h, settings_.lodBias);
    }
    /// TexelAt's key alone, without the texel's centre: for a caller that only marks or finds
    /// texels.
    TexelKey TexelKeyAt(const CacheHit& h) const {
        return TexelKeyOfHit(*meshes_[h.mesh], h, settings_.lodBias);
    }
    /// A texel's packed key and slot hash, for callers that prefetch and find it.
    TexelAddress AddressOf(const TexelKey& k) const { return {k.Pack(), Hash(k)}; }

    /// What TexelAt returned for `key` on mesh `mesh`, rebuilt from the key alone: for
    /// renderers that keep a pass's texel keys (8 bytes) instead of its requests.
    SampleRequest RequestOf(int mesh, const TexelKey& key) const {
        const MeshGrids& g = *meshes_[mesh];
        const int face = int(key.face - g.FaceOffset());
        const int res = g.Res(face, key.mip);
        return {mesh, face, key.mip, TexelCenter(key.iu, res), TexelCenter(key.iv, res), key};
    }

    /// Whether a texel is in the texel cache right now (read-only: never shades, claims or
    /// counts anything), e.g. for a hit/miss heat map. Always false in reference mode.
    bool ContainsTexel(const SampleRequest& texel) const {
        Texel t;
        return texels_ && texels_->Find(texel.key.Pack(), Hash(texel.key), &t);
    }
    /// The texel's value when it is in the texel cache right now (read-only, like ContainsTexel).
    bool FindTexel(const SampleRequest& texel, Texel* out) const {
        return FindTexel(AddressOf(texel.key), out);
    }
    bool FindTexel(const TexelAddress& a, Texel* out) const {
        return texels_ && texels_->Find(a.key, a.hash, out);
    }
    /// Whether a sample is in the sample cache right now (read-only, like ContainsTexel).
    bool ContainsSample(const TexelKey& key) const {
        Stored s;
        return samples_ && samples_->Find(key.Pack(), Hash(key), &s);
    }

    /// Starts fetching a texel's slot into the CPU cache: call it for a batch of texels before
    /// their lookups to overlap the memory latency of a large texel table.
    void Prefetch(const SampleRequest& texel) const { Prefetch(AddressOf(texel.key)); }
    void Prefetch(const TexelAddress& a) const {
        if (texels_) texels_->Prefetch(a.hash);
    }
    /// After a Prefetch has had time to arrive: starts loading the texel's other slots unless
    /// the first holds it, so that a FindTexel ending there finds them in the CPU cache too.
    void PrefetchOtherSlots(const TexelAddress& a) const {
        if (texels_) texels_->PrefetchOthers(a.key, a.hash);
    }

    /// The filtered value at a hit: texel cache hit, or gather + shade missing samples + filter.
    template <typename ShadeFn, typename FilterFn>
    Texel Lookup(const CacheHit& h, int radius, ShadeFn&& shade, FilterFn&& filter, CacheStats& st,
                 FootprintTaps taps = FootprintTaps::VisibleSymmetric) {
        return LookupTexel(TexelAt(h), radius, shade, filter, st, taps);
    }

    /// Lookup() for a texel already addressed with TexelAt().
    template <typename ShadeFn, typename FilterFn>
    Texel LookupTexel(const SampleRequest& centre, int radius, ShadeFn&& shade, FilterFn&& filter,
                      CacheStats& st, FootprintTaps taps = FootprintTaps::VisibleSymmetric) {
        ++st.lookups;
        const uint64_t key = centre.key.Pack();
        const uint64_t hash = Hash(centre.key);
        Texel texel;
        SlotTicket ticket;
        const AcquireResult r = refTexels_ ? refTexels_->Acquire(key, &texel)
                                           : texels_->Acquire(key, hash, &texel, &ticket);
        if (r == AcquireResult::Hit) {
            ++st.texelHits;
            return texel;
        }
        ++st.texelMisses;
        if (r != AcquireResult::Claimed) {
            // Another thread is filtering this texel, or the slot is busy with another key: filter
            // without storing rather than wait (rare; the samples are shared through the cache).
            ++st.texelUncached;
            return Filter(centre, radius, shade, filter, st, taps);
        }
        if (ticket.evicted) ++st.texelEvictions;
        if (!FilterBlock(centre, radius, shade, filter, st, taps, &texel))
            texel = Filter(centre, radius, shade, filter, st, taps);
        if (refTexels_)
            refTexels_->Publish(key, texel);
        else
            texels_->Publish(ticket, texel);
        return texel;
    }

    /// Footprints keep only the taps `visible` contains (and their centre), as each lookup's
    /// FootprintTaps says, or every tap when null: see visible_texels.h. Set it between renders,
    /// never while lookups run; the set must outlive its use. Texels already in the texel cache
    /// keep the value they were filtered with.
    void RestrictFootprints(const VisibleTexels* visible) { visible_ = visible; }

    /// Evicts everything (the scene changed).
    void InvalidateAll() {
        epoch_.fetch_add(1, std::memory_order_relaxed);
        if (refSamples_) {
            refSamples_->InvalidateIf([](uint64_t) { return true; });
            refTexels_->InvalidateIf([](uint64_t) { return true; });
        } else if (samples_) {
            samples_->InvalidateAll();
            texels_->InvalidateAll();
        }
    }
    /// Evicts one mesh's samples and texels (that object was edited).
    void InvalidateMesh(int mesh) { InvalidateKeys(MeshKeys(mesh)); }
    /// Whether a packed sample or texel key lies on cache mesh `mesh`, as a predicate.
    auto MeshKeys(int mesh) const {
        const uint32_t lo = meshes_[mesh]->FaceOffset(),
                       hi = lo + uint32_t(meshes_[mesh]->NumFaces());
        return [lo, hi](uint64_t k) {
            const uint32_t f = TexelKey::Unpack(k).face;
            return f >= lo && f < hi;
        };
    }
    /// Evicts the samples and texels whose packed key satisfies `pred(key)` (one mesh; a part
    /// of the cache re-shaded progressively). Between frames.
    template <typename Pred>
    void InvalidateKeys(Pred pred) {
        epoch_.fetch_add(1, std::memory_order_relaxed);
        if (refSamples_) {
            refSamples_->InvalidateIf(pred);
            refTexels_->InvalidateIf(pred);
        } else if (samples_) {
            samples_->InvalidateIf(pred);
            texels_->InvalidateIf(pred);
        }
    }

    /// Bytes of the tap memo each render thread keeps besides the two caches (see Filter).
    static constexpr size_t kTapMemoBytes = sizeof(internal::TapMemo<Sample>);

    /// Bytes held by the caches' storage (bounded mode: never above the configured budgets;
    /// each thread that filtered also holds one tap memo of kTapMemoBytes).
    size_t BytesUsed() const {
        if (refSamples_)
            return refSamples_->Size() * (sizeof(Stored) + 32) +
                   refTexels_->Size() * (sizeof(Texel) + 32);
        return samples_ ? samples_->BytesUsed() + texels_->BytesUsed() : 0;
    }
    /// Bytes of each cache's storage: 0 until Allocate().
    size_t SampleCacheBytes() const { return samples_ ? samples_->BytesUsed() : 0; }
    size_t TexelCacheBytes() const { return texels_ ? texels_->BytesUsed() : 0; }
    /// Samples the sample cache can hold at once (SIZE_MAX in reference mode: unbounded).
    size_t SampleSlots() const {
        if (settings_.referenceMode) return SIZE_MAX;
        return samples_ ? samples_->NumSlots()
                        : std::min<size_t>(
                              settings_.sampleCacheBytes / DirectMappedCache<Stored>::kSlotBytes,
                              UINT32_MAX);
    }

private:
    uint64_t Hash(const TexelKey& k) const { return internal::TexelSlotHash(k); }

    // Gathers the footprint, shades what is missing (deferring samples other threads are
    // shading, revisiting them after the rest), then filters.
    //
    // The tap memo: texel misses come in runs of neighbours (a render tile's pixels land on
    // adjacent texels), and neighbouring (2r+1)^2 footprints share all but 2r+1 of their taps, so
    // fetching every tap from the shared sample cache (a seqlock read in a table of tens of MB,
    // mostly missing the CPU caches) repeats the same reads hundreds of times. Each thread keeps
    // the samples it fetched last in a small table of its own (no atomics, L2-resident) and only
    // asks the shared cache for the rest. A memo entry is a sample of that key published or
    // shaded in this cache since its last invalidation (the memo is tagged with the cache and its
    // epoch), so it is exactly what the shared cache could have returned.
    template <typename ShadeFn, typename FilterFn>
    Texel Filter(const SampleRequest& centre, int radius, ShadeFn& shade, FilterFn& filter,
                 CacheStats& st, FootprintTaps keep) {
        thread_local std::vector<FootprintSample> taps;
        thread_local std::vector<Sample> values;
        const MeshGrids& g = *meshes_[centre.mesh];
        st.tapsUnseen +=
            uint64_t(GatherFootprint(g, centre.face, centre.mip, centre.key.iu, centre.key.iv,
                                     radius, &taps, keep == FootprintTaps::All ? nullptr : visible_,
                                     keep == FootprintTaps::VisibleSymmetric));
        FetchTaps(centre.mesh, taps, &values, shade, st);
        int centreIndex = 0;
        for (size_t i = 0; i < taps.size(); ++i)
            if (taps[i].key == centre.key) centreIndex = int(i);
        FilterInput<Sample> in{std::span<const FootprintSample>(taps.data(), taps.size()),
                               std::span<const Sample>(values.data(), values.size()), centreIndex,
                               centre};
        return filter(in);
    }

    // The samples of `taps` into `values` (same order): from the tap memo, else the sample cache,
    // shading what is missing (deferring samples other threads are shading, revisiting them after
    // the rest).
    template <typename ShadeFn>
    void FetchTaps(int mesh, const std::vector<FootprintSample>& taps, std::vector<Sample>* out,
                   ShadeFn& shade, CacheStats& st) {
        thread_local std::vector<int> missing, deferred;
        internal::TapMemo<Sample>& memo = ThreadMemo();
        const uint64_t epoch = epoch_.load(std::memory_order_relaxed);
        if (memo.owner != id_ || memo.epoch != epoch) memo.Reset(id_, epoch);
        std::vector<Sample>& values = *out;
        values.resize(taps.size());
        missing.clear();
        deferred.clear();
        // Taps come face by face: the face/mip part of the memo slot is computed once per run.
        uint32_t runFace = ~0u;
        uint8_t runMip = 0xff;
        uint64_t runBase = 0;
        for (size_t i = 0; i < taps.size(); ++i) {
            const TexelKey k = taps[i].key;
            if (k.face != runFace || k.mip != runMip)
                runFace = k.face, runMip = k.mip, runBase = internal::MixFaceMip(k.face, k.mip);
            const size_t m = MemoSlot(runBase, k);
            if (memo.keys[m] == k.Pack()) {
                values[i] = memo.values[m];
                ++st.sampleMemoHits;
                continue;
            }
            missing.push_back(int(i));
            // Start loading the slot: the lookups below then overlap their cache misses.
            if (samples_) samples_->Prefetch(Hash(taps[i].key));
        }
        st.sampleLookups += taps.size() - missing.size();
        st.sampleHits += taps.size() - missing.size();
        auto remember = [&](int i) {
            const TexelKey& k = taps[i].key;
            const size_t m = MemoSlot(internal::MixFaceMip(k.face, k.mip), k);
            memo.keys[m] = taps[i].key.Pack();
            memo.values[m] = values[i];
        };
        for (int i : missing) {
            if (!FetchOrShade(mesh, taps[i], &values[i], shade, st, /*wait=*/false)) {
                deferred.push_back(i);
                ++st.deferrals;
                continue;
            }
            remember(i);
        }
        for (int i : deferred) {
            FetchOrShade(mesh, taps[i], &values[i], shade, st, /*wait=*/true);
            remember(i);
        }
    }

    // Block reconstruction: a miss whose filter takes a SampleTile (see there) reconstructs, from
    // one gather, every visible texel of its 16x16 block (four of the visible set's 8x8 blocks),
    // and puts those nobody holds into the texel cache. Why: neighbouring
    // windows share all but 2r+1 of their taps, and the visible texels of a block are looked up
    // soon (the prepass marked them from this frame's camera rays), so gathering, fetching and
    // testing each window's taps again per texel would be most of a 21x21 render (perf, car AO,
    // `texcache experiment filter-size`). The tile is at most (16 + 2r)^2 samples per thread
    // (r = 10: 1296, 47 KiB with ShadedSample): per texel of the block, 5 tile positions to
    // build, fetch and test, where 8x8 blocks need 12. Past the face's edges the tile reads the
    // face's pad, which gives every window there the taps GatherFootprint gives it; a window
    // holding a texel twice (around extraordinary vertices, beside coarser grids) drops the
    // positions GatherFootprint drops from its own copy of the tile's bit rows, so such windows
    // stay on the block path too (on the car's 21x21 AO they are a large share of the misses).
    // Texels are reconstructed from the samples they would have been filtered with, so their
    // values are the per-texel path's.
    // False when the block path does not apply to the centre: no tile overload, no visible set,
    // reference mode, an unseen centre, or a tile past the face's edges that is wider than 64
    // texels or whose face is too large for a pad.
    template <typename ShadeFn, typename FilterFn>
    bool FilterBlock(const SampleRequest& centre, int radius, ShadeFn& shade, FilterFn& filter,
                     CacheStats& st, FootprintTaps keep, Texel* out) {
        if constexpr (!requires(const SampleTile<Sample>& t) { filter(t, 0, 0, 0, centre); }) {
            return false;
        } else {
            if (!visible_ || keep == FootprintTaps::All || !texels_ || radius <= 0) return false;
            const MeshGrids& g = *meshes_[centre.mesh];
            const int face = centre.face, mip = centre.mip, res = g.Res(face, mip);
            const int iu = centre.key.iu, iv = centre.key.iv;
            if (!visible_->Contains(centre.key)) return false;
            if (IsolatedMiss(centre.key, res)) return false;
            // The block's texels and the tile their windows cover; where it passes the face's
            // edges, the face's pad (footprint.h) continues it as GatherFootprint does.
            // 16x16 blocks while their tiles fit the 64-bit rows (r <= 24), else 8x8.
            const int blockMask = 16 + 2 * radius <= 64 ? 15 : 7;
            const int xlo = iu & ~blockMask, xhi = std::min(iu | blockMask, res - 1);
            const int ylo = iv & ~blockMask, yhi = std::min(iv | blockMask, res - 1);
            const int x0 = xlo - radius, y0 = ylo - radius;
            const int w = xhi - xlo + 1 + 2 * radius, h = yhi - ylo + 1 + 2 * radius;
            const bool padded = x0 < 0 || y0 < 0 || x0 + w > res || y0 + h > res;
            if (padded && (w > 64 || !internal::PaddedRun(g, face, mip, radius, -1, -1)))
                return false;
            thread_local std::vector<FootprintSample> taps;
            thread_local std::vector<Sample> values, tile;
            thread_local std::vector<uint8_t> seen;
            thread_local std::vector<int> at;
            thread_local std::vector<uint64_t> rows, reversed, duplicates;
            thread_local std::vector<int> flagged;  // taps that may hold a texel twice
            taps.clear();
            at.clear();
            flagged.clear();
            seen.assign(size_t(w) * size_t(h), 0);
            tile.resize(seen.size());
            const bool bits = w <= 64;
            rows.assign(size_t(h), 0);
            reversed.assign(size_t(h), 0);
            duplicates.assign(size_t(h), 0);
            bool anyDuplicate = false;
            // Taps are written field by field in place: a FootprintSample built on the stack from
            // narrow stores and copied out with wide loads stalled on store forwarding (half of
            // this function's time in perf annotate, car AO 21x21), and so did a key updated
            // field by field and then read whole.
            auto add = [&](uint32_t kface, uint8_t kmip, uint16_t kiu, uint16_t kiv, float u,
                           float v, int tx, int ty) {
                FootprintSample& s = taps.emplace_back();
                s.key.face = kface, s.key.mip = kmip, s.key.iu = kiu, s.key.iv = kiv;
                s.dx = 0, s.dy = 0, s.u = u, s.v = v;
                at.push_back(ty * w + tx);
                seen[size_t(ty * w + tx)] = 1;
                if (bits) {
                    rows[size_t(ty)] |= uint64_t(1) << tx;
                    reversed[size_t(ty)] |= uint64_t(1) << (w - 1 - tx);
                }
            };
            // The tile's visible texels: inside the face a word of the visible set per 8 texels
            // of a row, outside it the pad's texels, each with its stored probe.
            const float inv = 1.0f / float(res);  // exact: res is a power of two
            const uint32_t gface = centre.key.face;
            const uint8_t gmip = centre.key.mip;
            for (int y = y0; y < y0 + h; ++y) {
                const int ty = y - y0;
                auto padRun = [&](int xa, int xb) {
                    const internal::PaddedTexel* p =
                        internal::PaddedRun(g, face, mip, radius, xa, y);
                    for (int x = xa; x <= xb; ++x, ++p) {
                        if (!(p->flags & internal::PaddedTexel::kReached)) continue;
                        if (!visible_->ContainsAt(p->probe, uint64_t(1) << p->bit)) {
                            ++st.tapsUnseen;
                            continue;
                        }
                        if (p->flags & internal::PaddedTexel::kDuplicate) {
                            duplicates[size_t(ty)] |= uint64_t(1) << (x - x0);
                            flagged.push_back(int(taps.size()));
                            anyDuplicate = true;
                        }
                        const TexelKey pk = TexelKey::Unpack(p->key);
                        add(pk.face, pk.mip, pk.iu, pk.iv, p->u, p->v, x - x0, ty);
                    }
                };
                if (y < 0 || y >= res) {
                    padRun(x0, x0 + w - 1);
                    continue;
                }
                if (x0 < 0) padRun(x0, -1);
                const int a = std::max(x0, 0), b = std::min(x0 + w - 1, res - 1);
                for (int blk = a >> 3; blk <= b >> 3; ++blk) {
                    const TexelKey bk{gface, gmip, uint16_t(blk << 3), uint16_t(y)};
                    uint32_t m = uint32_t(visible_->BlockBits(bk) >> ((y & 7) * 8)) & 0xFFu;
                    const int lo = std::max(a - (blk << 3), 0), hi = std::min(b - (blk << 3), 7);
                    m &= (0xFFu << lo) & (0xFFu >> (7 - hi));
                    st.tapsUnseen += uint64_t(hi - lo + 1 - std::popcount(m));
                    for (; m; m &= m - 1) {
                        const int x = (blk << 3) + std::countr_zero(m);
                        add(gface, gmip, uint16_t(x), uint16_t(y), (float(x) + 0.5f) * inv,
                            (float(y) + 0.5f) * inv, x - x0, ty);
                    }
                }
                if (x0 + w - 1 >= res) padRun(res, x0 + w - 1);
            }
            // A window holding a texel twice keeps it at one position, the closest
            // (GatherFootprint): such windows are reconstructed from bit rows of their own.
            const uint64_t window =
                2 * radius + 1 >= 64 ? ~uint64_t(0) : (uint64_t(1) << (2 * radius + 1)) - 1;
            auto single = [&](int tx, int ty) {
                if (!anyDuplicate) return true;
                for (int j = ty - radius; j <= ty + radius; ++j)
                    if ((duplicates[size_t(j)] >> (tx - radius)) & window) return false;
                return true;
            };
            FetchTaps(centre.mesh, taps, &values, shade, st);
            for (size_t i = 0; i < taps.size(); ++i) tile[size_t(at[i])] = values[i];
            const SampleTile<Sample> t{w,
                                       h,
                                       tile.data(),
                                       seen.data(),
                                       keep == FootprintTaps::VisibleSymmetric,
                                       bits ? rows.data() : nullptr,
                                       bits ? reversed.data() : nullptr};
            const auto prepared = internal::PrepareTile(filter, t, radius);
            // A window holding a texel twice (`single` false): the tile with the positions
            // that lose removed from this window's copy of the bit rows, as GatherFootprint
            // removes them (per texel the smallest |dx| + |dy|, then dx, then dy; a texel of
            // the face that the ring wrapped around to is a candidate at its own position too).
            thread_local std::vector<uint64_t> ownRows, ownReversed;
            thread_local std::vector<uint8_t> ownSeen;
            thread_local std::vector<internal::DuplicateTap> candidates;
            auto deduplicated = [&](int tx, int ty, const SampleRequest& texel) {
                candidates.clear();
                auto inWindow = [&](int dx, int dy) {
                    return std::abs(dx) <= radius && std::abs(dy) <= radius;
                };
                for (const int i : flagged) {
                    const int dx = at[size_t(i)] % w - tx, dy = at[size_t(i)] / w - ty;
                    if (!inWindow(dx, dy)) continue;
                    const TexelKey k = taps[size_t(i)].key;
                    candidates.push_back({k.Pack(), int16_t(dx), int16_t(dy)});
                    if (k.face != gface || k.mip != gmip) continue;
                    const int qx = int(k.iu) - x0, qy = int(k.iv) - y0;  // its twin on the face
                    if (inWindow(qx - tx, qy - ty) && seen[size_t(qy * w + qx)])
                        candidates.push_back({k.Pack(), int16_t(qx - tx), int16_t(qy - ty)});
                }
                ownRows.assign(rows.begin(), rows.end());
                ownReversed.assign(reversed.begin(), reversed.end());
                ownSeen.assign(seen.begin(), seen.end());
                internal::ForEachLosingDuplicate(&candidates, [&](int dx, int dy) {
                    const int x = tx + dx, y = ty + dy;
                    ownRows[size_t(y)] &= ~(uint64_t(1) << x);
                    ownReversed[size_t(y)] &= ~(uint64_t(1) << (w - 1 - x));
                    ownSeen[size_t(y * w + x)] = 0;
                });
                const SampleTile<Sample> own{w,
                                             h,
                                             tile.data(),
                                             ownSeen.data(),
                                             t.symmetric,
                                             ownRows.data(),
                                             ownReversed.data()};
                return filter(own, tx, ty, radius, texel);
            };
            auto reconstruct = [&](int tx, int ty, const SampleRequest& texel) {
                return single(tx, ty) ? prepared(tx, ty, texel) : deduplicated(tx, ty, texel);
            };
            for (int y = ylo; y <= yhi; ++y)
                for (int x = xlo; x <= xhi; ++x) {
                    if ((x == iu && y == iv) || !seen[size_t((y - y0) * w + (x - x0))]) continue;
                    const TexelKey k{gface, gmip, uint16_t(x), uint16_t(y)};
                    const uint64_t key = k.Pack(), hash = Hash(k);
                    Texel texel;
                    SlotTicket ticket;
                    if (texels_->Acquire(key, hash, &texel, &ticket) != AcquireResult::Claimed)
                        continue;  // cached already, or another thread's
                    if (ticket.evicted) ++st.texelEvictions;
                    const SampleRequest r = RequestOf(centre.mesh, k);
                    texels_->Publish(ticket, reconstruct(x - x0, y - y0, r));
                    ++st.texelsPrefiltered;
                }
            *out = reconstruct(iu - x0, iv - y0, centre);
            return true;
        }
    }

    // Whether a miss is isolated: another visible texel of its 2x2 quad is in the texel cache.
    // A block reconstruction (FilterBlock) pays off when the block's other texels are missing
    // too, as in a frame that fills the cache; a miss in a filled block (the few texels a warm
    // frame lost to conflicts) costs its whole tile's gather there, ~5x the per-texel window
    // (hundreds of such misses in a warm frame of `texcache bench cache`). Both paths give the
    // same value (BlockReconstructionGivesThePerTexelValues), so the choice changes the time,
    // never the image.
    bool IsolatedMiss(const TexelKey& k, int res) const {
        for (int q = 1; q < 4; ++q) {
            const int u = int(k.iu) ^ (q & 1), v = int(k.iv) ^ (q >> 1);
            if (u >= res || v >= res) continue;
            const TexelKey n{k.face, k.mip, uint16_t(u), uint16_t(v)};
            Texel t;
            if (visible_->Contains(n) && texels_->Find(n.Pack(), Hash(n), &t)) return true;
        }
        return false;
    }

    // One memo per thread for all caches of this Sample type (whatever their shaders and
    // filters), allocated on the thread's first miss.
    static internal::TapMemo<Sample>& ThreadMemo() {
        thread_local std::unique_ptr<internal::TapMemo<Sample>> memo;
        if (!memo) memo = std::make_unique<internal::TapMemo<Sample>>();
        return *memo;
    }

    // Memo slot of a key: (iu, iv) mod 64 in scanline order, offset by the face and mip, so a
    // 64x64-texel window of one face never collides with itself.
    static size_t MemoSlot(uint64_t faceMipMix, const TexelKey& k) {
        return size_t(faceMipMix + (uint64_t(k.iv & 63) << 6) + uint64_t(k.iu & 63)) &
               (internal::TapMemo<Sample>::kEntries - 1);
    }

    static uint64_t NextInstanceId() {
        static std::atomic<uint64_t> next{1};
        return next.fetch_add(1, std::memory_order_relaxed);
    }

    // Returns false (without a value) when another thread is shading the sample and !wait.
    template <typename ShadeFn>
    bool FetchOrShade(int mesh, const FootprintSample& tap, Sample* out, ShadeFn& shade,
                      CacheStats& st, bool wait) {
        const uint64_t key = tap.key.Pack();
        const uint64_t hash = Hash(tap.key);
        const MeshGrids& g = *meshes_[mesh];
        const int localFace = int(tap.key.face - g.FaceOffset());
        const SampleRequest req{mesh, localFace, tap.key.mip, tap.u, tap.v, tap.key};
        ++st.sampleLookups;
        // Shades the sample as it will be stored (see SampleCodec).
        auto shadeStored = [&](Stored* stored) {
            *stored = Codec::Encode(shade(req));
            *out = Codec::Decode(*stored);
            ++st.samplesShaded;
        };
        for (int spins = 0;; ++spins) {
            SlotTicket ticket;
            Stored stored;
            const AcquireResult r = refSamples_ ? refSamples_->Acquire(key, &stored)
                                                : samples_->Acquire(key, hash, &stored, &ticket);
            switch (r) {
                case AcquireResult::Hit:
                    ++st.sampleHits;
                    *out = Codec::Decode(stored);
                    return true;
                case AcquireResult::Claimed:
                    if (ticket.evicted) ++st.sampleEvictions;
                    shadeStored(&stored);
                    if (refSamples_)
                        refSamples_->Publish(key, stored);
                    else
                        samples_->Publish(ticket, stored);
                    return true;
                case AcquireResult::Conflict:
                    // The slot is busy with an unrelated key: shade for this filter only.
                    shadeStored(&stored);
                    ++st.samplesUncached;
                    return true;
                case AcquireResult::Pending:
                    if (!wait) return false;
                    ++st.waits;
                    if (spins > 1000000) {  // the owner is stuck far longer than any shader takes
                        shadeStored(&stored);
                        ++st.samplesUncached;
                        return true;
                    }
                    std::this_thread::yield();
                    break;
            }
        }
    }

    CacheSettings settings_;
    uint64_t id_;                             ///< tags the tap memos (see Filter)
    std::atomic<uint64_t> epoch_{0};          ///< bumped by every invalidation (see Filter)
    const VisibleTexels* visible_ = nullptr;  ///< see RestrictFootprints
    std::vector<std::unique_ptr<MeshGrids>> meshes_;
    std::unique_ptr<DirectMappedCache<Stored>> samples_;
    std::unique_ptr<DirectMappedCache<Texel>> texels_;
    std::unique_ptr<internal::UnboundedCache<Stored>> refSamples_;
    std::unique_ptr<internal::UnboundedCache<Texel>> refTexels_;
};

}  // namespace texcache
