// SPDX-License-Identifier: Apache-2.0
#include "cli_util.h"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "renderer/scene/scene_loader.h"

namespace texcache::cli {

namespace fs = std::filesystem;

void ParseResolution(const std::string& s, int* width, int* height) {
    // from_chars, not sscanf: "4294967360x64" must not wrap around to 64x64.
    const auto bad = [&] {
        return InputError("--resolution", "expected WxH (e.g. 1280x720), got '" + Excerpt(s) + "'");
    };
    const size_t x = s.find_first_of("xX");
    if (x == std::string::npos) throw bad();
    long long wh[2];
    const std::string_view parts[2] = {std::string_view(s).substr(0, x),
                                       std::string_view(s).substr(x + 1)};
    for (int i = 0; i < 2; ++i) {
        const auto r = std::from_chars(parts[i].data(), parts[i].data() + parts[i].size(), wh[i]);
        if (parts[i].empty() || r.ptr != parts[i].data() + parts[i].size()) throw bad();
        if (r.ec != std::errc() || wh[i] < 1 || wh[i] > 16384)
            throw InputError("--resolution",
                             "'" + Excerpt(s) + "': width and height must be in [1, 16384]");
    }
    *width = int(wh[0]);
    *height = int(wh[1]);
}

static std::string Extension(const std::string& path) {
    std::string e = fs::path(path).extension().string();
    for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
    return e;
}

Scene LoadSceneOrObj(const std::string& path, std::vector<std::string>* warnings) {
    return LoadSceneFile(path, std::string(TEXCACHE_SCENES_DIR) + "/envmaps/studio.exr", warnings);
}

namespace {

/// The identity of a file: device and inode when it exists (hard links and symlinks agree), else
/// its canonical path (existing parents resolved).
std::string FileKey(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0)
        return "inode " + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
    std::error_code ec;
    const fs::path canon = fs::weakly_canonical(fs::absolute(path, ec), ec);
    return "path " + (ec ? fs::path(path).lexically_normal() : canon).string();
}

/// Throws unless a new file can be written in place of `path` (see FileSet).
void CheckWritable(const std::string& path, const std::string& option) {
    const auto fail = [&](const std::string& why) {
        throw InputError(option, "cannot write '" + path + "': " + why);
    };
    std::error_code ec;
    const fs::file_status st = fs::status(path, ec);
    if (fs::is_directory(st)) fail("it is a directory");
    if (fs::exists(st) && !fs::is_regular_file(st)) fail("it is not a regular file");
    const fs::path parent = fs::path(path).parent_path();
    const fs::path dir = parent.empty() ? fs::path(".") : parent;
    if (!fs::is_directory(dir, ec)) fail("directory '" + dir.string() + "' does not exist");
    // A probe file, the way the real one will be made: permissions, read-only mounts and a full
    // directory all show up here rather than after the render.
    const std::string probe = path + ".probe-" + std::to_string(::getpid());
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0644);
    if (fd < 0) {
        if (errno != EEXIST)
            fail(std::string("cannot create files in its directory (") + std::strerror(errno) +
                 ")");
        return;  // a stale probe of an earlier process with our pid: the directory takes files
    }
    ::close(fd);
    ::unlink(probe.c_str());
}

}  // namespace

void FileSet::Input(const std::string& path, const std::string& what) {
    files_.push_back({path, what, false});
}

void FileSet::Output(const std::string& path, const std::string& option) {
    files_.push_back({path, option, true});
}

void FileSet::SceneInputs(const Scene& scene) {
    Input(scene.path, "the scene");
    for (const Object& o : scene.objects) Input(o.objPath, "mesh file of object '" + o.name + "'");
    for (const Texture& t : scene.textures)
        if (!t.path.empty()) Input(t.path, "texture file");
    for (const EnvironmentLight& e : scene.environments)
        if (!e.path.empty()) Input(e.path, "environment map");
}

void FileSet::Check() const {
    std::map<std::string, const File*> seen;  // by FileKey: O(n log n) for thousands of frames
    for (const File& f : files_) {
        if (f.output) CheckWritable(f.path, f.role);
        const auto [it, fresh] = seen.emplace(FileKey(f.path), &f);
        if (fresh) continue;
        const File& other = *it->second;
        if (!f.output && !other.output) continue;  // reading a file twice is fine
        const File& out = f.output ? f : other;
        const File& prior = f.output ? other : f;
        throw InputError(out.role, "'" + out.path + "' is the same file as " +
                                       (prior.output ? "the output of " : "") + prior.role + " ('" +
                                       prior.path + "'): refusing to overwrite it");
    }
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
                         "unsupported image type '" + Excerpt(ext) + "' (expected .exr or .png)");
    }
    return p;
}

void AddOutputs(FileSet& files, const OutputPaths& out) {
    if (!out.exr.empty()) files.Output(out.exr, "--output");
    if (!out.png.empty())
        files.Output(out.png, out.exr.empty() ? "--output" : "--output (the PNG beside the EXR)");
}

void WriteOutputs(OutputPaths& out, const Image& beauty, const std::vector<ImageLayer>& layers,
                  float exposure, AtomicFiles& group) {
    if (!out.exr.empty()) {
        WriteImage(out.exr, beauty, layers, 0.0f, &group);
        out.written.push_back(out.exr);
    }
    if (!out.png.empty()) {
        WriteImage(out.png, beauty, {}, exposure, &group);
        out.written.push_back(out.png);
    }
}

void WriteText(const std::string& path, const std::string& text, AtomicFiles& group) {
    const std::string tmp = group.Stage(path);
    std::ofstream f(tmp, std::ios::binary);
    if (!f || !(f << text) || !f.flush()) throw InputError(path, "cannot write file");
}

Image Montage(const std::vector<std::vector<const Image*>>& rows, int gap) {
    int width = 0, height = 0;
    for (const auto& row : rows) {
        int w = 0;
        for (const Image* img : row) w += img->width + (w ? gap : 0);
        width = std::max(width, w);
        height += row.front()->height + (height ? gap : 0);
    }
    Image out(width, height, 3);
    int y0 = 0;
    for (const auto& row : rows) {
        int x0 = 0;
        for (const Image* img : row) {
            for (int y = 0; y < img->height; ++y)
                for (int x = 0; x < img->width; ++x)
                    std::copy_n(img->At(x, y), 3, out.At(x0 + x, y0 + y));
            x0 += img->width + gap;
        }
        y0 += row.front()->height + gap;
    }
    return out;
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
