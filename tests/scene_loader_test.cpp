// SPDX-License-Identifier: Apache-2.0
// Scene files: a valid scene round-trips into the structs; every kind of bad input names the file
// and the key path; bare OBJs are framed; keyframed transforms interpolate and clamp.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <glm/gtc/matrix_transform.hpp>

#include "renderer/scene/scene_loader.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

fs::path TempDir() {
    const fs::path dir = fs::path(::testing::TempDir()) / "texcache_scene_loader";
    fs::create_directories(dir);
    return dir;
}

std::string WriteFile(const std::string& name, const std::string& text) {
    const fs::path p = TempDir() / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
}

bool Contains(const std::string& s, const std::string& part) {
    return s.find(part) != std::string::npos;
}

std::string Mesh() {
    return "\"" + test::MeshPath("catmark_cube") + "\"";
}

std::string Valid() {
    return R"({
  "camera": {"position": [0, 1, 5], "look_at": [0, 0, 0], "fov": 45, "shutter": [0, 0.5],
             "lens_radius": 0.1, "focus_distance": 5},
  "materials": {"red": {"type": "ggx", "albedo": [0.8, 0.1, 0.1], "roughness": 0.3,
                        "specular": [0.05, 0.05, 0.05], "filter": "gaussian", "filter_radius": 3},
                "chk": {"albedo": {"texture": "checker", "colors": [[1,1,1],[0,0,0]], "scale": 4}}},
  "objects": [{"name": "a", "mesh": )" +
           Mesh() + R"(, "material": "red",
               "keyframes": [{"time": 0, "translate": [0,0,0]}, {"time": 1, "translate": [1,0,0], "rotate": [90, 0, 1, 0]}]},
              {"mesh": )" +
           Mesh() + R"(, "material": "chk", "transform": {"scale": 2}}],
  "lights": [{"type": "environment", "constant": [1, 1, 1], "intensity": 2, "rotation": 30},
             {"type": "quad", "corner": [0,2,0], "edge1": [1,0,0], "edge2": [0,0,1], "radiance": [5,5,5]},
             {"type": "distant", "direction": [0,-2,0], "irradiance": [2,2,2]}],
  "render": {"resolution": [320, 200], "spp": 8, "integrator": "ao", "seed": 3, "tessellation_rate": 4,
             "max_depth": 3, "ao_samples": 2, "ao_distance": 0.5, "time": 0.25, "seconds": 1.5}
})";
}

