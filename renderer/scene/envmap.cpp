// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/envmap.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <mutex>

#include "renderer/image/image.h"
#include "renderer/integrators/bsdf.h"
#include "renderer/integrators/sampling.h"
#include "texcache/error.h"

namespace texcache {

namespace {

/// Texels brighter than this (after the intensity) are clamped: sums over a map of them stay
/// finite in float.
constexpr float kMaxRadiance = 1e30f;

/// Light is finite, not negative and summable: NaN would poison every sum, a sampler cannot draw
/// from negative light, and sums of texels near FLT_MAX overflow. Such texels are repaired (set
/// to 0, or clamped to kMaxRadiance) and counted in the returned note, for the caller's warning.
/// Lossy EXRs undershoot a little around bright texels (the bundled maps by up to 0.6% of their
/// mean): negatives within 5% of the mean magnitude are clamped to zero without a note.
std::string LightRepairs(const Image& img, float intensity) {
    double sum = 0.0;
    for (const float v : img.data)
        if (std::isfinite(v)) sum += std::abs(double(v));
    const double tolerance = 0.05 * sum / double(std::max<size_t>(img.data.size(), 1));
    size_t nonFinite = 0, negative = 0, huge = 0;
    float lowest = 0.0f;
    for (size_t i = 0; i < img.NumPixels(); ++i) {
        const float* p = &img.data[i * size_t(img.channels)];
        bool bad = false, neg = false, big = false;
        for (int k = 0; k < 3; ++k) {
            bad = bad || !std::isfinite(p[k]);
            if (!std::isfinite(p[k])) continue;
            neg = neg || p[k] < -tolerance;
            big = big || double(p[k]) * intensity > double(kMaxRadiance);
            lowest = std::min(lowest, p[k]);
        }
        nonFinite += bad, negative += !bad && neg, huge += !bad && !neg && big;
    }
    std::string note;
    const auto add = [&](size_t n, const std::string& what) {
        if (n == 0) return;
        note += (note.empty() ? "" : ", ") + what + " in " + std::to_string(n) + " of its " +
                std::to_string(img.NumPixels()) + " texels";
    };
    char low[32];
    std::snprintf(low, sizeof low, "%g", double(lowest));
    add(nonFinite, "NaN or infinite values (set to 0)");
    add(negative, std::string("negative values down to ") + low + " (set to 0)");
    add(huge, "values above 1e30 (clamped)");
    return note;
}

}  // namespace

EnvironmentMap EnvironmentMap::Load(const std::string& path, float intensity,
                                    float rotationDegrees) {
    const Image img = ReadImageRGB(path);
    if (img.width != 2 * img.height)
        throw InputError(path,
                         "environment map is not lat-long (expected width = 2 x height, got " +
                             std::to_string(img.width) + "x" + std::to_string(img.height) + ")");
    if (!(intensity >= 0.0f) || !std::isfinite(intensity))
        throw InputError(path, "environment intensity must be a finite number >= 0");
    EnvironmentMap e;
    e.repairs_ = LightRepairs(img, intensity);
    e.isConstant_ = false;
    e.width_ = img.width;
    e.height_ = img.height;
    e.rotation_ = glm::radians(rotationDegrees);
    e.texels_.resize(img.NumPixels());
    std::vector<float> weights(img.NumPixels());
    for (int y = 0; y < img.height; ++y) {
        const float sinTheta = std::sin(kPiF * (float(y) + 0.5f) / float(img.height));
        for (int x = 0; x < img.width; ++x) {
            const float* p = img.At(x, y);
            // Lossy EXRs carry slightly negative texels (and NaN would poison sums): clamp.
            glm::vec3 c(p[0], p[1], p[2]);
            for (int k = 0; k < 3; ++k)
                c[k] = std::isfinite(c[k])
                           ? std::min(std::max(c[k], 0.0f) * intensity, kMaxRadiance)
                           : 0.0f;
            e.texels_[size_t(y) * img.width + x] = glm::vec4(c, 0.0f);
            weights[size_t(y) * img.width + x] =
                (0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z) * sinTheta;
        }
    }
    // Sampling picks a texel and a uniform point in it, while Eval interpolates bilinearly: the
    // texel's own value drives the pdf; both are consistent estimators (pdf > 0 wherever the
    // bilinear radiance is non-zero, since neighbours of a bright texel get its weight too).
    std::vector<float> blurred(weights);
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            float m = 0.0f;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int yy = std::clamp(y + dy, 0, img.height - 1);
                    const int xx = (x + dx + img.width) % img.width;
                    m = std::max(m, weights[size_t(yy) * img.width + xx]);
                }
            blurred[size_t(y) * img.width + x] = m;
        }
    e.dist_ = Distribution2D(blurred, img.width, img.height);
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x)
            e.texels_[size_t(y) * img.width + x].w = e.dist_.BinPdf(x, y);
    return e;
}

