// SPDX-License-Identifier: Apache-2.0
// The frame buffers' diffuse light from the one store (TextureSpaceOptions::frameBufferSamples
// Hits): it fills from a budget of the camera hits and lazily where it holds too few samples,
// keeps the same image for any thread count, forgets an edited object's bins, decays only while
// something in the scene moves and never takes a non-finite sample.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

#include <tbb/global_control.h>

#include "frame_buffers_util.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/integrators/bsdf.h"
#include "renderer/render_internal.h"
#include "renderer/texture_space/texture_space.h"
#include "screen_space/brdf_table.h"
#include "screen_space/screen_denoiser.h"
#include "test_util.h"
#include "torus_scene.h"

namespace texcache {
namespace {

using internal::BinnedHit;
using internal::HitRecord;
using internal::PixelOwnLight;
using screen::FrameBuffers;
using test::CachedFrameOptions;
using test::Finite;
using test::TestScene;

/// The test scene with every material diffuse: no glossy ray looks the grid up, so a frame's
/// cache statistics are the store's reads alone.
Scene DiffuseScene() {
    Scene s = TestScene();
    for (Material& m : s.materials) m.type = Material::Type::Diffuse;
    return s;
}

/// Store frames as the preview renders them: temporal accumulation (eq. 6's 0.7), one pixel in
/// four a frame.
RenderOptions StoreOptions() {
    RenderOptions o = CachedFrameOptions(40, 30, TextureFilterKind::None, -1);
    o.texture.frameBufferSamples = TextureSamples::Hits;
    o.texture.frameBufferBudget = 4;
    o.texture.temporalAlpha = 0.7f;
    return o;
}

// A first frame traces every stored pixel's path (the store is empty: all lazy); the next ones
// the budget's quarter and more where the store holds few samples yet
// (TracesMoreWhereTheStoreHoldsFew), so that by the sixteenth frame a third of the reads or more
// find their light from earlier frames (measured 0.46), and at most three quarters. Forgetting the
// ground (an edit) empties its bins, and the next frame traces every ground pixel again.
TEST(FrameBufferStore, FillsFromBudgetedHitsAndLazilyWhereEmpty) {
    Scene s = DiffuseScene();
    RenderScene rs(s, {});
    RenderOptions o = StoreOptions();
    TextureSpaceCache cache(rs, o.texture);
    FrameBuffers fb;
    cache.Refresh(1, 16, false);
    o.seed = 1;
    const RenderStats first = RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
    ASSERT_GT(first.cache.lookups, 100u);
    EXPECT_EQ(first.cache.texelHits, 0u);
    EXPECT_EQ(first.cache.samplesShaded, first.cache.lookups);
    RenderStats later;
    for (uint32_t f = 2; f <= 16; ++f) {
        cache.Refresh(f, 16, false);
        o.seed = f;
        later = RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
    }
    const double hitRate = double(later.cache.texelHits) / double(later.cache.lookups);
    std::printf("store reads served by earlier frames: %.3f\n", hitRate);
    EXPECT_GT(hitRate, 0.33);
    EXPECT_LE(hitRate, 0.76);  // a quarter traced by the budget
    size_t ground = 0;
    for (size_t p = 0; p < fb.NumPixels(); ++p) ground += fb.objectId[p] == 0;
    ASSERT_GT(ground, 100u);
    const size_t blocks = cache.LightStoreIfAny()->Samples().BlocksUsed();
    cache.InvalidateObject(0);
    EXPECT_LT(cache.LightStoreIfAny()->Samples().BlocksUsed(), blocks);
    cache.Refresh(17, 16, false);
    o.seed = 17;
    const RenderStats edited = RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
    EXPECT_GE(edited.cache.samplesShaded, ground);
    for (size_t p = 0; p < fb.NumPixels(); ++p) ASSERT_TRUE(Finite(fb.indirect[p])) << p;
}

/// The share of the stored pixels that trace their paths in each of 48 store frames of `s`,
/// the view and the scene's time fixed, the previous frame's time -0.04.
std::vector<double> TracedShares(const Scene& s, size_t* reads) {
    RenderScene rs(s, {});
    RenderOptions o = StoreOptions();
    TextureSpaceCache cache(rs, o.texture);
    FrameBuffers fb;
    std::vector<double> share;
    for (uint32_t f = 1; f <= 48; ++f) {
        cache.Refresh(f, 16, false);
        o.seed = f;
        const RenderStats st = RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        EXPECT_GT(st.cache.lookups, 100u);
        *reads = st.cache.lookups;
        share.push_back(double(st.cache.samplesShaded) / double(st.cache.lookups));
        for (size_t p = 0; p < fb.NumPixels(); ++p)
            EXPECT_TRUE(Finite(fb.indirect[p])) << "frame " << f << " pixel " << p;
    }
    std::printf(
        "traced share of the stored pixels, frames 1, 2, 4, 8, 16, 32, 48: %.3f %.3f %.3f "
        "%.3f %.3f %.3f %.3f\n",
        share[0], share[1], share[3], share[7], share[15], share[31], share[47]);
    return share;
}
double MeanOf(const std::vector<double>& v, size_t a, size_t b) {
    double m = 0.0;
    for (size_t i = a; i < b; ++i) m += v[i];
    return m / double(b - a);
}

// Paths go first where the store holds few samples: a view's first frame traces every stored
// pixel (an empty store), the next frames a share that falls as the bins fill. In a scene where
// nothing moves the store is a running mean (TextureSpaceCache::FrameStoreKeep), its bins keep
// filling, and the share falls to the budget's (measured 0.243 at frame 48; 0.25 within the
// ordered dither's spread). A pixel still traces at least its budget's share, so the store keeps
// being refreshed.
TEST(FrameBufferStore, TracesMoreWhereTheStoreHoldsFew) {
    size_t reads = 0;
    const std::vector<double> share = TracedShares(DiffuseScene(), &reads);
    EXPECT_EQ(share[0], 1.0);
    // The second frame's bins hold one frame's paths: fewer than the target, so far more than
    // the budget's quarter traces again.
    EXPECT_GT(share[1], 0.5);
    // Falling as the bins fill: each stretch of 8 frames traces less than the one before it
    // (a 2 % margin for the dither's frame-to-frame spread).
    EXPECT_LT(MeanOf(share, 8, 16), MeanOf(share, 1, 8));
    EXPECT_LT(MeanOf(share, 16, 24), MeanOf(share, 8, 16) + 0.02);
    // Never below the budget's share (one pixel in 4, to within the ordered dither over a
    // 40x30 image: 1 / sqrt(reads) of the reads), and at it once the bins hold the target.
    const double budgetShare = 1.0 / double(StoreOptions().texture.frameBufferBudget);
    const double floorShare = budgetShare - 1.0 / std::sqrt(double(reads));
    for (size_t f = 0; f < share.size(); ++f) EXPECT_GE(share[f], floorShare) << "frame " << f + 1;
    EXPECT_LT(MeanOf(share, 40, 48), budgetShare + 0.03);
}

// While an object moves the store decays by eq. 6 (the shadows and bounce light of what moved
// fade from the bins), so the bins settle where the paths they gain a frame balance what the
// decay forgets: above the budget's share (measured 0.48 at frames 32 and 48),
// where the same view of the same scene at rest falls to the budget's (the test above). The
// ground object gets a second pose (a hundredth of a unit higher at time 1): it moves between
// every frame's previous time and its own.
TEST(FrameBufferStore, DecaysWhileSomethingMoves) {
    Scene s = DiffuseScene();
    ASSERT_FALSE(s.MovesBetween(-0.04f, 0.0f));
    std::vector<Keyframe>& keys = s.objects[0].transform.keys;
    ASSERT_LE(keys.size(), 1u);
    Keyframe before = keys.empty() ? Keyframe{} : keys[0], after = before;
    before.time = -1.0f, after.time = 1.0f;
    after.translation.y += 0.01f;
    keys = {before, after};
    ASSERT_TRUE(s.MovesBetween(-0.04f, 0.0f));
    size_t reads = 0;
    const std::vector<double> share = TracedShares(s, &reads);
    EXPECT_EQ(share[0], 1.0);
    const double budgetShare = 1.0 / double(StoreOptions().texture.frameBufferBudget);
    EXPECT_GT(MeanOf(share, 40, 48), budgetShare + 0.1);
    EXPECT_LT(MeanOf(share, 40, 48), 0.6);
    EXPECT_NEAR(MeanOf(share, 40, 48), MeanOf(share, 32, 40), 0.03);
}

// A running mean keeps every bin it was given: once the store holds far more than a view's bins
// (a long flight through a large scene), frames decay it by eq. 6 even where nothing moves, so
// that the bins the camera no longer sees fade and the table can release them. Bins of faces no
// camera hit reaches stand for those: 64 of them keep their sums over a still scene's frame,
// 8192 of them (more than twice the first table of this 40x30 view) are scaled down.
TEST(FrameBufferStore, ACrowdedStoreDecaysWhereNothingMoves) {
    Scene s = DiffuseScene();
    RenderScene rs(s, {});
    for (const int faraway : {64, 8192}) {
        SCOPED_TRACE(faraway);
        RenderOptions o = StoreOptions();
        TextureSpaceCache cache(rs, o.texture);
        FrameBuffers fb;
        // A table with room for them all, so that it does not grow (nor release anything).
        cache.LightStore(size_t(1) << 16);
        cache.Refresh(1, 16, false);
        RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);  // the view's bins
        LightHitStore& store = *cache.LightStoreIfAny();
        const size_t viewBlocks = store.Samples().BlocksUsed();
        ASSERT_GT(viewBlocks, 0u);
        RadianceBin::Value one;
        const float unitLight[3] = {1.0f, 1.0f, 1.0f};
        ASSERT_TRUE(RadianceBin::FromRadiance(unitLight, &one));
        one.count *= cache.HitUnit();
        auto key = [](int i) { return TexelKey{TexelKey::kMaxFaces - 1u - uint32_t(i), 0, 0, 0}; };
        for (int i = 0; i < faraway; ++i) ASSERT_TRUE(store.Samples().Add(key(i), one));
        store.AddsDone();
        cache.Refresh(2, 16, false);
        o.seed = 2;
        RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        const LightHitStore& after = *cache.LightStoreIfAny();
        const RadianceBin::Value v = after.Samples().Find(key(0));
        std::printf("%d faraway blocks (the view's %zu): a faraway bin keeps %.4f of its count\n",
                    faraway, viewBlocks, double(v.count) / double(one.count));
        if (faraway == 64)
            EXPECT_EQ(v.count, one.count);
        else
            EXPECT_LT(v.count, one.count);
        EXPECT_GT(v.count, 0u);
        for (size_t p = 0; p < fb.NumPixels(); ++p) ASSERT_TRUE(Finite(fb.indirect[p])) << p;
    }
}

/// A floor and a wall at a right angle, both facing the camera, under a sky: the paths from each
/// mostly reach the other where the camera sees it, so the store holds their light.
Scene CornerScene() {
    Scene s = test::OneObjectScene(test::PlaneCage(2.0f), glm::vec3(0.6f));
    s.objects[0].subdivide = false;
    Object wall = s.objects[0];
    Keyframe k;
    k.translation = glm::vec3(0.0f, 2.0f, -2.0f);
    k.rotation = glm::angleAxis(glm::radians(90.0f), glm::vec3(1.0f, 0.0f, 0.0f));  // normal +Z
    wall.transform.keys = {k};
    s.objects.push_back(wall);
    EnvironmentLight sky;
    sky.constant = glm::vec3(1.0f);
    s.environments.push_back(sky);
    // Far enough back to see all of both.
    s.camera.pose.keys = {test::LookAt({0.0f, 3.0f, 10.0f}, {0.0f, 1.0f, -1.0f})};
    s.camera.fovYDegrees = 45.0f;
    return s;
}

// Frames from the store never allocate the grid (a glossy material's ray reads the store too),
// and where the store holds the surfaces the paths reach, those paths end there (the store holds
// all of the diffuse light: cacheDiffuseLayer). A path traces its first ray and, unless that ray
// ends in the store, more: by the sixth frame the corner's traced paths take at most half the
// rays beyond their first that the first frame's take, which find an empty store (measured 0.23
// a path and 0). Frames from the grid allocate it.
TEST(FrameBufferStore, NeverAllocatesTheGridAndPathsEndInTheStore) {
    for (const bool glossy : {false, true}) {
        SCOPED_TRACE(glossy ? "glossy test scene" : "diffuse corner");
        const Scene s = glossy ? TestScene() : CornerScene();
        RenderScene rs(s, {});
        RenderOptions o = StoreOptions();
        o.texture.cacheDiffuseLayer = true;
        TextureSpaceCache cache(rs, o.texture);
        FrameBuffers fb;
        cache.Refresh(1, 16, false);
        o.seed = 1;
        const RenderStats first = RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        RenderStats later;
        for (uint32_t f = 2; f <= 6; ++f) {
            cache.Refresh(f, 16, false);
            o.seed = f;
            later = RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        }
        EXPECT_FALSE(cache.GridPrepared());
        ASSERT_GT(first.cache.samplesShaded, 100u);
        ASSERT_GT(later.cache.samplesShaded, 50u);
        for (size_t p = 0; p < fb.NumPixels(); ++p) {
            ASSERT_TRUE(Finite(fb.indirect[p])) << p;
            if (!fb.glossy.empty()) {
                ASSERT_TRUE(Finite(fb.glossy[p]) || std::isnan(fb.glossy[p].x)) << p;
            }
        }
        if (!glossy) {
            // All diffuse: the bounce rays are the paths' alone.
            const double a = double(first.bounceRays) / double(first.cache.samplesShaded);
            const double b = double(later.bounceRays) / double(later.cache.samplesShaded);
            std::printf("bounce rays per traced pixel: first frame %.3f, sixth %.3f\n", a, b);
            EXPECT_LT(b - 1.0, 0.5 * (a - 1.0));
        }

        RenderOptions g = o;
        g.texture.frameBufferSamples = TextureSamples::Grid;
        TextureSpaceCache grid(rs, g.texture);
        grid.Refresh(1, 16, false);
        RenderFrameBuffers(rs, g, -0.04f, &fb, &grid);
        EXPECT_TRUE(grid.GridPrepared());
    }
}

// The store's sums are integers added in any order, and a frame reads it only between its
// phases; the pixels' own samples are summed in frame order: ten frames, eight of them still,
// give the same buffers on one thread and on two (within 1e-6, float rounding of the same sums).
TEST(FrameBufferStore, SameImageForOneAndTwoThreads) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    std::vector<glm::vec3> indirect[2];
    for (int t = 0; t < 2; ++t) {
        tbb::global_control threads(tbb::global_control::max_allowed_parallelism, size_t(t + 1));
        RenderOptions o = StoreOptions();
        TextureSpaceCache cache(rs, o.texture);
        FrameBuffers fb;
        // Eight still frames, in which every pixel traces its path each frame, so the blend
        // with its own samples (BlendWithOwnLight) runs too.
        for (uint32_t f = 1; f <= 10; ++f) {
            cache.Refresh(f, 16, f > 2);
            o.seed = f;
            RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        }
        indirect[t] = fb.indirect;
    }
    ASSERT_EQ(indirect[0].size(), indirect[1].size());
    for (size_t p = 0; p < indirect[0].size(); ++p)
        for (int k = 0; k < 3; ++k)
            ASSERT_NEAR(indirect[0][p][k], indirect[1][p][k], 1e-6f * (1.0f + indirect[0][p][k]))
                << p;
}

