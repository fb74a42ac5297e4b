// SPDX-License-Identifier: Apache-2.0
// Image files (EXR round trip with layers, sRGB PNG, atomic writes) and error metrics with known
// answers.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "renderer/image/image.h"
#include "renderer/image/metrics.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

std::string Temp(const std::string& name) {
    const fs::path dir = fs::path(::testing::TempDir()) / "texcache_images";
    fs::create_directories(dir);
    return (dir / name).string();
}

Image Ramp(int w, int h) {
    Image img(w, h, 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int k = 0; k < 3; ++k) img.At(x, y)[k] = float(x + 2 * y + k) / float(w + 2 * h);
    return img;
}

TEST(ImageIO, ExrRoundTripsExactlyWithLayers) {
    const Image a = Ramp(17, 9);
    ImageLayer depth{"depth", Image(17, 9, 1, 3.5f), {"Z"}};
    const std::string path = Temp("roundtrip.exr");
    WriteImage(path, a, {depth});
    const Image b = ReadImageRGB(path);
    ASSERT_EQ(b.width, 17);
    ASSERT_EQ(b.height, 9);
    EXPECT_EQ(a.data, b.data);  // 32-bit float EXR is lossless
    const Image all = ReadImage(path);
    ASSERT_EQ(all.channels, 4);
    EXPECT_EQ(all.At(3, 4)[3], 3.5f);
}

TEST(ImageIO, PngIsSrgbEncodedAndSurvivesNaN) {
    EXPECT_EQ(LinearToSrgb8(0.0f), 0);
    EXPECT_EQ(LinearToSrgb8(1.0f), 255);
    EXPECT_EQ(LinearToSrgb8(0.5f), 188);  // the sRGB OETF, not linear 128
    EXPECT_EQ(LinearToSrgb8(NAN), 0);
    EXPECT_EQ(LinearToSrgb8(INFINITY), 255);
    Image img(4, 2, 3, 0.5f);
    img.At(1, 1)[0] = NAN;
    const std::string path = Temp("nan.png");
    WriteImage(path, img);
    const Image back = ReadImageRGB(path);
    EXPECT_NEAR(back.At(0, 0)[0], 188.0f / 255.0f, 1e-6f);
    EXPECT_EQ(back.At(1, 1)[0], 0.0f);
}

TEST(ImageIO, FailedWritesNeverClobberAGoodFile) {
    const std::string path = Temp("good.png");
    WriteImage(path, Image(2, 2, 3, 0.25f));
    const auto before = fs::file_size(path);
    EXPECT_THROW(WriteImage(path, Image()), InputError);                        // empty image
    EXPECT_THROW(WriteImage(Temp("nodir/x.exr"), Image(2, 2, 3)), InputError);  // missing dir
    EXPECT_THROW(WriteImage(Temp("x.bmpx"), Image(2, 2, 3)), InputError);       // unknown type
    EXPECT_EQ(fs::file_size(path), before);
    for (const auto& e : fs::directory_iterator(fs::path(path).parent_path()))
        EXPECT_EQ(e.path().string().find(".tmp-"), std::string::npos) << "temporary file left";
}

TEST(ImageIO, UnreadableFilesNameThePath) {
    const std::string garbage = Temp("garbage.exr");
    std::ofstream(garbage) << "not an image";
    for (const std::string& p : {garbage, Temp("missing.exr")}) {
        try {
            ReadImageRGB(p);
            FAIL() << p;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
        }
    }
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