std::shared_ptr<const EnvironmentMap> EnvironmentMap::Shared(const std::string& path,
                                                             float intensity,
                                                             float rotationDegrees) {
    namespace fs = std::filesystem;
    std::error_code ec;  // a missing file gets Load()'s own error below
    const auto size = fs::file_size(path, ec);
    const auto mtime = fs::last_write_time(path, ec).time_since_epoch().count();
    const std::string key = fs::absolute(path, ec).string() + '|' + std::to_string(size) + '|' +
                            std::to_string(mtime) + '|' + std::to_string(intensity) + '|' +
                            std::to_string(rotationDegrees);
    // Weak references, so that a map no scene uses is freed, except for the last one loaded: an
    // animation builds and drops a RenderScene per frame, and without it each frame would read
    // the file again. Loads are rare and serialized.
    static std::mutex mutex;
    static std::map<std::string, std::weak_ptr<const EnvironmentMap>> loaded;
    static std::shared_ptr<const EnvironmentMap> last;
    const std::lock_guard<std::mutex> lock(mutex);
    if (auto e = loaded[key].lock()) return last = e;
    std::erase_if(loaded, [](const auto& kv) { return kv.second.expired(); });
    last.reset();  // before loading, so that two maps are never held only by the cache
    last = std::make_shared<const EnvironmentMap>(Load(path, intensity, rotationDegrees));
    loaded[key] = last;
    return last;
}

EnvironmentMap EnvironmentMap::Constant(glm::vec3 radiance) {
    EnvironmentMap e;
    e.constant_ = radiance;
    return e;
}

glm::vec2 EnvironmentMap::DirToUv(glm::vec3 d) const {
    float phi = std::atan2(d.x, -d.z) + rotation_;
    float u = phi / (2.0f * kPiF);
    u -= std::floor(u);
    const float v = std::acos(std::clamp(d.y, -1.0f, 1.0f)) / kPiF;
    return {std::min(u, 0x1.fffffep-1f), std::min(v, 0x1.fffffep-1f)};
}

glm::vec3 EnvironmentMap::UvToDir(glm::vec2 uv) const {
    const float phi = uv.x * 2.0f * kPiF - rotation_, theta = uv.y * kPiF;
    const float st = std::sin(theta);
    return {st * std::sin(phi), std::cos(theta), -st * std::cos(phi)};
}

glm::vec3 EnvironmentMap::Eval(glm::vec3 dir) const {
    return isConstant_ ? constant_ : EvalUv(DirToUv(dir));
}

glm::vec3 EnvironmentMap::EvalUv(glm::vec2 uv) const {
    if (isConstant_) return constant_;
    const float x = uv.x * float(width_) - 0.5f, y = uv.y * float(height_) - 0.5f;
    const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
    const float fx = x - float(x0), fy = y - float(y0);
    // Columns wrap and rows clamp. The columns of uv in [0,1) are in [-1, width]: they wrap
    // without the two integer divisions a modulo costs (four texels a light sample).
    const auto wrap = [w = width_](int xi) {
        return xi < 0 ? (xi >= -w ? xi + w : (xi % w + w) % w) : xi < w ? xi : xi % w;
    };
    const int xa = wrap(x0), xb = wrap(x0 + 1);
    const int ya = std::clamp(y0, 0, height_ - 1), yb = std::clamp(y0 + 1, 0, height_ - 1);
    return glm::mix(glm::mix(Texel(xa, ya), Texel(xb, ya), fx),
                    glm::mix(Texel(xa, yb), Texel(xb, yb), fx), fy);
}

glm::vec3 EnvironmentMap::Sample(glm::vec3 n, glm::vec2 u, glm::vec3* dir, float* pdf) const {
    if (isConstant_) {
        const glm::vec3 local = SampleCosineHemisphere(u);
        *dir = Frame::FromZ(n).FromLocal(local);
        *pdf = CosineHemispherePdf(local.z);
        return constant_;
    }
    float pdfUv;
    const glm::vec2 uv = dist_.Sample(u, &pdfUv);
    const float sinTheta = std::sin(uv.y * kPiF);
    *dir = UvToDir(uv);
    // dω = 2π² sinθ du dv
    *pdf = sinTheta > 0.0f ? pdfUv / (2.0f * kPiF * kPiF * sinTheta) : 0.0f;
    return EvalUv(uv);
}

float EnvironmentMap::Pdf(glm::vec3 n, glm::vec3 dir) const {
    if (isConstant_) return CosineHemispherePdf(glm::dot(n, dir));
    return PdfUv(DirToUv(dir));
}

glm::vec3 EnvironmentMap::EvalPdf(glm::vec3 n, glm::vec3 dir, float* pdf) const {
    if (isConstant_) {
        *pdf = CosineHemispherePdf(glm::dot(n, dir));
        return constant_;
    }
    const glm::vec2 uv = DirToUv(dir);
    *pdf = PdfUv(uv);
    return EvalUv(uv);
}

