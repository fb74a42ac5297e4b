// SPDX-License-Identifier: Apache-2.0
// The `texcache` program end to end: outputs, exit codes, error messages, and that a failed run
// never replaces a good output.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "cli_run.h"
#include "renderer/image.h"
#include "test_util.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

using test::CliRun;
using test::Texcache;

fs::path Dir() {
    const fs::path d = fs::path(::testing::TempDir()) / "texcache_cli";
    fs::create_directories(d);
    return d;
}

TEST(Cli, RendersAnObjToExrAndPng) {
    const fs::path out = Dir() / "cube.exr";
    const CliRun r = Texcache("render " + test::MeshPath("catmark_cube") +
                              " --spp 2 --resolution 64x32 --integrator ao -q -o " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("Mrays/s"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("peak memory"), std::string::npos) << r.out;
    const Image img = ReadImageRGB(out.string());
    EXPECT_EQ(img.width, 64);
    EXPECT_TRUE(fs::exists(Dir() / "cube.png"));
}

TEST(Cli, WritesRequestedAovLayers) {
    const fs::path out = Dir() / "aov.exr";
    const CliRun r =
        Texcache("render " + test::MeshPath("catmark_torus") +
                 " --spp 1 --resolution 32x32 --integrator normal --aov albedo,depth,ptex -q -o " +
                 out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(ReadImage(out.string()).channels, 3 + 3 + 1 + 3);
}

TEST(Cli, HelpOnEverySubcommand) {
    for (const char* c :
         {"--help", "render --help", "compare --help", "bench --help", "bench rays --help"}) {
        const CliRun r = Texcache(c);
        EXPECT_EQ(r.code, 0) << c << ": " << r.out;
        EXPECT_NE(r.out.find("Usage"), std::string::npos) << c;
    }
}

TEST(Cli, BadInputExitsTwoWithAClearMessage) {
    const fs::path bad = Dir() / "bad.obj";
    std::ofstream(bad) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n";
    const fs::path notLatLong = Dir() / "square.exr";
    WriteImage(notLatLong.string(), Image(16, 16, 3, 1.0f));
    const fs::path scene = Dir() / "env.json";
    std::ofstream(scene) << R"({"camera": {"position": [0,0,5], "look_at": [0,0,0]},
        "objects": [{"mesh": ")"
                         << test::MeshPath("catmark_cube") << R"("}],
        "lights": [{"type": "environment", "file": ")"
                         << notLatLong.string() << R"("}]})";
    struct Case {
        std::string args, expect;
    };
    const std::string cube = test::MeshPath("catmark_cube");
    for (const Case& c :
         {Case{"render /no/such/scene.json", "/no/such/scene.json"},
          Case{"render " + bad.string(), "bad.obj:4"},
          Case{"render " + cube + " --spp -5", "--spp"},
          Case{"render " + cube + " --resolution 10", "--resolution"},
          Case{"render " + cube + " --integrator magic", "valid: normal"},
          Case{"render " + cube + " -o out.tiff", "--output"},
          Case{"render " + cube + " --shading texture --filter fancy",
               "valid: none, normal, gaussian, regression, softshadow"},
          Case{"render " + cube + " --shading texture --footprint seen",
               "--footprint: unknown footprint 'seen' (valid: auto, visible, all)"},
          Case{"render " + cube + " --shading texture --filter-radius -2", "--filter-radius"},
          Case{"render " + cube + " --shading texture --filter-radius 33", "--filter-radius"},
          Case{"render " + cube + " --shading texture --shadow-samples 0", "--shadow-samples"},
          Case{"render " + cube + " --shading texture --frames 3 --temporal-alpha 1.5",
               "--temporal-alpha: must be in [0, 1)"},
          Case{"render " + cube + " --shading texture --temporal-alpha 0.7", "give --frames"},
          Case{"render " + cube + " --temporal-alpha 0.7 --frames 3", "needs --shading texture"},
          Case{"render " + cube + " --frames 5:2", "--frames"},
          Case{"render " + cube + " --frames x", "--frames"},
          Case{"render " + cube + " --frames 2 --fps 0", "--fps"},
          Case{"render " + cube + " --shading texture --sample-cache-mb 0", "--sample-cache-mb"},
          Case{"render " + cube + " --shading texture --lod-bias 99", "--lod-bias"},
          Case{"render " + scene.string() + " -o " + (Dir() / "x.exr").string(), "lat-long"},
          Case{"compare /no/a.exr /no/b.exr", "/no/a.exr"},
          Case{"render", "scene"}}) {
        const CliRun r = Texcache(c.args);
        EXPECT_EQ(r.code, 2) << c.args << ": " << r.out;
        EXPECT_NE(r.out.find(c.expect), std::string::npos) << c.args << ": " << r.out;
    }
}

