// SPDX-License-Identifier: Apache-2.0
// Hostile and careless input through the `texcache` program (issue 47), class by class: scenes
// at any scale render (never an abort inside Embree, never a silent blank image), light and
// textures that are not finite are repaired with a warning or refused on one line, and a render
// that cannot show anything says why. Every refusal is one line and exit code 2.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

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

// ---- Flags that do nothing
// -----------------------------------------------------------------------

// An option the integrator, the shading mode or the other options leave unused is one line
// naming it (each would otherwise be ignored in silence).
TEST(UnusedFlags, AreOneLineNamingTheOption) {
    const std::string cube = " " + test::MeshPath("catmark_cube");
    const std::string png = " -q --spp 1 --resolution 16x16 -o " + (Dir() / "flag.png").string();
    const std::string exr = " -q --spp 1 --resolution 16x16 -o " + (Dir() / "flag.exr").string();
    struct Case {
        std::string args, names;
    };
    for (const Case& c : {
             Case{"render --integrator path --ao-distance 3" + cube + png, "--ao-distance"},
             Case{"render --integrator direct --ao-samples 3" + cube + png, "--ao-samples"},
             Case{"render --integrator ao --max-depth 3" + cube + png, "--max-depth"},
             Case{"render --integrator ao --hit-samples 2" + cube + png, "--hit-samples"},
             Case{"render --pass-spp 4" + cube + png, "--pass-spp"},
             Case{"render --filter gaussian" + cube + png, "--filter"},
             Case{"render --direct-mapped" + cube + png, "--direct-mapped"},
             Case{"render --shadow-samples 8" + cube + png, "--shadow-samples"},
             Case{"render --psr-cache-mb 4" + cube + png, "--psr-cache-mb"},
             Case{"render --psr-lod-bias 2" + cube + png, "--psr-lod-bias"},
             Case{"render --fps 10" + cube + png, "--fps"},
             Case{"render --seed 18446744073709551616" + cube + png, "--seed"},
             Case{"render --seed 0x10" + cube + png, "--seed"},
             Case{"render --seed -1" + cube + png, "--seed"},
             Case{"render --no-png" + cube + png, "--no-png"},
             Case{"render --no-png --exposure 2" + cube + exr, "--exposure"},
             Case{"preview --bench --frames 3 --bench-frames 1" + cube, "--frames"},
             Case{"preview --fps 10" + cube, "--fps"},
             Case{"preview --bench-still" + cube, "--bench-still"},
             Case{"preview --bench-frames 3" + cube, "--bench-frames"},
             Case{"preview --bench --bench-fixed-alpha" + cube, "--bench-fixed-alpha"},
             Case{"preview --bench-equal-error" + cube, "--bench-equal-error"},
             Case{"preview --bench --denoise off --bench-equal-error" + cube,
                  "--bench-equal-error"},
             Case{"experiment cpis --methods per-hit --quick --out " + (Dir() / "x").string(),
                  "--methods"},
             Case{"experiment cpis --ablation --quick --out " + (Dir() / "x").string(),
                  "--ablation"},
         }) {
        const CliRun r = Texcache(c.args);
        EXPECT_TRUE(OneLineError(r)) << c.args;
        EXPECT_NE(r.out.find("error: " + c.names + ":"), std::string::npos) << c.args << "\n"
                                                                            << r.out;
    }
    EXPECT_FALSE(fs::exists(Dir() / "x"));
    // The whole documented range of --seed is taken.
    const CliRun top = Texcache("render --seed 18446744073709551615" + cube + png);
    EXPECT_EQ(top.code, 0) << top.out;
}

// ---- Sizes the machine cannot hold
// ---------------------------------------------------------------