float EnvironmentMap::PdfUv(glm::vec2 uv) const {
    const float sinTheta = std::sin(uv.y * kPiF);
    if (!(sinTheta > 0.0f)) return 0.0f;
    // dist_.Pdf(uv), from the texel's copy (the bins are the texels).
    const int x = std::clamp(int(uv.x * float(width_)), 0, width_ - 1);
    const int y = std::clamp(int(uv.y * float(height_)), 0, height_ - 1);
    return texels_[size_t(y) * width_ + x].w / (2.0f * kPiF * kPiF * sinTheta);
}

glm::vec3 EnvironmentMap::Irradiance(glm::vec3 n) const {
    if (isConstant_) return kPiF * constant_;
    std::call_once(sh_->once, [this] {
        // Each texel's radiance times the basis at its centre times its solid angle
        // (2 pi / W)(pi / H) sin(theta), summed in double.
        constexpr double kPiD = 3.14159265358979323846;
        glm::dvec3 acc[9] = {};
        const double dA = (2.0 * kPiD / width_) * (kPiD / height_);
        for (int y = 0; y < height_; ++y) {
            const float v = (float(y) + 0.5f) / float(height_);
            const double w = dA * std::sin(double(v) * kPiD);
            for (int x = 0; x < width_; ++x) {
                const glm::vec3 d = UvToDir({(float(x) + 0.5f) / float(width_), v});
                const double basis[9] = {0.282095,
                                         0.488603 * d.y,
                                         0.488603 * d.z,
                                         0.488603 * d.x,
                                         1.092548 * d.x * d.y,
                                         1.092548 * d.y * d.z,
                                         0.315392 * (3.0 * d.z * d.z - 1.0),
                                         1.092548 * d.x * d.z,
                                         0.546274 * (d.x * d.x - d.y * d.y)};
                const glm::dvec3 L = glm::dvec3(Texel(x, y)) * w;
                for (int k = 0; k < 9; ++k) acc[k] += basis[k] * L;
            }
        }
        for (int k = 0; k < 9; ++k) sh_->c[k] = glm::vec3(acc[k]);
    });
    // Ramamoorthi and Hanrahan's eq. 13: the clamped cosine's convolution in closed form.
    constexpr float c1 = 0.429043f, c2 = 0.511664f, c3 = 0.743125f, c4 = 0.886227f, c5 = 0.247708f;
    const glm::vec3* L = sh_->c;
    const glm::vec3 E = c1 * L[8] * (n.x * n.x - n.y * n.y) + c3 * L[6] * n.z * n.z + c4 * L[0] -
                        c5 * L[6] +
                        2.0f * c1 * (L[4] * n.x * n.y + L[7] * n.x * n.z + L[5] * n.y * n.z) +
                        2.0f * c2 * (L[3] * n.x + L[1] * n.y + L[2] * n.z);
    return glm::max(E, glm::vec3(0.0f));
}

const EnvironmentMap::LuminancePyramid& EnvironmentMap::Pyramid() const {
    std::call_once(pyramid_->once, [this] {
        std::vector<LuminancePyramid::Level>& levels = pyramid_->pyramid.levels;
        if (isConstant_) {
            levels.push_back({2, 1, std::vector<float>(2, Luminance(constant_))});
            return;
        }
        LuminancePyramid::Level l0{width_, height_, std::vector<float>(texels_.size())};
        for (size_t i = 0; i < texels_.size(); ++i) l0.texels[i] = Luminance(glm::vec3(texels_[i]));
        levels.push_back(std::move(l0));
        while (levels.back().width > 2 && levels.back().height > 1) {
            const LuminancePyramid::Level& f = levels.back();
            if (f.width % 2 || f.height % 2) pyramid_->pyramid.exact = false;
            LuminancePyramid::Level c{f.width / 2, f.height / 2, {}};
            c.texels.resize(size_t(c.width) * c.height);
            for (int y = 0; y < c.height; ++y)
                for (int x = 0; x < c.width; ++x) {
                    const float* r0 = &f.texels[size_t(2 * y) * f.width + 2 * x];
                    const float* r1 = r0 + f.width;
                    c.texels[size_t(y) * c.width + x] = 0.25f * (r0[0] + r0[1] + r1[0] + r1[1]);
                }
            levels.push_back(std::move(c));
        }
    });
    return pyramid_->pyramid;
}

glm::vec3 EnvironmentMap::AverageRadiance() const {
    if (isConstant_) return constant_;
    glm::dvec3 sum(0.0);
    double wsum = 0.0;
    for (int y = 0; y < height_; ++y) {
        const double w = std::sin(kPiF * (y + 0.5) / height_);
        for (int x = 0; x < width_; ++x) sum += w * glm::dvec3(Texel(x, y)), wsum += w;
    }
    return glm::vec3(sum / wsum);
}

}  // namespace texcache
