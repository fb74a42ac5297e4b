// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/texture.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "renderer/image/image.h"
#include "texcache/error.h"

namespace texcache {

namespace {
bool IsFloatFormat(const std::string& path) {
    auto dot = path.rfind('.');
    std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
    for (auto& ch : ext) ch = char(std::tolower(ch));
    return ext == "exr" || ext == "hdr" || ext == "pfm";
}
}  // namespace

TextureImage::TextureImage(const Texture& desc) : desc_(desc) {
    if (desc.kind == Texture::Kind::Ptex) {
        ptex_ = ptex::Texture::Open(desc.path);
        if (desc.channel >= ptex_->NumChannels())
            throw InputError(desc.path, "channel " + std::to_string(desc.channel) +
                                            " asked for, but the file has " +
                                            std::to_string(ptex_->NumChannels()) + " channels");
        return;
    }
    if (desc.kind != Texture::Kind::Image) return;
    Image img = ReadImageRGB(desc.path);
    // NaN or infinity would make every pixel that samples the texel NaN (a float image can hold
    // them), and a negative colour emits light from a surface: refused, with their count. Lossy
    // float images undershoot a little next to bright texels: down to -1e-3 is clamped to 0.
    size_t nonFinite = 0, negative = 0;
    float lowest = 0.0f;
    for (size_t i = 0; i < img.NumPixels(); ++i) {
        const float* p = &img.data[i * 3];
        const float low = std::min({p[0], p[1], p[2]});
        nonFinite += !std::isfinite(p[0] + p[1] + p[2]);
        negative += std::isfinite(p[0] + p[1] + p[2]) && low < -1e-3f;
        if (std::isfinite(low)) lowest = std::min(lowest, low);
    }
    const std::string of = " of its " + std::to_string(img.NumPixels()) + " texels";
    if (nonFinite > 0)
        throw InputError(desc.path,
                         "texture has NaN or infinite values in " + std::to_string(nonFinite) + of);
    char low[32];
    std::snprintf(low, sizeof low, "%g", double(lowest));
    if (negative > 0)
        throw InputError(desc.path, std::string("texture has negative values (down to ") + low +
                                        ") in " + std::to_string(negative) + of);
    width_ = img.width;
    height_ = img.height;
    texels_.resize(size_t(width_) * height_);
    const bool decode = !IsFloatFormat(desc.path);  // 8-bit images store sRGB-encoded colour
    for (int y = 0; y < height_; ++y)
        for (int x = 0; x < width_; ++x) {
            const float* p = img.At(x, y);
            glm::vec3 c(p[0], p[1], p[2]);
            if (decode) c = {SrgbToLinear(c.x), SrgbToLinear(c.y), SrgbToLinear(c.z)};
            texels_[size_t(y) * width_ + x] = glm::max(c, glm::vec3(0.0f));
        }
}

glm::vec3 TextureImage::Eval(glm::vec2 uv) const {
    if (desc_.kind == Texture::Kind::Checker) {
        const int cx = int(std::floor(uv.x * desc_.scale)),
                  cy = int(std::floor(uv.y * desc_.scale));
        return ((cx + cy) & 1) ? desc_.colorB : desc_.colorA;
    }
    // Bilinear with wrapping; v = 0 is the bottom row of the image (OBJ convention).
    const float x = (uv.x - std::floor(uv.x)) * width_ - 0.5f;
    const float y = (1.0f - (uv.y - std::floor(uv.y))) * height_ - 0.5f;
    const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
    const float fx = x - x0, fy = y - y0;
    auto at = [&](int xi, int yi) {
        xi = ((xi % width_) + width_) % width_;
        yi = ((yi % height_) + height_) % height_;
        return texels_[size_t(yi) * width_ + xi];
    };
    return glm::mix(glm::mix(at(x0, y0), at(x0 + 1, y0), fx),
                    glm::mix(at(x0, y0 + 1), at(x0 + 1, y0 + 1), fx), fy);
}

glm::vec3 TextureImage::Color(const TextureQuery& q) const {
    if (!ptex_) return Eval(q.uv);
    float c[3] = {0.0f, 0.0f, 0.0f};
    const int n = std::min(3, ptex_->NumChannels() - desc_.channel);
    ptex_->Lookup(q.face, q.u, q.v, q.width, c, desc_.channel, n);
    if (desc_.srgb)
        for (float& v : c) v = SrgbToLinear(v);
    return n == 3 ? glm::vec3(c[0], c[1], c[2]) : glm::vec3(c[0]);
}

float TextureImage::Scalar(const TextureQuery& q) const {
    if (!ptex_) {
        const glm::vec3 c = Eval(q.uv);
        return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
    }
    float x = 0.0f;
    ptex_->Lookup(q.face, q.u, q.v, q.width, &x, desc_.channel, 1);
    return desc_.srgb ? SrgbToLinear(x) : x;
}

}  // namespace texcache
