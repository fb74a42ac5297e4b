// SPDX-License-Identifier: Apache-2.0
// The screen-space stage's input from files and the command line: the bundled animated scenes
// render frame pairs, the multi-layer EXR files round-trip every buffer, bad input names its file
// and key, and `texcache render --frame-buffers` writes one EXR per frame.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli_run.h"
#include "frame_buffers_util.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/scene/scene_loader.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;
using screen::FrameBuffers;
using test::AllNaN;
using test::ExpectSameBuffer;
using test::Finite;
using test::FrameOptions;
using test::TempDir;
using test::TestScene;
using test::Translate;

// Every bundled animated scene loads and renders a frame pair (prev = t - 1/24) with valid,
// finite buffers, and what the scene is about moves.
TEST(FrameBuffers, AnimatedScenesRenderFramePairs) {
    struct Case {
        const char* file;
        const char* what;  // the motion the scene must show
    };
    const Case cases[] = {{"anim_shadow.json", "blocker"},
                          {"anim_light.json", "light"},
                          {"anim_glossy.json", "glossy"},
                          {"anim_disocclusion.json", "object"},
                          {"anim_flythrough.json", "camera"}};
    for (const Case& c : cases) {
        SCOPED_TRACE(c.file);
        std::vector<std::string> warnings;
        const Scene s = LoadScene(test::SceneDir() + "/" + c.file, &warnings);
        EXPECT_TRUE(warnings.empty()) << warnings.front();
        FrameBuffers frames[2];
        for (int f = 0; f < 2; ++f) {
            const float t = 0.6f + float(f) / 24.0f;
            RenderSceneOptions ro;
            ro.frameTime = t;
            RenderScene rs(s, ro);
            RenderOptions o = FrameOptions(48, 27, uint64_t(f));
            o.maxDepth = 3;
            o.frameTime = t;
            RenderFrameBuffers(rs, o, t - 1.0f / 24.0f, &frames[f]);
        }
        int moved = 0, surfaces = 0;
        // Glossy only where a material has a specular lobe (anim_shadow and anim_disocclusion
        // have none: the stage then skips the component).
        bool ggx = false;
        for (const Object& o : s.objects)
            ggx |= s.materials[size_t(o.material)].type == Material::Type::GGX;
        for (const FrameBuffers& fb : frames) {
            ASSERT_NO_THROW(fb.Validate(c.file));
            EXPECT_EQ(fb.glossy.empty(), !ggx);
            EXPECT_EQ(fb.glossyHit.empty(), !ggx);
            for (size_t p = 0; p < fb.NumPixels(); ++p) {
                ASSERT_TRUE(Finite(fb.emitted[p]) && Finite(fb.shading[p]) &&
                            (fb.glossy.empty() || Finite(fb.glossy[p])) && Finite(fb.indirect[p]) &&
                            std::isfinite(fb.visibility[p]))
                    << p;
                const bool hit = Finite(fb.position[p]);
                EXPECT_EQ(std::isfinite(fb.depth[p]), hit) << p;
                EXPECT_EQ(Finite(fb.normal[p]), hit) << p;
                EXPECT_EQ(Finite(fb.prevPosition[p]), hit) << p;
                surfaces += fb.objectId[p] >= 0;
                for (int k = 0; k < screen::kNumCones; ++k) {
                    const glm::vec3 cone = fb.cones[p * screen::kNumCones + k];
                    EXPECT_TRUE(Finite(cone) || AllNaN(cone)) << p;
                }
                auto differs = [](glm::vec3 a, glm::vec3 b) {
                    return Finite(a) && glm::distance(a, b) > 1e-4f;
                };
                const std::string what = c.what;
                if (what == "blocker") moved += differs(fb.blocker[p], fb.prevBlocker[p]);
                if (what == "light") moved += differs(fb.lightSample[p], fb.prevLightSample[p]);
                if (what == "glossy") moved += differs(fb.glossyHit[p], fb.prevGlossyHit[p]);
                if (what == "object") moved += differs(fb.position[p], fb.prevPosition[p]);
            }
        }
        if (std::string(c.what) == "camera") {
            moved = frames[0].camera.worldToClip != frames[1].camera.worldToClip;
            // Nothing else moves: every point's previous position is itself.
            for (size_t p = 0; p < frames[0].NumPixels(); ++p) {
                if (Finite(frames[0].position[p])) {
                    EXPECT_NEAR(glm::distance(frames[0].position[p], frames[0].prevPosition[p]),
                                0.0f, 1e-5f);
                }
            }
        }
        EXPECT_GT(moved, 0) << c.what;
        EXPECT_GT(surfaces, 48 * 27 / 2);
        if (std::string(c.what) == "glossy") {
            // The floor's roughness is a checker: two alphas on it (0.2^2 and 0.6^2).
            int smooth = 0, rough = 0;
            for (float a : frames[0].roughness) {
                smooth += std::abs(a - 0.04f) < 1e-4f;
                rough += std::abs(a - 0.36f) < 1e-4f;
            }
            EXPECT_GT(smooth, 50);
            EXPECT_GT(rough, 50);
        }
    }
}

