// SPDX-License-Identifier: Apache-2.0
// Scene files: a valid scene round-trips; every kind of bad input names the file and key.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "renderer/camera.h"
#include "renderer/scene_loader.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

std::string WriteScene(const std::string& name, const std::string& json) {
    const fs::path dir = fs::path(::testing::TempDir()) / "texcache_scenes";
    fs::create_directories(dir);
    // Meshes are referenced relative to the scene file: point at the bundled ones.
    const fs::path p = dir / name;
    std::ofstream(p) << json;
    return p.string();
}

std::string Mesh() {
    return "\"" + test::MeshPath("catmark_cube") + "\"";
}

std::string Valid() {
    return R"({
  "camera": {"position": [0, 1, 5], "look_at": [0, 0, 0], "fov": 45, "shutter": [0, 0.5]},
  "materials": {"red": {"type": "ggx", "albedo": [0.8, 0.1, 0.1], "roughness": 0.3},
                "chk": {"albedo": {"texture": "checker", "colors": [[1,1,1],[0,0,0]], "scale": 4}}},
  "objects": [{"name": "a", "mesh": )" +
           Mesh() + R"(, "material": "red",
               "keyframes": [{"time": 0, "translate": [0,0,0]}, {"time": 1, "translate": [1,0,0], "rotate": [90, 0, 1, 0]}]},
              {"mesh": )" +
           Mesh() + R"(, "material": "chk", "transform": {"scale": 2}}],
  "lights": [{"type": "environment", "constant": [1, 1, 1]},
             {"type": "quad", "corner": [0,2,0], "edge1": [1,0,0], "edge2": [0,0,1], "radiance": [5,5,5]},
             {"type": "distant", "direction": [0,-1,0], "irradiance": [2,2,2]}],
  "render": {"resolution": [320, 200], "spp": 8, "integrator": "ao", "seed": 3, "tessellation_rate": 4}
})";
}

TEST(SceneLoader, ValidSceneRoundTrips) {
    std::vector<std::string> w;
    const Scene s = LoadScene(WriteScene("valid.json", Valid()), &w);
    EXPECT_EQ(s.objects.size(), 2u);
    EXPECT_EQ(s.meshes.size(), 1u);  // the shared OBJ is loaded once
    EXPECT_EQ(s.materials.size(), 2u);
    EXPECT_EQ(s.materials[s.objects[0].material].type, Material::Type::GGX);
    EXPECT_EQ(s.textures.size(), 1u);
    EXPECT_EQ(s.environments.size(), 1u);
    EXPECT_EQ(s.quadLights.size(), 1u);
    EXPECT_EQ(s.distantLights.size(), 1u);
    EXPECT_EQ(s.settings.width, 320);
    EXPECT_EQ(s.settings.integrator, "ao");
    EXPECT_FLOAT_EQ(s.settings.tessellationRate, 4.0f);
    EXPECT_FLOAT_EQ(s.camera.shutterClose, 0.5f);
    EXPECT_TRUE(s.objects[0].transform.IsAnimated());
    EXPECT_FALSE(s.objects[1].transform.IsAnimated());
    // Keyframes interpolate: halfway is 45 degrees about Y and x = 0.5.
    const glm::mat4 M = s.objects[0].transform.Eval(0.5f);
    EXPECT_NEAR(M[3][0], 0.5f, 1e-6f);
    const glm::vec3 x = glm::mat3(M) * glm::vec3(1, 0, 0);
    EXPECT_NEAR(x.x, std::cos(glm::radians(45.0f)), 1e-5f);
    EXPECT_NEAR(x.z, -std::sin(glm::radians(45.0f)), 1e-5f);
    // Clamped outside the keys.
    EXPECT_NEAR(s.objects[0].transform.Eval(7.0f)[3][0], 1.0f, 1e-6f);
    EXPECT_NEAR(s.objects[0].transform.Eval(-1.0f)[3][0], 0.0f, 1e-6f);
}

