// SPDX-License-Identifier: Apache-2.0
// The screen-space stage's building blocks against independent references: the cone and BRDF
// tables against Monte Carlo estimates, and the vectorized kernels (box sums, compose, cone
// shading) against scalar code.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "screen_space/brdf_table.h"
#include "screen_space/cone_overlap.h"
#include "screen_space/planes.h"
#include "screen_space/screen_denoiser.h"
#include "screen_space_util.h"
#include "testing/screen_space_scene.h"
#include "texcache/error.h"

namespace texcache::screen {
namespace {

using test::FullScene;
using test::SharedBrdf;
using test::SynthRender;
using test::SynthScene;

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
