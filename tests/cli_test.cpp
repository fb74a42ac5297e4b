// SPDX-License-Identifier: Apache-2.0
// The `texcache` program end to end: outputs, exit codes, error messages, and that a failed run
// never replaces a good output.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "cli_run.h"
#include "renderer/image/image.h"
#include "renderer/library_versions.h"
#include "test_util.h"
#include "testing/cages.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

using test::CliRun;
using test::Texcache;

fs::path Dir() {
    return test::CliTempDir("texcache_cli");
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

// A 16-gon is past Embree's limits: it renders through the limit tessellation, and the scene
// statistics say which faces needed it.
TEST(Cli, RendersA16GonAndCountsTheFacesPastEmbreesLimits) {
    const fs::path obj = Dir() / "prism16.obj", out = Dir() / "prism16.exr";
    test::WriteObj(test::PrismCage(16), obj.string());
    const CliRun r = Texcache("render " + obj.string() +
                              " --spp 2 --resolution 64x32 --integrator ao --shading texture -q "
                              "--sample-cache-mb 4 --texel-cache-mb 4 "
                              "-o " +
                              out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("2 cage faces past Embree's limits (1 mesh, 18 cage faces "
                         "tessellated"),
              std::string::npos)
        << r.out;
    const Image img = ReadImageRGB(out.string());
    int lit = 0;
    for (float x : img.data) lit += x > 0.1f;
    EXPECT_GT(lit, 64 * 32 / 10) << "the prism covers ~20% of the view";
}

// The value of a top-level number in --stats JSON (one "key": value per line); NaN when absent.
double StatsValue(const std::string& json, const std::string& key) {
    const size_t at = json.find("\"" + key + "\": ");
    if (at == std::string::npos) return std::nan("");
    return std::strtod(json.c_str() + at + key.size() + 4, nullptr);
}

// --stats says how many cage faces were past Embree's limits and how many were tessellated from
// the limit surface, as the printed scene line does: the 16-gon prism (2 caps past the limit,
// all 18 faces tessellated), a cage Embree takes whole (none), and the same cage with
// --geometry quads (all of it, none past the limits).
TEST(Cli, StatsCountTheFacesPastEmbreesLimits) {
    const fs::path prism = Dir() / "stats_prism16.obj";
    test::WriteObj(test::PrismCage(16), prism.string());
    struct Case {
        std::string obj, args;
        double ptex, beyond, meshes, tessellated;
    };
    const std::string torus = test::MeshPath("catmark_torus");
    for (const Case& c :
         {Case{prism.string(), "", 16 + 16 + 16, 2, 1, 18}, Case{torus, "", 32, 0, 0, 0},
          Case{torus, " --geometry quads", 32, 0, 1, 32}}) {
        const fs::path stats = Dir() / "stats.json", out = Dir() / "stats.exr";
        const CliRun r =
            Texcache("render " + c.obj + c.args + " --spp 1 --resolution 16x16 --integrator ao " +
                     "-q --no-png -o " + out.string() + " --stats " + stats.string());
        ASSERT_EQ(r.code, 0) << r.out;
        std::ifstream f(stats);
        const std::string json((std::istreambuf_iterator<char>(f)), {});
        SCOPED_TRACE(c.obj + c.args + "\n" + json);
        EXPECT_EQ(StatsValue(json, "ptex_faces"), c.ptex);
        EXPECT_EQ(StatsValue(json, "cage_faces_beyond_embree"), c.beyond);
        EXPECT_EQ(StatsValue(json, "limit_tessellated_meshes"), c.meshes);
        EXPECT_EQ(StatsValue(json, "limit_tessellated_cage_faces"), c.tessellated);
        EXPECT_EQ(json.find(",\n}"), std::string::npos) << "no comma after the last value";
    }
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
    for (const char* c : {"--help", "render --help", "compare --help", "bench --help",
                          "bench rays --help", "bench peer --help"}) {
        const CliRun r = Texcache(c);
        EXPECT_EQ(r.code, 0) << c << ": " << r.out;
        EXPECT_NE(r.out.find("Usage"), std::string::npos) << c;
    }
}

// `texcache --version`: texcache's version on the first line, then each library's, as the
// renderer reports them (no subcommand needed, exit 0).
TEST(Cli, VersionNamesTexcacheAndItsLibraries) {
    const CliRun r = Texcache("--version");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(r.out.rfind(std::string("texcache ") + TexcacheVersion() + "\n", 0), 0u) << r.out;
    const std::vector<LibraryVersion> libs = LibraryVersions();
    ASSERT_EQ(libs.size(), 4u);
    for (const char* name : {"Embree", "OpenSubdiv", "OpenEXR", "OpenImageIO"}) {
        const auto it = std::find_if(libs.begin(), libs.end(),
                                     [&](const LibraryVersion& v) { return v.name == name; });
        ASSERT_NE(it, libs.end()) << name;
        EXPECT_FALSE(it->version.empty()) << name;
        EXPECT_TRUE(std::isdigit(static_cast<unsigned char>(it->version[0]))) << it->version;
        EXPECT_NE(r.out.find(it->name + " " + it->version + "\n"), std::string::npos) << r.out;
    }
}

// The help of the commands with many options lists them under headings, in this order, each
// option under its own (a sample of each group).
TEST(Cli, HelpGroupsTheOptions) {
    struct Group {
        std::string heading;
        std::vector<std::string> options;
    };
    struct Case {
        std::string command;
        std::vector<Group> groups;
    };
    const Case cases[] = {
        {"render --help",
         {{"Output:", {"--output", "--aov", "--frames"}},
          {"Sampling:", {"--spp", "--integrator", "--light-sampling"}},
          {"Texture space:", {"--shading", "--ts-samples", "--texel-cache-mb"}},
          {"Screen-space stage:", {"--frame-buffers", "--denoise"}},
          {"Stereo and blur:", {"--stereo", "--visibility-filter"}},
          {"Diagnostics:", {"--stats", "--overshading"}}}},
        {"preview --help",
         {{"View:", {"--resolution", "--view"}},
          {"Texture space:", {"--shading", "--no-reshade"}},
          {"Screen-space stage:", {"--denoise", "--motion"}},
          {"Stereo:", {"--eye-separation"}},
          {"Headless test mode:", {"--screenshot", "--play"}},
          {"Benchmark:", {"--bench-frames"}}}},
    };
    for (const Case& c : cases) {
        const CliRun r = Texcache(c.command);
        ASSERT_EQ(r.code, 0) << c.command << ": " << r.out;
        size_t last = 0;
        for (size_t g = 0; g < c.groups.size(); ++g) {
            const size_t at = r.out.find("\n" + c.groups[g].heading + "\n");
            ASSERT_NE(at, std::string::npos) << c.command << ": " << c.groups[g].heading;
            EXPECT_GT(at, last) << c.command << ": " << c.groups[g].heading << " out of order";
            const size_t end = g + 1 < c.groups.size()
                                   ? r.out.find("\n" + c.groups[g + 1].heading + "\n")
                                   : r.out.size();
            for (const std::string& o : c.groups[g].options) {
                // The option's own line: "  --spp INT ..." or "  -o,--output TEXT ...".
                size_t opt = r.out.find("\n  " + o + " ", at);
                opt = std::min(opt, r.out.find("," + o + " ", at));
                EXPECT_TRUE(opt != std::string::npos && opt < end)
                    << c.command << ": " << o << " not under " << c.groups[g].heading;
            }
            last = at;
        }
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
          Case{"render " + cube + " --shading texture --ts-samples texels",
               "--ts-samples: unknown texture-space sample source 'texels' (valid: grid, hits)"},
          Case{"render " + cube + " --shading texture --cached-light some",
               "--cached-light: unknown value 'some' (valid: auto, all, indirect)"},
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
          Case{"render " + cube + " --light-sampling best", "valid: mis, pis, cpis"},
          Case{"render " + test::SceneDir() + "/sunlit.json --light-sampling cpis",
               "sunlit.json has no environment light"},
          Case{"render " + test::SceneDir() + "/brushed.json --integrator ao --light-sampling pis",
               "direct and path integrators only"},
          Case{"render " + test::SceneDir() +
                   "/brushed.json --light-sampling cpis --psr-cache-mb 0.0001",
               "--psr-cache-mb"},
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

    // A single frame with the spatial method, demodulated unless --no-demodulate; methods that
    // need history say so; unknown names list the valid ones; --demodulate and --no-demodulate
    // need --denoise and contradict each other. Nothing is written by a failed run.
    const CliRun single = Texcache("render " + scene + " --resolution 48x27 --denoise spatial -o " +
                                   (Dir() / "dn_single.exr").string());
    EXPECT_EQ(single.code, 0) << single.out;
    EXPECT_NE(single.out.find("spatial, demodulated"), std::string::npos) << single.out;
    EXPECT_TRUE(fs::exists(Dir() / "dn_single.exr"));
    const CliRun plain =
        Texcache("render " + scene + " --resolution 48x27 --denoise spatial --no-demodulate -o " +
                 (Dir() / "dn_plain.exr").string());
    EXPECT_EQ(plain.code, 0) << plain.out;
    EXPECT_EQ(plain.out.find("demodulated"), std::string::npos) << plain.out;
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
    EXPECT_EQ(Texcache("render " + scene + " --no-demodulate -o " + none.string()).code, 2);
    const CliRun both = Texcache(
        "render " + scene + " --denoise spatial --demodulate --no-demodulate -o " + none.string());
    EXPECT_EQ(both.code, 2);
    EXPECT_NE(both.out.find("contradicts --demodulate"), std::string::npos) << both.out;
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

std::string Slurp(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
}

// Every error is one line: "texcache: error: ...", exit code 2.
void ExpectOneLineError(const CliRun& r, const std::string& args, const std::string& expect) {
    EXPECT_EQ(r.code, 2) << args << ": " << r.out;
    EXPECT_EQ(r.out.rfind("texcache: error: ", 0), 0u) << args << ": " << r.out;
    EXPECT_EQ(r.out.find('\n'), r.out.size() - 1) << args << ": " << r.out;
    EXPECT_NE(r.out.find(expect), std::string::npos) << args << ": " << r.out;
}

// A refused command line, one CTest case each (every case is one run of the program): the
// placeholders {scene} (a scene with a mesh {obj} and an environment map {env}), {good} and
// {goodpng} (outputs of an earlier run), {cube} (the bundled cube) and {dir} are replaced by the
// fixture's files; {dir}/soft.json is the cube with a material setting the softshadow filter.
struct Refusal {
    const char* name;
    const char* args;
    const char* expect;
};

class CliRefuses : public ::testing::TestWithParam<Refusal> {
protected:
    void SetUp() override {
        dir_ = Dir() / (std::string("refuses_") + GetParam().name);
        fs::remove_all(dir_);
        fs::create_directories(dir_ / "blocked.png");
        fs::copy_file(test::MeshPath("catmark_cube"), dir_ / "cube.obj");
        WriteImage((dir_ / "env.exr").string(), Image(8, 4, 3, 1.0f));
        std::ofstream(dir_ / "s.json") << R"({"objects": [{"mesh": "cube.obj"}],
            "lights": [{"type": "environment", "file": "env.exr"}]})";
        std::ofstream(dir_ / "soft.json") << R"({"objects": [{"mesh": "cube.obj",
            "material": "clay"}], "materials": {"clay": {"type": "diffuse",
            "filter": "softshadow"}}, "lights": [{"type": "environment", "file": "env.exr"}]})";
        WriteImage((dir_ / "good.exr").string(), Image(4, 4, 3, 0.5f));
        WriteImage((dir_ / "good.png").string(), Image(4, 4, 3, 0.5f));
        for (const auto& e : fs::directory_iterator(dir_))
            if (e.is_regular_file()) before_[e.path().filename().string()] = Slurp(e.path());
    }
    std::string Args() const {
        std::string a = GetParam().args;
        const std::pair<std::string, std::string> subs[] = {
            {"{scene}", (dir_ / "s.json").string()},
            {"{obj}", (dir_ / "cube.obj").string()},
            {"{env}", (dir_ / "env.exr").string()},
            {"{good}", (dir_ / "good.exr").string()},
            {"{goodpng}", (dir_ / "good.png").string()},
            {"{cube}", test::MeshPath("catmark_cube")},
            {"{dir}", dir_.string()}};
        for (const auto& [from, to] : subs)
            for (size_t at; (at = a.find(from)) != std::string::npos;)
                a.replace(at, from.size(), to);
        return a;
    }
    fs::path dir_;
    std::map<std::string, std::string> before_;
};

