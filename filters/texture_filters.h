// SPDX-License-Identifier: Apache-2.0
// Texture-space reconstruction filters over a footprint of cached samples (Munkberg et al. 2016,
// Sec. 6.1): plug into ShadingCache::Lookup as the `filter` callable.
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <string>

#include <glm/glm.hpp>

#include "texcache/shading_cache.h"

namespace texcache {

/// What the renderer caches per sample: the shaded term, the noise-free surface normal at the
/// texel centre, the variance of the term's mean (luminance; for filters that estimate error),
/// and one per-filter extra (the filters' inputs share storage rather than every sample paying
/// for every filter's). The sample cache stores it in 16 bytes (SampleCodec below).
struct ShadedSample {
    glm::vec3 value;
    glm::vec3 normal;
    float variance = 0.0f;
    union {
        float roughness;   ///< regression: an extra feature (microfacet materials; else 0)
        float blurTexels;  ///< soft shadows: the blur std the occluders allow, in texels of the
                           ///< sample's own grid (inf: nothing blocked)
    };

    ShadedSample() : value(0.0f), normal(0.0f), roughness(0.0f) {}
    ShadedSample(glm::vec3 v, glm::vec3 n, float var, float extra = 0.0f)
        : value(v), normal(n), variance(var), roughness(extra) {}
};

/// A ShadedSample as the sample cache keeps it, in 16 bytes instead of 36, so a sample-cache slot
/// takes 32 bytes instead of 56 (1.75x the samples per MB, so less overshading in a small cache:
/// results/cache_size.md): the normal octahedron-encoded in 2 x 16 bits (error below 1e-4
/// radians; filters compare normals at cos 0.9), value, variance and extra as half floats
/// (relative precision 5e-4, far below the Monte Carlo noise of a sample; magnitudes past 65504,
/// extreme fireflies, are clamped there; inf and NaN are kept).
struct PackedShadedSample {
    uint16_t value[3];
    uint16_t variance;
    uint16_t extra;
    uint16_t unused = 0;
    uint32_t normal;  ///< octahedral, or kZeroNormal / kNanNormal
    /// Codes the encoding never makes (its coordinates stop at 65534).
    static constexpr uint32_t kZeroNormal = 0xFFFFFFFFu, kNanNormal = 0x0000FFFFu;
};

/// Octahedral encoding of a direction (Cigolle et al. 2014, "A survey of efficient
/// representations for independent unit vectors"), 16 bits per coordinate. A zero or non-finite
/// vector keeps its meaning through reserved codes (filters reject both).
uint32_t EncodeOctNormal(glm::vec3 n);
glm::vec3 DecodeOctNormal(uint32_t code);

/// Half-float encoding with finite magnitudes clamped to 65504 (inf and NaN kept as such).
uint16_t EncodeHalf(float v);
float DecodeHalf(uint16_t h);

template <>
struct SampleCodec<ShadedSample> {
    using Stored = PackedShadedSample;
    static Stored Encode(const ShadedSample& s) {
        return {{EncodeHalf(s.value.x), EncodeHalf(s.value.y), EncodeHalf(s.value.z)},
                EncodeHalf(s.variance),
                EncodeHalf(s.roughness),
                0,
                EncodeOctNormal(s.normal)};
    }
    static ShadedSample Decode(const Stored& p) {
        return {glm::vec3(DecodeHalf(p.value[0]), DecodeHalf(p.value[1]), DecodeHalf(p.value[2])),
                DecodeOctNormal(p.normal), DecodeHalf(p.variance), DecodeHalf(p.extra)};
    }
};

enum class TextureFilterKind { None, Normal, Gaussian, Regression, SoftShadow };

/// Parses a filter name; throws InputError listing the valid names.
TextureFilterKind ParseTextureFilter(const std::string& name, const std::string& where);
/// Valid filter names for help texts and errors ("none, normal, ...").
std::string TextureFilterNames();

/// The paper's trivial filter: a box (or Gaussian) window averaging samples whose normals are
/// within the threshold of the centre sample's normal (cos > 0.9 in the paper). Non-finite
/// samples are skipped (a NaN normal fails the test too). The centre always counts when it is
/// finite; when it is not (a hole, an unreachable point) and no neighbour passes the normal test,
/// the result is the plain mean of the finite taps, and 0 when there are none.
struct NormalWeightedFilter {
    float cosThreshold = 0.9f;
    float sigma = 0.0f;  ///< 0: box window; > 0: Gaussian weights exp(-d^2 / (2 sigma^2)) in texels

    glm::vec3 operator()(const FilterInput<ShadedSample>& in) const {
        int reach = 0;  // the largest squared offset, for the weight table
        if (sigma > 0.0f)
            for (const FootprintSample& t : in.taps)
                reach = std::max(reach, int(t.dx) * t.dx + int(t.dy) * t.dy);
        Sum sum(*this, in.samples[in.centre].normal, reach);
        for (size_t i = 0; i < in.samples.size(); ++i)
            sum.Add(in.samples[i], int(i) == in.centre, in.taps[i].dx, in.taps[i].dy);
        return sum.Result();
    }

    /// The same for texel (cx, cy) of a block's tile (ShadingCache's block reconstruction): the
    /// window's seen taps row by row, as the footprint lists them, so the sum is the same.
    glm::vec3 operator()(const SampleTile<ShadedSample>& t, int cx, int cy, int radius,
                         const SampleRequest&) const {
        const int c = cy * t.w + cx;
        Sum sum(*this, t.samples[c].normal, 2 * radius * radius);
        t.ForEachTap(cx, cy, radius,
                     [&](int i, int dx, int dy) { sum.Add(t.samples[i], i == c, dx, dy); });
        return sum.Result();
    }

