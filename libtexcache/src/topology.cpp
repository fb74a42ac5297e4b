// SPDX-License-Identifier: Apache-2.0
#include "texcache/topology.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/ptexIndices.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <xmmintrin.h>

#include "osd_refiner.h"
#include "texcache/error.h"

namespace texcache {
namespace Far = OpenSubdiv::Far;
namespace Sdc = OpenSubdiv::Sdc;

namespace internal {

std::unique_ptr<Far::TopologyRefiner> CreateRefiner(const ControlCage& cage, bool withUvs) {
    Far::TopologyDescriptor desc;
    desc.numVertices = cage.numVertices();
    desc.numFaces = cage.numFaces();
    desc.numVertsPerFace = cage.faceVertexCounts.data();
    desc.vertIndicesPerFace = cage.faceVertexIndices.data();
    std::vector<int> creasePairs;
    creasePairs.reserve(cage.creaseEdges.size() * 2);
    for (const auto& e : cage.creaseEdges) creasePairs.insert(creasePairs.end(), {e[0], e[1]});
    desc.numCreases = int(cage.creaseEdges.size());
    desc.creaseVertexIndexPairs = creasePairs.data();
    desc.creaseWeights = cage.creaseWeights.data();
    desc.numCorners = int(cage.cornerVertices.size());
    desc.cornerVertexIndices = cage.cornerVertices.data();
    desc.cornerWeights = cage.cornerWeights.data();
    desc.numHoles = int(cage.holes.size());
    desc.holeIndices = cage.holes.data();
    Far::TopologyDescriptor::FVarChannel uvChannel;
    if (withUvs && !cage.uvs.empty()) {
        uvChannel.numValues = int(cage.uvs.size());
        uvChannel.valueIndices = cage.faceUvIndices.data();
        desc.numFVarChannels = 1;
        desc.fvarChannels = &uvChannel;
    }

    Sdc::Options options;
    // Always explicit: OSD defaults to VTX_BOUNDARY_NONE, which turns every boundary face into a
    // hole.
    switch (cage.boundary) {
        case BoundaryInterpolation::None:
            options.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_NONE);
            break;
        case BoundaryInterpolation::EdgeAndCorner:
            options.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
            break;
        case BoundaryInterpolation::EdgeOnly:
            options.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
            break;
    }
    // Uvs linear along boundaries, as the renderer's Embree geometry pins them
    // (RTC_SUBDIVISION_MODE_PIN_BOUNDARY; ctest -R TessellationAgreesWithEmbreeWhereBothWork).
    if (desc.numFVarChannels > 0)
        options.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_BOUNDARIES);
    using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;
    std::unique_ptr<Far::TopologyRefiner> refiner(
        Factory::Create(desc, Factory::Options(Sdc::SCHEME_CATMARK, options)));
    if (!refiner) throw InputError(cage.sourcePath, "OpenSubdiv rejected the cage topology");
    return refiner;
}

}  // namespace internal

namespace {
// The Ptex edges that cover cage edge `a` (from face vertex a to a+1) of a coarse face, in the
// face's counter-clockwise direction: the quad's edge a, or for an n-gon the first half on
// sub-face a (its edge 0) and the second half on sub-face a+1 (its edge 3).
struct Segment {
    int ptex, edge;
    float start, length;
};
// Whether control point i (row-major in (v, u)) of a regular patch lies outside the boundary
// edges `boundary` (OpenSubdiv's mask: 1 v=0, 2 u=1, 4 v=1, 8 u=0).
bool OutsideBoundary(int boundary, int i) {
    const int iu = i % 4, iv = i / 4;
    return ((boundary & 1) && iv == 0) || ((boundary & 2) && iu == 3) ||
           ((boundary & 4) && iv == 3) || ((boundary & 8) && iu == 0);
}
int SideSegments(int firstPtex, int numVerts, int a, Segment out[2]) {
    if (numVerts == 4) {
        out[0] = {firstPtex, a, 0.0f, 1.0f};
        return 1;
    }
    out[0] = {firstPtex + a, 0, 0.0f, 0.5f};
    out[1] = {firstPtex + (a + 1) % numVerts, 3, 0.5f, 0.5f};
    return 2;
}
}  // namespace

