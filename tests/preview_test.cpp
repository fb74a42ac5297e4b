// SPDX-License-Identifier: Apache-2.0
// `texcache preview` tested as a person would use it: under Xvfb (Mesa software OpenGL) with a
// scripted camera orbit, reading back what the window shows; and without any display.
// xvfb-run comes from scripts/setup.sh (packages xvfb, xauth, libgl1-mesa-dri): when it is missing
// the test fails rather than skips, so a machine that was not set up cannot pass silently.
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "renderer/image.h"
#include "renderer/scene_loader.h"

namespace {

namespace fs = std::filesystem;

const std::string kBin = std::string(TEXCACHE_BIN_DIR) + "/texcache";
const std::string kScene = std::string(TEXCACHE_SOURCE_DIR) + "/scenes/car.json";

struct ShellResult {
    int exitCode = -1;
    std::string output;  // stdout + stderr
};

ShellResult Shell(const std::string& cmd) {
    ShellResult r;
    FILE* p = popen((cmd + " 2>&1").c_str(), "r");
    if (!p) return r;
    char buf[4096];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
    const int status = pclose(p);
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

fs::path TempDir(const std::string& name) {
    const fs::path d = fs::temp_directory_path() / ("texcache_preview_test_" + name);
    fs::remove_all(d);
    fs::create_directories(d);
    return d;
}

std::string ReadText(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
}

/// Hit rate the preview prints after the scripted move, in percent (-1 when absent).
double HitRateAfterMove(const std::string& out) {
    const std::string key = "cache hit rate after the move: ";
    const size_t at = out.find(key);
    return at == std::string::npos ? -1.0 : std::atof(out.c_str() + at + key.size());
}

TEST(Preview, HeadlessOrbitShowsTheSceneAndReusesTheCache) {
    ASSERT_EQ(Shell("command -v xvfb-run").exitCode, 0)
        << "xvfb-run is not installed: run scripts/setup.sh (installs xvfb, xauth, "
           "libgl1-mesa-dri)";
    const fs::path dir = TempDir("orbit");
    const fs::path shot = dir / "shot.png";
    // 256x256 keeps the software renderer quick; 8 frames over 8 degrees: 1.1 degrees per frame,
    // a slow interactive orbit.
    const ShellResult r =
        Shell("xvfb-run -a -s '-screen 0 1280x1024x24' " + kBin + " preview " + kScene +
              " --frames 8 --orbit 8 --resolution 256x256 --screenshot " + shot.string());
    ASSERT_EQ(r.exitCode, 0) << r.output;

    // Not blank: the window shows the rendered car and ground (AO: mostly bright grey) beside the
    // panel. The render area is the left 256 columns.
    const texcache::Image img = texcache::ReadImageRGB(shot.string());
    ASSERT_GE(img.width, 256);
    double sum = 0.0, sum2 = 0.0;
    size_t bright = 0, n = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < 256; ++x) {
            const float* p = img.At(x, y);
            const double v = (p[0] + p[1] + p[2]) / 3.0;
            sum += v, sum2 += v * v, ++n;
            bright += v > 0.3;
        }
    const double mean = sum / double(n);
    const double stddev = std::sqrt(std::max(0.0, sum2 / double(n) - mean * mean));
    // The 256x256 image fills 256 of the window's rows at most: >= 15% of the area is lit ground
    // or car (about 25% measured), and the picture has structure, not one flat colour.
    EXPECT_GT(double(bright) / double(n), 0.15) << r.output;
    EXPECT_GT(stddev, 0.1) << r.output;

    // Texture-space AO with LOD bias 1 keeps most texels across a 1-degree step: about 90% hit
    // after the move measured; 75% leaves room for jitter in which texels a pixel lands on.
    const double hitRate = HitRateAfterMove(r.output);
    EXPECT_GT(hitRate, 75.0) << r.output;
    fs::remove_all(dir);
}

TEST(Preview, SavesTheCameraAndKeepsTheRestOfTheSceneFile) {
    ASSERT_EQ(Shell("command -v xvfb-run").exitCode, 0)
        << "xvfb-run is not installed: run scripts/setup.sh";
    // A copy in a temporary folder, its relative mesh and envmap paths linked to the bundled ones.
    const fs::path dir = TempDir("camera");
    const fs::path scenes = fs::path(TEXCACHE_SOURCE_DIR) / "scenes";
    fs::create_directory_symlink(scenes / "meshes", dir / "meshes");
    fs::create_directory_symlink(scenes / "envmaps", dir / "envmaps");
    const fs::path copy = dir / "car.json";
    const std::string before = "// hand-written comment\n" + ReadText(scenes / "car.json");
    std::ofstream(copy, std::ios::binary) << before;
    const ShellResult r = Shell("xvfb-run -a " + kBin + " preview " + copy.string() +
                                " --frames 2 --orbit 30 --resolution 64x64 --save-camera");
    const std::string after = ReadText(copy);
    std::vector<std::string> warnings;
    texcache::Scene saved, original;
    EXPECT_NO_THROW(saved = texcache::LoadScene(copy.string(), &warnings)) << after;
    original = texcache::LoadScene((scenes / "car.json").string(), &warnings);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    // Everything but the camera object is byte-identical (comment and layout included).
    const size_t cam = before.find("\"camera\"");
    const size_t objects = before.find("\"materials\"");
    ASSERT_NE(cam, std::string::npos);
    EXPECT_EQ(after.substr(0, cam), before.substr(0, cam));
    EXPECT_EQ(after.substr(after.find("\"materials\"")), before.substr(objects));
    // The camera moved by the orbit (30 degrees about the pivot), same field of view.
    const glm::vec3 p0 = glm::vec3(original.camera.pose.Eval(0.0f)[3]);
    const glm::vec3 p1 = glm::vec3(saved.camera.pose.Eval(0.0f)[3]);
    EXPECT_GT(glm::length(p1 - p0), 0.5f);
    EXPECT_NEAR(saved.camera.fovYDegrees, original.camera.fovYDegrees, 1e-4f);
    fs::remove_all(dir);
}

TEST(Preview, WithoutADisplayFailsCleanly) {
    const ShellResult r = Shell("env -u DISPLAY -u WAYLAND_DISPLAY " + kBin + " preview " + kScene);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("no display"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("xvfb-run"), std::string::npos) << r.output;
}

}  // namespace
