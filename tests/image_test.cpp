// SPDX-License-Identifier: Apache-2.0
// Image files: exact EXR round trips with AOV layers, the sRGB PNG encode, PFM/HDR, atomic writes
// that never clobber a good file, and read errors that name the file or path.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include "renderer/image/atomic_files.h"
#include "renderer/image/image.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

using test::Ramp;

namespace fs = std::filesystem;

// A fresh directory per test, so leftover-file checks see only that test's files.
fs::path TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    const fs::path dir = fs::path(::testing::TempDir()) / "texcache_image_test" /
                         (std::string(info->test_suite_name()) + "." + info->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

std::string Slurp(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
}

// No "<name>.tmp-<pid>" file may survive a write, failed or not.
void ExpectNoTemporaries(const fs::path& dir) {
    for (const auto& e : fs::directory_iterator(dir))
        EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos)
            << "temporary file left: " << e.path();
}

// Values a lossy path would change: negatives, denormals, > 1, non-dyadic fractions.
Image Awkward(int w, int h, int c) {
    Image img(w, h, c);
    for (size_t i = 0; i < img.data.size(); ++i)
        img.data[i] = float(double(i) / 3.0 - 7.0) * (i % 5 == 0 ? 1e-3f : 1.0f);
    img.data[1] = std::numeric_limits<float>::denorm_min();
    img.data[2] = 65504.5f;  // not representable as half: catches a half-float writer
    return img;
}

bool BitIdentical(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

TEST(ImageFiles, ExrRoundTripIsBitExactWithLayers) {
    const int w = 13, h = 7;
    const Image beauty = Awkward(w, h, 3);
    const Image albedo = Awkward(w, h, 3);
    Image depth(w, h, 1);
    for (size_t i = 0; i < depth.data.size(); ++i) depth.data[i] = 100.0f + float(i);
    depth.data[0] = std::numeric_limits<float>::infinity();  // a background miss
    const std::string path = (TempDir() / "layers.exr").string();
    WriteImage(path, beauty, {{"albedo", albedo, {"R", "G", "B"}}, {"depth", depth, {"Z"}}});

    const Image rgb = ReadImageRGB(path);
    ASSERT_EQ(rgb.width, w);
    ASSERT_EQ(rgb.height, h);
    ASSERT_EQ(rgb.channels, 3);
    EXPECT_TRUE(BitIdentical(rgb.data, beauty.data));  // 32-bit float + zip: lossless

    // The beauty comes first on reading, then the layers in the order written.
    const Image all = ReadImage(path);
    ASSERT_EQ(all.channels, 7);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            for (int k = 0; k < 3; ++k) {
                ASSERT_EQ(all.At(x, y)[k], beauty.At(x, y)[k]) << x << "," << y;
                ASSERT_EQ(all.At(x, y)[3 + k], albedo.At(x, y)[k]) << x << "," << y;
            }
            ASSERT_EQ(all.At(x, y)[6], depth.At(x, y)[0]) << x << "," << y;
        }
}

TEST(ImageFiles, ExrKeepsAlphaAndRowOrder) {
    Image img(3, 2, 4);
    for (int y = 0; y < 2; ++y)
        for (int x = 0; x < 3; ++x)
            for (int k = 0; k < 4; ++k) img.At(x, y)[k] = float(10 * y + x) + 0.25f * float(k);
    const std::string path = (TempDir() / "rgba.exr").string();
    WriteImage(path, img);
    const Image back = ReadImage(path);
    ASSERT_EQ(back.channels, 4);
    EXPECT_TRUE(BitIdentical(back.data, img.data));  // row 0 stays the top row
    const Image rgb = ReadImageRGB(path);
    EXPECT_EQ(rgb.channels, 3);
    EXPECT_EQ(rgb.At(2, 1)[2], img.At(2, 1)[2]);
}

TEST(ImageFiles, SrgbEncodeMatchesTheOetf) {
    EXPECT_EQ(LinearToSrgb8(0.0f), 0);
    EXPECT_EQ(LinearToSrgb8(1.0f), 255);
    EXPECT_EQ(LinearToSrgb8(0.5f), 188);       // the sRGB OETF; a linear quantizer would give 128
    EXPECT_EQ(LinearToSrgb8(0.0031308f), 10);  // end of the linear segment: 12.92 * x * 255
    EXPECT_EQ(LinearToSrgb8(-1.0f), 0);
    EXPECT_EQ(LinearToSrgb8(7.0f), 255);
    EXPECT_EQ(LinearToSrgb8(std::numeric_limits<float>::quiet_NaN()), 0);
    EXPECT_EQ(LinearToSrgb8(std::numeric_limits<float>::infinity()), 255);
    EXPECT_EQ(LinearToSrgb8(-std::numeric_limits<float>::infinity()), 0);
    // Every code survives decode -> encode (the encode is the exact inverse of the sRGB EOTF).
    for (int code = 0; code < 256; ++code) {
        const double s = code / 255.0;
        const double lin = s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
        EXPECT_EQ(LinearToSrgb8(float(lin)), code) << code;
    }
}

