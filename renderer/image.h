// SPDX-License-Identifier: Apache-2.0
// Float images and their files (EXR with AOV layers, tone-mapped sRGB PNG), written atomically.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace texcache {

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

/// Writes .exr (32-bit float, linear: beauty as R,G,B[,A] + each layer as "name.CH") or .png
/// (exposure in stops, clamp, exact sRGB OETF, 8-bit; layers ignored), chosen by extension.
/// Writes "<path>.tmp-<pid>" and renames it, so a failed write never clobbers a good file.
/// Throws InputError naming the path on failure.
void WriteImage(const std::string& path, const Image& beauty,
                const std::vector<ImageLayer>& layers = {}, float exposure = 0.0f);
/// Reads any image OpenImageIO reads as float RGB (1 channel is replicated); throws InputError.
Image ReadImageRGB(const std::string& path);
/// Reads all channels as stored; throws InputError.
Image ReadImage(const std::string& path);
/// Linear value -> 8-bit sRGB (NaN -> 0, +inf -> 255).
uint8_t LinearToSrgb8(float linear);

}  // namespace texcache
