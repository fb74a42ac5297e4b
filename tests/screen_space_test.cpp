// SPDX-License-Identifier: Apache-2.0
// The screen-space stage on synthetic frames (testing/screen_space_scene.h): reprojection,
// temporal convergence, disocclusion, moving shadows, NaN/Inf containment, input errors, the cone
// and BRDF tables, demodulation. Every tolerance is stated where it is checked.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "screen_space/brdf_table.h"
#include "screen_space/cone_overlap.h"
#include "screen_space/planes.h"
#include "screen_space/screen_denoiser.h"
#include "testing/screen_space_scene.h"
#include "texcache/error.h"

namespace texcache::screen {
namespace {

using test::SynthObject;
using test::SynthRender;
using test::SynthScene;

constexpr Method kAllMethods[] = {Method::SpatialOnly, Method::Baseline, Method::BaselineClamp,
                                  Method::Reliable};
constexpr Method kTemporal[] = {Method::Baseline, Method::BaselineClamp, Method::Reliable};

std::shared_ptr<const BrdfPreintegration> SharedBrdf() {
    static auto table = std::make_shared<const BrdfPreintegration>();
    return table;
}

SynthObject Ground(int id = 0, glm::vec3 albedo = glm::vec3(0.6f)) {
    SynthObject o;
    o.kind = SynthObject::Kind::Plane;
    o.id = id;
    o.a = glm::vec3(0.0f), o.b = glm::vec3(0.0f, 1.0f, 0.0f);
    o.albedo = albedo;
    return o;
}
SynthObject Box(int id, glm::vec3 lo, glm::vec3 hi, glm::vec3 velocity = glm::vec3(0.0f)) {
    SynthObject o;
    o.kind = SynthObject::Kind::Box;
    o.id = id, o.a = lo, o.b = hi, o.velocity = velocity;
    o.albedo = glm::vec3(0.8f, 0.3f, 0.2f);
    return o;
}

// ---- Tables --------------------------------------------------------------------------------

TEST(ScreenSpaceTables, ConeShadeWeightsAreCosineShares) {
    // (1/pi) int_cell cos dw by midpoint quadrature on a 1000 x 2000 (cos theta, phi) grid;
    // the grid's error is < 1e-4 (cell boundaries cut ~1/1000 of the cells).
    const auto axes = ConeAxes(glm::vec3(0.0f, 0.0f, 1.0f));
    double wsum[kNumCones] = {};
    const int nc = 1000, np = 2000;
    for (int i = 0; i < nc; ++i) {
        const double c = (i + 0.5) / nc, s = std::sqrt(1.0 - c * c);
        for (int j = 0; j < np; ++j) {
            const double ph = (j + 0.5) / np * 2.0 * M_PI;
            const glm::vec3 w(float(s * std::cos(ph)), float(s * std::sin(ph)), float(c));
            wsum[ConeOf(axes, w)] += c * (1.0 / nc) * (2.0 * M_PI / np) / M_PI;
        }
    }
    double total = 0.0;
    for (int k = 0; k < kNumCones; ++k) {
        EXPECT_NEAR(wsum[k], kConeShadeWeight[k], 1e-4) << "cone " << k;
        total += kConeShadeWeight[k];
    }
    EXPECT_NEAR(total, 1.0, 1e-6);
}

TEST(ScreenSpaceTables, MazonkaOverlapMatchesMonteCarlo) {
    // Fraction of 2M uniform sphere directions inside both cones, times 4 pi: the binomial std of
    // the estimate is < 1.5% of the overlaps checked here, the tolerance is 5%.
    std::mt19937 rng(7);
    std::normal_distribution<float> nd;
    const float ct = kConeCosHalfAngle;
    const int n = 2000000;
    for (float deg : {20.0f, 45.0f, 60.0f}) {
        const float a = glm::radians(deg);
        const glm::vec3 b(std::sin(a), 0.0f, std::cos(a));
        int in = 0;
        for (int k = 0; k < n; ++k) {
            glm::vec3 v(nd(rng), nd(rng), nd(rng));
            v = glm::normalize(v);
            in += v.z > ct && glm::dot(v, b) > ct;
        }
        const double mc = double(in) / n * 4.0 * M_PI;
        EXPECT_NEAR(ConeOverlap(a), mc, 0.05 * mc) << deg << " degrees";
    }
    EXPECT_NEAR(ConeOverlap(0.0), M_PI / 3.0, 1e-6);  // one cone: pi / 3 (float 5/6: 1e-7)
    EXPECT_EQ(ConeOverlap(2.0 * std::acos(ct) + 1e-6), 0.0);
    // The 1D table against the formula: within 1e-4 sr (1024 entries in sin(angle / 2), linear
    // interpolation of a smooth function).
    ConeOverlapTable t;
    for (float deg = 0.0f; deg < 90.0f; deg += 0.7f) {
        const float a = glm::radians(deg);
        EXPECT_NEAR(t.Overlap(std::cos(a)), ConeOverlap(a), 1e-4) << deg;
    }
    // The layout's 6x6 table: diagonal pi/3, cone 0 against the ring cones (60 degrees apart)
    // and ring neighbours (61.2 degrees) overlap a little, ring cones 144 degrees apart not.
    EXPECT_NEAR(t.SameFrame(0, 0), M_PI / 3.0, 1e-5);
    EXPECT_NEAR(t.SameFrame(0, 3), ConeOverlap(glm::radians(60.0)), 1e-5);
    EXPECT_GT(t.SameFrame(1, 2), 0.0f);
    EXPECT_EQ(t.SameFrame(1, 3), 0.0f);
}

TEST(ScreenSpaceTables, BrdfTableMatchesHighSampleEstimate) {
    // Its build time is screen_space_benchmark's to measure, not a test's (machines are shared).
    BrdfPreintegration table;  // 1024 samples per entry, the size Zhuang et al. use
    // In [0, 1], and F_beta = F0 A + B <= 1 for F0 = 1 (energy: A + B is the albedo of a
    // perfect reflector), with 1e-3 slack for the estimate's error.
    for (int j = 0; j < BrdfPreintegration::kSize; ++j)
        for (int i = 0; i < BrdfPreintegration::kSize; ++i) {
            const glm::vec2 e = table.Entry(i, j);
            ASSERT_GE(e.x, 0.0f);
            ASSERT_GE(e.y, 0.0f);
            ASSERT_LE(e.x + e.y, 1.001f) << i << " " << j;
        }
    // Against an independent stratified estimate with 2^18 samples (its own error is < 2e-4):
    // the table (Hammersley, 1024 samples) is within 2e-3 everywhere tested, and at
    // entry centres away from grazing it is within 1e-3. Measured max error printed.
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    float maxErr = 0.0f;
    for (int k = 0; k < 40; ++k) {
        const int i = 8 + int(uni(rng) * 247), j = int(uni(rng) * 255);
        const float c = float(i) / 255.0f, a = float(j) / 255.0f;
        const glm::vec2 ref = BrdfPreintegration::Reference(c, a, 1 << 18, 11 + k);
        const glm::vec2 got = table.ScaleBias(c, a);
        maxErr = std::max({maxErr, std::abs(got.x - ref.x), std::abs(got.y - ref.y)});
        EXPECT_NEAR(got.x, ref.x, 2e-3) << "cos " << c << " alpha " << a;
        EXPECT_NEAR(got.y, ref.y, 2e-3) << "cos " << c << " alpha " << a;
    }
    std::printf("BRDF table: max |error| vs 2^18-sample estimate = %.2e\n", maxErr);
    // Smooth limit: a mirror (alpha ~ 0) reflects Schlick's F exactly: A = 1 - (1-c)^5, B =
    // (1-c)^5.
    for (float c : {0.2f, 0.5f, 0.9f}) {
        const glm::vec2 e = table.ScaleBias(c, 0.0f);
        const float fc = std::pow(1.0f - c, 5.0f);
        EXPECT_NEAR(e.x, 1.0f - fc, 2e-3);
        EXPECT_NEAR(e.y, fc, 2e-3);
    }
    EXPECT_THROW(BrdfPreintegration(0), InputError);
}

// ---- Reprojection --------------------------------------------------------------------------

// A camera looking straight down -z at a wall (plane z = 0) from z = d.
SynthScene WallScene(int w, int h) {
    SynthScene sc;
    sc.width = w, sc.height = h;
    sc.eye = glm::vec3(0.0f, 0.0f, 5.0f), sc.target = glm::vec3(0.0f, 0.0f, 0.0f);
    SynthObject wall;
    wall.kind = SynthObject::Kind::Plane;
    wall.id = 0, wall.a = glm::vec3(0.0f), wall.b = glm::vec3(0.0f, 0.0f, 1.0f);
    sc.objects.push_back(wall);
    sc.glossy = sc.indirect = false;
    return sc;
}

TEST(ScreenSpaceReprojection, CameraTranslationLandsOnTheRightPixel) {
    // Camera moving by (0.1, 0.05, 0) per frame parallel to a fronto-parallel wall 5 units away:
    // a wall point moves by -(dx, -dy) * f / 5 pixels, f = (h / 2) / tan(fovY / 2). The
    // back-projected position must be within 0.01 px of that (float round-off of the
    // projections is ~1e-4 px).
    SynthScene sc = WallScene(96, 64);
    sc.eyeVelocity = glm::vec3(0.1f, 0.05f, 0.0f);
    ScreenSpaceDenoiser dn;
    dn.Denoise(SynthRender(sc, 0, 1), Method::Baseline, Demodulation::Off);
    dn.Denoise(SynthRender(sc, 1, 1), Method::Baseline, Demodulation::Off);
    const auto mv = dn.LastMotion(MotionKind::Traditional);
    const float f = 0.5f * float(sc.height) / std::tan(0.5f * sc.fovY);
    const glm::vec2 shift(-0.1f * f / 5.0f, 0.05f * f / 5.0f);  // previous = current - motion
    int checked = 0;
    for (int y = 4; y < sc.height - 4; ++y)
        for (int x = 4; x < sc.width - 4; ++x) {
            const glm::vec2 got = mv[size_t(y) * size_t(sc.width) + size_t(x)];
            const glm::vec2 want = glm::vec2(float(x) + 0.5f, float(y) + 0.5f) - shift;
            ASSERT_NEAR(got.x, want.x, 0.01f) << x << "," << y;
            ASSERT_NEAR(got.y, want.y, 0.01f) << x << "," << y;
            ++checked;
        }
    EXPECT_GT(checked, 4000);
}

TEST(ScreenSpaceReprojection, ObjectMotionLandsOnTheRightPixel) {
    // A box 1 unit in front of the wall moves by (0.3, 0, 0) per frame; its front face is 4
    // units from the camera, so its pixels came from 0.3 f / 4 px to the left (within 0.01 px);
    // the static wall's pixels did not move, and wall pixels the box covered in the previous
    // frame have no history (the disocclusion test).
    SynthScene sc = WallScene(96, 64);
    sc.objects.push_back(Box(1, glm::vec3(-0.5f, -0.5f, 0.5f), glm::vec3(0.5f, 0.5f, 1.0f),
                             glm::vec3(0.3f, 0.0f, 0.0f)));
    ScreenSpaceDenoiser dn;
    dn.Denoise(SynthRender(sc, 0, 1), Method::Baseline, Demodulation::Off);
    const FrameBuffers f1 = SynthRender(sc, 1, 1);
    dn.Denoise(f1, Method::Baseline, Demodulation::Off);
    const auto mv = dn.LastMotion(MotionKind::Traditional);
    const float f = 0.5f * float(sc.height) / std::tan(0.5f * sc.fovY);
    const float shift = 0.3f * f / 4.0f;
    int onBox = 0, onWall = 0, revealed = 0;
    const FrameBuffers f0 = SynthRender(sc, 0, 1);
    for (int y = 0; y < sc.height; ++y)
        for (int x = 0; x < sc.width; ++x) {
            const size_t i = size_t(y) * size_t(sc.width) + size_t(x);
            const glm::vec2 c(float(x) + 0.5f, float(y) + 0.5f);
            if (f1.objectId[i] == 1 && f1.normal[i].z > 0.99f) {
                ASSERT_NEAR(mv[i].x, c.x - shift, 0.01f) << x << "," << y;
                ASSERT_NEAR(mv[i].y, c.y, 0.01f);
                ++onBox;
            } else if (f1.objectId[i] == 0 && f0.objectId[i] == 0) {
                // Wall seen in both frames at this pixel (and its bilinear neighbours, mostly).
                if (!std::isnan(mv[i].x)) {
                    ASSERT_NEAR(mv[i].x, c.x, 0.01f);
                    ASSERT_NEAR(mv[i].y, c.y, 0.01f);
                    ++onWall;
                }
            } else if (f1.objectId[i] == 0 && f0.objectId[i] == 1) {
                // Revealed wall: history only from wall taps of the previous frame. Pixels deep
                // inside the revealed strip (their whole 2x2 footprint was box) have none.
                bool wallTap = false;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int xx = x + dx, yy = y + dy;
                        if (xx >= 0 && yy >= 0 && xx < sc.width && yy < sc.height)
                            wallTap |= f0.objectId[size_t(yy) * size_t(sc.width) + size_t(xx)] == 0;
                    }
                if (!wallTap) {
                    EXPECT_TRUE(std::isnan(mv[i].x))
                        << "revealed wall pixel " << x << "," << y << " took history from the box";
                    ++revealed;
                }
            }
        }
    EXPECT_GT(onBox, 100);
    EXPECT_GT(onWall, 1000);
    EXPECT_GT(revealed, 10);
}

// ---- Smoke: every method on a full synthetic scene stays finite -----------------------------

SynthScene FullScene(int w, int h) {
    SynthScene sc;
    sc.width = w, sc.height = h;
    sc.lightRadius = 0.3f;
    sc.objects.push_back(Ground(0));
    SynthObject floorGloss = Ground(0);
    sc.objects[0].f0 = glm::vec3(0.6f);
    sc.objects[0].roughness = 0.1f, sc.objects[0].roughness2 = 0.5f;
    sc.objects.push_back(Box(1, glm::vec3(-1.5f, 0.0f, -0.5f), glm::vec3(-0.5f, 1.0f, 0.5f),
                             glm::vec3(0.05f, 0.0f, 0.0f)));
    SynthObject sph;
    sph.kind = SynthObject::Kind::Sphere;
    sph.id = 2, sph.a = glm::vec3(1.0f, 0.7f, 0.0f), sph.b = glm::vec3(0.7f, 0.0f, 0.0f);
    sph.albedo = glm::vec3(0.2f, 0.7f, 0.3f);
    sc.objects.push_back(sph);
    SynthObject back = Ground(3, glm::vec3(0.7f));
    back.a = glm::vec3(0.0f, 0.0f, -3.0f), back.b = glm::vec3(0.0f, 0.0f, 1.0f);
    sc.objects.push_back(back);
    sc.eyeVelocity = glm::vec3(0.02f, 0.0f, 0.0f);
    sc.lightVelocity = glm::vec3(0.05f, 0.0f, 0.0f);
    (void)floorGloss;
    return sc;
}

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

// ---- Temporal behaviour ---------------------------------------------------------------------

// The composed image of a frame whose components are averages of many samples.
std::vector<glm::vec3> Reference(const SynthScene& sc, int frame, int spp) {
    return SynthRender(sc, frame, 99, spp).Compose();
}

std::vector<char> GeometryMask(const FrameBuffers& f) {
    std::vector<char> m(f.NumPixels());
    for (size_t i = 0; i < m.size(); ++i) m[i] = f.objectId[i] >= 0;
    return m;
}

TEST(ScreenSpaceTemporal, StaticNoisySceneConverges) {
    // A static scene with a soft shadow, a glossy sphere and diffuse indirect light, 1 sample
    // per pixel per frame. After 16 frames the error against the 256-spp reference must be at
    // most 1/4 of the noisy input's and at most 0.8x the first frame's (which is already
    // spatially filtered) for every temporal method; 0.6x with the default settings, which
    // converge alike (measured 0.55x for each). Reliable with its glossy vectors jittered over
    // the lobe's footprint (maxGlossyJitter 4 px, issue 21's default) converged less, ~0.73x:
    // the jitter reuses a random pixel of the lobe's footprint, a blur that never converges.
    SynthScene sc = FullScene(96, 64);
    sc.eyeVelocity = sc.lightVelocity = glm::vec3(0.0f);
    for (SynthObject& o : sc.objects) o.velocity = glm::vec3(0.0f);
    sc.objects[2].f0 = glm::vec3(0.9f, 0.6f, 0.3f);  // the sphere: glossy
    sc.objects[2].roughness = 0.3f;
    const auto ref = Reference(sc, 0, 256);
    const auto mask = GeometryMask(SynthRender(sc, 0, 1));
    for (Method m : kTemporal) {
        ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
        double first = 0.0, last = 0.0, noisy = 0.0;
        for (int fr = 0; fr < 16; ++fr) {
            const FrameBuffers f = SynthRender(sc, fr, 3);
            const auto out = dn.Denoise(f, m, Demodulation::On);
            if (fr == 0)
                first = test::Rmse(out, ref, &mask), noisy = test::Rmse(f.Compose(), ref, &mask);
            if (fr == 15) last = test::Rmse(out, ref, &mask);
        }
        std::printf("%-15s RMSE noisy %.4f, frame 1 %.4f, frame 16 %.4f\n", MethodName(m), noisy,
                    first, last);
        EXPECT_LT(last, 0.6 * first) << MethodName(m);
        EXPECT_LT(last, 0.25 * noisy) << MethodName(m);
    }
}

// Where the history is valid (a static scene, 1 spp per frame), Reliable's diffuse indirect
// must converge as well as the baseline's. Issue 21: clamping to 1-spp 3x3 neighbourhoods (whose
// sigma is often 0 where the light is sparse) and the raw cone history (SVGF keeps the first
// a-trous level instead) kept Reliable above the plain baseline. Indirect RMSE against a
// 128-spp reference after 10 frames: Reliable at most 1.05x the baseline's (measured 1.00x),
// and with issue 5's settings (clamped cones) at least 1.05x (measured 1.14x), so that the
// scene tells the two apart.
TEST(ScreenSpaceTemporal, ReliableIndirectConvergesLikeTheBaselineWhereHistoryIsValid) {
    SynthScene sc = FullScene(96, 64);
    sc.eyeVelocity = sc.lightVelocity = glm::vec3(0.0f);
    for (SynthObject& o : sc.objects) o.velocity = glm::vec3(0.0f);
    const FrameBuffers ref = SynthRender(sc, 0, 99, 128);
    const auto mask = GeometryMask(ref);
    std::vector<FrameBuffers> frames;
    for (int fr = 0; fr < 10; ++fr) frames.push_back(SynthRender(sc, fr, 3));
    DenoiserSettings issue5;
    issue5.reliableGlossyClampK = issue5.reliableIndirectClampK = 3.0f;
    issue5.indirectCones = true;
    auto indirectRmse = [&](Method m, const DenoiserSettings& set) {
        ScreenSpaceDenoiser dn(set, SharedBrdf());
        for (const FrameBuffers& f : frames) dn.Denoise(f, m, Demodulation::Off);
        return test::Rmse(dn.Indirect(), ref.indirect, &mask);
    };
    const double base = indirectRmse(Method::Baseline, {});
    const double rel = indirectRmse(Method::Reliable, {});
    const double old = indirectRmse(Method::Reliable, issue5);
    std::printf("indirect RMSE: baseline %.4f, reliable %.4f (%.2fx), issue 5's %.4f (%.2fx)\n",
                base, rel, rel / base, old, old / base);
    EXPECT_LE(rel, 1.05 * base);
    EXPECT_GE(old, 1.05 * base);
}

// A wall (grey) with a red box in front of it that stands still for 6 frames, then jumps 0.4
// units (~8 pixels) to the right. Lit from the camera (its shadow hides behind it), indirect
// light at 64 spp (nearly noise-free), so the exact frame is known.
struct JumpScene {
    SynthScene before, after;
    explicit JumpScene(int width = 128, int height = 80) {
        before = WallScene(width, height);
        before.light = before.eye, before.lightIntensity = glm::vec3(60.0f);
        before.objects[0].albedo = glm::vec3(0.2f);
        before.indirect = true, before.cones = true;
        SynthObject box = Box(1, glm::vec3(-0.6f, -0.5f, 0.5f), glm::vec3(0.2f, 0.5f, 1.0f));
        box.albedo = glm::vec3(1.0f, 0.1f, 0.1f);
        before.objects.push_back(box);
        after = before;
        // at frame 6 the box is at +0.4 and came from +0 (velocity 0.4 per frame)
        after.objects[1].velocity = glm::vec3(0.4f, 0.0f, 0.0f);
        after.objects[1].a -= 6.0f * glm::vec3(0.4f, 0.0f, 0.0f) - glm::vec3(0.4f, 0.0f, 0.0f);
        after.objects[1].b -= 6.0f * glm::vec3(0.4f, 0.0f, 0.0f) - glm::vec3(0.4f, 0.0f, 0.0f);
    }
};

class Disocclusion : public ::testing::TestWithParam<int> {};

TEST_P(Disocclusion, RevealedPixelsTakeNoHistoryFromTheOccluder) {
    // After the jump, wall pixels the box covered in the previous frame must look like the
    // wall: their red excess (r - g) stays within 0.1 of the exact frame's (the box's own is
    // ~0.3; one frame of box history at alpha 0.2 would add ~0.25), for every temporal method
    // and with / without demodulation. At 128x80 the box's motion is fitted to all its pixels,
    // at 256x160 to a subsample of them (OcclusionMotion's kFitStep).
    const JumpScene js(128 * GetParam(), 80 * GetParam());
    std::vector<FrameBuffers> still;
    for (int fr = 0; fr < 6; ++fr) still.push_back(SynthRender(js.before, fr, 1, 64));
    const FrameBuffers& prev = still[5];
    const FrameBuffers cur = SynthRender(js.after, 6, 1, 64);
    const auto exact = cur.Compose();
    std::vector<size_t> revealed;
    for (size_t i = 0; i < cur.NumPixels(); ++i)
        if (cur.objectId[i] == 0 && prev.objectId[i] == 1) revealed.push_back(i);
    ASSERT_GT(revealed.size(), 200u);
    for (Method m : kTemporal)
        for (Demodulation d : {Demodulation::Off, Demodulation::On}) {
            ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
            for (const FrameBuffers& f : still) dn.Denoise(f, m, d);
            const auto out = dn.Denoise(cur, m, d);
            float worst = 0.0f;
            for (size_t i : revealed) {
                const float excess = (out[i].r - out[i].g) - (exact[i].r - exact[i].g);
                worst = std::max(worst, excess);
            }
            EXPECT_LT(worst, 0.1f) << MethodName(m) << (d == Demodulation::On ? " demod" : "");
            if (m == Method::Reliable) {
                // The occlusion vectors of revealed pixels point at wall in the previous frame.
                const auto mv = dn.LastMotion(MotionKind::Occlusion);
                int onWall = 0, total = 0;
                for (size_t i : revealed) {
                    if (std::isnan(mv[i].x)) continue;
                    ++total;
                    const int px = int(mv[i].x), py = int(mv[i].y);
                    onWall += prev.objectId[size_t(py) * size_t(cur.width) + size_t(px)] == 0;
                }
                EXPECT_GT(total, int(revealed.size()) / 2) << "dual vectors found no history";
                EXPECT_EQ(onWall, total);
            }
        }
}
INSTANTIATE_TEST_SUITE_P(ScreenSpaceTemporal, Disocclusion, ::testing::Values(1, 2));

// The frame's cachedVisibility (here a constant 0.25, far from the scene's visibility of ~1)
// is taken exactly where the visibility has no history: after the box's jump, every revealed
// pixel without a vector (Reliable: shadow vectors, which fall back to the traditional ones;
// Baseline and BaselineClamp: the traditional ones) shows 0.25 (within 1e-3: nothing else is
// mixed in), and every pixel more than 32 px from those (beyond the a-trous's 30 px and the
// clean-up's 4) is bit for bit what a denoiser without the buffer gives. Used everywhere, the far
// pixels would be 0.25; used nowhere, the revealed ones would not.
TEST(ScreenSpaceTemporal, CachedVisibilityOnlyWhereThereIsNoHistory) {
    const JumpScene js;
    std::vector<FrameBuffers> still;
    for (int fr = 0; fr < 2; ++fr) still.push_back(SynthRender(js.before, fr, 1));
    const FrameBuffers cur = SynthRender(js.after, 6, 1);
    FrameBuffers withCache = cur;
    withCache.cachedVisibility.assign(cur.NumPixels(), 0.25f);
    const int w = cur.width, h = cur.height;
    for (Method m : kTemporal) {
        SCOPED_TRACE(MethodName(m));
        ScreenSpaceDenoiser plain(DenoiserSettings{}, SharedBrdf()),
            cached(DenoiserSettings{}, SharedBrdf());
        for (const FrameBuffers& f : still) {
            plain.Denoise(f, m, Demodulation::On);
            cached.Denoise(f, m, Demodulation::On);
        }
        plain.Denoise(cur, m, Demodulation::On);
        cached.Denoise(withCache, m, Demodulation::On);
        const std::vector<float> v0 = plain.Visibility(), v1 = cached.Visibility();
        const auto mv =
            cached.LastMotion(m == Method::Reliable ? MotionKind::Shadow : MotionKind::Traditional);
        std::vector<char> none(cur.NumPixels(), 0);
        int numNone = 0;
        for (size_t i = 0; i < none.size(); ++i)
            if (cur.objectId[i] >= 0 && std::isnan(mv[i].x)) none[i] = 1, ++numNone;
        ASSERT_GT(numNone, 100);
        int numFar = 0;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const size_t i = size_t(y) * size_t(w) + size_t(x);
                if (cur.objectId[i] < 0) continue;
                if (none[i]) {
                    EXPECT_NEAR(v1[i], 0.25f, 1e-3f) << x << ", " << y;
                    continue;
                }
                bool far = true;
                for (int dy = -32; dy <= 32 && far; ++dy)
                    for (int dx = -32; dx <= 32 && far; ++dx) {
                        const int xx = x + dx, yy = y + dy;
                        if (xx >= 0 && yy >= 0 && xx < w && yy < h &&
                            none[size_t(yy) * size_t(w) + size_t(xx)])
                            far = false;
                    }
                if (!far) continue;
                ++numFar;
                EXPECT_EQ(v1[i], v0[i]) << x << ", " << y;
            }
        EXPECT_GT(numFar, 1000);
    }
}

