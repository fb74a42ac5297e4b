// SPDX-License-Identifier: Apache-2.0
// Baking texture-space shading into Ptex files: the files hold the cage's faces, adjacency and
// mip levels, and a render that shows them as emission matches the texture-space render of the
// light they baked.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "ptex_test_util.h"
#include "renderer/image/metrics.h"
#include "renderer/render.h"
#include "renderer/scene/scene_loader.h"
#include "renderer/texture_space/bake.h"
#include "texcache/error.h"
#include "texcache/ptex/mesh_faces.h"
#include "texcache/ptex/texture.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

fs::path Dir() {
    const fs::path d = fs::path(::testing::TempDir()) / "texcache_bake";
    fs::create_directories(d);
    return d;
}

/// A torus over a ground plane, both diffuse, seen from above at an angle; `materials` and the
/// objects' material names, and `lights`, vary.
std::string SceneFile(const std::string& name, const std::string& materials,
                      const std::string& torus, const std::string& ground,
                      const std::string& lights) {
    const fs::path p = Dir() / name;
    std::ofstream(p) << R"({
  "camera": {"position": [0, 2.5, 3.5], "look_at": [0, 0, 0], "fov": 40},
  "materials": {)" << materials
                     << R"(},
  "objects": [{"name": "torus", "mesh": ")"
                     << test::MeshPath("catmark_torus") << "\"" << torus << R"(},
              {"name": "ground", "mesh": ")"
                     << test::MeshPath("ground") << "\"" << ground
                     << R"(, "transform": {"translate": [0, -0.6, 0], "scale": 0.4}}],
  "lights": [)" << lights
                     << R"(],
  "render": {"resolution": [96, 72], "integrator": "ao", "ao_distance": 1.0}
})";
    return p.string();
}

RenderSceneOptions SceneOptions(bool lights) {
    RenderSceneOptions ro;
    ro.needLights = ro.needEnvironment = lights;
    return ro;
}

// The round trip of the brief: bake AO, show the baked files as emission (black albedo, no
// light, the path integrator: a camera ray sees the emission and nothing else), and compare with
// the texture-space AO render. Measured relMSE 0.0022 (16 texels along the largest face, 256
// rays a texel; 128 and 64 camera samples a pixel: at 16 the emission render's own edge noise
// alone brings it near 0.01). Bound: 0.01.
TEST(Bake, RenderOfTheBakedFileMatchesTheTextureSpaceRender) {
    std::vector<std::string> w;
    const Scene scene = LoadScene(
        SceneFile("ao.json", "", "", "", R"({"type": "environment", "constant": [1, 1, 1]})"), &w);
    const RenderScene rs(scene, SceneOptions(false));
    BakeOptions bake;
    bake.samples = 256;
    bake.resolution = 16;
    const std::vector<BakedTexture> baked = Bake(rs, RenderOptionsFrom(scene.settings), bake);
    ASSERT_EQ(baked.size(), 2u);
    for (const BakedTexture& b : baked) {
        EXPECT_EQ(b.unreachable, 0u) << b.object;
        ptex::WriteTexture((Dir() / (b.object + ".ptx")).string(), b.options, b.Faces());
    }

    RenderOptions a = RenderOptionsFrom(scene.settings);
    a.spp = 128;
    a.texture.enabled = true;
    a.progress = false;
    const Image reference = Render(rs, a).beauty;

    const std::string emit = R"("t": {"albedo": [0, 0, 0], "emission": {"ptex": ")" +
                             (Dir() / "torus.ptx").string() + R"("}},
       "g": {"albedo": [0, 0, 0], "emission": {"ptex": ")" +
                             (Dir() / "ground.ptx").string() + R"("}})";
    const Scene shown = LoadScene(
        SceneFile("shown.json", emit, R"(, "material": "t")", R"(, "material": "g")", ""), &w);
    const RenderScene rs2(shown, SceneOptions(true));
    RenderOptions b = RenderOptionsFrom(shown.settings);
    b.integrator = IntegratorKind::Path;
    b.maxDepth = 1;
    b.spp = 64;
    b.progress = false;
    const Image image = Render(rs2, b).beauty;
    const double relMSE = RelMSE(image, reference);
    RecordProperty("bake_relmse", std::to_string(relMSE));
    EXPECT_LT(relMSE, 0.01);
}

// What a Ptex reader needs of a baked file: the cage's faces with the adjacency of its topology,
// half floats, mip levels, a texel size equal on every face, and values in [0, 1] for AO.
TEST(Bake, FilesHoldTheCagesFacesAdjacencyAndLevels) {
    std::vector<std::string> w;
    const Scene scene = LoadScene(SceneFile("faces.json", "", "", "", ""), &w);
    const RenderScene rs(scene, SceneOptions(false));
    BakeOptions bake;
    bake.samples = 16;
    bake.resolution = 8;
    const std::vector<BakedTexture> baked = Bake(rs, RenderOptionsFrom(scene.settings), bake);
    for (size_t o = 0; o < baked.size(); ++o) {
        SCOPED_TRACE(baked[o].object);
        const fs::path path = Dir() / ("faces_" + baked[o].object + ".ptx");
        ptex::WriteTexture(path.string(), baked[o].options, baked[o].Faces());
        const ptex::Texture t = ptex::Texture::Open(path.string());
        const PtexTopology& topo = rs.Topology(int(o));
        ASSERT_EQ(t.NumFaces(), topo.NumPtexFaces());
        EXPECT_EQ(t.GetHeader().dataType, ptex::DataType::Half);
        EXPECT_EQ(t.NumChannels(), 1);
        EXPECT_GT(t.GetHeader().numLevels, 1);
        const std::vector<ptex::FaceInfo> want = ptex::MeshFaces(topo, ptex::Res{}, ptex::Res{});
        int largest = 0;
        for (int f = 0; f < t.NumFaces(); ++f) {
            EXPECT_EQ(t.Face(f).adjFaces, want[size_t(f)].adjFaces) << f;
            EXPECT_EQ(t.Face(f).res.ulog2, t.Face(f).res.vlog2) << f;
            largest = std::max(largest, int(t.Face(f).res.ulog2));
            std::vector<float> mean(1);
            t.Mean(f, 0, mean.data());
            EXPECT_GE(mean[0], 0.0f);
            EXPECT_LE(mean[0], 1.0f);
        }
        EXPECT_EQ(largest, 3);  // --resolution 8
    }
}

TEST(Bake, RejectsBadSettings) {
    BakeOptions bake;
    bake.resolution = 12;
    EXPECT_THROW(CheckBakeOptions(bake), InputError);
    bake.resolution = 8;
    bake.samples = 0;
    EXPECT_THROW(CheckBakeOptions(bake), InputError);
    bake.samples = 4;
    bake.integrator = IntegratorKind::Normal;
    EXPECT_THROW(CheckBakeOptions(bake), InputError);
    bake.integrator = IntegratorKind::Path;
    EXPECT_NO_THROW(CheckBakeOptions(bake));
}

}  // namespace
}  // namespace texcache
