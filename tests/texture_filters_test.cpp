// SPDX-License-Identifier: Apache-2.0
// Texture-space filters on synthetic footprints: the regression recovers linear signals and
// stays finite and non-negative on the hard cases (rank-deficient features, fireflies, NaN/Inf
// samples, unusable centres, huge values, wildly varying normals); the normal-weighted and
// soft-shadow filters fall back sensibly when every tap is rejected.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "filters/regression_filter.h"
#include "filters/soft_shadow_filter.h"
#include "filters/texture_filters.h"

namespace texcache {
namespace {

/// A square footprint of radius R on one face, with values, normals and variances from callables.
struct Footprint {
    std::vector<FootprintSample> taps;
    std::vector<ShadedSample> samples;
    int centre = 0;

    FilterInput<ShadedSample> Input() const {
        return {std::span<const FootprintSample>(taps), std::span<const ShadedSample>(samples),
                centre, SampleRequest{}};
    }
};

Footprint Square(
    int R, const std::function<glm::vec3(int, int)>& value,
    const std::function<glm::vec3(int, int)>& normal = [](int, int) { return glm::vec3(0, 0, 1); },
    float variance = 0.0f, int width = -1) {
    Footprint f;
    const int wx = width < 0 ? R : width;
    for (int dy = -R; dy <= R; ++dy)
        for (int dx = -wx; dx <= wx; ++dx) {
            FootprintSample t{};
            t.key = TexelKey{0, 0, uint16_t(dx + 64), uint16_t(dy + 64)};
            t.dx = dx, t.dy = dy;
            if (dx == 0 && dy == 0) f.centre = int(f.taps.size());
            f.taps.push_back(t);
            f.samples.emplace_back(value(dx, dy), glm::normalize(normal(dx, dy)), variance);
        }
    return f;
}

bool Finite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
bool NonNegativeFinite(glm::vec3 v) {
    return Finite(v) && v.x >= 0.0f && v.y >= 0.0f && v.z >= 0.0f;
}

// Gaussian noise of std `sigma` on a linear ramp: a noise-free value with a known gradient.
Footprint NoisyRamp(int R, float sigma, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> noise(0.0f, sigma);
    return Square(
        R, [&](int dx, int dy) { return glm::vec3(1.0f + 0.02f * dx - 0.01f * dy + noise(rng)); },
        [](int, int) { return glm::vec3(0, 0, 1); }, sigma * sigma);
}

// A noise-free linear signal over a planar footprint is reproduced exactly (tolerance: float
// round-off of the inputs, 1e-5 relative).
TEST(RegressionFilter, ReproducesALinearSignal) {
    const Footprint f = Square(
        8, [](int dx, int dy) { return glm::vec3(2.0f + 0.1f * dx, 1.0f - 0.05f * dy, 0.5f); });
    RegressionInfo info;
    const glm::vec3 v = RegressionFilter{64, false}.Reconstruct(f.Input(), &info);
    EXPECT_NEAR(v.x, 2.0f, 2e-5f);
    EXPECT_NEAR(v.y, 1.0f, 2e-5f);
    EXPECT_NEAR(v.z, 0.5f, 2e-5f);
    EXPECT_EQ(info.rank, 2);  // flat: constant normals carry no information
}

// Noise on a ramp: the regression picks a large ring and lands much closer to the truth than
// the centre sample (averaged over 200 footprints: RMSE at most 0.2 of the noise std).
TEST(RegressionFilter, AveragesNoiseAwayOnSmoothSignals) {
    for (int n : {1, 16}) {
        double err2 = 0.0, centre2 = 0.0;
        int rings = 0;
        for (uint32_t seed = 0; seed < 200; ++seed) {
            const Footprint f = NoisyRamp(8, 0.1f, seed);
            RegressionInfo info;
            const glm::vec3 v = RegressionFilter{n, false}.Reconstruct(f.Input(), &info);
            err2 += double(v.x - 1.0f) * (v.x - 1.0f);
            const float c = f.samples[f.centre].value.x;
            centre2 += double(c - 1.0f) * (c - 1.0f);
            rings += info.ring;
        }
        EXPECT_LT(std::sqrt(err2 / 200), 0.2 * 0.1) << "n = " << n;
        EXPECT_LT(err2, 0.05 * centre2) << "n = " << n;
        EXPECT_GT(rings / 200.0, 4.0) << "n = " << n;
    }
}

// A step edge (a shadow boundary) at the centre's doorstep: the error estimate must keep the
// model small rather than blur the edge in (result within 0.15 of the centre's side).
TEST(RegressionFilter, KeepsASharpEdge) {
    std::mt19937 rng(3);
    std::normal_distribution<float> noise(0.0f, 0.02f);
    const Footprint f = Square(
        8, [&](int dx, int) { return glm::vec3((dx <= 1 ? 1.0f : 0.0f) + noise(rng)); },
        [](int, int) { return glm::vec3(0, 0, 1); }, 0.02f * 0.02f);
    RegressionInfo info;
    const glm::vec3 v = RegressionFilter{16, false}.Reconstruct(f.Input(), &info);
    EXPECT_NEAR(v.x, 1.0f, 0.15f) << "ring " << info.ring;
    EXPECT_LE(info.ring, 2);
}

// Rank-deficient features: a footprint one texel wide (collinear coordinates, as at a boundary
// where only one column exists) and a single tap. Finite, exact on a linear signal.
TEST(RegressionFilter, RankDeficientFootprints) {
    const Footprint column = Square(
        8, [](int, int dy) { return glm::vec3(1.0f + 0.05f * dy); },
        [](int, int) { return glm::vec3(0, 0, 1); }, 0.0f, 0);
    RegressionInfo info;
    glm::vec3 v = RegressionFilter{4, false}.Reconstruct(column.Input(), &info);
    EXPECT_EQ(info.rank, 1);
    EXPECT_NEAR(v.x, 1.0f, 1e-5f);

    const Footprint single = Square(0, [](int, int) { return glm::vec3(0.25f); });
    v = RegressionFilter{4, false}.Reconstruct(single.Input(), &info);
    EXPECT_EQ(info.rank, 0);
    EXPECT_FLOAT_EQ(v.x, 0.25f);

    // Normals that vary exactly with the coordinates (a cylinder's normals are a function of u):
    // collinear features, the TSVD keeps only the independent directions.
    const Footprint cyl = Square(
        8, [](int dx, int) { return glm::vec3(0.5f + 0.01f * dx); },
        [](int dx, int) { return glm::vec3(std::sin(0.01f * dx), 0.0f, std::cos(0.01f * dx)); });
    v = RegressionFilter{4, false}.Reconstruct(cyl.Input(), &info);
    EXPECT_LE(info.rank, 3);
    EXPECT_NEAR(v.x, 0.5f, 1e-4f);
}

// Wildly varying normals (a valence-3 or high-valence corner seen at a coarse mip, tiny faces
// folded into one footprint): full rank, finite, non-negative.
TEST(RegressionFilter, ChaoticNormalsStayFinite) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    const Footprint f = Square(
        8, [&](int, int) { return glm::vec3(0.5f + 0.5f * u(rng)); },
        [&](int, int) { return glm::vec3(u(rng), u(rng), u(rng) + 1.5f); }, 0.01f);
    RegressionInfo info;
    const glm::vec3 v = RegressionFilter{4, false}.Reconstruct(f.Input(), &info);
    EXPECT_TRUE(NonNegativeFinite(v));
    EXPECT_LE(v.x, 1.0f);
    EXPECT_EQ(info.rank, 5);
}

// A firefly 1e6 times brighter in the footprint. With per-sample variances (n = 16), the models
// that include it have a huge a-priori error and the result stays at the surrounding level
// (within 2x). With one ray per sample (n = 1, noise estimated from the footprint) it reads as
// noise and is spread over a large ring: its energy is kept at no more than 1/81 of its peak
// (at least a 9x9 average). A firefly at the centre stays finite and at most its own value.
TEST(RegressionFilter, Fireflies) {
    Footprint f = NoisyRamp(8, 0.05f, 11);
    f.samples[f.centre + 3].value = glm::vec3(1e6f);
    glm::vec3 v = RegressionFilter{16, false}(f.Input());
    EXPECT_TRUE(NonNegativeFinite(v));
    EXPECT_LT(v.x, 2.0f);
    v = RegressionFilter{1, false}(f.Input());
    EXPECT_TRUE(NonNegativeFinite(v));
    EXPECT_LE(v.x, 1e6f / 81.0f);
    EXPECT_GT(v.x, 0.5f);

    f = NoisyRamp(8, 0.05f, 12);
    f.samples[f.centre].value = glm::vec3(1e6f);
    for (int n : {1, 16}) {
        v = RegressionFilter{n, false}(f.Input());
        EXPECT_TRUE(NonNegativeFinite(v));
        EXPECT_LE(v.x, 1e6f);
    }
}

// NaN and Inf samples (values, normals, variances) are excluded and counted, never propagated.
TEST(RegressionFilter, NonFiniteSamplesAreExcludedAndCounted) {
    Footprint f = NoisyRamp(8, 0.05f, 5);
    f.samples[1].value = glm::vec3(NAN);
    f.samples[2].value = glm::vec3(INFINITY, 0, 0);
    f.samples[3].normal = glm::vec3(NAN);
    f.samples[4].variance = INFINITY;
    f.samples[5].value = glm::vec3(-INFINITY);
    RegressionInfo info;
    const glm::vec3 v = RegressionFilter{16, false}.Reconstruct(f.Input(), &info);
    EXPECT_EQ(info.rejected, 5);
    EXPECT_FALSE(info.fallback);
    EXPECT_TRUE(NonNegativeFinite(v));
    EXPECT_NEAR(v.x, 1.0f, 0.05f);
}

// An unusable centre (a hole, a NaN-shaded point) falls back to the mean of the usable taps
// with the centre's normal, or of all usable taps; with nothing usable, 0.
TEST(RegressionFilter, UnusableCentreFallsBack) {
    Footprint f = Square(2, [](int, int) { return glm::vec3(0.7f); });
    f.samples[f.centre].value = glm::vec3(NAN);
    RegressionInfo info;
    glm::vec3 v = RegressionFilter{4, false}.Reconstruct(f.Input(), &info);
    EXPECT_TRUE(info.fallback);
    EXPECT_NEAR(v.x, 0.7f, 1e-6f);

    f.samples[f.centre].normal = glm::vec3(NAN);
    v = RegressionFilter{4, false}.Reconstruct(f.Input(), &info);
    EXPECT_NEAR(v.x, 0.7f, 1e-6f);

    for (ShadedSample& s : f.samples) s.value = glm::vec3(NAN);
    v = RegressionFilter{4, false}.Reconstruct(f.Input(), &info);
    EXPECT_EQ(v, glm::vec3(0.0f));
}

// Radiance is never negative, even where a steep ramp extrapolates below zero at the centre.
TEST(RegressionFilter, NeverNegative) {
    const Footprint f = Square(8, [](int dx, int) { return glm::vec3(dx > 0 ? 0.1f * dx : 0.0f); });
    const glm::vec3 v = RegressionFilter{64, false}(f.Input());
    EXPECT_TRUE(NonNegativeFinite(v));
}

// Huge magnitudes (1e30: far beyond any sane radiance, well inside float) stay finite.
TEST(RegressionFilter, HugeValuesStayFinite) {
    const Footprint f = Square(
        8, [](int dx, int dy) { return glm::vec3(1e30f * (1.0f + 0.01f * dx + 0.01f * dy)); });
    const glm::vec3 v = RegressionFilter{4, false}(f.Input());
    EXPECT_TRUE(Finite(v));
    EXPECT_NEAR(v.x / 1e30f, 1.0f, 1e-3f);
}

// The roughness feature: a signal that depends on roughness only (a microfacet material with a
// roughness texture) is explained by it; without the feature the same footprint is not.
TEST(RegressionFilter, RoughnessFeature) {
    auto rough = [](int dx, int dy) { return 0.5f + 0.4f * std::sin(1.3f * dx + 0.7f * dy); };
    Footprint f = Square(8, [&](int dx, int dy) { return glm::vec3(2.0f * rough(dx, dy)); });
    for (size_t i = 0; i < f.samples.size(); ++i)
        f.samples[i].roughness = rough(f.taps[i].dx, f.taps[i].dy);
    const float truth = 2.0f * rough(0, 0);
    f.samples[f.centre].value = glm::vec3(truth + 0.3f);  // a noisy centre
    for (auto& s : f.samples) s.variance = 0.01f;
    const glm::vec3 with = RegressionFilter{4, true}(f.Input());
    EXPECT_NEAR(with.x, truth, 0.05f);
}

// Every tap rejected by the normal test and the centre unusable: the normal filter returns the
// mean of the finite taps; with none finite, 0.
TEST(NormalWeightedFilter, AllTapsRejectedFallsBackToTheMean) {
    Footprint f = Square(
        2, [](int dx, int) { return glm::vec3(dx >= 0 ? 1.0f : 0.5f); },
        [](int dx, int) { return glm::vec3(dx >= 0 ? 1.0f : -1.0f, 0.0f, 0.1f); });
    f.samples[f.centre].value = glm::vec3(NAN);
    f.samples[f.centre].normal = glm::vec3(NAN);
    glm::vec3 v = NormalWeightedFilter{0.9f, 0.0f}(f.Input());
    EXPECT_TRUE(Finite(v));
    EXPECT_GT(v.x, 0.5f);
    EXPECT_LT(v.x, 1.0f);
    for (ShadedSample& s : f.samples) s.value = glm::vec3(INFINITY);
    EXPECT_EQ(NormalWeightedFilter{}(f.Input()), glm::vec3(0.0f));
    // Fireflies are averaged, not hidden: a 1e6 tap stays finite.
    f = Square(6, [](int, int) { return glm::vec3(1.0f); });
    f.samples[7].value = glm::vec3(1e6f);
    EXPECT_TRUE(Finite(NormalWeightedFilter{}(f.Input())));
}

// A w x h tile of samples with its seen bytes and bit rows, and the footprint a window of it
// gives GatherFootprint's way (its seen taps row by row, mirrored ones only when symmetric).
struct TestTile {
    int w, h;
    std::vector<ShadedSample> samples;
    std::vector<uint8_t> seen;
    std::vector<uint64_t> rows, reversed;

