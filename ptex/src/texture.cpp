// SPDX-License-Identifier: Apache-2.0
// Reading a Ptex file (format.h has the layout). The parser checks every position and size
// against the file before using it and every zlib size against what its compressed bytes can
// expand to (PlausibleInflate) before allocating, then decodes in two passes: the first walks
// all headers and plans where each tile goes in the arena, the second allocates the arena once
// and inflates into it. A bad file throws InputError naming the file and the first problem.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <new>
#include <optional>

#include "texcache/error.h"
#include "texture_impl.h"

namespace texcache::ptex {

using namespace internal;

namespace {

std::string ByteCount(uint64_t n) {
    return std::to_string(n) + (n == 1 ? " byte" : " bytes");
}

/// A block of a level: a face at that level (stored in the file) or a tile of it.
struct FileBlock {
    uint64_t pos = 0;
    uint32_t size = 0;
    Encoding encoding = kConstant;
};

/// An edit that replaces a face's level 0.
struct FaceEdit {
    FileBlock block;
    bool constant = false;
};

/// A packed tile to inflate into the arena.
struct InflateJob {
    FileBlock block;
    Res res;
    uint64_t offset;
    std::string what;  ///< "face 3 level 0", for messages
};

class Parser {
public:
    Parser(std::span<const uint8_t> file, const std::string& name) : file_(file) {
        im_ = std::make_shared<Texture::Impl>();
        im_->path = name;
        im_->fileBytes = file.size();
    }

    std::shared_ptr<const Texture::Impl> Run() {
        ReadHeader();
        ReadFaceInfo();
        ReadConstData();
        ReadLevelInfo();
        ReadEdits();
        ReadMetaData();
        PlanLevels();
        Decode();
        Reduce();
        return im_;
    }

private:
    [[noreturn]] void Fail(const std::string& what) const { throw InputError(im_->path, what); }

    /// Checks that [pos, pos + size) lies in the file.
    std::span<const uint8_t> Block(uint64_t pos, uint64_t size, const std::string& what) const {
        if (pos > file_.size() || size > file_.size() - pos)
            Fail("truncated: " + what + " at byte " + std::to_string(pos) + " takes " +
                 ByteCount(size) + ", the file has " + ByteCount(file_.size()));
        return file_.subspan(size_t(pos), size_t(size));
    }

    /// Inflates a zlib block of the file to exactly memSize bytes.
    std::vector<uint8_t> InflateBlock(uint64_t pos, uint64_t zipSize, uint64_t memSize,
                                      const std::string& what) const {
        const std::span<const uint8_t> in = Block(pos, zipSize, what);
        if (!PlausibleInflate(zipSize, memSize))
            Fail(what + ": " + ByteCount(memSize) + " cannot come from " + ByteCount(zipSize) +
                 " of zlib data");
        std::vector<uint8_t> out;
        Allocate(out, memSize, what);
        if (memSize == 0) return out;
        const std::string err = Inflate(in, out);
        if (!err.empty()) Fail(what + ": " + err);
        return out;
    }

    void Allocate(std::vector<uint8_t>& v, uint64_t size, const std::string& what) const {
        try {
            v.resize(size_t(size));
        } catch (const std::bad_alloc&) {
            Fail(what + " needs " + ByteCount(size) + " of memory, which is not available");
        } catch (const std::length_error&) {
            Fail(what + " needs " + ByteCount(size) + " of memory, which is not available");
        }
    }

