// SPDX-License-Identifier: Apache-2.0
// Error metrics with known answers: relMSE by hand, exact RMSE/PSNR of offsets, SSIM of constant
// images in closed form, the non-finite policy (counted, excluded, never NaN), and the error image.
#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>

#include "renderer/image/image.h"
#include "renderer/image/metrics.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

using test::Ramp;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

// Smooth structure plus multiples of 1/64 so that offsets by 1/8 are exact in float.
Image Pattern(int w, int h) {
    Image img(w, h, 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int k = 0; k < 3; ++k)
                img.At(x, y)[k] = float((x * 3 + y * 5 + k * 11) % 48) / 64.0f;
    return img;
}

Image AddNoise(const Image& img, float sigma, unsigned seed) {
    Image out = img;
    std::mt19937 gen(seed);
    std::normal_distribution<float> n(0.0f, sigma);
    for (float& v : out.data) v += n(gen);
    return out;
}

TEST(ErrorMetrics, IdenticalImages) {
    const Image a = Pattern(40, 23);
    const ImageErrors e = CompareImages(a, a);
    EXPECT_EQ(e.relMSE, 0.0);
    EXPECT_EQ(e.rmse, 0.0);
    EXPECT_TRUE(std::isinf(e.psnr) && e.psnr > 0);
    EXPECT_EQ(e.ssim, 1.0);  // equal means and moments make numerator and denominator equal
    EXPECT_EQ(e.nonFinite, 0u);
    EXPECT_TRUE(std::isinf(PSNR(a, a)));
}

TEST(ErrorMetrics, ConstantOffsetGivesExactRmseAndPsnr) {
    const Image ref = Pattern(31, 17);
    Image test = ref;
    for (float& v : test.data) v += 0.125f;  // exact: both are multiples of 1/64 below 2
    EXPECT_EQ(RMSE(test, ref), 0.125);       // every squared difference is exactly 1/64
    EXPECT_EQ(RMSE(ref, test), 0.125);
    // 20 log10(1 / 0.125) = 20 log10(8); double rounding only.
    EXPECT_NEAR(PSNR(test, ref), 20.0 * std::log10(8.0), 1e-12);
    EXPECT_NEAR(PSNR(test, ref, 2.0), 20.0 * std::log10(16.0), 1e-12);
    EXPECT_EQ(CompareImages(test, ref).rmse, 0.125);
}

TEST(ErrorMetrics, RelMseByHand) {
    // 2x2, reference greys 0.5, 0, 0.5, 0.5 (gray = mean of R,G,B); all values dyadic.
    Image ref(2, 2, 3), test(2, 2, 3);
    const float r[4][3] = {{0.5f, 0.5f, 0.5f}, {0, 0, 0}, {1.0f, 0.5f, 0}, {0.25f, 0.25f, 1.0f}};
    const float t[4][3] = {
        {0.75f, 0.5f, 0.5f}, {0.125f, 0, 0}, {1.0f, 0.5f, 0.25f}, {0.25f, 0.25f, 1.0f}};
    for (int p = 0; p < 4; ++p)
        for (int k = 0; k < 3; ++k) ref.data[p * 3 + k] = r[p][k], test.data[p * 3 + k] = t[p][k];
    // Per pixel: sum_c d^2 / (gray^2 + eps)
    //   p0: 0.0625 / (0.25 + 0.001)   p1: 0.015625 / (0 + 0.001) = 15.625
    //   p2: 0.0625 / (0.25 + 0.001)   p3: 0
    const double expected = (0.0625 / 0.251 + 15.625 + 0.0625 / 0.251 + 0.0) / 4.0;
    EXPECT_NEAR(expected, 4.03075199, 1e-8);                     // the hand arithmetic itself
    EXPECT_NEAR(RelMSE(test, ref), expected, 1e-12 * expected);  // double sums of exact inputs
    EXPECT_NEAR(CompareImages(test, ref).relMSE, expected, 1e-12 * expected);
    const double eps01 = (0.0625 / 0.26 + 0.015625 / 0.01 + 0.0625 / 0.26) / 4.0;
    EXPECT_NEAR(RelMSE(test, ref, 0.01), eps01, 1e-12 * eps01);
    // relMSE normalizes by the reference only: it is not symmetric.
    EXPECT_NE(RelMSE(ref, test), RelMSE(test, ref));
}