    TestTile(int width, int height, std::mt19937& rng, float normalSpread, float seenFraction)
        : w(width), h(height), samples(size_t(w * h)), seen(samples.size()) {
        std::uniform_real_distribution<float> u(-1.0f, 1.0f);
        for (size_t i = 0; i < samples.size(); ++i) {
            const glm::vec3 n(normalSpread * u(rng), normalSpread * u(rng), 1.0f);
            samples[i] = ShadedSample(glm::vec3(u(rng) + 1.0f, u(rng) + 1.0f, u(rng) + 1.0f),
                                      glm::normalize(n), 0.0f);
            seen[i] = u(rng) * 0.5f + 0.5f < seenFraction;
        }
    }
    void MakeBits() {
        rows.assign(size_t(h), 0), reversed.assign(size_t(h), 0);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x)
                if (seen[size_t(y * w + x)]) {
                    rows[size_t(y)] |= uint64_t(1) << x;
                    reversed[size_t(y)] |= uint64_t(1) << (w - 1 - x);
                }
    }
    SampleTile<ShadedSample> View(bool symmetric, bool bits) const {
        return {w,
                h,
                samples.data(),
                seen.data(),
                symmetric,
                bits ? rows.data() : nullptr,
                bits ? reversed.data() : nullptr};
    }
    Footprint Window(int cx, int cy, int R, bool symmetric) const {
        const int c = cy * w + cx;
        Footprint f;
        for (int dy = -R; dy <= R; ++dy)
            for (int dx = -R; dx <= R; ++dx) {
                const int i = c + dy * w + dx, m = c - dy * w - dx;
                if (!seen[size_t(i)] || (symmetric && !seen[size_t(m)])) continue;
                if (i == c) f.centre = int(f.taps.size());
                FootprintSample t{};
                t.dx = int16_t(dx), t.dy = int16_t(dy);
                f.taps.push_back(t);
                f.samples.push_back(samples[size_t(i)]);
            }
        return f;
    }
};

