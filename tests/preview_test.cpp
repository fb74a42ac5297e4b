// SPDX-License-Identifier: Apache-2.0
// `texcache preview` tested as a person would use it: under Xvfb (Mesa software OpenGL) with a
// scripted camera orbit, reading back what the window shows; and without any display.
// xvfb-run comes from scripts/setup.sh (packages xvfb, xauth, libgl1-mesa-dri): when it is missing
// the test fails rather than skips, so a machine that was not set up cannot pass silently.
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "renderer/image/image.h"
#include "renderer/image/metrics.h"
#include "renderer/preview/progressive_renderer.h"
#include "renderer/render.h"
#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene_loader.h"
#include "renderer/texture_space/texture_space.h"
#include "test_util.h"
#include "testing/cages.h"

namespace {

namespace fs = std::filesystem;

const std::string kBin = std::string(TEXCACHE_BIN_DIR) + "/texcache";
const std::string kScene = std::string(TEXCACHE_SOURCE_DIR) + "/scenes/car.json";
// The bundled animated scene: a torus tumbling about X over 2 s above a static ground.
const std::string kAnimated = std::string(TEXCACHE_SOURCE_DIR) + "/scenes/turntable.json";
constexpr float kPanelWidth = 380.0f;  // the preview panel's width (preview_app.cpp)

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
    const fs::path d = fs::path(::testing::TempDir()) / ("texcache_preview_test_" + name);
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

/// Runs the preview headless under Xvfb; `args` after the scene.
ShellResult Headless(const std::string& scene, const std::string& args) {
    return Shell("xvfb-run -a -s '-screen 0 1280x1024x24' " + kBin + " preview " + scene + " " +
                 args);
}

/// The rendered w x h image inside a window screenshot: the preview draws it left of the panel,
/// scaled to fit and centred (DrawImage in preview_app.cpp).
texcache::Image RenderArea(const texcache::Image& shot, int w, int h) {
    const float areaW = float(shot.width) - kPanelWidth, areaH = float(shot.height);
    const float s = std::min(areaW / float(w), areaH / float(h));
    const float x0 = 0.5f * (areaW - s * float(w)), y0 = 0.5f * (areaH - s * float(h));
    texcache::Image out(w, h, 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const int sx = std::clamp(int(x0 + (float(x) + 0.5f) * s), 0, shot.width - 1);
            const int sy = std::clamp(int(y0 + (float(y) + 0.5f) * s), 0, shot.height - 1);
            const float* src = shot.At(sx, sy);
            float* dst = out.At(x, y);
            dst[0] = src[0], dst[1] = src[1], dst[2] = src[2];
        }
    return out;
}

texcache::Image Screenshot(const fs::path& png, int w, int h) {
    return RenderArea(texcache::ReadImageRGB(png.string()), w, h);
}

/// Hit rate printed for headless frame `frame` ("frame N: t = T s, ..., cache hit rate H %"),
/// -1 when absent; `*time` gets T.
double FrameHitRate(const std::string& out, int frame, double* time = nullptr) {
    const std::string key = "frame " + std::to_string(frame) + ": t = ";
    const size_t at = out.find(key);
    if (at == std::string::npos) return -1.0;
    if (time) *time = std::atof(out.c_str() + at + key.size());
    const std::string rate = "cache hit rate ";
    const size_t r = out.find(rate, at);
    return r == std::string::npos ? -1.0 : std::atof(out.c_str() + r + rate.size());
}

/// Pixels of a hit/miss map by colour: green-dominant (hit), red-dominant (miss), and pixels
/// with any colour at all (geometry; the background is black).
struct HitMissPixels {
    size_t hit = 0, miss = 0, geometry = 0;
    double MissFraction() const { return hit + miss ? double(miss) / double(hit + miss) : 0.0; }
};
HitMissPixels ClassifyHitMiss(const texcache::Image& img) {
    HitMissPixels c;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const float* p = img.At(x, y);
            if (std::max({p[0], p[1], p[2]}) < 0.01f) continue;
            ++c.geometry;
            if (p[1] > 1.5f * p[0]) ++c.hit;
            if (p[0] > 1.5f * p[1]) ++c.miss;
        }
    return c;
}

/// Fraction of pixels whose colour differs by more than `tol` in some channel.
double DifferingFraction(const texcache::Image& a, const texcache::Image& b, float tol) {
    size_t n = 0;
    for (size_t i = 0; i < a.data.size(); i += 3)
        n += std::abs(a.data[i] - b.data[i]) > tol ||
             std::abs(a.data[i + 1] - b.data[i + 1]) > tol ||
             std::abs(a.data[i + 2] - b.data[i + 2]) > tol;
    return double(n) / double(a.data.size() / 3);
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
              " --integrator ao --denoise off --frames 8 --orbit 8 --resolution 256x256 "
              "--screenshot " +
              shot.string());
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

