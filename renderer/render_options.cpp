// SPDX-License-Identifier: Apache-2.0
#include "renderer/render_options.h"

#include <algorithm>

#include "texcache/enum_names.h"

namespace texcache {

namespace {
constexpr EnumName<FootprintMode> kFootprintModes[] = {{"auto", FootprintMode::Auto},
                                                       {"visible", FootprintMode::Visible},
                                                       {"all", FootprintMode::All}};
constexpr EnumName<TextureSamples> kTextureSamples[] = {{"grid", TextureSamples::Grid},
                                                        {"hits", TextureSamples::Hits}};
constexpr EnumName<LightSampling> kLightSamplings[] = {
    {"mis", LightSampling::Mis}, {"pis", LightSampling::Pis}, {"cpis", LightSampling::Cpis}};
}  // namespace

LightSampling ParseLightSampling(const std::string& name, const std::string& where) {
    return ParseEnum(kLightSamplings, name, where, "light sampling");
}

std::string LightSamplingNames() {
    return EnumNames(kLightSamplings);
}

const char* LightSamplingName(LightSampling s) {
    return EnumToName(kLightSamplings, s);
}

TextureSamples ParseTextureSamples(const std::string& name, const std::string& where) {
    return ParseEnum(kTextureSamples, name, where, "texture-space sample source");
}

FootprintMode ParseFootprintMode(const std::string& name, const std::string& where) {
    return ParseEnum(kFootprintModes, name, where, "footprint");
}

std::string FootprintModeNames() {
    return EnumNames(kFootprintModes);
}

RenderOptions RenderOptionsFrom(const RenderSettings& s) {
    RenderOptions o;
    o.integrator = s.integrator;
    o.width = s.width;
    o.height = s.height;
    o.spp = s.spp;
    o.seconds = s.seconds;
    o.seed = s.seed;
    o.maxDepth = s.maxDepth;
    o.aoSamples = s.aoSamples;
    o.aoDistance = s.aoDistance;
    o.frameTime = s.time;
    return o;
}

void CheckFilterRadius(int radius, const std::string& where) {
    // 2r+1 = 65 texels a side is far past any useful kernel (the paper uses up to 21).
    if (radius < 0 || radius > 32)
        throw InputError(
            where, "filter radius must be between 0 and 32 texels, got " + std::to_string(radius));
}

bool ShadesAtHits(const RenderOptions& o) {
    return (o.integrator == IntegratorKind::AO || o.integrator == IntegratorKind::Path ||
            (o.integrator == IntegratorKind::Direct && o.texture.cacheDirect)) &&
           o.texture.samples == TextureSamples::Hits && !o.aovs.Any() &&
           o.texture.constantTerm < 0.0f;
}

bool VisibleOnly(FootprintMode mode, IntegratorKind integrator) {
    return mode == FootprintMode::Visible ||
           (mode == FootprintMode::Auto && integrator == IntegratorKind::AO);
}

void SizeCachesToFrame(CacheSettings* cache, int width, int height, int views,
                       IntegratorKind integrator, FootprintMode footprint) {
    // Bytes per pixel: 4 slots of 32 bytes per texel or sample a pixel needs (three choices per
    // key keep evictions rare at a quarter full: on car AO a few percent of the texels are
    // evicted once, and the samples shaded barely change); four times that for whole-window
    // footprints.
    constexpr double kTexelBytes = 128.0, kVisibleSampleBytes = 128.0, kAllSampleBytes = 512.0;
    constexpr size_t kMin = size_t(4) << 20, kMax = size_t(64) << 20;
    const bool visibleOnly = VisibleOnly(footprint, integrator);
    const double pixels =
        double(std::max(width, 1)) * double(std::max(height, 1)) * double(std::max(views, 1));
    auto fit = [&](double perPixel) {
        return std::clamp(size_t(std::min(pixels * perPixel, double(kMax))), kMin, kMax);
    };
    cache->texelCacheBytes = fit(kTexelBytes);
    cache->sampleCacheBytes = fit(visibleOnly ? kVisibleSampleBytes : kAllSampleBytes);
}

int DefaultFilterRadius(TextureFilterKind kind) {
    switch (kind) {
        case TextureFilterKind::None:
            return 0;
        case TextureFilterKind::Normal:
            return 6;
        case TextureFilterKind::Gaussian:
            return 10;
        case TextureFilterKind::Regression:
        case TextureFilterKind::SoftShadow:
            return 8;
    }
    return 6;
}

}  // namespace texcache
