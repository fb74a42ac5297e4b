// SPDX-License-Identifier: Apache-2.0
// Helpers for tests: bundled data paths and tiny scenes built in code.
#pragma once
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
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

/// Rewrites a zip-compressed scanline EXR (as WriteImage writes) so that its header claims
/// width x height pixels (dataWindow, displayWindow) and its line-offset table has that height's
/// entries (16 scanlines per chunk; the new ones 0), while its pixel data stays what it was: a
/// small file lying about its size that OpenEXR still opens.
inline void ClaimExrSize(const std::string& path, int width, int height) {
    std::string bytes;
    {
        std::ifstream f(path, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(f), {});
    }
    // Header: magic and version (8 bytes), then attributes "name\0type\0" int32 size, value,
    // up to an empty name.
    size_t pos = 8;
    int oldHeight = 0;
    while (pos < bytes.size() && bytes[pos] != '\0') {
        const std::string name = bytes.c_str() + pos;
        pos += name.size() + 1;
        const std::string type = bytes.c_str() + pos;
        pos += type.size() + 1;
        int32_t size = 0;
        std::memcpy(&size, &bytes[pos], 4);
        pos += 4;
        if (name == "dataWindow" || name == "displayWindow") {
            int32_t box[4];
            std::memcpy(box, &bytes[pos], sizeof box);
            oldHeight = box[3] - box[1] + 1;
            const int32_t claim[4] = {0, 0, width - 1, height - 1};
            std::memcpy(&bytes[pos], claim, sizeof claim);
        }
        pos += size_t(size);
    }
    const size_t table = pos + 1, oldChunks = size_t(oldHeight + 15) / 16;
    const size_t newChunks = size_t(height + 15) / 16;
    bytes.insert(table + 8 * oldChunks, 8 * (newChunks - oldChunks), '\0');
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

}  // namespace texcache::test