// The block (tile) form of the normal filter gives what the footprint form gives for the same
// taps, bit for bit (same taps in the same order: ShadingCache relies on it), from seen bytes and
// from bit rows, with and without mirrored taps, for box and Gaussian weights, with holes (NaN and
// inf samples), rejected normals and unseen taps.
TEST(NormalWeightedFilter, TileFormEqualsFootprintForm) {
    const int R = 4;
    std::mt19937 rng(11);
    TestTile tile(15, 13, rng, 0.4f, 2.0f / 3.0f);
    tile.samples[20].value = glm::vec3(NAN), tile.samples[33].value = glm::vec3(INFINITY);
    tile.samples[47].normal = glm::vec3(NAN);
    tile.MakeBits();
    int compared = 0;
    for (bool withBits : {false, true})
        for (bool symmetric : {false, true})
            for (float sigma : {0.0f, 2.0f})
                for (int cy = R; cy < tile.h - R; ++cy)
                    for (int cx = R; cx < tile.w - R; ++cx) {
                        if (!tile.seen[size_t(cy * tile.w + cx)]) continue;
                        const NormalWeightedFilter filter{0.9f, sigma};
                        const glm::vec3 a = filter(tile.Window(cx, cy, R, symmetric).Input()),
                                        b = filter(tile.View(symmetric, withBits), cx, cy, R, {});
                        ASSERT_EQ(a, b) << cx << "," << cy << " sigma " << sigma;
                        ++compared;
                    }
    EXPECT_GT(compared, 100);
}