// Animation mode: numbered frames (a run of # in the name), the cache and its temporal history
// carried across frames.
TEST(Cli, RendersNumberedAnimationFrames) {
    const fs::path out = Dir() / "anim_###.png";
    const CliRun r = Texcache("render " + test::SceneDir() +
                              "/turntable.json --resolution 48x27 --spp 1 --shading texture "
                              "--temporal-alpha 0.7 --frames 2:4 --fps 8 -o " +
                              out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    for (const char* f : {"anim_002.png", "anim_003.png", "anim_004.png"})
        EXPECT_TRUE(fs::exists(Dir() / f)) << f << "\n" << r.out;
    EXPECT_FALSE(fs::exists(Dir() / "anim_001.png"));
    EXPECT_NE(r.out.find("rendered 3 frames"), std::string::npos) << r.out;
}

double MeanOf(const Image& img) {
    double sum = 0.0;
    for (float v : img.data) sum += v;
    return sum / double(img.data.size());
}

// --denoise renders each frame's buffers in memory and writes the screen-space stage's images,
// numbered like an animation; the denoised frame keeps the light of the scene: its mean within
// 10% of a 64-spp path-traced render (measured ratio 1.010: the stage redistributes 1-spp noise, it
// neither adds nor removes light; the rest is the mean's noise at 48x27).
TEST(Cli, DenoisesAnAnimation) {
    const std::string scene = test::SceneDir() + "/anim_shadow.json";
    const fs::path out = Dir() / "dn_####.exr";
    const CliRun r = Texcache("render " + scene +
                              " --resolution 48x27 --denoise reliable --demodulate --frames 0:2 "
                              "-o " +
                              out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    for (const char* f : {"dn_0000.exr", "dn_0001.exr", "dn_0002.exr", "dn_0002.png"})
        EXPECT_TRUE(fs::exists(Dir() / f)) << f << "\n" << r.out;
    EXPECT_NE(r.out.find("denoised 3 frames"), std::string::npos) << r.out;
    const Image img = ReadImageRGB((Dir() / "dn_0002.exr").string());
    ASSERT_EQ(img.width, 48);
    for (float v : img.data) ASSERT_TRUE(std::isfinite(v));
    const fs::path ref = Dir() / "dn_ref.exr";
    ASSERT_EQ(Texcache("render " + scene +
                       " --resolution 48x27 --integrator path --spp 64 --time 0.08333333 -q -o " +
                       ref.string())
                  .code,
              0);
    const double ratio = MeanOf(img) / MeanOf(ReadImageRGB(ref.string()));
    std::printf("denoised mean / path-traced mean: %.4f\n", ratio);
    EXPECT_NEAR(ratio, 1.0, 0.1);

    // A single frame with the spatial method; methods that need history say so; unknown names
    // list the valid ones; --demodulate needs --denoise. Nothing is written by a failed run.
    EXPECT_EQ(Texcache("render " + scene + " --resolution 48x27 --denoise spatial -o " +
                       (Dir() / "dn_single.exr").string())
                  .code,
              0);
    EXPECT_TRUE(fs::exists(Dir() / "dn_single.exr"));
    const fs::path none = Dir() / "dn_none.exr";
    const CliRun noHistory = Texcache("render " + scene + " --denoise clamp -o " + none.string());
    EXPECT_EQ(noHistory.code, 2);
    EXPECT_NE(noHistory.out.find("--frames"), std::string::npos) << noHistory.out;
    const CliRun unknown =
        Texcache("render " + scene + " --denoise svgf --frames 0:1 -o " + none.string());
    EXPECT_EQ(unknown.code, 2);
    EXPECT_NE(unknown.out.find("valid: spatial, baseline, clamp, reliable"), std::string::npos)
        << unknown.out;
    EXPECT_EQ(Texcache("render " + scene + " --demodulate -o " + none.string()).code, 2);
    EXPECT_FALSE(fs::exists(none));
}

// `texcache montage` puts images of the same height side by side, `--gap` black columns apart,
// pixel for pixel; a different height or a bad output name is exit 2 naming the file, and
// nothing is written.
TEST(Cli, MontagePutsImagesSideBySide) {
    const fs::path a = Dir() / "montage_a.exr", b = Dir() / "montage_b.exr";
    WriteImage(a.string(), Image(3, 2, 3, 0.25f));
    WriteImage(b.string(), Image(4, 2, 3, 0.75f));
    const fs::path out = Dir() / "montage.exr";
    const CliRun r =
        Texcache("montage " + a.string() + " " + b.string() + " --gap 2 -o " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    const Image m = ReadImageRGB(out.string());
    ASSERT_EQ(m.width, 3 + 2 + 4);
    ASSERT_EQ(m.height, 2);
    for (int x = 0; x < m.width; ++x) {
        const float want = x < 3 ? 0.25f : x < 5 ? 0.0f : 0.75f;
        EXPECT_FLOAT_EQ(m.At(x, 1)[0], want) << x;
    }
    const fs::path tall = Dir() / "montage_tall.exr", bad = Dir() / "montage_bad.exr";
    WriteImage(tall.string(), Image(2, 5, 3, 0.5f));
    const CliRun h =
        Texcache("montage " + a.string() + " " + tall.string() + " -o " + bad.string());
    EXPECT_EQ(h.code, 2);
    EXPECT_NE(h.out.find("montage_tall.exr"), std::string::npos) << h.out;
    EXPECT_NE(h.out.find("height 5"), std::string::npos) << h.out;
    EXPECT_EQ(Texcache("montage " + a.string() + " -o " + (Dir() / "m.xyz").string()).code, 2);
    EXPECT_FALSE(fs::exists(bad));
}

TEST(Cli, FailedRenderKeepsTheGoodOutput) {
    const fs::path out = Dir() / "keep.png";
    WriteImage(out.string(), Image(8, 8, 3, 0.5f));
    const auto size = fs::file_size(out);
    const fs::path bad = Dir() / "bad2.obj";
    std::ofstream(bad) << "v 0 0 nan\n";
    EXPECT_EQ(Texcache("render " + bad.string() + " -o " + out.string()).code, 2);
    EXPECT_EQ(fs::file_size(out), size);
    EXPECT_EQ(ReadImageRGB(out.string()).width, 8);
}

TEST(Cli, CompareReportsMetrics) {
    const fs::path a = Dir() / "a.exr", b = Dir() / "b.exr", c = Dir() / "c.exr";
    WriteImage(a.string(), Image(16, 8, 3, 0.5f));
    WriteImage(b.string(), Image(16, 8, 3, 0.6f));
    WriteImage(c.string(), Image(8, 8, 3, 0.6f));
    const CliRun r = Texcache("compare " + a.string() + " " + b.string() + " --error-image " +
                              (Dir() / "err.png").string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("relMSE"), std::string::npos);
    EXPECT_NE(r.out.find("SSIM"), std::string::npos);
    EXPECT_TRUE(fs::exists(Dir() / "err.png"));
    EXPECT_EQ(Texcache("compare " + a.string() + " " + c.string()).code, 2);
}

}  // namespace
}  // namespace texcache