TEST(Preview, HitMissViewShowsMissesWhenColdAndHitsAfterASmallMove) {
    ASSERT_EQ(Shell("command -v xvfb-run").exitCode, 0) << "xvfb-run is not installed";
    const fs::path dir = TempDir("hitmiss");
    const fs::path cold = dir / "cold.png", moved = dir / "moved.png";
    const ShellResult a = Headless(
        kScene, "--integrator ao --view hitmiss --frames 1 --resolution 128x128 --screenshot " +
                    cold.string());
    ASSERT_EQ(a.exitCode, 0) << a.output;
    // 4 frames over 3 degrees: 1 degree per step.
    const ShellResult b = Headless(
        kScene,
        "--integrator ao --view hitmiss --frames 4 --orbit 3 --resolution 128x128 --screenshot " +
            moved.string());
    ASSERT_EQ(b.exitCode, 0) << b.output;
    const HitMissPixels c = ClassifyHitMiss(Screenshot(cold, 128, 128));
    const HitMissPixels m = ClassifyHitMiss(Screenshot(moved, 128, 128));
    // Car and ground fill most of the picture, and (1 spp) every geometry pixel is all-hit or
    // all-miss: no grey "no lookup", no yellow.
    EXPECT_GT(double(c.geometry), 0.4 * 128 * 128) << a.output;
    EXPECT_GT(double(c.hit + c.miss), 0.95 * double(c.geometry));
    // Cold cache: only pixels sharing a texel with an earlier pixel hit (LOD bias 1: ~2x2 pixels
    // per texel): 75% miss measured at 128x128 (a re-probe after the frame would show none).
    EXPECT_GT(c.MissFraction(), 0.6) << a.output;
    // After 1-degree steps the cache holds most texels: 20% miss measured.
    EXPECT_LT(m.MissFraction(), 0.3) << b.output;
    // The map agrees with the frame's own statistics (each pixel is one lookup).
    EXPECT_NEAR(100.0 * (1.0 - c.MissFraction()), HitRateAfterMove(a.output), 8.0) << a.output;
    EXPECT_NEAR(100.0 * (1.0 - m.MissFraction()), HitRateAfterMove(b.output), 8.0) << b.output;
    fs::remove_all(dir);
}

TEST(Preview, OvershadingViewShowsWhereFootprintsShadeSamples) {
    ASSERT_EQ(Shell("command -v xvfb-run").exitCode, 0) << "xvfb-run is not installed";
    const fs::path dir = TempDir("overshading");
    const fs::path shot = dir / "shot.png";
    // A 5x5 normal-filter footprint on a cold cache, every texel of the window (the paper's
    // footprint): misses shade up to 25 samples each.
    const ShellResult r =
        Headless(kScene,
                 "--integrator ao --view overshading --filter normal --filter-radius 2 "
                 "--footprint all --frames 1 --resolution 128x128 "
                 "--screenshot " +
                     shot.string());
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const std::string key = "overshading scale: 0 to ";
    const size_t at = r.output.find(key);
    ASSERT_NE(at, std::string::npos) << r.output;
    const double top = std::atof(r.output.c_str() + at + key.size());
    // The busiest pixel shaded about a footprint's worth (25), rounded up to a power of two: 32
    // measured.
    EXPECT_GE(top, 8.0) << r.output;
    EXPECT_LE(top, 64.0) << r.output;
    EXPECT_TRUE(std::isfinite(top));
    // Not blank and not one colour: geometry everywhere the car and ground are, with cold (blue:
    // few samples) and hot (red/yellow: many) pixels.
    const texcache::Image img = Screenshot(shot, 128, 128);
    size_t geometry = 0, cold = 0, hot = 0;
    for (size_t i = 0; i < img.data.size(); i += 3) {
        const float rr = img.data[i], g = img.data[i + 1], b = img.data[i + 2];
        ASSERT_TRUE(std::isfinite(rr + g + b));
        if (std::max({rr, g, b}) < 0.01f) continue;
        ++geometry;
        cold += b > rr;
        hot += rr > b;
    }
    const double n = 128.0 * 128.0;
    EXPECT_GT(double(geometry), 0.4 * n) << r.output;
    EXPECT_GT(double(cold), 0.05 * n) << r.output;
    EXPECT_GT(double(hot), 0.05 * n) << r.output;
    // Footprints of visible texels only (the default) shade fewer samples in all. (Not per pixel:
    // a miss there reconstructs the visible texels of its 8x8 block at once, and the samples of
    // the whole block count for the pixel whose lookup missed.)
    const ShellResult rv =
        Headless(kScene,
                 "--integrator ao --view overshading --filter normal --filter-radius 2 "
                 "--footprint visible --frames 1 --resolution 128x128 "
                 "--screenshot " +
                     (dir / "visible.png").string());
    ASSERT_EQ(rv.exitCode, 0) << rv.output;
    auto shaded = [](const std::string& out) {  // "..., N samples shaded" of frame 0
        const size_t end = out.find(" samples shaded");
        const size_t begin = out.rfind(' ', end - 1);
        return end == std::string::npos ? -1.0 : std::atof(out.c_str() + begin + 1);
    };
    ASSERT_GT(shaded(r.output), 0.0) << r.output;
    ASSERT_GT(shaded(rv.output), 0.0) << rv.output;
    EXPECT_LT(shaded(rv.output), shaded(r.output)) << r.output << rv.output;
    fs::remove_all(dir);
}

