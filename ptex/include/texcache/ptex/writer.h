// SPDX-License-Identifier: Apache-2.0
// Writing Ptex files that Ptex's own library and Texture read: constant faces in the constant
// block, other faces zlib-compressed (uint8/uint16 as running differences, large faces in
// tiles), mip levels reduced 2x2 down to 4 texels on the shorter side (colour premultiplied by
// alpha, as Ptex stores reductions), meta data (items over 1 KB in their own blocks).
#pragma once
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "texcache/ptex/texture.h"

namespace texcache::ptex {

/// What to write, for the whole file.
struct WriteOptions {
    MeshType meshType = MeshType::Quad;
    DataType dataType = DataType::Half;
    int numChannels = 3;
    int alphaChannel = -1;  ///< -1: none
    BorderMode uBorder = BorderMode::Clamp, vBorder = BorderMode::Clamp;
    EdgeFilterMode edgeFilter = EdgeFilterMode::None;
    bool mipmaps = true;
    /// Faces (and reductions) whose texels take more bytes than this are split into tiles of
    /// about this size (Ptex's default); 0 never tiles.
    size_t tileBytes = 65536;
    std::vector<MetaEntry> meta;
};

/// One face to write: its info (res, adjacency, subface flag; the other flags are computed) and
/// its texels as floats, row-major from v = 0 with the channels interleaved: res.U() * res.V()
/// * numChannels values, or numChannels for a constant face. Faces whose texels all store the
/// same value become constant faces.
struct FaceTexels {
    FaceInfo info;
    std::span<const float> texels;
};

/// The bytes of a Ptex file holding `faces` (face i is Ptex face i). Throws
/// std::invalid_argument for inconsistent input (texel counts, resolutions, adjacency).
std::vector<uint8_t> EncodeTexture(const WriteOptions& options, std::span<const FaceTexels> faces);

/// Writes EncodeTexture's bytes to `path` through a temporary file renamed into place, so an
/// existing file is replaced whole or not at all. Throws InputError(path, ...) when it cannot.
void WriteTexture(const std::string& path, const WriteOptions& options,
                  std::span<const FaceTexels> faces);

}  // namespace texcache::ptex
