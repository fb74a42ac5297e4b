// SPDX-License-Identifier: Apache-2.0
// The Ptex file layout (all little-endian, packed), shared by the reader and the writer:
//
//   Header (64 bytes)          magic "Ptex", version, meshtype, datatype, alphachan, nchannels,
//                              nlevels, nfaces, the sizes of the blocks below, minor version,
//                              meta data zip/mem sizes
//   Extended header            border modes, edge filter mode, large meta data and edit sizes;
//                              `extheadersize` bytes (0 in files before format 1.3)
//   Face info (zlib)           20 bytes per face: res (2), adjedges (1), flags (1), adjfaces (16)
//   Constant data (zlib)       one pixel per face
//   Level info                 16 bytes per level: data size (8), header size (4), nfaces (4)
//   Level data, per level      zlib face data headers (4 bytes each: size | encoding << 30),
//                              then each face's block. Level 0 lists faces in face id order,
//                              level k >= 1 the first nfaces faces sorted by their shorter side
//                              (descending, stable; constant faces count as 2 texels), each at
//                              its resolution halved k times
//   Meta data (zlib)           entries: keysize (1, with the NUL), key, type (1), size (4), data
//   Compatibility barrier      8 zero bytes (absent in files before 1.3)
//   Large meta data            zlib headers (as above, plus each item's zip size), then items
//   Edit data                  appended edits: type (1), size (4), payload
//
// A face block is constant (one pixel), zipped or diff-zipped (the channels one after the
// other, each row-major; diff: uint8/uint16 stored as running differences) or tiled (tile res
// (2), tile header zip size (4), zlib tile headers, then the tiles, each a block of the other
// kinds).
#pragma once
#include <Imath/half.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "texcache/ptex/texture.h"

