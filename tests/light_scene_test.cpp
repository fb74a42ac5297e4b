// SPDX-License-Identifier: Apache-2.0
// The scene file's lights (point, spot, sun, distant with an angle), emissive objects and plain
// meshes: a valid file fills the structs, bad values are errors naming the file and the key, and
// the bundled scene with every kind of light loads and renders finite.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "renderer/render.h"
#include "renderer/render_policy.h"
#include "renderer/scene/scene_loader.h"
#include "test_util.h"
#include "texcache/error.h"
#include "torus_scene.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

std::string WriteScene(const std::string& name, const std::string& text) {
    const fs::path dir = fs::path(::testing::TempDir()) / "texcache_light_scene";
    fs::create_directories(dir);
    const fs::path p = dir / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
}

std::string Mesh() {
    return "\"" + test::MeshPath("catmark_cube") + "\"";
}

/// A scene of one cube with `objectExtra` added to the object and `lights` as its lights.
std::string SceneText(const std::string& lights, const std::string& objectExtra = "") {
    return R"({"camera": {"position": [0, 1, 5], "look_at": [0, 0, 0]},
  "objects": [{"mesh": )" +
           Mesh() + objectExtra + R"(}],
  "lights": [)" +
           lights + R"(]})";
}

/// The message of the InputError loading `text` throws ("" when it loads).
std::string LoadError(const std::string& name, const std::string& text) {
    try {
        LoadScene(WriteScene(name, text), nullptr);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(LightScene, EveryKindLoads) {
    const std::string path = WriteScene(
        "ok.json",
        SceneText(
            R"({"type": "point", "position": [1, 2, 3], "intensity": [4, 5, 6], "radius": 0.5},
               {"type": "spot", "position": [0, 3, 0], "intensity": [2, 2, 2], "direction": [0, -2, 0],
                "outer_angle": 40, "inner_angle": 10},
               {"type": "spot", "position": [0, 3, 0], "intensity": [1, 1, 1], "direction": [1, 0, 0]},
               {"type": "sun", "direction": [0, -1, 0], "irradiance": [3, 3, 3]},
               {"type": "distant", "direction": [0, -1, 0], "irradiance": [1, 1, 1], "angle": 2})",
            R"(, "subdivision": "none", "emission": {"radiance": [1, 2, 3], "scale": 2, "two_sided": true})"));
    const Scene s = LoadScene(path, nullptr);
    ASSERT_EQ(s.pointLights.size(), 3u);
    EXPECT_EQ(s.pointLights[0].position, glm::vec3(1, 2, 3));
    EXPECT_EQ(s.pointLights[0].intensity, glm::vec3(4, 5, 6));
    EXPECT_EQ(s.pointLights[0].radius, 0.5f);
    EXPECT_FALSE(s.pointLights[0].spot);
    EXPECT_TRUE(s.pointLights[1].spot);
    EXPECT_EQ(s.pointLights[1].direction, glm::vec3(0, -1, 0));  // normalised
    EXPECT_EQ(s.pointLights[1].outerDegrees, 40.0f);
    EXPECT_EQ(s.pointLights[1].innerDegrees, 10.0f);
    EXPECT_EQ(s.pointLights[1].radius, 0.0f);
    EXPECT_EQ(s.pointLights[2].outerDegrees, 30.0f);  // defaults: 30, and 5/6 of it
    EXPECT_EQ(s.pointLights[2].innerDegrees, 25.0f);
    ASSERT_EQ(s.distantLights.size(), 2u);
    EXPECT_EQ(s.distantLights[0].angleDegrees, 0.53f);  // the sun's
    EXPECT_EQ(s.distantLights[1].angleDegrees, 2.0f);
    ASSERT_EQ(s.objects.size(), 1u);
    EXPECT_FALSE(s.objects[0].subdivide);
    EXPECT_EQ(s.objects[0].emission, glm::vec3(2, 4, 6));
    EXPECT_TRUE(s.objects[0].emissionTwoSided);
    const LightKinds k = SceneLightKinds(s);
    EXPECT_TRUE(k.soft);
    EXPECT_TRUE(k.delta);
}

// The same OBJ as a subdivision surface and as a plain mesh: two meshes (one Embree geometry
// each); two objects of the same form share one.
TEST(LightScene, SubdivisionFormsGetTheirOwnMesh) {
    const std::string path =
        WriteScene("forms.json", R"({"camera": {"position": [0, 1, 5], "look_at": [0, 0, 0]},
  "objects": [{"mesh": )" + Mesh() + R"(}, {"mesh": )" +
                                     Mesh() + R"(, "subdivision": "none"}, {"mesh": )" + Mesh() +
                                     R"(, "subdivision": "catmull-clark"}],
  "lights": [{"type": "point", "position": [0, 3, 0], "intensity": [1, 1, 1]}]})");
    const Scene s = LoadScene(path, nullptr);
    ASSERT_EQ(s.meshes.size(), 2u);
    EXPECT_EQ(s.objects[0].mesh, 0);
    EXPECT_EQ(s.objects[1].mesh, 1);
    EXPECT_EQ(s.objects[2].mesh, 0);
    EXPECT_EQ(s.meshes[1].positions, s.meshes[0].positions);
}

// Negative, out-of-range and inconsistent values name the file and the key path.
TEST(LightScene, BadValuesNameTheKey) {
    struct Case {
        std::string lights, objectExtra, expected;
    };
    const Case cases[] = {
        {R"({"type": "point", "position": [0, 1, 0], "intensity": [1, -1, 1]})", "",
         "key 'lights[0].intensity[1]': value -1 is out of range"},
        {R"({"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1], "radius": -0.1})", "",
         "key 'lights[0].radius': value -0.1 is out of range"},
        {R"({"type": "point", "position": [0, 1, 0]})", "",
         "key 'lights[0].intensity': missing (required)"},
        {R"({"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1], "direction": [0, -1, 0]})",
         "", "key 'lights[0].direction': unknown key"},
        {R"({"type": "spot", "position": [0, 1, 0], "intensity": [1, 1, 1], "direction": [0, 0, 0]})",
         "", "key 'lights[0].direction': direction is zero"},
        {R"({"type": "spot", "position": [0, 1, 0], "intensity": [1, 1, 1], "direction": [0, -1, 0],
             "outer_angle": 20, "inner_angle": 30})",
         "", "key 'lights[0].inner_angle': the inner angle 30 is larger than the outer angle 20"},
        {R"({"type": "spot", "position": [0, 1, 0], "intensity": [1, 1, 1], "direction": [0, -1, 0],
             "outer_angle": 180})",
         "", "key 'lights[0].outer_angle': value 180 is out of range (0, 180)"},
        {R"({"type": "sun", "direction": [0, -1, 0], "irradiance": [1, 1, 1], "angle": -1})", "",
         "key 'lights[0].angle': value -1 is out of range"},
        {R"({"type": "sun", "direction": [0, -1, 0], "irradiance": [1, 1, "x"]})", "",
         "key 'lights[0].irradiance[2]': expected a number"},
        {R"({"type": "lamp"})", "", "key 'lights[0].type': unknown light type 'lamp'"},
        {"", R"(, "emission": [1, -2, 1])",
         "key 'objects[0].emission[1]': value -2 is out of range"},
        {"", R"(, "emission": {"radiance": [1, 1, 1], "scale": -3})",
         "key 'objects[0].emission.scale': value -3 is out of range"},
        {"", R"(, "emission": {"scale": 3})", "key 'objects[0].emission.radiance': missing"},
        {"", R"(, "emission": {"radiance": [1, 1, 1], "power": 3})",
         "key 'objects[0].emission.power': unknown key"},
        {"", R"(, "emission": {"radiance": [1e30, 1, 1], "scale": 1e30})",
         "key 'objects[0].emission.scale': radiance x scale overflows a float"},
        {"", R"(, "subdivision": "loop")",
         "key 'objects[0].subdivision': unknown subdivision 'loop' (valid: catmull-clark, none)"},
    };
    int i = 0;
    for (const Case& c : cases) {
        const std::string name = "bad" + std::to_string(i++) + ".json";
        const std::string msg = LoadError(name, SceneText(c.lights, c.objectExtra));
        EXPECT_NE(msg.find(name), std::string::npos) << msg;
        EXPECT_NE(msg.find(c.expected), std::string::npos) << msg << "\n  expected: " << c.expected;
    }
}

