// SPDX-License-Identifier: Apache-2.0
// The pass's sequence of first-bounce points (PixelSequence): aligned blocks of pixels get nets,
// the order is the same for any thread count, and the noise it leaves has no pattern that
// repeats with the pixel grid.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <tbb/global_control.h>

#include "renderer/integrators/path_tracer.h"
#include "renderer/integrators/sampling.h"
#include "renderer/render.h"
#include "renderer/render_options.h"
#include "test_util.h"

namespace texcache {
namespace {

RenderOptions AoOptions(int spp) {
    RenderOptions o;
    o.integrator = IntegratorKind::AO;
    o.width = 64, o.height = 64;
    o.spp = spp;
    o.progress = false;
    return o;
}

/// The pass's points of camera samples [s0, s1) of the pixels of the side x side block at
/// (x0, y0), dimension pair `pair`, `rays` per camera sample.
std::vector<glm::vec2> BlockPoints(const internal::PixelSequence& seq, int x0, int y0, int side,
                                   int s0, int s1, int rays, uint32_t pair = 0) {
    std::vector<glm::vec2> pts;
    for (int y = y0; y < y0 + side; ++y)
        for (int x = x0; x < x0 + side; ++x)
            for (int s = s0; s < s1; ++s)
                for (int i = 0; i < rays; ++i)
                    pts.push_back(seq.At(seq.First(x, y, s) + uint64_t(i), pair));
    return pts;
}

/// Whether n = 2^m points put exactly one point in every elementary box 2^-a x 2^-(m-a): for
/// each a, their boxes' numbers are n different ones.
bool IsNet(const std::vector<glm::vec2>& pts) {
    const int m = std::countr_zero(pts.size());
    if (size_t(1) << m != pts.size()) return false;
    std::vector<uint32_t> boxes(pts.size());
    for (int a = 0; a <= m; ++a) {
        std::transform(pts.begin(), pts.end(), boxes.begin(), [&](glm::vec2 p) {
            return uint32_t(p.x * float(1 << a)) << (m - a) | uint32_t(p.y * float(1 << (m - a)));
        });
        std::sort(boxes.begin(), boxes.end());
        if (std::adjacent_find(boxes.begin(), boxes.end()) != boxes.end() ||
            boxes.back() >= pts.size())
            return false;
    }
    return true;
}

// Every aligned 2^k x 2^k block of pixels takes a net of the pass's points (hit bins of 4x4
// pixels and more average them together), and so does each pixel's samples of the pass: for a
// 4x4 block at 4 spp the first coordinates of its 64 points fall in the 64 strata of 1/64 once
// each. Blocks that are not aligned are not nets in general, and that is not asked.
TEST(PixelSequence, AlignedBlocksOfPixelsAreNets) {
    for (int rays : {1, 2}) {
        RenderOptions o = AoOptions(4);
        o.width = 200, o.height = 120;
        o.aoSamples = rays;
        o.seed = 11;
        const internal::PixelSequence seq(o, 0, 4);
        for (int side : {1, 2, 4, 8})
            for (int y0 = 0; y0 + side <= 32; y0 += side)
                for (int x0 = 64; x0 + side <= 104; x0 += side) {
                    const std::vector<glm::vec2> pts = BlockPoints(seq, x0, y0, side, 0, 4, rays);
                    ASSERT_TRUE(IsNet(pts)) << side << " " << x0 << " " << y0;
                    if (side != 4 || rays != 1) continue;
                    std::vector<int> strata(64, 0);
                    for (const glm::vec2& p : pts) ++strata[size_t(p.x * 64.0f)];
                    ASSERT_EQ(std::count(strata.begin(), strata.end(), 1), 64);
                }
        // The light and BSDF pairs of the path integrators share the order.
        EXPECT_TRUE(IsNet(BlockPoints(seq, 16, 16, 4, 0, 4, rays, 1)));
        EXPECT_TRUE(IsNet(BlockPoints(seq, 16, 16, 4, 0, 4, rays, 2)));
    }
}

// The order is a bijection: a 64x48 image's camera samples of a pass of 8 (at 2 rays each) take
// the first 64 x 64 x 8 x 2 points, each once (the Morton square of 64 x 64 pixels holds the
// image). A pass of 3 samples leaves one slot of 4 unused in each pixel: which one is random
// (each of the four in 25% +- 5% of 4096 pixels), not the same everywhere; and another pass, or
// another seed, deals the points in another order.
TEST(PixelSequence, OrderIsABijectionAndDiffersPerPass) {
    RenderOptions o = AoOptions(8);
    o.width = 64, o.height = 48;
    o.aoSamples = 2;
    const internal::PixelSequence seq(o, 0, 8);
    std::vector<bool> taken(64 * 64 * 8 * 2, false);
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x)
            for (int s = 0; s < 8; ++s) {
                const uint64_t j = seq.First(x, y, s);
                ASSERT_EQ(j % 2, 0u);
                ASSERT_LT(j, taken.size());
                ASSERT_FALSE(taken[j]) << x << " " << y << " " << s;
                taken[j] = true;
            }