// A render expected to need more memory than allowed (2048 MiB by default, --max-memory-mb, never
// more than the memory available) is refused before it allocates, in one line naming the option
// that asks for the size and the MiB it would need; the same frame renders once allowed. The
// refusals run in milliseconds: nothing the size of the frame is allocated.
TEST(TooBig, RendersBeyondTheMemoryBudgetAreOneLineNamingTheOption) {
    const std::string cube = " " + test::MeshPath("catmark_cube") + " -q --spp 1 ";
    const std::string png = " -o " + (Dir() / "big.png").string();
    const std::string fb = " --frame-buffers " + (Dir() / "bigfb").string();
    fs::remove(Dir() / "big.png");
    struct Case {
        std::string args, names;
    };
    for (const Case& c : {
             Case{"--integrator normal --resolution 16384x16384" + png, "--resolution"},
             Case{"--resolution 16384x16384 --stereo" + png, "--resolution"},
             Case{"--integrator normal --resolution 16384x16384 --aov all -o " +
                      (Dir() / "big.exr").string(),
                  "--resolution"},
             Case{"--resolution 16384x16384" + fb, "--resolution"},
             Case{"--resolution 512x512 --max-memory-mb 8" + png, "--resolution"},
             // Shading at the hits keeps a record per camera sample (about 9 MiB a sample per
             // pixel here, 3 MiB for AO), which the film alone would not count.
             Case{"--resolution 640x360 --integrator path --shading texture --max-memory-mb 48" +
                      png,
                  "--resolution"},
             Case{"--resolution 48x36 --shading texture --sample-cache-mb 20000" + png,
                  "--sample-cache-mb/--texel-cache-mb"},
             Case{"--resolution 48x36 --shading texture --texel-cache-mb 3000" + png,
                  "--sample-cache-mb/--texel-cache-mb"},
         }) {
        // The time limit catches a render that goes ahead (minutes at these sizes), with room
        // for a loaded machine's process start.
        const CliRun r = Texcache("render" + cube + c.args, 60);
        EXPECT_TRUE(OneLineError(r)) << c.args;
        EXPECT_NE(r.out.find("error: " + c.names + ":"), std::string::npos) << c.args << "\n"
                                                                            << r.out;
        EXPECT_NE(r.out.find("needs about"), std::string::npos) << r.out;
    }
    EXPECT_FALSE(fs::exists(Dir() / "big.png"));
    const CliRun psr = Texcache("render " + test::SceneDir() +
                                "/brushed.json -q --spp 1 --resolution 48x36 --integrator direct "
                                "--light-sampling cpis --psr-cache-mb 20000" +
                                png);
    EXPECT_TRUE(OneLineError(psr));
    EXPECT_NE(psr.out.find("error: --psr-cache-mb:"), std::string::npos) << psr.out;
    const CliRun ok = Texcache("render" + cube + "--resolution 48x36 --max-memory-mb 64" + png);
    EXPECT_EQ(ok.code, 0) << ok.out;
    const CliRun pv =
        Texcache("preview --bench --resolution 16384x16384 " + test::MeshPath("catmark_cube"), 20);
    EXPECT_TRUE(OneLineError(pv));
    EXPECT_NE(pv.out.find("--resolution"), std::string::npos) << pv.out;
}

// montage and compare read the images' headers first and refuse, in one line, inputs whose
// decoded pixels would not fit; TEXCACHE_MAX_MEMORY_MB sets the budget (here 32 MiB, so small
// images stand in for huge ones).
TEST(TooBig, MontageAndCompareCheckTheHeadersFirst) {
    const fs::path a = Dir() / "big_in.exr";
    WriteImage(a.string(), Image(400, 300, 3, 0.25f));
    fs::remove(Dir() / "big_montage.exr");
    ::setenv("TEXCACHE_MAX_MEMORY_MB", "32", 1);
    const CliRun m = Texcache("montage " + a.string() + " " + a.string() + " -o " +
                              (Dir() / "big_montage.exr").string());
    const CliRun c = Texcache("compare " + a.string() + " " + a.string());
    ::unsetenv("TEXCACHE_MAX_MEMORY_MB");
    EXPECT_TRUE(OneLineError(m));
    EXPECT_NE(m.out.find("TEXCACHE_MAX_MEMORY_MB="), std::string::npos) << m.out;
    EXPECT_FALSE(fs::exists(Dir() / "big_montage.exr"));
    EXPECT_TRUE(OneLineError(c));
    const CliRun fine = Texcache("montage " + a.string() + " " + a.string() + " -o " +
                                 (Dir() / "big_montage.exr").string());
    EXPECT_EQ(fine.code, 0) << fine.out;
}

// ---- Outputs
// -------------------------------------------------------------------------------------

// montage refuses to write over one of its inputs, which stays as it was; --exposure on an EXR
// output is an error.
TEST(Outputs, MontageNeverOverwritesItsInput) {
    const fs::path a = Dir() / "montage_in.exr";
    WriteImage(a.string(), Image(4, 2, 3, 0.25f));
    const auto before = fs::file_size(a);
    const auto mtime = fs::last_write_time(a);
    const CliRun r = Texcache("montage " + a.string() + " " + a.string() + " -o " + a.string());
    EXPECT_TRUE(OneLineError(r));
    EXPECT_EQ(fs::file_size(a), before);
    EXPECT_EQ(fs::last_write_time(a), mtime);
    const CliRun e = Texcache("montage --exposure 3 " + a.string() + " -o " +
                              (Dir() / "montage_out.exr").string());
    EXPECT_TRUE(OneLineError(e));
    EXPECT_NE(e.out.find("--exposure"), std::string::npos) << e.out;
}