TEST(Preview, AnimatedSceneRendersTheTimeAskedAndReshadesPerFrame) {
    ASSERT_EQ(Shell("command -v xvfb-run").exitCode, 0) << "xvfb-run is not installed";
    const fs::path dir = TempDir("animation");
    auto run = [&](const std::string& name, const std::string& args, ShellResult* r) {
        const fs::path png = dir / (name + ".png");
        *r =
            Headless(kAnimated, args +
                                    " --integrator ao --denoise off --orbit 0 --resolution 128x128 "
                                    "--screenshot " +
                                    png.string());
        EXPECT_EQ(r->exitCode, 0) << r->output;
        return Screenshot(png, 128, 128);
    };
    ShellResult r0, rHalf, rPlay;
    const texcache::Image t0 = run("t0", "--frames 1 --time 0", &r0);
    const texcache::Image tHalf = run("thalf", "--frames 1 --time 0.5", &rHalf);
    // Frames at t = 0, 0.25, 0.5.
    const texcache::Image played = run("play", "--frames 3 --time 0 --play --fps 4", &rPlay);
    ASSERT_FALSE(HasFailure());

    // The torus turned 40 degrees: its silhouette and the AO it casts changed (42% of the pixels
    // measured, the ground within the AO distance included).
    EXPECT_GT(DifferingFraction(t0, tHalf, 0.05f), 0.1);
    // --play advanced the time by 1/fps per frame ...
    double time = -1.0;
    FrameHitRate(rPlay.output, 2, &time);
    EXPECT_NEAR(time, 0.5, 1e-3) << rPlay.output;
    // ... and began a cache frame at each new time: every frame is as cold as a first one (33%
    // hits measured; 84% without BeginFrame, the moved torus hitting its stale texels) ...
    for (int f = 1; f < 3; ++f) EXPECT_LT(FrameHitRate(rPlay.output, f), 50.0) << rPlay.output;
    // ... so the same time gives the same picture, whatever came before: the last frame is
    // exactly a fresh render at t = 0.5 (stale texels of t = 0 or 0.25 would show; 37% of the
    // pixels differ without BeginFrame).
    EXPECT_EQ(DifferingFraction(played, tHalf, 0.02f), 0.0);
    fs::remove_all(dir);
}

/// Per-pixel cache counts (the heat maps' input) account for exactly the frame's lookups, on
/// both render paths (AO's two-phase tiles, the path integrator's per-pixel loop).
TEST(Preview, PixelCacheCountsAddUpToTheFrameStatistics) {
    std::vector<std::string> warnings;
    texcache::Scene scene = texcache::LoadScene(kAnimated, &warnings);
    texcache::RenderSceneOptions ro;
    const texcache::RenderScene rs(scene, ro);
    for (texcache::IntegratorKind k :
         {texcache::IntegratorKind::AO, texcache::IntegratorKind::Path}) {
        texcache::RenderOptions opt;
        opt.integrator = k;
        opt.width = 48, opt.height = 32, opt.spp = 2, opt.aoSamples = 4, opt.maxDepth = 2;
        opt.progress = false;
        opt.texture.enabled = true;
        opt.texture.filter = texcache::TextureFilterKind::Normal;
        opt.texture.radius = 1;
        std::vector<texcache::PixelCacheCounts> counts;
        opt.pixelCache = &counts;
        texcache::TextureSpaceCache cache(rs, opt.texture);
        for (int frame = 0; frame < 2; ++frame) {  // cold, then warm
            const texcache::RenderResult r = texcache::Render(rs, opt, &cache);
            ASSERT_EQ(counts.size(), size_t(48 * 32));
            uint64_t lookups = 0, hits = 0, shaded = 0;
            for (const texcache::PixelCacheCounts& c : counts) {
                EXPECT_LE(c.texelHits, c.lookups);
                lookups += c.lookups, hits += c.texelHits, shaded += c.samplesShaded;
            }
            SCOPED_TRACE("integrator " + std::to_string(int(k)) + ", frame " +
                         std::to_string(frame));
            EXPECT_GT(lookups, 0u);
            EXPECT_EQ(lookups, r.stats.cache.lookups);
            EXPECT_EQ(hits, r.stats.cache.texelHits);
            EXPECT_EQ(shaded, r.stats.cache.samplesShaded);
            if (frame == 1) {
                EXPECT_EQ(hits, lookups);  // the same frame again: every texel is cached
            }
        }
    }
}

/// Mean absolute difference between horizontally adjacent pixels: how noisy a picture is.
double PixelNoise(const texcache::Image& img) {
    double sum = 0.0;
    size_t n = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 1; x < img.width; ++x)
            for (int k = 0; k < 3; ++k, ++n) sum += std::abs(img.At(x, y)[k] - img.At(x - 1, y)[k]);
    return n ? sum / double(n) : 0.0;
}

// The screen-space stage in the preview: two frames of an animation (--play), denoised by
// Reliable on the preview's own frames (texture-space indirect light), against the same frames
// undenoised (the path tracer at 1 spp). The shown image differs (most pixels), is finite, keeps
// the light (the displayed mean 0.9-1.35 times the noisy one's: measured 1.20, the display clips
// the noisy frames' bright 1-spp outliers) and is much less noisy (pixel-to-pixel variation at
// most half: measured 0.0096 against 0.129); the log gives the stage's share of each frame and its
// history.
TEST(Preview, DenoisedAnimationDiffersFromTheNoisyFrames) {
    ASSERT_EQ(Shell("command -v xvfb-run").exitCode, 0) << "xvfb-run is not installed";
    const fs::path dir = TempDir("denoise");
    const std::string anim = std::string(TEXCACHE_SOURCE_DIR) + "/scenes/anim_shadow.json";
    const std::string common = " --play --frames 2 --orbit 0 --resolution 96x54 --screenshot ";
    const ShellResult dn =
        Headless(anim, "--denoise reliable" + common + (dir / "denoised.png").string());
    ASSERT_EQ(dn.exitCode, 0) << dn.output;
    const ShellResult raw =
        Headless(anim, "--integrator path --denoise off" + common + (dir / "noisy.png").string());
    ASSERT_EQ(raw.exitCode, 0) << raw.output;
    const texcache::Image a = Screenshot(dir / "denoised.png", 96, 54);
    const texcache::Image b = Screenshot(dir / "noisy.png", 96, 54);
    double meanA = 0.0, meanB = 0.0;
    for (size_t i = 0; i < a.data.size(); ++i) {
        ASSERT_TRUE(std::isfinite(a.data[i]));
        meanA += a.data[i], meanB += b.data[i];
    }
    EXPECT_GT(meanA, 0.05 * double(a.data.size())) << "blank:\n" << dn.output;
    EXPECT_GT(meanA / meanB, 0.9);
    EXPECT_LT(meanA / meanB, 1.35);
    std::printf("denoised / noisy mean %.3f, pixel noise %.4f / %.4f\n", meanA / meanB,
                PixelNoise(a), PixelNoise(b));
    EXPECT_GT(DifferingFraction(a, b, 0.02f), 0.3);
    EXPECT_LT(PixelNoise(a), 0.5 * PixelNoise(b))
        << "denoised " << PixelNoise(a) << ", noisy " << PixelNoise(b);
    EXPECT_NE(dn.output.find("frame 1: t = 0.042 s"), std::string::npos) << dn.output;
    EXPECT_NE(dn.output.find("% of the frame), 2 frames of history"), std::string::npos)
        << dn.output;
    EXPECT_EQ(raw.output.find("of history"), std::string::npos) << raw.output;
    fs::remove_all(dir);
}

