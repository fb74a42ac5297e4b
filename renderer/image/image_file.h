// SPDX-License-Identifier: Apache-2.0
// Image files as image.cpp and frame_buffers_exr.cpp read and write them. Internal to renderer/.
//
// Why OpenImageIO is not linked: Debian's build of it needs ~260 shared libraries (OpenCV,
// FFmpeg, GDAL, Poppler, ...), and binding them makes every process that links the renderer
// spend ~0.3 s of CPU in the dynamic loader before main(): each `texcache` command, and each of
// the hundreds of test processes CTest starts (`render_test --gtest_list_tests` shows it against
// the cache library's tests, which link no OpenImageIO). So:
//   - EXR, the renderer's own format (every render's output, the environment maps, the frame
//     buffers), is read and written with OpenEXR directly (a handful of libraries);
//   - 8-bit PNG, the picture beside every render's EXR, is written with libpng;
//   - every other read or write (PNG and other textures read, HDR) goes through OpenImageIO in
//     the module texcache_oiio (image_file_oiio.cpp), opened with dlopen on first use.
// A render never loads OpenImageIO unless its scene reads such a texture.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace texcache::internal {

/// A float attribute of an image's header (EXR: FloatAttribute, V3fAttribute, M44fAttribute).
struct ImageAttribute {
    enum class Kind { Float, Vec3, Matrix44 } kind = Kind::Float;
    std::string name;
    std::vector<float> values;  ///< 1, 3 or 16 values (a matrix in the order it was written)
    bool found = false;         ///< reading: whether the file had it
};

/// An image as it goes to a file.
struct ImageFile {
    int width = 0, height = 0, channels = 0;
    std::vector<std::string> channelNames;  ///< empty: the format's default names
    std::vector<float> pixels;              ///< interleaved float pixels (unless `bytes` is used)
    std::vector<uint8_t> bytes;             ///< 8-bit pixels instead (PNG)
    int alphaChannel = -1;
    std::string colorSpace;  ///< e.g. "sRGB"; empty: none stated
    std::vector<ImageAttribute> attributes;
};

/// Writes `file` to `path` as `format` ("openexr": zip-compressed float EXR; "png": 8-bit
/// `bytes` with libpng, float pixels through the module; "hdr": through the module). Throws
/// std::runtime_error with the library's message; a partial file may be left behind (callers write
/// temporaries).
void WriteImageFile(const std::string& path, const char* format, const ImageFile& file);

/// What a file's header says.
struct ImageHeader {
    int width = 0, height = 0, channels = 0;
    uint64_t rawBytes = 0;  ///< the pixels' size in the file's own types, uncompressed
    bool floatPixels = false;
    std::string colorSpace;                 ///< as OpenImageIO names it; empty for EXR
    std::vector<std::string> channelNames;  ///< in reading order (see ImageReader)
};

/// Reads a file in two steps, so that a caller can check the header before anything the size of
/// the image is allocated. Channels come beauty first (R, G, B, A), then each layer's in
/// alphabetical order of layers with R, G, B, A first within a layer, as OpenImageIO orders them.
class ImageReader {
public:
    /// Opens `path` and reads its header, and the attributes listed in `*attributes` (their
    /// `found` and `values` set); throws std::runtime_error with the library's message.
    explicit ImageReader(const std::string& path,
                         std::vector<ImageAttribute>* attributes = nullptr);
    ~ImageReader();
    ImageReader(const ImageReader&) = delete;
    ImageReader& operator=(const ImageReader&) = delete;

    const ImageHeader& Header() const { return header_; }
    /// The first `channels` channels of every pixel, interleaved, as float, into `out`
    /// (width * height * channels floats); throws std::runtime_error.
    void Read(int channels, float* out);

    struct Impl;

private:
    ImageHeader header_;
    std::unique_ptr<Impl> impl_;
};

/// The module's table (image_file_oiio.cpp); the module's entry point returns it.
struct ImageModuleCalls {
    /// Opens `path`, fills `header` and the listed attributes; null with *error set on failure.
    void* (*open)(const std::string& path, ImageHeader* header,
                  std::vector<ImageAttribute>* attributes, std::string* error);
    /// Reads the first `channels` channels as float; false with *error set on failure.
    bool (*read)(void* reader, int channels, float* out, std::string* error);
    void (*close)(void* reader);
    /// WriteImageFile for a format other than EXR; false with *error set on failure.
    bool (*write)(const std::string& path, const char* format, const ImageFile& file,
                  std::string* error);
};

}  // namespace texcache::internal
