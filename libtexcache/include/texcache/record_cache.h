// SPDX-License-Identifier: Apache-2.0
// A texture-space cache of records: one value of any trivially copyable type per texel, built
// on demand by a callback and shared by every hit that maps to that texel (Munkberg et al. 2016,
// Sec. 6, "Cached Product Importance Sampling": a product sampling record per texel, kilobytes
// rather than a colour). The same grids, keys, LOD selection (eq. 1, 2) and lock-free slots as
// ShadingCache's texel cache, without the sample level and the filter: a record is used as built.
//
// Threading: as DirectMappedCache (a seqlock per slot): a lookup copies the record out, so a
// record being replaced by another thread is never read torn. A key whose slot another thread
// holds is built again for this lookup and not stored (counted as `uncached`).
// Memory: exactly the slot array, floor(capacity / kSlotBytes) records; nothing per lookup.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "texcache/shading_cache.h"

namespace texcache {

/// Per-thread counters of a RecordCache (merge them at the end).
struct RecordStats {
    uint64_t lookups = 0, hits = 0, built = 0, uncached = 0, evictions = 0;
    void Merge(const RecordStats& o) {
        lookups += o.lookups, hits += o.hits, built += o.built, uncached += o.uncached;
        evictions += o.evictions;
    }
};

template <typename Record>
class RecordCache {
public:
    /// Bytes one record costs in the cache (its slot: the record plus 16 bytes of key/sequence).
    static constexpr size_t kSlotBytes = DirectMappedCache<Record>::kSlotBytes;

    /// Allocates floor(capacityBytes / kSlotBytes) slots (throws InputError when none fits);
    /// `threeChoices` as in CacheSettings.
    explicit RecordCache(size_t capacityBytes, bool threeChoices = true)
        : slots_(capacityBytes, threeChoices) {}

    /// Registers a mesh with texels of about `texelSize` world units at mip 0 (its Ptex
    /// topology shared when given, as ShadingCache::AddMesh); returns its id.
    int AddMesh(const ControlCage& cage, float texelSize,
                std::shared_ptr<const PtexTopology> topology = nullptr) {
        return AppendMeshGrids(meshes_, cage, texelSize, std::move(topology));
    }
    const MeshGrids& Mesh(int mesh) const { return *meshes_[mesh]; }

    /// The texel a hit maps to at eq. 1's level plus `lodBias` (coarser for records that stay
    /// valid over a larger area).
    SampleRequest TexelAt(const CacheHit& h, float lodBias) const {
        return TexelOfHit(*meshes_[h.mesh], h, lodBias);
    }

    /// Copies the texel's record into `out`, building it first with `build(texel, Record*)` when
    /// it is not cached. `build` must not throw (a claimed slot would stay busy).
    template <typename BuildFn>
    void Lookup(const SampleRequest& texel, BuildFn&& build, Record* out, RecordStats& st) {
        ++st.lookups;
        SlotTicket ticket;
        const uint64_t key = texel.key.Pack();
        switch (slots_.Acquire(key, internal::TexelSlotHash(texel.key), out, &ticket)) {
            case AcquireResult::Hit:
                ++st.hits;
                return;
            case AcquireResult::Claimed:
                if (ticket.evicted) ++st.evictions;
                build(texel, out);
                ++st.built;
                slots_.Publish(ticket, *out);
                return;
            case AcquireResult::Pending:
            case AcquireResult::Conflict:
                build(texel, out);
                ++st.built, ++st.uncached;
                return;
        }
    }

    /// Bytes of the slot array (never above the capacity given).
    size_t BytesUsed() const { return slots_.BytesUsed(); }
    size_t Capacity() const { return slots_.NumSlots(); }
    /// Evicts every record (the scene or the view changed).
    void InvalidateAll() { slots_.InvalidateAll(); }

private:
    DirectMappedCache<Record> slots_;
    std::vector<std::unique_ptr<MeshGrids>> meshes_;
};

}  // namespace texcache
