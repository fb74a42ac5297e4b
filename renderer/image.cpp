// SPDX-License-Identifier: Apache-2.0
#include "renderer/image.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>

#include <OpenImageIO/imageio.h>

#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;
OIIO_NAMESPACE_USING

namespace {

std::string Lower(std::string s) {
    for (char& c : s) c = char(std::tolower(c));
    return s;
}

// Writes `pixels` with `spec` to a temporary file next to `path`, then renames it over `path`.
void WriteAtomic(const std::string& path, const ImageSpec& spec, const void* pixels,
                 TypeDesc type) {
    const fs::path dir = fs::path(path).parent_path();
    if (!dir.empty() && !fs::is_directory(dir))
        throw InputError(path,
                         "cannot write image: directory '" + dir.string() + "' does not exist");
    const std::string ext = fs::path(path).extension().string();
    // Keep the real extension last so OIIO picks the right writer for the temporary file.
    const std::string tmp = path + ".tmp-" + std::to_string(::getpid()) + ext;
    auto out = ImageOutput::create(tmp);
    if (!out) throw InputError(path, "cannot write image: " + OIIO::geterror());
    bool ok = out->open(tmp, spec) && out->write_image(type, pixels) && out->close();
    if (!ok) {
        const std::string err = out->geterror();
        out.reset();
        std::error_code ec;
        fs::remove(tmp, ec);
        throw InputError(path, "cannot write image: " + err);
    }
    out.reset();
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        throw InputError(path, "cannot write image: " + ec.message());
    }
}

}  // namespace

uint8_t LinearToSrgb8(float v) {
    if (!(v > 0.0f)) return 0;  // also NaN
    if (v >= 1.0f) return 255;
    const float s = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
    return uint8_t(std::lround(s * 255.0f));
}

void WriteImage(const std::string& path, const Image& beauty, const std::vector<ImageLayer>& layers,
                float exposure) {
    if (beauty.width <= 0 || beauty.height <= 0 || beauty.channels <= 0 ||
        beauty.data.size() != beauty.NumPixels() * beauty.channels)
        throw InputError(path, "refusing to write an empty or inconsistent image");
    const std::string ext = Lower(fs::path(path).extension().string());
    if (ext == ".png") {
        const int c = std::min(beauty.channels, 3) == 1 ? 1 : 3;
        std::vector<uint8_t> px(beauty.NumPixels() * c);
        const float scale = std::exp2(exposure);
        for (size_t p = 0; p < beauty.NumPixels(); ++p)
            for (int k = 0; k < c; ++k)
                px[p * c + k] = LinearToSrgb8(beauty.data[p * beauty.channels + k] * scale);
        ImageSpec spec(beauty.width, beauty.height, c, TypeDesc::UINT8);
        WriteAtomic(path, spec, px.data(), TypeDesc::UINT8);
        return;
    }
    if (ext != ".exr")
        throw InputError(path, "unsupported image type '" + ext + "' (supported: .exr, .png)");
    int total = beauty.channels;
    for (const ImageLayer& l : layers) {
        if (l.image.width != beauty.width || l.image.height != beauty.height ||
            int(l.channelNames.size()) != l.image.channels)
            throw InputError(path, "layer '" + l.name + "' does not match the image size");
        total += l.image.channels;
    }
    ImageSpec spec(beauty.width, beauty.height, total, TypeDesc::FLOAT);
    spec.channelnames.clear();
    static const char* kBeauty[] = {"R", "G", "B", "A"};
    for (int k = 0; k < beauty.channels; ++k)
        spec.channelnames.push_back(k < 4 ? kBeauty[k] : "C" + std::to_string(k));
    for (const ImageLayer& l : layers)
        for (const std::string& ch : l.channelNames) spec.channelnames.push_back(l.name + "." + ch);
    if (beauty.channels >= 4) spec.alpha_channel = 3;
    spec.attribute("compression", "zip");
    std::vector<float> px(beauty.NumPixels() * total);
    for (size_t p = 0; p < beauty.NumPixels(); ++p) {
        float* o = &px[p * total];
        for (int k = 0; k < beauty.channels; ++k) *o++ = beauty.data[p * beauty.channels + k];
        for (const ImageLayer& l : layers)
            for (int k = 0; k < l.image.channels; ++k)
                *o++ = l.image.data[p * l.image.channels + k];
    }
    WriteAtomic(path, spec, px.data(), TypeDesc::FLOAT);
}

Image ReadImage(const std::string& path) {
    if (!fs::exists(path)) throw InputError(path, "cannot read image: no such file");
    auto in = ImageInput::open(path);
    if (!in) throw InputError(path, "cannot read image: " + OIIO::geterror());
    const ImageSpec& spec = in->spec();
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
        throw InputError(path, "cannot read image: empty image");
    Image img(spec.width, spec.height, spec.nchannels);
    if (!in->read_image(0, 0, 0, spec.nchannels, TypeDesc::FLOAT, img.data.data()))
        throw InputError(path, "cannot read image: " + in->geterror());
    in->close();
    return img;
}

Image ReadImageRGB(const std::string& path) {
    Image src = ReadImage(path);
    if (src.channels == 3) return src;
    Image rgb(src.width, src.height, 3);
    for (size_t p = 0; p < src.NumPixels(); ++p)
        for (int k = 0; k < 3; ++k)
            rgb.data[p * 3 + k] = src.data[p * src.channels + (src.channels < 3 ? 0 : k)];
    return rgb;
}

}  // namespace texcache