// Exit 2 with one line naming the problem, and every file of the directory exactly as it was:
// nothing replaced, nothing new (no output, no temporary).
TEST_P(CliRefuses, WithOneLineAndNoFileTouched) {
    const std::string args = Args();
    ExpectOneLineError(Texcache(args), args, GetParam().expect);
    std::map<std::string, std::string> after;
    for (const auto& e : fs::directory_iterator(dir_))
        if (e.is_regular_file()) after[e.path().filename().string()] = Slurp(e.path());
    EXPECT_EQ(after, before_) << args;
}

std::string RefusalName(const ::testing::TestParamInfo<Refusal>& info) {
    return info.param.name;
}

#define RENDER_SCENE "render {scene} --spp 1 --resolution 8x8 -q "
#define RENDER_CUBE "render {cube} --spp 1 -q -o {dir}/x.png "

// No flag can destroy a file. An output that is an input (the scene, its
// mesh, its environment map, a compared image) or another output (the PNG beside the EXR,
// --stats) is refused, and so is an output that cannot be written (missing directory, a
// directory in the way, a path under a regular file), all before anything renders.
INSTANTIATE_TEST_SUITE_P(
    DataLoss, CliRefuses,
    ::testing::Values(
        Refusal{"StatsOverTheScene", RENDER_SCENE "-o {dir}/x.exr --stats {scene}",
                "is the same file as the scene"},
        Refusal{"StatsOverTheImage", RENDER_SCENE "-o {good} --stats {good}", "--stats: '"},
        Refusal{"StatsOverThePngSibling", RENDER_SCENE "-o {good} --stats {dir}/./good.png",
                "the PNG beside the EXR"},
        Refusal{"OutputOverTheEnvironmentMap", RENDER_SCENE "-o {env}", "environment map"},
        Refusal{"StatsOverTheMesh", RENDER_SCENE "-o {dir}/x.exr --stats {obj}", "mesh file"},
        Refusal{"ErrorImageOverTheTestImage", "compare {good} {goodpng} --error-image {good}",
                "--error-image: "},
        Refusal{"ErrorImageOverTheReference",
                "compare {good} {goodpng} --error-image {dir}/../refuses_"
                "ErrorImageOverTheReference/good.png",
                "the reference image"},
        Refusal{"StatsInAMissingDirectory", RENDER_SCENE "-o {good} --stats {dir}/no/s.json",
                "does not exist"},
        Refusal{"PngSiblingIsADirectory", RENDER_SCENE "-o {dir}/blocked.exr", "is a directory"},
        Refusal{"StatsUnderARegularFile", RENDER_SCENE "-o {good} --stats {good}/s.json",
                "--stats: cannot write"}),
    RefusalName);

