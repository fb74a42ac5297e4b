// SPDX-License-Identifier: Apache-2.0
// OBJ materials: MTL files parsed (and their errors named by file:line), mapped onto the
// project's materials, given per face by usemtl, overridden by the scene file, and seen per face
// by the renderer.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "renderer/scene/obj_materials.h"
#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene_loader.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

fs::path Dir() {
    const fs::path d = fs::path(::testing::TempDir()) / "texcache_obj_materials";
    fs::create_directories(d);
    return d;
}

std::string Write(const std::string& name, const std::string& text) {
    const fs::path p = Dir() / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
}

bool Contains(const std::string& s, const std::string& part) {
    return s.find(part) != std::string::npos;
}

std::string ErrorOf(const std::function<void()>& fn) {
    try {
        fn();
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(ObjMaterials, ParsesTheMtlStatementsItUses) {
    std::vector<std::string> w;
    const std::vector<MtlMaterial> m = ParseMtl(R"(# comment
newmtl red paint
Kd 0.8 0.1 0.05   # trailing comment
Ka 0 0 0
illum 2
Ns 98
Ks 0.5
d 0.5
newmtl lamp
Ke 2 2 1
Tr 0.25
map_Kd -s 1 1 1 tex/wood.png
Pr 0.5
Pr 0.3
)",
                                                "a.mtl", &w);
    ASSERT_EQ(m.size(), 2u);
    EXPECT_EQ(m[0].name, "red paint");
    EXPECT_EQ(m[0].line, 2);
    EXPECT_FLOAT_EQ(m[0].Kd.g, 0.1f);
    EXPECT_EQ(m[0].Ks, glm::vec3(0.5f));  // one value: grey
    EXPECT_FLOAT_EQ(m[0].Ns, 98.0f);
    EXPECT_FLOAT_EQ(m[0].d, 0.5f);
    EXPECT_EQ(m[1].Ke, glm::vec3(2, 2, 1));
    EXPECT_FLOAT_EQ(m[1].d, 0.75f);
    EXPECT_EQ(m[1].mapKd, "tex/wood.png");
    EXPECT_EQ(m[1].Ns, -1.0f);  // not given
    // map_Kd's options, and the one unused statement (once, with its count).
    ASSERT_EQ(w.size(), 2u);
    EXPECT_TRUE(Contains(w[0], "a.mtl:12: map_Kd options are ignored")) << w[0];
    EXPECT_TRUE(Contains(w[1], "a.mtl:13: 'Pr' is not used (2 lines)")) << w[1];
}

TEST(ObjMaterials, MtlErrorsNameTheFileAndLine) {
    const std::pair<const char*, const char*> cases[] = {
        {"newmtl a\nKd 0.5 x 0.5\n", "bad.mtl:2: malformed number 'x'"},
        {"Kd 1 1 1\n", "bad.mtl:1: 'Kd' before any 'newmtl'"},
        {"newmtl a\nKd spectral file.rfl\n", "bad.mtl:2: 'Kd spectral' colours are not supported"},
        {"newmtl a\nKd 1 1\n", "bad.mtl:2: 'Kd' needs r g b"},
        {"newmtl a\nKd -1 0 0\n", "bad.mtl:2: value -1 is out of range"},
        {"newmtl a\nd 1.5\n", "bad.mtl:2: value 1.5 is out of range"},
        {"newmtl a\nNs nan\n", "bad.mtl:2: malformed number 'nan'"},
        {"newmtl\n", "bad.mtl:1: 'newmtl' without a name"},
        {"newmtl a\nmap_Kd\n", "bad.mtl:2: 'map_Kd' needs a file name"},
    };
    for (const auto& [text, want] : cases) {
        const std::string e = ErrorOf([&] { ParseMtl(text, "bad.mtl", nullptr); });
        EXPECT_TRUE(Contains(e, want)) << text << " -> " << e;
    }
}

TEST(ObjMaterials, MapsMtlOntoDiffuseAndGgxMaterials) {
    const std::string png = Write("wood.png", "only existence is checked here");
    const std::string ptx = Write("paint.ptx", "only existence is checked here");
    std::vector<Texture> textures;
    std::vector<std::string> w;
    MtlMaterial plain;
    plain.name = "plain";
    plain.Kd = glm::vec3(0.5f, 1.5f, 0.2f);  // clamped to [0, 1]
    const Material d = ToMaterial(plain, (Dir() / "x.mtl").string(), &textures, &w);
    EXPECT_EQ(d.type, Material::Type::Diffuse);
    EXPECT_EQ(d.albedo.value, glm::vec3(0.5f, 1.0f, 0.2f));
    EXPECT_EQ(d.emission.value, glm::vec3(0.0f));

    MtlMaterial shiny = plain;
    shiny.Ks = glm::vec3(0.04f);
    shiny.Ns = 98.0f;  // Blinn-Phong 98: alpha = sqrt(2 / 100), roughness = sqrt(alpha)
    shiny.Ke = glm::vec3(3.0f);
    shiny.d = 0.5f;
    shiny.mapKd = "wood.png";
    const Material g = ToMaterial(shiny, (Dir() / "x.mtl").string(), &textures, &w);
    EXPECT_EQ(g.type, Material::Type::GGX);
    EXPECT_EQ(g.specular.value, glm::vec3(0.04f));
    EXPECT_NEAR(g.roughness.value, std::pow(0.02f, 0.25f), 1e-6f);
    EXPECT_EQ(g.emission.value, glm::vec3(3.0f));
    ASSERT_EQ(g.albedo.texture, 0);
    EXPECT_EQ(textures[0].kind, Texture::Kind::Image);
    EXPECT_EQ(fs::path(textures[0].path), fs::path(png));
    ASSERT_EQ(w.size(), 1u);  // transparency
    EXPECT_TRUE(Contains(w[0], "transparency (d/Tr) is not supported")) << w[0];

    shiny.mapKd = "paint.ptx";  // Ptex: looked up by Ptex face, not uv
    const Material p = ToMaterial(shiny, (Dir() / "x.mtl").string(), &textures, nullptr);
    EXPECT_EQ(textures[size_t(p.albedo.texture)].kind, Texture::Kind::Ptex);
    EXPECT_EQ(fs::path(textures[size_t(p.albedo.texture)].path), fs::path(ptx));

    shiny.mapKd = "missing.png";
    shiny.mapKdLine = 7;
    const std::string e =
        ErrorOf([&] { ToMaterial(shiny, (Dir() / "x.mtl").string(), &textures, nullptr); });
    EXPECT_TRUE(Contains(e, "x.mtl:7: map_Kd: texture file")) << e;
}

/// Two unit quads side by side in the XZ plane (facing +Y) and a triangle: red, blue, and the
/// triangle with no material.
std::string TwoQuadObj(const std::string& mtllib) {
    return "mtllib " + mtllib +
           "\n"
           "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 0 -1\nv 1 0 -1\nv 2 0 -1\nv 3 0 0\n"
           "f 3 7 6\n"
           "g left\nusemtl red\nf 1 2 5 4\n"
           "g right\nusemtl blue\nf 2 3 6 5\n";
}

TEST(ObjMaterials, UsemtlGivesEachFaceItsMaterialAndTheSceneOverridesByName) {
    Write("pair.mtl", "newmtl red\nKd 0.9 0.1 0.1\nnewmtl blue\nKd 0.1 0.1 0.9\n");
    const std::string obj = Write("pair.obj", TwoQuadObj("pair.mtl"));
    std::vector<std::string> w;
    // Without a scene material of either name: the MTL's; the triangle, before any usemtl, the
    // default material.
    Scene s = LoadScene(Write("pair.json", R"({"objects": [{"mesh": ")" + obj + R"("}]})"), &w);
    ASSERT_EQ(s.objects.size(), 1u);
    const Object& o = s.objects[0];
    ASSERT_EQ(o.faceMaterials.size(), 3u);
    EXPECT_EQ(s.materials[size_t(o.faceMaterials[0])].name, "default");
    EXPECT_EQ(s.materials[size_t(o.faceMaterials[1])].albedo.value, glm::vec3(0.9f, 0.1f, 0.1f));
    EXPECT_EQ(s.materials[size_t(o.faceMaterials[2])].name, "blue");
    EXPECT_EQ(o.material, o.faceMaterials[0]);
    EXPECT_EQ(o.Materials().size(), 3u);

    // A scene material named "blue" replaces the MTL's; an object's "material" replaces all.
    s = LoadScene(Write("pair2.json", R"({
      "materials": {"blue": {"type": "ggx", "albedo": [0, 1, 0]}, "grey": {}},
      "objects": [{"mesh": ")" + obj + R"("}, {"mesh": ")" +
                                          obj + R"(", "material": "grey"}]})"),
                  &w);
    const Object& a = s.objects[0];
    EXPECT_EQ(s.materials[size_t(a.faceMaterials[2])].type, Material::Type::GGX);
    EXPECT_EQ(s.materials[size_t(a.faceMaterials[2])].albedo.value, glm::vec3(0, 1, 0));
    EXPECT_TRUE(s.objects[1].faceMaterials.empty());
    EXPECT_EQ(s.materials[size_t(s.objects[1].material)].name, "grey");
    EXPECT_EQ(s.meshes.size(), 1u);  // both objects share the cage
}

