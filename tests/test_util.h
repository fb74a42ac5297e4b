// SPDX-License-Identifier: Apache-2.0
// Helpers for tests: bundled data paths and tiny scenes built in code.
#pragma once
#include <string>
#include <vector>

#include "renderer/obj_loader.h"
#include "renderer/scene.h"

namespace texcache::test {

inline std::string SceneDir() {
    return std::string(TEXCACHE_SOURCE_DIR) + "/scenes";
}
inline std::string MeshPath(const std::string& name) {
    return SceneDir() + "/meshes/" + name + ".obj";
}

inline const std::vector<std::string>& BundledMeshes() {
    static const std::vector<std::string> names = {
        "catmark_car",           "catmark_bishop",
        "catmark_rook",          "catmark_pawn",
        "catmark_helmet",        "catmark_cube",
        "catmark_torus",         "catmark_pyramid",
        "catmark_cube_creases1", "catmark_cubes_infsharp",
        "catmark_tent_creases1", "catmark_hole_test1",
        "catmark_nonquads",      "catmark_xord_interior"};
    return names;
}

inline ControlCage LoadMesh(const std::string& name) {
    std::vector<std::string> warnings;
    return LoadObj(MeshPath(name), &warnings);
}

/// A scene with one object (the cage), a diffuse material and a camera looking at the origin.
inline Scene OneObjectScene(ControlCage cage, glm::vec3 albedo = glm::vec3(0.8f)) {
    Scene s;
    s.meshes.push_back(std::move(cage));
    Object o;
    o.mesh = 0;
    o.material = 0;
    s.objects.push_back(o);
    Material m;
    m.albedo.value = albedo;
    s.materials.push_back(m);
    return s;
}

/// Camera pose looking from `eye` at `target` (+Y up).
inline Keyframe LookAt(glm::vec3 eye, glm::vec3 target) {
    Keyframe k;
    k.translation = eye;
    const glm::vec3 f = glm::normalize(target - eye);
    const glm::vec3 r = glm::normalize(glm::cross(f, glm::vec3(0, 1, 0)));
    const glm::vec3 u = glm::cross(r, f);
    k.rotation = glm::quat_cast(glm::mat3(r, u, -f));
    return k;
}

/// A single planar quad cage of half-size `h` in the XZ plane (boundary pinned: stays planar).
inline ControlCage PlaneCage(float h) {
    ControlCage c;
    c.positions = {{-h, 0, -h}, {-h, 0, h}, {h, 0, h}, {h, 0, -h}};
    c.faceVertexCounts = {4};
    c.faceVertexIndices = {0, 1, 2, 3};
    c.boundary = BoundaryInterpolation::EdgeAndCorner;
    c.sourcePath = "plane";
    return c;
}

}  // namespace texcache::test
