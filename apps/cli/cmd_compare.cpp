// SPDX-License-Identifier: Apache-2.0
// `texcache compare test.exr ref.exr`: relMSE (eps = 0.001), RMSE, PSNR, SSIM, non-finite pixels.
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "cli_util.h"
#include "commands.h"
#include "renderer/image/image.h"
#include "renderer/image/metrics.h"
#include "renderer/render_policy.h"
#include "texcache/error.h"

namespace texcache::cli {

namespace {

struct CompareArgs {
    std::string test, ref, errorImage;
    bool json = false;
};

// JSON has no infinity: PSNR of identical images is written as null.
std::string JsonNumber(double v) {
    if (!std::isfinite(v)) return "null";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.9g", v);
    return buf;
}

/// "a.png" -> "sRGB-encoded", for the note on mixed encodings.
const char* EncodingName(ColorEncoding e) {
    return e == ColorEncoding::Srgb ? "sRGB-encoded" : "linear";
}

int RunCompare(const CompareArgs& a) {
    // Reject a bad or dangerous error-image name (an input, an unwritable place) before reading.
    if (!a.errorImage.empty()) {
        CheckImageOutputPath(a.errorImage);
        FileSet files;
        files.Input(a.test, "the test image");
        files.Input(a.ref, "the reference image");
        files.Output(a.errorImage, "--error-image");
        files.Check();
    }
    // Both images as float RGB, the error image and the metrics' buffers: a size check on the
    // headers refuses what would not fit before anything is decoded.
    const uint64_t pixels = ImagePixelsClaimed(a.test) + ImagePixelsClaimed(a.ref);
    CheckMemoryBudget(32.0 + double(pixels) * 40.0 / double(1 << 20), MemoryBudgetMiB(0.0),
                      "comparing " + std::to_string(pixels) + " pixels", a.test);
    ColorEncoding testEnc, refEnc;
    Image test = ReadImageRGB(a.test, &testEnc);
    Image ref = ReadImageRGB(a.ref, &refEnc);
    // A PNG holds display values (sRGB OETF), an EXR linear light: comparing them as they are
    // would measure the encoding. The sRGB one is decoded to linear and the user told so (its
    // values were clipped to [0, 1] and quantized when it was written, which stays in the error),
    // once the comparison has succeeded: a refusal stays one line.
    const bool mixed = testEnc != refEnc, testSrgb = testEnc == ColorEncoding::Srgb;
    if (mixed) SrgbToLinear(testSrgb ? &test : &ref);
    if (test.width != ref.width || test.height != ref.height)
        throw InputError(a.test, "size " + std::to_string(test.width) + "x" +
                                     std::to_string(test.height) + " differs from the reference " +
                                     a.ref + " (" + std::to_string(ref.width) + "x" +
                                     std::to_string(ref.height) + ")");
    ImageErrors e;
    try {
        e = CompareImages(test, ref);
    } catch (const InputError& err) {  // name the files, not just "compare"
        throw InputError(a.test + " vs " + a.ref, err.what());
    }
    if (mixed)
        std::fprintf(stderr,
                     "texcache: note: %s is %s and %s %s: %s decoded to linear light for the "
                     "comparison\n",
                     a.test.c_str(), EncodingName(testEnc), a.ref.c_str(), EncodingName(refEnc),
                     testSrgb ? a.test.c_str() : a.ref.c_str());
    if (a.json) {
        std::printf(
            "{\"relmse\": %s, \"rmse\": %s, \"psnr\": %s, \"ssim\": %s, \"nonfinite\": %zu, "
            "\"width\": %d, \"height\": %d}\n",
            JsonNumber(e.relMSE).c_str(), JsonNumber(e.rmse).c_str(), JsonNumber(e.psnr).c_str(),
            JsonNumber(e.ssim).c_str(), e.nonFinite, test.width, test.height);
    } else {
        std::printf("relMSE:    %.6g  (eps = 0.001)\n", e.relMSE);
        std::printf("RMSE:      %.6g\n", e.rmse);
        if (std::isinf(e.psnr))
            std::printf("PSNR:      inf dB  (identical)\n");
        else
            std::printf("PSNR:      %.3f dB\n", e.psnr);
        std::printf("SSIM:      %.5f\n", e.ssim);
        std::printf("nonfinite: %zu  (pixels with NaN/Inf, excluded from the metrics)\n",
                    e.nonFinite);
    }
    std::fflush(stdout);  // the numbers are out even if writing the error image fails
    if (!a.errorImage.empty()) {
        WriteImage(a.errorImage, FalseColorError(test, ref));
        if (!a.json) std::printf("wrote %s\n", a.errorImage.c_str());
    }
    return 0;
}

}  // namespace

void AddCompareCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<CompareArgs>();
    CLI::App* cmd = app.add_subcommand(
        "compare",
        "Error of an image against a reference: relMSE (eps = 0.001, Munkberg et al. 2016), RMSE, "
        "PSNR (peak 1), SSIM (of the sRGB-encoded luma). Pixels with NaN/Inf are counted and "
        "excluded. Images are compared in the values they store; when one is sRGB-encoded (PNG) "
        "and the other linear (EXR), the sRGB one is decoded to linear first, with a note.");
    cmd->add_option("test", args->test, "Image to evaluate (any format OpenImageIO reads)")
        ->required();
    cmd->add_option("reference", args->ref, "Reference image of the same size (high sample count)")
        ->required();
    cmd->add_option("--error-image", args->errorImage,
                    "Also write a false-colour per-pixel relMSE image (log scale 1e-4..10, "
                    "inferno; NaN/Inf magenta) to this .png or .exr");
    cmd->add_flag("--json", args->json,
                  "Print one JSON object {relmse, rmse, psnr, ssim, nonfinite, width, height} "
                  "instead (psnr is null for identical images)");
    cmd->callback([args, &exitCode] { exitCode = RunCompare(*args); });
}

}  // namespace texcache::cli