// A ground plane lit by a point light straight above, a small box floating between them and
// moving along x: a hard shadow moving over a static receiver (the traditional vectors say
// "no motion", Zeng Fig. 1 left).
SynthScene ShadowScene() {
    SynthScene sc;
    sc.width = 128, sc.height = 96;
    sc.eye = glm::vec3(0.0f, 6.0f, 4.0f), sc.target = glm::vec3(0.0f, 0.0f, 0.0f);
    sc.light = glm::vec3(0.0f, 8.0f, 0.0f), sc.lightIntensity = glm::vec3(100.0f);
    sc.objects.push_back(Ground(0, glm::vec3(0.5f)));
    sc.objects.push_back(Box(1, glm::vec3(-1.6f, 3.0f, -0.4f), glm::vec3(-0.8f, 3.3f, 0.4f),
                             glm::vec3(0.12f, 0.0f, 0.0f)));
    sc.glossy = sc.indirect = false;
    return sc;
}

class MovingHardShadow : public ::testing::TestWithParam<VisibilityOrder> {};

TEST_P(MovingHardShadow, FollowsWithShadowVectors) {
    // The shadow moves ~2.5 px per frame. Over frames 6-11, the RMSE of the denoised
    // visibility against the exact one (the noise-free input) on the ground must be at least
    // 3x lower with shadow motion vectors than with the baseline's traditional ones, whose
    // history drags a trail behind the shadow; in either order of Reliable's visibility passes.
    const SynthScene sc = ShadowScene();
    double err[2] = {0.0, 0.0};
    const Method methods[2] = {Method::Baseline, Method::Reliable};
    DenoiserSettings set;
    set.reliableVisibilityOrder = GetParam();
    for (int k = 0; k < 2; ++k) {
        ScreenSpaceDenoiser dn(set, SharedBrdf());
        for (int fr = 0; fr < 12; ++fr) {
            const FrameBuffers f = SynthRender(sc, fr, 1);
            dn.Denoise(f, methods[k], Demodulation::Off);
            if (fr < 6) continue;
            const auto mask = GeometryMask(f);
            const double e = test::Rmse(dn.Visibility(), f.visibility, &mask);
            err[k] += e * e;
        }
        err[k] = std::sqrt(err[k] / 6.0);
    }
    std::printf("moving hard shadow: visibility RMSE baseline %.4f, reliable %.4f (%.1fx)\n",
                err[0], err[1], err[0] / err[1]);
    EXPECT_LT(err[1] * 3.0, err[0]);
}
INSTANTIATE_TEST_SUITE_P(ScreenSpaceTemporal, MovingHardShadow,
                         ::testing::Values(VisibilityOrder::Zeng, VisibilityOrder::Svgf));