TEST(ErrorMetrics, SsimOfConstantImagesIsClosedForm) {
    // Flat images have zero variance and covariance: SSIM = (2 a b + C1) / (a^2 + b^2 + C1) on
    // the display values (C2 terms cancel). Linear 0 and 1 encode to 0 and 1.
    const double c1 = 1e-4;
    // Luma planes are stored as float (relative rounding 6e-8), the blur of a constant is
    // constant to a few ulp: 1e-7 absorbs both.
    EXPECT_NEAR(SSIM(Image(20, 20, 3, 0.0f), Image(20, 20, 3, 1.0f)), c1 / (1.0 + c1), 1e-7);
    // Linear 0.5 -> sRGB 0.735357 in every channel, so luma 0.735357 (weights sum to 1).
    const double s = 1.055 * std::pow(0.5, 1.0 / 2.4) - 0.055;
    EXPECT_NEAR(SSIM(Image(20, 20, 3, 0.5f), Image(20, 20, 3, 1.0f)),
                (2 * s + c1) / (s * s + 1 + c1), 1e-7);
    // Values above 1 are clamped as on screen: 5.0 looks like 1.0.
    EXPECT_NEAR(SSIM(Image(9, 9, 3, 5.0f), Image(9, 9, 3, 1.0f)), 1.0, 1e-12);
}

TEST(ErrorMetrics, SsimOfNoisyImages) {
    const Image ref = Pattern(96, 64);
    const Image slight = AddNoise(ref, 0.02f, 1), heavy = AddNoise(ref, 0.2f, 2);
    const double s1 = SSIM(slight, ref), s2 = SSIM(heavy, ref);
    EXPECT_GT(s1, 0.0);
    EXPECT_LT(s1, 1.0);
    EXPECT_GT(s2, 0.0);
    EXPECT_LT(s2, s1);  // more noise, less similar
    // The formula is symmetric in the two images; only summation order could differ (none here).
    EXPECT_NEAR(SSIM(ref, slight), s1, 1e-12);
    EXPECT_NEAR(SSIM(ref, heavy), s2, 1e-12);
}

TEST(ErrorMetrics, ResultsDoNotDependOnThreadCount) {
    const Image ref = Pattern(300, 200), test = AddNoise(ref, 0.05f, 3);
    const ImageErrors many = CompareImages(test, ref);
    ImageErrors one;
    tbb::task_arena arena(1);
    arena.execute([&] { one = CompareImages(test, ref); });
    // Bit-identical, not just close: the reductions have a fixed order.
    EXPECT_EQ(std::memcmp(&one.relMSE, &many.relMSE, sizeof(double)), 0);
    EXPECT_EQ(std::memcmp(&one.rmse, &many.rmse, sizeof(double)), 0);
    EXPECT_EQ(std::memcmp(&one.ssim, &many.ssim, sizeof(double)), 0);
}

TEST(ErrorMetrics, MismatchedImagesThrow) {
    EXPECT_THROW(CompareImages(Image(4, 4, 3), Image(4, 5, 3)), InputError);
    EXPECT_THROW(CompareImages(Image(4, 4, 3), Image(5, 4, 3)), InputError);
    EXPECT_THROW(CompareImages(Image(4, 4, 3), Image(4, 4, 4)), InputError);
    EXPECT_THROW(CompareImages(Image(4, 4, 1), Image(4, 4, 1)), InputError);
    EXPECT_THROW(RelMSE(Image(4, 4, 3), Image(3, 4, 3)), InputError);
    EXPECT_THROW(RMSE(Image(4, 4, 3), Image(3, 4, 3)), InputError);
    EXPECT_THROW(SSIM(Image(4, 4, 3), Image(3, 4, 3)), InputError);
    EXPECT_THROW(FalseColorError(Image(4, 4, 3), Image(3, 4, 3)), InputError);
    try {
        CompareImages(Image(4, 4, 3), Image(4, 5, 3));
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("4x4 vs 4x5"), std::string::npos) << e.what();
    }
}

