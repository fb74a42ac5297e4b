// SPDX-License-Identifier: Apache-2.0
// Plain meshes ("subdivision": "none"): a cage's polygons rendered as they are. Every Ptex face
// becomes one Embree quad: a quad face as it is, an n-gon (triangles included) as its n quad
// sub-faces from the centroid through the edge midpoints, the sub-faces Ptex and the project's
// topology (PtexTopology) give it. Sub-face i has corner (0,0) at the face's vertex i, u towards
// the midpoint of edge (i, i+1), v towards the midpoint of edge (i-1, i), (1,1) at the centroid.
// The Embree primitive id is then the Ptex face id and a hit's (u,v) is the face's (u,v): the
// per-face texel grids of the cache apply unchanged.
//
// Embree treats a quad as the triangles (0,1,3) and (2,3,1), with (u,v) affine on each and u + v
// = 1 on the diagonal; the surface and its Ptex parametrization here are exactly that, so a cache
// sample's surface point (PlainQuadEval) lies on the surface rays hit. Normals are flat: each
// triangle's (an OBJ's `vn` are ignored, as for subdivision cages).
// Internal to renderer/scene/.
#pragma once
#include <array>
#include <vector>

#include "texcache/cage.h"
#include "texcache/topology.h"

namespace texcache::internal {

/// The position (when P is given) and derivatives in (u,v) of a plain quad at (u,v), its
/// `corners` 4 points of 4 floats each; outputs of 3 floats. True.
inline bool PlainQuadEval(const float* corners, float u, float v, float* P, float* du, float* dv) {
    const float* c0 = corners;
    const float* c1 = corners + 4;
    const float* c2 = corners + 8;
    const float* c3 = corners + 12;
    if (u + v <= 1.0f) {
        // c0 + u (c1 - c0) + v (c3 - c0)
        for (int k = 0; k < 3; ++k) {
            du[k] = c1[k] - c0[k];
            dv[k] = c3[k] - c0[k];
            if (P) P[k] = c0[k] + u * du[k] + v * dv[k];
        }
    } else {
        // c2 + (1 - u) (c3 - c2) + (1 - v) (c1 - c2)
        for (int k = 0; k < 3; ++k) {
            du[k] = c2[k] - c3[k];
            dv[k] = c2[k] - c1[k];
            if (P) P[k] = c2[k] - (1.0f - u) * du[k] - (1.0f - v) * dv[k];
        }
    }
    return true;
}

/// The 4 corners of every Ptex face of `cage` as a plain mesh (see the top), in Ptex face order,
/// counter-clockwise like the cage's faces; the faces of holes collapse to a point (never hit).
/// With `uvs` given and the cage's uvs present, the corners' texture coordinates likewise.
std::vector<std::array<float, 3>> PlainQuadCorners(const ControlCage& cage,
                                                   const PtexTopology& topo,
                                                   std::vector<std::array<float, 2>>* uvs);

}  // namespace texcache::internal