// An output name of up to 255 bytes is written (its temporary name is cut to fit, with a hash),
// EXR and PNG beside it, and a longer one is refused before rendering.
TEST(Outputs, AnyLegalFileNameIsWritten) {
    const std::string cube = " " + test::MeshPath("catmark_cube") + " -q --spp 1 --resolution 8x8";
    const fs::path exr = Dir() / (std::string(251, 'e') + ".exr");
    const CliRun r = Texcache("render" + cube + " -o " + exr.string());
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(fs::exists(exr));
    EXPECT_TRUE(fs::exists(fs::path(exr).replace_extension(".png")));
    for (const auto& e : fs::directory_iterator(Dir()))
        EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
    const CliRun tooLong =
        Texcache("render" + cube + " -o " + (Dir() / (std::string(300, 'z') + ".png")).string());
    EXPECT_TRUE(OneLineError(tooLong));
    EXPECT_NE(tooLong.out.find("255"), std::string::npos) << tooLong.out;
}

// Temporaries left by a killed run (its pid gone) are removed by the next run writing into the
// directory; those of a live process (pid 1) and other files are kept.
TEST(Outputs, StaleTemporariesOfDeadProcessesAreRemoved) {
    const fs::path d = Dir() / "stale";
    fs::create_directories(d);
    pid_t dead = 4000000;
    while (dead > 2 && !(::kill(dead, 0) != 0 && errno == ESRCH)) --dead;
    const std::string deadPid = std::to_string(dead);
    for (const std::string& name :
         std::vector<std::string>{"a.png.tmp-" + deadPid, "b.exr.probe-" + deadPid, "c.png.tmp-1",
                                  "d.tmp-x" + deadPid, "notes.txt"})
        Write(d / name, "x");
    const CliRun r = Texcache("render " + test::MeshPath("catmark_cube") +
                              " -q --spp 1 --resolution 8x8 -o " + (d / "out.png").string());
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_FALSE(fs::exists(d / ("a.png.tmp-" + deadPid)));
    EXPECT_FALSE(fs::exists(d / ("b.exr.probe-" + deadPid)));
    EXPECT_TRUE(fs::exists(d / "c.png.tmp-1"));
    EXPECT_TRUE(fs::exists(d / ("d.tmp-x" + deadPid)));
    EXPECT_TRUE(fs::exists(d / "notes.txt"));
}

// ---- One line
// ------------------------------------------------------------------------------------

// An unknown subcommand or experiment is named; an experiment refusing its options leaves no
// empty --out directory.
TEST(OneLine, UnknownWordsAreNamedAndNothingIsLeft) {
    const CliRun bench = Texcache("bench bogus");
    EXPECT_TRUE(OneLineError(bench));
    EXPECT_NE(bench.out.find("'bogus'"), std::string::npos) << bench.out;
    const CliRun exp = Texcache("experiment bogus --out " + (Dir() / "e").string());
    EXPECT_TRUE(OneLineError(exp));
    EXPECT_NE(exp.out.find("'bogus'"), std::string::npos) << exp.out;
    const fs::path out = Dir() / "exp_nope";
    const CliRun methods =
        Texcache("experiment speed-vs-error --quick --methods nope --out " + out.string());
    EXPECT_TRUE(OneLineError(methods));
    EXPECT_FALSE(fs::exists(out));
}

// ---- Fuzzing the whole program
// -------------------------------------------------------------------

/// The numbers most likely to break a renderer: beyond float, at Embree's and the loader's
/// limits, below float's normal range, zero, negative, not a number.
const char* const kHostile[] = {"1e30", "-1e30", "5e17",       "1e18", "-7e17", "1e-40",
                                "1e-8", "0",     "-0",         "nan",  "inf",   "-1",
                                "3e38", "1e10",  "2147483648", "-5"};

/// Replaces one number of `text` (chosen by `rng`) with a hostile one, or every number with
/// itself times a hostile scale (`scaleAll`, OBJ vertices only).
std::string MutateNumbers(const std::string& text, std::mt19937& rng, bool scaleAll) {
    static const std::regex number(R"(-?[0-9]+(\.[0-9]+)?(e-?[0-9]+)?)");
    std::vector<std::pair<size_t, size_t>> spans;
    for (auto it = std::sregex_iterator(text.begin(), text.end(), number);
         it != std::sregex_iterator(); ++it)
        spans.emplace_back(size_t(it->position()), size_t(it->length()));
    if (spans.empty()) return text;
    const char* hostile = kHostile[rng() % std::size(kHostile)];
    if (!scaleAll) {
        const auto [at, n] = spans[rng() % spans.size()];
        return text.substr(0, at) + hostile + text.substr(at + n);
    }
    std::string out;
    size_t last = 0;
    for (const auto& [at, n] : spans) {
        out += text.substr(last, at - last);
        const bool vertex = at > 1 && text.compare(text.rfind('\n', at) + 1, 2, "v ") == 0;
        char buf[64];
        std::snprintf(buf, sizeof buf, "%.9g",
                      std::stod(text.substr(at, n)) * std::strtod(hostile, nullptr));
        out += vertex ? std::string(buf) : text.substr(at, n);
        last = at + n;
    }
    return out + text.substr(last);
}

