// SPDX-License-Identifier: Apache-2.0
// Ptex-style face topology of a Catmull-Clark cage: every quad is one Ptex face, every n-gon is
// split into n quad sub-faces with consecutive ids (OpenSubdiv's Far::PtexIndices convention).
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "texcache/cage.h"

namespace texcache {

namespace internal {
struct TopologyBuilder;  // builds the classes below from one OpenSubdiv refiner (topology.cpp)
}

/// Ptex face ids of a control cage. Built once per mesh; immutable and thread-safe afterwards.
class PtexTopology {
public:
    /// Builds the topology with OpenSubdiv; throws InputError for cages OpenSubdiv rejects.
    explicit PtexTopology(const ControlCage& cage);
    ~PtexTopology();
    PtexTopology(PtexTopology&&) noexcept;
    PtexTopology& operator=(PtexTopology&&) noexcept;

    /// Number of Ptex faces (quads count 1, n-gons count n).
    int NumPtexFaces() const { return int(ptexToCoarse_.size()); }
    /// Number of coarse (cage) faces.
    int NumCoarseFaces() const { return int(firstPtex_.size()) - 1; }
    /// First Ptex id of a coarse face; an n-gon's sub-face i has id FirstPtexFace(f) + i.
    int FirstPtexFace(int coarseFace) const { return firstPtex_[coarseFace]; }
    /// True when the coarse face is a quad (one Ptex face, no sub-faces).
    bool IsQuad(int coarseFace) const {
        return firstPtex_[coarseFace + 1] - firstPtex_[coarseFace] == 1;
    }
    /// Coarse face a Ptex face belongs to.
    int CoarseFace(int ptexFace) const { return ptexToCoarse_[ptexFace]; }
    /// Sub-face index within its n-gon (0 for quads).
    int SubFace(int ptexFace) const { return ptexFace - firstPtex_[ptexToCoarse_[ptexFace]]; }

    /// What lies across one edge of a Ptex face. Edges are numbered as in Ptex: 0 (v=0), 1 (u=1),
    /// 2 (v=1), 3 (u=0), counter-clockwise. A quad edge bordering an n-gon meets two sub-faces,
    /// each covering half of it, hence up to two segments.
    struct EdgeLink {
        int8_t count = 0;           ///< 0: boundary or non-manifold edge (no neighbour)
        int8_t edge[2] = {-1, -1};  ///< the neighbours' edge numbers
        int face[2] = {-1, -1};     ///< the neighbours' Ptex ids
        /// Extent of each neighbour segment along the shared cage edge, in the neighbour's own
        /// counter-clockwise parameter (start, length); and of this edge in ours.
        float segStart[2] = {0, 0}, segLength[2] = {1, 1};
        float myStart = 0.0f, myLength = 1.0f;
    };
    /// Adjacency across edge `edge` (0..3) of a Ptex face.
    EdgeLink Edge(int ptexFace, int edge) const {
        EdgeLink l;
        const uint32_t* w = &links_[(size_t(ptexFace) * 4 + size_t(edge)) * 2];
        for (int j = 0; j < 2 && w[j] != kNoLink; ++j) {
            l.count = int8_t(j + 1);
            l.face[j] = int(w[j] >> kFaceShift);
            l.edge[j] = int8_t(w[j] & 3);
            Extent(w[j] & kNeighbourIsSubFace, w[j] & 3, &l.segStart[j], &l.segLength[j]);
            Extent(w[j] & kIsSubFace, edge, &l.myStart, &l.myLength);
        }
        return l;
    }

    /// A point just outside edge `edge` of a Ptex face, at (u,v) in that face's (extended)
    /// parameter, mapped into the neighbour: its face, (u,v), and the neighbour edge crossed.
    /// False at boundaries. `outside` > 0 is how far beyond the edge the point is.
    bool Cross(int ptexFace, int edge, float along, float outside, int* nbFace, float* nbU,
               float* nbV, int* nbEdge, float* scale) const;