TEST(ErrorMetrics, NonFinitePixelsAreCountedAndExcluded) {
    const Image ref = Pattern(16, 12);
    Image test = ref;
    for (float& v : test.data) v += 0.125f;
    test.At(2, 2)[1] = kNaN;
    test.At(3, 3)[0] = kInf;
    test.At(4, 4)[2] = -kInf;
    Image badRef = ref;
    badRef.At(5, 5)[0] = kNaN;  // a broken reference pixel is excluded the same way

    const ImageErrors e = CompareImages(test, badRef);
    EXPECT_EQ(e.nonFinite, 4u);
    // Excluded pixels are not counted as zero error: the remaining offset is still exact.
    EXPECT_EQ(e.rmse, 0.125);
    EXPECT_TRUE(std::isfinite(e.relMSE));
    EXPECT_TRUE(std::isfinite(e.psnr));
    EXPECT_TRUE(std::isfinite(e.ssim));
    EXPECT_GT(e.relMSE, 0.0);
    // Pixels that are not excluded carry the same relMSE as without the bad ones.
    Image clean = ref;
    for (float& v : clean.data) v += 0.125f;
    EXPECT_NEAR(e.relMSE, RelMSE(clean, ref),
                0.1 * RelMSE(clean, ref));  // 4 of 192 pixels left out

    // NaN only where the images agree otherwise: SSIM is still exactly 1 (excluded, no structure).
    Image same = ref;
    same.At(7, 7)[2] = kNaN;
    const ImageErrors s = CompareImages(same, ref);
    EXPECT_EQ(s.nonFinite, 1u);
    EXPECT_EQ(s.rmse, 0.0);
    EXPECT_EQ(s.ssim, 1.0);

    // Nothing comparable: the functions say NaN, CompareImages refuses rather than print it.
    const Image allNaN(8, 8, 3, kNaN);
    EXPECT_TRUE(std::isnan(RelMSE(allNaN, Image(8, 8, 3))));
    EXPECT_TRUE(std::isnan(SSIM(allNaN, Image(8, 8, 3))));
    EXPECT_THROW(CompareImages(allNaN, Image(8, 8, 3)), InputError);
}

TEST(ErrorMetrics, FalseColorErrorImage) {
    const Image ref = Pattern(8, 4);
    Image test = ref;
    test.At(1, 0)[0] += 0.01f;  // a small error
    test.At(2, 0)[0] += 10.0f;  // beyond the top of the scale
    test.At(3, 0)[1] = kNaN;
    const Image fc = FalseColorError(test, ref);
    ASSERT_EQ(fc.width, 8);
    ASSERT_EQ(fc.height, 4);
    ASSERT_EQ(fc.channels, 3);
    for (float v : fc.data) ASSERT_TRUE(std::isfinite(v) && v >= 0.0f && v <= 1.0f);
    // Zero error is the bottom of inferno (near black), the maximum its pale yellow end; these
    // are linear values chosen so that the PNG's sRGB encode shows the colour map's own colours.
    const float* zero = fc.At(0, 0);
    EXPECT_EQ(LinearToSrgb8(zero[0]), 0);  // inferno[0] = (0.0015, 0.0005, 0.0139) * 255
    EXPECT_EQ(LinearToSrgb8(zero[2]), 4);
    const float* top = fc.At(2, 0);
    EXPECT_EQ(LinearToSrgb8(top[0]), 252);  // inferno[255] = (0.988, 0.998, 0.645) * 255
    EXPECT_EQ(LinearToSrgb8(top[1]), 255);
    EXPECT_EQ(LinearToSrgb8(top[2]), 164);
    const float* small = fc.At(1, 0);
    EXPECT_GT(small[0] + small[1] + small[2], zero[0] + zero[1] + zero[2]);
    EXPECT_LT(small[1], top[1]);
    const float* bad = fc.At(3, 0);
    EXPECT_EQ(bad[0], 1.0f);  // magenta marks excluded pixels
    EXPECT_EQ(bad[1], 0.0f);
    EXPECT_EQ(bad[2], 1.0f);
}