TEST(SceneLoader, ValidSceneRoundTrips) {
    std::vector<std::string> w;
    const Scene s = LoadScene(WriteFile("valid.json", Valid()), &w);
    EXPECT_TRUE(w.empty()) << w[0];
    ASSERT_EQ(s.objects.size(), 2u);
    EXPECT_EQ(s.meshes.size(), 1u);  // the shared OBJ is loaded once
    EXPECT_EQ(s.objects[0].mesh, 0);
    EXPECT_EQ(s.objects[1].mesh, 0);
    EXPECT_EQ(s.objects[0].name, "a");
    EXPECT_EQ(s.objects[1].name, "object1");
    EXPECT_TRUE(fs::path(s.objects[0].objPath).is_absolute());
    EXPECT_EQ(s.meshes[0].numFaces(), 6);

    ASSERT_EQ(s.materials.size(), 2u);
    const Material& red = s.materials[size_t(s.objects[0].material)];
    EXPECT_EQ(red.name, "red");
    EXPECT_EQ(red.type, Material::Type::GGX);
    EXPECT_FLOAT_EQ(red.albedo.value.g, 0.1f);
    EXPECT_FLOAT_EQ(red.roughness.value, 0.3f);
    EXPECT_FLOAT_EQ(red.specular.r, 0.05f);
    EXPECT_EQ(red.cacheFilter, "gaussian");
    EXPECT_EQ(red.cacheRadius, 3);
    const Material& chk = s.materials[size_t(s.objects[1].material)];
    EXPECT_EQ(chk.type, Material::Type::Diffuse);
    ASSERT_EQ(s.textures.size(), 1u);
    EXPECT_EQ(chk.albedo.texture, 0);
    EXPECT_EQ(s.textures[0].kind, Texture::Kind::Checker);
    EXPECT_FLOAT_EQ(s.textures[0].scale, 4.0f);
    EXPECT_EQ(s.textures[0].colorB, glm::vec3(0.0f));

    ASSERT_EQ(s.environments.size(), 1u);
    EXPECT_TRUE(s.environments[0].path.empty());
    EXPECT_EQ(s.environments[0].constant, glm::vec3(1.0f));
    EXPECT_FLOAT_EQ(s.environments[0].intensity, 2.0f);
    EXPECT_FLOAT_EQ(s.environments[0].rotationDegrees, 30.0f);
    ASSERT_EQ(s.quadLights.size(), 1u);
    EXPECT_EQ(s.quadLights[0].corner, glm::vec3(0, 2, 0));
    EXPECT_FALSE(s.quadLights[0].twoSided);
    ASSERT_EQ(s.distantLights.size(), 1u);
    EXPECT_EQ(s.distantLights[0].direction, glm::vec3(0, -1, 0));  // normalised

    EXPECT_EQ(s.settings.width, 320);
    EXPECT_EQ(s.settings.height, 200);
    EXPECT_EQ(s.settings.spp, 8);
    EXPECT_EQ(s.settings.integrator, IntegratorKind::AO);
    EXPECT_EQ(s.settings.seed, 3u);
    EXPECT_EQ(s.settings.maxDepth, 3);
    EXPECT_EQ(s.settings.aoSamples, 2);
    EXPECT_FLOAT_EQ(s.settings.aoDistance, 0.5f);
    EXPECT_FLOAT_EQ(s.settings.time, 0.25f);
    EXPECT_FLOAT_EQ(s.settings.seconds, 1.5f);
    EXPECT_FLOAT_EQ(s.settings.tessellationRate, 4.0f);

    EXPECT_FLOAT_EQ(s.camera.fovYDegrees, 45.0f);
    EXPECT_FLOAT_EQ(s.camera.lensRadius, 0.1f);
    EXPECT_FLOAT_EQ(s.camera.focusDistance, 5.0f);
    EXPECT_FLOAT_EQ(s.camera.shutterClose, 0.5f);
    // The camera's -Z looks at look_at, its +Y is the part of up orthogonal to the view.
    const glm::mat4 C = s.camera.pose.Eval(0.0f);
    const glm::vec3 fwd = glm::mat3(C) * glm::vec3(0, 0, -1);
    const glm::vec3 want = glm::normalize(glm::vec3(0, -1, -5));
    EXPECT_NEAR(glm::dot(fwd, want), 1.0f, 1e-6f);
    const glm::vec3 up = glm::mat3(C) * glm::vec3(0, 1, 0);
    EXPECT_NEAR(glm::dot(up, fwd), 0.0f, 1e-6f);
    EXPECT_GT(up.y, 0.98f);
    EXPECT_NEAR((glm::mat3(C) * glm::vec3(1, 0, 0)).x, 1.0f, 1e-6f);  // right is +X
    EXPECT_EQ(glm::vec3(C[3]), glm::vec3(0, 1, 5));

    EXPECT_TRUE(s.objects[0].transform.IsAnimated());
    EXPECT_FALSE(s.objects[1].transform.IsAnimated());
    EXPECT_FLOAT_EQ(s.objects[1].transform.Eval(0.0f)[1][1], 2.0f);
}

TEST(SceneLoader, PathsAreRelativeToTheSceneFileAndCommentsAreAllowed) {
    // A scene in a subdirectory referencing its own mesh, an image texture and an environment.
    WriteFile("rel/meshes/tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nt hole 1/0/0 5\n");
    WriteFile("rel/tex/wood.png", "not really a png: only existence is checked");
    WriteFile("rel/env.exr", "");
    const std::string path = WriteFile("rel/scene.json", R"({
      // comments are allowed
      "materials": {"wood": {"type": "ggx", "albedo": {"texture": "tex/wood.png"},
                             "roughness": {"texture": "checker"}}},
      "objects": [{"mesh": "meshes/tri.obj", "material": "wood"},
                  {"mesh": "meshes/../meshes/tri.obj"}],  /* same file */
      "lights": [{"type": "environment", "file": "env.exr"}]
    })");
    std::vector<std::string> w;
    const Scene s = LoadScene(path, &w);
    const fs::path dir = fs::absolute(TempDir() / "rel").lexically_normal();
    EXPECT_EQ(s.objects[0].objPath, (dir / "meshes/tri.obj").string());
    EXPECT_EQ(s.meshes.size(), 1u);
    ASSERT_EQ(s.textures.size(), 2u);
    EXPECT_EQ(s.textures[0].kind, Texture::Kind::Image);
    EXPECT_EQ(s.textures[0].path, (dir / "tex/wood.png").string());
    EXPECT_EQ(s.textures[1].kind, Texture::Kind::Checker);
    EXPECT_EQ(s.materials[0].roughness.texture, 1);
    EXPECT_EQ(s.environments[0].path, (dir / "env.exr").string());
    // The object without a material gets a grey diffuse default.
    ASSERT_EQ(s.materials.size(), 2u);
    EXPECT_EQ(s.materials[size_t(s.objects[1].material)].name, "default");
    // OBJ warnings reach the caller with the OBJ's own file and line.
    ASSERT_EQ(w.size(), 1u);
    EXPECT_TRUE(Contains(w[0], "tri.obj:5: hole names face 5")) << w[0];
    // No camera: the default one frames the objects.
    ASSERT_EQ(s.camera.pose.keys.size(), 1u);
    EXPECT_GT(glm::length(s.camera.pose.keys[0].translation), 0.5f);
}