    void ReadHeader() {
        if (file_.size() >= 4 && Load32(file_.data()) != kMagic)
            Fail("not a Ptex file (it does not start with \"Ptex\")");
        if (file_.size() < kHeaderSize)
            Fail("truncated: " + ByteCount(file_.size()) + ", a Ptex header takes 64");
        h_ = ParseHeader(file_.data(), file_.size());
        if (h_.version != 1)
            Fail("Ptex format version " + std::to_string(h_.version) + " is not supported (1 is)");
        if (h_.meshType > 1)
            Fail("mesh type " + std::to_string(h_.meshType) +
                 " is neither triangle (0) nor quad (1)");
        if (h_.dataType > 3)
            Fail("data type " + std::to_string(h_.dataType) +
                 " is not uint8 (0), uint16 (1), half (2) or float (3)");
        if (h_.numChannels == 0) Fail("the header declares 0 channels");
        if (h_.alphaChannel < -1 || h_.alphaChannel >= int(h_.numChannels))
            Fail("alpha channel " + std::to_string(h_.alphaChannel) + " is not one of the " +
                 std::to_string(h_.numChannels) + " channels");
        if (h_.numFaces == 0) Fail("the header declares no faces");
        if (h_.numLevels == 0) Fail("the header declares no levels");
        if (h_.uBorder > 2 || h_.vBorder > 2)
            Fail("border mode " + std::to_string(std::max(h_.uBorder, h_.vBorder)) +
                 " is not clamp (0), black (1) or periodic (2)");
        if (h_.edgeFilter > 1)
            Fail("edge filter mode " + std::to_string(h_.edgeFilter) +
                 " is neither none (0) nor tanvec (1)");
        Block(kHeaderSize, h_.extHeaderSize, "the extended header");

        Header& hd = im_->header;
        hd.version = int(h_.version);
        hd.minorVersion = int(h_.minorVersion);
        hd.meshType = MeshType(h_.meshType);
        hd.dataType = DataType(h_.dataType);
        hd.alphaChannel = h_.alphaChannel;
        hd.numChannels = h_.numChannels;
        hd.numLevels = h_.numLevels;
        hd.numFaces = int(std::min<uint32_t>(h_.numFaces, INT32_MAX));
        hd.uBorder = BorderMode(h_.uBorder);
        hd.vBorder = BorderMode(h_.vBorder);
        hd.edgeFilter = EdgeFilterMode(h_.edgeFilter);
        im_->pixelSize = DataSize(hd.dataType) * hd.numChannels;
        if (h_.numFaces > uint32_t(INT32_MAX))
            Fail("the header declares " + std::to_string(h_.numFaces) + " faces");

        // Each block must lie in the file, which also keeps these sums from overflowing.
        uint64_t pos = kHeaderSize + uint64_t(h_.extHeaderSize);
        auto next = [&](uint64_t* at, uint64_t size, const char* what) {
            *at = pos;
            if (size > 0) Block(pos, size, what);
            pos += size;
        };
        next(&faceInfoPos_, h_.faceInfoSize, "the face info block");
        next(&constDataPos_, h_.constDataSize, "the constant data block");
        next(&levelInfoPos_, h_.levelInfoSize, "the level info block");
        next(&levelDataPos_, h_.levelDataSize, "the level data");
        next(&metaPos_, h_.metaZipSize, "the meta data");
        pos += kBarrierSize;  // absent before format 1.3, so not checked
        next(&lmdHeaderPos_, h_.lmdHeaderZipSize, "the large meta data headers");
        next(&lmdDataPos_, h_.lmdDataSize, "the large meta data");
        editPos_ = std::max(pos, h_.editDataPos);
    }

    void ValidateFaceInfo(const FaceInfo& f, const std::string& what) const {
        const int nfaces = im_->header.numFaces;
        if (f.res.ulog2 < 0 || f.res.vlog2 < 0 || f.res.ulog2 > kMaxResLog2 ||
            f.res.vlog2 > kMaxResLog2)
            Fail(what + ": resolution 2^" + std::to_string(f.res.ulog2) + " x 2^" +
                 std::to_string(f.res.vlog2) + " is outside 1 .. 2^" + std::to_string(kMaxResLog2) +
                 " texels a side");
        if (im_->header.meshType == MeshType::Triangle && f.res.ulog2 != f.res.vlog2)
            Fail(what + ": a triangle's texels must be square, not 2^" +
                 std::to_string(f.res.ulog2) + " x 2^" + std::to_string(f.res.vlog2));
        const int nedges = im_->header.meshType == MeshType::Triangle ? 3 : 4;
        for (int e = 0; e < nedges; ++e)
            if (f.adjFaces[e] < -1 || f.adjFaces[e] >= nfaces)
                Fail(what + ": edge " + std::to_string(e) + " names face " +
                     std::to_string(f.adjFaces[e]) + ", the file has " + std::to_string(nfaces));
    }