    o.width = o.height = 64;
    o.aoSamples = 1;
    const internal::PixelSequence three(o, 4, 7);
    int unused[4] = {0, 0, 0, 0};
    for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x) {
            int quarters = 0;
            for (int s = 4; s < 7; ++s) quarters |= 1 << int(three.At(three.First(x, y, s)).x * 4);
            ASSERT_EQ(std::popcount(unsigned(quarters)), 3);
            ++unused[std::countr_zero(unsigned(~quarters))];
        }
    for (int q = 0; q < 4; ++q) EXPECT_NEAR(unused[q] / 4096.0, 0.25, 0.05) << q;

    const internal::PixelSequence next(o, 7, 10);
    RenderOptions other = o;
    other.seed = 1;
    const internal::PixelSequence otherSeed(other, 4, 7);
    int sameNext = 0, sameSeed = 0;
    for (int x = 0; x < 64; ++x) {
        sameNext += three.First(x, 5, 4) == next.First(x, 5, 7);
        sameSeed += three.First(x, 5, 4) == otherSeed.First(x, 5, 4);
    }
    // A pixel's first slot is uniform over the pass's 64 x 64 x 4: 0.016 equal by chance.
    EXPECT_LE(sameNext, 2);
    EXPECT_LE(sameSeed, 2);
}

// Each level of the order is shuffled: over the 2^k x 2^k blocks of a 1024 x 1024 image (one
// sample, one ray: a pixel's number is its point), the place of a block's four children in the
// block's numbers is uniform whatever the child's place in the block (each block's children
// take the four places, a random permutation: Pearson's chi^2 over the 4 x 4 table of counts is
// 4/3 of a chi^2 with 9 degrees of freedom; chi^2 / 12 < 4, 4e-5 by chance), for every level
// with 64 blocks or more; and the two children that share a half of the block's numbers lie
// side by side or above each other, each in half the blocks (within 5 standard deviations),
// never diagonally.
TEST(PixelSequence, EveryLevelIsShuffled) {
    RenderOptions o = AoOptions(1);
    o.width = o.height = 1024;
    const internal::PixelSequence seq(o, 0, 1);
    for (int k = 0; k < 7; ++k) {
        const int side = 1 << (k + 1);  // a block of level k: side x side pixels
        int count[4][4] = {};
        int across = 0, blocks = 0;
        for (int y = 0; y < o.height; y += side)
            for (int x = 0; x < o.width; x += side) {
                uint32_t digit[4];
                for (int c = 0; c < 4; ++c)
                    digit[c] =
                        uint32_t(seq.First(x + (c & 1) * side / 2, y + (c >> 1) * side / 2, 0) >>
                                 (2 * k)) &
                        3u;
                for (int c = 0; c < 4; ++c) ++count[c][digit[c]];
                across += (digit[0] >> 1) == (digit[1] >> 1);
                ASSERT_NE(digit[0] >> 1, digit[3] >> 1) << k;
                ++blocks;
            }
        double chi2 = 0.0;
        for (auto& row : count)
            for (int n : row) chi2 += (n - blocks / 4.0) * (n - blocks / 4.0) / (blocks / 4.0);
        EXPECT_LT(chi2 / 12.0, 4.0) << "level " << k << ", " << blocks << " blocks";
        std::printf("level %d: %6d blocks, chi2/12 %.2f, side by side %.3f\n", k, blocks,
                    chi2 / 12.0, double(across) / blocks);
        // 5 standard deviations of a fraction of 1/2.
        EXPECT_NEAR(double(across) / blocks, 0.5, 2.5 / std::sqrt(double(blocks))) << k;
    }
}