// Numbers are taken as written or refused (no wraparound, NaN is not "not given"),
// empty values and combinations that would silently drop something are errors naming the option.
INSTANTIATE_TEST_SUITE_P(
    Numbers, CliRefuses,
    ::testing::Values(
        Refusal{"ResolutionWraparound", RENDER_CUBE "--resolution 4294967360x64",
                "--resolution: '4294967360x64'"},
        Refusal{"FramesWraparound", RENDER_CUBE "--frames 0:4294967296", "--frames"},
        Refusal{"SecondsNan", RENDER_CUBE "--seconds nan", "--seconds: expected a number"},
        Refusal{"AoDistanceNan", RENDER_CUBE "--ao-distance nan", "--ao-distance: expected"},
        Refusal{"TessellationRateNan", RENDER_CUBE "--tessellation-rate nan",
                "--tessellation-rate: expected"},
        Refusal{"TimeNan", RENDER_CUBE "--time nan", "--time: expected a number"},
        Refusal{"ExposureRange", RENDER_CUBE "--exposure 1e9",
                "--exposure: value 1e+09 is out of range [-64, 64]"},
        Refusal{"EmptyIntegrator", RENDER_CUBE "--integrator ''", "--integrator: empty value"},
        Refusal{"EmptyThreads", RENDER_CUBE "--threads ''", "--threads: empty value"},
        Refusal{"EmptyFrames", RENDER_CUBE "--frames ''", "--frames: empty value"},
        Refusal{"EmptyFrameBuffers", RENDER_CUBE "--frame-buffers ''",
                "--frame-buffers: empty value"},
        Refusal{"FilterRadiusMinusOne", RENDER_CUBE "--shading texture --filter-radius -1",
                "--filter-radius"},
        Refusal{"SoftShadowWithAo",
                RENDER_CUBE "--shading texture --filter softshadow "
                            "--integrator ao",
                "--filter: softshadow"},
        Refusal{"MaterialSoftShadowWithAo",
                "render {dir}/soft.json --spp 1 --resolution 8x8 -q -o {dir}/x.png "
                "--shading texture --integrator ao",
                "soft.json: material 'clay': filter softshadow filters area-light visibility"},
        Refusal{"MaterialSoftShadowAtTheHits",
                "render {dir}/soft.json --spp 1 --resolution 8x8 -q -o {dir}/x.png "
                "--shading texture --integrator direct --cached-light all",
                "material 'clay': filter softshadow"},
        Refusal{"AovIntoPng", RENDER_CUBE "--aov albedo", "--aov: AOV layers are written to EXR"},
        Refusal{"CacheBeyondMemory", RENDER_CUBE "--shading texture --sample-cache-mb 1048576",
                "do not fit in this machine's"}),
    RefusalName);