TEST(ScreenSpaceTemporal, SvgfOrderVisibilityIsTheBaselinesWhereNoShadowMoves) {
    // A camera flying over a static scene (objects and light still, soft shadows, 1 spp): every
    // shadow vector is the traditional one, splatted ones included, so Reliable's visibility in
    // SVGF order must be the baseline's (issue 21: on anim_flythrough Reliable trailed the
    // plain baseline): the shadow vectors land within 0.08 px of the traditional ones here, so
    // the traditional vectors and taps replace them and the passes are the baseline's. Tolerance
    // 1e-6 on the largest difference over 8 frames (measured 0: the same arithmetic). Zeng's
    // order differs by more than 0.02 (measured 0.72 at a shadow edge: the test tells the two
    // apart).
    SynthScene sc = FullScene(96, 64);
    sc.lightVelocity = glm::vec3(0.0f);
    for (SynthObject& o : sc.objects) o.velocity = glm::vec3(0.0f);
    sc.eyeVelocity = glm::vec3(0.06f, 0.0f, -0.04f);
    auto maxDiff = [&](VisibilityOrder order) {
        DenoiserSettings set;
        set.reliableVisibilityOrder = order;
        ScreenSpaceDenoiser base(set, SharedBrdf()), rel(set, SharedBrdf());
        float worst = 0.0f;
        for (int fr = 0; fr < 8; ++fr) {
            const FrameBuffers f = SynthRender(sc, fr, 7);
            base.Denoise(f, Method::Baseline, Demodulation::On);
            rel.Denoise(f, Method::Reliable, Demodulation::On);
            const std::vector<float> vb = base.Visibility(), vr = rel.Visibility();
            for (size_t i = 0; i < vb.size(); ++i) {
                EXPECT_TRUE(std::isfinite(vr[i]));
                worst = std::max(worst, std::fabs(vb[i] - vr[i]));
            }
        }
        return worst;
    };
    const float svgf = maxDiff(VisibilityOrder::Svgf), zeng = maxDiff(VisibilityOrder::Zeng);
    std::printf("largest visibility difference from the baseline: SVGF order %.2g, Zeng's %.2g\n",
                svgf, zeng);
    EXPECT_LE(svgf, 1e-6f);
    EXPECT_GT(zeng, 0.02f);
}