/// A flat field: a plane (y = 0) seen from 0.3 above at a grazing angle (the frame's rows span
/// 1.7 to 10 units: texture space's texels, and so its bins, are far narrower across the rows
/// than along them), under a plane at y = 0.5 (AO: rays of length 1 escape below 60 degrees
/// from the normal, a cosine-weighted fraction of exactly 1/4 everywhere) or under a quad light
/// there (direct and path: light from almost all of the hemisphere, sampled by area with MIS, so
/// each hit's estimate is noisy). Expected values vary by under 1e-3 over the frame.
Scene FlatField(bool quadLight) {
    Scene s = test::OneObjectScene(test::PlaneCage(20.0f), glm::vec3(0.5f));
    if (quadLight) {
        QuadLight q;
        q.corner = glm::vec3(-100.0f, 0.5f, -100.0f);
        q.edge1 = glm::vec3(200.0f, 0.0f, 0.0f);
        q.edge2 = glm::vec3(0.0f, 0.0f, 200.0f);  // emits downwards: cross(e1, e2) = -Y
        q.transform.keys.push_back({});
        s.quadLights.push_back(q);
    } else {
        ControlCage ceiling = test::PlaneCage(20.0f);
        for (auto& p : ceiling.positions) p[1] = 0.5f;
        s.meshes.push_back(ceiling);
        Object o = s.objects[0];
        o.mesh = 1;
        s.objects.push_back(o);
    }
    s.camera.pose.keys = {test::LookAt({0.0f, 0.3f, 3.0f}, {0.0f, 0.0f, 0.0f})};
    s.camera.fovYDegrees = 8.0f;
    return s;
}

/// Options for FlatField: AO rays of length 1; texture space as `--shading texture` takes it
/// there (shaded at the hits, all light of the quad cached).
RenderOptions FlatFieldOptions(IntegratorKind integrator, bool texture, int spp) {
    RenderOptions o = AoOptions(spp);
    o.integrator = integrator;
    o.aoDistance = 1.0f;
    o.texture.enabled = texture;
    o.texture.samples = TextureSamples::Hits;
    o.texture.cacheDirect = true;
    return o;
}

/// The pixel classes' test of a flat field's noise, for classes c = (x mod p, y mod p). Each
/// 16 x 16 tile of an image gives d_c, the mean of class c (luminance) less the tile's mean;
/// over an image's T tiles, t_c = mean(d_c) / sqrt(var(d_c) / T). Noise without a pattern gives
/// mean(d_c) about 0, and a pattern with the pixel grid the same d_c in every tile. With the
/// classes exchangeable, (1 - 1/p^2) sum_c t_c^2 is about chi^2 with p^2 - 1 degrees of freedom
/// (the d_c sum to 0); summed over images of independent seeds. The variance comes from the
/// tiles, not from the pixels: neighbouring pixels' errors are correlated (they cancel within a
/// net; in texture space they share bins), so the pixels' own variance would misjudge the
/// class means'.
struct ClassTest {
    int p;
    double chi2 = 0.0;
    int dof = 0;
    void Add(const Image& img) {
        constexpr int kTile = 16;
        const size_t classes = size_t(p * p);
        std::vector<double> sum(classes, 0.0), sum2(classes, 0.0);
        int tiles = 0;
        for (int y0 = 0; y0 + kTile <= img.height; y0 += kTile)
            for (int x0 = 0; x0 + kTile <= img.width; x0 += kTile, ++tiles) {
                std::vector<double> m(classes, 0.0);
                double all = 0.0;
                for (int y = y0; y < y0 + kTile; ++y)
                    for (int x = x0; x < x0 + kTile; ++x) {
                        const float* px = img.At(x, y);
                        const double v = (double(px[0]) + px[1] + px[2]) / 3.0;
                        m[size_t(y % p * p + x % p)] += v, all += v;
                    }
                for (size_t c = 0; c < classes; ++c) {
                    const double d = (m[c] - all / double(classes)) / (kTile * kTile / classes);
                    sum[c] += d, sum2[c] += d * d;
                }
            }
        double t2 = 0.0;
        for (size_t c = 0; c < classes; ++c) {
            const double mean = sum[c] / tiles;
            const double var = (sum2[c] - tiles * mean * mean) / (tiles - 1);
            t2 += mean * mean * tiles / var;
        }
        chi2 += t2 * (1.0 - 1.0 / double(classes));
        dof += int(classes) - 1;
    }
    double PerDof() const { return chi2 / dof; }
};

