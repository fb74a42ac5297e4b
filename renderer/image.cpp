// SPDX-License-Identifier: Apache-2.0
#include "renderer/image.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <memory>

#include <OpenImageIO/imageio.h>

#include "renderer/atomic_files.h"
#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;
OIIO_NAMESPACE_USING

namespace {

enum class Format { kExr, kPng, kHdr };

struct FormatInfo {
    const char* ext;
    const char* oiioName;  // the OIIO writer, named explicitly: the temporary file's name has no
                           // image extension for OIIO to infer it from
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

// Writes `pixels` with `spec` to the temporary file `group` stages for `path` (own group of one
// when null, committed at once: rename within a directory is atomic, so readers see the old file
// or the complete new one, never a partial one).
void WriteAtomic(const std::string& path, const FormatInfo& fmt, const ImageSpec& spec,
                 const void* pixels, TypeDesc type, AtomicFiles* group) {
    CheckDirectory(path);
    AtomicFiles own;
    AtomicFiles& files = group ? *group : own;
    const std::string tmp = files.Stage(path);
    auto out = ImageOutput::create(fmt.oiioName);
    if (!out) throw InputError(path, "cannot write image: " + OIIO::geterror());
    if (!(out->open(tmp, spec) && out->write_image(type, pixels) && out->close())) {
        const std::string err = out->geterror();
        throw InputError(path, "cannot write image: " + (err.empty() ? "write failed" : err));
    }
    out.reset();
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
        // OIIO would quantize linearly; the sRGB encode is done here. Fewer than 3 channels: grey.
        const int c = bc >= 3 ? 3 : 1;
        const float scale = std::exp2(exposure);
        std::vector<uint8_t> px(n * c);
        for (size_t p = 0; p < n; ++p)
            for (int k = 0; k < c; ++k)
                px[p * c + k] = LinearToSrgb8(beauty.data[p * bc + k] * scale);
        ImageSpec spec(beauty.width, beauty.height, c, TypeDesc::UINT8);
        spec.attribute("oiio:ColorSpace", "sRGB");
        WriteAtomic(path, fmt, spec, px.data(), TypeDesc::UINT8, group);
        return;
    }

    if (fmt.format == Format::kHdr) {
        // Radiance RGBE holds exactly RGB: grey is replicated, alpha dropped.
        std::vector<float> px(n * 3);
        for (size_t p = 0; p < n; ++p)
            for (int k = 0; k < 3; ++k) px[p * 3 + k] = beauty.data[p * bc + (bc >= 3 ? k : 0)];
        ImageSpec spec(beauty.width, beauty.height, 3, TypeDesc::FLOAT);
        WriteAtomic(path, fmt, spec, px.data(), TypeDesc::FLOAT, group);
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
    ImageSpec spec(beauty.width, beauty.height, total, TypeDesc::FLOAT);
    spec.channelnames.clear();
    static const char* kBeauty[] = {"R", "G", "B", "A"};
    for (int k = 0; k < bc; ++k)
        spec.channelnames.push_back(k < 4 ? kBeauty[k] : "C" + std::to_string(k));
    for (const ImageLayer& l : layers)
        for (const std::string& ch : l.channelNames) spec.channelnames.push_back(l.name + "." + ch);
    spec.alpha_channel = bc >= 4 ? 3 : -1;
    spec.attribute("compression", "zip");  // lossless
    std::vector<float> px(n * total);
    for (size_t p = 0; p < n; ++p) {
        float* o = &px[p * total];
        for (int k = 0; k < bc; ++k) *o++ = beauty.data[p * bc + k];
        for (const ImageLayer& l : layers)
            for (int k = 0; k < l.image.channels; ++k)
                *o++ = l.image.data[p * l.image.channels + k];
    }
    WriteAtomic(path, fmt, spec, px.data(), TypeDesc::FLOAT, group);
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
    auto in = ImageInput::open(path);
    if (!in) {
        const std::string err = OIIO::geterror();
        throw InputError(path, "cannot read image: " + (err.empty() ? "unknown format" : err));
    }
    const ImageSpec& spec = in->spec();
    CheckImageSizeClaim(path, spec.width, spec.height, spec.nchannels, spec.image_bytes(true));
    const int channels = maxChannels > 0 ? std::min(spec.nchannels, maxChannels) : spec.nchannels;
    if (encoding) {
        // OIIO names the colour space it read (PNG: "sRGB" unless a gAMA chunk says otherwise);
        // without one, integer pixels are display values and float pixels are linear.
        std::string cs = spec.get_string_attribute("oiio:ColorSpace");
        for (char& c : cs) c = char(std::tolower(static_cast<unsigned char>(c)));
        const bool srgbName = cs.find("srgb") != std::string::npos && cs.find("lin") != 0;
        *encoding = srgbName || (cs.empty() && !spec.format.is_floating_point())
                        ? ColorEncoding::Srgb
                        : ColorEncoding::Linear;
    }
    Image img(spec.width, spec.height, channels);
    if (!in->read_image(0, 0, 0, channels, TypeDesc::FLOAT, img.data.data())) {
        const std::string err = in->geterror();
        throw InputError(path, "cannot read image: " + (err.empty() ? "read failed" : err));
    }
    in->close();
    return img;
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

void SrgbToLinear(Image* img) {
    for (float& v : img->data)
        v = v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

}  // namespace texcache