namespace internal {

struct TopologyBuilder {
    static PtexTopology Ptex(const ControlCage& cage, const Far::TopologyRefiner& refiner);
    static RegularPatches Regular(const ControlCage& cage, Far::TopologyRefiner& refiner);
};

PtexTopology TopologyBuilder::Ptex(const ControlCage& cage, const Far::TopologyRefiner& refiner) {
    PtexTopology t;
    Far::PtexIndices ptex(refiner);
    const int nf = cage.numFaces();
    if (uint64_t(ptex.GetNumFaces()) >= PtexTopology::kMaxPtexFaces)
        throw InputError(cage.sourcePath, std::to_string(ptex.GetNumFaces()) +
                                              " Ptex faces exceed the limit of " +
                                              std::to_string(PtexTopology::kMaxPtexFaces - 1));
    t.firstPtex_.resize(nf + 1);
    for (int f = 0; f < nf; ++f) t.firstPtex_[f] = ptex.GetFaceId(f);
    t.firstPtex_[nf] = ptex.GetNumFaces();
    t.ptexToCoarse_.resize(ptex.GetNumFaces());
    for (int f = 0; f < nf; ++f)
        for (int p = t.firstPtex_[f]; p < t.firstPtex_[f + 1]; ++p) t.ptexToCoarse_[p] = f;

    const Far::TopologyLevel& level = refiner.GetLevel(0);
    t.valence_.resize(level.GetNumVertices());
    for (int v = 0; v < level.GetNumVertices(); ++v) t.valence_[v] = level.GetVertexEdges(v).size();
    std::vector<char> hole(nf, 0);
    for (int h : cage.holes)
        if (h >= 0 && h < nf) hole[h] = 1;

    t.links_.assign(size_t(ptex.GetNumFaces()) * 8, PtexTopology::kNoLink);
    // Appends a neighbour segment to edge `edge` of Ptex face `p`.
    auto link = [&](int p, int edge, int nbFace, int nbEdge) {
        uint32_t* w = &t.links_[(size_t(p) * 4 + size_t(edge)) * 2];
        const int j = w[0] == PtexTopology::kNoLink ? 0 : 1;
        w[j] = uint32_t(nbFace) << PtexTopology::kFaceShift |
               (t.IsQuad(t.ptexToCoarse_[p]) ? 0u : PtexTopology::kIsSubFace) |
               (t.IsQuad(t.ptexToCoarse_[nbFace]) ? 0u : PtexTopology::kNeighbourIsSubFace) |
               uint32_t(nbEdge);
    };
    for (int f = 0; f < nf; ++f) {
        if (hole[f]) continue;
        const auto fVerts = level.GetFaceVertices(f);
        const auto fEdges = level.GetFaceEdges(f);
        const int n = fVerts.size();
        const int first = t.firstPtex_[f];
        // Edges inside an n-gon: sub-face i's edge 1 meets sub-face i+1's edge 2.
        if (n != 4) {
            for (int i = 0; i < n; ++i) {
                const int a = first + i, b = first + (i + 1) % n;
                link(a, 1, b, 2);
                link(b, 2, a, 1);
            }
        }
        for (int a = 0; a < n; ++a) {
            const int e = fEdges[a];
            const auto eFaces = level.GetEdgeFaces(e);
            if (eFaces.size() != 2) continue;  // boundary or non-manifold: no neighbour
            const int other = eFaces[0] == f ? 1 : 0;
            const int g = eFaces[other];
            if (g == f || hole[g]) continue;
            const auto gVerts = level.GetFaceVertices(g);
            const int m = gVerts.size();
            // The edge's place in the neighbour from OpenSubdiv rather than a scan of its edges:
            // a scan costs the neighbour's size per edge, the square of a face's size when two
            // large n-gons share their edges.
            const int b = level.GetEdgeFaceLocalIndices(e)[other];
            // Consistently oriented neighbours traverse the shared edge in opposite directions;
            // anything else (non-orientable) is treated as a boundary.
            if (b < 0 || gVerts[b] != fVerts[(a + 1) % n] || gVerts[(b + 1) % m] != fVerts[a])
                continue;
            Segment mine[2], theirs[2];
            const int nm = SideSegments(first, n, a, mine);
            const int nt = SideSegments(t.firstPtex_[g], m, b, theirs);
            for (int i = 0; i < nm; ++i) {
                // Our segment [s, s+l] is [1-s-l, 1-s] in the neighbour's parameter.
                const float lo = 1.0f - mine[i].start - mine[i].length, hi = 1.0f - mine[i].start;
                for (int j = 0; j < nt; ++j) {
                    const float tlo = theirs[j].start, thi = theirs[j].start + theirs[j].length;
                    if (std::min(hi, thi) - std::max(lo, tlo) <= 1e-6f) continue;
                    link(mine[i].ptex, mine[i].edge, theirs[j].ptex, theirs[j].edge);
                }
            }
        }
    }
    return t;
}

}  // namespace internal

