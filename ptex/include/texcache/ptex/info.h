// SPDX-License-Identifier: Apache-2.0
// What `texcache ptex info` reports about a Ptex file (the project's ptxinfo), and a face's
// texels as an image.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "texcache/ptex/texture.h"

namespace texcache::ptex {

/// One face: the file's info, its levels, and the mean of its level-0 texels per channel
/// (computed from the decoded texels; `constValue` is the file's constant block entry).
struct FaceSummary {
    FaceInfo info;
    int numLevels = 1;
    std::vector<float> mean;
    std::vector<float> constValue;
};

/// A whole file.
struct Info {
    std::string path;
    uint64_t fileBytes = 0;
    Header header;
    std::vector<FileLevel> levels;
    std::vector<MetaEntry> meta;
    std::vector<FaceSummary> faces;
    uint64_t decodedBytes = 0;
};

/// Summarises a texture (the means read every level-0 texel once).
Info Summarize(const Texture& texture);

/// The summary as JSON text: {"file", "bytes", "header": {...}, "border": {"u", "v"},
/// "edge_filter", "levels": [{"faces", "bytes"}], "meta": [{"key", "type", "value"}],
/// "faces": [{"id", "res": [ulog2, vlog2], "size": [u, v], "constant", "subface", "edited",
/// "levels", "adjfaces": [4], "adjedges": [4], "mean": [...], "const": [...]}]}.
/// Non-finite numbers are written as null.
std::string ToJson(const Info& info, int indent = 2);

/// A short human-readable report: header, border modes, meta data, levels, and one line per
/// face when `perFace`.
std::string ToText(const Info& info, bool perFace);

/// A face's texels at a level as floats: row t holds the texels of v index t (v = 0 first),
/// `channels` values per texel (the file's channels, stored values: see Texture::Texel).
struct FloatImage {
    int width = 0, height = 0, channels = 0;
    std::vector<float> pixels;
};
/// Throws InputError (naming the file) for a face or level the texture does not have.
FloatImage FaceImage(const Texture& texture, int face, int level);

}  // namespace texcache::ptex
