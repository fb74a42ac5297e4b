// SPDX-License-Identifier: Apache-2.0
// Float images and their files (EXR with AOV layers, tone-mapped sRGB PNG, Radiance HDR),
// written atomically. OpenImageIO stays in image.cpp so users of this header need not find it.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace texcache {

class AtomicFiles;

struct Image {
    int width = 0, height = 0, channels = 0;
    std::vector<float> data;  ///< interleaved, row-major, row 0 = top of the picture

    Image() = default;
    Image(int w, int h, int c, float fill = 0.0f)
        : width(w), height(h), channels(c), data(size_t(w) * h * c, fill) {}
    float* At(int x, int y) { return &data[(size_t(y) * width + x) * channels]; }
    const float* At(int x, int y) const { return &data[(size_t(y) * width + x) * channels]; }
    size_t NumPixels() const { return size_t(width) * height; }
};

/// An extra EXR layer (AOV), e.g. {"albedo", img, {"R","G","B"}}.
struct ImageLayer {
    std::string name;
    Image image;
    std::vector<std::string> channelNames;  ///< size == image.channels
};

/// Writes by extension: .exr (32-bit float, linear; beauty as R,G,B[,A], each layer as "name.CH"),
/// .png (exposure in stops, clamp, exact sRGB OETF, 8-bit; layers and alpha ignored), .hdr
/// (linear RGBE, ~1% precision; layers and alpha ignored). Writes "<path>.tmp-<pid>" and renames it
/// over `path`, so a failed or interrupted write never clobbers a good file; with a `group` the
/// temporary file is the group's and is renamed by its Commit(), together with the group's other
/// files. Throws InputError naming the path.
void WriteImage(const std::string& path, const Image& beauty,
                const std::vector<ImageLayer>& layers = {}, float exposure = 0.0f,
                AtomicFiles* group = nullptr);
/// Throws the InputError WriteImage would throw for this path's extension or missing directory,
/// so a command can reject a bad output name before doing its work.
void CheckImageOutputPath(const std::string& path);
/// How a file's values encode light: linear (EXR, HDR) or through the sRGB OETF (8- and 16-bit
/// PNG, JPEG, ...: display values).
enum class ColorEncoding { Linear, Srgb };
/// Reads any image OpenImageIO reads, as float: the first 3 channels (1 or 2 channels: the first
/// replicated), so channels == 3; values as stored (sRGB files are not decoded), `encoding` (may
/// be null) says which. Throws InputError("path", "cannot read image: ...").
Image ReadImageRGB(const std::string& path, ColorEncoding* encoding = nullptr);
/// Reads all channels as stored in the file (environment maps, AOVs); throws InputError.
Image ReadImage(const std::string& path);
/// The pixels an image file's header claims (width x height), without reading them, so that a
/// command can check what decoding would take first; 0 when the file cannot be read (reading it
/// then says why).
uint64_t ImagePixelsClaimed(const std::string& path);
/// Decodes sRGB-encoded values in [0, 1] to linear light in place (exact inverse OETF).
void SrgbToLinear(Image* img);
/// The same for one value.
float SrgbToLinear(float v);
/// Throws InputError unless an image file's header claims a size worth allocating: at most
/// kMaxImagePixels pixels and 2^30 values, and at most kMaxCompression raw pixel bytes per byte
/// of the file beyond the first 256 MiB (no codec OpenImageIO reads packs pixels tighter than
/// deflate's 1032:1), so a 23 KB file claiming 46340x46340 pixels is rejected before anything
/// is allocated, in time and memory proportional to the file.
void CheckImageSizeClaim(const std::string& path, int width, int height, int channels,
                         uint64_t rawBytes);
constexpr uint64_t kMaxImagePixels = uint64_t(16384) * 16384;  ///< --resolution's limit
constexpr uint64_t kMaxCompression = 4096;

/// Linear value -> 8-bit sRGB through the exact sRGB OETF (NaN and <= 0 -> 0, >= 1 and +inf ->
/// 255).
uint8_t LinearToSrgb8(float linear);

}  // namespace texcache
