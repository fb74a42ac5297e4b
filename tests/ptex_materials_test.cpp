// SPDX-License-Identifier: Apache-2.0
// Materials that read Ptex files, on the three Ptex sets of scenes/ptex: what a hit sees is the
// file's texels at the hit's Ptex face and (u,v), through the scene, the renderer and its
// emission; a file for another mesh is refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "ptex_test_util.h"
#include "renderer/render.h"
#include "renderer/scene/camera.h"
#include "renderer/scene/scene_loader.h"
#include "texcache/error.h"
#include "texcache/ptex/texture.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

fs::path Dir() {
    const fs::path d = fs::path(::testing::TempDir()) / "texcache_ptex_materials";
    fs::create_directories(d);
    return d;
}

Scene Load(const std::string& file) {
    std::vector<std::string> w;
    return LoadScene(test::SceneDir() + "/" + file, &w);
}

/// Camera hits of a scene's own view, on a grid of pixels (pinhole, through pixel centres).
template <typename Fn>
void ForEachHit(const RenderScene& rs, int step, Fn&& fn) {
    const Scene& s = rs.scene();
    const CameraModel cam(s.camera, 0.0f, s.settings.width, s.settings.height);
    for (int y = step / 2; y < s.settings.height; y += step)
        for (int x = step / 2; x < s.settings.width; x += step) {
            const Ray ray = cam.Generate(float(x) + 0.5f, float(y) + 0.5f, {0.5f, 0.5f}, nullptr);
            Hit hit;
            if (rs.Intersect(ray, &hit) && hit.object >= 0) fn(ray, rs.Interact(ray, hit));
        }
}

/// Whether `value` (channel c of a bilinear lookup at (u, v), level 0) lies within the 2x2
/// texels around (u, v) that the file holds, with `slack`; false when (u, v) is within a texel
/// of the face's border (taps from the neighbours there).
bool WithinTexels(const ptex::Texture& t, int face, float u, float v, int c, float value,
                  float slack, bool* inside) {
    const ptex::Res r = t.LevelRes(face, 0);
    const float x = u * float(r.U()) - 0.5f, y = v * float(r.V()) - 0.5f;
    *inside = x >= 1.0f && y >= 1.0f && x < float(r.U() - 2) && y < float(r.V() - 2);
    if (!*inside) return true;
    float lo = INFINITY, hi = -INFINITY;
    std::vector<float> px(size_t(t.NumChannels()));
    for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
            t.Texel(face, 0, int(std::floor(x)) + dx, int(std::floor(y)) + dy, px.data());
            const float p = px[size_t(std::min(c, t.NumChannels() - 1))];
            lo = std::min(lo, p), hi = std::max(hi, p);
        }
    return value >= lo - slack && value <= hi + slack;
}

// On each set's own view, every hit's albedo is the file's bilinear lookup at the hit's Ptex
// face and (u,v) (the cube's one channel as grey), and lies within the four texels the file
// holds around that point (8-bit files: within half a level).
TEST(PtexMaterials, HitsSeeTheTexelsTheFileHolds) {
    const std::pair<const char*, const char*> sets[] = {
        {"ptex_flatsphere.json", "flatsphere/cellnoise.ptx"},
        {"ptex_cube.json", "cube/text/cube.ptx"},
        {"ptex_nonquad.json", "nonquad/test/pPlane1Unsub.ptx"}};
    for (const auto& [file, ptx] : sets) {
        SCOPED_TRACE(file);
        const Scene s = Load(file);
        RenderSceneOptions ro;
        ro.needLights = false;
        const RenderScene rs(s, ro);
        const ptex::Texture t = ptex::Texture::Open(test::PtexPath(ptx));
        int hits = 0, checked = 0, outside = 0, subfaces = 0;
        ForEachHit(rs, 4, [&](const Ray&, const SurfaceInteraction& si) {
            if (si.object != 0) return;  // nonquad: the unsubdivided plane only
            ++hits;
            const glm::vec3 albedo = rs.Albedo(si);
            float want[3];
            t.Lookup(si.ptex.face, si.ptex.u, si.ptex.v, 0.0f, want, 0,
                     std::min(3, t.NumChannels()));
            if (t.NumChannels() == 1) want[1] = want[2] = want[0];
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(albedo[c], want[c], 1e-6f);
            subfaces += t.Face(si.ptex.face).subface;
            for (int c = 0; c < 3; ++c) {
                bool inside;
                outside += !WithinTexels(t, si.ptex.face, si.ptex.u, si.ptex.v, c, albedo[c],
                                         0.5f / 255.0f, &inside);
                checked += inside;
            }
        });
        EXPECT_GT(hits, 500);
        EXPECT_GT(checked, hits);  // most hits lie inside their faces
        EXPECT_EQ(outside, 0);
        if (std::string(file) == "ptex_nonquad.json") {
            EXPECT_GT(subfaces, 10);  // the triangles' sub-faces
        }
    }
}

