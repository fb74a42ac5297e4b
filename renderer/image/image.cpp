// SPDX-License-Identifier: Apache-2.0
#include "renderer/image/image.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <memory>

#include "renderer/image/atomic_files.h"
#include "renderer/image/image_file.h"
#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;
using internal::ImageFile;

namespace {

enum class Format { kExr, kPng, kHdr };

struct FormatInfo {
    const char* ext;
    const char* writer;  // WriteImageFile's format, named explicitly: the temporary file's name
                         // has no image extension to infer it from
    Format format;
};
constexpr FormatInfo kFormats[] = {{".exr", "openexr", Format::kExr},
                                   {".png", "png", Format::kPng},
                                   {".hdr", "hdr", Format::kHdr}};

std::string LowerExtension(const std::string& path) {
    std::string e = fs::path(path).extension().string();
    for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
    return e;
}

const FormatInfo& FormatOf(const std::string& path) {
    const std::string ext = LowerExtension(path);
    for (const FormatInfo& f : kFormats)
        if (ext == f.ext) return f;
    throw InputError(
        path, "cannot write image: unsupported type '" + ext + "' (supported: .exr, .png, .hdr)");
}

void CheckDirectory(const std::string& path) {
    const fs::path dir = fs::path(path).parent_path();
    if (!dir.empty() && !fs::is_directory(dir))
        throw InputError(path,
                         "cannot write image: directory '" + dir.string() + "' does not exist");
}

// Writes `file` to the temporary file `group` stages for `path` (own group of one when null,
// committed at once: rename within a directory is atomic, so readers see the old file or the
// complete new one, never a partial one).
void WriteAtomic(const std::string& path, const FormatInfo& fmt, const ImageFile& file,
                 AtomicFiles* group) {
    CheckDirectory(path);
    AtomicFiles own;
    AtomicFiles& files = group ? *group : own;
    const std::string tmp = files.Stage(path);
    try {
        internal::WriteImageFile(tmp, fmt.writer, file);
    } catch (const std::exception& e) {
        const std::string err = e.what();
        throw InputError(path, "cannot write image: " + (err.empty() ? "write failed" : err));
    }
    if (!group) own.Commit();
}

}  // namespace

uint8_t LinearToSrgb8(float v) {
    if (!(v > 0.0f)) return 0;  // also NaN
    if (v >= 1.0f) return 255;  // also +inf
    const float s = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
    return uint8_t(std::lround(s * 255.0f));
}

void CheckImageOutputPath(const std::string& path) {
    FormatOf(path);
    CheckDirectory(path);
}

void WriteImage(const std::string& path, const Image& beauty, const std::vector<ImageLayer>& layers,
                float exposure, AtomicFiles* group) {
    // Validate everything before the temporary file exists, so a bad call leaves no trace.
    const FormatInfo& fmt = FormatOf(path);
    if (beauty.width <= 0 || beauty.height <= 0 || beauty.channels <= 0 ||
        beauty.data.size() != beauty.NumPixels() * beauty.channels)
        throw InputError(path, "cannot write image: empty or inconsistent image (" +
                                   std::to_string(beauty.width) + "x" +
                                   std::to_string(beauty.height) + "x" +
                                   std::to_string(beauty.channels) + ")");
    const size_t n = beauty.NumPixels();
    const int bc = beauty.channels;

    if (fmt.format == Format::kPng) {
        // OpenImageIO would quantize linearly; the sRGB encode is done here. Fewer than 3 channels:
        // grey.
        const int c = bc >= 3 ? 3 : 1;
        const float scale = std::exp2(exposure);
        std::vector<uint8_t> px(n * c);
        for (size_t p = 0; p < n; ++p)
            for (int k = 0; k < c; ++k)
                px[p * c + k] = LinearToSrgb8(beauty.data[p * bc + k] * scale);
        ImageFile f;
        f.width = beauty.width, f.height = beauty.height, f.channels = c;
        f.bytes = std::move(px);
        f.colorSpace = "sRGB";
        WriteAtomic(path, fmt, f, group);
        return;
    }

    if (fmt.format == Format::kHdr) {
        // Radiance RGBE holds exactly RGB: grey is replicated, alpha dropped.
        std::vector<float> px(n * 3);
        for (size_t p = 0; p < n; ++p)
            for (int k = 0; k < 3; ++k) px[p * 3 + k] = beauty.data[p * bc + (bc >= 3 ? k : 0)];
        ImageFile f;
        f.width = beauty.width, f.height = beauty.height, f.channels = 3;
        f.pixels = std::move(px);
        WriteAtomic(path, fmt, f, group);
        return;
    }

    int total = bc;
    for (const ImageLayer& l : layers) {
        if (l.image.width != beauty.width || l.image.height != beauty.height)
            throw InputError(
                path, "cannot write image: layer '" + l.name + "' is not the size of the image");
        if (l.image.channels <= 0 || int(l.channelNames.size()) != l.image.channels ||
            l.image.data.size() != l.image.NumPixels() * l.image.channels)
            throw InputError(path, "cannot write image: layer '" + l.name +
                                       "' has inconsistent channels or channel names");
        total += l.image.channels;
    }
    ImageFile f;
    f.width = beauty.width, f.height = beauty.height, f.channels = total;
    static const char* kBeauty[] = {"R", "G", "B", "A"};
    for (int k = 0; k < bc; ++k)
        f.channelNames.push_back(k < 4 ? kBeauty[k] : "C" + std::to_string(k));
    for (const ImageLayer& l : layers)
        for (const std::string& ch : l.channelNames) f.channelNames.push_back(l.name + "." + ch);
    f.alphaChannel = bc >= 4 ? 3 : -1;
    f.pixels.resize(n * total);
    for (size_t p = 0; p < n; ++p) {
        float* o = &f.pixels[p * total];
        for (int k = 0; k < bc; ++k) *o++ = beauty.data[p * bc + k];
        for (const ImageLayer& l : layers)
            for (int k = 0; k < l.image.channels; ++k)
                *o++ = l.image.data[p * l.image.channels + k];
    }
    WriteAtomic(path, fmt, f, group);
}

