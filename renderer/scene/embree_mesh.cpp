// SPDX-License-Identifier: Apache-2.0
// A scene mesh as Embree geometry (embree_mesh.h): the cage handed to Embree as its own
// subdivision surface, with OpenSubdiv's patches where rtcInterpolate would be slow, or, for a
// cage Embree cannot take, quads on the limit surface.
//
// Design note: cages Embree cannot take.
//
// Embree 3.13 (Debian) renders a Catmull-Clark cage as its own subdivision geometry, but not
// every valid cage: a face of exactly 16 vertices aborts the process (`Assertion
// 'N<MAX_PATCH_VALENCE' failed`), larger faces and every face around a vertex of valence 65 or
// more silently vanish, and so do the faces around a vertex whose
// faces are large and many (ten 15-gons; probes of Embree alone, FacesBeyondEmbree below; ctest
// -R EmbreeLimits renders each case). OpenSubdiv takes any face size and valence. A mesh with
// any such face is therefore rendered, whole, as quads on its limit surface
// (texcache/limit_tessellation.h): OpenSubdiv refines the cage uniformly (level from the
// tessellation rate, as many segments per quad edge as Embree's grids) and moves every vertex to
// its exact limit position. Why this and not the alternatives:
// - Only part of a mesh cannot be handed over: Embree's patch of a face depends on its
//   neighbours, so the faces next to a removed 16-gon (or marked as a hole: Embree turns hole
//   edges into boundaries) would change shape, and a seam between Embree's grids and our quads
//   only closes if both sample the shared edge identically, which Embree does not promise.
//   One tessellation per mesh has no seam: neighbouring quads share their limit vertices.
// - One level of refinement before Embree would fix large faces (every child is a quad) but not
//   valence: a vertex keeps its valence under refinement. The tessellation handles both.
// The Ptex mapping stays exact: after the first refinement every quad lies in one Ptex face (a
// quad's child j is its quadrant j, an n-gon's child j its sub-face j), so a hit's quad (u,v)
// maps affinely to Ptex (u,v). Shading derivatives (and the cache's surface queries) come from
// OpenSubdiv's patches (LimitSurface) off the regular faces, which keep the bicubic fast path.
// Ptex adjacency and footprints come from the cage alone and do not change. At a power-of-two
// rate the quads are exactly Embree's grid (its grids sample the limit at the same dyadic Ptex
// parameters): on cages both take, the same rays hit within 1e-6 of the diagonal on the same Ptex
// face and (u,v), except where Embree approximates the limit (fractional and infinite
// sharpness; near some of the car's extraordinary vertices and creases, up to 6e-5 of the
// diagonal: ctest -R TessellationAgreesWithEmbree says which cages). Cost: the scene build adds
// OpenSubdiv's refinement and patch table (a fraction of a second for a cage of a few thousand
// faces) and holds every quad up front; rays cost less than on Embree's subdivision geometry on
// cages with many irregular faces (the car's: `texcache preview --geometry`, results/preview.md),
// no more elsewhere. The preview traces every mesh this way unless the quads would be many
// (preview::LimitQuadsFit).
#include "renderer/scene/embree_mesh.h"

#include <cmath>
#include <limits>

#include <tbb/parallel_for.h>

