// SPDX-License-Identifier: Apache-2.0
// Hostile and careless input through the `texcache` program (issue 47), class by class: scenes
// at any scale render (never an abort inside Embree, never a silent blank image), light and
// textures that are not finite are repaired with a warning or refused on one line, and a render
// that cannot show anything says why. Every refusal is one line and exit code 2.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "cli_run.h"
#include "renderer/image/image.h"
#include "test_util.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;
using test::CliRun;
using test::Texcache;

fs::path Dir() {
    return test::CliTempDir("texcache_robustness_cli");
}

void Write(const fs::path& p, const std::string& text) {
    std::ofstream(p, std::ios::trunc) << text;
}

/// A cube of side `side` centred at (offset, 0, 0), as OBJ text; `holes` makes every face a hole.
std::string CubeObj(double side, double offset = 0.0, bool holes = false) {
    std::string s;
    char line[160];
    for (int i = 0; i < 8; ++i) {
        std::snprintf(line, sizeof line, "v %.17g %.17g %.17g\n",
                      offset + side * ((i & 1) ? 0.5 : -0.5), side * ((i & 2) ? 0.5 : -0.5),
                      side * ((i & 4) ? 0.5 : -0.5));
        s += line;
    }
    s += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
    if (holes) s += "t hole 6/0/0 0 1 2 3 4 5\n";
    return s;
}

/// Whether `r` is a refusal: exit code 2 and one line.
::testing::AssertionResult OneLineError(const CliRun& r) {
    if (r.code == 2 && std::count(r.out.begin(), r.out.end(), '\n') == 1)
        return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << "exit " << r.code << ": " << r.out;
}

/// The share of pixels of an image that are not black.
double LitFraction(const fs::path& path) {
    const Image img = ReadImageRGB(path.string());
    size_t lit = 0;
    for (size_t i = 0; i < img.NumPixels(); ++i) {
        const float* p = &img.data[i * 3];
        lit += p[0] + p[1] + p[2] > 0.01f;
    }
    return double(lit) / double(std::max<size_t>(img.NumPixels(), 1));
}

const char* kNormal = " --integrator normal --spp 1 --resolution 48x36 -q -o ";

// ---- Aborts inside Embree, and scales the default camera did not frame --------------------------

// A cube of any size the loader accepts, near the origin or far from it, renders: the scene is
// moved into render units where the default camera frames it and rays stay in Embree's range.
// The cube covers about a fifth of the frame at every scale (about 0.2 measured).
TEST(AnyScale, TheDefaultCameraFramesACubeOfAnySize) {
    struct Case {
        double side, offset;
    };
    for (const Case c : {Case{5e17, 0}, Case{1e15, 0}, Case{1e10, 0}, Case{1e-8, 0}, Case{1e-20, 0},
                         Case{1e-40, 0}, Case{1, 1e5}, Case{1e-3, 1e2}}) {
        const fs::path obj = Dir() / "scaled.obj", out = Dir() / "scaled.exr";
        Write(obj, CubeObj(c.side, c.offset));
        fs::remove(out);
        const CliRun r = Texcache("render " + obj.string() + kNormal + out.string());
        ASSERT_EQ(r.code, 0) << c.side << " at " << c.offset << ": " << r.out;
        EXPECT_GT(LitFraction(out), 0.05) << c.side << " at " << c.offset;
        EXPECT_EQ(r.out.find("warning"), std::string::npos) << r.out;
    }
}

// Every integrator's rays stay valid for Embree on a scene at the loader's largest scale (an
// invalid ray aborted the program there).
TEST(AnyScale, EveryIntegratorTracesTheLargestScene) {
    const fs::path obj = Dir() / "huge.obj", out = Dir() / "huge.exr";
    Write(obj, CubeObj(5e17));
    for (const char* integrator : {"ao", "direct", "path"}) {
        const CliRun r = Texcache("render " + obj.string() + " --integrator " + integrator +
                                  " --spp 1 --resolution 32x24 -q -o " + out.string());
        EXPECT_EQ(r.code, 0) << integrator << ": " << r.out;
        EXPECT_EQ(r.out.find("not traced"), std::string::npos) << r.out;
    }
}

// An eye separation that would put the eyes beyond float's reach of the objects is one line
// naming the option; a scene file's is one line naming the file.
TEST(AnyScale, AStereoRigTooWideIsOneLine) {
    const std::string cube = test::MeshPath("catmark_cube");
    const fs::path out = Dir() / "stereo.png";
    const CliRun flag =
        Texcache("render " + cube + " --stereo --eye-separation 1e30" + kNormal + out.string());
    EXPECT_TRUE(OneLineError(flag));
    EXPECT_NE(flag.out.find("--eye-separation"), std::string::npos) << flag.out;

    const fs::path scene = Dir() / "stereo_wide.json";
    Write(scene, R"({"objects": [{"mesh": ")" + cube +
                     R"("}], "camera": {"position": [3, 2, 3], "look_at": [0, 0, 0],
                     "stereo": {"eye_separation": 1e30, "convergence": 5}},
                     "lights": [{"type": "environment", "constant": [1, 1, 1]}]})");
    const CliRun file = Texcache("render " + scene.string() + " --stereo" + kNormal + out.string());
    EXPECT_TRUE(OneLineError(file));
    EXPECT_NE(file.out.find("stereo_wide.json"), std::string::npos) << file.out;
}

// ---- Renders that cannot show anything say why ------------------------------------------------

