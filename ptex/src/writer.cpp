// SPDX-License-Identifier: Apache-2.0
// Encoding a Ptex file (format.h has the layout). Everything is assembled in memory: a baked
// texture is a few hundred MB at most, and one buffer makes the temporary-file-and-rename
// write trivial.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "format.h"
#include "texcache/error.h"
#include "texcache/ptex/writer.h"

namespace texcache::ptex {

using namespace internal;

namespace {

[[noreturn]] void Invalid(const std::string& what) {
    throw std::invalid_argument("Ptex writer: " + what);
}

/// A face block in the file: its bytes and its face data header word.
struct EncodedBlock {
    std::vector<uint8_t> bytes;
    uint32_t header = 0;
};

class Encoder {
public:
    explicit Encoder(const WriteOptions& o)
        : o_(o), ps_(size_t(DataSize(o.dataType) * o.numChannels)) {}

    /// Stored pixels of `values` (interleaved floats), `count` pixels.
    std::vector<uint8_t> Quantize(const float* values, size_t count) const {
        std::vector<uint8_t> raw(count * ps_);
        for (size_t i = 0; i < count; ++i)
            for (int c = 0; c < o_.numChannels; ++c)
                FloatToChannel(values[i * size_t(o_.numChannels) + size_t(c)], raw.data() + i * ps_,
                               c, o_.dataType);
        return raw;
    }

    bool AllEqual(const std::vector<uint8_t>& raw) const {
        for (size_t p = ps_; p < raw.size(); p += ps_)
            if (std::memcmp(raw.data(), raw.data() + p, ps_) != 0) return false;
        return true;
    }

    /// One face (or reduction) as a block: zipped, or tiled when larger than tileBytes.
    EncodedBlock Block(const std::vector<uint8_t>& raw, Res res) const {
        const Res tile = TileRes(res);
        if (tile == res) return Zipped(raw.data(), res.U(), res);
        EncodedBlock b;
        const int ntu = 1 << (res.ulog2 - tile.ulog2), ntv = 1 << (res.vlog2 - tile.vlog2);
        std::vector<uint8_t> headers, data, tileRaw(size_t(tile.U()) * size_t(tile.V()) * ps_);
        for (int tv = 0; tv < ntv; ++tv)
            for (int tu = 0; tu < ntu; ++tu) {
                // Tile (tu, tv) gathered into its own rows.
                for (int y = 0; y < tile.V(); ++y) {
                    const size_t row =
                        size_t(tv * tile.V() + y) * size_t(res.U()) + size_t(tu * tile.U());
                    std::memcpy(tileRaw.data() + size_t(y) * size_t(tile.U()) * ps_,
                                raw.data() + row * ps_, size_t(tile.U()) * ps_);
                }
                EncodedBlock t;
                if (AllEqual(tileRaw)) {
                    t.bytes.assign(tileRaw.begin(), tileRaw.begin() + long(ps_));
                    t.header = uint32_t(ps_) | kConstant << 30;
                } else {
                    t = Zipped(tileRaw.data(), tile.U(), tile);
                }
                Put32(headers, t.header);
                data.insert(data.end(), t.bytes.begin(), t.bytes.end());
            }
        Put8(b.bytes, uint8_t(tile.ulog2));
        Put8(b.bytes, uint8_t(tile.vlog2));
        std::vector<uint8_t> zipped;
        Put32(b.bytes, uint32_t(Deflate(headers, zipped)));
        b.bytes.insert(b.bytes.end(), zipped.begin(), zipped.end());
        b.bytes.insert(b.bytes.end(), data.begin(), data.end());
        b.header = BlockWord(b.bytes.size(), kTiled);
        return b;
    }

private:
    /// Tiles of about tileBytes, as square as the face allows (Ptex's rule).
    Res TileRes(Res res) const {
        const uint64_t bytes = (uint64_t(1) << (res.ulog2 + res.vlog2)) * ps_;
        if (o_.tileBytes == 0 || bytes <= o_.tileBytes) return res;
        int ntilesLog2 = 0;
        while ((bytes >> (ntilesLog2 + 1)) >= o_.tileBytes) ++ntilesLog2;
        if (ntilesLog2 == 0) return res;
        const int n = res.ulog2 + res.vlog2 - ntilesLog2;
        Res t;
        t.ulog2 = int8_t(std::min((n + 1) / 2, int(res.ulog2)));
        t.vlog2 = int8_t(std::min(n - t.ulog2, int(res.vlog2)));
        t.ulog2 = int8_t(std::min(n - t.vlog2, int(res.ulog2)));
        return t;
    }

    static uint32_t BlockWord(size_t size, Encoding e) {
        if (size > 0x3fffffffu)
            Invalid("a face block of " + std::to_string(size) + " bytes (tile it)");
        return uint32_t(size) | uint32_t(e) << 30;
    }

