// SPDX-License-Identifier: Apache-2.0
#include "format.h"

#include <zlib.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <type_traits>

namespace texcache::ptex {

const char* Name(MeshType t) {
    return t == MeshType::Triangle ? "triangle" : "quad";
}
const char* Name(DataType t) {
    static const char* names[] = {"uint8", "uint16", "half", "float"};
    return names[int(t) & 3];
}
const char* Name(BorderMode m) {
    switch (m) {
        case BorderMode::Clamp:
            return "clamp";
        case BorderMode::Black:
            return "black";
        default:
            return "periodic";
    }
}
const char* Name(EdgeFilterMode m) {
    return m == EdgeFilterMode::TangentVector ? "tanvec" : "none";
}
const char* Name(MetaType t) {
    static const char* names[] = {"string", "int8", "int16", "int32", "float", "double"};
    return int(t) < 6 ? names[int(t)] : "unknown";
}
int DataSize(DataType t) {
    static const int sizes[] = {1, 2, 2, 4};
    return sizes[int(t) & 3];
}

namespace internal {

namespace {

// The header's fields in file order, for reading and writing alike (`h` const or not).
template <class H, class F>
void HeaderFields(H& h, F&& f) {
    f(h.magic), f(h.version), f(h.meshType), f(h.dataType), f(h.alphaChannel);
    f(h.numChannels), f(h.numLevels), f(h.numFaces), f(h.extHeaderSize), f(h.faceInfoSize);
    f(h.constDataSize), f(h.levelInfoSize), f(h.minorVersion), f(h.levelDataSize);
    f(h.metaZipSize), f(h.metaMemSize);
}
template <class H, class F>
void ExtHeaderFields(H& h, F&& f) {
    uint16_t pad = 0;
    f(h.uBorder), f(pad), f(h.vBorder), f(h.edgeFilter), f(h.lmdHeaderZipSize);
    f(h.lmdHeaderMemSize), f(h.lmdDataSize), f(h.editDataSize), f(h.editDataPos);
}

/// Reads little-endian integers one after the other.
struct Reader {
    const uint8_t* p;
    template <class T>
    void operator()(T& v) {
        std::make_unsigned_t<T> u = 0;
        for (size_t i = 0; i < sizeof(T); ++i) u = decltype(u)(u | decltype(u)(p[i]) << (8 * i));
        v = T(u);
        p += sizeof(T);
    }
};

/// Appends little-endian integers.
struct Writer {
    std::vector<uint8_t>& out;
    template <class T>
    void operator()(const T& v) {
        const std::make_unsigned_t<T> u = std::make_unsigned_t<T>(v);
        for (size_t i = 0; i < sizeof(T); ++i) out.push_back(uint8_t(u >> (8 * i)));
    }
};

}  // namespace

RawHeader ParseHeader(const uint8_t* p, size_t available) {
    RawHeader h;
    HeaderFields(h, Reader{p});
    // The extended header has grown over versions: read what the file has, zeros past it.
    uint8_t ext[kExtHeaderSize] = {};
    const size_t n = std::min({size_t(h.extHeaderSize), kExtHeaderSize, available - kHeaderSize});
    std::memcpy(ext, p + kHeaderSize, n);
    ExtHeaderFields(h, Reader{ext});
    return h;
}

void AppendHeader(std::vector<uint8_t>& out, const RawHeader& h) {
    HeaderFields(h, Writer{out});
    ExtHeaderFields(h, Writer{out});
}

FaceInfo ParseFaceInfo(const uint8_t* p) {
    FaceInfo f;
    f.res.ulog2 = int8_t(p[0]);
    f.res.vlog2 = int8_t(p[1]);
    for (int e = 0; e < 4; ++e) {
        f.adjEdges[e] = uint8_t((p[2] >> (2 * e)) & 3);
        f.adjFaces[e] = int32_t(Load32(p + 4 + 4 * e));
    }
    f.constant = p[3] & kFlagConstant;
    f.hasEdits = p[3] & kFlagHasEdits;
    f.neighborhoodConstant = p[3] & kFlagNbConstant;
    f.subface = p[3] & kFlagSubface;
    return f;
}

void AppendFaceInfo(std::vector<uint8_t>& out, const FaceInfo& f) {
    Put8(out, uint8_t(f.res.ulog2));
    Put8(out, uint8_t(f.res.vlog2));
    uint8_t edges = 0;
    for (int e = 0; e < 4; ++e) edges = uint8_t(edges | (f.adjEdges[e] & 3) << (2 * e));
    Put8(out, edges);
    Put8(out,
         uint8_t((f.constant ? kFlagConstant : 0) | (f.hasEdits ? kFlagHasEdits : 0) |
                 (f.neighborhoodConstant ? kFlagNbConstant : 0) | (f.subface ? kFlagSubface : 0)));
    for (int e = 0; e < 4; ++e) Put32(out, uint32_t(f.adjFaces[e]));
}

std::string Inflate(std::span<const uint8_t> in, std::span<uint8_t> out) {
    z_stream z{};
    if (inflateInit(&z) != Z_OK) return "zlib cannot start";
    // zlib counts in uInt: feed and drain in chunks so blocks over 4 GB work too.
    const uInt kChunk = uInt(1) << 30;
    size_t inPos = 0, outPos = 0;
    int r = Z_OK;
    for (;;) {
        if (z.avail_in == 0 && inPos < in.size()) {
            z.next_in = const_cast<Bytef*>(in.data() + inPos);
            z.avail_in = uInt(std::min<size_t>(kChunk, in.size() - inPos));
            inPos += z.avail_in;
        }
        // One spare byte past the expected size tells a stream that expands further.
        uint8_t spare = 0;
        if (outPos < out.size()) {
            z.next_out = out.data() + outPos;
            z.avail_out = uInt(std::min<size_t>(kChunk, out.size() - outPos));
        } else {
            z.next_out = &spare;
            z.avail_out = 1;
        }
        const uInt before = z.avail_out;
        r = inflate(&z, Z_NO_FLUSH);
        const size_t produced = before - z.avail_out;
        if (outPos >= out.size() && produced > 0) {
            inflateEnd(&z);
            return "zlib data expands past the " + std::to_string(out.size()) +
                   " bytes the file declares";
        }
        outPos += produced;
        if (r == Z_STREAM_END) break;
        if (r != Z_OK && r != Z_BUF_ERROR) {
            const std::string msg = z.msg ? z.msg : "invalid data";
            inflateEnd(&z);
            return "corrupt zlib data (" + msg + ")";
        }
        if (r == Z_BUF_ERROR && z.avail_in == 0 && inPos >= in.size()) {
            inflateEnd(&z);
            return "zlib data ends early (" + std::to_string(outPos) + " of " +
                   std::to_string(out.size()) + " bytes)";
        }
    }
    inflateEnd(&z);
    if (outPos != out.size())
        return "zlib data holds " + std::to_string(outPos) + " bytes, the file declares " +
               std::to_string(out.size());
    return {};
}

size_t Deflate(std::span<const uint8_t> in, std::vector<uint8_t>& out) {
    const size_t start = out.size();
    uLongf bound = compressBound(uLong(in.size()));
    out.resize(start + bound);
    // compress2 takes the whole input at once; face blocks are far below its uLong limit.
    if (compress2(out.data() + start, &bound, in.data(), uLong(in.size()), Z_DEFAULT_COMPRESSION) !=
        Z_OK) {
        out.resize(start);
        throw std::runtime_error("zlib compression failed");
    }
    out.resize(start + bound);
    return bound;
}

std::vector<uint32_t> ReductionOrder(const std::vector<FaceInfo>& faces) {
    std::vector<uint32_t> order(faces.size());
    std::iota(order.begin(), order.end(), 0u);
    auto shorter = [&](uint32_t f) {
        return faces[f].constant ? 1 : std::min(faces[f].res.ulog2, faces[f].res.vlog2);
    };
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return shorter(a) > shorter(b); });
    return order;
}

int MetaTypeSize(MetaType t) {
    static const int sizes[] = {1, 1, 2, 4, 4, 8};
    return sizes[int(t)];
}

void FloatToChannel(float value, uint8_t* pixel, int channel, DataType t) {
    switch (t) {
        case DataType::UInt8: {
            const float v = std::isnan(value) ? 0.0f : std::clamp(value, 0.0f, 1.0f);
            pixel[channel] = uint8_t(std::lround(v * 255.0f));
            break;
        }
        case DataType::UInt16: {
            const float v = std::isnan(value) ? 0.0f : std::clamp(value, 0.0f, 1.0f);
            const uint16_t q = uint16_t(std::lround(v * 65535.0f));
            pixel[2 * channel] = uint8_t(q), pixel[2 * channel + 1] = uint8_t(q >> 8);
            break;
        }
        case DataType::Half: {
            const uint16_t h = FloatToHalf(value);
            pixel[2 * channel] = uint8_t(h), pixel[2 * channel + 1] = uint8_t(h >> 8);
            break;
        }
        default:
            std::memcpy(pixel + 4 * channel, &value, 4);
    }
}

}  // namespace internal
}  // namespace texcache::ptex