    void ReadFaceInfo() {
        const int n = im_->header.numFaces;
        const std::vector<uint8_t> raw = InflateBlock(
            faceInfoPos_, h_.faceInfoSize, uint64_t(n) * kFaceInfoSize, "the face info block");
        im_->faces.resize(size_t(n));
        for (int f = 0; f < n; ++f) {
            FaceInfo fi = ParseFaceInfo(raw.data() + size_t(f) * kFaceInfoSize);
            if (im_->header.meshType == MeshType::Triangle) fi.adjFaces[3] = -1;
            ValidateFaceInfo(fi, "face " + std::to_string(f));
            im_->faces[size_t(f)] = fi;
        }
        // Reductions list faces in the order of the faces as written, before any edit.
        order_ = ReductionOrder(im_->faces);
        rank_.resize(order_.size());
        for (size_t r = 0; r < order_.size(); ++r) rank_[order_[r]] = uint32_t(r);
    }

    void ReadConstData() {
        im_->constData = InflateBlock(constDataPos_, h_.constDataSize,
                                      uint64_t(im_->header.numFaces) * uint64_t(im_->pixelSize),
                                      "the constant data block");
    }

    void ReadLevelInfo() {
        const int nlevels = h_.numLevels;
        const std::span<const uint8_t> raw =
            Block(levelInfoPos_, uint64_t(nlevels) * kLevelInfoSize, "the level info block");
        if (h_.levelInfoSize < uint64_t(nlevels) * kLevelInfoSize)
            Fail("the level info block has " + ByteCount(h_.levelInfoSize) + ", " +
                 std::to_string(nlevels) + " levels take " +
                 ByteCount(uint64_t(nlevels) * kLevelInfoSize));
        uint64_t pos = levelDataPos_;
        for (int k = 0; k < nlevels; ++k) {
            const uint8_t* p = raw.data() + size_t(k) * kLevelInfoSize;
            LevelInfo li{pos, Load64(p), Load32(p + 8), Load32(p + 12)};
            const std::string what = "level " + std::to_string(k);
            if (k == 0 && li.numFaces != h_.numFaces)
                Fail(what + " holds " + std::to_string(li.numFaces) + " faces, the header " +
                     std::to_string(h_.numFaces));
            if (k > 0 && li.numFaces > levelInfo_.back().numFaces)
                Fail(what + " holds more faces (" + std::to_string(li.numFaces) +
                     ") than the level before it");
            if (li.headerSize > li.dataSize)
                Fail(what + ": its face headers (" + ByteCount(li.headerSize) +
                     ") are larger than the level (" + ByteCount(li.dataSize) + ")");
            if (pos - levelDataPos_ > h_.levelDataSize ||
                li.dataSize > h_.levelDataSize - (pos - levelDataPos_))
                Fail(what + " runs past the level data the header declares (" +
                     ByteCount(h_.levelDataSize) + ")");
            Block(pos, li.dataSize, what);
            levelInfo_.push_back(li);
            im_->fileLevels.push_back({int(li.numFaces), li.dataSize});
            pos += li.dataSize;
        }
    }

    /// Face data headers of a level, as blocks with their file positions.
    std::vector<FileBlock> LevelBlocks(int k) const {
        const LevelInfo& li = levelInfo_[size_t(k)];
        const std::string what = "level " + std::to_string(k);
        const std::vector<uint8_t> raw =
            InflateBlock(li.pos, li.headerSize, uint64_t(li.numFaces) * kFaceDataHeaderSize,
                         what + "'s face data headers");
        return Blocks(raw, li.numFaces, li.pos + li.headerSize, li.pos + li.dataSize, what);
    }

    /// Consecutive blocks from `pos`, each within [pos, end).
    std::vector<FileBlock> Blocks(const std::vector<uint8_t>& headers, uint32_t count, uint64_t pos,
                                  uint64_t end, const std::string& what) const {
        std::vector<FileBlock> blocks(count);
        for (uint32_t i = 0; i < count; ++i) {
            const uint32_t word = Load32(headers.data() + size_t(i) * 4);
            FileBlock& b = blocks[i];
            b.pos = pos;
            b.size = word & 0x3fffffffu;
            b.encoding = Encoding(word >> 30);
            if (b.size > end - pos)
                Fail(what + ": block " + std::to_string(i) + " (" + ByteCount(b.size) +
                     ") runs past the end of its data (" + ByteCount(end - pos) + " left)");
            pos += b.size;
        }
        return blocks;
    }