PtexTopology::PtexTopology(const ControlCage& cage)
    : PtexTopology(internal::TopologyBuilder::Ptex(cage, *internal::CreateRefiner(cage))) {}

size_t PtexTopology::Bytes() const {
    return (firstPtex_.capacity() + ptexToCoarse_.capacity() + valence_.capacity()) * sizeof(int) +
           links_.capacity() * sizeof(uint32_t);
}

bool PtexTopology::Cross(int ptexFace, int edge, float along, float outside, int* nbFace,
                         float* nbU, float* nbV, int* nbEdge, float* scale) const {
    const EdgeLink& link = Edge(ptexFace, edge);
    if (link.count == 0) return false;
    // To the shared cage edge's parameter, across it, then into the neighbour segment.
    const float t = 1.0f - (link.myStart + std::clamp(along, 0.0f, 1.0f) * link.myLength);
    int j = 0;
    if (link.count == 2 && t > link.segStart[1] - 1e-7f) j = 1;
    if (link.count == 2 && t < link.segStart[0] + link.segLength[0]) j = 0;
    const float s = link.myLength / link.segLength[j];
    const float tn = std::clamp((t - link.segStart[j]) / link.segLength[j], 0.0f, 1.0f);
    *nbFace = link.face[j];
    *nbEdge = link.edge[j];
    *scale = s;
    EdgeToUv(link.edge[j], tn, outside * s, nbU, nbV);
    return true;
}

RegularPatches internal::TopologyBuilder::Regular(const ControlCage& cage,
                                                  Far::TopologyRefiner& refiner) {
    RegularPatches r;
    Far::PtexIndices ptex(refiner);
    r.index_.assign(ptex.GetNumFaces(), -1);
    r.positions_ = cage.positions;
    // Only quads can be regular patches, so only quads are refined and patched: the end caps
    // around an n-gon's centre (valence n) take stencils of n points each, n of them, which on
    // one 2,000-gon cost more than the rest of the scene build.
    std::vector<Far::Index> quads;
    for (int f = 0; f < cage.numFaces(); ++f)
        if (cage.faceVertexCounts[f] == 4) quads.push_back(f);
    if (quads.empty()) return r;  // an empty selection would mean every face to OpenSubdiv
    const Far::ConstIndexArray selected(quads.data(), int(quads.size()));
    // One adaptive level is enough to tell regular faces (depth-0 regular patches) from the rest.
    refiner.RefineAdaptive(Far::TopologyRefiner::AdaptiveOptions(1), selected);
    Far::PatchTableFactory::Options options(1);
    options.endCapType = Far::PatchTableFactory::Options::ENDCAP_BILINEAR_BASIS;
    std::unique_ptr<Far::PatchTable> table(
        Far::PatchTableFactory::Create(refiner, options, selected));
    const int numCoarse = cage.numVertices();
    for (int a = 0; a < table->GetNumPatchArrays(); ++a) {
        if (table->GetPatchArrayDescriptor(a).GetType() != Far::PatchDescriptor::REGULAR) continue;
        r.cvs_.reserve(r.cvs_.size() + size_t(table->GetNumPatches(a)) * 16);
        for (int p = 0; p < table->GetNumPatches(a); ++p) {
            const Far::PatchParam param = table->GetPatchParam(a, p);
            if (param.GetDepth() != 0 || param.NonQuadRoot()) continue;
            const Far::ConstIndexArray cv = table->GetPatchVertices(a, p);
            const int boundary = param.GetBoundary();
            // Control points outside a boundary are not part of the patch: only the others must
            // be coarse vertices.
            bool coarse = cv.size() == 16;
            for (int i = 0; i < cv.size() && coarse; ++i)
                coarse = OutsideBoundary(boundary, i) || (cv[i] >= 0 && cv[i] < numCoarse);
            const int face = param.GetFaceId();
            if (!coarse || face < 0 || face >= int(r.index_.size())) continue;
            if (r.cvs_.size() / 16 >= size_t(1) << 27)
                throw InputError(cage.sourcePath, "more than 2^27 regular patches");
            r.index_[face] = int(r.cvs_.size() / 16) << 4 | boundary;
            for (int i = 0; i < 16; ++i) r.cvs_.push_back(OutsideBoundary(boundary, i) ? 0 : cv[i]);
        }
    }
    r.cvs_.shrink_to_fit();
    return r;
}

RegularPatches::RegularPatches(const ControlCage& cage)
    : RegularPatches(internal::TopologyBuilder::Regular(cage, *internal::CreateRefiner(cage))) {}

