// SPDX-License-Identifier: Apache-2.0
// Helpers for tests: bundled data paths and tiny scenes built in code.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "renderer/image/image.h"
#include "renderer/scene/obj_loader.h"
#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene.h"
#include "texcache/topology.h"

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

/// Drops creases and corners with fractional sharpness (< 1), which Embree and OpenSubdiv
/// subdivide differently (tests/ptex_mapping_test.cpp,
/// FractionalCreasesDifferBetweenEmbreeAndOpenSubdiv).
inline ControlCage WithoutFractionalSharpness(ControlCage c) {
    ControlCage out = c;
    out.creaseEdges.clear(), out.creaseWeights.clear();
    for (size_t i = 0; i < c.creaseEdges.size(); ++i)
        if (c.creaseWeights[i] >= 1.0f)
            out.creaseEdges.push_back(c.creaseEdges[i]),
                out.creaseWeights.push_back(c.creaseWeights[i]);
    out.cornerVertices.clear(), out.cornerWeights.clear();
    for (size_t i = 0; i < c.cornerVertices.size(); ++i)
        if (c.cornerWeights[i] >= 1.0f)
            out.cornerVertices.push_back(c.cornerVertices[i]),
                out.cornerWeights.push_back(c.cornerWeights[i]);
    return out;
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

/// Writes a cage's positions and faces as an OBJ file (for the programs' tests).
inline void WriteObj(const ControlCage& c, const std::string& path) {
    std::ofstream f(path);
    for (const auto& p : c.positions) f << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
    size_t at = 0;
    for (int n : c.faceVertexCounts) {
        f << 'f';
        for (int i = 0; i < n; ++i) f << ' ' << c.faceVertexIndices[at++] + 1;
        f << '\n';
    }
}

/// Bounding-box centre and diagonal of a cage.
inline void CageBounds(const ControlCage& c, glm::vec3* center, float* diagonal) {
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const auto& p : c.positions) {
        lo = glm::min(lo, glm::vec3(p[0], p[1], p[2]));
        hi = glm::max(hi, glm::vec3(p[0], p[1], p[2]));
    }
    *center = 0.5f * (lo + hi);
    *diagonal = glm::length(hi - lo);
}

/// Up to n rays from all around towards a cage (random directions, from two diagonals away,
/// origins jittered by `jitter` diagonals so they do not all pass through the centre).
inline std::vector<Ray> RaysAround(const ControlCage& cage, int n, unsigned seed, float jitter) {
    glm::vec3 center;
    float diag;
    CageBounds(cage, &center, &diag);
    std::mt19937 gen(seed);
    std::uniform_real_distribution<float> U11(-1.0f, 1.0f);
    std::vector<Ray> rays;
    for (int i = 0; i < n; ++i) {
        glm::vec3 d(U11(gen), U11(gen), U11(gen));
        if (glm::length(d) < 0.1f) continue;
        d = glm::normalize(d);
        Ray ray;
        ray.org =
            center - d * diag * 2.0f + glm::vec3(U11(gen), U11(gen), U11(gen)) * jitter * diag;
        ray.dir = d;
        rays.push_back(ray);
    }
    return rays;
}

/// A ray's hit on a one-object scene: the distance from the hit point to OpenSubdiv's limit point
/// at the hit's decoded Ptex location (-1 when that location is not on the limit surface), and
/// the shading normal.
struct DecodedHit {
    size_t ray;
    float offLimit;
    glm::vec3 N;
};
inline std::vector<DecodedHit> DecodeHits(const RenderScene& rs, const LimitSurface& osd,
                                          const std::vector<Ray>& rays) {
    std::vector<DecodedHit> out;
    for (size_t i = 0; i < rays.size(); ++i) {
        Hit hit;
        if (!rs.Intersect(rays[i], &hit)) continue;
        const SurfaceInteraction si = rs.Interact(rays[i], hit);
        LimitPoint ref;
        const bool on = osd.Eval(si.ptex.face, si.ptex.u, si.ptex.v, &ref);
        const float d = glm::length(si.P - glm::vec3(ref.P[0], ref.P[1], ref.P[2]));
        out.push_back({i, on ? d : -1.0f, si.N});
    }
    return out;
}

/// A w x h RGB image of smooth ramps, different per channel.
inline Image Ramp(int w, int h) {
    Image img(w, h, 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int k = 0; k < 3; ++k) img.At(x, y)[k] = float(x + 2 * y + k) / float(w + 2 * h);
    return img;
}

/// Mean of an image over the mean of a reference; NaN when the image has a non-finite value.
inline double MeanRatio(const Image& img, const Image& ref) {
    double a = 0.0, b = 0.0;
    for (size_t i = 0; i < img.data.size(); ++i) {
        if (!std::isfinite(img.data[i])) return std::nan("");
        a += img.data[i], b += ref.data[i];
    }
    return a / b;
}

}  // namespace texcache::test
