// SPDX-License-Identifier: Apache-2.0
// The screen-space stage as a whole, on synthetic frames (testing/screen_space_scene.h): every
// method stays finite, NaN and Inf in any input stay contained, bad input throws naming the
// buffer, and BRDF demodulation keeps a roughness texture. Every tolerance is stated where it is
// checked.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "screen_space/brdf_table.h"
#include "screen_space/screen_denoiser.h"
#include "screen_space_util.h"
#include "testing/screen_space_scene.h"
#include "texcache/error.h"

namespace texcache::screen {
namespace {

using test::FullScene;
using test::GeometryMask;
using test::Ground;
using test::kAllMethods;
using test::RelMse;
using test::SharedBrdf;
using test::SynthObject;
using test::SynthRender;
using test::SynthScene;

TEST(ScreenSpaceSmoke, EveryMethodStaysFinite) {
    const SynthScene sc = FullScene(96, 64);
    for (Method m : kAllMethods)
        for (Demodulation d : {Demodulation::Off, Demodulation::On}) {
            ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
            for (int fr = 0; fr < 3; ++fr) {
                const auto img = dn.Denoise(SynthRender(sc, fr, 5), m, d);
                ASSERT_EQ(img.size(), size_t(sc.width * sc.height));
                for (const glm::vec3& c : img)
                    ASSERT_TRUE(std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z))
                        << MethodName(m);
            }
        }
}

// For every input buffer: a 3x3 block of NaN (then +Inf) at (20, 20) in the second of three
// frames. Every output stays finite, and pixels more than 60 px away are as in a clean run
// (within 1e-3 relative: the a-trous reaches 15 px, the shadow filter 15, the clean-up 4, the
// shadow splat 8, all twice that at half resolution, where the upsample adds 2; only per-object
// motion fits see the whole image, and they skip non-finite samples).
void ExpectNonFiniteInputsContained(const DenoiserSettings& settings) {
    SynthScene sc = FullScene(160, 96);
    const FrameBuffers clean[3] = {SynthRender(sc, 0, 2), SynthRender(sc, 1, 2),
                                   SynthRender(sc, 2, 2)};
    const int w = sc.width, h = sc.height;
    auto far = [&](size_t i) {
        const int x = int(i % size_t(w)), y = int(i / size_t(w));
        return (x - 20) * (x - 20) + (y - 20) * (y - 20) > 60 * 60;
    };
    using Vec3Buf = std::vector<glm::vec3> FrameBuffers::*;
    using FloatBuf = std::vector<float> FrameBuffers::*;
    const std::pair<const char*, Vec3Buf> vec3Bufs[] = {
        {"emitted", &FrameBuffers::emitted},
        {"shading", &FrameBuffers::shading},
        {"glossy", &FrameBuffers::glossy},
        {"indirect", &FrameBuffers::indirect},
        {"position", &FrameBuffers::position},
        {"normal", &FrameBuffers::normal},
        {"albedo", &FrameBuffers::albedo},
        {"specular", &FrameBuffers::specular},
        {"prevPosition", &FrameBuffers::prevPosition},
        {"prevNormal", &FrameBuffers::prevNormal},
        {"blocker", &FrameBuffers::blocker},
        {"prevBlocker", &FrameBuffers::prevBlocker},
        {"lightSample", &FrameBuffers::lightSample},
        {"prevLightSample", &FrameBuffers::prevLightSample},
        {"glossyHit", &FrameBuffers::glossyHit},
        {"prevGlossyHit", &FrameBuffers::prevGlossyHit},
        {"cones", &FrameBuffers::cones}};
    const std::pair<const char*, FloatBuf> floatBufs[] = {{"visibility", &FrameBuffers::visibility},
                                                          {"depth", &FrameBuffers::depth},
                                                          {"roughness", &FrameBuffers::roughness}};
    const float bad[2] = {std::numeric_limits<float>::quiet_NaN(),
                          std::numeric_limits<float>::infinity()};
    for (Method m : {Method::Baseline, Method::Reliable}) {
        std::vector<glm::vec3> ref;
        {
            ScreenSpaceDenoiser dn(settings, SharedBrdf());
            for (const FrameBuffers& f : clean) ref = dn.Denoise(f, m, Demodulation::On);
        }
        auto run = [&](const std::string& name, auto&& poison) {
            for (float b : bad) {
                ScreenSpaceDenoiser dn(settings, SharedBrdf());
                std::vector<glm::vec3> out;
                for (int fr = 0; fr < 3; ++fr) {
                    FrameBuffers f = clean[fr];
                    if (fr == 1) poison(f, b);
                    out = dn.Denoise(f, m, Demodulation::On);
                    for (const glm::vec3& c : out)
                        ASSERT_TRUE(std::isfinite(c.x + c.y + c.z))
                            << name << " = " << b << " leaked (" << MethodName(m) << ")";
                }
                float worst = 0.0f;
                for (size_t i = 0; i < out.size(); ++i)
                    if (far(i))
                        worst = std::max(
                            worst, glm::length(out[i] - ref[i]) / (glm::length(ref[i]) + 1e-3f));
                EXPECT_LT(worst, 1e-3f)
                    << name << " = " << b << " spread (" << MethodName(m) << ")";
            }
        };
        auto block = [&](auto&& set) {
            for (int y = 19; y <= 21; ++y)
                for (int x = 19; x <= 21; ++x) set(size_t(y) * size_t(w) + size_t(x));
        };
        for (const auto& [name, buf] : vec3Bufs)
            run(name,
                [&, buf = buf, cones = std::string(name) == "cones"](FrameBuffers& f, float b) {
                    block([&](size_t i) {
                        if (cones)
                            for (int k = 0; k < kNumCones; ++k)
                                (f.*buf)[i * kNumCones + k] = glm::vec3(b);
                        else
                            (f.*buf)[i] = glm::vec3(b, 0.5f, b);
                    });
                });
        for (const auto& [name, buf] : floatBufs)
            run(name, [&, buf = buf](FrameBuffers& f, float b) {
                block([&](size_t i) { (f.*buf)[i] = b; });
            });
    }
    (void)h;
}

TEST(ScreenSpaceRobustness, NonFiniteInputsStayContained) {
    ExpectNonFiniteInputsContained(DenoiserSettings{});
}

TEST(ScreenSpaceRobustness, NonFiniteInputsStayContainedAtHalfResolution) {
    DenoiserSettings s;
    s.halfResolutionRows = 1;
    ExpectNonFiniteInputsContained(s);
}

// The stage on half the pixels against the full-resolution stage, both against a 64-spp render
// of the last of 6 moving frames (192x128, Reliable, demodulated): the half-resolution error is
// within 15% of the full-resolution one (at 1920x1080 they are within a few percent,
// results/screen_space_benchmark.md; at this size a 2x2 block is a larger share of every
// object), and both are below a tenth of the 1-spp input's.
TEST(ScreenSpaceHalfResolution, ErrorStaysNearTheFullResolutionStage) {
    const SynthScene sc = FullScene(192, 128);
    constexpr int kFrames = 6;
    const std::vector<glm::vec3> ref = SynthRender(sc, kFrames - 1, 99, 64).Compose();
    double rel[2] = {0.0, 0.0};
    std::vector<glm::vec2> motion[2];
    for (int half = 0; half < 2; ++half) {
        DenoiserSettings s;
        s.halfResolutionRows = half ? sc.height : 0;
        ScreenSpaceDenoiser dn(s, SharedBrdf());
        std::vector<glm::vec3> img;
        for (int fr = 0; fr < kFrames; ++fr)
            dn.Denoise(SynthRender(sc, fr, 3), Method::Reliable, Demodulation::On, &img);
        for (const glm::vec3& c : img) ASSERT_TRUE(std::isfinite(c.x + c.y + c.z));
        rel[half] = RelMse(img, ref);
        motion[half] = dn.LastMotion(MotionKind::Traditional);
    }
    // The block's traditional vectors stand for its pixels: where both stages have one, within
    // 1 px of the full-resolution vector on 95% of the pixels (the camera pans ~1 px a frame;
    // a block's representative is up to a pixel away from the others), and at least 90% of the
    // pixels with one at full resolution have one at half.
    int both = 0, close = 0, fullOnly = 0;
    for (size_t i = 0; i < motion[0].size(); ++i) {
        if (!std::isfinite(motion[0][i].x)) continue;
        if (!std::isfinite(motion[1][i].x)) {
            ++fullOnly;
            continue;
        }
        ++both;
        close += glm::length(motion[1][i] - motion[0][i]) <= 1.0f;
    }
    EXPECT_GE(close, 0.95 * both);
    EXPECT_LE(fullOnly, 0.1 * (both + fullOnly));
    const double input = RelMse(SynthRender(sc, kFrames - 1, 3).Compose(), ref);
    EXPECT_LT(rel[0], 0.1 * input);
    EXPECT_LT(rel[1], 0.1 * input);
    EXPECT_LT(rel[1], 1.15 * rel[0]) << "full " << rel[0] << ", half " << rel[1];
}

// Demodulation where a channel of the albedo is 0: a checker of 8x8-pixel cells, grey (0.8) and
// pure red (0.8, 0, 0), lit by indirect light 1 + noise. The red cells' green and blue indirect
// light is 0 and must stay about 0 where the filter mixes in the grey cells' light: their
// channel's remodulation factor is the albedo floored at 1e-3, so what the filter carries in
// comes back times 1e-3 at most (bound 2e-3: light up to 1.5 after filtering). A factor of 1
// (the channel left undivided) lit the red cells' edges green and blue with the grey cells'
// light (about 0.5). The grey cells keep their light within 10% on average.
TEST(ScreenSpaceDemodulation, AChannelWithoutAlbedoStaysDark) {
    const SynthScene sc = FullScene(96, 64);
    FrameBuffers f = SynthRender(sc, 0, 5);
    f.glossy.clear();
    uint32_t rng = 12345u;
    auto noise = [&] {
        rng = rng * 1664525u + 1013904223u;
        return float(rng >> 8) * (1.0f / 16777216.0f);
    };
    auto red = [&](size_t i) {
        const int x = int(i % size_t(f.width)), y = int(i / size_t(f.width));
        return ((x / 8) + (y / 8)) % 2 == 1;
    };
    for (size_t i = 0; i < f.NumPixels(); ++i) {
        if (f.objectId[i] < 0) continue;
        f.albedo[i] = red(i) ? glm::vec3(0.8f, 0.0f, 0.0f) : glm::vec3(0.8f);
        f.indirect[i] = f.albedo[i] * (0.5f + noise());
    }
    ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
    dn.Denoise(f, Method::SpatialOnly, Demodulation::On);
    const std::vector<glm::vec3> ind = dn.Indirect();
    ASSERT_EQ(ind.size(), f.NumPixels());
    float worst = 0.0f;
    double grey = 0.0;
    int reds = 0, greys = 0;
    for (size_t i = 0; i < f.NumPixels(); ++i) {
        if (f.objectId[i] < 0) continue;
        ASSERT_TRUE(std::isfinite(ind[i].x + ind[i].y + ind[i].z)) << i;
        if (red(i)) {
            worst = std::max({worst, ind[i].y, ind[i].z}), ++reds;
        } else {
            grey += ind[i].y, ++greys;
        }
    }
    std::printf("red cells' largest green or blue indirect %.3g; grey cells' mean green %.3f\n",
                worst, grey / std::max(greys, 1));
    ASSERT_GT(reds, 1000);
    EXPECT_LE(worst, 2e-3f);
    EXPECT_NEAR(grey / greys, 0.8, 0.08);
}

// Edges: diffuse indirect light 1 (demodulated) on the box and 0 everywhere else, so that what a
// pixel's indirect differs from its own object's value is what the filters carried across an
// objectId boundary. SVGF's a-trous stops at depth and normal, not at objects, so the
// full-resolution stage itself carries some along the box's contact with the floor (mean 5e-5,
// largest 0.008-0.011 over the pixels within 2 px of a boundary); the upsample never mixes
// objects, but the half-resolution a-trous's steps span twice the pixels and its depth
// tolerance twice the depth (mean 4e-4, largest 0.016-0.017). Checked: the mean within 1e-3
// (a tenth of a percent of the box's value), the largest within 3x the full-resolution
// stage's. Two frames: no history, then reprojected.
TEST(ScreenSpaceHalfResolution, KeepsObjectBoundaries) {
    const SynthScene sc = FullScene(130, 90);  // odd half-resolution sizes on purpose
    const int w = sc.width, h = sc.height;
    DenoiserSettings halfSettings;
    halfSettings.halfResolutionRows = 1;
    ScreenSpaceDenoiser full(DenoiserSettings{}, SharedBrdf()), half(halfSettings, SharedBrdf());
    ScreenSpaceDenoiser* dn[2] = {&full, &half};
    for (int fr = 0; fr < 2; ++fr) {
        FrameBuffers f = SynthRender(sc, fr, 5);
        f.glossy.clear();
        for (size_t i = 0; i < f.NumPixels(); ++i)
            f.indirect[i] = f.objectId[i] == 1 ? f.albedo[i] : glm::vec3(0.0f);
        auto nearBoundary = [&](int x, int y) {
            const int id = f.objectId[size_t(y) * size_t(w) + size_t(x)];
            for (int dy = -2; dy <= 2; ++dy)
                for (int dx = -2; dx <= 2; ++dx) {
                    const int u = std::clamp(x + dx, 0, w - 1), v = std::clamp(y + dy, 0, h - 1);
                    if (f.objectId[size_t(v) * size_t(w) + size_t(u)] != id) return true;
                }
            return false;
        };
        double mean[2] = {0.0, 0.0}, worst[2] = {0.0, 0.0};
        int band = 0;
        for (int k = 0; k < 2; ++k) {
            dn[k]->Denoise(f, Method::Reliable, Demodulation::On);
            const std::vector<glm::vec3> ind = dn[k]->Indirect();
            ASSERT_EQ(ind.size(), f.NumPixels());
            band = 0;
            for (int y = 0; y < h; ++y)
                for (int x = 0; x < w; ++x) {
                    const size_t i = size_t(y) * size_t(w) + size_t(x);
                    if (f.objectId[i] < 0 || !nearBoundary(x, y)) continue;
                    const glm::vec3 want = f.objectId[i] == 1 ? f.albedo[i] : glm::vec3(0.0f);
                    const double e = glm::length(ind[i] - want);
                    mean[k] += e, worst[k] = std::max(worst[k], e), ++band;
                }
            mean[k] /= std::max(1, band);
        }
        ASSERT_GT(band, 200);
        EXPECT_LE(mean[1], 1e-3) << "frame " << fr;
        EXPECT_LE(worst[1], 3.0 * worst[0]) << "frame " << fr;
    }
}

// The half-resolution stage on a width x height frame. Odd sizes: the reduction's last column
// and row of blocks have one or two samples, and the upsample writes its last output pair one
// past the row. At half resolution the image is composed in the same pass as the upsample and
// the accessors read what that pass keeps, so they must add up to the image: emitted + shading
// * Visibility() + Glossy() + Indirect(), within float rounding (1e-5 of the value; the pass
// and the sum differ only in the order of one multiply-add). Two frames: no history, then
// reprojected.
void ExpectAccessorsAddUpToTheImage(int width, int height) {
    SCOPED_TRACE(std::to_string(width) + "x" + std::to_string(height));
    const SynthScene sc = FullScene(width, height);
    DenoiserSettings s;
    s.halfResolutionRows = 1;
    ScreenSpaceDenoiser dn(s, SharedBrdf());
    for (int fr = 0; fr < 2; ++fr) {
        const FrameBuffers f = SynthRender(sc, fr, 3);
        std::vector<glm::vec3> img;
        dn.Denoise(f, Method::Reliable, Demodulation::On, &img);
        const std::vector<float> vis = dn.Visibility();
        const std::vector<glm::vec3> gl = dn.Glossy(), ind = dn.Indirect();
        ASSERT_EQ(img.size(), f.NumPixels());
        ASSERT_EQ(vis.size(), f.NumPixels());
        ASSERT_EQ(gl.size(), f.NumPixels());
        ASSERT_EQ(ind.size(), f.NumPixels());
        int checked = 0;
        for (size_t i = 0; i < f.NumPixels(); ++i) {
            ASSERT_TRUE(std::isfinite(img[i].x + img[i].y + img[i].z)) << "pixel " << i;
            const glm::vec3 e = f.emitted.empty() ? glm::vec3(0.0f) : f.emitted[i];
            if (!std::isfinite(e.x + e.y + e.z) ||
                !std::isfinite(f.shading[i].x + f.shading[i].y + f.shading[i].z))
                continue;
            const glm::vec3 want = e + f.shading[i] * vis[i] + gl[i] + ind[i];
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(img[i][c], want[c], 1e-5 * (1.0 + std::fabs(want[c])))
                    << "frame " << fr << ", pixel " << i << ", channel " << c;
            ++checked;
        }
        EXPECT_GT(checked, int(f.NumPixels() / 2));
    }
}

TEST(ScreenSpaceHalfResolution, AccessorsAddUpToTheImageAtOddSizes) {
    ExpectAccessorsAddUpToTheImage(131, 91);
}

// The reduction takes blocks in chunks of 64, 8 at a time: widths whose half rows end with a
// full chunk plus one block, a chunk plus 7 blocks, and two chunks plus 3 blocks with a last
// block of one column, on a few rows. The image stays finite and consistent with the
// accessors where a chunk's last lanes are partly past the row (those lanes are computed but
// not stored).
TEST(ScreenSpaceHalfResolution, AccessorsAddUpToTheImageAtChunkTails) {
    for (const int w : {2 * 65, 2 * 71, 2 * 131 - 1}) ExpectAccessorsAddUpToTheImage(w, 11);
}

TEST(ScreenSpaceRobustness, BadInputThrowsNamingTheBuffer) {
    const FrameBuffers good = SynthRender(FullScene(32, 24), 0, 1);
    auto expectError = [&](const FrameBuffers& f, Method m, Demodulation d,
                           const std::string& word) {
        ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
        try {
            dn.Denoise(f, m, d);
            ADD_FAILURE() << "no InputError for " << word;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
        }
    };
    // A wrong size in any buffer names it.
    using Vec3Buf = std::vector<glm::vec3> FrameBuffers::*;
    const std::pair<const char*, Vec3Buf> vec3Bufs[] = {
        {"'emitted'", &FrameBuffers::emitted},
        {"'shading'", &FrameBuffers::shading},
        {"'glossy'", &FrameBuffers::glossy},
        {"'indirect'", &FrameBuffers::indirect},
        {"'position'", &FrameBuffers::position},
        {"'normal'", &FrameBuffers::normal},
        {"'prevPosition'", &FrameBuffers::prevPosition},
        {"'prevBlocker'", &FrameBuffers::prevBlocker},
        {"'cones'", &FrameBuffers::cones}};
    for (const auto& [name, buf] : vec3Bufs) {
        FrameBuffers f = good;
        (f.*buf).pop_back();
        expectError(f, Method::Reliable, Demodulation::On, name);
    }
    {
        FrameBuffers f = good;
        f.visibility.push_back(1.0f);
        expectError(f, Method::Baseline, Demodulation::On, "'visibility'");
        f = good;
        f.objectId.resize(3);
        expectError(f, Method::SpatialOnly, Demodulation::On, "'objectId'");
    }
    // Missing required buffers, and buffers a method or the demodulation needs.
    {
        FrameBuffers f = good;
        f.depth.clear();
        expectError(f, Method::SpatialOnly, Demodulation::Off, "'depth'");
        f = good;
        f.prevPosition.clear();
        expectError(f, Method::Baseline, Demodulation::Off, "'prevPosition'");
        f = good;
        f.prevLightSample.clear();
        expectError(f, Method::Reliable, Demodulation::Off, "'prevLightSample'");
        f = good;
        f.prevGlossyHit.clear();
        expectError(f, Method::Reliable, Demodulation::Off, "'prevGlossyHit'");
        f = good;
        f.specular.clear();
        expectError(f, Method::SpatialOnly, Demodulation::On, "'specular'");
        f = good;
        f.albedo.clear();
        expectError(f, Method::Baseline, Demodulation::On, "'albedo'");
        f = good;
        f.width = 0;
        expectError(f, Method::SpatialOnly, Demodulation::Off, "size");
        f = good;
        f.camera.width = 7;
        expectError(f, Method::SpatialOnly, Demodulation::Off, "camera");
    }
    // Impossible settings.
    auto badSettings = [](auto&& change, const char* word) {
        DenoiserSettings s;
        change(s);
        try {
            ScreenSpaceDenoiser dn(s);
            ADD_FAILURE() << "no InputError for " << word;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
        }
    };
    badSettings([](DenoiserSettings& s) { s.alpha = 0.0f; }, "alpha");
    badSettings([](DenoiserSettings& s) { s.alpha = std::nanf(""); }, "alpha");
    badSettings([](DenoiserSettings& s) { s.atrousLevels = 9; }, "atrousLevels");
    badSettings([](DenoiserSettings& s) { s.halfResolutionRows = -1; }, "halfResolutionRows");
    badSettings([](DenoiserSettings& s) { s.brdfSamples = 0; }, "brdfSamples");
    badSettings([](DenoiserSettings& s) { s.shadowFalloff = true; }, "reliableVisibilityOrder");
}

// cachedVisibility: optional, but when given it must have the frame's size and hold
// visibilities (finite, >= 0) or NaN for "none"; the error names the buffer and the pixel.
TEST(ScreenSpaceRobustness, BadCachedVisibilityThrowsNamingIt) {
    const FrameBuffers good = SynthRender(FullScene(32, 24), 0, 1);
    auto message = [&](const FrameBuffers& f) -> std::string {
        ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
        try {
            dn.Denoise(f, Method::Reliable, Demodulation::On);
        } catch (const InputError& e) {
            return e.what();
        }
        return "";
    };
    FrameBuffers f = good;
    f.cachedVisibility.assign(good.NumPixels() - 1, 0.5f);
    EXPECT_NE(message(f).find("'cachedVisibility' has 767 entries"), std::string::npos)
        << message(f);
    for (float bad : {-0.1f, std::numeric_limits<float>::infinity()}) {
        f.cachedVisibility.assign(good.NumPixels(), 0.5f);
        f.cachedVisibility[5 * 32 + 7] = bad;
        const std::string e = message(f);
        EXPECT_NE(e.find("'cachedVisibility'"), std::string::npos) << e;
        EXPECT_NE(e.find("(7, 5)"), std::string::npos) << e;
    }
    // NaN is "none here": accepted, and the output stays finite.
    f.cachedVisibility.assign(good.NumPixels(), std::numeric_limits<float>::quiet_NaN());
    EXPECT_EQ(message(f), "");
    ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
    for (const glm::vec3& c : dn.Denoise(f, Method::Baseline, Demodulation::On))
        ASSERT_TRUE(std::isfinite(c.x + c.y + c.z));
}

// ---- Demodulation --------------------------------------------------------------------------

TEST(ScreenSpaceDemodulation, BrdfDemodulationKeepsARoughnessTexture) {
    // A metal plane (F0 = (0.9, 0.6, 0.3)) whose GGX alpha alternates 0.05 / 0.6 in 0.25-unit
    // squares (~4-8 px) under a sky gradient: the glossy component is the texture times a
    // smooth lighting. Filtering F_beta out and back in must lower the RMSE of the glossy
    // component against its 256-spp reference by at least 1.3x, for the spatial filter on one
    // frame and for SVGF after 8 static frames.
    SynthScene sc;
    sc.width = 96, sc.height = 64;
    sc.eye = glm::vec3(0.0f, 1.2f, 4.0f), sc.target = glm::vec3(0.0f, 0.0f, -1.0f);
    sc.lightIntensity = glm::vec3(0.0f);
    sc.skyHorizon = glm::vec3(2.0f, 1.8f, 1.5f), sc.skyZenith = glm::vec3(0.3f, 0.5f, 1.2f);
    SynthObject plane = Ground(0);
    plane.f0 = glm::vec3(0.9f, 0.6f, 0.3f);
    plane.roughness = 0.05f, plane.roughness2 = 0.6f, plane.checkerPeriod = 0.25f;
    sc.objects.push_back(plane);
    sc.indirect = false;
    const FrameBuffers refF = SynthRender(sc, 0, 77, 256);
    const auto mask = GeometryMask(refF);
    for (Method m : {Method::SpatialOnly, Method::Baseline}) {
        double err[2];
        for (int d = 0; d < 2; ++d) {
            ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
            const int frames = m == Method::SpatialOnly ? 1 : 8;
            for (int fr = 0; fr < frames; ++fr)
                dn.Denoise(SynthRender(sc, fr, 5), m, d ? Demodulation::On : Demodulation::Off);
            err[d] = test::Rmse(dn.Glossy(), refF.glossy, &mask);
        }
        std::printf("%-15s glossy RMSE without demodulation %.4f, with %.4f (%.2fx)\n",
                    MethodName(m), err[0], err[1], err[0] / err[1]);
        EXPECT_LT(err[1] * 1.3, err[0]) << MethodName(m);
    }
}

}  // namespace
}  // namespace texcache::screen