/// Every corner of the box projects into a width x height image (pinhole, camera looks down -Z).
void ExpectFramed(const Camera& cam, glm::vec3 lo, glm::vec3 hi, int width, int height,
                  const std::string& what) {
    const glm::mat4 worldToCam = glm::inverse(cam.pose.Eval(0.0f));
    const float tanY = std::tan(glm::radians(cam.fovYDegrees) * 0.5f);
    const float tanX = tanY * float(width) / float(height);
    for (int i = 0; i < 8; ++i) {
        const glm::vec3 p(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z);
        const glm::vec3 c(worldToCam * glm::vec4(p, 1.0f));
        ASSERT_LT(c.z, 0.0f) << what;
        // Normalised film coordinates in [-1, 1]; the framing leaves a margin.
        EXPECT_LT(std::abs(c.x / -c.z / tanX), 0.95f) << what << " corner " << i;
        EXPECT_LT(std::abs(c.y / -c.z / tanY), 0.95f) << what << " corner " << i;
    }
    // Looking down at it from above (+Y up), not from below.
    EXPECT_GT(glm::vec3(cam.pose.Eval(0.0f)[3]).y, 0.5f * (lo.y + hi.y)) << what;
}

TEST(SceneLoader, BareObjIsFramedByTheDefaultCamera) {
    for (const std::string& name : test::BundledMeshes()) {
        std::vector<std::string> w;
        const Scene s =
            SceneFromObj(test::MeshPath(name), test::SceneDir() + "/envmaps/studio.exr", &w);
        ASSERT_EQ(s.objects.size(), 1u);
        ASSERT_EQ(s.materials.size(), 1u);
        EXPECT_EQ(s.materials[0].type, Material::Type::Diffuse);
        ASSERT_EQ(s.environments.size(), 1u);
        EXPECT_EQ(s.environments[0].path, test::SceneDir() + "/envmaps/studio.exr");
        glm::vec3 lo(1e30f), hi(-1e30f);
        for (const auto& p : s.meshes[0].positions) {
            lo = glm::min(lo, glm::vec3(p[0], p[1], p[2]));
            hi = glm::max(hi, glm::vec3(p[0], p[1], p[2]));
        }
        ExpectFramed(s.camera, lo, hi, s.settings.width, s.settings.height, name);
    }
    // A missing default environment map: constant white, with a warning.
    std::vector<std::string> w;
    const Scene s = SceneFromObj(test::MeshPath("catmark_cube"), "/nonexistent/studio.exr", &w);
    EXPECT_TRUE(s.environments[0].path.empty());
    EXPECT_EQ(s.environments[0].constant, glm::vec3(1.0f));
    ASSERT_EQ(w.size(), 1u);
    EXPECT_TRUE(Contains(w[0], "/nonexistent/studio.exr")) << w[0];
}

TEST(SceneLoader, SceneWithoutCameraFramesItsObjects) {
    std::vector<std::string> w;
    const Scene s = LoadScene(WriteFile("nocam.json", R"({
      "objects": [{"mesh": )" + Mesh() + R"(, "transform": {"translate": [10, 0, 0]}},
                  {"mesh": )" + Mesh() + R"(, "transform": {"translate": [-4, 2, 1], "scale": 3}}],
      "render": {"resolution": [200, 400]}
    })"),
                              &w);
    // Cube vertices are at +-1: the world box of both objects.
    ExpectFramed(s.camera, {-7, -1, -2}, {11, 5, 4}, 200, 400, "portrait");
}