// CLI11's own errors (a bad number, an unknown option, a repeated option, a missing
// argument) in the same one-line form, pointing at --help.
INSTANTIATE_TEST_SUITE_P(
    Messages, CliRefuses,
    ::testing::Values(
        Refusal{"BadNumber", "render {cube} --spp abc", "--spp = abc (see texcache render --help)"},
        Refusal{"UnknownOption", "render {cube} --bogus", "--bogus (see texcache render --help)"},
        Refusal{"RepeatedOption", "render {cube} --spp 1 --spp 2", "--spp"},
        Refusal{"MissingArgument", "compare {good}", "reference"},
        Refusal{"UnknownGeometry", "render {cube} --geometry nurbs",
                "--geometry: nurbs not in {subdivision,quads}"}),
    RefusalName);

// compare of a PNG (sRGB-encoded) with an EXR (linear) of the same picture decodes the PNG and
// says so: the error is the PNG's 8-bit quantization (relMSE < 1e-4), not the encoding (~0.09).
TEST(Cli, CompareDecodesSrgbAgainstLinearAndSaysSo) {
    const fs::path exr = Dir() / "enc.exr", png = Dir() / "enc.png";
    Image ramp(32, 4, 3);
    for (size_t i = 0; i < ramp.data.size(); ++i) ramp.data[i] = 0.1f + 0.8f * float(i % 32) / 31;
    WriteImage(exr.string(), ramp);
    WriteImage(png.string(), ramp);
    const CliRun r = Texcache("compare " + png.string() + " " + exr.string() + " --json");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("decoded to linear"), std::string::npos) << r.out;
    const size_t at = r.out.find("\"relmse\": ");
    ASSERT_NE(at, std::string::npos) << r.out;
    EXPECT_LT(std::stod(r.out.substr(at + 10)), 1e-4) << r.out;
}