// A light so bright that the paths' sums overflow to infinity: no such sample enters the store
// (RadianceBin::FromRadiance drops it), so its bins stay far from saturation and every pixel's
// indirect light stays finite.
TEST(FrameBufferStore, NonFiniteSamplesNeverEnterTheStore) {
    Scene s = DiffuseScene();
    for (QuadLight& q : s.quadLights) q.radiance = glm::vec3(3.0e38f);
    RenderScene rs(s, {});
    RenderOptions o = StoreOptions();
    TextureSpaceCache cache(rs, o.texture);
    FrameBuffers fb;
    // Still from the second frame on: nor does it enter a pixel's own samples.
    for (uint32_t f = 1; f <= 6; ++f) {
        cache.Refresh(f, 16, f > 1);
        o.seed = f;
        RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        for (size_t p = 0; p < fb.NumPixels(); ++p) ASSERT_TRUE(Finite(fb.indirect[p])) << p;
    }
    const PixelOwnLight* own = cache.StillOwnLight(o.width, o.height);
    ASSERT_NE(own, nullptr);
    for (size_t p = 0; p < fb.NumPixels(); ++p) {
        ASSERT_TRUE(Finite(own[p].mean) && std::isfinite(own[p].m2)) << p;
    }
    // No bin saturated: an infinite sample clamped instead of dropped would fill its sums.
    std::vector<uint64_t> records;
    cache.LightStoreIfAny()->Samples().ExportBlocks(&records);
    for (size_t i = 0; i < records.size(); ++i) {
        if (i % RadianceBins::kRecordWords != 0) {
            ASSERT_LT(records[i], UINT64_MAX / 2) << i;
        }
    }
}