TEST(SceneLoader, BadInputNamesFileAndKey) {
    struct Case {
        std::string from, to, expect;
    };
    const std::vector<Case> cases = {
        {"\"fov\": 45", "\"fvo\": 45",
         "key 'camera.fvo': unknown key (expected one of: position, look_at, up, fov"},
        {"\"fov\": 45", "\"fov\": \"45\"", "key 'camera.fov': expected a number, got the string"},
        {"\"fov\": 45", "\"fov\": 180", "key 'camera.fov': value 180 is out of range (0, 180)"},
        {"\"fov\": 45", "\"fov\": 0", "key 'camera.fov': value 0 is out of range (0, 180)"},
        {"\"fov\": 45", "\"fov\": 1e999", "bad.json:2:66: JSON number overflow parsing '1e999'"},
        {"\"lens_radius\": 0.1", "\"lens_radius\": -1", "key 'camera.lens_radius'"},
        {"\"focus_distance\": 5", "\"focus_distance\": 0", "key 'camera.focus_distance'"},
        {"\"shutter\": [0, 0.5]", "\"shutter\": [1, 0.5]", "closes before it opens"},
        {"\"shutter\": [0, 0.5]", "\"shutter\": [0]", "key 'camera.shutter': expected [open"},
        {"\"look_at\": [0, 0, 0]", "\"look_at\": [0, 1, 5]", "look_at equals position"},
        {"\"position\": [0, 1, 5]", "\"position\": [0, 5, 0]", "up is parallel"},
        {"\"fov\": 45", "\"fov\": 45, \"up\": [0, 0, 0]", "up is zero"},
        {"\"position\": [0, 1, 5], ", "", "key 'camera': the camera needs 'position' and"},
        {"\"spp\": 8", "\"spp\": \"16\"",
         "key 'render.spp': expected a positive integer, got the string \"16\""},
        {"\"spp\": 8", "\"spp\": -1", "key 'render.spp': expected a positive integer"},
        {"\"spp\": 8", "\"spp\": 0", "key 'render.spp': value 0 is out of range [1, "},
        {"\"spp\": 8", "\"spp\": 2.5", "expected a positive integer, got the number 2.5"},
        {"\"spp\": 8", "\"spp\": 18446744073709551615", "render.spp"},
        {"[320, 200]", "[0, 200]",
         "key 'render.resolution[0]': value 0 is out of range [1, 16384]"},
        {"[320, 200]", "[320, 16385]", "key 'render.resolution[1]'"},
        {"[320, 200]", "[320]", "key 'render.resolution': expected [width, height]"},
        {"\"integrator\": \"ao\"", "\"integrator\": \"magic\"",
         "unknown integrator 'magic' (valid: normal, ptex, uv, eyelight, ao, direct, path)"},
        {"\"tessellation_rate\": 4", "\"tessellation_rate\": 0.5", "render.tessellation_rate"},
        {"\"seed\": 3", "\"seed\": -3", "render.seed"},
        {"\"max_depth\": 3", "\"max_depth\": 3, \"maxdepth\": 3", "key 'render.maxdepth'"},
        {"\"roughness\": 0.3", "\"roughness\": 1.5", "key 'materials.red.roughness': value 1.5"},
        {"\"roughness\": 0.3", "\"roughness\": [0.3, 0.2, 0.1]",
         "key 'materials.red.roughness': expected a number or an array of 2 numbers"},
        {"\"roughness\": 0.3", "\"roughness\": [0.3, -0.2]", "key 'materials.red.roughness[1]'"},
        {"\"albedo\": [0.8, 0.1, 0.1]", "\"albedo\": [0.8, 0.1, -0.1]",
         "key 'materials.red.albedo[2]'"},
        {"\"type\": \"ggx\"", "\"type\": \"plastic\"",
         "unknown material type 'plastic' (valid: diffuse, ggx)"},
        {"\"filter\": \"gaussian\"", "\"filter\": \"box\"", "unknown filter 'box'"},
        {"\"filter_radius\": 3", "\"filter_radius\": 33", "materials.red.filter_radius"},
        {"\"scale\": 4", "\"scale\": 4, \"size\": 1", "key 'materials.chk.albedo.size'"},
        {"{\"texture\": \"checker\", \"colors\": [[1,1,1],[0,0,0]], \"scale\": 4}",
         "{\"texture\": \"missing.png\"}", "key 'materials.chk.albedo.texture': texture file '"},
        {"\"texture\": \"checker\"", "\"texture\": \"valid.json\"",
         "key 'materials.chk.albedo.texture': the image texture 'valid.json' takes no "
         "parameters, but 'colors' is given"},
        {"\"material\": \"red\"", "\"material\": \"blue\"",
         "key 'objects[0].material': unknown material 'blue' (defined: chk, red)"},
        {"\"name\": \"a\", \"mesh\": " + Mesh(), "\"name\": \"a\"",
         "key 'objects[0].mesh': missing (required)"},
        {Mesh(), "\"missing.obj\"", "key 'objects[0].mesh': mesh file '"},
        {Mesh(), "42", "key 'objects[0].mesh': expected a string, got the number 42"},
        {"{\"time\": 1, \"translate\"", "{\"time\": 0, \"translate\"",
         "key 'objects[0].keyframes[1].time': keyframe times must increase"},
        {"{\"time\": 1, \"translate\"", "{\"translate\"", "objects[0].keyframes[1].time': missing"},
        {"\"rotate\": [90, 0, 1, 0]", "\"rotate\": [90, 0, 0, 0]", "rotation axis is zero"},
        {"\"rotate\": [90, 0, 1, 0]", "\"rotate\": [0, 1, 0]", "expected [angle_degrees"},
        {"\"scale\": 2", "\"scale\": 0", "key 'objects[1].transform.scale'"},
        {"\"transform\": {\"scale\": 2}", "\"transform\": {\"scale\": 2}, \"keyframes\": []",
         "not both"},
        {"\"type\": \"distant\"", "\"type\": \"laser\"",
         "unknown light type 'laser' (valid: environment, quad, distant, sun, point, spot)"},
        {"\"irradiance\": [2,2,2]", "\"irradiance\": [2,2]",
         "key 'lights[2].irradiance': expected an array of 3 numbers, got an array of 2"},
        {"\"direction\": [0,-2,0]", "\"direction\": [0,0,0]", "direction is zero"},
        {"\"edge2\": [0,0,1]", "\"edge2\": [2,0,0]", "zero area"},
        {"\"radiance\": [5,5,5]", "\"radiance\": [5,5,5], \"two_sided\": 1",
         "key 'lights[1].two_sided': expected true or false"},
        {"\"corner\": [0,2,0], ", "", "key 'lights[1].corner': missing (required)"},
        {"\"constant\": [1, 1, 1]", "\"file\": \"nope.exr\"", "environment map '"},
        {"\"constant\": [1, 1, 1]", "\"constant\": [1, 1, 1], \"file\": \"x.exr\"",
         "exactly one of 'file' or 'constant'"},
        {"\"fov\": 45", "\"fov\": 45, \"fov\": 46", "key 'camera.fov': duplicate key"},
        {"\"seed\": 3", "\"seed\": 3, \"seed\": 3", "key 'render.seed': duplicate key"},
    };
    std::vector<std::string> w;
    for (const Case& c : cases) {
        std::string text = Valid();
        const size_t at = text.find(c.from);
        ASSERT_NE(at, std::string::npos) << c.from;
        text.replace(at, c.from.size(), c.to);
        const std::string path = WriteFile("bad.json", text);
        try {
            LoadScene(path, &w);
            ADD_FAILURE() << "no error for " << c.to;
        } catch (const InputError& e) {
            const std::string msg = e.what();
            EXPECT_TRUE(Contains(msg, path)) << msg;
            EXPECT_TRUE(Contains(msg, c.expect)) << c.to << " -> " << msg;
        }
    }
}

