// SPDX-License-Identifier: Apache-2.0
// Ptex face records (adjacency, sub-face flags) from the project's own topology of a cage: what
// a writer of textures for that cage stores, and what a texture read for it must agree with.
#pragma once
#include <array>
#include <functional>
#include <vector>

#include "texcache/ptex/texture.h"
#include "texcache/topology.h"

namespace texcache::ptex {

/// The face across edge `e` of a Ptex face as a Ptex file records it: where the edge meets two
/// n-gon sub-faces, the one covering the first half of this edge (the first met going
/// counter-clockwise round this face). {-1, 0} at a boundary.
std::array<int, 2> FileNeighbour(const PtexTopology& topo, int face, int e);

/// Face info (adjacency, sub-face flag) of every Ptex face of a topology, each face's resolution
/// from `res(face)`.
std::vector<FaceInfo> MeshFaces(const PtexTopology& topo, const std::function<Res(int)>& res);

/// The same with one resolution for quads and one for the sub-faces of n-gons.
std::vector<FaceInfo> MeshFaces(const PtexTopology& topo, Res quadRes, Res subfaceRes);

}  // namespace texcache::ptex