// The noise of a flat field at 4 spp has no pattern with the pixel grid, per hit or shaded at
// the hits in texture space, for AO and path tracing: over 8 seeds of 128 x 128 pixels, the
// classes (x mod 2, y mod 2) and (x mod 4, y mod 4) give chi^2 / dof < 2.5 (ClassTest). Noise
// without a pattern gives 1; with 24 degrees of freedom 2.5 is exceeded by chance with
// probability 1e-4 (the t statistics' heavier tails make it a little more). A Morton order with
// the same scramble for every block gives chi^2 / dof in the thousands per hit.
TEST(PixelSequence, FlatFieldNoiseHasNoPixelPattern) {
    struct Case {
        const char* name;
        IntegratorKind integrator;
        bool texture;
    };
    for (const Case& k : {Case{"ao per hit", IntegratorKind::AO, false},
                          Case{"ao texture", IntegratorKind::AO, true},
                          Case{"path per hit", IntegratorKind::Path, false},
                          Case{"path texture", IntegratorKind::Path, true}}) {
        const Scene s = FlatField(k.integrator != IntegratorKind::AO);
        const RenderScene rs(s, {});
        RenderOptions o = FlatFieldOptions(k.integrator, k.texture, 4);
        o.width = o.height = 128;
        ClassTest two{2}, four{4};
        double sum = 0.0;
        const int seeds = 8;
        for (int seed = 0; seed < seeds; ++seed) {
            o.seed = uint64_t(seed);
            const Image img = Render(rs, o).beauty;
            two.Add(img), four.Add(img);
            for (float v : img.data) sum += v;
        }
        const double mean = sum / double(seeds * o.width * o.height * 3);
        std::printf("%-13s mean %.4f  chi2/dof: period 2 %.2f, period 4 %.2f\n", k.name, mean,
                    two.PerDof(), four.PerDof());
        RecordProperty(std::string(k.name) + " chi2/dof", std::to_string(two.PerDof()));
        EXPECT_LT(two.PerDof(), 2.5) << k.name;
        EXPECT_LT(four.PerDof(), 2.5) << k.name;
        if (k.integrator == IntegratorKind::AO) {  // 8 sd of the mean of independent pixels
            EXPECT_NEAR(mean, 0.25, 0.005) << k.name;
        }
    }
}

// The same seed gives the same image, bit for bit, for 1 and 2 threads: a camera sample's points
// depend on its pixel, its sample and the pass alone, whatever tile or thread traces it. Per hit
// and at the hits in texture space, AO and path tracing, a pass of 3 samples (a slot unused).
TEST(PixelSequence, SameImageForAnyThreadCount) {
    auto render = [](const RenderScene& rs, const RenderOptions& o, int threads) {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, size_t(threads));
        return Render(rs, o).beauty.data;
    };
    for (IntegratorKind integrator : {IntegratorKind::AO, IntegratorKind::Path})
        for (bool texture : {false, true}) {
            const Scene s = FlatField(integrator != IntegratorKind::AO);
            const RenderScene rs(s, {});
            RenderOptions o = FlatFieldOptions(integrator, texture, 3);
            o.seed = 5;
            EXPECT_TRUE(render(rs, o, 1) == render(rs, o, 2))
                << int(integrator) << " texture " << texture;
        }
}

}  // namespace
}  // namespace texcache