TEST(ImageFiles, PngIsSrgbEncodedWithExposureAndSurvivesNonFinite) {
    Image img(4, 2, 3, 0.5f);
    img.At(1, 0)[0] = std::numeric_limits<float>::quiet_NaN();
    img.At(2, 0)[1] = std::numeric_limits<float>::infinity();
    img.At(3, 0)[2] = -std::numeric_limits<float>::infinity();
    img.At(0, 1)[0] = 0.0f;
    img.At(1, 1)[0] = 1.0f;
    const fs::path dir = TempDir();
    const std::string path = (dir / "nan.png").string();
    WriteImage(path, img);
    const Image back = ReadImageRGB(path);  // 8-bit codes come back as code / 255
    ASSERT_EQ(back.width, 4);
    ASSERT_EQ(back.height, 2);
    auto code = [&](int x, int y, int k) { return int(std::lround(back.At(x, y)[k] * 255.0f)); };
    EXPECT_EQ(code(0, 0, 0), 188);
    EXPECT_EQ(code(1, 0, 0), 0);    // NaN -> 0
    EXPECT_EQ(code(2, 0, 1), 255);  // +inf -> 255
    EXPECT_EQ(code(3, 0, 2), 0);    // -inf -> 0
    EXPECT_EQ(code(0, 1, 0), 0);
    EXPECT_EQ(code(1, 1, 0), 255);

    // Exposure is in stops: 0.25 at +1 stop shows as 0.5 does at 0.
    const std::string bright = (dir / "bright.png").string();
    WriteImage(bright, Image(2, 2, 3, 0.25f), {}, 1.0f);
    EXPECT_EQ(int(std::lround(ReadImageRGB(bright).At(1, 1)[2] * 255.0f)), 188);

    // One channel is written as grey and read back replicated to RGB.
    const std::string grey = (dir / "grey.png").string();
    WriteImage(grey, Image(3, 3, 1, 0.5f));
    const Image g = ReadImageRGB(grey);
    ASSERT_EQ(g.channels, 3);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(int(std::lround(g.At(2, 2)[k] * 255.0f)), 188);
    ExpectNoTemporaries(dir);
}

// The PNG beside every render's EXR is written with libpng: writing it loads none of
// OpenImageIO's libraries (~0.3 s of CPU per process; renderer/image/image_file.h). CTest runs each
// test in a process of its own, so nothing else here has loaded them.
TEST(ImageFiles, WritingAPngLoadsNoOpenImageIO) {
    const fs::path dir = TempDir();
    WriteImage((dir / "plain.png").string(), Image(8, 4, 3, 0.5f));
    ASSERT_TRUE(fs::exists(dir / "plain.png"));
    std::ifstream maps("/proc/self/maps");
    std::string line;
    int mapped = 0;
    while (std::getline(maps, line)) mapped += line.find("OpenImageIO") != std::string::npos;
    EXPECT_EQ(mapped, 0);
}

TEST(ImageFiles, HdrIsClose) {
    const fs::path dir = TempDir();
    Image img(5, 3, 3);
    for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = 0.1f + 0.37f * float(i);
    img.At(4, 0)[0] = 0.0f;  // row 0 must stay on top: one distinctive pixel
    const std::string hdr = (dir / "a.hdr").string();
    WriteImage(hdr, img);
    const Image back = ReadImageRGB(hdr);
    ASSERT_EQ(back.width, 5);
    ASSERT_EQ(back.height, 3);
    for (size_t i = 0; i < img.data.size(); ++i)  // RGBE: 8-bit mantissas, shared exponent
        EXPECT_NEAR(back.data[i], img.data[i], 0.01f * img.data[i] + 0.02f) << i;
    EXPECT_EQ(back.At(4, 0)[0], 0.0f);
    ExpectNoTemporaries(dir);
}