// A moving view reads one bin a pixel (StoreLightAt with a jitter) instead of the 2x2 around its
// point: over uniform jitters a bin comes out with its bilinear weight, so that the reads
// average to the bilinear reconstruction. Every face of the torus (closed: every edge has a
// neighbour) holding a different light in each bin (and each face a different one), 8 samples
// each (equal counts: the bilinear read's count weighting is then its weights alone), read at
// the level where its first face is 8x8: at points inside that face and within half a bin of its
// edges (where both reads take the neighbour's bins through the Ptex adjacency; a read held
// inside the face is up to 89 % off there, with these faces' different lights) the mean of the
// reads over a 256x256 grid of jitters is within 0.5 % of the bilinear read (a weight is off by
// at most 1/256, times the step between neighbouring bins' lights; measured 0.37 %). A bin with
// fewer samples than asked for is read bilinearly, bit for bit; so is every bin of an object
// whose material sets a filter (its light is the filter's).
TEST(FrameBufferStore, StochasticReadsAverageToTheBilinearReconstruction) {
    const Scene s = DiffuseScene();
    RenderScene rs(s, {});
    TextureSpaceCache cache(rs, StoreOptions().texture);
    LightHitStore& store = cache.LightStore(4096);
    const int mesh = cache.MeshOf(1), face = 0;
    const MeshGrids& g = cache.Grids(mesh);
    int level = 0;
    while (g.Res(face, level) > 8) ++level;
    ASSERT_EQ(g.Res(face, level), 8) << "the torus's first face is coarser than 8x8";
    const uint64_t samples = 8 * cache.HitUnit();
    auto lightOf = [](int f, int i, int j) {
        return glm::vec3(0.2f + 0.1f * float(i) + 0.5f * float(f),
                         0.3f + 0.05f * float(j) + 0.25f * float(f % 3),
                         1.0f + 0.3f * float(i * j));
    };
    // Every face's bins at the level (clamped to the face's chain), into `into`.
    auto fill = [&](const TextureSpaceCache& c, LightHitStore& into) {
        const MeshGrids& mg = c.Grids(mesh);
        for (int f = 0; f < mg.NumFaces(); ++f) {
            const int fl = mg.ClampMip(f, level), res = mg.Res(f, fl);
            for (int j = 0; j < res; ++j)
                for (int i = 0; i < res; ++i) {
                    const glm::vec3 L = lightOf(f, i, j);
                    RadianceBin::Value v;
                    ASSERT_TRUE(RadianceBin::FromRadiance(&L.x, &v));
                    for (uint64_t& w : v.sum) w *= samples;
                    v.count *= samples;
                    ASSERT_TRUE(into.Samples().Add(
                        {mg.FaceOffset() + uint32_t(f), uint8_t(fl), uint16_t(i), uint16_t(j)}, v));
                }
        }
        into.AddsDone();
    };
    fill(cache, store);
    constexpr int kN = 256;
    double worst = 0.0;
    for (const glm::vec2 at :
         {glm::vec2(0.31f, 0.55f), glm::vec2(0.5f, 0.19f), glm::vec2(0.7f, 0.77f),
          glm::vec2(0.1f, 0.9f), glm::vec2(0.02f, 0.4f), glm::vec2(0.6f, 0.985f),
          glm::vec2(0.97f, 0.3f), glm::vec2(0.45f, 0.01f)}) {
        const HitRecord h{HitRecord::Quantize(at.x), HitRecord::Quantize(at.y), mesh,
                          uint32_t(face) << 4 | uint32_t(level)};
        const glm::vec3 bilinear = internal::StoreLightAt(cache, store, h);
        glm::dvec3 sum(0.0);
        for (int b = 0; b < kN; ++b)
            for (int a = 0; a < kN; ++a) {
                const glm::vec2 jitter((float(a) + 0.5f) / kN - 0.5f,
                                       (float(b) + 0.5f) / kN - 0.5f);
                sum += glm::dvec3(internal::StoreLightAt(cache, store, h, jitter, double(samples)));
            }
        const glm::dvec3 mean = sum / double(kN * kN);
        for (int k = 0; k < 3; ++k) {
            worst = std::max(worst, std::abs(mean[k] / double(bilinear[k]) - 1.0));
            EXPECT_NEAR(mean[k], bilinear[k], 0.005 * bilinear[k])
                << at.x << " " << at.y << " " << k;
        }
        // Too few samples in the bin: the bilinear read, and its count.
        glm::vec3 light;
        const glm::vec2 jitter(at.x < 0.5f ? 0.2f : -0.2f, at.y < 0.5f ? 0.3f : -0.3f);  // inside
        EXPECT_EQ(internal::StoreLightAt(cache, store, h, jitter, double(samples + 1)), bilinear);
        EXPECT_EQ(internal::StoreCountAt(cache, store, h, jitter, double(samples + 1), &light),
                  internal::StoreCountAt(cache, store, h));
        EXPECT_EQ(light, bilinear);
        // Enough: the one bin's.
        EXPECT_EQ(internal::StoreCountAt(cache, store, h, jitter, double(samples), &light),
                  double(samples));
        EXPECT_EQ(light, internal::StoreLightAt(cache, store, h, jitter, double(samples)));
    }
    std::printf("stochastic reads: mean over jitters / bilinear, worst channel off by %.5f\n",
                worst);

    // The torus's material with a Gaussian filter: every read is the filter's.
    Scene filtered = DiffuseScene();
    filtered.materials[1].cacheFilter = "gaussian";
    RenderScene frs(filtered, {});
    TextureSpaceCache fcache(frs, StoreOptions().texture);
    ASSERT_EQ(fcache.FilterOf(1), TextureFilterKind::Gaussian);
    LightHitStore& fstore = fcache.LightStore(4096);
    fill(fcache, fstore);
    for (const glm::vec2 at : {glm::vec2(0.31f, 0.55f), glm::vec2(0.02f, 0.4f)}) {
        const HitRecord h{HitRecord::Quantize(at.x), HitRecord::Quantize(at.y), mesh,
                          uint32_t(face) << 4 | uint32_t(level)};
        const glm::vec3 reconstruction = internal::StoreLightAt(fcache, fstore, h);
        EXPECT_GT(Luminance(reconstruction), 0.0f);
        for (const glm::vec2 jitter : {glm::vec2(-0.4f, 0.3f), glm::vec2(0.45f, -0.2f)})
            EXPECT_EQ(internal::StoreLightAt(fcache, fstore, h, jitter, double(samples)),
                      reconstruction);
    }
}

