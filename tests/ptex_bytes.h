// SPDX-License-Identifier: Apache-2.0
// Ptex files' bytes edited for the tests of bad input: block positions the header implies,
// zlib blocks replaced, edits appended, and zlib streams that expand without bound.
#pragma once
#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdint>
#include <cstring>
#include <functional>
#include <random>
#include <vector>

#include "texcache/ptex/writer.h"

namespace texcache::test {

inline std::vector<uint8_t> Zip(const std::vector<uint8_t>& in) {
    uLongf n = compressBound(uLong(in.size()));
    std::vector<uint8_t> out(n);
    EXPECT_EQ(compress2(out.data(), &n, in.data(), uLong(in.size()), 6), Z_OK);
    out.resize(n);
    return out;
}

inline std::vector<uint8_t> Unzip(const uint8_t* p, size_t zipSize, size_t memSize) {
    std::vector<uint8_t> out(memSize);
    uLongf n = memSize;
    EXPECT_EQ(uncompress(out.data(), &n, p, uLong(zipSize)), Z_OK);
    return out;
}

/// A Ptex file's bytes with the block positions the header implies, and edits that keep it
/// consistent apart from the lie under test (format.h of the library has the layout).
class PtexBytes {
public:
    explicit PtexBytes(std::vector<uint8_t> b) : b(std::move(b)) {}
    std::vector<uint8_t> b;

    uint32_t U32(size_t o) const {
        uint32_t v;
        std::memcpy(&v, &b[o], 4);
        return v;
    }
    uint64_t U64(size_t o) const {
        uint64_t v;
        std::memcpy(&v, &b[o], 8);
        return v;
    }
    void Set32(size_t o, uint32_t v) { std::memcpy(&b[o], &v, 4); }
    void Set64(size_t o, uint64_t v) { std::memcpy(&b[o], &v, 8); }

    // Header offsets.
    static constexpr size_t kNumFaces = 24, kFaceInfoSize = 32, kConstDataSize = 36,
                            kLevelInfoSize = 40, kLevelDataSize = 48, kMetaZip = 56, kMetaMem = 60,
                            kEditSize = 64 + 24, kEditPos = 64 + 32;
    size_t FaceInfoPos() const { return 64 + U32(28); }
    size_t LevelInfoPos() const { return FaceInfoPos() + U32(kFaceInfoSize) + U32(kConstDataSize); }
    size_t LevelPos(int k) const {
        size_t pos = LevelInfoPos() + U32(kLevelInfoSize);
        for (int i = 0; i < k; ++i) pos += size_t(U64(LevelInfoPos() + size_t(i) * 16));
        return pos;
    }
    size_t LevelFaces(int k) const { return U32(LevelInfoPos() + size_t(k) * 16 + 12); }

    /// Replaces the zlib block [pos, pos + zipSize) by a stream of `content`; returns the
    /// change in size and moves the edit data position with it.
    long Rezip(size_t pos, size_t zipSize, const std::vector<uint8_t>& content) {
        const std::vector<uint8_t> z = Zip(content);
        b.erase(b.begin() + long(pos), b.begin() + long(pos + zipSize));
        b.insert(b.begin() + long(pos), z.begin(), z.end());
        const long delta = long(z.size()) - long(zipSize);
        Set64(kEditPos, uint64_t(long(U64(kEditPos)) + delta));
        return delta;
    }

    /// Edits the face info records (20 bytes per face).
    void EditFaceInfo(const std::function<void(std::vector<uint8_t>&)>& fn) {
        std::vector<uint8_t> fi =
            Unzip(&b[FaceInfoPos()], U32(kFaceInfoSize), 20 * size_t(U32(kNumFaces)));
        fn(fi);
        const long d = Rezip(FaceInfoPos(), U32(kFaceInfoSize), fi);
        Set32(kFaceInfoSize, uint32_t(long(U32(kFaceInfoSize)) + d));
    }