namespace texcache::internal {

namespace {

RTCSubdivisionMode ToEmbree(BoundaryInterpolation b) {
    switch (b) {
        case BoundaryInterpolation::None:
            return RTC_SUBDIVISION_MODE_NO_BOUNDARY;
        // PIN_CORNERS matches OpenSubdiv's EDGE_AND_CORNER to ~3e-6 (ctest -R
        // LimitPositionsAgreeWithOpenSubdiv).
        case BoundaryInterpolation::EdgeAndCorner:
            return RTC_SUBDIVISION_MODE_PIN_CORNERS;
        // SMOOTH_BOUNDARY differs from OpenSubdiv's EDGE_ONLY by up to 2e-3 near valence-2
        // corners, the closest Embree has (ctest -R LimitPositionsAgreeWithOpenSubdiv).
        case BoundaryInterpolation::EdgeOnly:
            return RTC_SUBDIVISION_MODE_SMOOTH_BOUNDARY;
    }
    return RTC_SUBDIVISION_MODE_SMOOTH_BOUNDARY;
}

float ToEmbreeSharpness(float s) {
    // OpenSubdiv treats sharpness >= 10 as infinitely sharp; Embree needs +inf for that.
    return s >= 10.0f ? std::numeric_limits<float>::infinity() : s;
}

void RejectHoleHits(const RTCFilterFunctionNArguments* args) {
    const auto* isHole = static_cast<const uint8_t*>(args->geometryUserPtr);
    for (unsigned i = 0; i < args->N; ++i)
        if (args->valid[i] == -1 && isHole[RTCHitN_primID(args->hit, args->N, i)])
            args->valid[i] = 0;
}

// Embree 3.13's subdivision limits (probes of Embree alone, see the design note at the top):
// a face of 16 vertices aborts the process, larger faces vanish, and so does every face around a
// vertex whose 1-ring holds more than 64 edges or more than 128 vertices (of each face around
// it, the vertices other than itself and one of its two neighbours, which the next face shares;
// plus the far end of a boundary edge: valence 64 quads give 128, ten 15-gons 130).
constexpr int kEmbreeMaxFaceVertices = 15;
constexpr int kEmbreeMaxValence = 64;
constexpr int kEmbreeMaxRingVertices = 128;

/// Isolation level of the patches OffFastPathFaces' faces get.
constexpr int kIrregularPatchLevel = 6;

// OpenSubdiv's patches around a vertex of valence n (an n-gon's centre is one) take end caps whose
// points are stencils of the vertex's whole ring: n^2 weights (a 2,000-gon: 3.5 s and 550 MB, a
// 20,000-gon past 60 s and 12 GB); the faces next to a large face cost about a millisecond and
// 100 KB each (its 2,000 neighbours: 1.9 s, 390 MB). Faces larger than this, faces sharing a
// vertex with one, and faces around a vertex of higher valence are evaluated on the limit
// tessellation's quads instead (FacetFaces), which keeps the cost linear in the cage; the bound
// keeps the quadratic part of the others below a tenth of a second per face.
constexpr int kMaxPatchedFaceSize = 256;
constexpr int kMaxPatchedValence = 256;

/// Tessellation level matching Embree's rate: `rate` segments per quad edge, at least one
/// refinement (so every quad lies in one Ptex face), at most 4 (256 quads per cage quad: the
/// refined topology OpenSubdiv holds while building grows as 4^level).
int LimitTessellationLevel(float rate) {
    return std::clamp(int(std::ceil(std::log2(std::max(rate, 1.0f)))), 1, 4);
}

}  // namespace

size_t FacesBeyondEmbree(const ControlCage& cage, const PtexTopology& topo) {
    std::vector<int> faces(size_t(cage.numVertices()), 0), ring(size_t(cage.numVertices()), 0);
    int offset = 0;
    for (int f = 0; f < cage.numFaces(); ++f) {
        for (int i = 0; i < cage.faceVertexCounts[f]; ++i) {
            const int v = cage.faceVertexIndices[offset + i];
            ++faces[v];
            ring[v] += cage.faceVertexCounts[f] - 2;
        }
        offset += cage.faceVertexCounts[f];
    }
    auto vertexBeyond = [&](int v) {
        const int boundaryEnds = std::max(0, topo.Valence(v) - faces[v]);
        return topo.Valence(v) > kEmbreeMaxValence ||
               ring[v] + boundaryEnds > kEmbreeMaxRingVertices;
    };
    size_t n = 0;
    offset = 0;
    for (int f = 0; f < cage.numFaces(); ++f) {
        const int count = cage.faceVertexCounts[f];
        bool beyond = count > kEmbreeMaxFaceVertices;
        for (int i = 0; i < count && !beyond; ++i)
            beyond = vertexBeyond(cage.faceVertexIndices[offset + i]);
        n += beyond;
        offset += count;
    }
    return n;
}

/// The cage faces whose limit derivatives a hit on Embree's subdivision surface takes from
/// OpenSubdiv's patches (LimitSurface at kIrregularPatchLevel) rather than rtcInterpolate: those
/// off the regular fast path, except holes (never hit) and faces near a crease or corner whose
/// sharpness the patches do not reproduce:
/// - below 1, where the two libraries subdivide differently (tests/ptex_mapping_test.cpp,
///   FractionalCreasesDifferBetweenEmbreeAndOpenSubdiv);
/// - above the isolation level, infinite included: the end caps smooth what sharpness is left
///   (the rook's 7.9 creases: normals 56 degrees off Embree's, which match its positions).
/// A face's patch depends on the vertices of its neighbours, so faces within two rings of such
/// a vertex keep rtcInterpolate.
std::vector<int> OffFastPathFaces(const ControlCage& cage, const PtexTopology& topo,
                                  const RegularPatches& regular) {
    const int numFaces = cage.numFaces();
    auto unmatched = [](float w) {
        return w > 0.0f && (w < 1.0f || w > float(kIrregularPatchLevel));
    };
    std::vector<char> near(size_t(cage.numVertices()), 0);
    for (size_t i = 0; i < cage.creaseEdges.size(); ++i)
        if (unmatched(cage.creaseWeights[i]))
            near[cage.creaseEdges[i][0]] = near[cage.creaseEdges[i][1]] = 1;
    for (size_t i = 0; i < cage.cornerVertices.size(); ++i)
        if (unmatched(cage.cornerWeights[i])) near[cage.cornerVertices[i]] = 1;
    std::vector<size_t> start(size_t(numFaces) + 1, 0);
    for (int f = 0; f < numFaces; ++f) start[f + 1] = start[f] + size_t(cage.faceVertexCounts[f]);
    auto touches = [&](int f, const std::vector<char>& marked) {
        for (size_t i = start[f]; i < start[f + 1]; ++i)
            if (marked[cage.faceVertexIndices[i]]) return true;
        return false;
    };
    for (int ring = 0; ring < 2; ++ring) {  // grow the marked vertices by two face rings
        std::vector<char> grown = near;
        for (int f = 0; f < numFaces; ++f)
            if (touches(f, near))
                for (size_t i = start[f]; i < start[f + 1]; ++i)
                    grown[cage.faceVertexIndices[i]] = 1;
        near.swap(grown);
    }
    std::vector<char> hole(size_t(numFaces), 0);
    for (int h : cage.holes) hole[h] = 1;
    std::vector<int> faces;
    for (int f = 0; f < numFaces; ++f) {
        const bool fast = topo.IsQuad(f) && regular.Has(topo.FirstPtexFace(f));
        if (!fast && !hole[f] && !touches(f, near)) faces.push_back(f);
    }
    return faces;
}

/// mesh->irregular and irregularPart for `faces`: one LimitSurface per run of consecutive faces,
/// built in parallel (OpenSubdiv's refinement is serial, and the build comes before the first
/// ray). The parts depend on the face count only, so the images do not depend on the thread
/// count.
void BuildIrregularPatches(const ControlCage& cage, const std::vector<int>& faces,
                           EmbreeMesh* mesh) {
    if (faces.empty()) return;
    constexpr size_t kMinFacesPerPart = 128, kMaxParts = 8;
    const size_t parts = std::clamp<size_t>(faces.size() / kMinFacesPerPart, 1, kMaxParts);
    std::vector<std::vector<int>> runs(parts);
    for (size_t i = 0; i < faces.size(); ++i) runs[i * parts / faces.size()].push_back(faces[i]);
    mesh->irregular.resize(parts);
    tbb::parallel_for(size_t(0), parts, [&](size_t k) {
        mesh->irregular[k] = std::make_unique<LimitSurface>(cage, kIrregularPatchLevel, runs[k]);
    });
    mesh->irregularPart.assign(size_t(mesh->topo->NumPtexFaces()), EmbreeMesh::kNoPart);
    for (size_t k = 0; k < parts; ++k)
        for (int f : runs[k]) {
            for (int i = mesh->topo->FirstPtexFace(f); i < mesh->topo->FirstPtexFace(f + 1); ++i)
                mesh->irregularPart[size_t(i)] = uint8_t(k);
        }
}

/// The cage as Embree's subdivision surface.
RTCGeometry NewSubdivisionGeometry(RTCDevice device, const ControlCage& cage, float rate,
                                   bool withUv, EmbreeMesh* mesh) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SUBDIVISION);
    // Face sizes and indices are the cage's own arrays, shared rather than copied (20 MB on a
    // 1,000,000-quad cage): validated non-negative ints, bit for bit Embree's UINTs, and the
    // Scene outlives its RenderScene.
    static_assert(sizeof(int) == sizeof(unsigned));
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_FACE, 0, RTC_FORMAT_UINT,
                               cage.faceVertexCounts.data(), 0, sizeof(unsigned),
                               cage.faceVertexCounts.size());
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT,
                               cage.faceVertexIndices.data(), 0, sizeof(unsigned),
                               cage.faceVertexIndices.size());
    // 16-byte stride with w = 0: Embree loads vertices as 4-wide vectors, and garbage in the
    // 4th lane (the buffer's padding after the last vertex) would make rtcInterpolate read
    // uninitialised memory and, at random, reject valid patches.
    auto* pos = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float), cage.positions.size()));
    for (size_t i = 0; i < cage.positions.size(); ++i) {
        for (int k = 0; k < 3; ++k) pos[4 * i + k] = cage.positions[i][k];
        pos[4 * i + 3] = 0.0f;
    }
    if (!cage.creaseEdges.empty()) {
        auto* ce = static_cast<unsigned*>(
            rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_EDGE_CREASE_INDEX, 0, RTC_FORMAT_UINT2,
                                    2 * sizeof(unsigned), cage.creaseEdges.size()));
        auto* cw = static_cast<float*>(
            rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_EDGE_CREASE_WEIGHT, 0, RTC_FORMAT_FLOAT,
                                    sizeof(float), cage.creaseEdges.size()));
        for (size_t i = 0; i < cage.creaseEdges.size(); ++i) {
            ce[2 * i] = unsigned(cage.creaseEdges[i][0]);
            ce[2 * i + 1] = unsigned(cage.creaseEdges[i][1]);
            cw[i] = ToEmbreeSharpness(cage.creaseWeights[i]);
        }
    }
    if (!cage.cornerVertices.empty()) {
        auto* vi = static_cast<unsigned*>(
            rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX_CREASE_INDEX, 0, RTC_FORMAT_UINT,
                                    sizeof(unsigned), cage.cornerVertices.size()));
        auto* vw = static_cast<float*>(
            rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX_CREASE_WEIGHT, 0, RTC_FORMAT_FLOAT,
                                    sizeof(float), cage.cornerVertices.size()));
        for (size_t i = 0; i < cage.cornerVertices.size(); ++i) {
            vi[i] = unsigned(cage.cornerVertices[i]);
            vw[i] = ToEmbreeSharpness(cage.cornerWeights[i]);
        }
    }
    if (!cage.holes.empty()) {
        // OpenSubdiv's holes hide a face but leave its neighbours' limit surface unchanged;
        // Embree's hole buffer turns the hole's edges into boundaries instead, which moves
        // the surface around the hole (by up to 0.5 units on OpenSubdiv's catmark_hole_test1).
        // So keep the face and reject its hits.
        mesh->isHole.assign(cage.faceVertexCounts.size(), 0);
        for (int h : cage.holes) mesh->isHole[h] = 1;
        rtcSetGeometryUserData(g, mesh->isHole.data());
        rtcSetGeometryIntersectFilterFunction(g, RejectHoleHits);
        rtcSetGeometryOccludedFilterFunction(g, RejectHoleHits);
    }
    rtcSetGeometrySubdivisionMode(g, 0, ToEmbree(cage.boundary));
    rtcSetGeometryTessellationRate(g, rate);
    if (withUv) {
        // Face-varying uvs: a second topology (uv indices) with linear boundaries, as OBJ uvs
        // are authored on the cage.
        rtcSetGeometryTopologyCount(g, 2);
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 1, RTC_FORMAT_UINT,
                                   cage.faceUvIndices.data(), 0, sizeof(unsigned),
                                   cage.faceUvIndices.size());
        rtcSetGeometrySubdivisionMode(g, 1, RTC_SUBDIVISION_MODE_PIN_BOUNDARY);
        rtcSetGeometryVertexAttributeCount(g, 1);
        rtcSetGeometryVertexAttributeTopology(g, 0, 1);
        auto* uv = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX_ATTRIBUTE,
                                                               0, RTC_FORMAT_FLOAT2,
                                                               4 * sizeof(float), cage.uvs.size()));
        for (size_t i = 0; i < cage.uvs.size(); ++i) {
            uv[4 * i] = cage.uvs[i][0];
            uv[4 * i + 1] = cage.uvs[i][1];
            uv[4 * i + 2] = uv[4 * i + 3] = 0.0f;
        }
        mesh->hasUv = true;
    }
    return g;
}