    /// Channels one after the other, integer types as running differences, then zlib.
    EncodedBlock Zipped(const uint8_t* raw, int rowPixels, Res res) const {
        const size_t vs = size_t(DataSize(o_.dataType)), n = size_t(res.U()) * size_t(res.V());
        std::vector<uint8_t> planar(n * ps_);
        for (int c = 0; c < o_.numChannels; ++c)
            for (int y = 0; y < res.V(); ++y)
                for (int x = 0; x < res.U(); ++x) {
                    const size_t i = size_t(y) * size_t(res.U()) + size_t(x);
                    const size_t src = (size_t(y) * size_t(rowPixels) + size_t(x)) * ps_;
                    std::memcpy(planar.data() + (size_t(c) * n + i) * vs,
                                raw + src + size_t(c) * vs, vs);
                }
        Encoding e = kZipped;
        if (o_.dataType == DataType::UInt8) {
            uint8_t prev = 0;
            for (uint8_t& v : planar) {
                const uint8_t cur = v;
                v = uint8_t(cur - prev), prev = cur;
            }
            e = kDiffZipped;
        } else if (o_.dataType == DataType::UInt16) {
            uint16_t prev = 0;
            for (size_t i = 0; i + 1 < planar.size(); i += 2) {
                const uint16_t cur = Load16(&planar[i]), d = uint16_t(cur - prev);
                planar[i] = uint8_t(d), planar[i + 1] = uint8_t(d >> 8), prev = cur;
            }
            e = kDiffZipped;
        }
        EncodedBlock b;
        Deflate(planar, b.bytes);
        b.header = BlockWord(b.bytes.size(), e);
        return b;
    }

    const WriteOptions& o_;
    size_t ps_;
};

void Validate(const WriteOptions& o, std::span<const FaceTexels> faces) {
    if (o.numChannels < 1 || o.numChannels > 0xffff)
        Invalid(std::to_string(o.numChannels) + " channels");
    if (o.alphaChannel < -1 || o.alphaChannel >= o.numChannels)
        Invalid("alpha channel " + std::to_string(o.alphaChannel));
    if (faces.empty()) Invalid("no faces");
    const int nfaces = int(faces.size());
    for (int f = 0; f < nfaces; ++f) {
        const FaceInfo& fi = faces[size_t(f)].info;
        const std::string what = "face " + std::to_string(f) + ": ";
        if (fi.res.ulog2 < 0 || fi.res.vlog2 < 0 || fi.res.ulog2 > kMaxResLog2 ||
            fi.res.vlog2 > kMaxResLog2)
            Invalid(what + "resolution log2 " + std::to_string(fi.res.ulog2) + " x " +
                    std::to_string(fi.res.vlog2));
        if (o.meshType == MeshType::Triangle && fi.res.ulog2 != fi.res.vlog2)
            Invalid(what + "a triangle's texels must be square");
        const size_t n = faces[size_t(f)].texels.size(), nc = size_t(o.numChannels);
        if (n != nc && n != size_t(fi.res.U()) * size_t(fi.res.V()) * nc)
            Invalid(what + std::to_string(n) + " values for " + std::to_string(fi.res.U()) + " x " +
                    std::to_string(fi.res.V()) + " texels of " + std::to_string(nc) + " channels");
        for (int e = 0; e < 4; ++e) {
            if (fi.adjFaces[e] < -1 || fi.adjFaces[e] >= nfaces)
                Invalid(what + "edge " + std::to_string(e) + " names face " +
                        std::to_string(fi.adjFaces[e]));
            if (fi.adjEdges[e] > 3)
                Invalid(what + "adjacent edge " + std::to_string(fi.adjEdges[e]));
        }
    }
    for (const MetaEntry& m : o.meta) {
        if (m.key.empty() || m.key.size() > 254 || m.key.find('\0') != std::string::npos)
            Invalid("meta data key '" + Excerpt(m.key) + "' (1 to 254 bytes, no NUL)");
        if (int(m.type) > 5) Invalid("meta data '" + Excerpt(m.key) + "': unknown type");
    }
}

/// A meta entry's value bytes as the file stores them.
std::vector<uint8_t> MetaBytes(const MetaEntry& m) {
    std::vector<uint8_t> d;
    if (m.type == MetaType::String) {
        d.assign(m.text.begin(), m.text.end());
        d.push_back(0);
        return d;
    }
    for (const double x : m.numbers) {
        switch (m.type) {
            case MetaType::Int8:
                Put8(d, uint8_t(int8_t(x)));
                break;
            case MetaType::Int16:
                Put16(d, uint16_t(int16_t(x)));
                break;
            case MetaType::Int32:
                Put32(d, uint32_t(int32_t(x)));
                break;
            case MetaType::Float: {
                const float f = float(x);
                uint32_t bits;
                std::memcpy(&bits, &f, 4);
                Put32(d, bits);
                break;
            }
            default: {
                uint64_t bits;
                std::memcpy(&bits, &x, 8);
                Put64(d, bits);
            }
        }
    }
    return d;
}

/// Key, type and size of a meta entry (the part its data follows).
void AppendMetaHead(std::vector<uint8_t>& out, const MetaEntry& m, size_t dataSize) {
    Put8(out, uint8_t(m.key.size() + 1));
    out.insert(out.end(), m.key.begin(), m.key.end());
    Put8(out, 0);
    Put8(out, uint8_t(m.type));
    Put32(out, uint32_t(dataSize));
}

/// One level down (ReducedTexel) of interleaved floats.
std::vector<float> Halve(const std::vector<float>& src, Res res, int nchan, bool triangle) {
    const int w = res.U() / 2, h = res.V() / 2;
    std::vector<float> dst(size_t(w) * size_t(h) * size_t(nchan));
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < nchan; ++c)
                dst[(size_t(y) * size_t(w) + size_t(x)) * size_t(nchan) + size_t(c)] =
                    ReducedTexel(triangle, res.U(), x, y, [&](int xx, int yy) {
                        return src[(size_t(yy) * size_t(res.U()) + size_t(xx)) * size_t(nchan) +
                                   size_t(c)];
                    });
    return dst;
}

}  // namespace

