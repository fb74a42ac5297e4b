// SPDX-License-Identifier: Apache-2.0
// A control cage in the XML scene format of Embree's tutorials (`pathtracer -i scene.xml`), so
// that `texcache bench peer` can render the same surface with Embree's own path tracer.
//
// The format (Embree 3 tutorials, tutorials/common/scenegraph/xml_loader.cpp): a
// <SubdivisionMesh> with <positions>, <position_indices subdiv_mode="...">, <faces> (vertex
// count per face), <edge_creases> + <edge_crease_weights>, <vertex_creases> +
// <vertex_crease_weights>, <holes> and an "OBJ" <material> with a diffuse Kd.
#pragma once
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "texcache/cage.h"

namespace texcache {

/// What Embree's subdivision code (3.13.5) does not render as we do, in words a user can act on.
struct EmbreePeerCheck {
    /// Features the peer cannot take at all (its image would miss or abort on them); empty
    /// when it can render the cage.
    std::vector<std::string> cannot;
    /// Features it renders differently (the images then differ there); empty when it agrees.
    std::vector<std::string> differs;
};
EmbreePeerCheck CheckEmbreePeer(const ControlCage& cage);

/// The cage as an Embree tutorial XML scene, one white-or-`diffuse` OBJ material. Positions are
/// written with 9 significant digits (float round trip); sharpness >= 10 (OpenSubdiv's infinitely
/// sharp) becomes +inf, as Embree wants.
std::string EmbreeXmlScene(const ControlCage& cage, glm::vec3 diffuse);

}  // namespace texcache