TEST(SceneLoader, StructuralErrors) {
    struct Case {
        std::string json, expect;
    };
    const std::string m = Mesh();
    const std::vector<Case> cases = {
        {"[1, 2]", "s.json: expected an object, got an array"},
        {"{}", "key 'objects': missing (required)"},
        {"{\"objects\": []}", "key 'objects': needs at least one object"},
        {"{\"objects\": {}}", "key 'objects': expected an array, got an object"},
        {"{\"objects\": [{\"mesh\": " + m + "}], \"cameras\": {}}",
         "key 'cameras': unknown key (expected one of: camera, materials, objects, lights, "
         "render)"},
        {"{\"objects\": [{\"mesh\": " + m + "}], \"materials\": []}", "key 'materials'"},
        {"{\"objects\": [{\"mesh\": " + m + "}], \"lights\": [{\"typ\": \"quad\"}]}",
         "key 'lights[0].type': missing (required)"},
        {"{\"objects\": [{\"mesh\": " + m +
             "}], \"lights\": [{\"type\": \"environment\", \"constant\": [1,1,1]}, "
             "{\"type\": \"environment\", \"constant\": [1,1,1]}]}",
         "key 'lights[1]': only one environment light"},
        {"{\"objects\": [{\"mesh\": " + m +
             "}], \"camera\": {\"position\": [0,0,5], \"look_at\": [0,0,0], \"keyframes\": []}}",
         "not both"},
        {"{\"objects\": [{\"mesh\": " + m + "}], \"camera\": {\"keyframes\": []}}",
         "key 'camera.keyframes': needs at least one keyframe"},
        {"{\"objects\": [{\"mesh\": " + m +
             "}], \"camera\": {\"keyframes\": [{\"time\": 0, \"position\": [0,0,5], "
             "\"look_at\": [0,0,0]}, {\"time\": 0, \"position\": [0,0,5], \"look_at\": "
             "[0,0,1]}]}}",
         "key 'camera.keyframes[1].time': keyframe times must increase"},
        {"{\"objects\": [{\"mesh\": " + m + "}, {\"mesh\": " + m +
             ", \"transform\": {\"translate\": [1, 2]}}]}",
         "key 'objects[1].transform.translate': expected an array of 3 numbers"},
        {"{\"objects\": [{\"mesh\": " + m + ", \"material\": {\"a\": 1}}]}",
         "key 'objects[0].material': expected a string, got an object"},
    };
    std::vector<std::string> w;
    for (const Case& c : cases) {
        const std::string path = WriteFile("s.json", c.json);
        try {
            LoadScene(path, &w);
            ADD_FAILURE() << "no error for " << c.json;
        } catch (const InputError& e) {
            EXPECT_TRUE(Contains(e.what(), path)) << e.what();
            EXPECT_TRUE(Contains(e.what(), c.expect)) << c.json << " -> " << e.what();
        }
    }
}

