// SPDX-License-Identifier: Apache-2.0
// Small helpers shared by the subcommands: argument checks, scene loading, output writing.
#pragma once
#include <charconv>
#include <cmath>
#include <string>
#include <type_traits>
#include <vector>

#include "renderer/image/atomic_files.h"
#include "renderer/image/image.h"
#include "renderer/scene/scene.h"
#include "texcache/error.h"

namespace texcache::cli {

/// A number as a person writes it: integers exactly, floats in their shortest round-trip form
/// ("1e+30", "0.001", not "1000000015047466219876688855040.000000").
template <typename T>
std::string FormatNumber(T v) {
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
}

/// Returns v when lo <= v <= hi (and finite), else throws InputError naming the option.
template <typename T>
T CheckRange(const char* option, T v, T lo, T hi) {
    if constexpr (std::is_floating_point_v<T>)
        if (std::isnan(v)) throw InputError(option, "expected a number, got nan");
    if (!(v >= lo && v <= hi))
        throw InputError(option, "value " + FormatNumber(v) + " is out of range [" +
                                     FormatNumber(lo) + ", " + FormatNumber(hi) + "]");
    return v;
}

/// Parses "WxH" (1..16384 each).
void ParseResolution(const std::string& s, int* width, int* height);

/// LoadSceneFile with the bundled studio environment for bare .obj cages.
Scene LoadSceneOrObj(const std::string& path, std::vector<std::string>* warnings);

/// Every file a command reads and every file it writes, checked together before any work is
/// done, so that no flag can destroy a file: an output must not be an input or another output
/// (the same file by device and inode when it exists, else the same canonical path: symlinks and
/// "a/../b" resolve), must not be a directory or another non-regular file, and its directory must
/// exist and take a new file (a probe file is created there and removed).
class FileSet {
public:
    /// A file the command reads; `what` names it in messages ("the scene", "mesh file").
    void Input(const std::string& path, const std::string& what);
    /// A file the command writes; `option` names where it came from ("--stats", "-o").
    void Output(const std::string& path, const std::string& option);
    /// The scene file and every file it references (meshes, textures, environment maps).
    void SceneInputs(const Scene& scene);
    /// Throws InputError naming the output's option and path on the first conflict.
    void Check() const;

private:
    struct File {
        std::string path, role;
        bool output;
    };
    std::vector<File> files_;
};

struct OutputPaths {
    std::string exr, png;  ///< empty when not written
    std::vector<std::string> written;
};
/// Decides which files an output name means; checks the extension before any rendering.
OutputPaths PlanOutputs(const std::string& output, bool pngBesideExr);
/// Adds the planned files to `files` as outputs of -o.
void AddOutputs(FileSet& files, const OutputPaths& out);
/// Writes the planned files into `group` (renamed when the caller commits it); fills `written`.
void WriteOutputs(OutputPaths& out, const Image& beauty, const std::vector<ImageLayer>& layers,
                  float exposure, AtomicFiles& group);

/// Writes a text file into `group` (renamed when the caller commits it).
void WriteText(const std::string& path, const std::string& text, AtomicFiles& group);

/// Images in a grid, rows top to bottom and each row left to right, `gap` black pixels apart
/// (montage, bench peer's side-by-side picture). Every image of a row has the row's height.
Image Montage(const std::vector<std::vector<const Image*>>& rows, int gap);

double NowSeconds();
/// Peak resident memory of this process so far.
double PeakMemoryMiB();

}  // namespace texcache::cli