TEST(ErrorMetrics, LargeImageIsFastEnough) {
    // 1920x1080: the brief asks for well under a second. Generous bound for loaded or sanitizer
    // builds; the point is to catch an accidental O(window^2) or per-pixel allocation.
    const Image ref = Pattern(1920, 1080), test = AddNoise(ref, 0.05f, 4);
    const auto t0 = std::chrono::steady_clock::now();
    const ImageErrors e = CompareImages(test, ref);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_TRUE(std::isfinite(e.ssim));
    EXPECT_LT(s, 10.0);
    RecordProperty("compare_seconds", std::to_string(s));
}

TEST(Metrics, IdenticalImages) {
    const Image a = Ramp(32, 20);
    const ImageErrors e = CompareImages(a, a);
    EXPECT_EQ(e.relMSE, 0.0);
    EXPECT_EQ(e.rmse, 0.0);
    EXPECT_TRUE(std::isinf(e.psnr));
    EXPECT_NEAR(e.ssim, 1.0, 1e-12);
}

TEST(Metrics, KnownAnswers) {
    // 2x1 image, reference grey 0.5 and 0.0, test offset by 0.1 in every channel.
    Image ref(2, 1, 3), test(2, 1, 3);
    for (int k = 0; k < 3; ++k) ref.At(0, 0)[k] = 0.5f, ref.At(1, 0)[k] = 0.0f;
    for (int k = 0; k < 3; ++k) test.At(0, 0)[k] = 0.6f, test.At(1, 0)[k] = 0.1f;
    // relMSE = mean over pixels of sum_c d^2 / (gray^2 + 1e-3)
    const double expected = 0.5 * (3 * 0.01 / (0.25 + 1e-3) + 3 * 0.01 / (0.0 + 1e-3));
    EXPECT_NEAR(RelMSE(test, ref), expected, 1e-6 * expected);  // float inputs: 1e-6 relative
    EXPECT_NEAR(RMSE(test, ref), 0.1, 1e-6);
    EXPECT_NEAR(PSNR(test, ref), 20.0, 1e-4);
}

TEST(Metrics, SsimOfNoisyImageIsBetweenZeroAndOneAndSymmetric) {
    const Image a = Ramp(64, 48);
    Image b = a;
    std::mt19937 gen(1);
    std::normal_distribution<float> n(0.0f, 0.05f);
    for (float& v : b.data) v += n(gen);
    const double s = SSIM(a, b);
    EXPECT_GT(s, 0.0);
    EXPECT_LT(s, 0.99);
    EXPECT_NEAR(s, SSIM(b, a), 1e-12);
}

TEST(Metrics, MismatchAndNonFinite) {
    EXPECT_THROW(CompareImages(Image(4, 4, 3), Image(4, 5, 3)), InputError);
    Image a = Ramp(8, 8), b = Ramp(8, 8);
    a.At(2, 2)[1] = NAN;
    a.At(3, 3)[0] = INFINITY;
    const ImageErrors e = CompareImages(a, b);
    EXPECT_EQ(e.nonFinite, 2u);
    EXPECT_EQ(e.relMSE, 0.0);  // excluded, not propagated
    EXPECT_TRUE(std::isfinite(e.ssim));
    const Image fc = FalseColorError(a, b);
    EXPECT_EQ(fc.At(2, 2)[1], 0.0f);  // magenta marks non-finite pixels
}

}  // namespace
}  // namespace texcache
