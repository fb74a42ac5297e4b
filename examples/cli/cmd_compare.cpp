// SPDX-License-Identifier: Apache-2.0
// `texcache compare test.exr ref.exr`: relMSE (eps = 0.001), RMSE, PSNR, SSIM.
#include <cstdio>
#include <memory>

#include "cli_util.h"
#include "commands.h"
#include "renderer/metrics.h"

namespace texcache::cli {

namespace {

struct CompareArgs {
    std::string test, ref, errorImage;
    bool json = false;
};

int RunCompare(const CompareArgs& a) {
    const Image test = ReadImageRGB(a.test);
    const Image ref = ReadImageRGB(a.ref);
    if (test.width != ref.width || test.height != ref.height)
        throw InputError(a.test, "size " + std::to_string(test.width) + "x" +
                                     std::to_string(test.height) + " differs from the reference " +
                                     a.ref + " (" + std::to_string(ref.width) + "x" +
                                     std::to_string(ref.height) + ")");
    if (!a.errorImage.empty()) PlanOutputs(a.errorImage, false);  // check before the work
    const ImageErrors e = CompareImages(test, ref);
    if (a.json) {
        std::printf(
            "{\"relmse\": %.8g, \"rmse\": %.8g, \"psnr\": %.8g, \"ssim\": %.8g, \"nonfinite\": "
            "%zu}\n",
            e.relMSE, e.rmse, std::isinf(e.psnr) ? 1e300 : e.psnr, e.ssim, e.nonFinite);
    } else {
        std::printf("relMSE: %.6g  (eps = 0.001)\n", e.relMSE);
        std::printf("RMSE:   %.6g\n", e.rmse);
        std::printf("PSNR:   %.3f dB\n", e.psnr);
        std::printf("SSIM:   %.5f\n", e.ssim);
        if (e.nonFinite) std::printf("non-finite test pixels (excluded): %zu\n", e.nonFinite);
    }
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
        "compare", "Error of an image against a reference (relMSE, RMSE, PSNR, SSIM)");
    cmd->add_option("test", args->test, "Image to evaluate")->required();
    cmd->add_option("reference", args->ref, "Reference image (high sample count)")->required();
    cmd->add_option("--error-image", args->errorImage,
                    "Write a false-colour per-pixel relMSE image (.png or .exr)");
    cmd->add_flag("--json", args->json, "Print one JSON object");
    cmd->callback([args, &exitCode] { exitCode = RunCompare(*args); });
}

}  // namespace texcache::cli