/// Per cage face: evaluated on the limit tessellation's quads (too large, or around a vertex of
/// too high a valence, for OpenSubdiv's patches at a linear cost; kMaxPatchedFaceSize).
std::vector<char> FacetFaces(const ControlCage& cage, const PtexTopology& topo) {
    // Vertices of a large face or of too high a valence; then the faces that touch one.
    std::vector<char> marked(size_t(cage.numVertices()), 0);
    for (int v = 0; v < cage.numVertices(); ++v)
        marked[size_t(v)] = topo.Valence(v) > kMaxPatchedValence;
    size_t offset = 0;
    for (int f = 0; f < cage.numFaces(); ++f) {
        const int n = cage.faceVertexCounts[f];
        if (n > kMaxPatchedFaceSize)
            for (int i = 0; i < n; ++i)
                marked[size_t(cage.faceVertexIndices[offset + size_t(i)])] = 1;
        offset += size_t(n);
    }
    std::vector<char> facet(size_t(cage.numFaces()), 0);
    offset = 0;
    for (int f = 0; f < cage.numFaces(); ++f) {
        const int n = cage.faceVertexCounts[f];
        for (int i = 0; i < n && !facet[size_t(f)]; ++i)
            facet[size_t(f)] = marked[size_t(cage.faceVertexIndices[offset + size_t(i)])];
        offset += size_t(n);
    }
    return facet;
}