CageTopology BuildCageTopology(const ControlCage& cage) {
    auto refiner = internal::CreateRefiner(cage);
    // Ptex ids and adjacency read the base level, so they come before the adaptive refinement.
    PtexTopology ptex = internal::TopologyBuilder::Ptex(cage, *refiner);
    return {std::move(ptex), internal::TopologyBuilder::Regular(cage, *refiner)};
}

size_t RegularPatches::Bytes() const {
    return index_.capacity() * sizeof(int) + cvs_.capacity() * sizeof(int) +
           positions_.capacity() * sizeof(positions_[0]);
}

namespace {
// A point as (x, y, z, 0) in one SSE register: x and y in one 8-byte load (__m64 may alias the
// floats), z in a 4-byte one.
inline __m128 LoadPoint(const std::array<float, 3>& p) {
    const __m128 xy = _mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(p.data()));
    return _mm_movelh_ps(xy, _mm_load_ss(p.data() + 2));
}
// Uniform cubic B-spline basis and its derivative at t.
inline void BSpline(float t, float w[4], float d[4]) {
    const float s = 1.0f - t, t2 = t * t, t3 = t2 * t;
    w[0] = s * s * s / 6.0f;
    w[1] = (3.0f * t3 - 6.0f * t2 + 4.0f) / 6.0f;
    w[2] = (-3.0f * t3 + 3.0f * t2 + 3.0f * t + 1.0f) / 6.0f;
    w[3] = t3 / 6.0f;
    d[0] = -0.5f * s * s;
    d[1] = 1.5f * t2 - 2.0f * t;
    d[2] = -1.5f * t2 + t + 0.5f;
    d[3] = 0.5f * t2;
}
}  // namespace

void RegularPatches::Eval(int ptexFace, float u, float v, float P[3], float dPdu[3],
                          float dPdv[3]) const {
    const int entry = index_[ptexFace], boundary = entry & 15;
    const int* idx = &cvs_[size_t(entry >> 4) * 16];
    // Each point as (x, y, z, 0) in one SSE register, loaded there directly: written to memory
    // as floats and read back as vectors, the points stall on store forwarding (perf puts most
    // of the evaluation on those reads).
    __m128 c[16];
    for (int i = 0; i < 16; ++i) c[i] = LoadPoint(positions_[size_t(idx[i])]);
    if (boundary) {
        // Boundary patches use phantom points mirrored across the boundary (OpenSubdiv's
        // B-spline boundary rule, P0 = 2 P1 - P2), substituted here in the transposed order of
        // OSD's weight adjustment (left, top, right, bottom) so corners come out the same.
        auto mirror = [&](int dst, int p1, int p2) {
            c[dst] = _mm_sub_ps(_mm_mul_ps(_mm_set1_ps(2.0f), c[p1]), c[p2]);
        };
        if (boundary & 8)
            for (int j = 0; j < 4; ++j) mirror(4 * j, 4 * j + 1, 4 * j + 2);
        if (boundary & 4)
            for (int i = 0; i < 4; ++i) mirror(12 + i, 8 + i, 4 + i);
        if (boundary & 2)
            for (int j = 0; j < 4; ++j) mirror(4 * j + 3, 4 * j + 2, 4 * j + 1);
        if (boundary & 1)
            for (int i = 0; i < 4; ++i) mirror(i, 4 + i, 8 + i);
    }
    float wu[4], du[4], wv[4], dv[4];
    BSpline(u, wu, du);
    BSpline(v, wv, dv);
    // The tensor product in two passes: each row of points summed along u (with the basis and
    // with its derivative), then the rows along v: 2 x 16 + 3 x 4 vector multiply-adds over
    // (x, y, z, 0), where weighting each point on its own takes 16 x 3 x 3 scalar ones.
    auto sum4 = [](const float w[4], const __m128* x) {
        __m128 s = _mm_mul_ps(_mm_set1_ps(w[0]), x[0]);
        for (int i = 1; i < 4; ++i) s = _mm_add_ps(s, _mm_mul_ps(_mm_set1_ps(w[i]), x[i]));
        return s;
    };
    __m128 row[4], rowDu[4];
    for (int j = 0; j < 4; ++j) {
        row[j] = sum4(wu, c + 4 * j);
        rowDu[j] = sum4(du, c + 4 * j);
    }
    alignas(16) float sp[4], su[4], sv[4];
    if (P) _mm_store_ps(sp, sum4(wv, row));
    _mm_store_ps(su, sum4(wv, rowDu));
    _mm_store_ps(sv, sum4(dv, row));
    for (int k = 0; k < 3; ++k) {
        if (P) P[k] = sp[k];
        dPdu[k] = su[k], dPdv[k] = sv[k];
    }
}