// NaN cannot be written in JSON, and a number too large for a double is an error at its line;
// one too large for a float (the scene's values are floats) is out of range.
TEST(LightScene, NonFiniteValuesAreErrors) {
    const std::string nan = LoadError(
        "nan.json",
        SceneText(R"({"type": "point", "position": [0, 1, 0], "intensity": [NaN, 1, 1]})"));
    EXPECT_NE(nan.find("nan.json:"), std::string::npos) << nan;
    const std::string big = LoadError(
        "big.json",
        SceneText(R"({"type": "point", "position": [0, 1, 0], "intensity": [1e999, 1, 1]})"));
    EXPECT_NE(big.find("big.json:"), std::string::npos) << big;
    const std::string huge = LoadError(
        "huge.json",
        SceneText(R"({"type": "point", "position": [0, 1, 0], "intensity": [1e31, 1, 1]})"));
    EXPECT_NE(huge.find("key 'lights[0].intensity[0]': value 1e+31 is out of range"),
              std::string::npos)
        << huge;
}

// The bundled scene with every kind of light (scenes/lights.json) loads, and renders finite per
// hit and in texture space (small and short: the figures are in results/lights.md).
TEST(LightScene, BundledSceneRenders) {
    Scene s = LoadScene(test::SceneDir() + "/lights.json", nullptr);
    EXPECT_FALSE(s.pointLights.empty());
    const LightKinds k = SceneLightKinds(s);
    EXPECT_TRUE(k.soft && k.delta);
    const RenderScene rs(s, {});
    RenderOptions o;
    o.width = 48;
    o.height = 27;
    o.spp = 4;
    o.progress = false;
    o.integrator = IntegratorKind::Path;
    const Image hit = Render(rs, o).beauty;
    EXPECT_TRUE(test::AllFiniteIn(hit, 0.0f, 1e4f));
    o.texture.enabled = true;
    o.texture.samples = TextureSamples::Hits;
    o.texture.cacheDirect = o.texture.deltaDirectPerHit = true;
    const Image ts = Render(rs, o).beauty;
    EXPECT_TRUE(test::AllFiniteIn(ts, 0.0f, 1e4f));
}

}  // namespace
}  // namespace texcache