TEST(ObjMaterials, MissingLibrariesAndNamesWarnAndFallBack) {
    const std::string obj = Write("lost.obj", TwoQuadObj("nowhere.mtl"));
    std::vector<std::string> w;
    const Scene s =
        LoadScene(Write("lost.json", R"({"objects": [{"mesh": ")" + obj + R"("}]})"), &w);
    EXPECT_TRUE(s.objects[0].faceMaterials.empty());  // every face the default
    EXPECT_EQ(s.materials[size_t(s.objects[0].material)].name, "default");
    std::string all;
    for (const std::string& x : w) all += x + "\n";
    EXPECT_TRUE(Contains(all, "lost.obj:1: material library")) << all;
    EXPECT_TRUE(Contains(all, "lost.obj:14: usemtl 'blue'")) << all;
    EXPECT_TRUE(Contains(all, "no material library of the OBJ")) << all;

    // A bad MTL is an error naming its own line, through the scene.
    Write("broken.mtl", "newmtl red\nKd 1 oops 1\n");
    const std::string obj2 = Write("broken.obj", TwoQuadObj("broken.mtl"));
    const std::string e = ErrorOf([&] {
        LoadScene(Write("broken.json", R"({"objects": [{"mesh": ")" + obj2 + R"("}]})"), nullptr);
    });
    EXPECT_TRUE(Contains(e, "broken.mtl:2: malformed number 'oops'")) << e;
}