// The prepared tile (block reconstruction's form) gives the tile form's values bit for bit (the
// same finite taps summed in the same order; the stated tolerance is 0), whether its windows skip
// the normal test (smooth tiles) or take it: radius 0, 3 and 10, windows at the tile's borders,
// NaN and inf values (and finite components whose sum overflows), a non-finite centre, unseen
// taps, NaN and non-unit normals, creases (normals 40 degrees apart), Gaussian weights (smooth
// tiles too), and a spread of normals just inside the bound (+-8 degrees: any two within 23,
// cos 0.92).
TEST(NormalWeightedFilter, PreparedTileEqualsTileForm) {
    std::mt19937 rng(5);
    int smooth = 0, tested = 0, compared = 0;
    for (int R : {0, 3, 10})
        for (int variant = 0; variant < 7; ++variant) {
            const float spread = variant == 1 ? std::tan(0.14f) / std::sqrt(2.0f) : 0.03f;
            TestTile tile(2 * R + 9, 2 * R + 11, rng, spread, variant == 0 ? 1.0f : 0.6f);
            const int centre = (tile.h / 2) * tile.w + tile.w / 2;
            tile.seen[size_t(centre)] = tile.seen[size_t(centre - 1)] = 1;
            tile.seen[size_t(centre + 1)] = 1;
            tile.samples[3].value = glm::vec3(NAN);
            tile.samples[size_t(tile.w + 4)].value = glm::vec3(1.0f, -INFINITY, 0.0f);
            tile.samples[size_t(2 * tile.w + 2)].value = glm::vec3(3e38f);  // sum overflows
            tile.samples[size_t(centre)].value.y = variant == 2 ? NAN : 1.5f;
            if (variant == 3) tile.samples[size_t(centre + 1)].normal = glm::vec3(NAN);
            if (variant == 4) tile.samples[size_t(centre - 1)].normal *= 1.01f;
            if (variant == 5)  // a crease down the middle
                for (int y = 0; y < tile.h; ++y)
                    for (int x = tile.w / 2; x < tile.w; ++x)
                        tile.samples[size_t(y * tile.w + x)].normal =
                            glm::vec3(std::sin(0.7f), 0.0f, std::cos(0.7f));
            tile.MakeBits();
            for (bool symmetric : {false, true}) {
                const float sigma = variant == 6 ? 0.5f * float(R) + 0.5f : 0.0f;
                const NormalWeightedFilter filter{0.9f, sigma};
                const SampleTile<ShadedSample> t = tile.View(symmetric, true);
                const NormalWeightedFilter::Tile prepared = filter.Prepare(t, R);
                ++tested, smooth += prepared.Smooth();
                EXPECT_EQ(prepared.Smooth(), variant <= 2 || variant == 6)
                    << "variant " << variant << " r " << R;
                for (int cy = R; cy < tile.h - R; ++cy)
                    for (int cx = R; cx < tile.w - R; ++cx) {
                        if (!tile.seen[size_t(cy * tile.w + cx)]) continue;
                        const glm::vec3 a = filter(t, cx, cy, R, {}), b = prepared(cx, cy, {});
                        ASSERT_EQ(a, b) << "variant " << variant << " r " << R << " texel " << cx
                                        << "," << cy << " symmetric " << symmetric;
                        ++compared;
                    }
            }
        }
    EXPECT_GT(smooth, 0);
    EXPECT_LT(smooth, tested);
    EXPECT_GT(compared, 1000);
}