// compare never trusts an EXR header's size: a 23 KB file claiming 46340x46340 pixels is refused
// at once, before anything is allocated for the size it claims (8.5 GB).
TEST(Cli, CompareRefusesHeadersClaimingHugeSizes) {
    const fs::path liar = Dir() / "liar.exr";
    WriteImage(liar.string(), Image(64, 64, 1, 0.5f));
    test::ClaimExrSize(liar.string(), 46340, 46340);
    const std::string args = "compare " + liar.string() + " " + liar.string();
    ExpectOneLineError(Texcache(args), args, "46340x46340");
}

// `preview --bench --bench-equal-error`: per hit runs the orbit again with 2, 4 and 8 spp while
// its denoised relMSE is above texture space's, each pass timing both, and the last line says
// where per hit got to. A 32x18 cube in 2 frames: the wiring, not the figures.
TEST(Cli, PreviewBenchLooksForPerHitsCostAtTextureSpacesError) {
    const fs::path out = Dir() / "equal_error" / "bench";
    const CliRun r = Texcache("preview " + test::MeshPath("catmark_cube") +
                              " --bench --denoise reliable --resolution 32x18 --bench-frames 2 "
                              "--reference-spp 2 --bench-equal-error --bench-out " +
                              out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("equal error: per hit"), std::string::npos) << r.out;
    // None when per hit is below texture space's error at once, else a pass per doubling until
    // it gets there (at most 8 spp).
    const bool done = r.out.find("already") != std::string::npos ||
                      r.out.find("per hit reaches") != std::string::npos;
    EXPECT_TRUE(done || r.out.find("per hit at  8 spp:") != std::string::npos) << r.out;
    EXPECT_TRUE(fs::exists(out.string() + "_stage_texture.png"));
}