// A cage with nothing to render (every face a hole, or no area), or whose shape float cannot
// hold where it is, is refused at its file.
TEST(NothingToShow, CagesWithoutRenderableFacesAreOneLine) {
    const fs::path out = Dir() / "nothing.png";
    const fs::path holes = Dir() / "all_holes.obj";
    Write(holes, CubeObj(1.0, 0.0, true));
    const CliRun h = Texcache("render " + holes.string() + kNormal + out.string());
    EXPECT_TRUE(OneLineError(h));
    EXPECT_NE(h.out.find("every face of the cage is a hole"), std::string::npos) << h.out;

    const fs::path flat = Dir() / "no_area.obj";
    Write(flat, "v 0 0 0\nv 1 1 1\nv 2 2 2\nv 3 3 3\nf 1 2 3 4\n");
    const CliRun f = Texcache("render " + flat.string() + kNormal + out.string());
    EXPECT_TRUE(OneLineError(f));
    EXPECT_NE(f.out.find("no area"), std::string::npos) << f.out;

    // A unit cube at 1e12: float moves its vertices by thousands of units.
    const fs::path far = Dir() / "far.obj";
    Write(far, CubeObj(1.0, 1e12));
    const CliRun r = Texcache("render " + far.string() + kNormal + out.string());
    EXPECT_TRUE(OneLineError(r));
    EXPECT_NE(r.out.find("out of shape"), std::string::npos) << r.out;
}

// A camera that looks away from every object renders the background and says so.
TEST(NothingToShow, ACameraLookingAwayWarns) {
    const fs::path scene = Dir() / "away.json", out = Dir() / "away.png";
    Write(scene, R"({"objects": [{"mesh": ")" + test::MeshPath("catmark_cube") +
                     R"("}], "camera": {"position": [0, 0, 5], "look_at": [0, 0, 10]},
                     "lights": [{"type": "environment", "constant": [1, 1, 1]}]})");
    const CliRun r = Texcache("render " + scene.string() + kNormal + out.string());
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("warning: " + scene.string() + ": the camera sees none of the objects"),
              std::string::npos)
        << r.out;
}

// ---- Light and textures that are not finite ----------------------------------------------------

/// A 32x16 lat-long map of 1s with `bad` in every tenth texel.
fs::path EnvWith(const std::string& name, float bad) {
    Image img(32, 16, 3, 1.0f);
    for (size_t i = 0; i < img.NumPixels(); i += 10)
        for (int k = 0; k < 3; ++k) img.data[i * 3 + size_t(k)] = bad;
    const fs::path p = Dir() / name;
    WriteImage(p.string(), img);
    return p;
}

// NaN, infinite, negative or overflowing texels of an environment map are repaired (set to 0 or
// clamped), with a warning naming the file and their count, and the render is finite.
TEST(NonFiniteLight, EnvironmentMapsAreRepairedWithAWarning) {
    struct Case {
        const char* name;
        float bad;
        const char* says;
    };
    for (const Case c : {Case{"env_nan.exr", NAN, "NaN or infinite values (set to 0) in 52 of"},
                         Case{"env_inf.exr", INFINITY, "NaN or infinite values (set to 0) in 52"},
                         Case{"env_neg.exr", -4.0f, "negative values down to -4 (set to 0) in 52"},
                         Case{"env_huge.exr", 3e38f, "values above 1e30 (clamped) in 52"}}) {
        const fs::path env = EnvWith(c.name, c.bad), scene = Dir() / "env.json",
                       out = Dir() / "env.exr";
        Write(scene, R"({"objects": [{"mesh": ")" + test::MeshPath("catmark_cube") +
                         R"("}], "lights": [{"type": "environment", "file": ")" + env.string() +
                         R"("}]})");
        const CliRun r =
            Texcache("render " + scene.string() +
                     " --integrator path --spp 2 --resolution 32x24 -q -o " + out.string());
        ASSERT_EQ(r.code, 0) << c.name << ": " << r.out;
        EXPECT_NE(r.out.find("warning: " + env.string() + ": environment map has " + c.says),
                  std::string::npos)
            << r.out;
        const Image img = ReadImageRGB(out.string());
        EXPECT_TRUE(std::all_of(img.data.begin(), img.data.end(), [](float v) {
            return std::isfinite(v) && v >= 0.0f;
        })) << c.name;
    }
}

// A texture with NaN or negative texels is refused on one line with their count.
TEST(NonFiniteLight, TexturesWithNanOrNegativeTexelsAreOneLine) {
    for (const float bad : {NAN, -5.0f}) {
        Image img(8, 8, 3, 0.5f);
        img.data[0] = bad;
        const fs::path tex = Dir() / "bad_texture.exr", scene = Dir() / "tex.json";
        WriteImage(tex.string(), img);
        Write(scene, R"({"objects": [{"mesh": ")" + test::MeshPath("catmark_cube") +
                         R"(", "material": "m"}], "materials": {"m": {"albedo": {"texture": ")" +
                         tex.string() +
                         R"("}}}, "lights": [{"type": "environment", "constant": [1, 1, 1]}]})");
        const CliRun r =
            Texcache("render " + scene.string() + " --spp 1 --resolution 16x16 -q -o " +
                     (Dir() / "tex.png").string());
        EXPECT_TRUE(OneLineError(r)) << bad;
        EXPECT_NE(r.out.find("1 of its 64 texels"), std::string::npos) << r.out;
    }
}

}  // namespace
}  // namespace texcache