// The Gaussian weight table holds, for every squared offset, the weight computed per tap (exact:
// the same float expression), whether it was built for this reach, grown from a smaller one, or
// rebuilt after another sigma.
TEST(NormalWeightedFilter, GaussianWeightTableIsThePerTapWeight) {
    for (float sigma : {0.5f, 3.0f, 5.5f, 0.5f}) {
        const NormalWeightedFilter f{0.9f, sigma};
        const float inv2s2 = 1.0f / (2.0f * sigma * sigma);
        for (int reach : {2, 200, 50}) {
            const float* w = f.GaussianWeights(reach);
            for (int d2 = 0; d2 <= reach; ++d2)
                ASSERT_EQ(w[d2], std::exp(-float(d2) * inv2s2))
                    << "sigma " << sigma << " d2 " << d2;
        }
    }
}

// Soft shadows: the blur follows the occluder slope. A contact shadow (tiny blur radius) keeps
// the centre's visibility; no occluder around gives the wide average; NaN radii are ignored.
TEST(SoftShadowFilter, WidthFollowsTheOccluderDistance) {
    auto vis = [](int dx, int) { return glm::vec3(dx < 0 ? 0.0f : 1.0f); };
    Footprint f = Square(8, vis);
    for (auto& s : f.samples) s.blurTexels = 0.1f;  // clamped to 0.5
    glm::vec3 v = SoftShadowFilter{}(f.Input());
    // A 0.5-texel Gaussian: the centre's lit side weighs 1.44 against 0.17 for the dark column.
    EXPECT_GT(v.x, 0.85f);
    for (auto& s : f.samples) s.blurTexels = INFINITY;  // nothing blocked: widest filter
    v = SoftShadowFilter{}(f.Input());
    EXPECT_NEAR(v.x, 9.0f / 17.0f, 0.1f);
    for (auto& s : f.samples) s.blurTexels = NAN;
    v = SoftShadowFilter{}(f.Input());
    EXPECT_TRUE(Finite(v));
    for (auto& s : f.samples) s.blurTexels = 4.0f;  // a penumbra-wide blur
    v = SoftShadowFilter{}(f.Input());
    EXPECT_GT(v.x, 0.5f);
    EXPECT_LT(v.x, 0.9f);
}