// `preview SCENE` opens on what the scene is: car.json's own integrator (path, with its
// materials), texture space on, and the Reliable stage, which keeps up at this size. The
// defaults' image is the one of those options given explicitly (the same renders: no pixel
// differs by more than 0.02), not the AO image the preview used to open on (99.7% of the pixels
// differ by more than 0.05 measured).
TEST(Preview, DefaultsOpenOnTheScenesIntegratorDenoised) {
    ASSERT_EQ(Shell("command -v xvfb-run").exitCode, 0) << "xvfb-run is not installed";
    const fs::path dir = TempDir("defaults");
    const std::string common = "--frames 2 --orbit 0 --resolution 96x54 --screenshot ";
    auto run = [&](const std::string& name, const std::string& args, ShellResult* r) {
        const fs::path png = dir / (name + ".png");
        *r = Headless(kScene, args + common + png.string());
        EXPECT_EQ(r->exitCode, 0) << r->output;
        return Screenshot(png, 96, 54);
    };
    ShellResult rd, rp, ra;
    const texcache::Image def = run("defaults", "", &rd);
    const texcache::Image path =
        run("path", "--integrator path --shading texture --denoise reliable ", &rp);
    const texcache::Image ao = run("ao", "--integrator ao --denoise off ", &ra);
    ASSERT_FALSE(HasFailure());
    EXPECT_NE(rd.output.find("integrator path, texture space on, screen-space stage reliable"),
              std::string::npos)
        << rd.output;
    EXPECT_NE(rd.output.find("frames of history"), std::string::npos) << rd.output;
    std::printf("pixels differing from the explicit options %.4f, from AO %.4f\n",
                DifferingFraction(def, path, 0.02f), DifferingFraction(def, ao, 0.05f));
    EXPECT_EQ(DifferingFraction(def, path, 0.02f), 0.0);
    EXPECT_GT(DifferingFraction(def, ao, 0.05f), 0.5);
    fs::remove_all(dir);
}

// The stage is on by default up to twice 640x360's pixels (the preview's 512x512 and 640x360
// included), off at 1280x720 and above, where it alone would take most of a 10 fps frame.
TEST(Preview, StageIsOnByDefaultWhereItKeepsUp) {
    using texcache::preview::StageKeepsUp;
    EXPECT_TRUE(StageKeepsUp(512, 512));
    EXPECT_TRUE(StageKeepsUp(640, 360));
    EXPECT_TRUE(StageKeepsUp(960, 480));
    EXPECT_FALSE(StageKeepsUp(1280, 720));
    EXPECT_FALSE(StageKeepsUp(1920, 1080));
}

