// SPDX-License-Identifier: Apache-2.0
// Random numbers, warps and the GGX microfacet distribution: header-only hot-path code.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>

#include <glm/glm.hpp>

namespace texcache {

constexpr float kOneMinusEpsilon = 0x1.fffffep-1f;
constexpr float kPiF = 3.14159265358979323846f;
constexpr float kInvPiF = 0.31830988618379067154f;

/// SplitMix64's finalizer: a strong 64-bit mix for seeding streams from (pixel, sample) ids.
inline uint64_t MixBits(uint64_t v) {
    v ^= v >> 31;
    v *= 0x7fb5d329728ea185ull;
    v ^= v >> 27;
    v *= 0x81dadef4bc2dd44dull;
    v ^= v >> 33;
    return v;
}

/// PCG32 (O'Neill 2014): small state, good statistics, independent streams.
class Rng {
public:
    Rng(uint64_t seed, uint64_t stream) {
        state_ = 0u;
        inc_ = (stream << 1u) | 1u;
        NextU32();
        state_ += seed;
        NextU32();
    }
    uint32_t NextU32() {
        const uint64_t old = state_;
        state_ = old * 0x5851f42d4c957f2dull + inc_;
        const uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
        const uint32_t rot = uint32_t(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
    }
    /// Uniform in [0, 1), never 1.
    float Next1D() { return std::min(float(NextU32()) * 0x1p-32f, kOneMinusEpsilon); }
    glm::vec2 Next2D() {
        const float a = Next1D();
        return {a, Next1D()};
    }

private:
    uint64_t state_, inc_;
};

/// Orthonormal basis around a unit normal (Duff et al. 2017, branchless).
struct Frame {
    glm::vec3 s, t, n;
    static Frame FromZ(glm::vec3 n) {
        const float sign = std::copysign(1.0f, n.z);
        const float a = -1.0f / (sign + n.z);
        const float b = n.x * n.y * a;
        return {glm::vec3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x),
                glm::vec3(b, sign + n.y * n.y * a, -n.y), n};
    }
    glm::vec3 ToLocal(glm::vec3 v) const {
        return {glm::dot(v, s), glm::dot(v, t), glm::dot(v, n)};
    }
    glm::vec3 FromLocal(glm::vec3 v) const { return v.x * s + v.y * t + v.z * n; }
};

/// sin and cos of a in [-pi/4, pi/4] by Taylor polynomials (|error| < 4e-8 there): the
/// concentric map only needs this range, and libm's sincosf is a visible cost per AO ray.
inline void SinCosQuarterPi(float a, float* s, float* c) {
    const float a2 = a * a;
    *s = a * (1.0f + a2 * (-1.0f / 6.0f + a2 * (1.0f / 120.0f +
                                                a2 * (-1.0f / 5040.0f + a2 * (1.0f / 362880.0f)))));
    *c = 1.0f + a2 * (-0.5f + a2 * (1.0f / 24.0f + a2 * (-1.0f / 720.0f + a2 * (1.0f / 40320.0f))));
}

/// Concentric map of the unit square to the unit disk (Shirley-Chiu).
inline glm::vec2 SampleUniformDiskConcentric(glm::vec2 u) {
    const glm::vec2 o = 2.0f * u - 1.0f;
    if (o.x == 0.0f && o.y == 0.0f) return {0.0f, 0.0f};
    float s, c;
    if (std::abs(o.x) > std::abs(o.y)) {
        SinCosQuarterPi(0.25f * kPiF * (o.y / o.x), &s, &c);  // theta = pi/4 * y/x
        return o.x * glm::vec2(c, s);
    }
    SinCosQuarterPi(0.25f * kPiF * (o.x / o.y), &s, &c);  // theta = pi/2 - pi/4 * x/y
    return o.y * glm::vec2(s, c);
}

/// Cosine-weighted direction about +z; pdf = cos(theta) / pi.
inline glm::vec3 SampleCosineHemisphere(glm::vec2 u) {
    const glm::vec2 d = SampleUniformDiskConcentric(u);
    const float z = std::sqrt(std::max(0.0f, 1.0f - d.x * d.x - d.y * d.y));
    return {d.x, d.y, z};
}
/// The bits of x in reverse order.
inline uint32_t ReverseBits32(uint32_t x) {
    x = __builtin_bswap32(x);  // one instruction for the bytes, then the bits within them
    x = ((x & 0x0f0f0f0fu) << 4) | ((x & 0xf0f0f0f0u) >> 4);
    x = ((x & 0x33333333u) << 2) | ((x & 0xccccccccu) >> 2);
    return ((x & 0x55555555u) << 1) | ((x & 0xaaaaaaaau) >> 1);
}

/// Point j of the 2D Sobol' (0,2)-sequence in base 2 (van der Corput and Sobol's second
/// dimension), digitally shifted by (sx, sy): each 2^m consecutive points from a multiple of 2^m
/// form a (0,m,2)-net (one point in every elementary 2^-a x 2^-(m-a) box), and with a uniformly
/// random shift every point alone is uniform on [0,1)^2 (Kollig and Keller 2002).
inline glm::vec2 Sobol02(uint32_t j, uint32_t sx, uint32_t sy) {
    const uint32_t x = ReverseBits32(j);
    uint32_t y = 0;
    for (uint32_t v = 1u << 31; j; j >>= 1, v ^= v >> 1)
        if (j & 1) y ^= v;
    // 24 bits: exactly representable, and below 1.
    constexpr float kScale = 1.0f / float(1u << 24);
    return {float((x ^ sx) >> 8) * kScale, float((y ^ sy) >> 8) * kScale};
}

namespace detail {
/// A Laine-Karras style hash: bit k of the result depends on bits 0..k of x only (adds, odd
/// multiplies and x ^= x * even), so on bit-reversed values it is a nested uniform (Owen)
/// scramble. The constants and the seed-dependent multiply are Vegdahl's (2021) improvement of
/// Burley's (2020): with Burley's, two points of a net stayed correlated within their halves
/// (0.095, Sampling.OwenSobol02PointsFormNetsAndAreUniform).
inline uint32_t LaineKarras(uint32_t x, uint32_t seed) {
    x ^= x * 0x3d20adeau;
    x += seed;
    x *= (seed >> 16) | 1u;
    x ^= x * 0x05526c56u;
    x ^= x * 0x53a22864u;
    return x;
}
/// Sobol's second dimension, bit-reversed, 8 index bits per table: y = XOR of the columns of
/// the index's set bits (column k: v_0 = 2^31, v_{k+1} = v_k ^ v_k >> 1, as in Sobol02).
struct SobolSecondDimension {
    uint32_t table[4][256];
    constexpr SobolSecondDimension() : table{} {
        uint32_t column[32] = {};
        uint32_t v = 1u << 31;
        for (int k = 0; k < 32; ++k, v ^= v >> 1)
            for (int b = 0; b < 32; ++b) column[k] |= (v >> b & 1u) << (31 - b);
        for (int t = 0; t < 4; ++t)
            for (uint32_t x = 0; x < 256; ++x)
                for (int k = 0; k < 8; ++k)
                    if (x >> k & 1u) table[t][x] ^= column[8 * t + k];
    }
};
inline constexpr SobolSecondDimension kSobolSecondDimension{};
}  // namespace detail

/// The keys of one Owen scramble of OwenSobol02 (one per axis), mixed from a seed once: a
/// caller drawing several points of one scramble (a hit's rays) mixes them once.
struct OwenScramble {
    uint32_t x, y;
    explicit OwenScramble(uint32_t seed)
        : x(uint32_t(MixBits(seed))), y(uint32_t(MixBits(~uint64_t(seed)))) {}
};

/// Point j of the 2D Sobol' (0,2)-sequence, Owen-scrambled (hash-based nested uniform
/// scrambling, Burley 2020): like Sobol02, each 2^m consecutive points from a multiple of 2^m
/// form a (0,m,2)-net and every point alone is uniform, but the scramble is random per digit,
/// not one shift for all: an Owen-scrambled net's error falls faster on smooth integrands.
/// Two hashes, two bit reversals and four table lookups.
inline glm::vec2 OwenSobol02(uint32_t j, const OwenScramble& key) {
    const auto& t = detail::kSobolSecondDimension.table;
    const uint32_t yReversed =
        t[0][j & 255u] ^ t[1][j >> 8 & 255u] ^ t[2][j >> 16 & 255u] ^ t[3][j >> 24];
    // The first dimension is j bit-reversed: scrambling reversed bits is hashing j itself.
    const uint32_t x = ReverseBits32(detail::LaineKarras(j, key.x));
    const uint32_t y = ReverseBits32(detail::LaineKarras(yReversed, key.y));
    constexpr float kScale = 1.0f / float(1u << 24);
    return {float(x >> 8) * kScale, float(y >> 8) * kScale};
}
inline glm::vec2 OwenSobol02(uint32_t j, uint32_t seed) {
    return OwenSobol02(j, OwenScramble(seed));
}

/// The Morton (Z-order) index of (x, y), 16 bits each: pixels of every aligned 2^k x 2^k block
/// get consecutive indices.
inline uint32_t Morton2(uint32_t x, uint32_t y) {
    auto spread = [](uint32_t v) {
        v &= 0xffffu;
        v = (v | (v << 8)) & 0x00ff00ffu;
        v = (v | (v << 4)) & 0x0f0f0f0fu;
        v = (v | (v << 2)) & 0x33333333u;
        return (v | (v << 1)) & 0x55555555u;
    };
    return spread(x) | (spread(y) << 1);
}

/// One random order of the pixels of an image and of their sample slots, for ShuffledMorton: its
/// keys and masks.
struct MortonShuffle {
    uint32_t flipKey, swapKey;
    int slotBits;    ///< log2 of the slots per pixel
    int bits;        ///< the shuffled low bits of a number: the slots' and the image's levels'
    uint32_t low;    ///< those bits
    uint32_t high;   ///< those bits, bit-reversed
    uint32_t yBits;  ///< the y bits of the Morton digits among them, bit-reversed
    MortonShuffle(uint64_t seed, int pixelLevels, int slotBits_)
        : flipKey(uint32_t(MixBits(seed ^ 0x5851F42D4C957F2Dull))),
          swapKey(uint32_t(MixBits(seed ^ 0x14057B7EF767814Full))),
          slotBits(slotBits_),
          // At most 32: the levels above (blocks of 2^16 pixels and more) keep Morton order.
          bits(slotBits + 2 * std::min(pixelLevels, (32 - slotBits) / 2)),
          low(bits == 0 ? 0u : ~0u >> (32 - bits)),
          high(bits == 0 ? 0u : ~0u << (32 - bits)),
          // Morton digit k (x at bit slotBits + 2k of the number, y above it) lands
          // bit-reversed at 31 - slotBits - 2k (x) and 30 - slotBits - 2k (y): every other bit
          // from 32 - bits up to 30 - slotBits.
          yBits(bits == slotBits
                    ? 0u
                    : (0x55555555u << (slotBits & 1)) & high & ((1u << (31 - slotBits)) - 1u)) {}
};

/// The number of sample slot `slot` (< 2^key.slotBits) of pixel (x, y) in a random order of the
/// Morton order's numbers, Morton2(x, y) << slotBits plus the slot, that keeps every aligned
/// block of 2^n numbers (those that share the bits above n) together, taking it to an aligned
/// block of 2^n: a pixel's slots, and the slots of every aligned 2^k x 2^k block of pixels,
/// keep consecutive numbers. Each node of the quadtree permutes its four children by one of 16
/// permutations picked by a hash of the node's own place (the bits above its digit): x and y
/// swapped or not, so that the two children that share a half of the node's numbers are the
/// two side by side or the two above each other, either with probability 1/2; then each bit
/// flipped by a function of the bits above it. The slots get the flips. This is the random
/// permutation per node of Ahmed and Wonka (2020), which pbrt-v4's ZSobolSampler picks from all
/// 24 with a hash per level; here two Laine-Karras hashes of the bit-reversed number (bit j of
/// the hash is bit j of its input flipped by a function of bits 0..j - 1, the more significant
/// bits of the number) pick every level's at once, for a few dozen instructions per slot; the
/// pixel's own part, the bit-reversed Morton index, is the same for all its slots.
inline uint64_t ShuffledMorton(uint32_t x, uint32_t y, uint32_t slot, const MortonShuffle& key) {
    const uint32_t morton = Morton2(x, y);
    // The number bit-reversed: the Morton digits from the top down, then the slot's bits (in
    // reverse order of the slot's: any order of a pixel's slots will do).
    const uint32_t r =
        uint32_t((uint64_t(slot) << 32 | ReverseBits32(morton)) >> key.slotBits) & key.high;
    // The flip that the first hash gives a digit's y bit decides the digit's swap: a function
    // of the digits above alone. (The hash's bit below it is the parent's x bit flipped, so
    // two siblings side by side would always take opposite swaps.) The swaps come before the
    // flips: after them, the x bit (flipped by a function of the y bit) could pair diagonal
    // neighbours.
    const uint32_t swap = (detail::LaineKarras(r, key.swapKey) ^ r) & key.yBits;
    const uint32_t t = (r ^ r >> 1) & swap;
    const uint32_t shuffled = ReverseBits32(detail::LaineKarras(r ^ (t | t << 1), key.flipKey));
    return (uint64_t(morton) << key.slotBits & ~uint64_t(key.low)) | (shuffled & key.low);
}

inline float CosineHemispherePdf(float cosTheta) {
    return std::max(cosTheta, 0.0f) * kInvPiF;
}

/// Uniform direction on the sphere; pdf = 1 / (4 pi).
inline glm::vec3 SampleUniformSphere(glm::vec2 u) {
    const float z = 1.0f - 2.0f * u.x;
    const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    const float phi = 2.0f * kPiF * u.y;
    return {r * std::cos(phi), r * std::sin(phi), z};
}
constexpr float kUniformSpherePdf = 1.0f / (4.0f * kPiF);

/// Veach's power heuristic (beta = 2).
inline float PowerHeuristic(int nf, float fPdf, int ng, float gPdf) {
    const float f = float(nf) * fPdf, g = float(ng) * gPdf;
    if (std::isinf(f * f)) return 1.0f;
    const float d = f * f + g * g;
    return d > 0.0f ? f * f / d : 0.0f;
}

// ---- GGX (Trowbridge-Reitz), isotropic, in the local frame (z = normal) ------------------------

/// Normal distribution D(m); 0 below the horizon.
inline float GgxD(glm::vec3 m, float alpha) {
    if (m.z <= 0.0f) return 0.0f;
    const float a2 = alpha * alpha;
    const float c2 = m.z * m.z;
    const float d = c2 * (a2 - 1.0f) + 1.0f;
    return a2 / (kPiF * d * d);
}
/// Smith Lambda for direction w.
inline float GgxLambda(glm::vec3 w, float alpha) {
    const float c2 = w.z * w.z;
    if (c2 <= 0.0f) return 1e30f;  // grazing: fully shadowed
    const float t2 = std::max(0.0f, 1.0f - c2) / c2;
    return 0.5f * (std::sqrt(1.0f + alpha * alpha * t2) - 1.0f);
}
inline float GgxG1(glm::vec3 w, float alpha) {
    return 1.0f / (1.0f + GgxLambda(w, alpha));
}
/// Height-correlated masking-shadowing.
inline float GgxG(glm::vec3 wo, glm::vec3 wi, float alpha) {
    return 1.0f / (1.0f + GgxLambda(wo, alpha) + GgxLambda(wi, alpha));
}

/// Solid-angle pdf of wi = reflect(-wo, m) with m ~ visible normals: D_wo(m) / (4 |wo.m|).
inline float GgxPdfReflect(glm::vec3 wo, glm::vec3 wi, float alpha) {
    if (wo.z <= 0.0f || wi.z <= 0.0f) return 0.0f;
    const glm::vec3 m = glm::normalize(wo + wi);
    const float dotWoM = glm::dot(wo, m);
    if (dotWoM <= 0.0f) return 0.0f;
    // D_wo(m) = G1(wo) max(0, wo.m) D(m) / wo.z
    const float dwo = GgxG1(wo, alpha) * dotWoM * GgxD(m, alpha) / wo.z;
    return dwo / (4.0f * dotWoM);
}

// ---- GGX, anisotropic: alpha = (alpha_x along the frame's s, alpha_y along t) -----------------
// The isotropic functions above are the reference these reduce to when alpha.x == alpha.y
// (tests/sampling_test.cpp checks it); the renderer's Bsdf uses these.

/// Normal distribution D(m) = 1 / (pi ax ay ((mx/ax)^2 + (my/ay)^2 + mz^2)^2); 0 below the horizon.
inline float GgxD(glm::vec3 m, glm::vec2 alpha) {
    if (m.z <= 0.0f) return 0.0f;
    const float x = m.x / alpha.x, y = m.y / alpha.y;
    const float d = x * x + y * y + m.z * m.z;
    return 1.0f / (kPiF * alpha.x * alpha.y * d * d);
}
/// Smith Lambda: 0.5 (sqrt(1 + (ax^2 wx^2 + ay^2 wy^2) / wz^2) - 1).
inline float GgxLambda(glm::vec3 w, glm::vec2 alpha) {
    const float c2 = w.z * w.z;
    if (c2 <= 0.0f) return 1e30f;  // grazing: fully shadowed
    const float a2t2 = (alpha.x * alpha.x * w.x * w.x + alpha.y * alpha.y * w.y * w.y) / c2;
    return 0.5f * (std::sqrt(1.0f + a2t2) - 1.0f);
}
inline float GgxG1(glm::vec3 w, glm::vec2 alpha) {
    return 1.0f / (1.0f + GgxLambda(w, alpha));
}
inline float GgxG(glm::vec3 wo, glm::vec3 wi, glm::vec2 alpha) {
    return 1.0f / (1.0f + GgxLambda(wo, alpha) + GgxLambda(wi, alpha));
}

/// Visible-normal sampling (Heitz 2018), anisotropic; wo.z > 0.
inline glm::vec3 GgxSampleVisibleNormal(glm::vec3 wo, glm::vec2 alpha, glm::vec2 u) {
    const glm::vec3 vh = glm::normalize(glm::vec3(alpha.x * wo.x, alpha.y * wo.y, wo.z));
    const float lensq = vh.x * vh.x + vh.y * vh.y;
    const glm::vec3 t1 =
        lensq > 0.0f ? glm::vec3(-vh.y, vh.x, 0.0f) / std::sqrt(lensq) : glm::vec3(1, 0, 0);
    const glm::vec3 t2 = glm::cross(vh, t1);
    const float r = std::sqrt(u.x);
    const float phi = 2.0f * kPiF * u.y;
    const float p1 = r * std::cos(phi);
    float p2 = r * std::sin(phi);
    const float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * std::sqrt(std::max(0.0f, 1.0f - p1 * p1)) + s * p2;
    const glm::vec3 nh =
        p1 * t1 + p2 * t2 + std::sqrt(std::max(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
    return glm::normalize(glm::vec3(alpha.x * nh.x, alpha.y * nh.y, std::max(1e-6f, nh.z)));
}

/// Visible-normal sampling, isotropic: the anisotropic sampler with equal alphas.
inline glm::vec3 GgxSampleVisibleNormal(glm::vec3 wo, float alpha, glm::vec2 u) {
    return GgxSampleVisibleNormal(wo, glm::vec2(alpha), u);
}

/// Solid-angle pdf of wi = reflect(-wo, m) with m ~ visible normals, anisotropic.
inline float GgxPdfReflect(glm::vec3 wo, glm::vec3 wi, glm::vec2 alpha) {
    if (wo.z <= 0.0f || wi.z <= 0.0f) return 0.0f;
    const glm::vec3 m = glm::normalize(wo + wi);
    const float dotWoM = glm::dot(wo, m);
    if (dotWoM <= 0.0f) return 0.0f;
    return GgxG1(wo, alpha) * GgxD(m, alpha) / (4.0f * wo.z);
}

/// Schlick's Fresnel approximation.
inline glm::vec3 FresnelSchlick(glm::vec3 f0, float cosTheta) {
    const float m = std::clamp(1.0f - cosTheta, 0.0f, 1.0f);
    const float m2 = m * m;
    return f0 + (glm::vec3(1.0f) - f0) * (m2 * m2 * m);
}

}  // namespace texcache