TEST(ImageFiles, FailedWritesNeverTouchAGoodFile) {
    const fs::path dir = TempDir();
    const fs::path good = dir / "good.exr";
    WriteImage(good.string(), Image(4, 4, 3, 0.25f));
    const std::string before = Slurp(good);
    ASSERT_FALSE(before.empty());

    // Each bad call is rejected before the temporary file is created.
    EXPECT_THROW(WriteImage(good.string(), Image()), InputError);  // 0x0
    Image inconsistent(4, 4, 3);
    inconsistent.data.resize(5);
    EXPECT_THROW(WriteImage(good.string(), inconsistent), InputError);
    EXPECT_THROW(
        WriteImage(good.string(), Image(4, 4, 3), {{"albedo", Image(2, 2, 3), {"R", "G", "B"}}}),
        InputError);  // layer of another size
    EXPECT_THROW(WriteImage(good.string(), Image(4, 4, 3), {{"albedo", Image(4, 4, 3), {"R"}}}),
                 InputError);  // channel names do not match the channels
    EXPECT_EQ(Slurp(good), before);

    // A good write replaces it (through the temporary file) and leaves nothing behind.
    WriteImage(good.string(), Image(4, 4, 3, 0.75f));
    EXPECT_EQ(ReadImageRGB(good.string()).At(3, 3)[0], 0.75f);
    ExpectNoTemporaries(dir);
}

TEST(ImageFiles, FailureAfterWritingTheTemporaryCleansUp) {
    // The rename itself fails when the target is a non-empty directory: the complete temporary
    // file must be removed and the directory (the "existing output") left alone.
    const fs::path dir = TempDir();
    const fs::path target = dir / "out.png";
    fs::create_directories(target / "keep");
    try {
        WriteImage(target.string(), Image(2, 2, 3, 0.5f));
        FAIL() << "writing over a directory succeeded";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(target.string()), std::string::npos) << e.what();
    }
    EXPECT_TRUE(fs::is_directory(target / "keep"));
    ExpectNoTemporaries(dir);
}

TEST(ImageFiles, BadOutputPathsNameThePath) {
    const fs::path dir = TempDir();
    const std::string missingDir = (dir / "no" / "such" / "x.exr").string();
    try {
        WriteImage(missingDir, Image(2, 2, 3));
        FAIL();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(missingDir), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(dir / "no"));
    EXPECT_THROW(CheckImageOutputPath(missingDir), InputError);

    const std::string unknown = (dir / "x.bmpx").string();
    try {
        WriteImage(unknown, Image(2, 2, 3));
        FAIL();
    } catch (const InputError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(unknown), std::string::npos) << msg;
        EXPECT_NE(msg.find(".exr"), std::string::npos) << msg;  // lists what is supported
        EXPECT_NE(msg.find(".png"), std::string::npos) << msg;
    }
    EXPECT_THROW(CheckImageOutputPath(unknown), InputError);
    EXPECT_NO_THROW(CheckImageOutputPath((dir / "fine.PNG").string()));  // case-insensitive
    ExpectNoTemporaries(dir);
}

TEST(ImageFiles, UnreadableFilesNameThePath) {
    const fs::path dir = TempDir();
    const std::string garbage = (dir / "garbage.exr").string();
    std::ofstream(garbage) << "not an image at all";
    const std::string empty = (dir / "empty.png").string();  // zero bytes
    std::ofstream{empty};
    // An EXR cut in half: the header parses, the pixels do not. (Not a PNG: OIIO 2.4's PNG reader
    // leaks a string when libpng longjmps out of a truncated file, which fails ASan runs.)
    const std::string truncated = (dir / "truncated.exr").string();
    {
        Image noisy(64, 64, 3);
        for (size_t i = 0; i < noisy.data.size(); ++i) noisy.data[i] = float((i * 7919) % 256);
        WriteImage(truncated, noisy);
        const std::string bytes = Slurp(truncated);
        std::ofstream(truncated, std::ios::binary | std::ios::trunc)
            .write(bytes.data(), std::streamsize(bytes.size() / 2));
    }
    const std::string missing = (dir / "missing.exr").string();
    for (const std::string& p : {garbage, empty, truncated, missing, dir.string()}) {
        try {
            ReadImageRGB(p);
            FAIL() << "read " << p;
        } catch (const InputError& e) {
            const std::string msg = e.what();
            EXPECT_NE(msg.find(p), std::string::npos) << msg;
            EXPECT_NE(msg.find("cannot read image"), std::string::npos) << msg;
        }
    }
}