TEST(ObjMaterials, ABareObjRendersWithItsOwnMaterials) {
    Write("bare.mtl", "newmtl red\nKd 0.9 0.1 0.1\nnewmtl blue\nKd 0.1 0.1 0.9\n");
    const std::string obj = Write("bare.obj", TwoQuadObj("bare.mtl"));
    std::vector<std::string> w;
    const Scene s = SceneFromObj(obj, "", &w);
    ASSERT_EQ(s.objects[0].faceMaterials.size(), 3u);
    EXPECT_EQ(s.materials[size_t(s.objects[0].faceMaterials[1])].name, "red");
    EXPECT_EQ(s.materials[size_t(s.objects[0].faceMaterials[0])].albedo.value, glm::vec3(0.6f));
}

// The renderer sees each face's own material: rays straight down at points of each face find
// its albedo (the pair is subdivided, so points well inside each face).
TEST(ObjMaterials, HitsSeeTheirFacesMaterial) {
    Write("hits.mtl", "newmtl red\nKd 0.9 0.1 0.1\nnewmtl blue\nKd 0.1 0.1 0.9\nKs 0.04\n");
    const std::string obj = Write("hits.obj", TwoQuadObj("hits.mtl"));
    std::vector<std::string> w;
    const Scene s =
        LoadScene(Write("hits.json", R"({"objects": [{"mesh": ")" + obj + R"("}]})"), &w);
    RenderSceneOptions ro;
    ro.needLights = false;
    const RenderScene rs(s, ro);
    const std::pair<glm::vec2, glm::vec3> probes[] = {
        {{0.5f, -0.5f}, {0.9f, 0.1f, 0.1f}},   // left quad: red
        {{1.5f, -0.5f}, {0.1f, 0.1f, 0.9f}},   // right quad: blue
        {{2.3f, -0.3f}, {0.8f, 0.8f, 0.8f}}};  // triangle: default grey
    for (const auto& [xz, albedo] : probes) {
        Ray ray;
        ray.org = glm::vec3(xz.x, 1.0f, xz.y);
        ray.dir = glm::vec3(0, -1, 0);
        Hit hit;
        ASSERT_TRUE(rs.Intersect(ray, &hit)) << xz.x;
        const SurfaceInteraction si = rs.Interact(ray, hit);
        EXPECT_EQ(rs.Albedo(si), albedo) << xz.x;
        EXPECT_EQ(s.materials[size_t(si.material)].type,
                  xz.x > 1.0f && xz.x < 2.0f ? Material::Type::GGX : Material::Type::Diffuse);
    }
}

}  // namespace
}  // namespace texcache