// WriteFrameBuffers + ReadFrameBuffers round-trip every buffer, the camera and the time exactly.
TEST(FrameBuffers, ExrRoundTrip) {
    Scene s = TestScene();
    Translate(&s, 2, glm::vec3(0.5f, 0.0f, 0.0f));
    RenderSceneOptions ro;
    ro.frameTime = 0.3f;
    RenderScene rs(s, ro);
    RenderOptions o = FrameOptions(21, 13, 2);
    o.frameTime = 0.3f;
    FrameBuffers fb;
    RenderFrameBuffers(rs, o, 0.25f, &fb);
    const std::string path = (TempDir() / "round_trip.exr").string();
    WriteFrameBuffers(path, fb);
    const FrameBuffers back = ReadFrameBuffers(path);
    EXPECT_EQ(back.width, 21);
    EXPECT_EQ(back.height, 13);
    EXPECT_EQ(back.time, 0.3f);
    EXPECT_EQ(back.camera.worldToClip, fb.camera.worldToClip);
    EXPECT_EQ(back.camera.position, fb.camera.position);
    ExpectSameBuffer(back.emitted, fb.emitted, "emitted");
    ExpectSameBuffer(back.shading, fb.shading, "shading");
    ExpectSameBuffer(back.visibility, fb.visibility, "visibility");
    ExpectSameBuffer(back.glossy, fb.glossy, "glossy");
    ExpectSameBuffer(back.indirect, fb.indirect, "indirect");
    ExpectSameBuffer(back.position, fb.position, "position");
    ExpectSameBuffer(back.normal, fb.normal, "normal");
    ExpectSameBuffer(back.depth, fb.depth, "depth");
    ExpectSameBuffer(back.roughness, fb.roughness, "roughness");
    ExpectSameBuffer(back.albedo, fb.albedo, "albedo");
    ExpectSameBuffer(back.specular, fb.specular, "specular");
    ExpectSameBuffer(back.objectId, fb.objectId, "objectId");
    ExpectSameBuffer(back.prevPosition, fb.prevPosition, "prevPosition");
    ExpectSameBuffer(back.prevNormal, fb.prevNormal, "prevNormal");
    ExpectSameBuffer(back.blocker, fb.blocker, "blocker");
    ExpectSameBuffer(back.prevBlocker, fb.prevBlocker, "prevBlocker");
    ExpectSameBuffer(back.lightSample, fb.lightSample, "lightSample");
    ExpectSameBuffer(back.prevLightSample, fb.prevLightSample, "prevLightSample");
    ExpectSameBuffer(back.glossyHit, fb.glossyHit, "glossyHit");
    ExpectSameBuffer(back.prevGlossyHit, fb.prevGlossyHit, "prevGlossyHit");
    ExpectSameBuffer(back.cones, fb.cones, "cones");
    // The beauty channels are the composed image.
    const Image rgb = ReadImageRGB(path);
    const std::vector<glm::vec3> c = fb.Compose();
    for (size_t p = 0; p < c.size(); ++p)
        for (int k = 0; k < 3; ++k) ASSERT_EQ(rgb.data[3 * p + k], c[p][k]);
    // A frame where only the camera moved, rendered without its previous points
    // (RenderOptions::frameBufferPrevPoints off), is written with the current ones in their
    // place: the file reads back whole.
    Scene still = TestScene();
    RenderScene stillRs(still, {});
    RenderOptions lean = FrameOptions(21, 13, 2);
    lean.frameBufferPrevPoints = false;
    FrameBuffers leanFb;
    RenderFrameBuffers(stillRs, lean, -0.04f, &leanFb);
    ASSERT_TRUE(leanFb.prevPosition.empty() && leanFb.shadowsStill);
    WriteFrameBuffers(path, leanFb);
    const FrameBuffers leanBack = ReadFrameBuffers(path);
    ExpectSameBuffer(leanBack.prevPosition, leanFb.position, "prevPosition");
    ExpectSameBuffer(leanBack.prevNormal, leanFb.normal, "prevNormal");
    ExpectSameBuffer(leanBack.prevGlossyHit, leanFb.glossyHit, "prevGlossyHit");
}

