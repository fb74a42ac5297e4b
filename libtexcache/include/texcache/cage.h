// SPDX-License-Identifier: Apache-2.0
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace texcache {

/// Boundary interpolation of a Catmull-Clark cage, OpenSubdiv's names.
enum class BoundaryInterpolation : uint8_t {
    None,           ///< boundary faces are holes (OSD VTX_BOUNDARY_NONE)
    EdgeAndCorner,  ///< sharp boundary edges and corners (OSD VTX_BOUNDARY_EDGE_AND_CORNER)
    EdgeOnly,       ///< sharp boundary edges, smooth corners (OSD VTX_BOUNDARY_EDGE_ONLY)
};

/// A Catmull-Clark control cage: what an OBJ with OpenSubdiv tags describes. Plain data, no
/// renderer or subdivision library inside; indices are 0-based and validated by whoever fills it.
struct ControlCage {
    std::vector<std::array<float, 3>> positions;
    std::vector<int> faceVertexCounts;   ///< one entry per face, each >= 3
    std::vector<int> faceVertexIndices;  ///< concatenated face loops (counter-clockwise)

    /// Optional face-varying texture coordinates (OBJ `vt`), empty when absent.
    std::vector<std::array<float, 2>> uvs;
    std::vector<int> faceUvIndices;  ///< parallel to faceVertexIndices when uvs is non-empty

    std::vector<std::array<int, 2>> creaseEdges;  ///< vertex pairs of existing edges
    std::vector<float> creaseWeights;             ///< sharpness per crease edge (>= 10: infinite)
    std::vector<int> cornerVertices;
    std::vector<float> cornerWeights;
    std::vector<int> holes;  ///< face indices tagged as holes
    BoundaryInterpolation boundary = BoundaryInterpolation::EdgeOnly;

    std::string sourcePath;  ///< for messages
    /// `positions` are in units of 2^unitExponent of the file's: a cage far larger or smaller
    /// than a unit is stored scaled by a power of two (exactly), and its objects' transforms
    /// scale it back.
    int unitExponent = 0;

    int numFaces() const { return int(faceVertexCounts.size()); }
    int numVertices() const { return int(positions.size()); }
};

}  // namespace texcache