    /// Replaces block `i` of level `k` by `data` with encoding `enc` (its header word too).
    void ReplaceBlock(int k, size_t i, const std::vector<uint8_t>& data, uint32_t enc) {
        const size_t li = LevelInfoPos() + size_t(k) * 16, pos = LevelPos(k);
        const uint32_t headerSize = U32(li + 8);
        std::vector<uint8_t> words = Unzip(&b[pos], headerSize, 4 * LevelFaces(k));
        size_t at = pos + headerSize;
        for (size_t j = 0; j < i; ++j) at += WordSize(words, j);
        const size_t oldSize = WordSize(words, i);
        b.erase(b.begin() + long(at), b.begin() + long(at + oldSize));
        b.insert(b.begin() + long(at), data.begin(), data.end());
        const long dataDelta = long(data.size()) - long(oldSize);
        const uint32_t w = uint32_t(data.size()) | enc << 30;
        std::memcpy(&words[4 * i], &w, 4);
        const long headerDelta = Rezip(pos, headerSize, words);
        Set32(li + 8, uint32_t(long(headerSize) + headerDelta));
        Set64(li, uint64_t(long(U64(li)) + headerDelta + dataDelta));
        Set64(kLevelDataSize, uint64_t(long(U64(kLevelDataSize)) + headerDelta + dataDelta));
        Set64(kEditPos, uint64_t(long(U64(kEditPos)) + dataDelta));
    }

    /// Appends an edit record (type, payload) and counts it in the extended header.
    void AppendEdit(uint8_t type, const std::vector<uint8_t>& payload) {
        b.push_back(type);
        const uint32_t n = uint32_t(payload.size());
        b.insert(b.end(), reinterpret_cast<const uint8_t*>(&n),
                 reinterpret_cast<const uint8_t*>(&n) + 4);
        b.insert(b.end(), payload.begin(), payload.end());
        Set64(kEditSize, U64(kEditSize) + 5 + payload.size());
    }

private:
    static size_t WordSize(const std::vector<uint8_t>& words, size_t j) {
        uint32_t w;
        std::memcpy(&w, &words[4 * j], 4);
        return w & 0x3fffffff;
    }
};

/// A zlib stream of `megabytes` MB of zeros (about 1 KB per MB), built without holding them.
inline std::vector<uint8_t> ZlibBomb(int megabytes) {
    z_stream z{};
    EXPECT_EQ(deflateInit(&z, 1), Z_OK);
    const std::vector<uint8_t> zeros(1 << 20, 0);
    std::vector<uint8_t> out, chunk(1 << 16);
    for (int i = 0; i < megabytes; ++i) {
        const bool last = i + 1 == megabytes;
        z.next_in = const_cast<Bytef*>(zeros.data());
        z.avail_in = uInt(zeros.size());
        do {
            z.next_out = chunk.data();
            z.avail_out = uInt(chunk.size());
            deflate(&z, last ? Z_FINISH : Z_NO_FLUSH);
            out.insert(out.end(), chunk.data(), chunk.data() + (chunk.size() - z.avail_out));
        } while (z.avail_out == 0 || (last && z.avail_in > 0));
    }
    deflateEnd(&z);
    return out;
}

/// A file of one 1024x1024 uint8 face (1 MB), no mip levels, whose face data is a zlib stream
/// of `megabytes` MB of zeros.
inline PtexBytes ZlibBombFile(int megabytes) {
    std::vector<float> texels(1024 * 1024);
    std::mt19937 gen(4);
    for (float& x : texels) x = float(gen() % 256) / 255.0f;
    ptex::FaceInfo fi;
    fi.res = {10, 10};
    const ptex::FaceTexels face{fi, texels};
    ptex::WriteOptions o;
    o.dataType = ptex::DataType::UInt8;
    o.numChannels = 1;
    o.mipmaps = false;
    o.tileBytes = 0;
    PtexBytes p(ptex::EncodeTexture(o, {&face, 1}));
    p.ReplaceBlock(0, 0, ZlibBomb(megabytes), 1 /* zipped */);
    return p;
}

}  // namespace texcache::test