// `--geometry both`: the stage bench times the texture-space frames on the limit quads and on
// Embree's subdivision surfaces in turn, says the ratio of their render CPU and both errors,
// and writes each picture to its own file. Only the stage's bench has it: elsewhere it is an
// error naming the option. A 32x18 torus in 2 frames: the wiring, not the figures.
TEST(Cli, PreviewBenchComparesTheTwoGeometries) {
    const fs::path out = Dir() / "geometries" / "bench";
    const std::string scene = test::MeshPath("catmark_torus");
    const CliRun r = Texcache("preview " + scene +
                              " --bench --denoise reliable --resolution 32x18 --bench-frames 2 "
                              "--reference-spp 2 --fb-cache store --geometry both --bench-out " +
                              out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("store subdiv :"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("geometry: store render CPU a frame"), std::string::npos) << r.out;
    EXPECT_TRUE(fs::exists(out.string() + "_stage_texture.png"));
    EXPECT_TRUE(fs::exists(out.string() + "_stage_texture_subdivision.png"));
    for (const std::string args : {" --geometry both", " --bench --geometry both"}) {
        const CliRun bad = Texcache("preview " + scene + args);
        EXPECT_EQ(bad.code, 2) << args;
        EXPECT_NE(bad.out.find("--geometry: 'both' compares the two in the stage's bench"),
                  std::string::npos)
            << bad.out;
    }
}

// `bench peer` without Embree's pathtracer: one line saying so, exit 2, nothing rendered. The
// cage check comes first: a cage the peer cannot take is named whether or not it is installed.
TEST(Cli, BenchPeerSaysWhatItCannotRun) {
    const fs::path out = Dir() / "peer";
    fs::remove_all(out);
    const std::string cube = test::MeshPath("catmark_cube");
    CliRun r =
        Texcache("bench peer " + cube + " --pathtracer /no/such/pathtracer --out " + out.string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("/no/such/pathtracer: Embree's pathtracer is not installed"),
              std::string::npos)
        << r.out;
    EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
    EXPECT_FALSE(fs::exists(out));

    // A reference with no more samples than the timed renders is refused before anything runs.
    r = Texcache("bench peer " + cube + " --spp 64 --reference-spp 64 --out " + out.string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("--reference-spp: must be more than --spp (64), got 64"),
              std::string::npos)
        << r.out;
    EXPECT_FALSE(fs::exists(out));

    // Found on PATH by default: with an empty PATH it is not.
    const std::string path = std::getenv("PATH") ? std::getenv("PATH") : "";
    setenv("PATH", "/no/such/dir", 1);
    r = Texcache("bench peer " + cube + " --out " + out.string());
    setenv("PATH", path.c_str(), 1);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("bench peer: Embree's pathtracer is not installed (Debian: apt-get "
                         "install embree-tools)"),
              std::string::npos)
        << r.out;

    const fs::path big = Dir() / "sixteen.obj";
    {
        std::ofstream f(big);
        for (int i = 0; i < 16; ++i)
            f << "v " << std::cos(0.3927 * i) << " " << std::sin(0.3927 * i) << " 0\n";
        f << "f";
        for (int i = 1; i <= 16; ++i) f << " " << i;
        f << "\n";
    }
    r = Texcache("bench peer " + big.string() + " --out " + out.string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("cannot render this cage: a face of 16 vertices"), std::string::npos)
        << r.out;
    EXPECT_FALSE(fs::exists(out));
}