bool EmbreeMesh::EvalFacet(const PtexCoord& c, float* P, float* du, float* dv) const {
    // The face's quads in the tessellation's order: the quadrant digits, coarsest first.
    const int digits = topo->IsQuad(topo->CoarseFace(c.face)) ? facetLevel : facetLevel - 1;
    const float u = std::clamp(c.u, 0.0f, 1.0f), v = std::clamp(c.v, 0.0f, 1.0f);
    size_t q = size_t(facetQuad[size_t(c.face)]);
    float u0 = 0.0f, v0 = 0.0f, size = 1.0f;
    for (int d = digits - 1; d >= 0; --d) {
        size *= 0.5f;
        const bool right = u >= u0 + size, up = v >= v0 + size;
        const size_t k = up ? (right ? 2 : 3) : (right ? 1 : 0);
        q += k << (2 * d);
        u0 += right ? size : 0.0f;
        v0 += up ? size : 0.0f;
    }
    const float s = std::clamp((u - u0) / size, 0.0f, 1.0f),
                t = std::clamp((v - v0) / size, 0.0f, 1.0f);
    // As Embree parametrizes a quad, so that the point is the one a ray hitting the quad at
    // (s, t) reports: two triangles, (0, 1, 3) below the diagonal and (2, 3, 1) above it.
    const unsigned* idx = quadIndices + 4 * q;
    const bool upper = s + t > 1.0f;
    for (int k = 0; k < 3; ++k) {
        const float p0 = quadPositions[4 * idx[0] + k], p1 = quadPositions[4 * idx[1] + k];
        const float p2 = quadPositions[4 * idx[2] + k], p3 = quadPositions[4 * idx[3] + k];
        if (upper) {
            if (P) P[k] = p2 + (1.0f - s) * (p3 - p2) + (1.0f - t) * (p1 - p2);
            du[k] = (p2 - p3) / size;
            dv[k] = (p2 - p1) / size;
        } else {
            if (P) P[k] = p0 + s * (p1 - p0) + t * (p3 - p0);
            du[k] = (p1 - p0) / size;
            dv[k] = (p3 - p0) / size;
        }
    }
    return true;
}