    void ReadEdits() {
        // Files since format 1.3 record where their edits start: at the end of the file when
        // it has none, so a shorter file lost its end.
        if (h_.editDataPos > file_.size())
            Fail("truncated: the header places the edit data at byte " +
                 std::to_string(h_.editDataPos) + ", the file has " + ByteCount(file_.size()));
        uint64_t pos = editPos_;
        if (pos >= file_.size()) return;
        // Before 1.3 edits ran to the end of the file; since, the header says how far.
        const uint64_t avail = file_.size() - pos;
        const uint64_t end = pos + (h_.editDataPos > 0 ? std::min(h_.editDataSize, avail) : avail);
        const int ps = im_->pixelSize;
        while (pos < end && end - pos >= 5) {
            const uint8_t type = file_[size_t(pos)];
            const uint32_t size = Load32(file_.data() + pos + 1);
            if (size == 0) break;
            const std::string what = "the edit at byte " + std::to_string(pos);
            const std::span<const uint8_t> payload = Block(pos + 5, size, "an edit");
            const uint64_t payloadPos = pos + 5;
            pos = payloadPos + size;
            if (type == kEditFaceData) {
                if (size < kEditFaceHeaderSize + uint64_t(ps))
                    Fail(what + ": " + ByteCount(size) + " cannot hold a face edit");
                const uint32_t face = Load32(payload.data());
                if (face >= h_.numFaces)
                    Fail(what + " names face " + std::to_string(face) + ", the file has " +
                         std::to_string(h_.numFaces));
                FaceInfo fi = ParseFaceInfo(payload.data() + 4);
                ValidateFaceInfo(fi, what);
                fi.hasEdits = true;
                im_->faces[face] = fi;
                std::memcpy(im_->constData.data() + size_t(face) * size_t(ps),
                            payload.data() + kEditFaceHeaderSize, size_t(ps));
                const uint32_t word = Load32(payload.data() + 4 + kFaceInfoSize);
                FaceEdit e;
                e.constant = fi.constant;
                e.block.pos = payloadPos + kEditFaceHeaderSize + uint64_t(ps);
                e.block.size = word & 0x3fffffffu;
                e.block.encoding = Encoding(word >> 30);
                if (!fi.constant && e.block.size > size - kEditFaceHeaderSize - uint64_t(ps))
                    Fail(what + ": its face data (" + ByteCount(e.block.size) +
                         ") runs past the edit");
                edits_[face] = e;
            } else if (type == kEditMetaData) {
                if (size < kEditMetaHeaderSize)
                    Fail(what + ": " + ByteCount(size) + " cannot hold a meta data edit");
                metaEdits_.push_back({payloadPos + kEditMetaHeaderSize, Load32(payload.data()),
                                      Load32(payload.data() + 4)});
                if (metaEdits_.back().zipSize > size - kEditMetaHeaderSize)
                    Fail(what + ": its meta data runs past the edit");
            }  // other edit types are for future versions: skipped, as Ptex does
        }
    }

    /// Parses meta data entries from an inflated block. Large entries (`large`) carry a zip
    /// size and their data lies in the file from *lmdPos on.
    void ParseMeta(const std::vector<uint8_t>& buf, const std::string& what, bool large,
                   uint64_t* lmdPos) {
        size_t p = 0;
        auto need = [&](size_t n) {
            if (n > buf.size() - p) Fail(what + ": an entry runs past the block's end");
        };
        while (p < buf.size()) {
            need(1);
            const size_t keySize = buf[p++];
            if (keySize == 0) Fail(what + ": an entry has an empty key");
            need(keySize + 5 + (large ? 4 : 0));
            MetaEntry e;
            const char* key = reinterpret_cast<const char*>(buf.data() + p);
            e.key.assign(key, strnlen(key, keySize));
            p += keySize;
            if (buf[p] > 5)
                Fail(what + ": entry '" + Excerpt(e.key) + "' has unknown type " +
                     std::to_string(buf[p]));
            e.type = MetaType(buf[p++]);
            const uint32_t dataSize = Load32(buf.data() + p);
            p += 4;
            std::vector<uint8_t> largeData;
            const uint8_t* data;
            if (large) {
                const uint32_t zipSize = Load32(buf.data() + p);
                p += 4;
                largeData = InflateBlock(*lmdPos, zipSize, dataSize,
                                         "large meta data '" + Excerpt(e.key) + "'");
                *lmdPos += zipSize;
                if (*lmdPos > lmdDataPos_ + h_.lmdDataSize)
                    Fail("large meta data '" + Excerpt(e.key) +
                         "' runs past the large meta data block");
                data = largeData.data();
            } else {
                need(dataSize);
                data = buf.data() + p;
                p += dataSize;
            }
            const int size = MetaTypeSize(e.type);
            if (dataSize % uint32_t(size) != 0)
                Fail(what + ": entry '" + Excerpt(e.key) + "' has " + ByteCount(dataSize) +
                     ", not a whole number of " + Name(e.type) + " values");
            if (e.type == MetaType::String) {
                const char* s = reinterpret_cast<const char*>(data);
                e.text.assign(s, strnlen(s, dataSize));
            } else {
                e.numbers.reserve(dataSize / uint32_t(size));
                for (uint32_t i = 0; i < dataSize; i += uint32_t(size)) {
                    const uint8_t* v = data + i;
                    double x = 0;
                    switch (e.type) {
                        case MetaType::Int8:
                            x = int8_t(v[0]);
                            break;
                        case MetaType::Int16:
                            x = int16_t(Load16(v));
                            break;
                        case MetaType::Int32:
                            x = int32_t(Load32(v));
                            break;
                        case MetaType::Float: {
                            float f;
                            std::memcpy(&f, v, 4);
                            x = f;
                            break;
                        }
                        default: {
                            uint64_t bits = Load64(v);
                            std::memcpy(&x, &bits, 8);
                        }
                    }
                    e.numbers.push_back(x);
                }
            }
            im_->meta.push_back(std::move(e));
        }
    }