// Bad --denoise values are clear errors (exit 2, the option, the value and the valid names),
// checked before any window opens.
TEST(Preview, BadDenoiseValuesAreClearErrors) {
    const ShellResult r = Shell(kBin + " preview " + kScene + " --denoise svgf --frames 1");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("--denoise"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("'svgf'"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("off, spatial, baseline, clamp, reliable"), std::string::npos)
        << r.output;
    const ShellResult d =
        Shell(kBin + " preview " + kScene + " --denoise off --demodulate --frames 1");
    EXPECT_EQ(d.exitCode, 2) << d.output;
    EXPECT_NE(d.output.find("--denoise"), std::string::npos) << d.output;
    const ShellResult m =
        Shell(kBin + " preview " + kScene + " --denoise spatial --motion sideways --frames 1");
    EXPECT_EQ(m.exitCode, 2) << m.output;
    EXPECT_NE(m.output.find("traditional, shadow, glossy, occlusion"), std::string::npos)
        << m.output;
}

// --cached-visibility belongs to the stage on texture-space frames: without --denoise, or with
// per-hit shading, it is a clear error (exit 2, naming the flag) before any window opens.
TEST(Preview, CachedVisibilityNeedsTheStageAndTextureSpace) {
    for (const std::string& args : {std::string(" --denoise off --shading texture"),
                                    std::string(" --denoise reliable --shading hit")}) {
        const ShellResult r =
            Shell(kBin + " preview " + kScene + args + " --cached-visibility --frames 1");
        EXPECT_EQ(r.exitCode, 2) << args << ": " << r.output;
        EXPECT_NE(r.output.find("--cached-visibility"), std::string::npos) << r.output;
    }
}

// The preview's stage runs one a-trous level fewer below 720 rows (progressive_renderer.h: a
// quarter of its filtering at 640x360) and the library's defaults from 720 rows; both are
// settings the denoiser accepts.
TEST(Preview, StageFiltersLessOnSmallFrames) {
    using namespace texcache::preview;
    const texcache::screen::DenoiserSettings defaults;
    EXPECT_EQ(StageSettingsFor(1080).atrousLevels, defaults.atrousLevels);
    EXPECT_EQ(StageSettingsFor(720).atrousLevels, defaults.atrousLevels);
    EXPECT_EQ(StageSettingsFor(360).atrousLevels, defaults.atrousLevels - 1);
    for (int h : {1, 360, 1080})
        EXPECT_NO_THROW(texcache::screen::ScreenSpaceDenoiser{StageSettingsFor(h)}) << h;
}

// The preview worker's stage keeps its history while the camera orbits and the animation plays,
// and drops it when the resolution, the integrator, the method or the scene (re-tessellated)
// changes. One frame per change (maxFrames 1), 32x18: stageHistory counts the frames in it.
TEST(Preview, StageHistoryFollowsTheViewAndResetsOnChanges) {
    using namespace texcache::preview;
    std::vector<std::string> warnings;
    texcache::Scene scene = texcache::LoadScene(
        std::string(TEXCACHE_SOURCE_DIR) + "/scenes/anim_shadow.json", &warnings);
    PreviewSettings s;
    s.width = 32, s.height = 18;
    s.maxFrames = 1;
    s.denoise = true;
    s.sampleCacheMb = s.texelCacheMb = 4.0f;
    s.time = scene.settings.time;
    OrbitCamera cam;
    cam.FromScene(scene, s.time);
    ProgressiveRenderer r(std::move(scene), s, cam);
    auto history = [&](const char* what) {
        SCOPED_TRACE(what);
        EXPECT_TRUE(r.WaitForFrame(r.Post(s, cam))) << r.Error();
        const FrameStats st = r.Stats();
        EXPECT_TRUE(st.staged);
        EXPECT_TRUE(std::isfinite(st.stage.total));
        return st.stageHistory;
    };
    EXPECT_EQ(history("first frame"), 1);
    cam.Orbit(3.0f, 0.0f);
    EXPECT_EQ(history("orbit"), 2);
    s.time += 1.0f / 24.0f;
    EXPECT_EQ(history("next animation frame"), 3);
    s.view = ViewMode::Motion;
    EXPECT_EQ(history("motion view"), 4);
    s.view = ViewMode::Beauty;
    s.width = 40;
    EXPECT_EQ(history("resolution"), 1);
    cam.Orbit(3.0f, 0.0f);
    EXPECT_EQ(history("orbit"), 2);
    s.integrator = texcache::IntegratorKind::Direct;
    EXPECT_EQ(history("integrator"), 1);
    cam.Orbit(3.0f, 0.0f);
    EXPECT_EQ(history("orbit"), 2);
    s.denoiseMethod = texcache::screen::Method::BaselineClamp;
    EXPECT_EQ(history("method"), 1);
    cam.Orbit(3.0f, 0.0f);
    EXPECT_EQ(history("orbit"), 2);
    s.tessellationRate = 3.0f;
    EXPECT_EQ(history("scene re-tessellated"), 1);
    // Denoise off: the progressive image again, no stage.
    s.denoise = false;
    EXPECT_TRUE(r.WaitForFrame(r.Post(s, cam)));
    EXPECT_FALSE(r.Stats().staged);
}

// A 16-gon is past Embree's limits (it is tessellated instead): the preview shows the prism (AO:
// bright) in at least 5% of the 64x64 render area (13% measured).
TEST(Preview, ShowsACagePastEmbreesLimits) {
    const fs::path dir = TempDir("prism16");
    const fs::path obj = dir / "prism16.obj", shot = dir / "shot.png";
    texcache::test::WriteObj(texcache::test::PrismCage(16), obj.string());
    const ShellResult r = Headless(obj.string(),
                                   "--integrator ao --denoise off --frames 2 --resolution 64x64 "
                                   "--screenshot " +
                                       shot.string());
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const texcache::Image img = Screenshot(shot, 64, 64);
    size_t bright = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) bright += img.At(x, y)[1] > 0.3f;
    RecordProperty("brightFraction", std::to_string(double(bright) / (64 * 64)));
    EXPECT_GT(bright, size_t(64 * 64 / 20)) << r.output;
    fs::remove_all(dir);
}

// One 16x16 frame of the preview's renderer with settings `s` (size and frame count set here)
// on a prism of `sides` sides seen from (0, 1.5, 3); *framed says whether the frame came (if not,
// Error() says why).
std::unique_ptr<texcache::preview::ProgressiveRenderer> PrismFrame(
    int sides, texcache::preview::PreviewSettings s, bool* framed) {
    using namespace texcache::preview;
    texcache::Scene scene = texcache::test::OneObjectScene(texcache::test::PrismCage(sides));
    scene.camera.pose.keys = {texcache::test::LookAt({0.0f, 1.5f, 3.0f}, {0.0f, 0.0f, 0.0f})};
    s.width = 16, s.height = 16;
    s.maxFrames = 1;
    OrbitCamera cam;
    cam.FromScene(scene, 0.0f);
    auto r = std::make_unique<ProgressiveRenderer>(std::move(scene), s, cam);
    *framed = r->WaitForFrame(r->Post(s, cam));
    return r;
}

// The panel's scene statistics (FrameStats, what the panel prints through
// RenderScene::Describe): Ptex faces and the faces past Embree's limits of the 16-gon prism.
TEST(Preview, StatsCountTheFacesPastEmbreesLimits) {
    using namespace texcache::preview;
    PreviewSettings s;
    s.integrator = texcache::IntegratorKind::AO;
    bool framed = false;
    const auto r = PrismFrame(16, s, &framed);
    ASSERT_TRUE(framed) << r->Error();
    const FrameStats st = r->Stats();
    EXPECT_EQ(st.ptexFaces, 48u);
    EXPECT_EQ(st.tessellation.beyondEmbree, 2u);
    EXPECT_EQ(st.tessellation.meshes, 1);
    EXPECT_EQ(st.tessellation.cageFaces, 18u);
    EXPECT_EQ(texcache::RenderScene::Describe(st.tessellation),
              "2 cage faces past Embree's limits (1 mesh, 18 cage faces tessellated from "
              "OpenSubdiv's limit surface)");
}

