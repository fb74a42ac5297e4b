// SPDX-License-Identifier: Apache-2.0
#include "cli_util.h"

#include <sys/resource.h>

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include "renderer/scene_loader.h"

namespace texcache::cli {

namespace fs = std::filesystem;

void ParseResolution(const std::string& s, int* width, int* height) {
    int w = 0, h = 0;
    char x = 0, extra = 0;
    if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
        throw InputError("--resolution", "expected WxH (e.g. 1280x720), got '" + s + "'");
    *width = CheckRange("--resolution", w, 1, 16384);
    *height = CheckRange("--resolution", h, 1, 16384);
}

static std::string Extension(const std::string& path) {
    std::string e = fs::path(path).extension().string();
    for (char& c : e) c = char(std::tolower(c));
    return e;
}

Scene LoadSceneOrObj(const std::string& path, std::vector<std::string>* warnings) {
    return LoadSceneFile(path, std::string(TEXCACHE_SCENES_DIR) + "/envmaps/studio.exr", warnings);
}

OutputPaths PlanOutputs(const std::string& output, bool pngBesideExr) {
    OutputPaths p;
    const std::string ext = Extension(output);
    if (ext == ".exr") {
        p.exr = output;
        if (pngBesideExr) p.png = fs::path(output).replace_extension(".png").string();
    } else if (ext == ".png") {
        p.png = output;
    } else {
        throw InputError("--output",
                         "unsupported image type '" + ext + "' (expected .exr or .png)");
    }
    const fs::path dir = fs::path(output).parent_path();
    if (!dir.empty() && !fs::is_directory(dir))
        throw InputError("--output", "directory '" + dir.string() + "' does not exist");
    return p;
}

void WriteOutputs(OutputPaths& out, const Image& beauty, const std::vector<ImageLayer>& layers,
                  float exposure) {
    if (!out.exr.empty()) {
        WriteImage(out.exr, beauty, layers);
        out.written.push_back(out.exr);
    }
    if (!out.png.empty()) {
        WriteImage(out.png, beauty, {}, exposure);
        out.written.push_back(out.png);
    }
}

void WriteTextAtomic(const std::string& path, const std::string& text) {
    const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
    {
        std::ofstream f(tmp, std::ios::binary);
        if (!f || !(f << text) || !f.flush()) {
            std::error_code ec;
            fs::remove(tmp, ec);
            throw InputError(path, "cannot write file");
        }
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        throw InputError(path, "cannot write file: " + ec.message());
    }
}

double NowSeconds() {
    using namespace std::chrono;
    return duration<double>(steady_clock::now().time_since_epoch()).count();
}

double PeakMemoryMiB() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

}  // namespace texcache::cli