TEST(ScreenSpaceTemporal, MovingReflectionFollowsGlossyVectors) {
    // A nearly mirror-like floor (GGX alpha 0.05) reflecting a bright box that moves 0.15 units
    // (~3 px) per frame; camera, floor and sky static, so the traditional vectors say "no motion"
    // while the reflection moves. Over frames 6-11, the glossy RMSE against 32-spp references of
    // each frame must be lower with the glossy vectors than with the baseline's:
    // by 1.15x with the default unclamped glossy history (measured 1.30x; 1.26x with the 4 px
    // jitter) and 1.5x with it clamped at 3 sigma (measured 1.80x). The clamp's cost: it trims the
    // ghost at the reflection's edges here, and on the temporal experiment's 1-spp scenes it threw
    // valid history away (issue 21, results/temporal.md), hence off by default.
    SynthScene sc;
    sc.width = 96, sc.height = 64;
    sc.eye = glm::vec3(0.0f, 1.0f, 5.0f), sc.target = glm::vec3(0.0f, 0.3f, 0.0f);
    sc.lightIntensity = glm::vec3(0.0f);
    sc.skyHorizon = glm::vec3(0.2f), sc.skyZenith = glm::vec3(0.1f);
    SynthObject floor = Ground(0);
    floor.f0 = glm::vec3(0.9f), floor.roughness = 0.05f;
    sc.objects.push_back(floor);
    SynthObject box = Box(1, glm::vec3(-1.6f, 0.2f, -0.4f), glm::vec3(-0.8f, 1.0f, 0.4f),
                          glm::vec3(0.15f, 0.0f, 0.0f));
    box.albedo = glm::vec3(1.0f), box.ambient = 4.0f;
    sc.objects.push_back(box);
    sc.indirect = false;
    std::vector<FrameBuffers> frames, refs;
    for (int fr = 0; fr < 12; ++fr) {
        frames.push_back(SynthRender(sc, fr, 4));
        refs.push_back(SynthRender(sc, fr, 50, 32));
    }
    double err[3] = {0.0, 0.0, 0.0};
    const Method methods[3] = {Method::Baseline, Method::Reliable, Method::Reliable};
    DenoiserSettings clamped;
    clamped.reliableGlossyClampK = 3.0f;
    for (int k = 0; k < 3; ++k) {
        ScreenSpaceDenoiser dn(k == 2 ? clamped : DenoiserSettings{}, SharedBrdf());
        for (int fr = 0; fr < 12; ++fr) {
            dn.Denoise(frames[size_t(fr)], methods[k], Demodulation::On);
            if (fr < 6) continue;
            std::vector<char> mask(frames[0].NumPixels());
            for (size_t i = 0; i < mask.size(); ++i) mask[i] = frames[size_t(fr)].objectId[i] == 0;
            const double e = test::Rmse(dn.Glossy(), refs[size_t(fr)].glossy, &mask);
            err[k] += e * e;
        }
        err[k] = std::sqrt(err[k] / 6.0);
    }
    std::printf(
        "moving reflection: glossy RMSE baseline %.4f, reliable %.4f (%.2fx), clamped %.4f "
        "(%.2fx)\n",
        err[0], err[1], err[0] / err[1], err[2], err[0] / err[2]);
    EXPECT_LT(err[1] * 1.15, err[0]);
    EXPECT_LT(err[2] * 1.5, err[0]);
}

