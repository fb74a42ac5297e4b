// SPDX-License-Identifier: Apache-2.0
// The module texcache_oiio: image_file.h's calls for formats other than EXR, implemented with
// OpenImageIO. Built as a shared module of its own and opened with dlopen (image_file.cpp), so
// that OpenImageIO's libraries are loaded only by processes that read or write such a file.
#include <memory>

#include <OpenImageIO/imageio.h>

#include "renderer/image/image_file.h"

namespace {

OIIO_NAMESPACE_USING
using texcache::internal::ImageAttribute;
using texcache::internal::ImageFile;
using texcache::internal::ImageHeader;

TypeDesc TypeOf(ImageAttribute::Kind k) {
    switch (k) {
        case ImageAttribute::Kind::Float:
            return TypeFloat;
        case ImageAttribute::Kind::Vec3:
            return TypeVector;
        case ImageAttribute::Kind::Matrix44:
            return TypeMatrix44;
    }
    return TypeFloat;
}

bool Write(const std::string& path, const char* format, const ImageFile& f, std::string* error) {
    auto out = ImageOutput::create(format);
    if (!out) {
        *error = OIIO::geterror();
        return false;
    }
    const bool bytes = !f.bytes.empty();
    ImageSpec spec(f.width, f.height, f.channels, bytes ? TypeDesc::UINT8 : TypeDesc::FLOAT);
    if (!f.channelNames.empty()) spec.channelnames = f.channelNames;
    spec.alpha_channel = f.alphaChannel;
    if (!f.colorSpace.empty()) spec.attribute("oiio:ColorSpace", f.colorSpace);
    for (const ImageAttribute& a : f.attributes)
        spec.attribute(a.name, TypeOf(a.kind), a.values.data());
    const void* pixels = bytes ? static_cast<const void*>(f.bytes.data()) : f.pixels.data();
    if (out->open(path, spec) && out->write_image(spec.format, pixels) && out->close()) return true;
    *error = out->geterror();
    if (error->empty()) *error = "write failed";
    return false;
}

void* Open(const std::string& path, ImageHeader* h, std::vector<ImageAttribute>* attributes,
           std::string* error) {
    auto in = ImageInput::open(path);
    if (!in) {
        *error = OIIO::geterror();
        if (error->empty()) *error = "unknown format";
        return nullptr;
    }
    const ImageSpec& spec = in->spec();
    h->width = spec.width;
    h->height = spec.height;
    h->channels = spec.nchannels;
    h->rawBytes = spec.image_bytes(true);
    h->floatPixels = spec.format.is_floating_point();
    h->colorSpace = spec.get_string_attribute("oiio:ColorSpace");
    h->channelNames = spec.channelnames;
    if (attributes)
        for (ImageAttribute& a : *attributes) {
            a.values.assign(a.kind == ImageAttribute::Kind::Matrix44 ? 16
                            : a.kind == ImageAttribute::Kind::Vec3   ? 3
                                                                     : 1,
                            0.0f);
            a.found = spec.getattribute(a.name, TypeOf(a.kind), a.values.data());
        }
    return in.release();
}

bool Read(void* reader, int channels, float* out, std::string* error) {
    auto* in = static_cast<ImageInput*>(reader);
    if (in->read_image(0, 0, 0, channels, TypeDesc::FLOAT, out)) return true;
    *error = in->geterror();
    if (error->empty()) *error = "read failed";
    return false;
}

void Close(void* reader) {
    std::unique_ptr<ImageInput> in(static_cast<ImageInput*>(reader));
    in->close();
}

const texcache::internal::ImageModuleCalls kCalls{Open, Read, Close, Write};

}  // namespace

extern "C" __attribute__((visibility("default"))) const texcache::internal::ImageModuleCalls*
texcache_image_module_calls() {
    return &kCalls;
}