/// Relative MSE of the indirect light `v` against `ref` over the pixels where `mask` is set:
/// (luminance difference)^2 / (reference^2 + 0.01), averaged.
double IndirectRelMse(const std::vector<glm::vec3>& v, const std::vector<glm::vec3>& ref,
                      const std::vector<char>& mask) {
    double e = 0.0;
    size_t n = 0;
    for (size_t p = 0; p < ref.size(); ++p) {
        if (!mask[p]) continue;
        const double r = Luminance(ref[p]), d = Luminance(v[p]) - r;
        e += d * d / (r * r + 0.01), ++n;
    }
    return n ? e / double(n) : 0.0;
}

// A still view converges past the bins' bias. With the diffuse lobe's light all in the store
// (direct light included), the occluder's shadow on the ground has an edge that the store's bins
// average over a patch, so they stay biased there however many frames they hold; each pixel's
// own paths are unbiased, and the blend of the two (BlendWithOwnLight) moves to them as they pile
// up (every pixel traces a path each still frame). Against a 1024-spp per-pixel reference (its
// composed image: the diffuse materials' light), after 64 still frames the image's error is
// under 0.3 of that of the bins read alone (measured 0.0016 against 0.0102) and below its error
// after 16 frames (0.0047).
TEST(FrameBufferStore, StillViewConvergesPastTheBinsBias) {
    const Scene s = DiffuseScene();
    RenderScene rs(s, {});
    RenderOptions o = StoreOptions();
    o.texture.cacheDiffuseLayer = true;
    o.width = 48, o.height = 36;
    RenderOptions r = test::FrameOptions(o.width, o.height, 99);
    r.spp = 1024;
    FrameBuffers ref;
    RenderFrameBuffers(rs, r, -0.04f, &ref, nullptr);
    ref.indirect = ref.Compose();  // the store's `indirect` holds all of it

    TextureSpaceCache cache(rs, o.texture);
    FrameBuffers fb;
    const size_t n = size_t(o.width) * size_t(o.height);
    std::vector<char> mask(n);
    double after16 = 0.0;
    for (uint32_t f = 1; f <= 64; ++f) {
        cache.Refresh(f, 16, f > 1);
        o.seed = f;
        RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        if (f == 16) {
            for (size_t p = 0; p < n; ++p) mask[p] = cache.HitRecords(n)[p].mesh >= 0;
            after16 = IndirectRelMse(fb.indirect, ref.indirect, mask);
        }
    }
    // The bins alone: what the pixels read before they blend in their own samples.
    std::vector<glm::vec3> bins(n, glm::vec3(0.0f));
    const HitRecord* records = cache.HitRecords(n);
    const BinnedHit* binned = cache.BinnedHits(n);
    for (size_t p = 0; p < n; ++p)
        if (mask[p])
            bins[p] = binned[p].albedo *
                      internal::StoreLightAt(cache, *cache.LightStoreIfAny(), records[p]);
    const double last = IndirectRelMse(fb.indirect, ref.indirect, mask);
    const double binsOnly = IndirectRelMse(bins, ref.indirect, mask);
    std::printf("still view relMSE: 16 frames %.5f, 64 frames %.5f, the bins alone %.5f\n", after16,
                last, binsOnly);
    EXPECT_LT(last, 0.3 * binsOnly);
    EXPECT_LT(last, after16);
}