namespace texcache::ptex::internal {

inline constexpr uint32_t kMagic = 0x78657450;  // "Ptex"
inline constexpr size_t kHeaderSize = 64;
inline constexpr size_t kExtHeaderSize = 40;
inline constexpr size_t kFaceInfoSize = 20;
inline constexpr size_t kLevelInfoSize = 16;
inline constexpr size_t kFaceDataHeaderSize = 4;
inline constexpr size_t kEditFaceHeaderSize = 4 + kFaceInfoSize + kFaceDataHeaderSize;
inline constexpr size_t kEditMetaHeaderSize = 8;
inline constexpr size_t kBarrierSize = 8;

enum Encoding : uint32_t { kConstant = 0, kZipped = 1, kDiffZipped = 2, kTiled = 3 };
enum EditType : uint8_t { kEditFaceData = 0, kEditMetaData = 1 };
enum FaceFlags : uint8_t {
    kFlagConstant = 1,
    kFlagHasEdits = 2,
    kFlagNbConstant = 4,
    kFlagSubface = 8
};

/// Reductions stop when the shorter side would drop below 2^kMinReductionLog2 texels.
inline constexpr int kMinReductionLog2 = 2;
/// Meta data items larger than this go to their own zlib block.
inline constexpr size_t kMetaDataThreshold = 1024;
/// Largest face side the reader accepts (2^20 texels); no tool writes faces near it.
inline constexpr int kMaxResLog2 = 20;

/// Deflate cannot expand more than 1032:1 (a long run costs at least 2 bits per 258 bytes),
/// so a block of `zipSize` bytes that claims to inflate to more is lying. Checked before
/// allocating, which bounds memory by what the file's bytes can honestly expand to.
inline bool PlausibleInflate(uint64_t zipSize, uint64_t memSize) {
    return memSize <= zipSize * 1032 + 64;
}

inline uint16_t Load16(const uint8_t* p) {
    return uint16_t(p[0] | p[1] << 8);
}
inline uint32_t Load32(const uint8_t* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
inline uint64_t Load64(const uint8_t* p) {
    return uint64_t(Load32(p)) | uint64_t(Load32(p + 4)) << 32;
}
inline void Put8(std::vector<uint8_t>& b, uint8_t v) {
    b.push_back(v);
}
inline void Put16(std::vector<uint8_t>& b, uint16_t v) {
    b.push_back(uint8_t(v)), b.push_back(uint8_t(v >> 8));
}
inline void Put32(std::vector<uint8_t>& b, uint32_t v) {
    for (int i = 0; i < 4; ++i) b.push_back(uint8_t(v >> (8 * i)));
}
inline void Put64(std::vector<uint8_t>& b, uint64_t v) {
    for (int i = 0; i < 8; ++i) b.push_back(uint8_t(v >> (8 * i)));
}

/// The fixed header and the extended header, field for field.
struct RawHeader {
    uint32_t magic = kMagic, version = 1, meshType = 1, dataType = 0;
    int32_t alphaChannel = -1;
    uint16_t numChannels = 0, numLevels = 0;
    uint32_t numFaces = 0, extHeaderSize = 0, faceInfoSize = 0, constDataSize = 0,
             levelInfoSize = 0, minorVersion = 0;
    uint64_t levelDataSize = 0;
    uint32_t metaZipSize = 0, metaMemSize = 0;
    // Extended header (zero when the file's is shorter).
    uint16_t uBorder = 0, vBorder = 0, edgeFilter = 0;
    uint32_t lmdHeaderZipSize = 0, lmdHeaderMemSize = 0;
    uint64_t lmdDataSize = 0, editDataSize = 0, editDataPos = 0;
};
/// Parses the first kHeaderSize + min(extHeaderSize, kExtHeaderSize) bytes; the caller
/// checks that they are present.
RawHeader ParseHeader(const uint8_t* p, size_t available);
/// Appends the header and a full extended header (kExtHeaderSize).
void AppendHeader(std::vector<uint8_t>& out, const RawHeader& h);

/// FaceInfo as stored (20 bytes) and back; flags beyond the four known bits are dropped.
FaceInfo ParseFaceInfo(const uint8_t* p);
void AppendFaceInfo(std::vector<uint8_t>& out, const FaceInfo& f);

/// Inflates exactly `out.size()` bytes from `in`: returns an empty string, or what is wrong
/// (corrupt data, a stream that ends early, one that would expand past out.size()).
std::string Inflate(std::span<const uint8_t> in, std::span<uint8_t> out);
/// Deflates `in` into one zlib stream appended to `out`; returns its size.
size_t Deflate(std::span<const uint8_t> in, std::vector<uint8_t>& out);

/// Reduction face order: face ids sorted by shorter side, largest first (stable), constant
/// faces counting as log2 1. order[r] is the face at reduction index r.
std::vector<uint32_t> ReductionOrder(const std::vector<FaceInfo>& faces);
/// Number of reduction levels (level 0 excluded) a face of this kind gets from Ptex's writer.
inline int NaturalReductions(const FaceInfo& f) {
    const int m = f.constant ? 1 : std::min(f.res.ulog2, f.res.vlog2);
    return m > kMinReductionLog2 ? m - kMinReductionLog2 : 0;
}

/// Texel (s, t) of a level halved from one `srcSide` texels wide, from `get(x, y)` of the
/// source: the 2x2 box for quads; for triangles (Ptex's packed square, the odd texels
/// mirrored) the three even texels of the corner and the odd one between them.
template <class Get>
float ReducedTexel(bool triangle, int srcSide, int s, int t, const Get& get) {
    const float d =
        triangle ? get(srcSide - 1 - 2 * t, srcSide - 1 - 2 * s) : get(2 * s + 1, 2 * t + 1);
    return 0.25f * (get(2 * s, 2 * t) + get(2 * s + 1, 2 * t) + get(2 * s, 2 * t + 1) + d);
}

/// Bytes per value of a meta data type.
int MetaTypeSize(MetaType t);

/// Half-float conversions (IEEE 754 binary16, round to nearest even), Imath's.
inline float HalfToFloat(uint16_t h) {
    return imath_half_to_float(h);
}
inline uint16_t FloatToHalf(float f) {
    return imath_float_to_half(f);
}

/// One channel value of a stored pixel as float.
inline float ChannelToFloat(const uint8_t* pixel, int channel, DataType t) {
    switch (t) {
        case DataType::UInt8:
            return pixel[channel] * (1.0f / 255.0f);
        case DataType::UInt16:
            return Load16(pixel + 2 * channel) * (1.0f / 65535.0f);
        case DataType::Half:
            return HalfToFloat(Load16(pixel + 2 * channel));
        default: {
            float f;
            std::memcpy(&f, pixel + 4 * channel, 4);
            return f;
        }
    }
}
/// Stores a float as one channel value (integers rounded and clamped to their range).
void FloatToChannel(float value, uint8_t* pixel, int channel, DataType t);

}  // namespace texcache::ptex::internal