// --stereo: the image shown is both eyes side by side (twice the width), each half showing the
// scene (bright AO on the prism in at least 5% of its pixels), and the frame's statistics are
// both eyes' (two eyes' camera rays: lookups of 2 x 16 x 16 pixels).
TEST(Preview, StereoShowsBothEyesSideBySide) {
    using namespace texcache::preview;
    PreviewSettings s;
    s.stereo = true;
    s.sampleCacheMb = s.texelCacheMb = 4.0f;
    bool framed = false;
    const auto r = PrismFrame(6, s, &framed);
    ASSERT_TRUE(framed) << r->Error();
    const texcache::Image img = r->CopyImage();
    ASSERT_EQ(img.width, 32);
    ASSERT_EQ(img.height, 16);
    for (int half = 0; half < 2; ++half) {
        int bright = 0;
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 16; ++x) bright += img.At(16 * half + x, y)[1] > 0.3f;
        EXPECT_GT(bright, 16 * 16 / 20) << "half " << half;
    }
    EXPECT_EQ(r->Stats().lookups % 2, 0u);
    EXPECT_GE(r->Stats().lookups, 2u * 16 * 16 / 20);
}

TEST(Preview, WithoutADisplayFailsCleanly) {
    const ShellResult r = Shell("env -u DISPLAY -u WAYLAND_DISPLAY " + kBin + " preview " + kScene);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("no display"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("xvfb-run"), std::string::npos) << r.output;
}

}  // namespace

