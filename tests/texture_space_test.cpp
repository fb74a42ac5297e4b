// SPDX-License-Identifier: Apache-2.0
// Texture-space shading in the renderer: cached AO with a 1x1 filter converges to the per-hit
// image, the normal filter lowers error at equal samples, results do not depend on the thread
// count, and the caches stay within their budgets.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>

#include "renderer/image/metrics.h"
#include "renderer/integrators/path_tracer.h"
#include "renderer/render.h"
#include "renderer/scene/scene_loader.h"
#include "test_util.h"
#include "testing/cages.h"
#include "torus_scene.h"

namespace texcache {
namespace {

using test::AllFiniteIn;
using test::AoOptions;
using test::CachedAo;
using test::MakePlaneGlossy;
using test::RenderOnThreads;
using test::TorusAo;
using test::TorusOnPlane;

// Per-hit AO at 64 camera samples x 16 AO rays per pixel is the reference. Texture-space AO
// with the 1x1 filter and the same camera samples (same seed: the same camera rays, so coverage
// noise at silhouettes cancels) and 64 rays per cached sample converges to it up to the
// quantization of shading to texel centres: relMSE below 0.006 (measured 0.0029).
// The cache's grids hold the scene's Ptex topology rather than building their own (on a
// 1,000,000-quad cage a copy and the OpenSubdiv refiner behind it would take ~330 MB more in
// texture space). The torus is closed (front grids only); the plane is open (front and back
// grids share one topology too).
TEST(TextureSpace, CacheSharesTheScenesTopology) {
    const RenderScene& rs = TorusAo();
    const long torusBefore = rs.SharedTopology(0).use_count() - 1,
               planeBefore = rs.SharedTopology(1).use_count() - 1;
    const TextureSpaceCache cache(rs, CachedAo(1, 1, TextureFilterKind::Normal).texture);
    EXPECT_EQ(rs.SharedTopology(0).use_count() - 1, torusBefore + 1);
    EXPECT_EQ(rs.SharedTopology(1).use_count() - 1, planeBefore + 2);
    EXPECT_EQ(cache.MeshOf(0, true), cache.MeshOf(0, false));
    EXPECT_NE(cache.MeshOf(1, true), cache.MeshOf(1, false));
}

TEST(TextureSpace, OneByOneFilterConvergesToPerHitShading) {
    const RenderScene& rs = TorusAo();
    const Image ref = Render(rs, AoOptions(64, 16)).beauty;
    RenderOptions o = CachedAo(64, 64, TextureFilterKind::None);
    const RenderResult cached = Render(rs, o);
    const double e = RelMSE(cached.beauty, ref);
    RecordProperty("relMSE", std::to_string(e));
    EXPECT_LT(e, 0.006);  // measured 0.0029
    // More rays per cached sample: closer still (convergence, not just a bound).
    o.aoSamples = 8;
    EXPECT_LT(e, RelMSE(Render(rs, o).beauty, ref));
    EXPECT_GT(cached.stats.cache.texelHits, 0u);
    EXPECT_GT(cached.stats.cache.samplesShaded, 0u);
}

// A closed cage wound inward (clockwise seen from outside) has limit normals pointing into the
// solid. Per-hit shading faces the ray; a cache that shaded each texel on the side its normal
// points to would shade inside the torus (AO near 0). The cache's samples face outward, and
// texture-space AO is as close to per-hit AO as on the same torus wound outward: the 1x1
// filter, 8 camera samples, 32 rays per cached sample against 8 x 16 rays per pixel with the
// same camera rays; bound 1.5x the outward torus's error + 0.001 (measured 0.0081 inward, 0.0080
// outward).
TEST(TextureSpace, InwardWoundClosedCagesAreShadedOutside) {
    double error[2];
    for (const bool inward : {false, true}) {
        SCOPED_TRACE(inward ? "inward" : "outward");
        Scene s = TorusOnPlane();
        if (inward) test::ReverseFaces(&s.meshes[0]);
        RenderSceneOptions ro;
        ro.needLights = false;
        const RenderScene rs(s, ro);
        const Image ref = Render(rs, AoOptions(8, 16)).beauty;
        const RenderOptions o = CachedAo(8, 32, TextureFilterKind::None);
        const TextureSpaceCache cache(rs, o.texture);
        EXPECT_EQ(cache.SamplesAgainstNormal(cache.MeshOf(0)), inward);
        EXPECT_FALSE(cache.SamplesAgainstNormal(cache.MeshOf(1, false)));  // the open plane
        EXPECT_TRUE(cache.SamplesAgainstNormal(cache.MeshOf(1, true)));
        error[inward] = RelMSE(Render(rs, o).beauty, ref);
        RecordProperty(inward ? "relMSEInward" : "relMSEOutward", std::to_string(error[inward]));
    }
    EXPECT_LT(error[1], 1.5 * error[0] + 0.001);
}

// Texels whose rays start inside the object stay dark at any ray count. On the car's door (a
// close-up of the bundled scene) the tessellation lies above the limit point of some texels by
// more than 3% of a face, so a snap ray starting within 3% of a face of the limit point would
// start inside the car (and miss, or find the inner wall of a folded seam). Texture-space AO
// with the 1x1 filter at 256 rays per sample against per-hit AO with the same camera rays (same
// spp and seed: coverage cancels) at 256 rays per camera sample: a pixel is off by more than 0.2
// only where bias stays. The two estimates have standard deviations of at most 0.031 (one
// texel's 256 rays) and 0.016 (4 x 256 rays), so 0.2 is over 5 combined standard deviations;
// texel quantization moves AO by far less than 0.2 across a texel on this smooth door. Bound: at
// most 3 of the 3072 pixels (0.1%); measured 0 (relMSE 0.009).
TEST(TextureSpace, NoTexelStartsItsRaysInsideTheCar) {
    std::vector<std::string> warnings;
    Scene s = LoadScene(test::SceneDir() + "/car.json", &warnings);
    s.camera.pose.keys = {test::LookAt({3.4f, 1.35f, 3.7f}, {0.62f, 0.19f, -0.745f})};
    s.camera.fovYDegrees = 5.0f;
    RenderSceneOptions ro;
    ro.needLights = false;
    ro.needEnvironment = false;
    const RenderScene rs(s, ro);
    const Image ref = Render(rs, AoOptions(4, 256)).beauty;
    const Image tex = Render(rs, CachedAo(4, 256, TextureFilterKind::None)).beauty;
    int off = 0;
    for (size_t i = 0; i < ref.data.size(); i += size_t(ref.channels))
        off += std::abs(tex.data[i] - ref.data[i]) > 0.2f;
    RecordProperty("pixelsOff", off);
    EXPECT_LE(off, 3) << "of " << ref.NumPixels() << " pixels; relMSE " << RelMSE(tex, ref);
}

// At equal AO rays per sample, every filter is closer to the reference than the unfiltered
// cache: the normal-weighted 13x13 and 21x21 Gaussian average tens of samples per texel on
// smooth regions, the regression up to 17x17 where its error estimate allows (at least 2x lower
// relMSE; measured none 0.130, normal 0.042, Gaussian 0.041, regression 0.043 with visible
// footprints, 0.034 / 0.034 / 0.037 with full windows).
TEST(TextureSpace, FiltersLowerErrorAtEqualSamples) {
    const RenderScene& rs = TorusAo();
    const Image ref = Render(rs, AoOptions(256, 8)).beauty;
    RenderOptions o = CachedAo(4, 2, TextureFilterKind::None);
    const double none = RelMSE(Render(rs, o).beauty, ref);
    for (TextureFilterKind f :
         {TextureFilterKind::Normal, TextureFilterKind::Gaussian, TextureFilterKind::Regression}) {
        o.texture.filter = f;
        const double e = RelMSE(Render(rs, o).beauty, ref);
        EXPECT_LT(e, 0.5 * none) << "filter " << int(f) << ": none " << none << ", filtered " << e;
    }
}

// Footprints of visible texels only (texcache/visible_texels.h): the 13x13 normal filter then
// shades little more than the 1x1 render (the texels the camera rays reach), not every texel of
// each window, at an error close to the full window's.
TEST(TextureSpace, VisibleFootprintsShadeWhatTheCameraSees) {
    const RenderScene& rs = TorusAo();
    const Image ref = Render(rs, AoOptions(256, 8)).beauty;
    RenderOptions o = CachedAo(4, 4, TextureFilterKind::None);
    const RenderResult none = Render(rs, o);
    o.texture.filter = TextureFilterKind::Normal;
    o.texture.footprint = FootprintMode::All;
    const RenderResult all = Render(rs, o);
    o.texture.footprint = FootprintMode::Visible;
    const RenderResult visible = Render(rs, o);
    const double eNone = RelMSE(none.beauty, ref), eAll = RelMSE(all.beauty, ref),
                 eVisible = RelMSE(visible.beauty, ref);
    const double nNone = double(none.stats.cache.samplesShaded),
                 nAll = double(all.stats.cache.samplesShaded),
                 nVisible = double(visible.stats.cache.samplesShaded);
    RecordProperty("samples", std::to_string(nNone) + " / " + std::to_string(nAll) + " / " +
                                  std::to_string(nVisible));
    RecordProperty("relMSE", std::to_string(eNone) + " / " + std::to_string(eAll) + " / " +
                                 std::to_string(eVisible));
    EXPECT_EQ(none.stats.cache.tapsUnseen, 0u);  // no footprint, no prepass
    EXPECT_EQ(all.stats.cache.tapsUnseen, 0u);
    EXPECT_GT(visible.stats.cache.tapsUnseen, 0u);
    // Measured: samples 6416 / 21126 / 6786 (1x1 / all / visible), relMSE 0.059 / 0.0340 /
    // 0.0352 (each sample's 4 rays a (0,2,2)-net).
    EXPECT_LT(nVisible, 0.5 * nAll) << nNone << " " << nAll << " " << nVisible;
    EXPECT_LT(nVisible, 1.25 * nNone) << nNone << " " << nAll << " " << nVisible;
    EXPECT_LT(eVisible, 0.7 * eNone) << eNone << " " << eAll << " " << eVisible;
    EXPECT_LT(eVisible, 1.2 * eAll) << eNone << " " << eAll << " " << eVisible;
    // Each camera sample is traced once: the shading pass takes its texels from the prepass.
    EXPECT_EQ(visible.stats.cameraRays, all.stats.cameraRays);
}

// Progressive texture space (the note at the top of texture_space.h): each pass re-shades the
// cache with fresh random numbers, jittered sample positions and smaller footprints, so error
// keeps falling with the budget, where the paper's cache, shaded once, stalls. 13x13 normal
// filter, 1 AO ray per cached sample, 4 camera samples per pass; the reference's own relMSE is
// ~1e-4. Measured: 1 pass 0.0494, 16 passes 0.0051 (1/9.7); the cache shaded once with the same
// 64 camera samples 0.0106 (more camera samples still lower the pixels' coverage noise).
// Caches sized to the frame (a render that gives no size): texels and visible-footprint samples
// take 128 bytes per pixel of every view, whole-window footprints 512 bytes per sample, within
// [4, 64] MiB.
TEST(TextureSpace, CachesSizedToTheFrameStayWithinBounds) {
    constexpr size_t kMiB = size_t(1) << 20;
    CacheSettings c;
    SizeCachesToFrame(&c, 480, 270, 1, IntegratorKind::AO, FootprintMode::Auto);
    EXPECT_EQ(c.texelCacheBytes, size_t(480 * 270 * 128));
    EXPECT_EQ(c.sampleCacheBytes, size_t(480 * 270 * 128));
    SizeCachesToFrame(&c, 480, 270, 2, IntegratorKind::AO, FootprintMode::All);
    EXPECT_EQ(c.texelCacheBytes, size_t(2 * 480 * 270 * 128));
    EXPECT_EQ(c.sampleCacheBytes, 64 * kMiB);  // 2 x 480 x 270 x 512 = 126 MiB: capped
    SizeCachesToFrame(&c, 320, 180, 1, IntegratorKind::Path, FootprintMode::Auto);
    EXPECT_EQ(c.sampleCacheBytes, size_t(320 * 180 * 512));
    SizeCachesToFrame(&c, 320, 180, 1, IntegratorKind::Path, FootprintMode::Visible);
    EXPECT_EQ(c.sampleCacheBytes, size_t(320 * 180 * 128));
    SizeCachesToFrame(&c, 16, 9, 1, IntegratorKind::AO, FootprintMode::Auto);
    EXPECT_EQ(c.texelCacheBytes, 4 * kMiB);
    EXPECT_EQ(c.sampleCacheBytes, 4 * kMiB);
    SizeCachesToFrame(&c, 1 << 20, 1 << 20, 2, IntegratorKind::Direct, FootprintMode::Auto);
    EXPECT_EQ(c.texelCacheBytes, 64 * kMiB);
    EXPECT_EQ(c.sampleCacheBytes, 64 * kMiB);
    SizeCachesToFrame(&c, 0, -5, 0, IntegratorKind::AO, FootprintMode::Auto);  // nonsense: floor
    EXPECT_EQ(c.texelCacheBytes, 4 * kMiB);
}

TEST(TextureSpace, ProgressivePassesKeepConverging) {
    const RenderScene& rs = TorusAo();
    const Image ref = Render(rs, AoOptions(256, 16)).beauty;
    RenderOptions o = CachedAo(4, 1, TextureFilterKind::Normal);
    const double e1 = RelMSE(Render(rs, o).beauty, ref);
    o.spp = 64;
    const RenderResult sixteen = Render(rs, o);
    const double e16 = RelMSE(sixteen.beauty, ref);
    o.texture.passSpp = 0;  // one pass: the cache shaded once
    const double eOnce = RelMSE(Render(rs, o).beauty, ref);
    std::printf("relMSE: 1 pass %.5f, 16 passes %.5f (1/%.1f), shaded once %.5f\n", e1, e16,
                e1 / e16, eOnce);
    EXPECT_LT(e16, e1 / 8.0);
    EXPECT_LT(e16, 0.7 * eOnce);  // beats the cache shaded once at the same camera samples
    EXPECT_EQ(sixteen.stats.sppDone, 64);
}

// Each progressive pass filters with the texels its own camera samples see. Through a thin lens
// the passes see different texels around each one, and a visible set kept over the passes would
// grow with every pass, every sample of it shaded again each pass. Here a pass shades about as
// many samples at pass 8 as at pass 2 (within 10%; measured 1.00).
TEST(TextureSpace, PassesThroughALensShadeWhatTheyOwnSee) {
    Scene scene = TorusOnPlane();
    scene.camera.lensRadius = 0.15f;
    scene.camera.focusDistance = 3.5f;
    RenderSceneOptions ro;
    ro.needLights = false;
    const RenderScene rs(scene, ro);
    RenderOptions o = CachedAo(8, 1, TextureFilterKind::Normal);
    o.width = 128, o.height = 96;
    const RenderResult two = Render(rs, o);
    o.spp = 32;
    const RenderResult eight = Render(rs, o);
    const double perPassTwo = double(two.stats.cache.samplesShaded) / 2.0;
    const double perPassEight = double(eight.stats.cache.samplesShaded) / 8.0;
    std::printf("samples shaded per pass: %.0f over 2 passes, %.0f over 8 (%.3fx)\n", perPassTwo,
                perPassEight, perPassEight / perPassTwo);
    EXPECT_LT(perPassEight, 1.1 * perPassTwo);
    EXPECT_GT(perPassEight, 0.9 * perPassTwo);
}

// Defocus picks texels for the circle of confusion (RenderScene::Interact): through a wide lens
// focused on the torus, the blurred plane before and behind it takes coarser texels, so a render
// shades fewer samples than through a lens of negligible radius (same rays otherwise; measured
// 0.71x, 0.98x without the widening), and its error against a per-hit render of many samples
// stays below per-hit shading's at the same camera samples (measured 0.0537 against 0.0786;
// 0.0532 without the widening).
TEST(TextureSpace, DefocusedSurfacesTakeTexelsOfTheirBlur) {
    auto render = [](float lensRadius, bool cached, int spp) {
        Scene scene = TorusOnPlane();
        scene.camera.lensRadius = lensRadius;
        scene.camera.focusDistance = 3.4f;  // the torus
        RenderSceneOptions ro;
        ro.needLights = false;
        const RenderScene rs(scene, ro);
        RenderOptions o = cached ? CachedAo(spp, 1, TextureFilterKind::Normal) : AoOptions(spp, 1);
        o.width = 128, o.height = 96;
        return Render(rs, o);
    };
    const Image ref = render(0.2f, false, 256).beauty;
    const RenderResult narrow = render(1e-5f, true, 16), wide = render(0.2f, true, 16);
    const double shadedRatio =
        double(wide.stats.cache.samplesShaded) / double(narrow.stats.cache.samplesShaded);
    const double eWide = RelMSE(wide.beauty, ref),
                 ePerHit = RelMSE(render(0.2f, false, 16).beauty, ref);
    std::printf(
        "samples shaded, wide / narrow lens: %.3f; relMSE texture space %.5f, per hit %.5f\n",
        shadedRatio, eWide, ePerHit);
    EXPECT_LT(shadedRatio, 0.8);
    EXPECT_LT(eWide, ePerHit);
}

// Progressive passes stay deterministic: each pass's samples draw from streams of their key and
// the pass, so 4 passes give the same image on 1 and 2 threads (bit-exact).
TEST(TextureSpace, ProgressivePassesAreDeterministicAcrossThreadCounts) {
    const RenderScene& rs = TorusAo();
    RenderOptions o = CachedAo(16, 2, TextureFilterKind::Normal);
    EXPECT_EQ(RenderOnThreads(rs, o, 1).data, RenderOnThreads(rs, o, 2).data);
}

// The radius schedule r_k = round(r_0 (k + 1)^(-1/6)): r_0 at pass 0, never growing, half at
// pass 63, and still a valid radius at the last pass a 32-bit count can name (the pass count
// saturates there instead of wrapping to pass 0).
TEST(TextureSpace, PassRadiusShrinksAndSaturates) {
    EXPECT_EQ(TextureSpaceCache::PassRadius(6, 0), 6);
    EXPECT_EQ(TextureSpaceCache::PassRadius(6, 63), 3);
    EXPECT_EQ(TextureSpaceCache::PassRadius(0, 5), 0);
    int prev = 10;
    for (uint32_t k = 0; k < 100000; k = k * 2 + 1) {
        const int r = TextureSpaceCache::PassRadius(10, k);
        EXPECT_LE(r, prev) << "pass " << k;
        EXPECT_GE(r, 0);
        prev = r;
    }
    EXPECT_EQ(TextureSpaceCache::PassRadius(10, UINT32_MAX), 0);
    const RenderScene& rs = TorusAo();
    RenderOptions o = CachedAo(8, 1, TextureFilterKind::Normal);
    TextureSpaceCache cache(rs, o.texture);
    cache.BeginPass(UINT32_MAX - 1);
    const Image img = Render(rs, o, &cache).beauty;  // passes UINT32_MAX - 1 and UINT32_MAX
    EXPECT_EQ(cache.Pass(), UINT32_MAX);
    for (float v : img.data) ASSERT_TRUE(std::isfinite(v));
}

// Samples are shaded with a random stream derived from their key, so the image is the same
// whichever thread shades what (bit-exact), even with a cache small enough to evict.
TEST(TextureSpace, DeterministicAcrossThreadCounts) {
    const RenderScene& rs = TorusAo();
    RenderOptions o = AoOptions(4, 4);
    o.texture.enabled = true;
    o.texture.cache.sampleCacheBytes = 256 * 1024;
    EXPECT_EQ(RenderOnThreads(rs, o, 1).data, RenderOnThreads(rs, o, 2).data);
}

// The caches persist across frames: a second render of the same view hits every texel but the
// few that share a slot with another visible texel (direct mapping: ~n^2/2m pairs for n texels
// in m slots, here ~7 of 2600). Its image is the first one (bit-exact): a texel read from the
// cache, whether by the visibility prepass or by the shading pass, holds what a miss would
// filter.
TEST(TextureSpace, WarmCacheHitsEveryTexelOnTheSecondFrame) {
    const RenderScene& rs = TorusAo();
    RenderOptions o = AoOptions(1, 4);
    o.texture.enabled = true;
    TextureSpaceCache cache(rs, o.texture);
    const RenderResult first = Render(rs, o, &cache);
    const RenderResult second = Render(rs, o, &cache);
    EXPECT_EQ(first.beauty.data, second.beauty.data);
    const CacheStats& c = second.stats.cache;
    EXPECT_GE(double(c.texelHits), 0.99 * double(c.lookups));
    EXPECT_EQ(c.texelMisses, c.texelEvictions + c.texelUncached);  // every miss is a slot conflict
    EXPECT_LT(c.samplesShaded, c.lookups / 20);
    EXPECT_LE(cache.SampleCacheBytes() + cache.TexelCacheBytes(),
              o.texture.cache.sampleCacheBytes + o.texture.cache.texelCacheBytes);
}

// A pixel's samples mostly land on one texel, and the prepass of a warm frame gives a sample on
// the texel of the sample before it that sample's mark and lookup. Every sample still reads its
// own texel (the cold frame's image, bit-exact) and counts as one lookup, also with a texel cache
// so small that the frame's texels evict each other, where a texel found for one sample may be
// missing for the next on another texel: never another key's value.
TEST(TextureSpace, WarmPrepassReadsEachSamplesOwnTexel) {
    const RenderScene& rs = TorusAo();
    for (const size_t texelBytes : {size_t(64) << 20, size_t(16) << 10}) {
        SCOPED_TRACE(texelBytes);
        RenderOptions o = CachedAo(4, 2, TextureFilterKind::Normal);
        o.texture.cache.texelCacheBytes = texelBytes;
        TextureSpaceCache cache(rs, o.texture);
        const RenderResult first = Render(rs, o, &cache);
        const RenderResult warm = Render(rs, o, &cache);
        EXPECT_EQ(first.beauty.data, warm.beauty.data);
        const CacheStats& c = warm.stats.cache;
        EXPECT_EQ(c.lookups, first.stats.cache.lookups);
        EXPECT_GT(c.texelHits, 0u);
        if (texelBytes < first.stats.cache.lookups * 32)
            EXPECT_LT(double(c.texelHits), 0.9 * double(c.lookups));  // a cache that thrashes
        else
            EXPECT_GE(double(c.texelHits), 0.99 * double(c.lookups));
    }
}

// The visibility prepass asks the texel cache for its texels only when the cache may hold some
// (MayHoldTexels; skipping the probes of an empty table saved 7% of a 21x21 AO render). A render
// into an emptied cache behaves as the first render, one into a warm cache finds nearly all,
// and all give the image of a fresh cache. Every way of emptying the cache clears the flag.
TEST(TextureSpace, PrepassFindsTexelsOnlyInACacheThatMayHoldThem) {
    const RenderScene& rs = TorusAo();
    RenderOptions o = AoOptions(1, 4);
    o.texture.enabled = true;
    TextureSpaceCache cache(rs, o.texture);
    EXPECT_FALSE(cache.MayHoldTexels());
    const RenderResult first = Render(rs, o, &cache);
    EXPECT_TRUE(cache.MayHoldTexels());
    const RenderResult warm = Render(rs, o, &cache);
    EXPECT_GE(double(warm.stats.cache.texelHits), 0.99 * double(warm.stats.cache.lookups));
    EXPECT_EQ(first.beauty.data, warm.beauty.data);
    cache.Invalidate();
    EXPECT_FALSE(cache.MayHoldTexels());
    // Cold again: the first render's lookups and image (its hits are texels that block
    // reconstruction filtered beside a miss; which thread does which varies).
    const RenderResult again = Render(rs, o, &cache);
    EXPECT_EQ(again.stats.cache.lookups, first.stats.cache.lookups);
    EXPECT_GT(again.stats.cache.texelMisses, warm.stats.cache.texelMisses);
    EXPECT_EQ(first.beauty.data, again.beauty.data);
    cache.BeginFrame(1);
    EXPECT_FALSE(cache.MayHoldTexels());
    Render(rs, o, &cache);
    cache.BeginPass(cache.Pass() + 1);
    EXPECT_FALSE(cache.MayHoldTexels());
    Render(rs, o, &cache);
    EXPECT_TRUE(cache.Reconfigure(rs, o.texture));
    EXPECT_FALSE(cache.MayHoldTexels());
}

// RestartPasses (the preview, when the view moves after a still view re-shaded its cache for
// many passes) goes back to pass 0 and keeps what is cached: the next render of the view finds
// its texels, and once emptied the cache renders pass 0's image again (its full footprints),
// not pass 40's (radius 6 -> 3).
TEST(TextureSpace, RestartPassesKeepsTheCacheAndPassZerosFootprints) {
    const RenderScene& rs = TorusAo();
    RenderOptions o = CachedAo(2, 1, TextureFilterKind::Normal);
    o.texture.radius = 6;
    TextureSpaceCache cache(rs, o.texture);
    const Image pass0 = Render(rs, o, &cache).beauty;
    cache.BeginPass(40);
    const Image pass40 = Render(rs, o, &cache).beauty;
    EXPECT_NE(pass0.data, pass40.data);
    cache.RestartPasses();
    EXPECT_EQ(cache.Pass(), 0u);
    const RenderResult kept = Render(rs, o, &cache);
    EXPECT_GE(double(kept.stats.cache.texelHits), 0.99 * double(kept.stats.cache.lookups));
    cache.Invalidate();
    EXPECT_EQ(Render(rs, o, &cache).beauty.data, pass0.data);
}

// Reconfigure keeps the storage but starts empty with the new options: the render after it
// equals a render with a freshly built cache (bit-exact: samples draw from per-key streams), for
// a change of filter and radius. A different layout (cache size) is refused and changes nothing.
TEST(TextureSpace, ReconfiguredCacheRendersLikeANewOne) {
    const RenderScene& rs = TorusAo();
    RenderOptions o = AoOptions(2, 4);
    o.texture.enabled = true;
    o.texture.cache.sampleCacheBytes = o.texture.cache.texelCacheBytes = size_t(1) << 20;
    // One thread: with two, which of two keys sharing a slot is shaded first (so the shading
    // count, not the image) depends on scheduling.
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    TextureSpaceCache cache(rs, o.texture);
    Render(rs, o, &cache);  // warm: every texel of the view cached with the 13x13 filter

    RenderOptions other = o;
    other.texture.filter = TextureFilterKind::Gaussian;
    other.texture.radius = 4;
    ASSERT_TRUE(cache.Reconfigure(rs, other.texture));
    EXPECT_EQ(cache.RadiusOf(0), 4);
    const RenderResult reused = Render(rs, other, &cache);
    const RenderResult fresh = Render(rs, other);
    EXPECT_EQ(reused.beauty.data, fresh.beauty.data);
    EXPECT_EQ(reused.stats.cache.texelHits, fresh.stats.cache.texelHits);  // started cold
    EXPECT_EQ(reused.stats.cache.samplesShaded, fresh.stats.cache.samplesShaded);

    RenderOptions bigger = other;
    bigger.texture.cache.sampleCacheBytes *= 2;
    EXPECT_FALSE(cache.Reconfigure(rs, bigger.texture));
    EXPECT_EQ(cache.RadiusOf(0), 4);
    EXPECT_EQ(cache.SampleCacheBytes(), size_t(1) << 20);
}

// Texture-space diffuse light (path integrator; direct + indirect, or indirect only): finite, and
// close to per-hit path tracing in the mean (same estimator up to texel quantization and
// filtering). With a GGX plane, its diffuse base's light is cached (all of it: the specular
// lobe per hit, CachedTerm::DiffuseBase; or its indirect part: both lobes' direct light per hit
// and the specular lobe's indirect light, CachedTerm::BaseIndirect).
TEST(TextureSpace, CachedIndirectIsFiniteAndUnbiasedInTheMean) {
    for (bool glossy : {false, true}) {
        Scene s = TorusOnPlane();
        EnvironmentLight env;
        env.constant = glm::vec3(1.0f);
        s.environments.push_back(env);
        if (glossy) MakePlaneGlossy(&s);
        const RenderScene rs(s, {});
        RenderOptions o = AoOptions(16, 1);
        o.integrator = IntegratorKind::Path;
        o.maxDepth = 3;
        const Image hit = Render(rs, o).beauty;
        o.texture.enabled = true;
        for (bool direct : {true, false}) {  // diffuse direct light cached too, or per hit
            o.texture.cacheDirect = direct;
            const RenderResult tex = Render(rs, o);
            // Measured ~0.5% (glossy: 0.6%); a non-finite pixel makes the ratio NaN, which fails.
            EXPECT_NEAR(test::MeanRatio(tex.beauty, hit), 1.0, 0.03)
                << "cacheDirect " << direct << ", glossy plane " << glossy;
            EXPECT_GT(tex.stats.cache.samplesShaded, 0u);
        }
    }
}

// Every filter on the meshes with the hard features (extraordinary vertices up to valence 24,
// n-gons, a hole, semi-sharp and infinitely sharp creases, tiny faces next to big ones): AO stays
// finite and in [0, 1] at every pixel, in the first pass (texel centres) and in a progressive
// pass (samples jittered inside their texels, up to the faces' edges).
TEST(TextureSpace, EveryFilterIsFiniteOnHardMeshes) {
    for (const char* mesh : {"catmark_xord_interior", "catmark_hole_test1", "catmark_nonquads",
                             "catmark_cube_creases1", "catmark_cubes_infsharp", "catmark_bishop"}) {
        Scene s = test::OneObjectScene(test::LoadMesh(mesh));
        glm::vec3 lo(1e30f), hi(-1e30f);
        for (const auto& p : s.meshes[0].positions) {
            lo = glm::min(lo, glm::vec3(p[0], p[1], p[2]));
            hi = glm::max(hi, glm::vec3(p[0], p[1], p[2]));
        }
        const glm::vec3 c = 0.5f * (lo + hi);
        const float r = glm::length(hi - lo);
        // A grazing view: texels far from the camera get coarse mips, near ones fine.
        s.camera.pose.keys = {test::LookAt(c + r * glm::vec3(0.9f, 0.35f, 0.8f), c)};
        RenderSceneOptions ro;
        ro.needLights = false;
        const RenderScene rs(s, ro);
        for (TextureFilterKind f :
             {TextureFilterKind::None, TextureFilterKind::Normal, TextureFilterKind::Gaussian,
              TextureFilterKind::Regression, TextureFilterKind::SoftShadow}) {
            RenderOptions o = AoOptions(2, 2);
            o.aoDistance = 0.3f * r;
            o.texture.enabled = true;
            o.texture.passSpp = 1;  // two passes
            o.texture.filter = f;
            const Image img = Render(rs, o).beauty;
            EXPECT_TRUE(AllFiniteIn(img, 0.0f, 1.0f)) << mesh << " filter " << int(f);
        }
    }
}

// Very large coordinates: the torus and plane moved 1e5 units away and scaled 1e3 (the camera
// with them). Float positions then carry ~1e-2 absolute error; ray offsets and sample snapping
// scale with the coordinates, so AO with every filter stays finite and in [0, 1], and close to
// the same scene at the origin (relMSE below 0.05 against it; per-pixel noise differs anyway).
TEST(TextureSpace, VeryLargeCoordinatesStayFinite) {
    auto scene = [](float scale, glm::vec3 offset) {
        Scene s = TorusOnPlane();
        for (Object& o : s.objects) {
            if (o.transform.keys.empty()) o.transform.keys.push_back({});
            for (Keyframe& k : o.transform.keys) {
                k.translation = offset + scale * k.translation;
                k.scale *= scale;
            }
        }
        s.camera.pose.keys = {test::LookAt(offset + scale * glm::vec3(1.6f, 2.2f, 2.6f),
                                           offset + scale * glm::vec3(0, -0.2f, 0))};
        return s;
    };
    RenderSceneOptions ro;
    ro.needLights = false;
    const Scene near = scene(1.0f, glm::vec3(0.0f)), far = scene(1e3f, glm::vec3(1e5f));
    const RenderScene rsNear(near, ro), rsFar(far, ro);
    for (TextureFilterKind f : {TextureFilterKind::Normal, TextureFilterKind::Regression}) {
        RenderOptions o = AoOptions(4, 4);
        o.texture.enabled = true;
        o.texture.filter = f;
        const Image a = Render(rsNear, o).beauty;
        o.aoDistance *= 1e3f;
        const Image b = Render(rsFar, o).beauty;
        EXPECT_TRUE(AllFiniteIn(b, 0.0f, 1.0f)) << "filter " << int(f);
        EXPECT_LT(RelMSE(b, a), 0.05) << "filter " << int(f);
    }
}

// Temporal accumulation (eq. 6) over frames of a static scene averages the per-frame noise of
// the texels: the 8th frame with alpha = 0.7 is closer to the reference than one frame alone.
// RMSE rather than relMSE: at this size relMSE is ruled by a few dark crevice pixels and jumps
// by 2x from seed to seed. (alpha = 0.7 averages ~(1 + a) / (1 - a) = 5.7 frames in steady
// state; the bound asks for a 2x lower MSE.)
TEST(TextureSpace, TemporalAccumulationLowersErrorOnAStaticScene) {
    const RenderScene& rs = TorusAo();
    const Image ref = Render(rs, AoOptions(256, 8)).beauty;
    RenderOptions o = CachedAo(4, 1, TextureFilterKind::None);
    const double single = RMSE(Render(rs, o).beauty, ref);
    o.texture.temporalAlpha = 0.7f;
    TextureSpaceCache cache(rs, o.texture);
    Image last;
    for (uint32_t f = 0; f < 8; ++f) {
        cache.BeginFrame(f);
        RenderOptions fo = o;
        fo.seed = 1000 + f;
        last = Render(rs, fo, &cache).beauty;
    }
    const double accumulated = RMSE(last, ref);
    EXPECT_LT(accumulated, 0.7 * single) << "single " << single << " accumulated " << accumulated;
}

// Soft shadows: a quad light over the torus and plane. Cached, filtered visibility times the
// per-hit unshadowed light is closer to the reference than per-hit direct lighting at equal
// camera samples, and the mean brightness agrees (within 5%).
TEST(TextureSpace, SoftShadowFilterLowersDirectLightingError) {
    Scene s = TorusOnPlane();
    QuadLight q;
    q.corner = glm::vec3(-0.4f, 2.0f, -0.4f);
    q.edge1 = glm::vec3(0.8f, 0.0f, 0.0f);
    q.edge2 = glm::vec3(0.0f, 0.0f, 0.8f);  // emits downwards: cross(e1, e2) = -Y
    q.radiance = glm::vec3(5.0f);
    q.transform.keys.push_back({});
    s.quadLights.push_back(q);
    const RenderScene rs(s, {});
    RenderOptions o = AoOptions(256, 1);
    o.integrator = IntegratorKind::Direct;
    const Image ref = Render(rs, o).beauty;
    o.spp = 4;
    const Image hit = Render(rs, o).beauty;
    o.texture.enabled = true;
    o.texture.filter = TextureFilterKind::SoftShadow;
    const Image soft = Render(rs, o).beauty;
    ASSERT_TRUE(AllFiniteIn(soft, 0.0f, 1e4f));
    const double eHit = RelMSE(hit, ref), eSoft = RelMSE(soft, ref);
    // Measured: per hit 0.0299 (its light samples a net per pixel: PixelSequence), the filter
    // 0.0154.
    EXPECT_LT(eSoft, 0.6 * eHit) << "per hit " << eHit << " soft-shadow filter " << eSoft;
    double mr = 0, ms = 0;
    for (size_t i = 0; i < ref.data.size(); ++i) mr += ref.data[i], ms += soft.data[i];
    EXPECT_NEAR(ms / mr, 1.0, 0.05);
}

// The unshadowed light that multiplies the filtered visibility is estimated per hit from the
// texture.shadowSamples points on each quad light, a digitally shifted Sobol' net: a plane right
// under a large quad light, nothing in between (visibility 1), so the render's error is that
// estimate's alone (and the camera samples', 1 per pixel against 256). Measured with 4 points:
// relMSE 0.166 as a net, 0.519 with independent points; the bound sits between.
TEST(TextureSpace, UnshadowedQuadLightIsStratified) {
    Scene s = test::OneObjectScene(test::PlaneCage(4.0f));
    // Low and narrow: the plane under the light fills the frame, the light itself is out of it.
    s.camera.pose.keys = {test::LookAt({0.0f, 1.0f, 3.5f}, {0, -0.5f, 0})};
    s.camera.fovYDegrees = 20.0f;
    QuadLight q;
    q.corner = glm::vec3(-1.5f, 1.5f, -1.5f);
    q.edge1 = glm::vec3(3.0f, 0.0f, 0.0f);
    q.edge2 = glm::vec3(0.0f, 0.0f, 3.0f);  // emits downwards
    q.radiance = glm::vec3(1.0f);
    q.transform.keys.push_back({});
    s.quadLights.push_back(q);
    const RenderScene rs(s, {});
    RenderOptions o = AoOptions(256, 1);
    o.width = 64, o.height = 48;
    o.integrator = IntegratorKind::Direct;
    const Image ref = Render(rs, o).beauty;
    o.spp = 1;
    o.texture.enabled = true;
    o.texture.filter = TextureFilterKind::SoftShadow;
    o.texture.shadowSamples = 4;
    const Image soft = Render(rs, o).beauty;
    ASSERT_TRUE(AllFiniteIn(soft, 0.0f, 1e4f));
    const double e = RelMSE(soft, ref);
    std::printf("unshadowed light, 4 points per hit: relMSE %.4f\n", e);
    EXPECT_LT(e, 0.3);
}

}  // namespace
}  // namespace texcache
