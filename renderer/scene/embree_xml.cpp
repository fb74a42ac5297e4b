// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/embree_xml.h"

#include <algorithm>
#include <cstdio>

namespace texcache {

namespace {

// Embree 3.13.5's limits, measured with probe cages: a face of exactly 16 vertices aborts on an
// assertion (MAX_PATCH_VALENCE), faces of 17 and more are silently dropped, as are vertices of
// valence 65 and more.
constexpr int kMaxFaceVertices = 15;
constexpr int kMaxValence = 64;

/// The position_indices attribute for embree_mesh.cpp's ToEmbree mapping, in the XML loader's
/// names; smooth boundaries are its default, which it has no name for ("invalid subdivision
/// mode: smooth_boundary").
const char* SubdivModeAttribute(BoundaryInterpolation b) {
    switch (b) {
        case BoundaryInterpolation::None:
            return " subdiv_mode=\"no_boundary\"";
        case BoundaryInterpolation::EdgeAndCorner:
            return " subdiv_mode=\"pin_corners\"";
        case BoundaryInterpolation::EdgeOnly:
            return "";
    }
    return "";
}

void AppendSharpness(std::string* s, float w) {
    char buf[32];
    // OpenSubdiv treats sharpness >= 10 as infinitely sharp; Embree needs +inf for that.
    if (w >= 10.0f)
        std::snprintf(buf, sizeof buf, "+inf\n");
    else
        std::snprintf(buf, sizeof buf, "%.9g\n", double(w));
    *s += buf;
}

}  // namespace

EmbreePeerCheck CheckEmbreePeer(const ControlCage& cage) {
    EmbreePeerCheck c;
    const int maxFace =
        cage.faceVertexCounts.empty()
            ? 0
            : *std::max_element(cage.faceVertexCounts.begin(), cage.faceVertexCounts.end());
    if (maxFace > kMaxFaceVertices)
        c.cannot.push_back("a face of " + std::to_string(maxFace) +
                           " vertices (Embree 3 takes at most " + std::to_string(kMaxFaceVertices) +
                           ")");
    std::vector<int> valence(cage.positions.size(), 0);
    for (int v : cage.faceVertexIndices) ++valence[size_t(v)];
    const int maxValence = valence.empty() ? 0 : *std::max_element(valence.begin(), valence.end());
    if (maxValence > kMaxValence)
        c.cannot.push_back("a vertex in " + std::to_string(maxValence) +
                           " faces (Embree 3 takes at most " + std::to_string(kMaxValence) + ")");
    if (!cage.holes.empty())
        c.differs.push_back(std::to_string(cage.holes.size()) +
                            " hole face(s): Embree turns a hole's edges into boundaries, which "
                            "changes the surface around it; we keep OpenSubdiv's surface and "
                            "only hide the hole");
    return c;
}

std::string EmbreeXmlScene(const ControlCage& cage, glm::vec3 diffuse) {
    std::string s;
    s.reserve(64 * cage.positions.size() + 16 * cage.faceVertexIndices.size() + 512);
    char buf[256];
    s += "<?xml version=\"1.0\"?>\n<scene>\n<Group>\n<SubdivisionMesh>\n";
    s += "<positions>\n";
    for (const auto& p : cage.positions) {
        std::snprintf(buf, sizeof buf, "%.9g %.9g %.9g\n", double(p[0]), double(p[1]),
                      double(p[2]));
        s += buf;
    }
    s += "</positions>\n<position_indices";
    s += SubdivModeAttribute(cage.boundary);
    s += ">\n";
    size_t i = 0;
    for (int n : cage.faceVertexCounts) {
        for (int k = 0; k < n; ++k, ++i) {
            s += std::to_string(cage.faceVertexIndices[i]);
            s += k + 1 < n ? ' ' : '\n';
        }
    }
    s += "</position_indices>\n<faces>\n";
    for (int n : cage.faceVertexCounts) s += std::to_string(n) + '\n';
    s += "</faces>\n";
    if (!cage.creaseEdges.empty()) {
        s += "<edge_creases>\n";
        for (const auto& e : cage.creaseEdges)
            s += std::to_string(e[0]) + ' ' + std::to_string(e[1]) + '\n';
        s += "</edge_creases>\n<edge_crease_weights>\n";
        for (float w : cage.creaseWeights) AppendSharpness(&s, w);
        s += "</edge_crease_weights>\n";
    }
    if (!cage.cornerVertices.empty()) {
        s += "<vertex_creases>\n";
        for (int v : cage.cornerVertices) s += std::to_string(v) + '\n';
        s += "</vertex_creases>\n<vertex_crease_weights>\n";
        for (float w : cage.cornerWeights) AppendSharpness(&s, w);
        s += "</vertex_crease_weights>\n";
    }
    if (!cage.holes.empty()) {
        s += "<holes>\n";
        for (int h : cage.holes) s += std::to_string(h) + '\n';
        s += "</holes>\n";
    }
    std::snprintf(buf, sizeof buf,
                  "<material>\n<code>\"OBJ\"</code>\n<parameters>\n<float3 name=\"Kd\">%.9g %.9g "
                  "%.9g</float3>\n</parameters>\n</material>\n",
                  double(diffuse.x), double(diffuse.y), double(diffuse.z));
    s += buf;
    s += "</SubdivisionMesh>\n</Group>\n</scene>\n";
    return s;
}

}  // namespace texcache