namespace {

/// The image shown once a still view of `s` has accumulated s.maxFrames frames (the renderer
/// then idles), on the car scene seen from its own camera.
texcache::Image StillView(texcache::preview::PreviewSettings s) {
    using namespace texcache::preview;
    std::vector<std::string> warnings;
    texcache::Scene scene = texcache::LoadScene(kScene, &warnings);
    OrbitCamera cam;
    cam.FromScene(scene, 0.0f);
    ProgressiveRenderer r(std::move(scene), s, cam);
    EXPECT_TRUE(r.WaitForFrame(r.Post(s, cam))) << r.Error();
    for (int i = 0; i < 60000 && r.Stats().accumulated < s.maxFrames && r.Error().empty(); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_EQ(r.Stats().accumulated, s.maxFrames) << r.Error();
    return r.CopyImage();
}

}  // namespace

// A still view converges in texture space too. Texture-space AO at 2 rays per cached
// sample re-shades its cache on every accumulated frame (a progressive pass), so the mean of
// the frames loses the shading noise and the texels' bias; reusing the first frame's cache
// (--no-reshade) leaves both. relMSE against per-hit AO of 64 rays over 64 frames (the same
// camera rays), 64x36, car: with re-shading 0.107 after 4 frames and 0.0077 after 64 (1/13.8);
// without, 0.143 and 0.066 (only the anti-aliasing converges). Asserted: re-shading divides the
// error by at least 8 over 16x the frames and ends below a quarter of the reused cache's.
TEST(Preview, StillViewConverges) {
    using namespace texcache::preview;
    PreviewSettings s;
    s.width = 64, s.height = 36;
    s.sampleCacheMb = s.texelCacheMb = 4.0f;
    s.integrator = texcache::IntegratorKind::AO;
    PreviewSettings ref = s;
    ref.textureSpace = false;
    ref.aoSamples = 64;
    ref.maxFrames = 64;
    const texcache::Image reference = StillView(ref);
    s.aoSamples = 2;
    auto error = [&](bool reshade, int frames) {
        PreviewSettings t = s;
        t.refineCacheWhenStill = reshade;
        t.maxFrames = frames;
        const double e = texcache::RelMSE(StillView(t), reference);
        RecordProperty(std::string(reshade ? "reshade" : "reuse") + std::to_string(frames),
                       std::to_string(e));
        std::printf("re-shade %d, %2d frames: relMSE %.5f\n", int(reshade), frames, e);
        return e;
    };
    const double reshade4 = error(true, 4), reshade64 = error(true, 64);
    const double reuse4 = error(false, 4), reuse64 = error(false, 64);
    EXPECT_TRUE(std::isfinite(reshade64));
    EXPECT_LT(reshade64, reshade4 / 8.0);
    EXPECT_LT(reshade64, 0.25 * reuse64);
    EXPECT_GT(reuse4, 0.0);
}

namespace {

/// The stage's preview frames (denoised, texture space on) at w x h, `frames` of a still view.
texcache::preview::PreviewSettings StageSettings(int frames) {
    texcache::preview::PreviewSettings s;
    s.width = 48, s.height = 27;
    s.sampleCacheMb = s.texelCacheMb = 4.0f;
    s.integrator = texcache::IntegratorKind::Path;
    s.denoise = true;
    s.maxFrames = frames;
    return s;
}

/// Posts `s` and `cam` and waits until the worker has shown s.maxFrames frames of them.
texcache::Image Converged(texcache::preview::ProgressiveRenderer& r,
                          const texcache::preview::PreviewSettings& s,
                          const texcache::preview::OrbitCamera& cam) {
    const uint64_t v = r.Post(s, cam);
    EXPECT_TRUE(r.WaitForFrame(v)) << r.Error();
    for (int i = 0; i < 60000 && r.Error().empty() &&
                    !(r.Stats().version >= v && r.Stats().accumulated >= s.maxFrames);
         ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_GE(r.Stats().accumulated, s.maxFrames) << r.Error();
    return r.CopyImage();
}

/// A fresh preview of `scene` showing `frames` of settings `s` (its time) from its own camera.
texcache::Image FreshView(texcache::Scene scene, texcache::preview::PreviewSettings s) {
    using namespace texcache::preview;
    OrbitCamera cam;
    cam.FromScene(scene, s.time);
    ProgressiveRenderer r(std::move(scene), s, cam);
    return Converged(r, s, cam);
}

/// Mean squared difference of a and b's 3x3-pixel block means: the noise of two independent
/// renders averages out, a change of shading (colour, a moved shadow) does not.
double BlockMse(const texcache::Image& a, const texcache::Image& b) {
    double sum = 0.0;
    int n = 0;
    for (int by = 0; by + 3 <= a.height; by += 3)
        for (int bx = 0; bx + 3 <= a.width; bx += 3)
            for (int k = 0; k < 3; ++k) {
                double d = 0.0;
                for (int y = by; y < by + 3; ++y)
                    for (int x = bx; x < bx + 3; ++x) d += a.At(x, y)[k] - b.At(x, y)[k];
                sum += (d / 9.0) * (d / 9.0), ++n;
            }
    return sum / std::max(n, 1);
}

int MaterialNamed(const texcache::Scene& scene, const std::string& name) {
    for (size_t m = 0; m < scene.materials.size(); ++m)
        if (scene.materials[m].name == name) return int(m);
    return -1;
}

}  // namespace

// The stage's frames take the car's slowly changing light from the cache kept from frame to
// frame (the GGX paint's diffuse base, every diffuse indirect term) and, while the view is
// still, re-shade a part of it each frame into the texels' running mean: the denoised error
// against a path-traced reference (256 spp) falls over frames (32 frames: 0.27x the first's,
// measured at 48x27).
TEST(Preview, StageStillViewErrorFallsOverFrames) {
    using namespace texcache::preview;
    std::vector<std::string> warnings;
    const texcache::Scene scene = texcache::LoadScene(kScene, &warnings);
    PreviewSettings ref = StageSettings(256);
    ref.denoise = false, ref.textureSpace = false;
    const texcache::Image reference = FreshView(scene, ref);
    auto error = [&](int frames) {
        const double e = texcache::RelMSE(FreshView(scene, StageSettings(frames)), reference);
        RecordProperty("frames" + std::to_string(frames), std::to_string(e));
        std::printf("%2d frames: denoised relMSE %.5f\n", frames, e);
        return e;
    };
    const double e1 = error(1), e32 = error(32);
    EXPECT_TRUE(std::isfinite(e32));
    EXPECT_LT(e32, e1 / 2.0);  // 0.27 of it measured
}

// A camera move keeps the cache (most lookups of the next frame hit texels the last one shaded)
// and the stage's history (it reprojects); no cache frame begins.
TEST(Preview, StageCameraMoveKeepsTheCache) {
    using namespace texcache::preview;
    // The store's hit rate is its reads served by earlier frames' hits: at most three in four
    // with one pixel in four traced each frame (fbBudget), and fewer where the store holds few
    // samples, which trace faster: after a first frame alone nearly every pixel traces again,
    // so the store's view stays still for seven frames more first (every pixel traces in a
    // still view), as a user's first look at a scene does.
    for (const auto& [fb, minHitRate] :
         {std::pair{texcache::TextureSamples::Grid, 0.6}, {texcache::TextureSamples::Hits, 0.5}}) {
        std::vector<std::string> warnings;
        texcache::Scene scene = texcache::LoadScene(kScene, &warnings);
        PreviewSettings s = StageSettings(1);
        s.fbCache = fb;
        OrbitCamera cam;
        cam.FromScene(scene, 0.0f);
        ProgressiveRenderer r(std::move(scene), s, cam);
        Converged(r, s, cam);
        const FrameStats first = r.Stats();
        EXPECT_TRUE(first.staged && first.textureSpace);
        EXPECT_LT(first.texelHitRate, 0.5);
        if (fb == texcache::TextureSamples::Hits) {
            PreviewSettings still = StageSettings(8);
            still.fbCache = fb;
            Converged(r, still, cam);
        }
        const FrameStats before = r.Stats();
        cam.Orbit(2.0f, 0.0f);
        Converged(r, s, cam);
        const FrameStats moved = r.Stats();
        std::printf("texel hit rate: first frame %.3f, after the move %.3f\n", first.texelHitRate,
                    moved.texelHitRate);
        EXPECT_GT(moved.texelHitRate, minHitRate);
        EXPECT_EQ(moved.stageHistory, before.stageHistory + 1);
        EXPECT_EQ(moved.cacheFrame, first.cacheFrame);
    }
}

// Scene edits never show stale shading: after a material edit in the panel (the car's paint
// turned green) and after an animation moved an object (turntable's torus at t = 1), the
// picture is that of a fresh preview of the edited scene, within noise: its squared difference
// from the fresh one (3x3 block means) is under a quarter of the unedited picture's (0.12
// measured) for the edit, and within the noise of two fresh previews for the move.
TEST(Preview, StageEditsShowNoStaleShading) {
    using namespace texcache::preview;
    std::vector<std::string> warnings;
    {
        SCOPED_TRACE("material edit");
        texcache::Scene scene = texcache::LoadScene(kScene, &warnings);
        const int paint = MaterialNamed(scene, "paint");
        ASSERT_GE(paint, 0);
        const PreviewSettings s = StageSettings(8);
        OrbitCamera cam;
        cam.FromScene(scene, 0.0f);
        texcache::Scene green = scene;
        green.materials[size_t(paint)].albedo.value = glm::vec3(0.05f, 0.5f, 0.08f);
        ProgressiveRenderer r(std::move(scene), s, cam);
        const texcache::Image before = Converged(r, s, cam);
        PreviewSettings edited = s;
        for (const texcache::Material& m : green.materials)
            edited.materialAlbedo.push_back(m.albedo.value);
        const texcache::Image after = Converged(r, edited, cam);
        const texcache::Image fresh = FreshView(green, s);
        const double stale = BlockMse(before, fresh), now = BlockMse(after, fresh);
        std::printf("material edit: MSE to a fresh render %.6f (unedited %.6f)\n", now, stale);
        EXPECT_LT(now, 0.25 * stale);
    }
    {
        SCOPED_TRACE("object moved");
        texcache::Scene scene = texcache::LoadScene(kAnimated, &warnings);
        PreviewSettings s = StageSettings(8);
        s.time = 0.0f;
        OrbitCamera cam;
        cam.FromScene(scene, 0.0f);
        const texcache::Scene copy = scene;
        ProgressiveRenderer r(std::move(scene), s, cam);
        const texcache::Image before = Converged(r, s, cam);
        s.time = 1.0f;
        const texcache::Image after = Converged(r, s, cam);
        const texcache::Image fresh = FreshView(copy, s);
        PreviewSettings other = s;
        other.seed = 1;
        const double noise = BlockMse(FreshView(copy, other), fresh);
        const double stale = BlockMse(before, fresh), now = BlockMse(after, fresh);
        std::printf("object moved: MSE to a fresh render %.6f (before %.6f, two fresh ones %.6f)\n",
                    now, stale, noise);
        // Within the noise of two fresh previews (0.87 of it measured), where the picture before
        // the move is 2.4 times as far.
        EXPECT_LT(now, 1.5 * noise);
        EXPECT_LT(now, 0.5 * stale);
    }
}

// The preview traces every mesh as quads on its limit surface where they fit (limitQuads), the
// surface Embree's subdivision geometry renders: the car's stage frames (4 frames, 48x27) with
// either differ by under a hundredth of what two seeds on one geometry differ by (3x3 block
// means; 1e-4 of it measured: the quads' hits are Embree's within 6e-5 of the car's diagonal,
// and only the odd ray lands on another face). The panel's statistics say which geometry a
// frame traced.
TEST(Preview, LimitQuadsShowWhatEmbreesSubdivisionShows) {
    using namespace texcache::preview;
    std::vector<std::string> warnings;
    const texcache::Scene scene = texcache::LoadScene(kScene, &warnings);
    const int meshes = int(scene.objects.size());  // the car's and the ground's, one each
    auto view = [&](bool quads, uint64_t seed, FrameStats* st) {
        PreviewSettings s = StageSettings(4);
        s.limitQuads = quads;
        s.seed = seed;
        OrbitCamera cam;
        cam.FromScene(scene, 0.0f);
        ProgressiveRenderer r(texcache::Scene(scene), s, cam);
        const texcache::Image img = Converged(r, s, cam);
        *st = r.Stats();
        return img;
    };
    FrameStats quadStats, subdivStats, other;
    EXPECT_TRUE(PreviewSettings{}.limitQuads);
    const texcache::Image quads = view(true, 0, &quadStats);
    const texcache::Image subdiv = view(false, 0, &subdivStats);
    const texcache::Image reseeded = view(false, 1, &other);
    EXPECT_EQ(quadStats.tessellation.meshes, meshes);
    EXPECT_EQ(quadStats.tessellation.beyondEmbree, 0u);
    EXPECT_EQ(subdivStats.tessellation.meshes, 0);
    double mean = 0.0;
    for (const float v : quads.data) mean += double(v);
    mean /= double(quads.data.size());
    const double geometry = BlockMse(quads, subdiv), noise = BlockMse(reseeded, subdiv);
    std::printf(
        "quads against subdivision: block MSE %.3g; two seeds on subdivision %.3g; "
        "mean %.4f\n",
        geometry, noise, mean);
    RecordProperty("geometryMse", std::to_string(geometry));
    RecordProperty("seedMse", std::to_string(noise));
    EXPECT_GT(mean, 0.05);
    EXPECT_TRUE(std::isfinite(geometry));
    EXPECT_LT(geometry, 0.01 * noise);
}

// `texcache preview` (--geometry auto) traces limit quads unless they would be over a million
// (about rate^2 a subdivided cage face): the car's 1576 faces at rate 2 fit, a 300,000-face cage
// at rate 2 (1.2 million quads) does not, nor does the car at rate 32; a plain (unsubdivided)
// mesh's faces do not count.
TEST(Preview, LimitQuadsOnlyWhereTheyFit) {
    using texcache::preview::LimitQuadsFit;
    std::vector<std::string> warnings;
    texcache::Scene car = texcache::LoadScene(kScene, &warnings);
    EXPECT_TRUE(LimitQuadsFit(car));
    car.settings.tessellationRate = 32.0f;
    EXPECT_FALSE(LimitQuadsFit(car));
    texcache::Scene big = texcache::test::OneObjectScene(texcache::test::PrismCage(4));
    big.meshes[0].faceVertexCounts.assign(300000, 4);
    big.settings.tessellationRate = 2.0f;
    EXPECT_FALSE(LimitQuadsFit(big));
    big.objects[0].subdivide = false;
    EXPECT_TRUE(LimitQuadsFit(big));
}
