// SPDX-License-Identifier: Apache-2.0
// `texcache montage A B ... -o out.png`: images of the same height side by side, left to right,
// `--gap` black columns apart (scripts/demo.sh's per-hit | texture-space picture).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "cli_util.h"
#include "commands.h"
#include "renderer/image/image.h"
#include "renderer/render_policy.h"
#include "texcache/error.h"

namespace texcache::cli {

namespace {

struct MontageArgs {
    std::vector<std::string> inputs;
    std::string output;
    int gap = 4;
    float exposure = 0.0f;
    bool exposureGiven = false;  ///< --exposure on the command line
};

int RunMontage(const MontageArgs& a) {
    CheckImageOutputPath(a.output);  // a bad name fails before anything is read
    const int gap = CheckRange("--gap", a.gap, 0, 4096);
    const float exposure = CheckRange("--exposure", a.exposure, -32.0f, 32.0f);
    if (a.exposureGiven && std::filesystem::path(a.output).extension() != ".png")
        throw InputError("--exposure",
                         "sets a PNG output's exposure, and '" + a.output + "' is not a PNG");
    // The output may not overwrite an input (it is written after all are read, but a failed
    // montage must leave the inputs as they were, and a good one keep them).
    FileSet files;
    for (const std::string& path : a.inputs) files.Input(path, "an input image");
    files.Output(a.output, "--output");
    files.Check();
    // Every input as float RGB, the montage as large again and its 8-bit copy: a size check on
    // the headers refuses what would not fit before anything is decoded.
    uint64_t pixels = 0;
    for (const std::string& path : a.inputs) pixels += ImagePixelsClaimed(path);
    CheckMemoryBudget(32.0 + double(pixels) * 40.0 / double(1 << 20), MemoryBudgetMiB(0.0),
                      "a montage of " + std::to_string(pixels) + " pixels", a.output);
    std::vector<Image> images;
    for (const std::string& path : a.inputs) {
        images.push_back(ReadImageRGB(path));
        const Image& img = images.back();
        if (img.height != images.front().height)
            throw InputError(path, "height " + std::to_string(img.height) + " differs from " +
                                       a.inputs.front() + "'s (" +
                                       std::to_string(images.front().height) + ")");
    }
    std::vector<const Image*> row;
    for (const Image& img : images) row.push_back(&img);
    const Image out = Montage({row}, gap);
    WriteImage(a.output, out, {}, exposure);
    std::printf("wrote %s (%dx%d)\n", a.output.c_str(), out.width, out.height);
    return 0;
}

}  // namespace

void AddMontageCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<MontageArgs>();
    CLI::App* cmd = app.add_subcommand(
        "montage", "Images of the same height side by side, left to right, into one image");
    cmd->add_option("images", args->inputs, "Images (any format OpenImageIO reads), left first")
        ->required()
        ->expected(1, -1);
    cmd->add_option("-o,--output", args->output, "Output image (.png, .exr, ...)")->required();
    cmd->add_option("--gap", args->gap, "Black columns between images")->capture_default_str();
    cmd->add_option("--exposure", args->exposure, "Exposure in stops for a PNG output")
        ->capture_default_str();
    cmd->callback([args, cmd, &exitCode] {
        args->exposureGiven = cmd->count("--exposure") > 0;
        exitCode = RunMontage(*args);
    });
}

}  // namespace texcache::cli