float RegularPatches::Coverage() const {
    if (index_.empty()) return 0.0f;
    return float(std::count_if(index_.begin(), index_.end(), [](int i) { return i >= 0; })) /
           float(index_.size());
}

std::vector<uint8_t> ComputeFaceResolutions(const ControlCage& cage, const PtexTopology& topo,
                                            float texelSize, int maxLog2) {
    std::vector<uint8_t> res(topo.NumPtexFaces(), 0);
    auto P = [&](int i) { return cage.positions[cage.faceVertexIndices[i]]; };
    auto quadArea = [](const std::array<float, 3>& a, const std::array<float, 3>& b,
                       const std::array<float, 3>& c, const std::array<float, 3>& d) {
        const float d1[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const float d2[3] = {d[0] - b[0], d[1] - b[1], d[2] - b[2]};
        const float x = d1[1] * d2[2] - d1[2] * d2[1], y = d1[2] * d2[0] - d1[0] * d2[2],
                    z = d1[0] * d2[1] - d1[1] * d2[0];
        return 0.5f * std::sqrt(x * x + y * y + z * z);
    };
    int offset = 0;
    for (int f = 0; f < cage.numFaces(); ++f) {
        const int n = cage.faceVertexCounts[f];
        std::vector<float> areas;
        if (n == 4) {
            areas.push_back(quadArea(P(offset), P(offset + 1), P(offset + 2), P(offset + 3)));
        } else {
            std::array<float, 3> c{0, 0, 0};
            for (int i = 0; i < n; ++i)
                for (int k = 0; k < 3; ++k) c[k] += P(offset + i)[k] / float(n);
            auto mid = [&](int i, int j) {
                std::array<float, 3> m;
                for (int k = 0; k < 3; ++k) m[k] = 0.5f * (P(offset + i)[k] + P(offset + j)[k]);
                return m;
            };
            for (int i = 0; i < n; ++i)
                areas.push_back(
                    quadArea(P(offset + i), mid(i, (i + 1) % n), c, mid((i + n - 1) % n, i)));
        }
        for (size_t i = 0; i < areas.size(); ++i) {
            const float side = std::sqrt(areas[i]) / texelSize;
            const float l = side > 1.0f ? std::round(std::log2(side)) : 0.0f;
            res[topo.FirstPtexFace(f) + int(i)] = uint8_t(std::clamp(int(l), 0, maxLog2));
        }
        offset += n;
    }
    return res;
}
PtexTopology::~PtexTopology() = default;
PtexTopology::PtexTopology(PtexTopology&&) noexcept = default;
PtexTopology& PtexTopology::operator=(PtexTopology&&) noexcept = default;

// ---------------------------------------------------------------------------------------------
// LimitSurface: adaptive refinement to isolate irregular features, Gregory end caps, then
// patch-map lookups. All vertices (refined + local points) are precomputed so Eval only gathers.

namespace {

/// The 1-D scheme across a single semi-sharp crease: cubic B-spline subdivision of control
/// points q0..q3 whose vertex q1 is a crease vertex of sharpness s (the crease runs along the
/// other parameter direction). Catmull-Clark's rules on a regular grid are tensor products of
/// 1-D rules, and so are its crease rules when the crease runs straight along a row of the grid
/// (the crease vertex rule is the B-spline vertex rule along the crease and the identity across
/// it; the crease edge rule, the edge rule along and the identity across). So the limit surface
/// of a regular patch with one creased edge is B(u) x C(v), C being this curve. C is subdivided
/// for ceil(s) levels, with the sharp rule at q1 while the sharpness left is >= 1 and OpenSubdiv's
/// blend (weight = the fractional sharpness) below 1; past that, every rule is smooth and the
/// level's points are a uniform B-spline's. `rows` holds those points as weights over q0..q3,
/// at positions -1..2^levels+1 of that level (q1 at 0, q2 at 2^levels).
struct SemiSharpCurve {
    int levels = 0;
    std::vector<std::array<float, 4>> rows;

    explicit SemiSharpCurve(float sharpness) {
        levels = sharpness > 0.0f ? std::min(int(std::ceil(sharpness)), 10) : 0;
        std::vector<std::array<double, 4>> cur(4, std::array<double, 4>{});
        for (int i = 0; i < 4; ++i) cur[size_t(i)][size_t(i)] = 1.0;  // level 0: q0..q3
        for (int k = 0; k < levels; ++k) {
            const double w = std::min(double(sharpness) - k, 1.0);  // sharp rule's weight at q1
            const int n = (1 << (k + 1)) + 3;  // positions -1..2^(k+1)+1; index = position + 1
            std::vector<std::array<double, 4>> next(static_cast<size_t>(n));
            for (int p = -1; p < n - 1; ++p) {
                auto& out = next[size_t(p + 1)];
                const int i = p >= 0 ? p / 2 : -1;  // parent position (edge: its left end)
                for (int c = 0; c < 4; ++c) {
                    if (p & 1) {
                        out[c] = 0.5 * (cur[size_t(i + 1)][c] + cur[size_t(i + 2)][c]);
                    } else {
                        const double smooth = (cur[size_t(i)][c] + 6.0 * cur[size_t(i + 1)][c] +
                                               cur[size_t(i + 2)][c]) /
                                              8.0;
                        out[c] = i == 0 ? (1.0 - w) * smooth + w * cur[1][c] : smooth;
                    }
                }
            }
            cur.swap(next);
        }
        rows.resize(cur.size());
        for (size_t i = 0; i < cur.size(); ++i)
            for (int c = 0; c < 4; ++c) rows[i][c] = float(cur[i][c]);
    }

    /// Weights of q0..q3 for C(x) and dC/dx, x in [0,1] from q1 to q2.
    void Eval(float x, float w[4], float dw[4]) const {
        const int segments = 1 << levels;
        const float y = std::clamp(x, 0.0f, 1.0f) * float(segments);
        const int j = std::min(int(y), segments - 1);
        float b[4], db[4];
        BSpline(y - float(j), b, db);
        for (int c = 0; c < 4; ++c) w[c] = dw[c] = 0.0f;
        for (int m = 0; m < 4; ++m) {
            const auto& r = rows[size_t(j + m)];  // position j - 1 + m
            for (int c = 0; c < 4; ++c) {
                w[c] += b[m] * r[c];
                dw[c] += db[m] * float(segments) * r[c];
            }
        }
    }
};

}  // namespace

struct LimitSurface::Impl {
    std::unique_ptr<Far::PatchTable> patches;
    std::unique_ptr<Far::PatchMap> map;
    std::vector<std::array<float, 3>> points;  // refined vertices, then local points
    std::vector<char> nonQuadPtex;             // per ptex face: belongs to an n-gon
    std::vector<SemiSharpCurve> creases;       // per sharpness of a single-crease patch
    std::vector<int16_t> patchCrease;          // per patch: index in creases, -1 (empty: none)

    /// LimitSurface::Eval, and its derivatives alone when P is null.
    bool Evaluate(int ptexFace, float u, float v, float P[3], float dPdu[3], float dPdv[3]) const;

    /// Basis weights of a single-crease patch (OpenSubdiv's CPU EvaluateBasis ignores the
    /// crease: its PatchParam carries the creased edge as a boundary bit, which it would treat
    /// as a boundary). The 16 points are a regular patch's, row-major in v.
    void SingleCreaseWeights(const Far::PatchParam& param, const SemiSharpCurve& crease, float u,
                             float v, float wP[16], float wDu[16], float wDv[16]) const {
        param.Normalize(u, v);
        // Boundary bit e: edge e of the patch (0: v = 0, 1: u = 1, 2: v = 1, 3: u = 0).
        const int edge = __builtin_ctz(unsigned(param.GetBoundary()));
        const bool acrossV = (edge & 1) == 0, mirrored = edge == 1 || edge == 2;
        float along[4], dAlong[4], across[4], dAcross[4];
        BSpline(acrossV ? u : v, along, dAlong);
        const float x = acrossV ? v : u;
        if (!mirrored) {
            crease.Eval(x, across, dAcross);
        } else {  // the crease at the far row: q0..q3 reversed, x -> 1 - x
            float w[4], dw[4];
            crease.Eval(1.0f - x, w, dw);
            for (int c = 0; c < 4; ++c) {
                across[c] = w[3 - c];
                dAcross[c] = -dw[3 - c];
            }
        }
        const float* su = acrossV ? along : across;
        const float* dsu = acrossV ? dAlong : dAcross;
        const float* sv = acrossV ? across : along;
        const float* dsv = acrossV ? dAcross : dAlong;
        const float scale = float(1 << param.GetDepth());  // as OpenSubdiv's EvaluateBasis
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) {
                wP[4 * i + j] = su[j] * sv[i];
                wDu[4 * i + j] = scale * dsu[j] * sv[i];
                wDv[4 * i + j] = scale * su[j] * dsv[i];
            }
    }
};