/// A number field of a --stats JSON file.
double StatsField(const fs::path& stats, const std::string& name) {
    std::ifstream f(stats);
    std::stringstream text;
    text << f.rdbuf();
    const std::string json = text.str(), key = "\"" + name + "\": ";
    const size_t at = json.find(key);
    return at == std::string::npos ? NAN : std::stod(json.substr(at + key.size()));
}

// Without --sample-cache-mb/--texel-cache-mb the caches are sized to the frame (4 MiB floor at
// this size, SizeCachesToFrame), not the 64 MiB a large frame takes; a given size is kept. AO
// shaded at the hits (the default for AO) never looks them up: they are never allocated.
TEST(Cli, CachesAreSizedToTheFrameUnlessGiven) {
    const fs::path out = Dir() / "sized.exr", stats = Dir() / "sized.json";
    const std::string hits = "render " + test::SceneDir() +
                             "/car.json --integrator ao --resolution 64x36 --spp 1 --shading "
                             "texture -q --no-png -o " +
                             out.string() + " --stats " + stats.string();
    CliRun r = Texcache(hits);
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(StatsField(stats, "sample_cache_bytes"), 0.0);
    EXPECT_EQ(StatsField(stats, "texel_cache_bytes"), 0.0);
    EXPECT_GT(StatsField(stats, "hit_bin_bytes"), 0.0);
    EXPECT_EQ(StatsField(stats, "hit_bins_dropped"), 0.0);
    const std::string render = hits + " --ts-samples grid";
    r = Texcache(render);
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(StatsField(stats, "sample_cache_bytes"), double(4 << 20));
    EXPECT_EQ(StatsField(stats, "texel_cache_bytes"), double(4 << 20));
    r = Texcache(render + " --texel-cache-mb 8");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(StatsField(stats, "sample_cache_bytes"), double(4 << 20));
    EXPECT_EQ(StatsField(stats, "texel_cache_bytes"), double(8 << 20));
}