TEST(ScreenSpaceTemporal, FirstFrameAndVectorsLeavingTheImageHaveNoHistory) {
    // First frame: no vector of any kind. Then the camera pans 0.5 units (~8 px): the pixels
    // along the edge the view moved towards came from outside the previous image and have no
    // history; the output stays finite.
    SynthScene sc = WallScene(96, 64);
    sc.eyeVelocity = glm::vec3(0.5f, 0.0f, 0.0f);
    ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
    dn.Denoise(SynthRender(sc, 0, 1), Method::Reliable, Demodulation::Off);
    for (MotionKind k : {MotionKind::Traditional, MotionKind::Shadow, MotionKind::Occlusion})
        for (const glm::vec2& v : dn.LastMotion(k)) ASSERT_TRUE(std::isnan(v.x));
    const auto out = dn.Denoise(SynthRender(sc, 1, 1), Method::Reliable, Demodulation::Off);
    const auto mv = dn.LastMotion(MotionKind::Traditional);
    const float f = 0.5f * float(sc.height) / std::tan(0.5f * sc.fovY);
    const int shift = int(std::ceil(0.5f * f / 5.0f));  // pixels entering on the right
    for (int y = 0; y < sc.height; ++y)
        for (int x = sc.width - shift + 1; x < sc.width; ++x)
            EXPECT_TRUE(std::isnan(mv[size_t(y) * size_t(sc.width) + size_t(x)].x)) << x;
    for (const glm::vec3& c : out) ASSERT_TRUE(std::isfinite(c.x + c.y + c.z));
}

