// SPDX-License-Identifier: Apache-2.0
// Small helpers shared by the subcommands: argument checks, scene loading, output writing.
#pragma once
#include <cmath>
#include <string>
#include <vector>

#include "renderer/image.h"
#include "renderer/scene.h"
#include "texcache/error.h"

namespace texcache::cli {

/// Returns v when lo <= v <= hi (and finite), else throws InputError naming the option.
template <typename T>
T CheckRange(const char* option, T v, T lo, T hi) {
    if (!(v >= lo && v <= hi))  // also rejects NaN
        throw InputError(option, "value " + std::to_string(v) + " is out of range [" +
                                     std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return v;
}

/// Parses "WxH" (1..16384 each).
void ParseResolution(const std::string& s, int* width, int* height);

/// LoadSceneFile with the bundled studio environment for bare .obj cages.
Scene LoadSceneOrObj(const std::string& path, std::vector<std::string>* warnings);

struct OutputPaths {
    std::string exr, png;  ///< empty when not written
    std::vector<std::string> written;
};
/// Decides which files an output name means; checks the extension before any rendering.
OutputPaths PlanOutputs(const std::string& output, bool pngBesideExr);
/// Writes the planned files atomically (temporary file + rename); fills `written`.
void WriteOutputs(OutputPaths& out, const Image& beauty, const std::vector<ImageLayer>& layers,
                  float exposure);

/// Writes a text file atomically (temporary file + rename).
void WriteTextAtomic(const std::string& path, const std::string& text);

double NowSeconds();
/// Peak resident memory of this process so far.
double PeakMemoryMiB();

}  // namespace texcache::cli