    /// True when some Ptex edge has no neighbour (an open boundary, a hole or a non-manifold
    /// edge): such surfaces can be seen from both sides.
    bool HasBoundary() const {
        for (size_t i = 0; i < links_.size(); i += 2)
            if (links_[i] == kNoLink) return true;
        return false;
    }

    /// Valence of each coarse vertex (for tests and corner policies).
    int Valence(int vertex) const { return valence_[vertex]; }
    /// Bytes held (the Ptex adjacency takes 32 per Ptex face; see links_).
    size_t Bytes() const;

private:
    friend struct internal::TopologyBuilder;
    PtexTopology() = default;

    // An n-gon's sub-face covers the first half of the cage edge on its edge 0 and the second
    // half on its edge 3; its edges 1 and 2 lie inside the n-gon. Every other Ptex edge is one
    // whole cage edge. So the segment extents follow from two bits, and are not stored.
    static void Extent(bool subFace, int edge, float* start, float* length) {
        *start = subFace && edge == 3 ? 0.5f : 0.0f;
        *length = subFace && (edge == 0 || edge == 3) ? 0.5f : 1.0f;
    }

    // Adjacency, packed (a 1,000,000-quad cage holds 32 MB here, where whole EdgeLinks would
    // take 144 MB): two words per Ptex edge, one per neighbour segment, kNoLink when absent. A word
    // is the neighbour's Ptex id << kFaceShift | kIsSubFace (this face is an n-gon sub-face)
    // | kNeighbourIsSubFace | the neighbour's edge (2 bits).
    static constexpr uint32_t kNoLink = ~uint32_t(0);
    static constexpr int kFaceShift = 4;
    static constexpr uint32_t kIsSubFace = 8, kNeighbourIsSubFace = 4;
    /// Ptex faces a topology can hold (the packed words' face bits; TexelKey takes as many).
    static constexpr uint32_t kMaxPtexFaces = uint32_t(1) << (32 - kFaceShift);

    std::vector<int> firstPtex_;     // size numCoarseFaces + 1
    std::vector<int> ptexToCoarse_;  // size numPtexFaces
    std::vector<uint32_t> links_;    // 8 per Ptex face (see above)
    std::vector<int> valence_;
};

/// Point on edge `edge` of a unit face at counter-clockwise parameter `along`, `inward` into the
/// face (negative: outside): the face's (u,v).
inline void EdgeToUv(int edge, float along, float inward, float* u, float* v) {
    switch (edge & 3) {
        case 0:
            *u = along, *v = inward;
            break;
        case 1:
            *u = 1.0f - inward, *v = along;
            break;
        case 2:
            *u = 1.0f - along, *v = 1.0f - inward;
            break;
        default:
            *u = inward, *v = 1.0f - along;
            break;
    }
}
/// Inverse of EdgeToUv.
inline void UvToEdge(int edge, float u, float v, float* along, float* inward) {
    switch (edge & 3) {
        case 0:
            *along = u, *inward = v;
            break;
        case 1:
            *along = v, *inward = 1.0f - u;
            break;
        case 2:
            *along = 1.0f - u, *inward = 1.0f - v;
            break;
        default:
            *along = 1.0f - v, *inward = u;
            break;
    }
}

/// Fast limit evaluation for the Ptex faces whose limit surface is one regular bicubic B-spline
/// patch with no crease (interior or boundary; most faces of a typical cage): tens of
/// nanoseconds, a fraction of a general patch evaluation (`texcache bench rays` shows it in the
/// whole frame). Other faces report Has() == false and need a general evaluator.
/// Immutable.
class RegularPatches {
public:
    /// Finds the regular interior faces with OpenSubdiv and keeps their 16 control points.
    explicit RegularPatches(const ControlCage& cage);
    /// True when `ptexFace` has a regular patch here.
    bool Has(int ptexFace) const { return index_[ptexFace] >= 0; }
    /// Limit position and Ptex-space derivatives (object space); only valid when Has(ptexFace).
    /// P may be null: only the derivatives (what a ray hit needs).
    void Eval(int ptexFace, float u, float v, float P[3], float dPdu[3], float dPdv[3]) const;
    /// Fraction of Ptex faces with a regular patch.
    float Coverage() const;
    /// Bytes held: 64 per patch, 4 per Ptex face, 12 per cage vertex.
    size_t Bytes() const;

private:
    friend struct internal::TopologyBuilder;
    RegularPatches() = default;

