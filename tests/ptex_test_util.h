// SPDX-License-Identifier: Apache-2.0
// Helpers for the Ptex tests: the bundled Ptex sets, Ptex face info from the project's cage
// topology, and points on a cage's (bilinear) Ptex faces.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "test_util.h"
#include "texcache/ptex/texture.h"
#include "texcache/topology.h"

namespace texcache::test {

inline std::string PtexPath(const std::string& rel) {
    return SceneDir() + "/ptex/" + rel;
}

/// The face across edge `e` of a Ptex face as a Ptex file records it: where the edge meets two
/// n-gon sub-faces, the one covering the first half of this edge (the first met going
/// counter-clockwise round this face). {-1, 0} at a boundary.
inline std::array<int, 2> FileNeighbour(const PtexTopology& topo, int face, int e) {
    const PtexTopology::EdgeLink l = topo.Edge(face, e);
    if (l.count == 0) return {-1, 0};
    int j = 0;
    // Our parameter runs the shared cage edge the other way: a segment covers our first half
    // when its middle lies in the second half of its own parameter.
    if (l.count == 2 && l.segStart[1] + 0.5f * l.segLength[1] > 0.5f) j = 1;
    return {l.face[j], l.edge[j]};
}

/// Ptex face info (adjacency, sub-face flag, a resolution) of every Ptex face of a topology:
/// what a writer of textures for this cage stores.
inline std::vector<ptex::FaceInfo> PtexFaces(const PtexTopology& topo, ptex::Res quadRes,
                                             ptex::Res subfaceRes) {
    std::vector<ptex::FaceInfo> faces(size_t(topo.NumPtexFaces()));
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        ptex::FaceInfo& fi = faces[size_t(f)];
        fi.subface = !topo.IsQuad(topo.CoarseFace(f));
        fi.res = fi.subface ? subfaceRes : quadRes;
        for (int e = 0; e < 4; ++e) {
            const std::array<int, 2> n = FileNeighbour(topo, f, e);
            fi.adjFaces[size_t(e)] = n[0];
            fi.adjEdges[size_t(e)] = uint8_t(n[1]);
        }
    }
    return faces;
}

/// The point `along` edge `e` of face `f` (counter-clockwise parameter) seen from the face
/// across that edge, `inward` into it: returns that face and sets its (u, v). From a sub-face
/// to a quad the point lies on the half of the quad's edge the sub-face covers (the first
/// half when the quad names this sub-face). Call it from the sub-face side of such an edge.
inline int AcrossEdge(const ptex::Texture& t, int f, int e, float along, float inward, float* u,
                      float* v) {
    const ptex::FaceInfo& fi = t.Face(f);
    const int n = fi.adjFaces[size_t(e)], ne = fi.adjEdges[size_t(e)];
    float nAlong = 1 - along;
    if (fi.subface && !t.Face(n).subface)
        nAlong = t.Face(n).adjFaces[size_t(ne)] == f ? 0.5f * (1 - along) : 1 - 0.5f * along;
    EdgeToUv(ne, nAlong, inward, u, v);
    return n;
}

/// Point (u, v) of a Ptex face on the cage itself: the quad's bilinear patch, or for sub-face
/// i of an n-gon the quad (corner i, middle of the edge after it, centroid, middle of the edge
/// before it).
inline std::array<float, 3> CagePoint(const ControlCage& cage, const PtexTopology& topo, int face,
                                      float u, float v) {
    const int coarse = topo.CoarseFace(face);
    int first = 0;
    for (int c = 0; c < coarse; ++c) first += cage.faceVertexCounts[size_t(c)];
    const int n = cage.faceVertexCounts[size_t(coarse)];
    auto P = [&](int i) {
        return cage.positions[size_t(cage.faceVertexIndices[size_t(first + ((i % n) + n) % n)])];
    };
    std::array<std::array<float, 3>, 4> q;
    if (n == 4) {
        for (int i = 0; i < 4; ++i) q[size_t(i)] = P(i);
    } else {
        const int i = topo.SubFace(face);
        std::array<float, 3> centroid{0, 0, 0};
        for (int k = 0; k < n; ++k)
            for (int a = 0; a < 3; ++a) centroid[size_t(a)] += P(k)[size_t(a)] / float(n);
        for (int a = 0; a < 3; ++a) {
            q[0][size_t(a)] = P(i)[size_t(a)];
            q[1][size_t(a)] = 0.5f * (P(i)[size_t(a)] + P(i + 1)[size_t(a)]);
            q[2][size_t(a)] = centroid[size_t(a)];
            q[3][size_t(a)] = 0.5f * (P(i)[size_t(a)] + P(i - 1)[size_t(a)]);
        }
    }
    std::array<float, 3> p;
    for (int a = 0; a < 3; ++a)
        p[size_t(a)] = (1 - u) * (1 - v) * q[0][size_t(a)] + u * (1 - v) * q[1][size_t(a)] +
                       u * v * q[2][size_t(a)] + (1 - u) * v * q[3][size_t(a)];
    return p;
}

}  // namespace texcache::test
