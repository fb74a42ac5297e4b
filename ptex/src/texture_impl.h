// SPDX-License-Identifier: Apache-2.0
// The decoded texture: every face's levels as tiles in one byte arena, in the file's data type.
//
// Ownership: Texture holds a shared_ptr<const Impl>; nothing changes it after the parser has
// filled it, so lookups need no locks.
// Layout: a level is a grid of tiles (one tile when the file does not tile the face); a tile is
// either constant (one pixel in the arena) or packed (its texels row-major, channels
// interleaved). Constant faces are one level of one constant tile. Keeping constant tiles as one
// pixel keeps memory within what the file's bytes can expand to.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "format.h"
#include "texcache/ptex/texture.h"

namespace texcache::ptex {

namespace internal {

struct LevelData {
    Res res;
    Res tileRes;
    uint32_t firstTile = 0;
    bool stored = true;    ///< from the file (false: reduced by the reader)
    bool straight = true;  ///< colour not premultiplied (level 0; reductions are)
};

struct TileRef {
    uint64_t offset = 0;  ///< into the arena
    bool constant = false;
};

}  // namespace internal

struct Texture::Impl {
    std::string path;
    uint64_t fileBytes = 0;
    Header header;
    int pixelSize = 0;
    std::vector<FaceInfo> faces;
    std::vector<uint8_t> constData;  ///< pixelSize bytes per face
    std::vector<MetaEntry> meta;
    std::vector<FileLevel> fileLevels;
    std::vector<uint32_t> firstLevel;  ///< face f's levels: levels[firstLevel[f], firstLevel[f+1])
    std::vector<internal::LevelData> levels;
    std::vector<internal::TileRef> tiles;
    std::vector<uint8_t> texels;  ///< the arena

    const internal::LevelData& Level(int face, int level) const {
        return levels[firstLevel[face] + uint32_t(level)];
    }
    int NumLevels(int face) const { return int(firstLevel[face + 1] - firstLevel[face]); }
    /// Stored pixel of texel (s, t), both inside the level.
    const uint8_t* Pixel(const internal::LevelData& l, int s, int t) const {
        const int tu = l.tileRes.ulog2, tv = l.tileRes.vlog2;
        const uint32_t tile = uint32_t(t >> tv) << (l.res.ulog2 - tu) | uint32_t(s >> tu);
        const internal::TileRef& ref = tiles[l.firstTile + tile];
        if (ref.constant) return texels.data() + ref.offset;
        const size_t inTile = (size_t(t & ((1 << tv) - 1)) << tu) + size_t(s & ((1 << tu) - 1));
        return texels.data() + ref.offset + inTile * size_t(pixelSize);
    }
};

}  // namespace texcache::ptex