// ---- Robustness ----------------------------------------------------------------------------

TEST(ScreenSpaceRobustness, NonFiniteInputsStayContained) {
    // For every input buffer: a 3x3 block of NaN (then +Inf) at (20, 20) in the second of three
    // frames. Every output stays finite, and pixels more than 60 px away are as in a clean run
    // (within 1e-3 relative: the a-trous reaches 15 px, the shadow filter 15, the clean-up 4,
    // the shadow splat 8; only per-object motion fits see the whole image, and they skip
    // non-finite samples).
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
            ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
            for (const FrameBuffers& f : clean) ref = dn.Denoise(f, m, Demodulation::On);
        }
        auto run = [&](const std::string& name, auto&& poison) {
            for (float b : bad) {
                ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
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

// ---- Kernels against scalar references ------------------------------------------------------

// The box sum (the shadow splat's window) equals the brute-force sum of the in-image taps, on
// planes with mostly all-zero rows (skipped), rows of mixed 0/1 and pixel-offset values, widths
// crossing the kernels' chunks, radii within the padding (doubling) and beyond it (running sum),
// and boxes wider than the image. Tolerance 1e-5 of the sum of |v| over the box: float sums of up
// to 81x81 terms in another order; counts of a 0/1 mask stay exact.
TEST(ScreenSpaceKernels, BoxSumMatchesBruteForce) {
    using internal::Plane;
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-4.0f, 4.0f);
    for (int w : {1, 7, 300}) {
        for (int h : {1, 5, 70}) {
            for (int r : {0, 1, 8, 20, 40}) {
                Plane in[2], out[2], tmp[2];
                for (int c = 0; c < 2; ++c)
                    in[c].Resize(w, h), out[c].Resize(w, h), tmp[c].Resize(w, h);
                for (int y = 0; y < h; ++y) {
                    if (rng() % 3 != 0) continue;  // two thirds of the rows stay zero
                    for (int x = 0; x < w; ++x) {
                        const bool on = rng() % 4 == 0;
                        in[0].At(x, y) = on ? 1.0f : 0.0f;
                        in[1].At(x, y) = on ? u(rng) : 0.0f;
                    }
                }
                const Plane* ins[2] = {&in[0], &in[1]};
                Plane* outs[2] = {&out[0], &out[1]};
                Plane* tmps[2] = {&tmp[0], &tmp[1]};
                internal::BoxSum(2, ins, outs, tmps, r);
                int bad = 0;
                for (int c = 0; c < 2; ++c)
                    for (int y = 0; y < h; ++y)
                        for (int x = 0; x < w; ++x) {
                            double e = 0.0, mag = 0.0;
                            for (int yy = std::max(0, y - r); yy <= std::min(h - 1, y + r); ++yy)
                                for (int xx = std::max(0, x - r); xx <= std::min(w - 1, x + r);
                                     ++xx)
                                    e += in[c].At(xx, yy), mag += std::fabs(in[c].At(xx, yy));
                            const float got = out[c].At(x, y);
                            if (c == 0 ? got != float(e)
                                       : !(std::fabs(got - e) <= 1e-5 * (1.0 + mag)))
                                ++bad;
                        }
                EXPECT_EQ(bad, 0) << w << "x" << h << " r=" << r;
            }
        }
    }
}

// The vectorized final sum equals the per-pixel formula emitted + shading * visibility' +
// glossy' + indirect' (non-finite emitted / shading skipped as a whole), on random buffers with
// NaN/Inf in 5% of the pixels, a width crossing the kernels' 256-pixel chunks and every border.
// Tolerance 1e-5 relative: the same sum, up to the compiler contracting it into FMAs.
TEST(ScreenSpaceKernels, ComposeMatchesScalarSum) {
    SynthScene sc = FullScene(300, 40);
    FrameBuffers f = SynthRender(sc, 0, 1);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(0.0f, 2.0f);
    const float bad[3] = {std::numeric_limits<float>::quiet_NaN(),
                          std::numeric_limits<float>::infinity(),
                          -std::numeric_limits<float>::infinity()};
    f.emitted.assign(f.NumPixels(), glm::vec3(0.0f));
    for (size_t i = 0; i < f.NumPixels(); ++i) {
        f.emitted[i] = glm::vec3(u(rng), u(rng), u(rng));
        f.shading[i] = glm::vec3(u(rng), u(rng), u(rng));
        if (rng() % 20 == 0) f.emitted[i][rng() % 3] = bad[rng() % 3];
        if (rng() % 20 == 0) f.shading[i][rng() % 3] = bad[rng() % 3];
    }
    for (Method m : {Method::SpatialOnly, Method::Reliable}) {
        ScreenSpaceDenoiser dn(DenoiserSettings{}, SharedBrdf());
        const std::vector<glm::vec3> img = dn.Denoise(f, m, Demodulation::On);
        const std::vector<float> vis = dn.Visibility();
        const std::vector<glm::vec3> gl = dn.Glossy(), ind = dn.Indirect();
        ASSERT_EQ(img.size(), f.NumPixels());
        auto finite = [](glm::vec3 v) {
            return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
        };
        int bad_pixels = 0;
        for (size_t i = 0; i < img.size(); ++i) {
            glm::vec3 e(0.0f);
            if (finite(f.emitted[i])) e += f.emitted[i];
            if (finite(f.shading[i])) e += f.shading[i] * vis[i];
            if (!gl.empty()) e += gl[i];
            if (!ind.empty()) e += ind[i];
            for (int c = 0; c < 3; ++c)
                if (!(std::fabs(img[i][c] - e[c]) <= 1e-5f * (1.0f + std::fabs(e[c]))))
                    ++bad_pixels;
        }
        EXPECT_EQ(bad_pixels, 0) << MethodName(m);
    }
}

// The cones' diffuse shading (the preparation kernel, and the cone pass's per-cone sums) equals
// albedo * ShadeCones() per pixel: first frame of Reliable (no history: the pass passes the
// cones through), luminance stopping so tight that the a-trous keeps each pixel's own value
// (every pixel gets its own luminance). NaN cones in 2% of the pixels (skipped there, and they
// must not leak). Tolerance 1e-4 relative: sums of 6 products in another order.
TEST(ScreenSpaceKernels, ConeShadingMatchesShadeCones) {
    SynthScene sc = FullScene(300, 40);
    FrameBuffers f = SynthRender(sc, 0, 1);
    ASSERT_EQ(f.cones.size(), f.NumPixels() * kNumCones);
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0.0f, 1e-4f);
    std::vector<char> poisoned(f.NumPixels(), 0);
    for (size_t i = 0; i < f.NumPixels(); ++i) {
        // A per-pixel base 1e-3 i apart keeps every pixel's luminance distinct from its
        // neighbours' by far more than the random part (< 1e-4), which varies cones and channels.
        const float base = 1e-3f * float(i);
        for (int k = 0; k < kNumCones; ++k)
            f.cones[i * kNumCones + size_t(k)] =
                glm::vec3(base + u(rng), base + u(rng), base + u(rng));
        if (rng() % 50 == 0) {
            f.cones[i * kNumCones + rng() % kNumCones][rng() % 3] =
                std::numeric_limits<float>::quiet_NaN();
            poisoned[i] = 1;
        }
    }
    DenoiserSettings set;
    set.sigmaLuminance = 1e-7f;
    set.indirectCones = true;
    ScreenSpaceDenoiser dn(set, SharedBrdf());
    dn.Denoise(f, Method::Reliable, Demodulation::On);
    const std::vector<glm::vec3> ind = dn.Indirect();
    ASSERT_EQ(ind.size(), f.NumPixels());
    int checked = 0, bad = 0;
    for (size_t i = 0; i < ind.size(); ++i) {
        for (int c = 0; c < 3; ++c) EXPECT_TRUE(std::isfinite(ind[i][c])) << i;
        const bool usable = f.depth[i] > 0.0f && std::isfinite(f.depth[i]) &&
                            std::isfinite(f.albedo[i].x) && !poisoned[i];
        if (!usable) continue;
        const glm::vec3 e = f.albedo[i] * ShadeCones(&f.cones[i * kNumCones]);
        ++checked;
        for (int c = 0; c < 3; ++c)
            if (!(std::fabs(ind[i][c] - e[c]) <= 1e-4f * (1e-3f + std::fabs(e[c])))) ++bad;
    }
    EXPECT_GT(checked, int(f.NumPixels() / 2));
    EXPECT_EQ(bad, 0) << "of " << checked;
}

}  // namespace
}  // namespace texcache::screen