LimitSurface::LimitSurface(const ControlCage& cage, int maxIsolationLevel)
    : LimitSurface(cage, maxIsolationLevel, {}) {}

LimitSurface::LimitSurface(const ControlCage& cage, int maxIsolationLevel,
                           const std::vector<int>& cageFaces)
    : impl_(std::make_unique<Impl>()) {
    auto refiner = internal::CreateRefiner(cage);
    for (int f : cageFaces)
        if (f < 0 || f >= cage.numFaces())
            throw InputError(cage.sourcePath, "LimitSurface: cage face " + std::to_string(f) +
                                                  " out of range [0, " +
                                                  std::to_string(cage.numFaces()) + ")");
    // Empty: every face (OpenSubdiv's own default).
    const Far::ConstIndexArray selected(cageFaces.data(), int(cageFaces.size()));
    // Infinitely sharp features are isolated and end-capped, not given OSD's inf-sharp patches:
    // measured, that is what matches Embree on the regression shapes (the inf-sharp patches
    // differ from Embree near sharp extraordinary vertices of the bishop and rook; ctest -R
    // LimitPositionsAgreeWithOpenSubdiv).
    // A regular face with one creased edge is not isolated but becomes one single-crease patch
    // (evaluated by SingleCreaseWeights; an infinitely sharp crease gets the isolation level as
    // its sharpness, the same surface as isolating it): isolating the car's 314 sharpness-6
    // creases to level 6 would take several times the patch memory and OpenSubdiv time
    // (docs/surfaces.md), and deep patches are slower to find. ctest -R SingleCreasePatches.
    Far::PatchTableFactory::Options options(maxIsolationLevel);
    options.endCapType = Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS;
    options.useSingleCreasePatch = true;
    refiner->RefineAdaptive(options.GetRefineAdaptiveOptions(), selected);
    impl_->patches.reset(Far::PatchTableFactory::Create(*refiner, options, selected));
    impl_->map = std::make_unique<Far::PatchMap>(*impl_->patches);
    // Single-crease patches: the regular ones with a non-zero sharpness (every patch has a
    // sharpness index, and OpenSubdiv 3.5 can leave a stale sharpness on an end cap).
    const Far::PatchTable& table = *impl_->patches;
    const std::vector<Far::Index>& sharpnessOf = table.GetSharpnessIndexTable();
    std::vector<int> curveOf(table.GetSharpnessValues().size(), -1);
    for (int a = 0, patch = 0; a < table.GetNumPatchArrays(); ++a)
        for (int i = 0; i < table.GetNumPatches(a); ++i, ++patch) {
            const Far::Index s = sharpnessOf.empty() ? Far::INDEX_INVALID : sharpnessOf[patch];
            // The creased edge is the one boundary bit of its PatchParam (SingleCreaseWeights).
            if (table.GetPatchArrayDescriptor(a).GetType() != Far::PatchDescriptor::REGULAR ||
                s == Far::INDEX_INVALID || !(table.GetSharpnessValues()[s] > 0.0f) ||
                !std::has_single_bit(unsigned(table.GetPatchParamTable()[patch].GetBoundary())))
                continue;
            if (curveOf[s] < 0) {
                curveOf[s] = int(impl_->creases.size());
                impl_->creases.emplace_back(table.GetSharpnessValues()[s]);
            }
            if (impl_->patchCrease.empty())
                impl_->patchCrease.assign(size_t(table.GetNumPatchesTotal()), -1);
            impl_->patchCrease[size_t(patch)] = int16_t(curveOf[s]);
        }

    const int numRefined = refiner->GetNumVerticesTotal();
    // The templated accessor: the untemplated one downcasts StencilTableReal<float> to StencilTable
    // (UBSan flags it in OpenSubdiv's header).
    const Far::StencilTableReal<float>* local = impl_->patches->GetLocalPointStencilTable<float>();
    const int numLocal = local ? local->GetNumStencils() : 0;
    std::vector<internal::OsdVertex> verts(numRefined + numLocal);
    for (int i = 0; i < cage.numVertices(); ++i)
        for (int k = 0; k < 3; ++k) verts[i].p[k] = cage.positions[i][k];
    Far::PrimvarRefiner primvar(*refiner);
    internal::OsdVertex* src = verts.data();
    for (int level = 1; level <= refiner->GetMaxLevel(); ++level) {
        internal::OsdVertex* dst = src + refiner->GetLevel(level - 1).GetNumVertices();
        primvar.Interpolate(level, src, dst);
        src = dst;
    }
    if (local) local->UpdateValues(verts.data(), verts.data() + numRefined);
    impl_->points.resize(verts.size());
    for (size_t i = 0; i < verts.size(); ++i)
        impl_->points[i] = {verts[i].p[0], verts[i].p[1], verts[i].p[2]};

    // Ptex ids as Far::PtexIndices numbers them: one per quad, n per n-gon, in face order.
    for (int n : cage.faceVertexCounts)
        impl_->nonQuadPtex.insert(impl_->nonQuadPtex.end(), n == 4 ? 1 : n, n != 4);
}
LimitSurface::~LimitSurface() = default;

