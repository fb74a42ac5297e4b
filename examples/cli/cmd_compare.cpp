// SPDX-License-Identifier: Apache-2.0
// `texcache compare test.exr ref.exr`: relMSE (eps = 0.001), RMSE, PSNR, SSIM, non-finite pixels.
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "renderer/image.h"
#include "renderer/metrics.h"
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

int RunCompare(const CompareArgs& a) {
    // Reject a bad error-image name before reading anything.
    if (!a.errorImage.empty()) CheckImageOutputPath(a.errorImage);
    const Image test = ReadImageRGB(a.test);
    const Image ref = ReadImageRGB(a.ref);
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
        "excluded.");
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
