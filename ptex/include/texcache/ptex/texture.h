// SPDX-License-Identifier: Apache-2.0
// Ptex (.ptx) textures: one texel grid per face of a mesh, read from the file format
// (ptex.us/PtexFile.html). A Texture decodes the whole file when opened and is immutable after:
// lookups are const, lock-free and allocate nothing, so any number of threads may share one.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace texcache::ptex {

/// Face kind of the mesh the texture belongs to (the header's meshtype).
enum class MeshType : uint8_t { Triangle = 0, Quad = 1 };
/// Texel storage type: unsigned integers map [0, max] to [0, 1].
enum class DataType : uint8_t { UInt8 = 0, UInt16 = 1, Half = 2, Float = 3 };
/// What lookups see beyond a face edge that has no neighbour (u border: edges 1 and 3).
enum class BorderMode : uint8_t { Clamp = 0, Black = 1, Periodic = 2 };
/// TangentVector: channels 0 and 1 are a tangent-space vector, rotated when filtering across
/// an edge between faces whose (u,v) frames differ.
enum class EdgeFilterMode : uint8_t { None = 0, TangentVector = 1 };
/// Type of a meta data entry's values.
enum class MetaType : uint8_t { String = 0, Int8 = 1, Int16 = 2, Int32 = 3, Float = 4, Double = 5 };

/// Lowercase names, as `ptex info` prints them ("quad", "uint8", "clamp", "tanvec", "int32").
const char* Name(MeshType t);
const char* Name(DataType t);
const char* Name(BorderMode m);
const char* Name(EdgeFilterMode m);
const char* Name(MetaType t);
/// Bytes per channel value of a data type.
int DataSize(DataType t);

/// A face's texel grid size as powers of two.
struct Res {
    int8_t ulog2 = 0, vlog2 = 0;
    /// Texels along u and along v.
    int U() const { return 1 << ulog2; }
    int V() const { return 1 << vlog2; }
    bool operator==(const Res&) const = default;
};

/// One face as the file describes it. Edges are numbered counter-clockwise from the bottom:
/// 0 (v=0), 1 (u=1), 2 (v=1), 3 (u=0); adjFaces[e] is the face across edge e (-1: none) and
/// adjEdges[e] that face's edge. Across a quad edge that meets the two sub-faces of an n-gon,
/// the file names the first sub-face met going counter-clockwise round this face.
struct FaceInfo {
    Res res;
    std::array<int32_t, 4> adjFaces{-1, -1, -1, -1};
    std::array<uint8_t, 4> adjEdges{0, 0, 0, 0};
    bool constant = false;              ///< one value for the whole face (the constant block)
    bool subface = false;               ///< one of the n quad sub-faces of a non-quad face
    bool hasEdits = false;              ///< replaced by an edit appended to the file
    bool neighborhoodConstant = false;  ///< it and its neighbours hold one value (a writer hint)
};

/// A meta data entry: `text` for strings, `numbers` (each value converted) for the other types.
struct MetaEntry {
    std::string key;
    MetaType type = MetaType::String;
    std::string text;
    std::vector<double> numbers;
};

/// Header fields of a texture file.
struct Header {
    int version = 1;
    int minorVersion = 0;
    MeshType meshType = MeshType::Quad;
    DataType dataType = DataType::UInt8;
    int alphaChannel = -1;  ///< -1: no alpha channel
    int numChannels = 0;
    int numLevels = 0;  ///< mip levels stored in the file (level 0 included)
    int numFaces = 0;
    BorderMode uBorder = BorderMode::Clamp, vBorder = BorderMode::Clamp;
    EdgeFilterMode edgeFilter = EdgeFilterMode::None;
};

/// One stored level of the file: how many faces it holds and its bytes in the file.
struct FileLevel {
    int numFaces = 0;
    uint64_t bytes = 0;
};

/// A decoded Ptex texture. Copies share the same immutable data.
///
/// Levels: level 0 is the face's full resolution; level k halves both sides k times. A face has
/// the levels the file stores for it (Ptex writes them down to 4 texels on the shorter side),
/// and the reader makes the missing ones by 2x2 box reduction when a file has none (or the face
/// was edited). Reductions hold colour premultiplied by alpha when the file has an alpha
/// channel (as Ptex writes them); level 0 and ConstValue hold it as the file does (straight).
class Texture {
public:
    /// Reads and decodes `path`. Throws texcache::InputError naming the file and the problem
    /// (not a Ptex file, truncated, a size or count that the file cannot hold, corrupt zlib
    /// data). Memory is bounded by what the file's bytes can expand to.
    static Texture Open(const std::string& path);
    /// The same from bytes in memory; `name` stands for the file in messages.
    static Texture FromBytes(std::span<const uint8_t> bytes, const std::string& name);

    /// Path (or name) the texture was read from.
    const std::string& Path() const;
    /// Size of the file in bytes.
    uint64_t FileBytes() const;
    const Header& GetHeader() const;
    int NumFaces() const;
    int NumChannels() const;
    /// Face info (after edits), face in [0, NumFaces()).
    const FaceInfo& Face(int face) const;
    /// Meta data entries in file order (edits appended; a later entry overrides an earlier
    /// one with the same key in Meta()'s lookups).
    const std::vector<MetaEntry>& MetaData() const;
    /// The last entry named `key`, or null.
    const MetaEntry* Meta(std::string_view key) const;
    /// Levels as stored in the file.
    const std::vector<FileLevel>& FileLevels() const;
    /// Bytes held by the decoded texels and tables.
    size_t Bytes() const;

    /// Levels with texels for this face (>= 1; 1 for a constant face).
    int NumLevels(int face) const;
    /// Resolution of a face at a level in [0, NumLevels(face)).
    Res LevelRes(int face, int level) const;
    /// True when the face's level came from the file, false when the reader reduced it.
    bool LevelStored(int face, int level) const;
    /// The face's value in the file's constant block (its average; straight colour), as
    /// NumChannels() floats.
    void ConstValue(int face, float* out) const;

    /// Texel (s, t) of a face at a level, converted to float (NumChannels() values); s along u,
    /// t along v, clamped into the level's grid. For a triangle mesh the grid is Ptex's packed
    /// square (texels with s + t >= side are the upside-down triangles, mirrored).
    void Texel(int face, int level, int s, int t, float* out) const;

    /// Mean of a face's texels at a level, per channel (NumChannels() values; stored values as
    /// Texel returns them), computed from the decoded texels.
    void Mean(int face, int level, float* out) const;

    /// Filtered value at (u, v) in [0,1]^2 of a face: bilinear on the mip level whose texels
    /// are `width` wide (in the face's parameter units; <= 0: level 0), blended linearly in
    /// log2 between the two nearest levels, the face's constant value being the last level.
    /// Bilinear taps beyond an edge come from the face across it (the file's adjacency, with
    /// its rotation and the n-gon sub-face halves); beyond a mesh border the border mode
    /// applies; at a corner, the mean of the two ways round it. Colour comes back
    /// premultiplied by alpha when the file has an alpha channel. Triangle meshes: the nearest
    /// triangular texel of each level, within the face. Writes `numChannels` values (-1: all
    /// from `firstChannel`) of the file's channels from `firstChannel` on; channels past the
    /// file's are 0.
    void Lookup(int face, float u, float v, float width, float* out, int firstChannel = 0,
                int numChannels = -1) const;

    struct Impl;  // internal (ptex/src/texture_impl.h)

private:
    explicit Texture(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
    std::shared_ptr<const Impl> impl_;
};

}  // namespace texcache::ptex