    class Tile;
    /// The tile form with per-tile tables (ShadingCache's block reconstruction): see Tile.
    Tile Prepare(const SampleTile<ShadedSample>& t, int radius) const;

    /// Gaussian weights exp(-d2 / (2 sigma^2)) for squared offsets d2 = 0..reach: the thread's
    /// table, valid until its next call with another sigma or a larger reach. Why: one exp per
    /// tap is a third of a Gaussian-filtered AO render's filtering (perf, car 480x270, 21x21),
    /// and a window has only 2r^2 + 1 distinct offsets. Entries are the expression Sum used per
    /// tap, so results are unchanged.
    const float* GaussianWeights(int reach) const;

private:
    // The weighted mean of the taps that pass the normal test, with its fallbacks.
    struct Sum {
        const NormalWeightedFilter& f;
        glm::vec3 nc, sum{0.0f}, any{0.0f};
        const float* weights;  // by squared offset (Gaussian), or null (box)
        float wsum = 0.0f;
        int finite = 0;

        /// `reach`: the largest squared offset of the taps to come.
        Sum(const NormalWeightedFilter& filter, glm::vec3 centreNormal, int reach)
            : f(filter),
              nc(centreNormal),
              weights(f.sigma > 0.0f ? f.GaussianWeights(reach) : nullptr) {}
        void Add(const ShadedSample& s, bool centre, int dx, int dy) {
            if (!std::isfinite(s.value.x + s.value.y + s.value.z)) return;
            any += s.value, ++finite;
            if (!centre && !(glm::dot(s.normal, nc) > f.cosThreshold)) return;
            const float w = weights ? weights[dx * dx + dy * dy] : 1.0f;
            sum += w * s.value;
            wsum += w;
        }
        glm::vec3 Result() const {
            if (wsum > 0.0f) return sum / wsum;
            return finite ? any / float(finite) : glm::vec3(0.0f);
        }
    };
};

/// The normal filter over one tile, texel by texel, with what its windows share computed once.
/// Why: a block's 64 windows each test and sum up to (2r+1)^2 taps, and most tiles lie on a
/// smooth patch where every tap passes the normal test. Per tile: the mean normal m of the seen
/// taps and the least d = dot(n, m) over them. When d > 0 and 2 d^2 - 1 > cosThreshold + 1e-3,
/// every tap is within acos(d) of m, so any two are within 2 acos(d) and every tap passes
/// against any centre (the margin covers float rounding and normals off unit length by up to
/// 1e-4; taps further off make the tile take the test). A window's result is then the plain
/// mean (Gaussian: weighted mean) of its finite taps, summed in the tile form's order: the same
/// floats. Other tiles (creases, NaN normals, no bit rows) take the tile form. Valid until the
/// thread's next Prepare.
class NormalWeightedFilter::Tile {
public:
    glm::vec3 operator()(int cx, int cy, const SampleRequest& texel) const {
        if (!smooth_) return filter_(t_, cx, cy, radius_, texel);
        // ForEachTap's taps less the non-finite values.
        const int r = radius_, w = t_.w, side = 2 * r + 1;
        const uint64_t window = side >= 64 ? ~uint64_t(0) : (uint64_t(1) << side) - 1;
        glm::vec3 sum(0.0f);
        if (weights_) {
            // Gaussian: the tile form's weighted sum, in its order.
            float wsum = 0.0f;
            for (int dy = -r; dy <= r; ++dy) {
                uint64_t m = ((t_.rows[cy + dy] & finite_[cy + dy]) >> (cx - r)) & window;
                if (t_.symmetric) m &= t_.reversed[cy - dy] >> (w - 1 - cx - r);
                const ShadedSample* row = t_.samples + (cy + dy) * w + cx - r;
                for (; m; m &= m - 1) {
                    const int p = std::countr_zero(m), dx = p - r;
                    const float wt = weights_[dx * dx + dy * dy];
                    sum += wt * row[p].value;
                    wsum += wt;
                }
            }
            return wsum > 0.0f ? sum / wsum : glm::vec3(0.0f);
        }
        int n = 0;
        for (int dy = -r; dy <= r; ++dy) {
            uint64_t m = ((t_.rows[cy + dy] & finite_[cy + dy]) >> (cx - r)) & window;
            if (t_.symmetric) m &= t_.reversed[cy - dy] >> (w - 1 - cx - r);
            for (const ShadedSample* row = t_.samples + (cy + dy) * w + cx - r; m; m &= m - 1, ++n)
                sum += row[std::countr_zero(m)].value;
        }
        return n > 0 ? sum / float(n) : glm::vec3(0.0f);
    }
    /// Whether the tile's windows skip the normal test (tests check both paths).
    bool Smooth() const { return smooth_; }

private:
    friend struct NormalWeightedFilter;
    Tile(const NormalWeightedFilter& f, const SampleTile<ShadedSample>& t, int radius)
        : filter_(f), t_(t), radius_(radius) {}

    NormalWeightedFilter filter_;
    SampleTile<ShadedSample> t_;
    int radius_;
    bool smooth_ = false;
    const uint64_t* finite_ = nullptr;  // per row: bit x set when sample x's value is finite
    const float* weights_ = nullptr;    // Gaussian weights by squared offset; null: box
};

/// The 1x1 "filter": the centre sample as shaded.
struct CentreFilter {
    glm::vec3 operator()(const FilterInput<ShadedSample>& in) const {
        const glm::vec3 v = in.samples[in.centre].value;
        return std::isfinite(v.x + v.y + v.z) ? v : glm::vec3(0.0f);
    }
};

}  // namespace texcache