    void ReadMetaData() {
        if (h_.metaMemSize > 0)
            ParseMeta(InflateBlock(metaPos_, h_.metaZipSize, h_.metaMemSize, "the meta data"),
                      "the meta data", false, nullptr);
        if (h_.lmdHeaderMemSize > 0) {
            uint64_t lmdPos = lmdDataPos_;
            ParseMeta(InflateBlock(lmdHeaderPos_, h_.lmdHeaderZipSize, h_.lmdHeaderMemSize,
                                   "the large meta data headers"),
                      "the large meta data headers", true, &lmdPos);
        }
        for (const MetaEditBlock& e : metaEdits_)
            ParseMeta(InflateBlock(e.pos, e.zipSize, e.memSize, "a meta data edit"),
                      "a meta data edit", false, nullptr);
    }

    /// Adds the tiles of one face level, from a file block (or the face's constant pixel).
    void PlanLevel(int face, int level, Res res, const FileBlock* block, bool stored,
                   bool straight) {
        LevelData l;
        l.res = res;
        l.tileRes = res;
        l.firstTile = uint32_t(im_->tiles.size());
        l.stored = stored;
        l.straight = straight;
        const std::string what = "face " + std::to_string(face) + " level " + std::to_string(level);
        if (!block) {  // the constant block's pixel
            AddConstTile(ConstPixel(face));
        } else if (block->encoding == kTiled) {
            const std::span<const uint8_t> b = Block(block->pos, block->size, what);
            if (b.size() < 6) Fail(what + ": a tiled block of " + ByteCount(b.size()));
            l.tileRes.ulog2 = int8_t(b[0]);
            l.tileRes.vlog2 = int8_t(b[1]);
            const uint32_t headerSize = Load32(b.data() + 2);
            if (l.tileRes.ulog2 < 0 || l.tileRes.vlog2 < 0 || l.tileRes.ulog2 > res.ulog2 ||
                l.tileRes.vlog2 > res.vlog2)
                Fail(what + ": tiles of 2^" + std::to_string(l.tileRes.ulog2) + " x 2^" +
                     std::to_string(l.tileRes.vlog2) + " texels do not divide its 2^" +
                     std::to_string(res.ulog2) + " x 2^" + std::to_string(res.vlog2));
            const uint64_t ntiles =
                uint64_t(1) << ((res.ulog2 - l.tileRes.ulog2) + (res.vlog2 - l.tileRes.vlog2));
            if (headerSize > b.size() - 6) Fail(what + ": its tile headers run past the block");
            // Every tile takes at least a byte of the block.
            if (ntiles > b.size())
                Fail(what + ": " + std::to_string(ntiles) + " tiles cannot fit in its " +
                     ByteCount(b.size()));
            const std::vector<uint8_t> headers = InflateBlock(
                block->pos + 6, headerSize, ntiles * kFaceDataHeaderSize, what + "'s tile headers");
            const std::vector<FileBlock> tiles =
                Blocks(headers, uint32_t(ntiles), block->pos + 6 + headerSize,
                       block->pos + block->size, what + "'s tiles");
            for (size_t i = 0; i < tiles.size(); ++i) {
                if (tiles[i].encoding == kTiled) Fail(what + ": a tile is itself tiled");
                AddTile(tiles[i], l.tileRes, what + " tile " + std::to_string(i));
            }
        } else {
            AddTile(*block, res, what);
        }
        im_->levels.push_back(l);
    }