// Path tracing with --shading texture bins diffuse light at the hits by default (its grid caches
// are then never allocated); an option of the grid's cache (here --filter) takes the grid.
TEST(Cli, PathTracingShadesAtTheHitsByDefault) {
    const fs::path out = Dir() / "path_hits.exr", stats = Dir() / "path_hits.json";
    const std::string render = "render " + test::SceneDir() +
                               "/car.json --integrator path --resolution 64x36 --spp 2 "
                               "--shading texture -q --no-png -o " +
                               out.string() + " --stats " + stats.string();
    CliRun r = Texcache(render);
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_GT(StatsField(stats, "hit_bin_bytes"), 0.0);
    EXPECT_EQ(StatsField(stats, "texel_cache_bytes"), 0.0);
    r = Texcache(render + " --filter normal");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(StatsField(stats, "hit_bin_bytes"), 0.0);
}

// Cached product sampling: --stats reports the record cache (its bytes counted in bytes_used);
// without an environment light the option is one line naming the problem, exit 2.
TEST(Cli, LightSamplingCpisReportsRecordBytes) {
    const fs::path out = Dir() / "cpis.exr", stats = Dir() / "cpis_stats.json";
    const CliRun r = Texcache("render " + test::SceneDir() +
                              "/brushed.json --resolution 32x24 --spp 4 --light-sampling cpis -q "
                              "--no-png -o " +
                              out.string() + " --stats " + stats.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("product sampling records:"), std::string::npos) << r.out;
    std::ifstream f(stats);
    std::stringstream text;
    text << f.rdbuf();
    const std::string json = text.str();
    const size_t at = json.find("\"psr_cache_bytes\": ");
    ASSERT_NE(at, std::string::npos) << json;
    EXPECT_GT(std::stod(json.substr(at + 19)), 1e6) << json;  // the 16 MiB default
    EXPECT_NE(json.find("\"psr_built\": "), std::string::npos);

    const CliRun none = Texcache("render " + test::SceneDir() +
                                 "/sunlit.json --light-sampling cpis -q -o " + out.string());
    EXPECT_EQ(none.code, 2);
    EXPECT_EQ(std::count(none.out.begin(), none.out.end(), '\n'), 1) << none.out;
}

// `bench peer` compares like with like: both sides' high-sample renders show the same light. The
// peer's diffuse response is twice ours (cmd_bench_peer.cpp says how it was measured) and its
// pixels clip at 1, so its scene takes half the albedo; without that the car's body would be 1.0 on
// its side against 0.5 on ours: relMSE ~0.1 between the references, where noise at 64 spp on
// 48x48 pixels gives ~0.005. Needs Embree's pathtracer (scripts/setup.sh installs embree-tools).
TEST(Cli, BenchPeerReferencesShowTheSameLight) {
    ASSERT_EQ(::access("/usr/bin/pathtracer", X_OK), 0)
        << "Embree's pathtracer is missing: scripts/setup.sh installs embree-tools";
    const fs::path out = Dir() / "peer_light";
    fs::remove_all(out);
    const CliRun r = Texcache(
        "bench peer --resolution 48x48 --spp 4 --reference-spp 64 --repeats 1 "
        "--pathtracer /usr/bin/pathtracer --out " +
        out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    const size_t at = r.out.find("references against each other: relMSE ");
    ASSERT_NE(at, std::string::npos) << r.out;
    double relmse = -1.0, meanOurs = -1.0, meanPeer = -1.0;
    ASSERT_EQ(std::sscanf(r.out.c_str() + at,
                          "references against each other: relMSE %lf, mean value ours %lf, "
                          "Embree %lf",
                          &relmse, &meanOurs, &meanPeer),
              3)
        << r.out;
    EXPECT_LT(relmse, 0.03) << r.out;
    EXPECT_NEAR(meanOurs, meanPeer, 0.01) << r.out;
}

}  // namespace
}  // namespace texcache