// Where the cache lights a diffuse base, the specular lobe takes fewer light samples
// (specularLightSamples); a metal (no diffuse lobe) gives the cache nothing and keeps per hit's
// count, so its `shading` is per hit's bit for bit (same seed, same samples): on the torus made
// a metal, every pixel of it equal between a store frame and a per-hit frame. With 8 samples
// instead of 32 they differed on most of its pixels (brushed.json: store denoised relMSE 0.208
// against per hit's 0.128).
TEST(FrameBufferStore, MetalKeepsPerHitsLightSamples) {
    Scene s = TestScene();
    Material& metal = s.materials[1];  // the torus's
    metal.albedo.value = glm::vec3(0.0f);
    metal.specular.value = glm::vec3(0.9f, 0.8f, 0.6f);
    RenderScene rs(s, {});
    RenderOptions o = StoreOptions();
    o.texture.cacheDiffuseLayer = true;
    TextureSpaceCache cache(rs, o.texture);
    FrameBuffers store, perHit;
    RenderFrameBuffers(rs, o, -0.04f, &store, &cache);
    RenderOptions h = o;
    h.texture.enabled = false;
    RenderFrameBuffers(rs, h, -0.04f, &perHit, nullptr);
    int torus = 0;
    for (size_t p = 0; p < store.NumPixels(); ++p) {
        if (store.objectId[p] != 1) continue;
        ASSERT_EQ(store.shading[p], perHit.shading[p]) << p;
        ++torus;
    }
    EXPECT_GT(torus, 50);
}