    const uint8_t* ConstPixel(int face) const {
        return im_->constData.data() + size_t(face) * size_t(im_->pixelSize);
    }

    /// A constant tile whose pixel is copied from `pixel` once the arena exists.
    void AddConstTile(const uint8_t* pixel) {
        im_->tiles.push_back({arenaSize_, true});
        constCopies_.push_back({pixel, arenaSize_});
        arenaSize_ += uint64_t(im_->pixelSize);
    }

    void AddTile(const FileBlock& b, Res res, const std::string& what) {
        const uint64_t ps = uint64_t(im_->pixelSize);
        if (b.encoding == kConstant) {
            const std::span<const uint8_t> px = Block(b.pos, b.size, what);
            if (px.size() < ps)
                Fail(what + ": a constant block of " + ByteCount(px.size()) + ", a pixel takes " +
                     ByteCount(ps));
            AddConstTile(px.data());
            return;
        }
        const uint64_t bytes = (uint64_t(1) << (res.ulog2 + res.vlog2)) * ps;
        Block(b.pos, b.size, what);
        if (!PlausibleInflate(b.size, bytes))
            Fail(what + ": " + ByteCount(bytes) + " of texels cannot come from " +
                 ByteCount(b.size) + " of zlib data");
        im_->tiles.push_back({arenaSize_, false});
        jobs_.push_back({b, res, arenaSize_, what});
        maxTileBytes_ = std::max(maxTileBytes_, bytes);
        arenaSize_ += bytes;
    }

    void PlanLevels() {
        const int nfaces = im_->header.numFaces;
        std::vector<std::vector<FileBlock>> blocks(levelInfo_.size());
        for (size_t k = 0; k < levelInfo_.size(); ++k) blocks[k] = LevelBlocks(int(k));
        const std::vector<FaceInfo> original = OriginalFaces();
        im_->firstLevel.assign(size_t(nfaces) + 1, 0);
        for (int f = 0; f < nfaces; ++f) {
            im_->firstLevel[size_t(f)] = uint32_t(im_->levels.size());
            const FaceInfo& fi = im_->faces[size_t(f)];
            const auto edit = edits_.find(uint32_t(f));
            // One texel is the constant block's value, as for a constant face (Ptex does so).
            if (fi.constant || (fi.res.ulog2 == 0 && fi.res.vlog2 == 0)) {
                PlanLevel(f, 0, fi.res, nullptr, true, true);
                continue;
            }
            if (edit != edits_.end()) {
                PlanLevel(f, 0, fi.res, &edit->second.block, true, true);
            } else {
                PlanLevel(f, 0, fi.res, &blocks[0][size_t(f)], true, true);
                const uint32_t r = rank_[size_t(f)];
                for (size_t k = 1; k < levelInfo_.size() && r < levelInfo_[k].numFaces; ++k) {
                    const Res res{int8_t(original[size_t(f)].res.ulog2 - int(k)),
                                  int8_t(original[size_t(f)].res.vlog2 - int(k))};
                    if (res.ulog2 < 0 || res.vlog2 < 0)
                        Fail("level " + std::to_string(k) + " holds face " + std::to_string(f) +
                             ", whose 2^" + std::to_string(fi.res.ulog2) + " x 2^" +
                             std::to_string(fi.res.vlog2) + " texels cannot be halved " +
                             std::to_string(k) + " times");
                    PlanLevel(f, int(k), res, &blocks[k][r], true, false);
                }
            }
            // Levels the file lacks (no mip maps written, or an edited face) are reduced here,
            // down to where Ptex's writer stops.
            const int want = 1 + NaturalReductions(fi);
            const int stored = int(im_->levels.size() - im_->firstLevel[size_t(f)]);
            for (int k = stored; k < want; ++k) {
                const Res res{int8_t(fi.res.ulog2 - k), int8_t(fi.res.vlog2 - k)};
                LevelData l;
                l.res = l.tileRes = res;
                l.firstTile = uint32_t(im_->tiles.size());
                l.stored = false;
                l.straight = false;
                im_->tiles.push_back({arenaSize_, false});
                arenaSize_ += (uint64_t(1) << (res.ulog2 + res.vlog2)) * uint64_t(im_->pixelSize);
                im_->levels.push_back(l);
            }
        }
        im_->firstLevel[size_t(nfaces)] = uint32_t(im_->levels.size());
    }

