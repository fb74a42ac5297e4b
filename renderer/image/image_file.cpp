// SPDX-License-Identifier: Apache-2.0
#include "renderer/image/image_file.h"

#include <dlfcn.h>
#include <png.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <stdexcept>
#include <tuple>

#include <Imath/ImathMatrix.h>
#include <Imath/ImathVec.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfMatrixAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfVecAttribute.h>
#include <OpenEXR/ImfVersion.h>

namespace texcache::internal {

namespace {

// The module's table, opened on first use (thread-safe) and never closed (callers may hold its
// readers until exit). Throws when it cannot be loaded.
const ImageModuleCalls& Module() {
    static const ImageModuleCalls* calls = nullptr;
    static std::once_flag once;
    static std::string failure;
    std::call_once(once, [] {
        // The build's own module first (tests and build/bin programs), then one beside the
        // executable (an installed or copied program).
        std::vector<std::string> candidates{TEXCACHE_OIIO_MODULE};
        std::error_code ec;
        const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
        if (!ec)
            candidates.push_back(
                (exe.parent_path() / std::filesystem::path(TEXCACHE_OIIO_MODULE).filename())
                    .string());
        for (const std::string& path : candidates) {
            void* module = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
            if (!module) {
                const char* e = dlerror();
                failure += (failure.empty() ? "" : "; ") + std::string(e ? e : path);
                continue;
            }
            using Entry = const ImageModuleCalls* (*)();
            if (auto entry =
                    reinterpret_cast<Entry>(dlsym(module, "texcache_image_module_calls"))) {
                calls = entry();
                return;
            }
            failure += "; " + path + ": no texcache_image_module_calls";
        }
    });
    if (!calls) throw std::runtime_error("cannot load the image module (OpenImageIO): " + failure);
    return *calls;
}

bool IsExr(const std::string& path) {
    char magic[4] = {};
    std::ifstream f(path, std::ios::binary);
    return f.read(magic, 4) && Imf::isImfMagic(magic);
}

size_t ValueCount(ImageAttribute::Kind k) {
    return k == ImageAttribute::Kind::Matrix44 ? 16 : k == ImageAttribute::Kind::Vec3 ? 3 : 1;
}

// OpenImageIO's order of an EXR's channels (the file keeps them sorted by name): the unnamed
// layer first, then layers by name; within a layer R, G, B, A first, then the rest by name.
void SortChannels(std::vector<std::string>* names) {
    auto key = [](const std::string& n) {
        const size_t dot = n.rfind('.');
        const std::string layer = dot == std::string::npos ? "" : n.substr(0, dot);
        const std::string ch = dot == std::string::npos ? n : n.substr(dot + 1);
        static const char* const kFirst[] = {"R", "G", "B", "A"};
        int rank = 4;
        for (int k = 0; k < 4; ++k)
            if (ch == kFirst[k]) rank = k;
        return std::make_tuple(!layer.empty(), layer, rank, ch);
    };
    std::stable_sort(names->begin(), names->end(),
                     [&](const std::string& a, const std::string& b) { return key(a) < key(b); });
}

void WriteExr(const std::string& path, const ImageFile& f) {
    Imf::Header header(f.width, f.height);
    header.compression() = Imf::ZIP_COMPRESSION;  // lossless; 16-line chunks
    for (const ImageAttribute& a : f.attributes) {
        const float* v = a.values.data();
        switch (a.kind) {
            case ImageAttribute::Kind::Float:
                header.insert(a.name, Imf::FloatAttribute(v[0]));
                break;
            case ImageAttribute::Kind::Vec3:
                header.insert(a.name, Imf::V3fAttribute(Imath::V3f(v[0], v[1], v[2])));
                break;
            case ImageAttribute::Kind::Matrix44:
                header.insert(a.name, Imf::M44fAttribute(Imath::M44f(
                                          v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8],
                                          v[9], v[10], v[11], v[12], v[13], v[14], v[15])));
                break;
        }
    }
    Imf::FrameBuffer frame;
    const size_t xStride = sizeof(float) * size_t(f.channels);
    const size_t yStride = xStride * size_t(f.width);
    // OpenEXR reads through non-const pointers; nothing is written to them.
    char* base = reinterpret_cast<char*>(const_cast<float*>(f.pixels.data()));
    for (int c = 0; c < f.channels; ++c) {
        header.channels().insert(f.channelNames[size_t(c)], Imf::Channel(Imf::FLOAT));
        frame.insert(f.channelNames[size_t(c)],
                     Imf::Slice(Imf::FLOAT, base + sizeof(float) * size_t(c), xStride, yStride));
    }
    Imf::OutputFile out(path.c_str(), header);
    out.setFrameBuffer(frame);
    out.writePixels(f.height);
}

/// 8-bit grey or RGB(A) PNG with libpng. Every render writes one beside its EXR by default:
/// through OpenImageIO that costs each process ~0.3 s of CPU loading its libraries (more than a
/// small render itself), libpng costs nothing measurable.
void WritePng(const std::string& path, const ImageFile& f) {
    const int colorType = f.channels == 1   ? PNG_COLOR_TYPE_GRAY
                          : f.channels == 2 ? PNG_COLOR_TYPE_GRAY_ALPHA
                          : f.channels == 3 ? PNG_COLOR_TYPE_RGB
                          : f.channels == 4 ? PNG_COLOR_TYPE_RGB_ALPHA
                                            : -1;
    if (colorType < 0 || f.bytes.size() != size_t(f.width) * size_t(f.height) * size_t(f.channels))
        throw std::runtime_error("PNG: " + std::to_string(f.channels) +
                                 " channels of 8-bit pixels cannot be written");
    std::FILE* file = std::fopen(path.c_str(), "wb");
    if (!file) throw std::runtime_error("cannot open " + path + " for writing");
    // libpng reports errors through longjmp; the message is kept and thrown after cleanup.
    std::string error;
    png_structp png = png_create_write_struct(
        PNG_LIBPNG_VER_STRING, &error,
        [](png_structp p, png_const_charp msg) {
            *static_cast<std::string*>(png_get_error_ptr(p)) = msg;
            png_longjmp(p, 1);
        },
        nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    std::vector<png_bytep> rows(size_t(f.height));
    if (png && info && !setjmp(png_jmpbuf(png))) {
        png_init_io(png, file);
        png_set_IHDR(png, info, png_uint_32(f.width), png_uint_32(f.height), 8, colorType,
                     PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
        if (f.colorSpace == "sRGB")
            png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
        for (int y = 0; y < f.height; ++y)
            rows[size_t(y)] = const_cast<png_bytep>(f.bytes.data()) +
                              size_t(y) * size_t(f.width) * size_t(f.channels);
        png_set_rows(png, info, rows.data());
        png_write_png(png, info, PNG_TRANSFORM_IDENTITY, nullptr);
    } else if (error.empty()) {
        error = "out of memory";
    }
    png_destroy_write_struct(png ? &png : nullptr, info ? &info : nullptr);
    const bool closed = std::fclose(file) == 0;
    if (!error.empty()) throw std::runtime_error("PNG: " + error);
    if (!closed) throw std::runtime_error("cannot finish writing " + path);
}

}  // namespace

void WriteImageFile(const std::string& path, const char* format, const ImageFile& file) {
    if (std::strcmp(format, "openexr") == 0) {
        try {
            WriteExr(path, file);
        } catch (const std::exception& e) {
            throw std::runtime_error(e.what());
        }
        return;
    }
    if (std::strcmp(format, "png") == 0 && !file.bytes.empty()) return WritePng(path, file);
    std::string error;
    if (!Module().write(path, format, file, &error)) throw std::runtime_error(error);
}

struct ImageReader::Impl {
    std::unique_ptr<Imf::InputFile> exr;  // an EXR, read with OpenEXR
    void* module = nullptr;               // any other format: the module's reader
};

ImageReader::ImageReader(const std::string& path, std::vector<ImageAttribute>* attributes)
    : impl_(std::make_unique<Impl>()) {
    if (!IsExr(path)) {
        std::string error;
        impl_->module = Module().open(path, &header_, attributes, &error);
        if (!impl_->module) throw std::runtime_error(error);
        return;
    }
    try {
        impl_->exr = std::make_unique<Imf::InputFile>(path.c_str());
        const Imf::Header& h = impl_->exr->header();
        const Imath::Box2i dw = h.dataWindow();
        header_.width = dw.max.x - dw.min.x + 1;
        header_.height = dw.max.y - dw.min.y + 1;
        uint64_t bytesPerPixel = 0;
        for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
            header_.channelNames.push_back(it.name());
            bytesPerPixel += it.channel().type == Imf::HALF ? 2 : 4;
        }
        SortChannels(&header_.channelNames);
        header_.channels = int(header_.channelNames.size());
        header_.rawBytes = header_.width > 0 && header_.height > 0
                               ? bytesPerPixel * uint64_t(header_.width) * uint64_t(header_.height)
                               : 0;
        header_.floatPixels = true;
        if (attributes)
            for (ImageAttribute& a : *attributes) {
                a.values.assign(ValueCount(a.kind), 0.0f);
                a.found = false;
                if (a.kind == ImageAttribute::Kind::Float) {
                    if (const auto* v = h.findTypedAttribute<Imf::FloatAttribute>(a.name))
                        a.values[0] = v->value(), a.found = true;
                } else if (a.kind == ImageAttribute::Kind::Vec3) {
                    if (const auto* v = h.findTypedAttribute<Imf::V3fAttribute>(a.name))
                        std::copy(&v->value()[0], &v->value()[0] + 3, a.values.begin()),
                            a.found = true;
                } else if (const auto* v = h.findTypedAttribute<Imf::M44fAttribute>(a.name)) {
                    std::copy(&v->value()[0][0], &v->value()[0][0] + 16, a.values.begin());
                    a.found = true;
                }
            }
    } catch (const std::exception& e) {
        throw std::runtime_error(e.what());
    }
}

ImageReader::~ImageReader() {
    if (impl_->module) Module().close(impl_->module);
}

void ImageReader::Read(int channels, float* out) {
    if (impl_->module) {
        std::string error;
        if (!Module().read(impl_->module, channels, out, &error)) throw std::runtime_error(error);
        return;
    }
    try {
        const Imath::Box2i dw = impl_->exr->header().dataWindow();
        const size_t xStride = sizeof(float) * size_t(channels);
        const size_t yStride = xStride * size_t(header_.width);
        // Slices address pixel (x, y) of the data window at base + x * xStride + y * yStride.
        char* base = reinterpret_cast<char*>(out) - ptrdiff_t(dw.min.x) * ptrdiff_t(xStride) -
                     ptrdiff_t(dw.min.y) * ptrdiff_t(yStride);
        Imf::FrameBuffer frame;
        for (int c = 0; c < channels; ++c)
            frame.insert(
                header_.channelNames[size_t(c)],
                Imf::Slice(Imf::FLOAT, base + sizeof(float) * size_t(c), xStride, yStride));
        impl_->exr->setFrameBuffer(frame);
        impl_->exr->readPixels(dw.min.y, dw.max.y);
    } catch (const std::exception& e) {
        throw std::runtime_error(e.what());
    }
}

}  // namespace texcache::internal