TEST(SceneLoader, ObjErrorsKeepTheirOwnFileAndLine) {
    WriteFile("objerr/broken.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
    const std::string path =
        WriteFile("objerr/scene.json", R"({"objects": [{"mesh": "broken.obj"}]})");
    std::vector<std::string> w;
    try {
        LoadScene(path, &w);
        FAIL();
    } catch (const InputError& e) {
        EXPECT_TRUE(Contains(e.what(), "broken.obj:4: vertex index 4 is out of range")) << e.what();
    }
    // A missing OBJ names the scene's key and the resolved OBJ path.
    const std::string missing =
        WriteFile("objerr/missing.json", R"({"objects": [{"mesh": "sub/none.obj"}]})");
    try {
        LoadScene(missing, &w);
        FAIL();
    } catch (const InputError& e) {
        const std::string msg = e.what();
        EXPECT_TRUE(Contains(msg, "missing.json: key 'objects[0].mesh'")) << msg;
        EXPECT_TRUE(Contains(msg, "objerr/sub/none.obj' does not exist")) << msg;
    }
}

TEST(SceneLoader, JsonSyntaxErrorsReportLineAndColumn) {
    std::vector<std::string> w;
    const std::string path =
        WriteFile("syntax.json", "{\n  \"camera\": {\n    \"fov\": 45,,\n  }\n}\n");
    try {
        LoadScene(path, &w);
        FAIL();
    } catch (const InputError& e) {
        EXPECT_TRUE(Contains(e.what(), "syntax.json:3:15: JSON syntax error")) << e.what();
    }
    const std::string eof = WriteFile("eof.json", "{\"objects\": [\n");
    try {
        LoadScene(eof, &w);
        FAIL();
    } catch (const InputError& e) {
        EXPECT_TRUE(Contains(e.what(), "eof.json:2:")) << e.what();
    }
    try {
        LoadScene("/nonexistent/scene.json", &w);
        FAIL();
    } catch (const InputError& e) {
        EXPECT_TRUE(Contains(e.what(), "/nonexistent/scene.json: cannot open")) << e.what();
    }
    EXPECT_THROW(LoadScene(TempDir().string(), &w), InputError);  // a directory
}

std::string SceneError(const std::string& name, const std::string& text) {
    std::vector<std::string> w;
    try {
        LoadScene(WriteFile(name, text), &w);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

// Nesting is limited to 64 levels, stated in the message, and rejected as the 65th level opens:
// a 40,000-deep file (80 KB) fails like a 65-deep one, with a message of bounded size (it took
// 3 GB and 7 s when every level kept its whole key path).
TEST(SceneLoader, NestingBeyondTheStatedLimitIsRejected) {
    const auto nested = [](int depth) {
        return "{\"objects\": " + std::string(size_t(depth), '[') +
               std::string(size_t(depth), ']') + "}";
    };
    EXPECT_FALSE(Contains(SceneError("d63.json", nested(63)), "nested"));  // 64 levels: schema
    for (const int depth : {64, 40000}) {
        const std::string msg = SceneError("deep.json", nested(depth));
        EXPECT_TRUE(Contains(msg, "JSON nested deeper than 64 levels")) << depth << ": " << msg;
        EXPECT_LT(msg.size(), 400u) << msg;
    }
}

// Duplicate keys are found among 100,000 objects (a hash set per object; the linear scan and
// nlohmann's callback parser took 257 s here),
// named with their path.
TEST(SceneLoader, DuplicateKeysAreFoundAmongManyKeys) {
    std::string text = "{\"render\": {\"spp\": 1}, \"materials\": {";
    for (int i = 0; i < 100000; ++i) text += "\"m" + std::to_string(i) + "\": {}, ";
    text += "\"m99999\": {}}, \"objects\": []}";
    const std::string msg = SceneError("dup.json", text);
    EXPECT_TRUE(Contains(msg, "key 'materials.m99999': duplicate key")) << msg.substr(0, 300);
}

// Long tokens are cut to an excerpt (a 1 MB key, a 1 MB string value, a 700-byte unterminated
// comment), a NUL byte (a key's \u0000) is escaped rather than ending the message.
TEST(SceneLoader, MessagesQuoteExcerptsOfLongTokens) {
    const std::string big(1000000, 'k');
    for (const auto& [name, text, expect] : std::vector<std::array<std::string, 3>>{
             {"key.json", "{\"" + big + "\": 1}", "(1000000 bytes)': unknown key"},
             {"value.json", "{\"objects\": \"" + big + "\"}", "expected an array, got the string"},
             {"comment.json", "{\"objects\": [] /*" + std::string(700, 'x'), "(747 bytes)"},
             {"nul.json", "{\"obj\\u0000ects\": []}", "key 'obj\\x00ects': unknown key"}}) {
        const std::string msg = SceneError(name, text);
        EXPECT_TRUE(Contains(msg, expect)) << name << ": " << msg.substr(0, 300);
        EXPECT_LT(msg.size(), 400u) << name;
    }
}

// Range bounds hold as written: 1e12 is inside [1e-12, 1e12] (its float is below 1e12), a value
// just above is outside and printed so that it differs from the bound.
TEST(SceneLoader, RangeBoundsAreInclusiveAsWritten) {
    const std::string head =
        "{\"objects\": [{\"mesh\": " + Mesh() + ", \"transform\": {\"scale\": ";
    std::vector<std::string> w;
    EXPECT_NO_THROW(LoadScene(WriteFile("s12.json", head + "1e12}}]}"), &w));
    const std::string msg = SceneError("s13.json", head + "1.0000001e12}}]}");
    EXPECT_TRUE(Contains(msg, "value 1000000100000 is out of range [1e-12, 1e+12]")) << msg;
}

// An unknown texture kind is named as such, not as an unknown key of the image texture.
TEST(SceneLoader, UnknownTextureKindIsNamed) {
    const std::string head = "{\"materials\": {\"m\": {\"albedo\": ";
    const std::string tail = "}}, \"objects\": [{\"mesh\": " + Mesh() + ", \"material\": \"m\"}]}";
    EXPECT_TRUE(
        Contains(SceneError("noise.json", head + "{\"texture\": \"noise\", \"scale\": 2}" + tail),
                 "key 'materials.m.albedo.texture': unknown texture kind 'noise' "
                 "(valid: checker, or the path of an image file)"));
    EXPECT_TRUE(
        Contains(SceneError("img.json", head + "{\"texture\": \"wood.png\", \"scale\": 2}" + tail),
                 "the image texture 'wood.png' takes no parameters, but 'scale' is given"));
}

// Objects moved beyond +-1e18 by their transforms are blamed on the objects (the scene file),
// not on the default camera that cannot frame them.
TEST(SceneLoader, HugeObjectsAreBlamedOnTheObjectsNotTheCamera) {
    const std::string msg =
        SceneError("far.json", "{\"objects\": [{\"mesh\": " + Mesh() +
                                   ", \"transform\": {\"translate\": [1e25, 0, 0]}}]}");
    EXPECT_TRUE(Contains(msg, "far.json: the objects reach 1e+25")) << msg;
    EXPECT_FALSE(Contains(msg, "camera:")) << msg;
}

TEST(SceneLoader, WarnsAboutIgnoredValuesAndMissingLights) {
    std::vector<std::string> w;
    LoadScene(WriteFile("warn.json", R"({
      "materials": {"m": {"type": "diffuse", "roughness": 0.2}},
      "objects": [{"mesh": )" + Mesh() + R"(, "material": "m"}]
    })"),
              &w);
    ASSERT_EQ(w.size(), 2u);
    EXPECT_TRUE(Contains(w[0], "key 'materials.m.roughness': ignored by a diffuse material"))
        << w[0];
    EXPECT_TRUE(Contains(w[1], "no lights")) << w[1];
}

// "roughness": [along, across] makes an anisotropic GGX lobe (brushed metal).
TEST(SceneLoader, AnisotropicRoughness) {
    const Scene s = LoadScene(test::SceneDir() + "/brushed.json", nullptr);
    ASSERT_EQ(s.materials.size(), 1u);
    EXPECT_TRUE(s.materials[0].anisotropic);
    EXPECT_FLOAT_EQ(s.materials[0].roughness.value, 0.6f);
    EXPECT_FLOAT_EQ(s.materials[0].roughnessV, 0.25f);
}

TEST(SceneLoader, BundledScenesLoad) {
    for (const char* name : {"car.json", "chess.json", "features.json", "brushed.json"}) {
        std::vector<std::string> w;
        const Scene s = LoadScene(test::SceneDir() + "/" + name, &w);
        EXPECT_FALSE(s.objects.empty()) << name;
        for (const std::string& warning : w)
            EXPECT_TRUE(Contains(warning, "facevaryinginterpolateboundary")) << warning;
    }
}

TEST(TransformTrack, InterpolatesAndClamps) {
    TransformTrack t;
    EXPECT_EQ(t.Eval(3.0f), glm::mat4(1.0f));  // no keys: identity
    EXPECT_FALSE(t.IsAnimated());
    Keyframe a, b;
    a.time = 1.0f;
    a.translation = {0, 0, 0};
    b.time = 3.0f;
    b.translation = {2, 4, 0};
    b.rotation = glm::angleAxis(glm::radians(90.0f), glm::vec3(0, 1, 0));
    b.scale = glm::vec3(3.0f);
    t.keys = {a};
    EXPECT_FALSE(t.IsAnimated());
    t.keys = {a, a};
    t.keys[1].time = 2.0f;
    EXPECT_FALSE(t.IsAnimated());  // two keys, one pose
    t.keys = {a, b};
    EXPECT_TRUE(t.IsAnimated());

    // Mid time: half the translation and scale, 45 degrees about Y (tolerance 1e-5).
    const glm::mat4 M = t.Eval(2.0f);
    EXPECT_NEAR(M[3][0], 1.0f, 1e-5f);
    EXPECT_NEAR(M[3][1], 2.0f, 1e-5f);
    const glm::vec3 x = glm::mat3(M) * glm::vec3(1, 0, 0);
    EXPECT_NEAR(glm::length(x), 2.0f, 1e-5f);
    EXPECT_NEAR(x.x, 2.0f * std::cos(glm::radians(45.0f)), 1e-5f);
    EXPECT_NEAR(x.z, -2.0f * std::sin(glm::radians(45.0f)), 1e-5f);
    // T * R * S: scale applies first, translation last.
    const glm::mat4 want = glm::translate(glm::mat4(1.0f), glm::vec3(1, 2, 0)) *
                           glm::mat4_cast(glm::angleAxis(glm::radians(45.0f), glm::vec3(0, 1, 0))) *
                           glm::scale(glm::mat4(1.0f), glm::vec3(2.0f));
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) EXPECT_NEAR(M[c][r], want[c][r], 1e-5f) << c << "," << r;
    // Clamped outside the keys.
    EXPECT_EQ(t.Eval(-5.0f), t.Eval(1.0f));
    EXPECT_EQ(t.Eval(9.0f), t.Eval(3.0f));
    EXPECT_NEAR(t.Eval(9.0f)[3][0], 2.0f, 1e-6f);
    EXPECT_EQ(t.Eval(std::nanf("")), t.Eval(1.0f));  // NaN: the first key, no out-of-range read

    // Shortest path: 0 -> 270 degrees about Y is -90 degrees, so the midpoint is -45.
    b.translation = glm::vec3(0.0f);
    b.scale = glm::vec3(1.0f);
    b.rotation = glm::angleAxis(glm::radians(270.0f), glm::vec3(0, 1, 0));
    t.keys = {a, b};
    const glm::vec3 y = glm::mat3(t.Eval(2.0f)) * glm::vec3(1, 0, 0);
    EXPECT_NEAR(y.x, std::cos(glm::radians(45.0f)), 1e-5f);
    EXPECT_NEAR(y.z, std::sin(glm::radians(45.0f)), 1e-5f);

    // Three keys: the bracketing pair is used.
    Keyframe c = a;
    c.time = 5.0f;
    c.translation = {10, 0, 0};
    t.keys = {a, b, c};
    EXPECT_NEAR(t.Eval(4.0f)[3][0], 5.0f, 1e-5f);
}

}  // namespace
}  // namespace texcache
