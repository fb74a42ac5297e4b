// SPDX-License-Identifier: Apache-2.0
// Shading grids of a mesh (per-face resolution and mip chain) and the filter footprint: the
// (2r+1)^2 window of samples around a texel, continued across face edges.
#pragma once
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <vector>

#include "texcache/texel_key.h"
#include "texcache/topology.h"
#include "texcache/visible_texels.h"

namespace texcache {

/// The shading grids of one mesh: Ptex topology + a square power-of-two grid per face whose
/// texels have roughly equal world size, each with a mip chain down to 1x1. Global face ids are
/// `faceOffset + ptexFace`, so several meshes can share one cache.
class MeshGrids {
public:
    /// Builds topology and resolutions; throws InputError when the face ids would exceed the key.
    MeshGrids(const ControlCage& cage, float texelSize, uint32_t faceOffset);
    /// The same over a topology already built for `cage` (a renderer's, or another MeshGrids'
    /// of the same cage), shared rather than built again.
    MeshGrids(const ControlCage& cage, float texelSize, uint32_t faceOffset,
              std::shared_ptr<const PtexTopology> topology);

    const PtexTopology& Topology() const { return *topo_; }
    /// The topology, for another MeshGrids or a renderer to share.
    const std::shared_ptr<const PtexTopology>& SharedTopology() const { return topo_; }
    uint32_t FaceOffset() const { return faceOffset_; }
    int NumFaces() const { return topo_->NumPtexFaces(); }
    /// log2 of the face's grid side at mip 0.
    int Log2Res(int face) const { return log2Res_[face]; }
    /// Number of mip levels of a face (mip 0 .. Log2Res).
    int NumLevels(int face) const { return log2Res_[face] + 1; }
    /// Grid side at a mip (levels past the chain clamp to 1).
    int Res(int face, int mip) const { return 1 << std::max(0, log2Res_[face] - mip); }
    /// Clamps a mip to the face's chain.
    int ClampMip(int face, int mip) const { return std::clamp(mip, 0, int(log2Res_[face])); }
    /// Unique per instance (never reused): tags what is derived from these grids, e.g. the
    /// footprint pads GatherFootprint keeps per thread.
    uint64_t Id() const { return id_; }

private:
    std::shared_ptr<const PtexTopology> topo_;
    std::vector<uint8_t> log2Res_;
    uint32_t faceOffset_;
    uint64_t id_;
};

/// Appends grids for `cage` to `meshes`, numbering its faces after the last mesh's (keys hold
/// global face ids), with `topology` shared when given; returns the new mesh's id. The mesh
/// registry of ShadingCache and RecordCache.
inline int AppendMeshGrids(std::vector<std::unique_ptr<MeshGrids>>& meshes, const ControlCage& cage,
                           float texelSize, std::shared_ptr<const PtexTopology> topology) {
    const uint32_t offset =
        meshes.empty() ? 0u : meshes.back()->FaceOffset() + uint32_t(meshes.back()->NumFaces());
    meshes.push_back(topology
                         ? std::make_unique<MeshGrids>(cage, texelSize, offset, std::move(topology))
                         : std::make_unique<MeshGrids>(cage, texelSize, offset));
    return int(meshes.size()) - 1;
}

/// Which taps of a footprint a lookup keeps when the cache has a visibility set
/// (ShadingCache::RestrictFootprints; without one every tap is kept).
enum class FootprintTaps {
    All,               ///< every texel of the window (the paper's footprint)
    Visible,           ///< the visible ones: for filters that model gradients (regression)
    VisibleSymmetric,  ///< the visible ones whose mirror is visible: for averaging filters
};

/// One sample of a footprint: its key, where it sits in its face, and its offset from the
/// footprint's centre texel in centre-texel units.
struct FootprintSample {
    TexelKey key;
    int16_t dx, dy;
    float u, v;  ///< texel centre in its face's (u,v)
};

/// Collects the footprint of radius r around texel (face, mip, iu, iv) into `out` (cleared
/// first; reuse the vector to avoid allocation). Faces are the mesh's local Ptex ids; keys carry
/// global ids. Policy: the window is the (2r+1)^2 block of the face's grid around the texel,
/// continued past the face's edges by its pad: position (x, y) outside the face is the texel
/// reached from the nearest face texel by walking along u first, then along the (possibly
/// rotated) v axis, one texel at a time; crossing an edge lands in the first texel row of the
/// neighbour, whose frame is turned to continue the same direction. With neighbours of the face's
/// grid size that is the texel a walk from the centre reaches; with coarser or finer neighbours
/// taps keep their distance from the face along each axis, whatever the centre. Boundary and
/// non-manifold edges end the walk (that sample is left out). Around extraordinary vertices two
/// positions can hold the same texel; each sample is returned once (at the smallest |dx| + |dy|).
/// Pads are built once per thread, face, mip and radius (see footprint.cpp for their memory
/// bound); faces too large for one are walked from each centre. With `visible`, only
/// the samples it contains are returned (and the centre, always), and with `symmetric` only
/// those whose mirrored offset (-dx, -dy) is returned too (see visible_texels.h): the return
/// value is how many it left out.
int GatherFootprint(const MeshGrids& g, int face, int mip, int iu, int iv, int radius,
                    std::vector<FootprintSample>* out, const VisibleTexels* visible = nullptr,
                    bool symmetric = true);

namespace internal {
/// One position of a face's pad (see footprint.cpp): the texel a footprint reaches there.
struct PaddedTexel {
    static constexpr uint8_t kReached = 1;    ///< else a boundary ended the walk: no texel
    static constexpr uint8_t kDuplicate = 2;  ///< the pad or the face holds this texel elsewhere
    uint64_t key;                             ///< packed TexelKey
    float u, v;                               ///< texel centre in its face
    uint32_t probe;                           ///< VisibleTexels::Probe(key)
    uint8_t bit;                              ///< VisibleTexels::Bit(key), as a bit index
    uint8_t flags;
};
/// The pad texel at (x, y) of (face, mip)'s grid, a position outside the face within `radius`
/// of it; the next positions of row y follow while x stays on the same side of the face. Null
/// when the face has no pad at this radius (too large). Valid until this thread's next call (or
/// GatherFootprint) for another face.
const PaddedTexel* PaddedRun(const MeshGrids& g, int face, int mip, int radius, int x, int y);

/// A window position that may hold the same texel as another position of the window.
struct DuplicateTap {
    uint64_t key;  ///< packed TexelKey
    int16_t dx, dy;
};
/// Sorts `taps` and calls lose(dx, dy) for every position whose texel another position holds
/// too and wins: per texel the smallest |dx| + |dy|, then the smaller dx, then dy (as
/// RemoveDuplicateTexels keeps the closest walk). GatherFootprint and block reconstruction
/// (ShadingCache::FilterBlock) both drop duplicates this way, so they keep the same taps.
template <typename LoseFn>
void ForEachLosingDuplicate(std::vector<DuplicateTap>* taps, LoseFn&& lose) {
    std::sort(taps->begin(), taps->end(), [](const DuplicateTap& p, const DuplicateTap& q) {
        if (p.key != q.key) return p.key < q.key;
        const int dp = std::abs(p.dx) + std::abs(p.dy), dq = std::abs(q.dx) + std::abs(q.dy);
        if (dp != dq) return dp < dq;
        return p.dx != q.dx ? p.dx < q.dx : p.dy < q.dy;
    });
    for (size_t i = 1, winner = 0; i < taps->size(); ++i) {
        const DuplicateTap &d = (*taps)[i], &w = (*taps)[winner];
        if (d.key != w.key)
            winner = i;
        else if (d.dx != w.dx || d.dy != w.dy)
            lose(int(d.dx), int(d.dy));
    }
}

/// GatherFootprint, with `pads` false walking every window from its centre (what faces without a
/// pad get): for tests comparing the two.
int GatherFootprint(const MeshGrids& g, int face, int mip, int iu, int iv, int radius,
                    std::vector<FootprintSample>* out, const VisibleTexels* visible, bool symmetric,
                    bool pads);
}  // namespace internal

}  // namespace texcache