void CheckImageSizeClaim(const std::string& path, int width, int height, int channels,
                         uint64_t rawBytes) {
    const std::string size =
        std::to_string(width) + "x" + std::to_string(height) + "x" + std::to_string(channels);
    if (width <= 0 || height <= 0 || channels <= 0)
        throw InputError(path, "cannot read image: empty image (" + size + ")");
    const uint64_t pixels = uint64_t(width) * uint64_t(height);
    if (pixels > kMaxImagePixels || pixels * uint64_t(channels) > (uint64_t(1) << 30))
        throw InputError(path, "cannot read image: its header claims " + size +
                                   " values, more than the 16384x16384 pixels and 2^30 values "
                                   "read here");
    std::error_code ec;
    const uintmax_t fileBytes = fs::file_size(path, ec);
    constexpr uint64_t kFree = uint64_t(256) << 20;
    if (!ec && rawBytes > kFree && rawBytes / kMaxCompression > fileBytes)
        throw InputError(path, "cannot read image: its header claims " + size + " (" +
                                   std::to_string(rawBytes >> 20) +
                                   " MiB of pixels) but the file "
                                   "has only " +
                                   std::to_string(fileBytes) + " bytes: corrupt or truncated");
}

namespace {

/// The first `maxChannels` channels of `path` (all when 0) as float, checked before allocating.
Image ReadChannels(const std::string& path, int maxChannels, ColorEncoding* encoding) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec))
        throw InputError(path, fs::exists(path, ec) ? "cannot read image: not a regular file"
                                                    : "cannot read image: no such file");
    try {
        internal::ImageReader in(path);
        const internal::ImageHeader& h = in.Header();
        CheckImageSizeClaim(path, h.width, h.height, h.channels, h.rawBytes);
        const int channels = maxChannels > 0 ? std::min(h.channels, maxChannels) : h.channels;
        if (encoding) {
            // OpenImageIO names the colour space it read (PNG: "sRGB" unless a gAMA chunk says
            // otherwise); without one, integer pixels are display values and float pixels are
            // linear.
            std::string cs = h.colorSpace;
            for (char& c : cs) c = char(std::tolower(static_cast<unsigned char>(c)));
            const bool srgbName = cs.find("srgb") != std::string::npos && cs.find("lin") != 0;
            *encoding = srgbName || (cs.empty() && !h.floatPixels) ? ColorEncoding::Srgb
                                                                   : ColorEncoding::Linear;
        }
        Image img(h.width, h.height, channels);
        in.Read(channels, img.data.data());
        return img;
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        const std::string err = e.what();
        throw InputError(path, "cannot read image: " + (err.empty() ? "read failed" : err));
    }
}

}  // namespace

Image ReadImage(const std::string& path) {
    return ReadChannels(path, 0, nullptr);
}

Image ReadImageRGB(const std::string& path, ColorEncoding* encoding) {
    Image src = ReadChannels(path, 3, encoding);
    if (src.channels == 3) return src;
    Image rgb(src.width, src.height, 3);
    for (size_t p = 0; p < src.NumPixels(); ++p)
        for (int k = 0; k < 3; ++k) rgb.data[p * 3 + k] = src.data[p * src.channels];
    return rgb;
}

uint64_t ImagePixelsClaimed(const std::string& path) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) return 0;
    internal::ImageHeader h;
    try {
        h = internal::ImageReader(path).Header();
    } catch (const std::exception&) {
        return 0;
    }
    // A header that lies about its size is refused as such, not as too big to hold.
    CheckImageSizeClaim(path, h.width, h.height, h.channels, h.rawBytes);
    return uint64_t(std::max(h.width, 0)) * uint64_t(std::max(h.height, 0));
}

float SrgbToLinear(float v) {
    return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

void SrgbToLinear(Image* img) {
    for (float& v : img->data) v = SrgbToLinear(v);
}

}  // namespace texcache