// Files written as a group appear together or not at all: nothing is renamed before Commit(), a
// group abandoned on the way (an exception) leaves every target as it was and no temporary.
TEST(ImageFiles, GroupsOfFilesAreReplacedTogetherOrNotAtAll) {
    const fs::path dir = TempDir();
    const fs::path exr = dir / "a.exr", png = dir / "a.png";
    WriteImage(exr.string(), Image(4, 4, 3, 0.25f));
    WriteImage(png.string(), Image(4, 4, 3, 0.25f));
    const std::string exrBefore = Slurp(exr), pngBefore = Slurp(png);
    try {
        AtomicFiles group;
        WriteImage(exr.string(), Image(4, 4, 3, 0.75f), {}, 0.0f, &group);
        EXPECT_EQ(Slurp(exr), exrBefore);                     // staged, not renamed
        WriteImage(png.string(), Image(), {}, 0.0f, &group);  // fails: empty image
        FAIL() << "an empty image was written";
    } catch (const InputError&) {
    }
    EXPECT_EQ(Slurp(exr), exrBefore);
    EXPECT_EQ(Slurp(png), pngBefore);
    ExpectNoTemporaries(dir);

    AtomicFiles group;
    WriteImage(exr.string(), Image(4, 4, 3, 0.75f), {}, 0.0f, &group);
    WriteImage(png.string(), Image(4, 4, 3, 0.75f), {}, 0.0f, &group);
    group.Commit();
    EXPECT_EQ(ReadImageRGB(exr.string()).At(0, 0)[0], 0.75f);
    EXPECT_NE(Slurp(png), pngBefore);
    ExpectNoTemporaries(dir);
}

// A header may claim any size: a small file claiming 46340x46340 pixels is rejected before any
// allocation (it ended in bad_alloc), naming the file; honest files of any compression pass.
TEST(ImageFiles, HeaderSizeClaimsAreCheckedBeforeAllocating) {
    const fs::path dir = TempDir();
    const std::string liar = (dir / "liar.exr").string();
    WriteImage(liar, Image(64, 64, 1, 0.5f));
    test::ClaimExrSize(liar, 46340, 46340);
    for (const auto read : {+[](const std::string& p) { ReadImageRGB(p); },
                            +[](const std::string& p) { ReadImage(p); }}) {
        try {
            read(liar);
            FAIL() << "read a file claiming 46340x46340 pixels";
        } catch (const InputError& e) {
            const std::string msg = e.what();
            EXPECT_NE(msg.find(liar), std::string::npos) << msg;
            EXPECT_NE(msg.find("46340x46340"), std::string::npos) << msg;
        }
    }
    // The limits themselves: beyond 16384^2 pixels or 2^30 values always; a constant image
    // compresses well but stays under 4096:1 (the 256 MiB allowance covers small images).
    EXPECT_THROW(CheckImageSizeClaim(liar, 16385, 16384, 1, 0), InputError);
    EXPECT_THROW(CheckImageSizeClaim(liar, 16384, 16384, 5, 0), InputError);
    EXPECT_THROW(CheckImageSizeClaim(liar, 8192, 8192, 3, uint64_t(8192) * 8192 * 12), InputError);
    EXPECT_NO_THROW(CheckImageSizeClaim(liar, 4096, 4096, 4, uint64_t(4096) * 4096 * 16));
    const std::string flat = (dir / "flat.exr").string();
    WriteImage(flat, Image(512, 512, 3, 1.0f));
    EXPECT_EQ(ReadImageRGB(flat).width, 512);
}

// PNG holds sRGB-encoded display values, EXR linear light; ReadImageRGB says which, and
// SrgbToLinear decodes (the inverse of the PNG writer's OETF to within 8-bit quantization).
TEST(ImageFiles, ReadsTellTheColorEncoding) {
    const fs::path dir = TempDir();
    const std::string exr = (dir / "x.exr").string(), png = (dir / "x.png").string();
    Image ramp(16, 1, 3);
    for (int x = 0; x < 16; ++x)
        for (int k = 0; k < 3; ++k) ramp.At(x, 0)[k] = float(x) / 15.0f;
    WriteImage(exr, ramp);
    WriteImage(png, ramp);
    ColorEncoding e = ColorEncoding::Srgb;
    ReadImageRGB(exr, &e);
    EXPECT_EQ(e, ColorEncoding::Linear);
    Image back = ReadImageRGB(png, &e);
    EXPECT_EQ(e, ColorEncoding::Srgb);
    SrgbToLinear(&back);
    for (size_t i = 0; i < back.data.size(); ++i)
        EXPECT_NEAR(back.data[i], ramp.data[i], 0.01f) << i;  // 8-bit steps near 1: < 0.009
}

TEST(ImageFiles, ReadsBundledEnvironmentMap) {
    const std::string path = std::string(TEXCACHE_SOURCE_DIR) + "/scenes/envmaps/studio.exr";
    if (!fs::exists(path)) GTEST_SKIP() << "no " << path;
    const Image env = ReadImage(path);
    EXPECT_GT(env.width, 0);
    EXPECT_EQ(ReadImageRGB(path).channels, 3);
    for (float v : ReadImageRGB(path).data) ASSERT_TRUE(std::isfinite(v));
}

// Files in one directory shared by the ImageIO tests.
std::string Temp(const std::string& name) {
    const fs::path dir = fs::path(::testing::TempDir()) / "texcache_images";
    fs::create_directories(dir);
    return (dir / name).string();
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

}  // namespace
}  // namespace texcache