TEST(SceneLoader, BareObjIsFramedByTheDefaultCamera) {
    std::vector<std::string> w;
    for (const char* name : {"catmark_car", "catmark_pawn", "catmark_torus"}) {
        const Scene s =
            SceneFromObj(test::MeshPath(name), test::SceneDir() + "/envmaps/studio.exr", &w);
        const CameraModel cam(s.camera, 0.0f, 640, 360);
        for (const auto& p : s.meshes[0].positions) {
            glm::vec2 film;
            ASSERT_TRUE(cam.Project({p[0], p[1], p[2]}, &film)) << name;
            EXPECT_GE(film.x, 0.0f) << name;
            EXPECT_LE(film.x, 640.0f) << name;
            EXPECT_GE(film.y, 0.0f) << name;
            EXPECT_LE(film.y, 360.0f) << name;
        }
    }
}

TEST(SceneLoader, BadInputNamesFileAndKey) {
    struct Case {
        std::string from, to, expect;
    };
    const std::vector<Case> cases = {
        {"\"fov\": 45", "\"fvo\": 45", "camera.fvo"},
        {"\"fov\": 45", "\"fov\": \"45\"", "expected a number"},
        {"\"fov\": 45", "\"fov\": 190", "camera.fov"},
        {"\"spp\": 8", "\"spp\": -1", "render.spp"},
        {"\"spp\": 8", "\"spp\": 2.5", "expected an integer"},
        {"[320, 200]", "[0, 200]", "render.resolution"},
        {"\"integrator\": \"ao\"", "\"integrator\": \"magic\"", "valid: normal, ptex, uv"},
        {"\"roughness\": 0.3", "\"roughness\": 1.5", "materials.red.roughness"},
        {"\"material\": \"red\"", "\"material\": \"blue\"", "unknown material 'blue'"},
        {"\"type\": \"distant\"", "\"type\": \"spot\"", "unknown light type"},
        {"\"look_at\": [0, 0, 0]", "\"look_at\": [0, 1, 5]", "look_at equals position"},
        {"\"position\": [0, 1, 5]", "\"position\": [0, 5, 0]", "up is parallel"},
        {"{\"time\": 1, \"translate\"", "{\"time\": 0, \"translate\"", "times must increase"},
        {"\"irradiance\": [2,2,2]", "\"irradiance\": [2,2]", "array of 3 numbers"},
        {Mesh(), "\"missing.obj\"", "does not exist"},
    };
    std::vector<std::string> w;
    for (const Case& c : cases) {
        std::string text = Valid();
        const size_t at = text.find(c.from);
        ASSERT_NE(at, std::string::npos) << c.from;
        text.replace(at, c.from.size(), c.to);
        const std::string path = WriteScene("bad.json", text);
        try {
            LoadScene(path, &w);
            ADD_FAILURE() << "no error for " << c.to;
        } catch (const InputError& e) {
            const std::string msg = e.what();
            EXPECT_NE(msg.find("bad.json"), std::string::npos) << msg;
            EXPECT_NE(msg.find(c.expect), std::string::npos) << c.to << " -> " << msg;
        }
    }
}

TEST(SceneLoader, JsonSyntaxErrorsReportLineAndColumn) {
    std::vector<std::string> w;
    const std::string path =
        WriteScene("syntax.json", "{\n  \"camera\": {\n    \"fov\": 45,,\n  }\n}\n");
    try {
        LoadScene(path, &w);
        FAIL();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("syntax.json:3:"), std::string::npos) << e.what();
    }
    EXPECT_THROW(LoadScene("/nonexistent/scene.json", &w), InputError);
}

TEST(SceneLoader, BundledScenesLoad) {
    std::vector<std::string> w;
    for (const char* name : {"car.json", "chess.json", "features.json"}) {
        const Scene s = LoadScene(test::SceneDir() + "/" + name, &w);
        EXPECT_FALSE(s.objects.empty()) << name;
    }
}

}  // namespace
}  // namespace texcache
