// SPDX-License-Identifier: Apache-2.0
// `texcache ptex info FILE`: the project's ptxinfo. Header, border modes, meta data, levels and,
// per face, resolution, adjacency, constant flag and the mean of its decoded texels; `--face N
// -o out.exr` writes a face's texels as an image.
#include <cstdio>
#include <memory>
#include <string>

#include "cli_util.h"
#include "commands.h"
#include "renderer/image/image.h"
#include "texcache/error.h"
#include "texcache/ptex/info.h"
#include "texcache/ptex/texture.h"

namespace texcache::cli {

namespace {

struct PtexInfoArgs {
    std::string file, output;
    bool json = false, faces = false;
    int face = -1, level = 0;
};

/// A face's texels as an image whose bottom row is v = 0 (the way uv images are laid out, and
/// the way the face lies in its (u,v) frame).
Image FaceAsImage(const ptex::FloatImage& f) {
    Image img(f.width, f.height, f.channels);
    for (int t = 0; t < f.height; ++t)
        for (int s = 0; s < f.width; ++s)
            for (int c = 0; c < f.channels; ++c)
                img.At(s, f.height - 1 - t)[c] =
                    f.pixels[(size_t(t) * size_t(f.width) + size_t(s)) * size_t(f.channels) +
                             size_t(c)];
    return img;
}

int RunPtexInfo(const PtexInfoArgs& a) {
    if (a.face >= 0 && a.output.empty())
        throw InputError("--face", "needs -o FILE, the image to write the face's texels to");
    if (a.face < 0 && !a.output.empty())
        throw InputError("-o", "needs --face N, the face whose texels to write");
    if (a.face < 0 && a.level != 0)
        throw InputError("--level", "needs --face N (a level of the face written with -o)");
    if (!a.output.empty()) {
        CheckImageOutputPath(a.output);
        FileSet files;
        files.Input(a.file, "the Ptex file");
        files.Output(a.output, "-o");
        files.Check();
    }
    const ptex::Texture tex = ptex::Texture::Open(a.file);
    if (!a.output.empty()) {
        // Checked before anything is written: a face or level the file lacks names the file.
        const ptex::FloatImage face = ptex::FaceImage(tex, a.face, a.level);
        WriteImage(a.output, FaceAsImage(face));
        std::printf("wrote %s (face %d, level %d: %dx%d texels, %d channels)\n", a.output.c_str(),
                    a.face, a.level, face.width, face.height, face.channels);
        return 0;
    }
    const ptex::Info info = ptex::Summarize(tex);
    const std::string text = a.json ? ptex::ToJson(info) + "\n" : ptex::ToText(info, a.faces);
    std::fwrite(text.data(), 1, text.size(), stdout);
    return 0;
}

}  // namespace

void AddPtexCommand(CLI::App& app, int& exitCode) {
    CLI::App* ptex = app.add_subcommand("ptex", "Ptex (.ptx) textures");
    ptex->require_subcommand(1);
    auto args = std::make_shared<PtexInfoArgs>();
    CLI::App* info = ptex->add_subcommand(
        "info",
        "What a Ptex file holds (the project's ptxinfo): header, border modes, meta data, levels; "
        "per face its resolution, adjacency, constant flag and the mean of its decoded texels. A "
        "file that is not a valid Ptex file exits with code 2 and one line naming it.");
    info->add_option("file", args->file, "Ptex file (.ptx)")->required();
    info->add_flag("--json", args->json,
                   "Print everything as one JSON object, every face included with the 'mean' of "
                   "its level-0 texels");
    info->add_flag("--faces", args->faces, "Also print one line per face (text output)");
    info->add_option("--face", args->face,
                     "Write this face's texels to the image -o names instead of printing")
        ->check(CLI::NonNegativeNumber);
    info->add_option("--level", args->level, "Mip level of --face (0: full resolution)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    info->add_option("-o,--output", args->output,
                     "Image for --face (.exr: the stored values as float, v = 0 at the bottom; "
                     ".png: tone-mapped)");
    info->callback([args, &exitCode] { exitCode = RunPtexInfo(*args); });
}

}  // namespace texcache::cli
