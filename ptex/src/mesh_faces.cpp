// SPDX-License-Identifier: Apache-2.0
#include "texcache/ptex/mesh_faces.h"

namespace texcache::ptex {

std::array<int, 2> FileNeighbour(const PtexTopology& topo, int face, int e) {
    const PtexTopology::EdgeLink l = topo.Edge(face, e);
    if (l.count == 0) return {-1, 0};
    int j = 0;
    // Our parameter runs the shared cage edge the other way: a segment covers our first half
    // when its middle lies in the second half of its own parameter.
    if (l.count == 2 && l.segStart[1] + 0.5f * l.segLength[1] > 0.5f) j = 1;
    return {l.face[j], l.edge[j]};
}

std::vector<FaceInfo> MeshFaces(const PtexTopology& topo, const std::function<Res(int)>& res) {
    std::vector<FaceInfo> faces(size_t(topo.NumPtexFaces()));
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        FaceInfo& fi = faces[size_t(f)];
        fi.subface = !topo.IsQuad(topo.CoarseFace(f));
        fi.res = res(f);
        for (int e = 0; e < 4; ++e) {
            const std::array<int, 2> n = FileNeighbour(topo, f, e);
            fi.adjFaces[size_t(e)] = n[0];
            fi.adjEdges[size_t(e)] = uint8_t(n[1]);
        }
    }
    return faces;
}

std::vector<FaceInfo> MeshFaces(const PtexTopology& topo, Res quadRes, Res subfaceRes) {
    return MeshFaces(topo,
                     [&](int f) { return topo.IsQuad(topo.CoarseFace(f)) ? quadRes : subfaceRes; });
}

}  // namespace texcache::ptex