size_t LimitSurface::Bytes() const {
    const Far::PatchTable& t = *impl_->patches;
    const size_t patches = size_t(t.GetNumPatchesTotal());
    // PatchMap: about one quadtree node (16 bytes) and one handle (12 bytes) per patch.
    return impl_->points.capacity() * sizeof(impl_->points[0]) + impl_->nonQuadPtex.capacity() +
           size_t(t.GetNumControlVerticesTotal()) * sizeof(Far::Index) +
           patches * (sizeof(Far::PatchParam) + 28);
}
LimitSurface::LimitSurface(LimitSurface&&) noexcept = default;
LimitSurface& LimitSurface::operator=(LimitSurface&&) noexcept = default;

namespace {
inline void StorePoint(__m128 v, float out[3]) {
    alignas(16) float f[4];
    _mm_store_ps(f, v);
    out[0] = f[0], out[1] = f[1], out[2] = f[2];
}
}  // namespace

// The position's sums only when `P` is given. Each sum is a multiply and an add per
// control point in point order, lane by lane as the scalar loop did (no fused multiply-adds on
// the baseline ISA): the same values bit for bit, three lanes at once.
bool LimitSurface::Impl::Evaluate(int ptexFace, float u, float v, float P[3], float dPdu[3],
                                  float dPdv[3]) const {
    if (ptexFace < 0 || ptexFace >= int(nonQuadPtex.size())) return false;
    const Far::PatchTable::PatchHandle* h = map->FindPatch(ptexFace, u, v);
    if (!h) return false;  // hole
    float wP[20], wDu[20], wDv[20];
    const int crease = patchCrease.empty() ? -1 : patchCrease[size_t(h->patchIndex)];
    if (crease >= 0)
        SingleCreaseWeights(patches->GetPatchParam(*h), creases[size_t(crease)], u, v, wP, wDu,
                            wDv);
    else
        patches->EvaluateBasis(*h, u, v, wP, wDu, wDv);  // wP too: OSD's boundary rule writes it
    Far::ConstIndexArray cvs = patches->GetPatchVertices(*h);
    __m128 sp = _mm_setzero_ps(), su = _mm_setzero_ps(), sv = _mm_setzero_ps();
    for (int i = 0; i < cvs.size(); ++i) {
        const __m128 p = LoadPoint(points[size_t(cvs[i])]);
        if (P) sp = _mm_add_ps(sp, _mm_mul_ps(_mm_set1_ps(wP[i]), p));
        su = _mm_add_ps(su, _mm_mul_ps(_mm_set1_ps(wDu[i]), p));
        sv = _mm_add_ps(sv, _mm_mul_ps(_mm_set1_ps(wDv[i]), p));
    }
    // OSD 3.5 normalizes derivatives on n-gon sub-faces to a domain twice as large as the
    // sub-face's own (u,v) (measured against finite differences: ctest -R
    // OpenSubdivDerivativesMatchFiniteDifferences): bring them to the sub-face.
    if (nonQuadPtex[size_t(ptexFace)]) {
        su = _mm_mul_ps(su, _mm_set1_ps(0.5f));
        sv = _mm_mul_ps(sv, _mm_set1_ps(0.5f));
    }
    if (P) StorePoint(sp, P);
    StorePoint(su, dPdu);
    StorePoint(sv, dPdv);
    return true;
}

bool LimitSurface::Eval(int ptexFace, float u, float v, LimitPoint* out) const {
    LimitPoint r{};
    if (!impl_->Evaluate(ptexFace, u, v, r.P.data(), r.dPdu.data(), r.dPdv.data())) return false;
    *out = r;
    return true;
}

bool LimitSurface::EvalDerivatives(int ptexFace, float u, float v, float dPdu[3],
                                   float dPdv[3]) const {
    return impl_->Evaluate(ptexFace, u, v, nullptr, dPdu, dPdv);
}

}  // namespace texcache
