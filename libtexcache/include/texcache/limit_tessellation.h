// SPDX-License-Identifier: Apache-2.0
// A cage's limit surface as a quad mesh whose quads know their Ptex face and (u,v) square: for
// intersectors that cannot take the cage as a subdivision surface (Embree 3 past its face-size
// and valence limits), so that hits still address the cache by Ptex face and (u,v).
#pragma once
#include <array>
#include <vector>

#include "texcache/cage.h"

namespace texcache {

/// `level` uniform Catmull-Clark refinements of a cage (OpenSubdiv), every vertex moved to its
/// limit position. Neighbouring quads share their vertices, so the mesh has no cracks. After one
/// refinement every quad lies in one Ptex face: quad q covers the square
/// [u0, u0 + size] x [v0, v0 + size] of Ptex face squares[q].face, its corners 0..3 at
/// (u0, v0), (u0 + size, v0), (u0 + size, v0 + size), (u0, v0 + size). Hole faces get no quads.
/// Plain data, built once.
struct LimitTessellation {
    struct Square {
        int face = -1;  ///< Ptex face
        float u0 = 0.0f, v0 = 0.0f, size = 1.0f;
    };
    std::vector<std::array<float, 3>> positions;  ///< limit points
    std::vector<std::array<int, 4>> quads;        ///< indices into positions, counter-clockwise
    std::vector<Square> squares;                  ///< per quad
    /// Limit uvs (face-varying, linear along boundaries) per quad corner, 4 per quad; empty
    /// unless asked for and the cage has uvs.
    std::vector<std::array<float, 2>> cornerUvs;
};

/// Tessellates the limit surface with `level` >= 1 refinements (4^level quads per cage quad,
/// n 4^(level-1) per n-gon); throws InputError for cages OpenSubdiv rejects.
LimitTessellation TessellateLimitSurface(const ControlCage& cage, int level, bool withUvs);

}  // namespace texcache