// A pixel's own samples belong to its view: a camera move (Refresh not still) releases them, and
// a resize or an edit (InvalidateObject) starts them again from none.
TEST(FrameBufferStore, OwnSamplesResetOnMoveResizeAndEdit) {
    Scene s = DiffuseScene();
    RenderScene rs(s, {});
    RenderOptions o = StoreOptions();
    TextureSpaceCache cache(rs, o.texture);
    FrameBuffers fb;
    uint32_t f = 0;
    auto frames = [&](int count, bool still) {
        for (int i = 0; i < count; ++i) {
            cache.Refresh(++f, 16, still);
            o.seed = f;
            RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        }
    };
    auto samples = [&] {
        const PixelOwnLight* own = cache.StillOwnLight(o.width, o.height);
        size_t total = 0;
        for (size_t p = 0; own && p < size_t(o.width) * size_t(o.height); ++p) total += own[p].n;
        return total;
    };
    frames(1, false);
    EXPECT_EQ(cache.StillOwnLight(o.width, o.height), nullptr);  // moving: none kept
    frames(8, true);
    const size_t still = samples();
    EXPECT_GT(still, size_t(o.width * o.height) * 2);  // eight a stored pixel: every frame
    frames(1, false);
    EXPECT_EQ(cache.StillOwnLight(o.width, o.height), nullptr);
    frames(1, true);
    EXPECT_LE(samples(), still / 4);  // one frame's budget (and lazy pixels) since the move
    frames(4, true);
    EXPECT_GT(samples(), 0u);
    cache.InvalidateObject(0);
    EXPECT_EQ(samples(), 0u);
    frames(4, true);
    ASSERT_GT(samples(), 0u);
    o.width += 8;
    EXPECT_EQ(samples(), 0u);
}

