// SPDX-License-Identifier: Apache-2.0
#include "filters/texture_filters.h"

#include <cmath>

#include <algorithm>
#include <bit>
#include <vector>

#include <glm/gtc/packing.hpp>

#include "texcache/enum_names.h"

namespace texcache {

namespace {
constexpr EnumName<TextureFilterKind> kFilterNames[] = {
    {"none", TextureFilterKind::None},
    {"normal", TextureFilterKind::Normal},
    {"gaussian", TextureFilterKind::Gaussian},
    {"regression", TextureFilterKind::Regression},
    {"softshadow", TextureFilterKind::SoftShadow},
};
}  // namespace

TextureFilterKind ParseTextureFilter(const std::string& name, const std::string& where) {
    return ParseEnum(kFilterNames, name, where, "filter");
}

std::string TextureFilterNames() {
    return EnumNames(kFilterNames);
}

NormalWeightedFilter::Tile NormalWeightedFilter::Prepare(const SampleTile<ShadedSample>& t,
                                                         int radius) const {
    Tile tile(*this, t, radius);
    // Tiles wider than 64 texels have no bit rows.
    if (!t.rows || !t.reversed || t.w > 64) return tile;
    // The least d (see Tile) that passes: 2 d^2 - 1 > cosThreshold + 1e-3, d > 0 (NaN: none).
    const float need = std::sqrt(0.5f * (cosThreshold + 1e-3f + 1.0f));
    if (!(need >= 0.0f && need < 1.0f)) return tile;
    thread_local std::vector<uint64_t> finite;
    finite.assign(size_t(t.h), 0);
    // The seen taps' mean normal; a normal off unit length (NaN, zero) makes the tile take the
    // test.
    auto unit = [](glm::vec3 n) { return std::abs(glm::dot(n, n) - 1.0f) <= 1e-4f; };
    // Both passes visit the seen taps by their bit rows (a third of a 21x21 tile is seen).
    glm::vec3 mean(0.0f);
    for (int y = 0; y < t.h; ++y)
        for (uint64_t m = t.rows[y]; m; m &= m - 1) {
            const int x = std::countr_zero(m);
            const ShadedSample& s = t.samples[y * t.w + x];
            if (std::isfinite(s.value.x + s.value.y + s.value.z))  // as Sum::Add tests it
                finite[size_t(y)] |= uint64_t(1) << x;
            if (!unit(s.normal)) return tile;
            mean += s.normal;
        }
    const float length = glm::length(mean);
    if (!(length > 0.0f)) return tile;
    mean /= length;
    for (int y = 0; y < t.h; ++y)
        for (uint64_t m = t.rows[y]; m; m &= m - 1)
            if (!(glm::dot(t.samples[y * t.w + std::countr_zero(m)].normal, mean) > need))
                return tile;
    tile.smooth_ = true;
    tile.finite_ = finite.data();
    if (sigma > 0.0f) tile.weights_ = GaussianWeights(2 * radius * radius);
    return tile;
}

const float* NormalWeightedFilter::GaussianWeights(int reach) const {
    thread_local std::vector<float> table;
    thread_local float tableSigma = 0.0f;
    if (sigma != tableSigma || size_t(reach) >= table.size()) {
        const float inv2s2 = 1.0f / (2.0f * sigma * sigma);
        table.resize(std::max(table.size(), size_t(reach) + 1));
        for (size_t d2 = 0; d2 < table.size(); ++d2) table[d2] = std::exp(-float(int(d2)) * inv2s2);
        tableSigma = sigma;
    }
    return table.data();
}

namespace {
// A coordinate in [-1, 1] to 0..65534 and back: 65535 is left for the reserved codes.
uint32_t QuantizeOct(float v) {
    return uint32_t(std::lround((std::clamp(v, -1.0f, 1.0f) * 0.5f + 0.5f) * 65534.0f));
}
float DequantizeOct(uint32_t q) {
    return float(q) * (2.0f / 65534.0f) - 1.0f;
}
float SignNotZero(float v) {
    return v >= 0.0f ? 1.0f : -1.0f;
}
}  // namespace

uint32_t EncodeOctNormal(glm::vec3 n) {
    const float l1 = std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
    if (!std::isfinite(l1)) return PackedShadedSample::kNanNormal;
    if (!(l1 > 0.0f)) return PackedShadedSample::kZeroNormal;
    float x = n.x / l1, y = n.y / l1;
    if (n.z < 0.0f) {  // fold the lower hemisphere over the diagonals
        const float ox = x;
        x = (1.0f - std::abs(y)) * SignNotZero(ox);
        y = (1.0f - std::abs(ox)) * SignNotZero(y);
    }
    return QuantizeOct(x) | (QuantizeOct(y) << 16);
}

glm::vec3 DecodeOctNormal(uint32_t code) {
    if (code == PackedShadedSample::kZeroNormal) return glm::vec3(0.0f);
    if (code == PackedShadedSample::kNanNormal) return glm::vec3(NAN);
    glm::vec3 n(DequantizeOct(code & 0xFFFFu), DequantizeOct(code >> 16), 0.0f);
    n.z = 1.0f - std::abs(n.x) - std::abs(n.y);
    if (n.z < 0.0f) {
        const float ox = n.x;
        n.x = (1.0f - std::abs(n.y)) * SignNotZero(ox);
        n.y = (1.0f - std::abs(ox)) * SignNotZero(n.y);
    }
    return glm::normalize(n);
}

uint16_t EncodeHalf(float v) {
    if (std::isfinite(v)) v = std::clamp(v, -65504.0f, 65504.0f);
    return uint16_t(glm::packHalf1x16(v));
}

float DecodeHalf(uint16_t h) {
    return glm::unpackHalf1x16(h);
}

}  // namespace texcache