// The flat sphere's two files hold the same cells at different per-face resolutions
// (cellnoise 128x16 to 256x256, pPyramid1 64x512 to 512x512): through the renderer, the same
// hits see the same colours (measured: 95% of the hits within 0.05; the rest lie on the cells'
// edges, which the coarser file blurs). Bound: 85%.
TEST(PtexMaterials, FlatSphereShowsTheSameCellsAtBothResolutions) {
    Scene a = Load("ptex_flatsphere.json");
    Scene b = a;
    b.textures[size_t(b.materials[size_t(b.objects[0].material)].albedo.texture)].path =
        test::PtexPath("flatsphere/pPyramid1.ptx");
    RenderSceneOptions ro;
    ro.needLights = false;
    const RenderScene ra(a, ro), rb(b, ro);
    int hits = 0, same = 0;
    ForEachHit(ra, 3, [&](const Ray& ray, const SurfaceInteraction& si) {
        Hit h;
        ASSERT_TRUE(rb.Intersect(ray, &h));
        const SurfaceInteraction sb = rb.Interact(ray, h);
        ASSERT_EQ(sb.ptex.face, si.ptex.face);
        const glm::vec3 d = glm::abs(ra.Albedo(si) - rb.Albedo(sb));
        ++hits;
        same += std::max({d.x, d.y, d.z}) < 0.05f;
    });
    EXPECT_GT(hits, 2000);
    RecordProperty("same_fraction", std::to_string(double(same) / double(hits)));
    EXPECT_GT(double(same) / double(hits), 0.85);
}

// End to end through a render: the non-quad plane's file as emission (black albedo, no light),
// one camera ray through each pixel's centre; each pixel is the file's lookup at the Ptex face
// and (u,v) the render's own ptex layer reports for it.
TEST(PtexMaterials, RenderedEmissionIsTheFilesLookupAtEachPixel) {
    Scene s = Load("ptex_nonquad.json");
    for (Material& m : s.materials) {
        m.emission.texture = m.albedo.texture;
        m.albedo = {glm::vec3(0.0f), -1};
    }
    s.environments.clear();
    RenderSceneOptions ro;
    const RenderScene rs(s, ro);
    RenderOptions o = RenderOptionsFrom(s.settings);
    o.width = 160, o.height = 80, o.spp = 1, o.pixelCentre = true, o.progress = false;
    o.aovs.ptex = true;
    const RenderResult r = Render(rs, o);
    ASSERT_EQ(r.aovs.size(), 1u);
    const Image& ptexLayer = r.aovs[0].image;
    const ptex::Texture left = ptex::Texture::Open(test::PtexPath("nonquad/test/pPlane1Unsub.ptx"));
    const ptex::Texture right = ptex::Texture::Open(test::PtexPath("nonquad/test/pPlane1.ptx"));
    int hits = 0;
    float worst = 0.0f;
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x) {
            const float* p = ptexLayer.At(x, y);
            if (p[0] < 0.0f) {
                EXPECT_EQ(r.beauty.At(x, y)[0], 0.0f);  // no hit: black
                continue;
            }
            // Which plane: by the pixel's side of the image (they do not overlap).
            const ptex::Texture& t = x < o.width / 2 ? left : right;
            float want[3];
            t.Lookup(int(p[0]), p[1], p[2], 0.0f, want);
            for (int c = 0; c < 3; ++c)
                worst = std::max(worst, std::abs(r.beauty.At(x, y)[c] - want[c]));
            ++hits;
        }
    EXPECT_GT(hits, 2000);
    EXPECT_LT(worst, 1e-5f);
}

// A file painted for another mesh: an error naming the file, both counts and the object.
TEST(PtexMaterials, AFileForAnotherMeshIsAnError) {
    const fs::path scene = Dir() / "mismatch.json";
    std::ofstream(scene) << R"({"materials": {"m": {"albedo": {"ptex": ")"
                         << test::PtexPath("cube/text/cube.ptx") << R"("}}},
      "objects": [{"name": "sphere", "mesh": ")"
                         << test::PtexPath("flatsphere/ptex_test_object.obj")
                         << R"(", "material": "m"}]})";
    std::vector<std::string> w;
    const Scene s = LoadScene(scene.string(), &w);
    try {
        const RenderScene rs(s, RenderSceneOptions{});
        FAIL() << "no error";
    } catch (const InputError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("mismatch.json: key 'materials.m.albedo.ptex'"), std::string::npos) << m;
        EXPECT_NE(m.find("cube.ptx' has 72 faces"), std::string::npos) << m;
        EXPECT_NE(m.find("object 'sphere'"), std::string::npos) << m;
        EXPECT_NE(m.find("306 Ptex faces"), std::string::npos) << m;
    }
    // A channel the file does not have.
    std::ofstream(scene) << R"({"materials": {"m": {"albedo": {"ptex": ")"
                         << test::PtexPath("cube/text/cube.ptx") << R"(", "channel": 1}}},
      "objects": [{"mesh": ")"
                         << test::PtexPath("cube/cube.obj") << R"(", "material": "m"}]})";
    const Scene c = LoadScene(scene.string(), &w);
    EXPECT_THROW(RenderScene(c, RenderSceneOptions{}), InputError);
}

}  // namespace
}  // namespace texcache