// A lone bright path is bounded before it enters the store (BoundBrightHits): on a flat field of
// traced hits of light 1, a hit of 1000 keeps kStoreBoundRatio x the median around it and its
// 80 neighbours in the 9x9 window share the rest, so the frame's light is kept (to 1e-5
// relative). A hit of 10 (under the ratio) is left alone, and so is a bright hit with no
// reference (no neighbours of its group, no prior) or with a prior that makes it ordinary. Hits
// that are not there (negative), NaN or infinite are left as they are and never count as
// neighbours, so a window of them around a hit leaves it unbounded.
TEST(FrameBufferStore, BrightHitIsBoundedAndItsExcessSpread) {
    const int W = 24, H = 16;
    const size_t n = size_t(W) * H;
    std::vector<glm::vec3> light(n, glm::vec3(1.0f));
    std::vector<float> prior(n, 0.0f);
    std::vector<int32_t> group(n, 0);
    auto at = [&](int x, int y) { return size_t(y) * W + size_t(x); };
    light[at(5, 5)] = glm::vec3(1000.0f);    // a firefly
    light[at(15, 5)] = glm::vec3(10.0f);     // bright, but under the ratio
    light[at(20, 12)] = glm::vec3(1000.0f);  // its own group: no neighbours to compare with
    group[at(20, 12)] = 1;
    light[at(12, 12)] = glm::vec3(1000.0f);  // earlier frames saw this much there
    prior[at(12, 12)] = 100.0f;
    // A hit whose window (radius 4) holds only non-finite and missing ones.
    for (int y = 0; y < 5; ++y)
        for (int x = 0; x < 5; ++x)
            light[at(x, H - 1 - y)] = glm::vec3((x + y) % 3 == 0   ? NAN
                                                : (x + y) % 3 == 1 ? INFINITY
                                                                   : -1.0f);
    light[at(0, H - 1)] = glm::vec3(1000.0f);
    auto total = [&](const std::vector<glm::vec3>& v) {
        double sum = 0.0;
        for (const glm::vec3& c : v)
            if (Finite(c) && c.x >= 0.0f) sum += double(Luminance(c));
        return sum;
    };
    const std::vector<glm::vec3> in = light;
    EXPECT_EQ(BoundBrightHits(W, H, light.data(), group.data(), prior.data(), kStoreBoundRatio),
              1u);
    EXPECT_NEAR(total(light), total(in), 1e-5 * total(in));
    EXPECT_NEAR(Luminance(light[at(5, 5)]), kStoreBoundRatio, 1e-3f);
    EXPECT_NEAR(Luminance(light[at(6, 6)]), 1.0f + (1000.0f - kStoreBoundRatio) / 80.0f, 1e-3f);
    EXPECT_NEAR(Luminance(light[at(15, 5)]), 10.0f, 1e-5f);
    EXPECT_EQ(light[at(20, 12)], in[at(20, 12)]);
    EXPECT_EQ(light[at(12, 12)], in[at(12, 12)]);
    EXPECT_EQ(light[at(0, H - 1)], in[at(0, H - 1)]);
    for (size_t p = 0; p < n; ++p) {
        if (!Finite(in[p]) || in[p].x < 0.0f) {
            ASSERT_FALSE(Finite(light[p]) && light[p].x >= 0.0f) << p;  // left as it was
        } else {
            ASSERT_TRUE(Finite(light[p])) << p;
        }
    }
    // No prior at all (the first frame): the hit with a prior is judged by its neighbours alone.
    light = in;
    EXPECT_EQ(BoundBrightHits(W, H, light.data(), group.data(), nullptr, kStoreBoundRatio), 2u);
    EXPECT_NEAR(total(light), total(in), 1e-5 * total(in));
}