/// The cage as quads on its limit surface (see the design note at the top).
RTCGeometry NewLimitQuadGeometry(RTCDevice device, const ControlCage& cage, float rate, bool withUv,
                                 EmbreeMesh* mesh) {
    const int level = LimitTessellationLevel(rate);
    LimitTessellation t = TessellateLimitSurface(cage, level, withUv);
    mesh->tessellated = true;
    const std::vector<char> facet = FacetFaces(cage, *mesh->topo);
    std::vector<int> patched;
    for (int f = 0; f < cage.numFaces(); ++f)
        if (!facet[size_t(f)]) patched.push_back(f);
    if (patched.size() == size_t(cage.numFaces()))
        mesh->limit = std::make_unique<LimitSurface>(cage);
    else if (!patched.empty())  // (an empty selection would mean every face to OpenSubdiv)
        mesh->limit = std::make_unique<LimitSurface>(cage, kIrregularPatchLevel, patched);
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_QUAD);
    // 16-byte stride with w = 0, as for the subdivision cage's vertices.
    auto* pos = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float), t.positions.size()));
    for (size_t i = 0; i < t.positions.size(); ++i) {
        for (int k = 0; k < 3; ++k) pos[4 * i + k] = t.positions[i][k];
        pos[4 * i + 3] = 0.0f;
    }
    auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(unsigned), t.quads.size()));
    for (size_t q = 0; q < t.quads.size(); ++q)
        for (int k = 0; k < 4; ++k) idx[4 * q + k] = unsigned(t.quads[q][k]);
    if (patched.size() < size_t(cage.numFaces())) {
        // A face's quads are consecutive, so its first one is where the walk in EvalFacet starts.
        mesh->facetQuad.assign(size_t(mesh->topo->NumPtexFaces()), -1);
        for (size_t q = t.squares.size(); q-- > 0;)
            if (facet[size_t(mesh->topo->CoarseFace(t.squares[q].face))])
                mesh->facetQuad[size_t(t.squares[q].face)] = int(q);
        mesh->facetLevel = level;
        mesh->quadPositions = pos;
        mesh->quadIndices = idx;
    }
    mesh->squares = std::move(t.squares);
    mesh->cornerUvs = std::move(t.cornerUvs);
    mesh->hasUv = !mesh->cornerUvs.empty();
    return g;
}

}  // namespace texcache::internal
