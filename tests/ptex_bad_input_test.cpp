// SPDX-License-Identifier: Apache-2.0
// Bad Ptex files: truncated at every stretch of the file, sizes and counts that lie, huge
// resolutions, zlib streams that expand without bound, and seeded random mutations. Each must
// throw one InputError line naming the file, with memory bounded by what the file's bytes can
// expand to; never another exception or a crash (the sanitizer builds check the latter). Also
// the edits Ptex appends to files, applied and rejected when they lie.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <zlib.h>

#include <cstring>
#include <functional>
#include <random>

#include "texcache/error.h"
#include "texcache/ptex/info.h"
#include "texcache/ptex/texture.h"
#include "texcache/ptex/writer.h"

namespace texcache {
namespace {

using ptex::Texture;

std::vector<uint8_t> Zip(const std::vector<uint8_t>& in) {
    uLongf n = compressBound(uLong(in.size()));
    std::vector<uint8_t> out(n);
    EXPECT_EQ(compress2(out.data(), &n, in.data(), uLong(in.size()), 6), Z_OK);
    out.resize(n);
    return out;
}

std::vector<uint8_t> Unzip(const uint8_t* p, size_t zipSize, size_t memSize) {
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

/// A small file with every kind of block: uint16, two channels, tiles, mip levels, constant
/// faces, small and large meta data.
std::vector<uint8_t> SmallFile(bool mipmaps = true, size_t tileBytes = 256) {
    std::mt19937 gen(2);
    std::uniform_real_distribution<float> U(0.0f, 1.0f);
    std::vector<ptex::FaceInfo> infos(6);
    std::vector<std::vector<float>> texels(6);
    std::vector<ptex::FaceTexels> faces;
    for (int f = 0; f < 6; ++f) {
        infos[size_t(f)].res = {int8_t(2 + f % 4), int8_t(3 + f % 2)};
        infos[size_t(f)].adjFaces = {(f + 1) % 6, -1, (f + 5) % 6, -1};
        infos[size_t(f)].adjEdges = {2, 0, 0, 0};
        const size_t n = size_t(infos[size_t(f)].res.U()) * size_t(infos[size_t(f)].res.V()) * 2;
        for (size_t i = 0; i < n; ++i) texels[size_t(f)].push_back(f == 3 ? 0.25f : U(gen));
        faces.push_back({infos[size_t(f)], texels[size_t(f)]});
    }
    ptex::WriteOptions o;
    o.dataType = ptex::DataType::UInt16;
    o.numChannels = 2;
    o.alphaChannel = 1;
    o.mipmaps = mipmaps;
    o.tileBytes = tileBytes;
    o.meta = {{"name", ptex::MetaType::String, "small", {}},
              {"big", ptex::MetaType::Float, "", std::vector<double>(300, 0.5)}};
    return ptex::EncodeTexture(o, faces);
}

/// The error a file gives, "" when it loads (and then must be usable).
std::string ErrorOf(const std::vector<uint8_t>& bytes) {
    try {
        const Texture t = Texture::FromBytes(bytes, "bad.ptx");
        const ptex::Info info = ptex::Summarize(t);
        std::vector<float> out(static_cast<size_t>(t.NumChannels()) + 1);
        std::mt19937 gen(1);
        std::uniform_real_distribution<float> U(-0.1f, 1.1f);
        for (int i = 0; i < 64; ++i)
            t.Lookup(i % t.NumFaces(), U(gen), U(gen), U(gen) * 0.3f, out.data());
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

void ExpectError(const std::vector<uint8_t>& bytes, const std::string& part) {
    const std::string e = ErrorOf(bytes);
    EXPECT_EQ(e.rfind("bad.ptx: ", 0), 0u) << "'" << e << "'";
    EXPECT_NE(e.find(part), std::string::npos) << "'" << e << "' lacks '" << part << "'";
    EXPECT_EQ(e.find('\n'), std::string::npos);
}

/// A zlib stream of `megabytes` MB of zeros (about 1 KB per MB), built without holding them.
std::vector<uint8_t> ZlibBomb(int megabytes) {
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

long PeakRssKb() {
    rusage r{};
    getrusage(RUSAGE_SELF, &r);
    return r.ru_maxrss;
}

TEST(PtexBadInput, TheSmallFileLoads) {
    const std::vector<uint8_t> b = SmallFile();
    EXPECT_EQ(ErrorOf(b), "");
    const Texture t = Texture::FromBytes(b, "small.ptx");
    EXPECT_TRUE(t.Face(3).constant);
    EXPECT_GT(t.GetHeader().numLevels, 1);
    EXPECT_NE(t.Meta("big"), nullptr);
}

// Every prefix of the file is refused: the first 300 bytes one by one, then every 7th.
TEST(PtexBadInput, TruncatedAnywhereIsAnError) {
    const std::vector<uint8_t> b = SmallFile();
    int checked = 0;
    for (size_t n = 0; n < b.size(); n += n < 300 ? 1 : 7, ++checked) {
        const std::vector<uint8_t> cut(b.begin(), b.begin() + long(n));
        const std::string e = ErrorOf(cut);
        ASSERT_EQ(e.rfind("bad.ptx: ", 0), 0u) << "prefix of " << n << " bytes: '" << e << "'";
    }
    EXPECT_GT(checked, 300);
    ExpectError({}, "truncated");
    ExpectError(std::vector<uint8_t>(b.begin(), b.begin() + 40), "truncated");
    ExpectError(std::vector<uint8_t>(b.begin(), b.end() - 1), "truncated");
}

TEST(PtexBadInput, HeaderFieldsThatLie) {
    const std::vector<uint8_t> good = SmallFile();
    auto with = [&](size_t offset, uint32_t value) {
        PtexBytes p(good);
        p.Set32(offset, value);
        return p.b;
    };
    ExpectError(with(0, 0x12345678), "not a Ptex file");
    ExpectError(with(4, 2), "version 2");
    ExpectError(with(8, 7), "mesh type 7");
    ExpectError(with(12, 9), "data type 9");
    ExpectError(with(16, 5), "alpha channel 5");
    ExpectError(with(20, 0), "0 channels");  // channels 0, levels 0
    const uint32_t levels = PtexBytes(good).U32(20) >> 16;
    ExpectError(with(20, 2 | (levels + 1) << 16), "level info");  // one more level than stored
    ExpectError(with(PtexBytes::kNumFaces, 7), "face info");      // 7 faces, 6 stored
    ExpectError(with(PtexBytes::kNumFaces, 5), "face info");
    ExpectError(with(PtexBytes::kNumFaces, 0), "no faces");
    ExpectError(with(PtexBytes::kNumFaces, 0x7fffffff), "face info block");
    ExpectError(with(PtexBytes::kNumFaces, 0xffffffff), "faces");
    ExpectError(with(28, 0xfffffff0), "truncated");  // extended header size
    ExpectError(with(PtexBytes::kFaceInfoSize, 0xffffff00), "truncated");
    ExpectError(with(PtexBytes::kFaceInfoSize, 12), "face info");
    ExpectError(with(PtexBytes::kConstDataSize, 3), "constant data");
    ExpectError(with(PtexBytes::kLevelInfoSize, 8), "level info");
    ExpectError(with(PtexBytes::kLevelDataSize, 100), "level");
    ExpectError(with(PtexBytes::kMetaMem, 1 << 20), "meta data");
    ExpectError(with(PtexBytes::kMetaZip, 5), "meta data");
    ExpectError(with(64, 9), "border mode 9");
    ExpectError(with(64 + 4, 0x00050000), "edge filter mode 5");
    ExpectError(with(64 + 12, 1 << 30), "large meta data");  // lmd header mem size
    ExpectError(with(PtexBytes::kEditPos, 1 << 30), "truncated");
}

TEST(PtexBadInput, LevelSizesAndCountsThatLie) {
    const std::vector<uint8_t> good = SmallFile();
    PtexBytes base(good);
    const size_t li = base.LevelInfoPos();
    auto with = [&](size_t offset, uint64_t value, bool wide) {
        PtexBytes p(good);
        if (wide)
            p.Set64(offset, value);
        else
            p.Set32(offset, uint32_t(value));
        return p.b;
    };
    ExpectError(with(li, 1ull << 40, true), "level 0");             // data size
    ExpectError(with(li, 10, true), "level 0");                     // smaller than its header
    ExpectError(with(li + 8, 1u << 31, false), "level 0");          // header size
    ExpectError(with(li + 12, 5, false), "level 0 holds 5 faces");  // face count
    ExpectError(with(li + 16 + 12, 6000, false), "more faces");
    // A face block larger than the level holds, and one that is shorter than its data.
    PtexBytes p(good);
    const size_t pos = p.LevelPos(0), headerSize = p.U32(li + 8);
    std::vector<uint8_t> words = Unzip(&p.b[pos], headerSize, 24);
    std::vector<uint8_t> big = words;
    big[0] = 0xff, big[1] = 0xff, big[2] = 0x0f;  // face 0's block: 1 MB
    PtexBytes q(good);
    const long d = q.Rezip(pos, headerSize, big);
    q.Set32(li + 8, uint32_t(long(headerSize) + d));
    q.Set64(li, uint64_t(long(q.U64(li)) + d));
    q.Set64(PtexBytes::kLevelDataSize, uint64_t(long(q.U64(PtexBytes::kLevelDataSize)) + d));
    ExpectError(q.b, "runs past");
}

TEST(PtexBadInput, ResolutionsThatLie) {
    const std::vector<uint8_t> good = SmallFile(false, 0);
    auto res = [&](int face, int8_t u, int8_t v) {
        PtexBytes p(good);
        p.EditFaceInfo([&](std::vector<uint8_t>& fi) {
            fi[size_t(face) * 20] = uint8_t(u);
            fi[size_t(face) * 20 + 1] = uint8_t(v);
        });
        return p.b;
    };
    ExpectError(res(0, 20, 20), "cannot come from");  // 2^40 texels from a few hundred bytes
    ExpectError(res(0, 30, 2), "resolution");
    ExpectError(res(1, -1, 3), "resolution");
    ExpectError(res(2, 5, 6), "");  // larger than its data: zlib ends early or too short
    PtexBytes adj(good);
    adj.EditFaceInfo([](std::vector<uint8_t>& fi) { fi[4 + 4 * 2] = 99; });
    ExpectError(adj.b, "names face 99");
}

// A zlib stream of 256 MB of zeros (a quarter MB in the file) where the face declares 1 MB:
// inflating stops at the declared size. The process's peak memory grows by a few MB, not 256.
TEST(PtexBadInput, ZlibBombsStopAtTheDeclaredSize) {
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
    texels = {};
    p.ReplaceBlock(0, 0, ZlibBomb(256), 1 /* zipped */);
    const long before = PeakRssKb();
    ExpectError(p.b, "expands past the 1048576 bytes");
    EXPECT_LT(PeakRssKb() - before, 12 * 1024);

    // A huge declared size from a tiny stream is refused before any allocation.
    PtexBytes huge = p;
    huge.EditFaceInfo([](std::vector<uint8_t>& f) { f[0] = 20, f[1] = 20; });
    ExpectError(huge.b, "cannot come from");
    // So is a tiled face claiming 2^40 one-texel tiles.
    std::vector<uint8_t> tiled = {0, 0};
    const std::vector<uint8_t> headers = Zip(std::vector<uint8_t>(4096, 0));
    const uint32_t n = uint32_t(headers.size());
    tiled.insert(tiled.end(), reinterpret_cast<const uint8_t*>(&n),
                 reinterpret_cast<const uint8_t*>(&n) + 4);
    tiled.insert(tiled.end(), headers.begin(), headers.end());
    huge.ReplaceBlock(0, 0, tiled, 3 /* tiled */);
    ExpectError(huge.b, "tiles cannot fit");
    EXPECT_LT(PeakRssKb() - before, 12 * 1024);
}

// Edits appended to a file (Ptex's incremental writes): a constant face, a face with new
// texels (its reductions then made by the reader), a meta data entry. And edits that lie.
TEST(PtexBadInput, EditsApplyAndLyingEditsAreErrors) {
    const std::vector<uint8_t> good = SmallFile();
    auto faceEdit = [](uint32_t face, int8_t ulog2, int8_t vlog2, bool constant,
                       const std::vector<uint8_t>& pixel, const std::vector<uint8_t>& data,
                       uint32_t enc) {
        std::vector<uint8_t> e(4 + 20 + 4);
        std::memcpy(&e[0], &face, 4);
        e[4] = uint8_t(ulog2), e[5] = uint8_t(vlog2), e[7] = constant ? 1 : 0;
        for (int k = 0; k < 4; ++k) std::memset(&e[8 + 4 * size_t(k)], 0xff, 4);
        const uint32_t w = uint32_t(data.size()) | enc << 30;
        std::memcpy(&e[24], &w, 4);
        e.insert(e.end(), pixel.begin(), pixel.end());
        e.insert(e.end(), data.begin(), data.end());
        return e;
    };
    // uint16 pixels of 2 channels.
    const std::vector<uint8_t> half = {0x00, 0x80, 0xff, 0xff};  // 32768/65535, 1
    PtexBytes p(good);
    p.AppendEdit(0, faceEdit(2, 3, 3, true, half, {}, 0));
    // Face 4 becomes 8x8 of a ramp, zipped as Ptex stores it (channels one after the other).
    std::vector<uint8_t> planar;
    for (int c = 0; c < 2; ++c)
        for (int i = 0; i < 64; ++i) {
            const uint16_t v = uint16_t(c == 0 ? i * 1000 : 65535);
            planar.push_back(uint8_t(v)), planar.push_back(uint8_t(v >> 8));
        }
    p.AppendEdit(0, faceEdit(4, 3, 3, false, half, Zip(planar), 1));
    std::vector<uint8_t> meta = {5, 'n', 'o', 't', 'e', 0, 0, 3, 0, 0, 0, 'h', 'i', 0};
    std::vector<uint8_t> metaEdit(8);
    const std::vector<uint8_t> mz = Zip(meta);
    const uint32_t sizes[2] = {uint32_t(mz.size()), uint32_t(meta.size())};
    std::memcpy(metaEdit.data(), sizes, 8);
    metaEdit.insert(metaEdit.end(), mz.begin(), mz.end());
    p.AppendEdit(1, metaEdit);

    const Texture t = Texture::FromBytes(p.b, "edited.ptx");
    EXPECT_TRUE(t.Face(2).constant);
    EXPECT_TRUE(t.Face(2).hasEdits);
    float px[2];
    t.Lookup(2, 0.5f, 0.5f, 0.0f, px);
    EXPECT_NEAR(px[0], 32768.0f / 65535.0f, 1e-6f);  // alpha 1: premultiplying changes nothing
    EXPECT_FALSE(t.Face(4).constant);
    EXPECT_EQ(t.LevelRes(4, 0), (ptex::Res{3, 3}));
    t.Texel(4, 0, 5, 2, px);
    EXPECT_NEAR(px[0], 21000.0f / 65535.0f, 1e-6f);
    ASSERT_EQ(t.NumLevels(4), 2);
    EXPECT_FALSE(t.LevelStored(4, 1));  // the file's reductions are of the old face
    t.Texel(4, 1, 0, 0, px);
    EXPECT_NEAR(px[0], 0.25f * (0 + 1000 + 8000 + 9000) / 65535.0f, 2e-5f);
    ASSERT_NE(t.Meta("note"), nullptr);
    EXPECT_EQ(t.Meta("note")->text, "hi");

    PtexBytes far(good);
    far.AppendEdit(0, faceEdit(99, 3, 3, true, half, {}, 0));
    ExpectError(far.b, "names face 99");
    PtexBytes past(good);
    past.AppendEdit(0, faceEdit(4, 3, 3, false, half, Zip(planar), 1));
    past.b.resize(past.b.size() - 10);
    ExpectError(past.b, "truncated: an edit");
    PtexBytes wrong(good);  // the texels of 8x8 declared as 16x16
    wrong.AppendEdit(0, faceEdit(4, 4, 4, false, half, Zip(planar), 1));
    ExpectError(wrong.b, "zlib data");
}

// Seeded mutations of the small file: byte flips, header fields set to boundary values,
// truncations and insertions. Each either loads into a texture that summarises and looks up,
// or throws InputError; nothing else.
TEST(PtexBadInput, RandomMutationsLoadOrFailCleanly) {
    const std::vector<uint8_t> good = SmallFile();
    std::mt19937 gen(12345);
    int loaded = 0, refused = 0;
    const uint32_t boundary[] = {0, 1, 2, 3, 0xff, 0x7fffffff, 0x80000000, 0xffffffff, 64, 1024};
    for (int i = 0; i < 1500; ++i) {
        std::vector<uint8_t> b = good;
        const int kind = int(gen() % 4);
        if (kind == 0) {
            for (int k = 0; k < 1 + int(gen() % 4); ++k)
                b[gen() % b.size()] ^= uint8_t(1 + gen() % 255);
        } else if (kind == 1) {
            const size_t field = 4 * (gen() % 26);  // header and extended header words
            const uint32_t v = boundary[gen() % 10];
            std::memcpy(&b[field], &v, 4);
        } else if (kind == 2) {
            b.resize(gen() % b.size());
        } else {
            b.insert(b.begin() + long(gen() % b.size()), uint8_t(gen()));
        }
        const std::string e = ErrorOf(b);
        if (e.empty()) {
            ++loaded;
        } else {
            ++refused;
            ASSERT_EQ(e.rfind("bad.ptx: ", 0), 0u) << e;
        }
    }
    EXPECT_GT(refused, 500);
    EXPECT_GT(loaded, 20);  // flips inside texels and padding leave valid files
}

}  // namespace
}  // namespace texcache