// Bad input: a roughness texture that does not exist (scene file and key named), one that is not
// an image (key named when the render reads it), impossible frame options, unwritable or foreign
// files.
TEST(FrameBuffers, BadInputNamesFileAndKey) {
    const fs::path dir = TempDir();
    const std::string mesh = test::MeshPath("catmark_cube");
    auto sceneWith = [&](const std::string& name, const std::string& roughness) {
        const fs::path p = dir / name;
        std::ofstream(p) << R"({"materials": {"floor": {"type": "ggx", "roughness": )" << roughness
                         << R"(}}, "objects": [{"mesh": ")" << mesh
                         << R"(", "material": "floor"}], "camera": {"position": [0, 1, 5],
                         "look_at": [0, 0, 0]}})";
        return p.string();
    };
    const std::string missing = sceneWith("missing.json", R"({"texture": "nope.png"})");
    try {
        LoadScene(missing, nullptr);
        FAIL() << "no error";
    } catch (const InputError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("missing.json"), std::string::npos) << m;
        EXPECT_NE(m.find("materials.floor.roughness"), std::string::npos) << m;
        EXPECT_NE(m.find("nope.png"), std::string::npos) << m;
        EXPECT_NE(m.find("does not exist"), std::string::npos) << m;
    }
    std::ofstream(dir / "garbage.png") << "not an image";
    const std::string garbage = sceneWith("garbage.json", R"({"texture": "garbage.png"})");
    const Scene s = LoadScene(garbage, nullptr);
    try {
        RenderScene rs(s, {});
        FAIL() << "no error";
    } catch (const InputError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("garbage.json"), std::string::npos) << m;
        EXPECT_NE(m.find("materials.floor.roughness"), std::string::npos) << m;
        EXPECT_NE(m.find("garbage.png"), std::string::npos) << m;
    }
    EXPECT_THROW(LoadScene(sceneWith("range.json", "1.5"), nullptr), InputError);
    EXPECT_THROW(LoadScene(sceneWith("colors.json",
                                     R"({"texture": "checker", "colors": [[2, 0, 0], [0, 0, 0]]})"),
                           nullptr),
                 InputError);

    Scene t = TestScene();
    RenderScene rs(t, {});
    FrameBuffers fb;
    EXPECT_THROW(RenderFrameBuffers(rs, FrameOptions(0, 10), -0.04f, &fb), InputError);
    EXPECT_THROW(RenderFrameBuffers(rs, FrameOptions(10, 10), NAN, &fb), InputError);
    RenderFrameBuffers(rs, FrameOptions(8, 6), -0.04f, &fb);
    try {
        WriteFrameBuffers((dir / "no_such_dir" / "f.exr").string(), fb);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("no_such_dir"), std::string::npos) << e.what();
    }
    fb.shading.resize(3);  // a buffer of the wrong size
    EXPECT_THROW(WriteFrameBuffers((dir / "f.exr").string(), fb), InputError);
    // A plain EXR has no frame camera.
    const std::string plain = (dir / "plain.exr").string();
    WriteImage(plain, Image(4, 4, 3, 0.5f));
    try {
        ReadFrameBuffers(plain);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("plain.exr"), std::string::npos) << e.what();
    }
    EXPECT_THROW(ReadFrameBuffers((dir / "absent.exr").string()), InputError);
}

// `texcache render --frame-buffers DIR --frames A:B --fps F` writes one readable multi-layer EXR
// (+ PNG) per frame, 1 spp, prev time t - 1/fps; conflicting options exit 2 naming the option.
TEST(FrameBuffers, CliWritesOneExrPerFrame) {
    const fs::path out = TempDir() / "cli";
    fs::remove_all(out);
    const test::CliRun r =
        test::Texcache("render " + test::SceneDir() + "/anim_shadow.json --frame-buffers " +
                       out.string() + " --frames 3:4 --fps 12 --resolution 24x16");
    ASSERT_EQ(r.code, 0) << r.out;
    for (int f : {3, 4}) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d", f);
        const FrameBuffers fb = ReadFrameBuffers((out / (std::string(name) + ".exr")).string());
        EXPECT_EQ(fb.width, 24);
        EXPECT_EQ(fb.height, 16);
        EXPECT_NEAR(fb.time, float(f) / 12.0f, 1e-6f);
        EXPECT_NO_THROW(fb.Validate(name));
        EXPECT_TRUE(fs::exists(out / (std::string(name) + ".png")));
    }
    EXPECT_NE(r.out.find("1 spp"), std::string::npos) << r.out;
    const test::CliRun bad =
        test::Texcache("render " + test::SceneDir() + "/anim_shadow.json --frame-buffers " +
                       out.string() + " --integrator ao --resolution 8x8");
    EXPECT_EQ(bad.code, 2) << bad.out;
    EXPECT_NE(bad.out.find("--frame-buffers"), std::string::npos) << bad.out;
    const test::CliRun help = test::Texcache("render --help");
    EXPECT_NE(help.out.find("--frame-buffers"), std::string::npos);
}

}  // namespace
}  // namespace texcache