// The interactive path on the cages with hard features (a boundary and a hole, n-gons, creases,
// extraordinary vertices: test::kHardCages), each a glossy object on a ground plane under a white
// sky: store frames while the camera orbits (a running mean: nothing moves; one pixel in four
// traces), then a still view (every pixel traces, its own samples blend in), each frame through the
// Reliable stage. Every buffer the store writes and every denoised image is finite and
// non-negative; after 24 still frames the composed image is near a 256-spp per-hit frame of the
// same view (relMSE measured 0.0065-0.0164 on the four cages; bound 0.03), and the denoised image's
// mean luminance is within 5% of that reference's (measured -0.4% to +0.4%). The store's light
// scaled by 0.8 fails both (relMSE 0.042-0.050, mean -19% to -20%).
TEST(FrameBufferStore, HardCagesGiveFiniteSensibleFrames) {
    const auto brdf = std::make_shared<const screen::BrdfPreintegration>(64);
    for (const char* name : test::kHardCages) {
        SCOPED_TRACE(name);
        ControlCage cage = test::LoadMesh(name);
        glm::vec3 lo(INFINITY), hi(-INFINITY);
        for (const auto& q : cage.positions) {
            lo = glm::min(lo, glm::vec3(q[0], q[1], q[2]));
            hi = glm::max(hi, glm::vec3(q[0], q[1], q[2]));
        }
        const glm::vec3 centre = 0.5f * (lo + hi);
        const float radius = 0.5f * glm::length(hi - lo);
        Scene s = test::OneObjectScene(std::move(cage), glm::vec3(0.6f, 0.5f, 0.4f));
        s.materials[0].type = Material::Type::GGX;
        s.materials[0].roughness.value = 0.3f;
        s.materials[0].specular.value = glm::vec3(0.04f);
        s.meshes.push_back(test::PlaneCage(2.0f * radius));
        Material ground;
        ground.albedo.value = glm::vec3(0.5f);
        s.materials.push_back(ground);
        Object floor;
        floor.mesh = 1, floor.material = 1;
        Keyframe at;
        at.translation = glm::vec3(centre.x, lo.y, centre.z);
        floor.transform.keys = {at};
        s.objects.push_back(floor);
        EnvironmentLight sky;
        sky.constant = glm::vec3(1.0f);
        s.environments.push_back(sky);
        auto view = [&](float degrees) {
            const float a = glm::radians(30.0f + degrees);
            const glm::vec3 eye =
                centre + 2.2f * radius * glm::vec3(std::sin(a), 0.6f, std::cos(a));
            s.camera.pose.keys = {test::LookAt(eye, centre)};
        };
        s.camera.fovYDegrees = 40.0f;
        view(0.0f);
        RenderScene rs(s, {});  // keeps a reference: view() moves its camera

        RenderOptions o = StoreOptions();
        o.width = 48, o.height = 36;
        o.texture.cacheDiffuseLayer = true;  // a soft sky: all of the diffuse lobe's light
        TextureSpaceCache cache(rs, o.texture);
        screen::ScreenSpaceDenoiser denoiser({}, brdf);
        FrameBuffers fb;
        std::vector<glm::vec3> image;
        constexpr uint32_t kMoving = 8, kFrames = kMoving + 24;
        for (uint32_t f = 1; f <= kFrames; ++f) {
            const bool still = f > kMoving + 1;
            if (f <= kMoving + 1) view(2.0f * float(f));
            cache.Refresh(f, 16, still);
            o.seed = f;
            RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
            for (size_t p = 0; p < fb.NumPixels(); ++p) {
                ASSERT_TRUE(Finite(fb.indirect[p]) && fb.indirect[p].x >= 0.0f)
                    << "frame " << f << " pixel " << p;
                ASSERT_TRUE(Finite(fb.shading[p]) && Finite(fb.glossy[p])) << f << " " << p;
            }
            denoiser.SetStillView(still);
            denoiser.Denoise(fb, screen::Method::Reliable, screen::Demodulation::On, &image);
            for (size_t p = 0; p < image.size(); ++p)
                ASSERT_TRUE(Finite(image[p]) && image[p].x >= 0.0f && image[p].y >= 0.0f &&
                            image[p].z >= 0.0f)
                    << "frame " << f << " pixel " << p;
        }
        RenderOptions r = test::FrameOptions(o.width, o.height, 99);
        r.spp = 256;
        FrameBuffers ref;
        RenderFrameBuffers(rs, r, -0.04f, &ref, nullptr);
        const std::vector<glm::vec3> refImage = ref.Compose(), composed = fb.Compose();
        std::vector<char> mask(fb.NumPixels());
        size_t object = 0;
        double meanRef = 0.0, meanDenoised = 0.0;
        for (size_t p = 0; p < mask.size(); ++p) {
            mask[p] = fb.objectId[p] >= 0;
            object += fb.objectId[p] == 0;
            if (!mask[p]) continue;
            meanRef += Luminance(refImage[p]), meanDenoised += Luminance(image[p]);
        }
        ASSERT_GT(object, 100u);  // the cage fills a good part of the view
        const double err = IndirectRelMse(composed, refImage, mask);
        std::printf("%s: relMSE %.5f, denoised mean / reference %.3f\n", name, err,
                    meanDenoised / meanRef);
        EXPECT_LT(err, 0.03);
        EXPECT_NEAR(meanDenoised / meanRef, 1.0, 0.05);
    }
}

}  // namespace
}  // namespace texcache