// The sample cache's compact form: values, variance and the extra within half precision (2^-11
// relative), clamped at 65504, inf and NaN kept; normals within 1e-4 radians over the whole sphere
// (poles, equator, octant seams); zero and non-finite normals keep their meaning (filters reject
// both); 16 bytes.
TEST(SampleCodec, PackedSamplesRoundTrip) {
    static_assert(sizeof(PackedShadedSample) == 16);
    using Codec = SampleCodec<ShadedSample>;
    std::vector<glm::vec3> normals = {{0, 0, 1},  {0, 0, -1}, {1, 0, 0},        {-1, 0, 0},
                                      {0, 1, 0},  {0, -1, 0}, {1, 1, 1},        {-1, -1, -1},
                                      {1, -1, 0}, {-1, 1, 0}, {1e-7f, 0, -1.0f}};
    uint64_t state = 12345;
    auto next = [&] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return float(state >> 40) / float(1 << 24) * 2.0f - 1.0f;
    };
    for (int i = 0; i < 10000; ++i) normals.push_back({next(), next(), next()});
    double worst = 0.0;
    for (glm::vec3 n : normals) {
        if (glm::length(n) == 0.0f) continue;
        n = glm::normalize(n);
        const ShadedSample s(glm::vec3(0.3f, 1234.5f, -3e-3f), n, 1.7e-3f, 0.37f);
        const ShadedSample d = Codec::Decode(Codec::Encode(s));
        for (int k = 0; k < 3; ++k)
            EXPECT_NEAR(d.value[k], s.value[k], std::abs(s.value[k]) / 2048);
        EXPECT_NEAR(d.variance, s.variance, s.variance / 2048);
        EXPECT_NEAR(d.roughness, s.roughness, s.roughness / 2048);
        ASSERT_TRUE(std::isfinite(d.normal.x + d.normal.y + d.normal.z));
        // atan2(|a x b|, a . b) in double: acos of a float dot product cannot resolve angles
        // below ~3e-4 radians.
        const glm::dvec3 a(n), b(d.normal);
        worst = std::max(worst, std::atan2(glm::length(glm::cross(a, b)), glm::dot(a, b)));
    }
    EXPECT_LT(worst, 1e-4) << "worst angular error " << worst;
    EXPECT_EQ(DecodeOctNormal(EncodeOctNormal(glm::vec3(0.0f))), glm::vec3(0.0f));
    const glm::vec3 bad = DecodeOctNormal(EncodeOctNormal(glm::vec3(NAN, 0.0f, 1.0f)));
    EXPECT_TRUE(std::isnan(bad.x));
    EXPECT_TRUE(std::isnan(DecodeOctNormal(EncodeOctNormal(glm::vec3(INFINITY, 0, 0))).x));
    // Values: a 1e6 firefly is clamped to the largest half; inf, NaN and 0 survive.
    EXPECT_EQ(DecodeHalf(EncodeHalf(1e6f)), 65504.0f);
    EXPECT_EQ(DecodeHalf(EncodeHalf(-1e6f)), -65504.0f);
    EXPECT_EQ(DecodeHalf(EncodeHalf(INFINITY)), INFINITY);
    EXPECT_TRUE(std::isnan(DecodeHalf(EncodeHalf(NAN))));
    EXPECT_EQ(DecodeHalf(EncodeHalf(0.0f)), 0.0f);
    EXPECT_EQ(DecodeHalf(EncodeHalf(1.0f)), 1.0f);
    // Reserved codes are never produced by a real direction.
    for (glm::vec3 n : normals) {
        if (glm::length(n) == 0.0f) continue;
        const uint32_t c = EncodeOctNormal(n);
        EXPECT_NE(c, PackedShadedSample::kZeroNormal);
        EXPECT_NE(c, PackedShadedSample::kNanNormal);
    }
}

}  // namespace
}  // namespace texcache
