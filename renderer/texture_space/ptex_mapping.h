// SPDX-License-Identifier: Apache-2.0
// Embree subdivision hit parameters <-> Ptex face and (u,v).
//
// Embree reports (primID, U, V) for a subdivision hit with primID = coarse face index. On quads
// (U,V) is the Ptex (u,v) of the face. On other faces Embree encodes the sub-patch in (U,V):
//   l = floor(U/2), h = floor(V/2), i = 4h + l, u = 2 fract(U/2) - 0.5, v = 2 fract(V/2) - 0.5,
// and sub-patch i is OpenSubdiv's Ptex sub-face i (corner (0,0) at face vertex i, u towards edge
// (i,i+1), v towards edge (i-1,i)), so Ptex id = FirstPtexFace(primID) + i. Since du/dU = 1,
// Embree's derivatives with respect to (U,V) are also derivatives in the sub-face's (u,v).
// Pure arithmetic, no Embree header: the cache and tests reuse it.
#pragma once
#include <algorithm>
#include <cmath>

#include "texcache/topology.h"

namespace texcache {

/// A location in Ptex space.
struct PtexCoord {
    int face = -1;
    float u = 0.0f, v = 0.0f;
};

/// Embree (primID, U, V) -> Ptex face and (u,v), clamped to [0,1] (Embree can return values
/// like -4e-10 at edges; ctest -R RayHitsDecodeToTheirPtexLocation).
inline PtexCoord EmbreeToPtex(const PtexTopology& topo, unsigned primID, float U, float V) {
    PtexCoord c;
    if (topo.IsQuad(int(primID))) {
        c.face = topo.FirstPtexFace(int(primID));
        c.u = U;
        c.v = V;
    } else {
        const float hu = 0.5f * U, hv = 0.5f * V;
        const float l = std::floor(hu), h = std::floor(hv);
        c.face = topo.FirstPtexFace(int(primID)) + int(4.0f * h + l);
        c.u = 2.0f * (hu - l) - 0.5f;
        c.v = 2.0f * (hv - h) - 0.5f;
    }
    c.u = std::clamp(c.u, 0.0f, 1.0f);
    c.v = std::clamp(c.v, 0.0f, 1.0f);
    return c;
}

/// Ptex face and (u,v) -> Embree (primID, U, V): the inverse of EmbreeToPtex, for surface queries.
inline void PtexToEmbree(const PtexTopology& topo, const PtexCoord& c, unsigned* primID, float* U,
                         float* V) {
    const int coarse = topo.CoarseFace(c.face);
    *primID = unsigned(coarse);
    if (topo.IsQuad(coarse)) {
        *U = c.u;
        *V = c.v;
    } else {
        const int i = topo.SubFace(c.face);
        // u in [0,1] sits inside the decode window [-0.5, 1.5) of cell (i%4, i/4).
        *U = 2.0f * float(i % 4) + c.u + 0.5f;
        *V = 2.0f * float(i / 4) + c.v + 0.5f;
    }
}

}  // namespace texcache