    /// Face infos as the levels were written (edits replace them afterwards).
    std::vector<FaceInfo> OriginalFaces() const {
        if (edits_.empty()) return im_->faces;
        const std::vector<uint8_t> raw =
            InflateBlock(faceInfoPos_, h_.faceInfoSize,
                         uint64_t(im_->header.numFaces) * kFaceInfoSize, "the face info block");
        std::vector<FaceInfo> faces(size_t(im_->header.numFaces));
        for (size_t f = 0; f < faces.size(); ++f)
            faces[f] = ParseFaceInfo(raw.data() + f * kFaceInfoSize);
        return faces;
    }

    void Decode() {
        Allocate(im_->texels, arenaSize_, "the texture's texels");
        const size_t ps = size_t(im_->pixelSize);
        for (const auto& [pixel, offset] : constCopies_)
            std::memcpy(im_->texels.data() + offset, pixel, ps);
        std::vector<uint8_t> planar;
        Allocate(planar, maxTileBytes_, "a face's texels");
        const DataType type = im_->header.dataType;
        const size_t vs = size_t(DataSize(type));
        const int nchan = im_->header.numChannels;
        for (const InflateJob& job : jobs_) {
            const size_t texels = size_t(1) << (job.res.ulog2 + job.res.vlog2);
            const std::span<uint8_t> buf(planar.data(), texels * ps);
            const std::string err = Inflate(Block(job.block.pos, job.block.size, "a face"), buf);
            if (!err.empty()) Fail(job.what + ": " + err);
            if (job.block.encoding == kDiffZipped) UndoDifferences(buf, type);
            uint8_t* dst = im_->texels.data() + job.offset;
            switch (vs) {  // a fixed-size copy per value: the loop is most of the decoding
                case 1:
                    Interleave<1>(buf.data(), dst, texels, nchan);
                    break;
                case 2:
                    Interleave<2>(buf.data(), dst, texels, nchan);
                    break;
                default:
                    Interleave<4>(buf.data(), dst, texels, nchan);
            }
        }
    }

    /// Planar (channel after channel) to interleaved, `n` texels of `nchan` values of VS bytes.
    template <size_t VS>
    static void Interleave(const uint8_t* src, uint8_t* dst, size_t n, int nchan) {
        const size_t ps = VS * size_t(nchan);
        for (int c = 0; c < nchan; ++c, src += n * VS)
            for (size_t i = 0; i < n; ++i)
                std::memcpy(dst + i * ps + size_t(c) * VS, src + i * VS, VS);
    }

    static void UndoDifferences(std::span<uint8_t> buf, DataType type) {
        if (type == DataType::UInt8) {
            uint8_t prev = 0;
            for (uint8_t& v : buf) v = prev = uint8_t(v + prev);
        } else if (type == DataType::UInt16) {
            uint16_t prev = 0;
            for (size_t i = 0; i + 1 < buf.size(); i += 2) {
                prev = uint16_t(Load16(&buf[i]) + prev);
                buf[i] = uint8_t(prev), buf[i + 1] = uint8_t(prev >> 8);
            }
        }  // Ptex differences integer types only
    }