std::vector<uint8_t> EncodeTexture(const WriteOptions& o, std::span<const FaceTexels> faces) {
    Validate(o, faces);
    const Encoder enc(o);
    const int nfaces = int(faces.size()), nchan = o.numChannels, alpha = o.alphaChannel;
    const size_t ps = size_t(DataSize(o.dataType) * nchan);

    std::vector<FaceInfo> infos(faces.size());
    std::vector<uint8_t> constData(size_t(nfaces) * ps);
    std::vector<EncodedBlock> level0(faces.size());
    // Premultiplied floats of the faces that get reductions, reduced level by level.
    std::vector<std::vector<float>> current(faces.size());
    for (int f = 0; f < nfaces; ++f) {
        const FaceTexels& in = faces[size_t(f)];
        FaceInfo& fi = infos[size_t(f)];
        fi = in.info;
        fi.constant = fi.hasEdits = fi.neighborhoodConstant = false;
        if (o.meshType == MeshType::Triangle) fi.subface = false, fi.adjFaces[3] = -1;
        const size_t count = in.texels.size() / size_t(nchan);
        const std::vector<uint8_t> raw = enc.Quantize(in.texels.data(), count);
        if (count == 1 || enc.AllEqual(raw)) {
            fi.constant = true;
            std::memcpy(constData.data() + size_t(f) * ps, raw.data(), ps);
            continue;
        }
        level0[size_t(f)] = enc.Block(raw, fi.res);
        // The constant block holds the face's mean, colour not premultiplied.
        std::vector<double> sum(size_t(nchan), 0.0);
        double alphaSum = 0;
        for (size_t i = 0; i < count; ++i) {
            const float* p = in.texels.data() + i * size_t(nchan);
            const double a = alpha >= 0 ? p[alpha] : 1.0;
            alphaSum += a;
            for (int c = 0; c < nchan; ++c) sum[size_t(c)] += c == alpha ? p[c] : p[c] * a;
        }
        std::vector<float> mean(static_cast<size_t>(nchan));
        for (int c = 0; c < nchan; ++c)
            mean[size_t(c)] =
                float(c == alpha || alpha < 0 ? sum[size_t(c)] / double(count)
                                              : (alphaSum != 0 ? sum[size_t(c)] / alphaSum : 0.0));
        const std::vector<uint8_t> m = enc.Quantize(mean.data(), 1);
        std::memcpy(constData.data() + size_t(f) * ps, m.data(), ps);
        if (o.mipmaps && NaturalReductions(fi) > 0) {
            current[size_t(f)].assign(in.texels.begin(), in.texels.end());
            if (alpha >= 0)
                for (size_t i = 0; i < count; ++i)
                    for (int c = 0; c < nchan; ++c)
                        if (c != alpha)
                            current[size_t(f)][i * size_t(nchan) + size_t(c)] *=
                                current[size_t(f)][i * size_t(nchan) + size_t(alpha)];
        }
    }

    // Reductions: level k lists the faces with at least k of them, in reduction order.
    std::vector<std::vector<EncodedBlock>> levels(1);
    levels[0] = std::move(level0);
    if (o.mipmaps) {
        const std::vector<uint32_t> order = ReductionOrder(infos);
        for (int k = 1;; ++k) {
            std::vector<EncodedBlock> level;
            for (const uint32_t f : order) {
                if (NaturalReductions(infos[f]) < k) break;
                const Res res{int8_t(infos[f].res.ulog2 - (k - 1)),
                              int8_t(infos[f].res.vlog2 - (k - 1))};
                current[f] = Halve(current[f], res, nchan, o.meshType == MeshType::Triangle);
                const Res half{int8_t(res.ulog2 - 1), int8_t(res.vlog2 - 1)};
                level.push_back(enc.Block(
                    enc.Quantize(current[f].data(), current[f].size() / size_t(nchan)), half));
            }
            if (level.empty()) break;
            levels.push_back(std::move(level));
        }
    }

    RawHeader h;
    h.meshType = uint32_t(o.meshType);
    h.dataType = uint32_t(o.dataType);
    h.alphaChannel = alpha;
    h.numChannels = uint16_t(nchan);
    h.numLevels = uint16_t(levels.size());
    h.numFaces = uint32_t(nfaces);
    h.extHeaderSize = uint32_t(kExtHeaderSize);
    h.minorVersion = 4;  // Ptex's current file version (1.4)
    h.uBorder = uint16_t(o.uBorder);
    h.vBorder = uint16_t(o.vBorder);
    h.edgeFilter = uint16_t(o.edgeFilter);

    std::vector<uint8_t> body;  // everything after the headers
    std::vector<uint8_t> faceInfo;
    for (const FaceInfo& fi : infos) AppendFaceInfo(faceInfo, fi);
    h.faceInfoSize = uint32_t(Deflate(faceInfo, body));
    h.constDataSize = uint32_t(Deflate(constData, body));
    std::vector<uint8_t> levelInfo, levelData;
    for (const std::vector<EncodedBlock>& level : levels) {
        std::vector<uint8_t> headers;
        for (const EncodedBlock& b : level) Put32(headers, b.header);
        const size_t start = levelData.size();
        const size_t headerSize = Deflate(headers, levelData);
        for (const EncodedBlock& b : level)
            levelData.insert(levelData.end(), b.bytes.begin(), b.bytes.end());
        Put64(levelInfo, levelData.size() - start);
        Put32(levelInfo, uint32_t(headerSize));
        Put32(levelInfo, uint32_t(level.size()));
    }
    h.levelInfoSize = uint32_t(levelInfo.size());
    h.levelDataSize = levelData.size();
    body.insert(body.end(), levelInfo.begin(), levelInfo.end());
    body.insert(body.end(), levelData.begin(), levelData.end());

    std::vector<uint8_t> small, largeHeads, largeData;
    for (const MetaEntry& m : o.meta) {
        const std::vector<uint8_t> d = MetaBytes(m);
        if (d.size() > kMetaDataThreshold) {
            std::vector<uint8_t> z;
            const size_t zipSize = Deflate(d, z);
            AppendMetaHead(largeHeads, m, d.size());
            Put32(largeHeads, uint32_t(zipSize));
            largeData.insert(largeData.end(), z.begin(), z.end());
        } else {
            AppendMetaHead(small, m, d.size());
            small.insert(small.end(), d.begin(), d.end());
        }
    }
    if (!small.empty()) {
        h.metaMemSize = uint32_t(small.size());
        h.metaZipSize = uint32_t(Deflate(small, body));
    }
    for (size_t i = 0; i < kBarrierSize; ++i) Put8(body, 0);
    if (!largeHeads.empty()) {
        h.lmdHeaderMemSize = uint32_t(largeHeads.size());
        h.lmdHeaderZipSize = uint32_t(Deflate(largeHeads, body));
        h.lmdDataSize = largeData.size();
        body.insert(body.end(), largeData.begin(), largeData.end());
    }
    h.editDataPos = kHeaderSize + kExtHeaderSize + body.size();

    std::vector<uint8_t> out;
    out.reserve(kHeaderSize + kExtHeaderSize + body.size());
    AppendHeader(out, h);
    out.insert(out.end(), body.begin(), body.end());
    return out;
}

void WriteTexture(const std::string& path, const WriteOptions& options,
                  std::span<const FaceTexels> faces) {
    const std::vector<uint8_t> bytes = EncodeTexture(options, faces);
    const std::string temp = path + ".tmp-" + std::to_string(getpid());
    {
        std::ofstream out(temp, std::ios::binary | std::ios::trunc);
        if (!out) throw InputError(path, "cannot create " + temp);
        out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
        out.close();
        if (!out) {
            std::remove(temp.c_str());
            throw InputError(path, "cannot write " + temp);
        }
    }
    std::error_code ec;
    std::filesystem::rename(temp, path, ec);
    if (ec) {
        std::remove(temp.c_str());
        throw InputError(path, "cannot rename " + temp + " into place: " + ec.message());
    }
}

}  // namespace texcache::ptex