// Seeded mutations of a small scene that uses every input kind (an OBJ cage, a JSON scene with a
// camera, stereo rig, material texture and each kind of light, an EXR environment map and
// texture), rendered by the program with each integrator at a tiny size: every run exits 0, or
// 2 with one error line (after any warnings); never a signal, never past the time limit. 160 runs,
// about 20 s in Release.
TEST(FuzzRender, MutatedScenesRenderOrAreOneLine) {
    const fs::path d = Dir() / "fuzz";
    fs::create_directories(d);
    std::ifstream cubeFile(test::MeshPath("catmark_cube"));
    const std::string cube((std::istreambuf_iterator<char>(cubeFile)), {});
    const std::string scene = R"({
  "camera": {"position": [3, 2, 4], "look_at": [0, 0, 0], "fov": 40, "lens_radius": 0.01,
             "focus_distance": 5, "stereo": {"eye_separation": 0.1, "convergence": 5}},
  "materials": {"m": {"type": "ggx", "albedo": {"texture": "tex.exr"}, "roughness": [0.3, 0.2]}},
  "objects": [{"mesh": "cube.obj", "material": "m",
               "transform": {"translate": [0, 0, 0], "rotate": [30, 0, 1, 0], "scale": 1}}],
  "lights": [{"type": "environment", "file": "env.exr", "intensity": 1},
             {"type": "quad", "corner": [-1, 3, -1], "edge1": [2, 0, 0], "edge2": [0, 0, 2],
              "radiance": [2, 2, 2]},
             {"type": "distant", "direction": [-0.4, -1, -0.5], "irradiance": [1, 1, 1]},
             {"type": "point", "position": [2, 2, 2], "intensity": [3, 3, 3], "radius": 0.1}],
  "render": {"resolution": [16, 12], "spp": 1, "max_depth": 3, "ao_distance": 2}
})";
    std::mt19937 rng(47);
    const char* integrators[] = {"normal", "ao", "direct", "path"};
    const float texel[] = {NAN, INFINITY, -INFINITY, -3.0f, 3e38f, 0.0f, 1e-40f};
    int refused = 0;
    constexpr int kRuns = 160;
    for (int i = 0; i < kRuns; ++i) {
        std::string obj = cube, json = scene;
        Image env(16, 8, 3, 1.0f), tex(4, 4, 3, 0.5f);
        switch (i % 4) {
            case 0:
                obj = MutateNumbers(cube, rng, rng() % 3 == 0);
                break;
            case 1:
            case 2:
                json = MutateNumbers(scene, rng, false);
                break;
            default:
                for (Image* img : {&env, &tex})
                    for (int k = int(rng() % 4); k >= 0; --k)
                        img->data[rng() % img->data.size()] = texel[rng() % std::size(texel)];
        }
        Write(d / "cube.obj", obj);
        Write(d / "scene.json", json);
        WriteImage((d / "env.exr").string(), env);
        WriteImage((d / "tex.exr").string(), tex);
        const std::string args = "render " + (d / "scene.json").string() + " --integrator " +
                                 integrators[(i / 4) % 4] + (i % 7 == 0 ? " --stereo" : "") +
                                 " -q -o " + (d / "out.png").string();
        const CliRun r = Texcache(args, 60);
        // A refusal is one error line, the last; warnings about other inputs may precede it.
        size_t errors = 0, others = 0;
        std::istringstream lines(r.out);
        for (std::string line; std::getline(lines, line);)
            (line.starts_with("texcache: error: ") ? errors : others) +=
                !line.starts_with("texcache: warning: ");
        const bool ok = r.code == 0 || (r.code == 2 && errors == 1 && others == 0 &&
                                        r.out.rfind("texcache: error: ") ==
                                            r.out.rfind('\n', r.out.size() - 2) + 1);
        EXPECT_TRUE(ok) << "run " << i << " (" << args << "): exit " << r.code << "\n"
                        << r.out << "\nscene:\n"
                        << json << "\n";
        if (!ok)
            fs::copy(d, Dir() / ("fuzz_failed_" + std::to_string(i)),
                     fs::copy_options::recursive | fs::copy_options::overwrite_existing);
        refused += r.code == 2;
    }
    // Most mutations are still renderable scenes: the test exercises the renderer, not only the
    // loader's refusals.
    EXPECT_LT(refused, kRuns * 3 / 4);
}

}  // namespace
}  // namespace texcache