    /// Fills the levels the reader makes, each a 2x2 box reduction of the level above it.
    /// Colour is premultiplied by alpha, as Ptex's stored reductions are.
    void Reduce() {
        const Header& hd = im_->header;
        const int nchan = hd.numChannels, alpha = hd.alphaChannel;
        const bool triangle = hd.meshType == MeshType::Triangle;
        for (int f = 0; f < hd.numFaces; ++f) {
            for (int k = 1; k < im_->NumLevels(f); ++k) {
                const LevelData& dst = im_->Level(f, k);
                if (dst.stored) continue;
                const LevelData& src = im_->Level(f, k - 1);
                uint8_t* out = im_->texels.data() + im_->tiles[dst.firstTile].offset;
                for (int t = 0; t < dst.res.V(); ++t)
                    for (int s = 0; s < dst.res.U(); ++s) {
                        for (int c = 0; c < nchan; ++c) {
                            const auto get = [&](int x, int y) {
                                const uint8_t* p = im_->Pixel(src, x, y);
                                float v = ChannelToFloat(p, c, hd.dataType);
                                if (src.straight && alpha >= 0 && c != alpha)
                                    v *= ChannelToFloat(p, alpha, hd.dataType);
                                return v;
                            };
                            FloatToChannel(ReducedTexel(triangle, src.res.U(), s, t, get),
                                           out + (size_t(t) * size_t(dst.res.U()) + size_t(s)) *
                                                     size_t(im_->pixelSize),
                                           c, hd.dataType);
                        }
                    }
            }
        }
    }

    struct LevelInfo {
        uint64_t pos, dataSize;
        uint32_t headerSize, numFaces;
    };
    struct MetaEditBlock {
        uint64_t pos;
        uint32_t zipSize, memSize;
    };

    std::span<const uint8_t> file_;
    std::shared_ptr<Texture::Impl> im_;
    RawHeader h_;
    uint64_t faceInfoPos_ = 0, constDataPos_ = 0, levelInfoPos_ = 0, levelDataPos_ = 0,
             metaPos_ = 0, lmdHeaderPos_ = 0, lmdDataPos_ = 0, editPos_ = 0;
    std::vector<uint32_t> order_, rank_;
    std::vector<LevelInfo> levelInfo_;
    std::map<uint32_t, FaceEdit> edits_;
    std::vector<MetaEditBlock> metaEdits_;
    std::vector<std::pair<const uint8_t*, uint64_t>> constCopies_;
    std::vector<InflateJob> jobs_;
    uint64_t arenaSize_ = 0, maxTileBytes_ = 0;
};

}  // namespace

Texture Texture::FromBytes(std::span<const uint8_t> bytes, const std::string& name) {
    return Texture(Parser(bytes, name).Run());
}

Texture Texture::Open(const std::string& path) {
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in) throw InputError(path, "cannot open the file");
    const std::streamoff size = in.tellg();
    if (size < 0) throw InputError(path, "cannot read the file");
    std::vector<uint8_t> bytes;
    try {
        bytes.resize(size_t(size));
    } catch (const std::bad_alloc&) {
        throw InputError(path,
                         "the file (" + ByteCount(uint64_t(size)) + ") does not fit in memory");
    }
    in.seekg(0);
    if (!in.read(reinterpret_cast<char*>(bytes.data()), size))
        throw InputError(path, "cannot read the file");
    return FromBytes(bytes, path);
}

const std::string& Texture::Path() const {
    return impl_->path;
}
uint64_t Texture::FileBytes() const {
    return impl_->fileBytes;
}
const Header& Texture::GetHeader() const {
    return impl_->header;
}
int Texture::NumFaces() const {
    return impl_->header.numFaces;
}
int Texture::NumChannels() const {
    return impl_->header.numChannels;
}
const FaceInfo& Texture::Face(int face) const {
    return impl_->faces[size_t(face)];
}
const std::vector<MetaEntry>& Texture::MetaData() const {
    return impl_->meta;
}
const MetaEntry* Texture::Meta(std::string_view key) const {
    for (auto it = impl_->meta.rbegin(); it != impl_->meta.rend(); ++it)
        if (it->key == key) return &*it;
    return nullptr;
}
const std::vector<FileLevel>& Texture::FileLevels() const {
    return impl_->fileLevels;
}
size_t Texture::Bytes() const {
    const Impl& im = *impl_;
    return sizeof(Impl) + im.texels.capacity() + im.constData.capacity() +
           im.faces.capacity() * sizeof(FaceInfo) + im.levels.capacity() * sizeof(LevelData) +
           im.tiles.capacity() * sizeof(TileRef) + im.firstLevel.capacity() * sizeof(uint32_t);
}
int Texture::NumLevels(int face) const {
    return impl_->NumLevels(face);
}
Res Texture::LevelRes(int face, int level) const {
    return impl_->Level(face, level).res;
}
bool Texture::LevelStored(int face, int level) const {
    return impl_->Level(face, level).stored;
}

}  // namespace texcache::ptex