    // Per Ptex face: patch index << 4 | the patch's boundary edges (OpenSubdiv's mask), or -1.
    std::vector<int> index_;
    // 16 cage vertex indices per patch, row-major in (v, u); 0 for the points outside a
    // boundary, which Eval mirrors from the inside. Indices, not the points themselves: 64
    // bytes per patch instead of 192 (a 1,000,000-quad cage: 64 MB, not 192 MB).
    std::vector<int> cvs_;
    std::vector<std::array<float, 3>> positions_;  // the cage's
};

/// A cage's PtexTopology and RegularPatches from one OpenSubdiv refiner: constructing each on
/// its own builds the refiner twice (a 1,000,000-quad torus: 1.5-1.9 s against 1.16 s; the peak
/// is the same, ~310 MB above the cage, as one refiner lives at a time).
struct CageTopology {
    PtexTopology ptex;
    RegularPatches regular;
};
/// Builds both; throws InputError for cages OpenSubdiv rejects.
CageTopology BuildCageTopology(const ControlCage& cage);

/// Per-Ptex-face base shading resolution (log2 of the grid side at mip 0), chosen so texels have
/// about `texelSize` world size: side = 2^round(log2(sqrt(area) / texelSize)), clamped to
/// [0, maxLog2]. Areas come from the cage (sub-face quads for n-gons).
std::vector<uint8_t> ComputeFaceResolutions(const ControlCage& cage, const PtexTopology& topo,
                                            float texelSize, int maxLog2 = 13);

/// A point on the limit surface with its derivatives in Ptex (u,v) of the face it lies on.
struct LimitPoint {
    std::array<float, 3> P, dPdu, dPdv;
};

/// Reference limit-surface evaluator built on OpenSubdiv Far (adaptive refinement + patch table).
/// Independent of any ray tracer: renderers with their own intersector, and tests of the Embree
/// path, query (ptex face, u, v) here. Thread-safe for concurrent Eval calls.
class LimitSurface {
public:
    /// Builds patches for the cage (positions are copied); throws InputError on bad topology.
    explicit LimitSurface(const ControlCage& cage, int maxIsolationLevel = 6);
    /// The same, with patches for the listed cage faces only (their Ptex faces): Eval returns
    /// false on the others. Refinement, patches and memory are those of the listed faces (a
    /// renderer evaluating only the faces its fast path leaves out).
    LimitSurface(const ControlCage& cage, int maxIsolationLevel, const std::vector<int>& cageFaces);
    ~LimitSurface();
    LimitSurface(LimitSurface&&) noexcept;
    LimitSurface& operator=(LimitSurface&&) noexcept;

    /// Limit position and derivatives at (u,v) in [0,1]^2 of a Ptex face; derivatives are with
    /// respect to that face's own (u,v), also on n-gon sub-faces. False for holes/invalid faces.
    bool Eval(int ptexFace, float u, float v, LimitPoint* out) const;
    /// Eval's derivatives alone (what a ray hit needs: its point comes from the ray), the same
    /// values bit for bit, without the position's weights and sums.
    bool EvalDerivatives(int ptexFace, float u, float v, float dPdu[3], float dPdv[3]) const;
    /// Bytes held (points, patch vertices and parameters; the patch map's tree estimated).
    size_t Bytes() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace texcache
