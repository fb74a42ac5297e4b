// SPDX-License-Identifier: Apache-2.0
// Texel addressing: keys, mip selection from ray differentials (Munkberg et al. 2016, eq. 1) and
// quantization to the nearest texel (eq. 2).
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

namespace texcache {

/// A texel of a Ptex face's shading grid: (face, mip, iu, iv), packed into 60 bits so a cache slot
/// can compare whole keys with one atomic load. Faces are global ids (all objects' Ptex faces).
struct TexelKey {
    static constexpr int kFaceBits = 28, kMipBits = 4, kCoordBits = 14;
    static constexpr uint32_t kMaxFaces = 1u << kFaceBits;  ///< face ids must be below this
    static constexpr int kMaxMipLevels = 1 << kMipBits;     ///< mip 0..15
    static constexpr int kMaxResolution = 1 << kCoordBits;  ///< grid side at mip 0, at most 16384
    static constexpr uint64_t kEmpty = ~uint64_t(0);        ///< never a valid packed key

    uint32_t face = 0;
    uint8_t mip = 0;
    uint16_t iu = 0, iv = 0;

    /// Packs into 60 bits (callers guarantee the ranges above).
    constexpr uint64_t Pack() const {
        return (uint64_t(face) << (kMipBits + 2 * kCoordBits)) |
               (uint64_t(mip) << (2 * kCoordBits)) | (uint64_t(iu) << kCoordBits) | uint64_t(iv);
    }
    static constexpr TexelKey Unpack(uint64_t k) {
        TexelKey t;
        t.iv = uint16_t(k & ((1u << kCoordBits) - 1));
        t.iu = uint16_t((k >> kCoordBits) & ((1u << kCoordBits) - 1));
        t.mip = uint8_t((k >> (2 * kCoordBits)) & ((1u << kMipBits) - 1));
        t.face = uint32_t(k >> (kMipBits + 2 * kCoordBits));
        return t;
    }
    friend constexpr bool operator==(const TexelKey& a, const TexelKey& b) {
        return a.Pack() == b.Pack();
    }
};

/// std::ilogb(x) for a finite x > 0, read from the float's exponent bits (std::ilogb is a libm
/// call: 3% of a hit-binned AO frame, where every camera hit picks its texel's level); a
/// subnormal x (exponent field 0) takes the call.
inline int FloatExponent(float x) {
    uint32_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    const int e = int(bits >> 23) & 0xFF;
    return e ? e - 127 : std::ilogb(x);
}

/// Mip level of eq. 1, floored as the paper does (biasing towards higher resolution), plus a
/// global LOD bias, clamped to [0, numLevels - 1]. `log2Res` is the face's base resolution
/// (square, power of two); derivatives are d(u,v)/d(pixel x,y). Non-finite footprints map to
/// the finest level for zero and the coarsest for infinite ones.
inline int ComputeMip(int log2Res, float dudx, float dvdx, float dudy, float dvdy, float lodBias) {
    const float res2 = float(1 << (2 * log2Res));
    // Squared footprints: one square root and one log2 saved on every lookup.
    const float m2 = res2 * std::min(dudx * dudx + dvdx * dvdx, dudy * dudy + dvdy * dvdy);
    if (!(m2 == m2)) return 0;  // NaN differentials: finest level (safe, just more shading)
    const int numLevels = log2Res + 1;
    if (!(m2 > 0.0f)) return lodBias >= float(numLevels - 1) ? numLevels - 1 : 0;  // zero footprint
    if (!(m2 < 3.0e38f)) return numLevels - 1;                                     // huge or +inf
    int l;
    if (lodBias == std::floor(lodBias)) {
        // floor(log2(sqrt(m2))) = floor(ilogb(m2) / 2): exact, from the float's exponent.
        const int k = FloatExponent(m2);
        l = (k >= 0 ? k / 2 : -((1 - k) / 2)) + int(lodBias);
    } else {
        l = int(std::floor(0.5f * std::log2(m2) + lodBias));
    }
    return std::clamp(l, 0, numLevels - 1);
}

/// Texel index along one axis at a grid of `res` texels (eq. 2 without the +0.5): robust to
/// coordinates slightly outside [0,1] and to NaN (clamped to the edge texels).
inline int QuantizeCoord(float u, int res) {
    const float x = u * float(res);
    if (!(x > 0.0f)) return 0;
    return std::min(int(x), res - 1);
}

/// Centre of a texel in face (u,v) (eq. 2): where samples are shaded.
inline float TexelCenter(int i, int res) {
    return (float(i) + 0.5f) / float(res);
}

}  // namespace texcache
