// SPDX-License-Identifier: Apache-2.0
// The texture-space cache in the screen-space stage's input (renderer/frame_buffers/): cached
// diffuse light composes like the per-hit split's, every denoiser keeps it, and the cached
// visibility is near the per-hit visibility's expectation, in the library and from the CLI.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "cli_run.h"
#include "frame_buffers_util.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/image/metrics.h"
#include "renderer/integrators/bsdf.h"
#include "renderer/scene/scene_loader.h"
#include "screen_space/brdf_table.h"
#include "screen_space/screen_denoiser.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;
using screen::FrameBuffers;
using test::CachedFrameOptions;
using test::ExpectSameBuffer;
using test::Finite;
using test::FrameOptions;
using test::TempDir;
using test::TestScene;

// Texture-space shading composes with the split: diffuse materials take their indirect light
// from the cache (no diffuse ray: cones NaN there), the glossy torus keeps its rays. With the
// cache's unfiltered 1x1 texels (4 paths per cached sample; 4 spp per hit), the mean indirect
// light of the diffuse pixels over 64 frames is within 6% of the per-hit split's (measured
// 0.97-1.02 across seeds; without the cached term it would be 0, with direct light cached too
// several times larger) and the composed image's within 1% (measured 0.05%). (The default 13x13
// normal filter adds ~17% here: it spreads the strong indirect light under the torus, hidden from
// the camera, onto visible texels; that is the filter's bias, not the split's.)
// A Ptex texture is looked up with the pixel's footprint whether or not texture space is on, as
// the path tracer's camera hits look it up (RenderScene::Interact with ray differentials): the
// albedo buffers of a per-hit and a texture-space frame of Disney's flattened sphere agree
// within float rounding (1e-5). Without differentials the per-hit frame took the finest level,
// 0.83 away in a channel where the cell noise changes within the pixel, and its denoised
// relMSE on scenes/ptex_flatsphere.json was 0.106 against texture space's 0.003.
TEST(FrameBuffers, PtexFootprintWithAndWithoutTextureSpace) {
    std::vector<std::string> warnings;
    const Scene s = LoadScene(test::SceneDir() + "/ptex_flatsphere.json", &warnings);
    RenderScene rs(s, {});
    RenderOptions o = FrameOptions(96, 72);
    FrameBuffers perHit, cached;
    RenderFrameBuffers(rs, o, -0.04f, &perHit);
    o.texture.enabled = true;
    TextureSpaceCache cache(rs, o.texture);
    RenderFrameBuffers(rs, o, -0.04f, &cached, &cache);
    float worst = 0.0f;
    int surface = 0;
    for (size_t p = 0; p < perHit.NumPixels(); ++p) {
        if (perHit.objectId[p] < 0) continue;
        ASSERT_TRUE(Finite(perHit.albedo[p])) << p;
        const glm::vec3 d = glm::abs(perHit.albedo[p] - cached.albedo[p]);
        worst = std::max({worst, d.x, d.y, d.z}), ++surface;
    }
    std::printf("%d pixels on the surface, largest albedo difference %.3g\n", surface, worst);
    EXPECT_GT(surface, 1000);
    EXPECT_LE(worst, 1e-5f);
}

TEST(FrameBuffers, TextureSpaceCacheComposes) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    RenderOptions o = CachedFrameOptions(40, 30, TextureFilterKind::None, -1);
    o.spp = 4;
    TextureSpaceCache cache(rs, o.texture);
    double cached = 0.0, perHit = 0.0, cachedIndirect = 0.0, perHitIndirect = 0.0;
    FrameBuffers fb;
    auto diffuse = [&](size_t p) { return fb.objectId[p] == 0 || fb.objectId[p] == 2; };
    for (int f = 0; f < 64; ++f) {
        cache.BeginFrame(uint32_t(f));
        o.seed = uint64_t(f);
        o.texture.enabled = true;
        RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        for (size_t p = 0; p < fb.NumPixels(); ++p) {
            ASSERT_TRUE(Finite(fb.indirect[p])) << p;
            if (diffuse(p)) {
                // The cached irradiance / pi in all six cones: they shade to the indirect light.
                const glm::vec3* cones = &fb.cones[p * screen::kNumCones];
                for (int k = 0; k < screen::kNumCones; ++k) {
                    ASSERT_TRUE(Finite(cones[k])) << p;
                    EXPECT_EQ(cones[k], cones[0]) << p;
                }
                const glm::vec3 shaded = fb.albedo[p] * screen::ShadeCones(cones);
                for (int c = 0; c < 3; ++c)
                    EXPECT_NEAR(shaded[c], fb.indirect[p][c], 1e-5f * (1.0f + fb.indirect[p][c]));
                cachedIndirect += Luminance(fb.indirect[p]);
            }
        }
        for (const glm::vec3& c : fb.Compose()) cached += Luminance(c);
        o.texture.enabled = false;
        RenderFrameBuffers(rs, o, -0.04f, &fb);
        for (const glm::vec3& c : fb.Compose()) perHit += Luminance(c);
        for (size_t p = 0; p < fb.NumPixels(); ++p)
            if (diffuse(p)) perHitIndirect += Luminance(fb.indirect[p]);
    }
    std::printf("cached / per hit: indirect %.5f, composed %.5f\n", cachedIndirect / perHitIndirect,
                cached / perHit);
    EXPECT_NEAR(cachedIndirect / perHitIndirect, 1.0, 0.06);
    EXPECT_NEAR(cached / perHit, 1.0, 0.01);
}

/// 32 frames of the test scene at 40x30, 4 spp, unfiltered texels, each rendered with the
/// texture-space cache (all of the diffuse lobe's light cached with `layered`) and per hit:
/// the ratio of the sums of `measure(fb)` over the cached frames and over the per-hit ones;
/// `checkCached(fb)` sees each cached frame.
template <typename Measure, typename Check>
double CachedOverPerHit(bool layered, Measure&& measure, Check&& checkCached) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    RenderOptions o = CachedFrameOptions(40, 30, TextureFilterKind::None, -1);
    o.texture.cacheDiffuseLayer = layered;
    o.spp = 4;
    TextureSpaceCache cache(rs, o.texture);
    double cached = 0.0, perHit = 0.0;
    FrameBuffers fb;
    for (int f = 0; f < 32; ++f) {
        cache.BeginFrame(uint32_t(f));
        o.seed = uint64_t(f);
        o.texture.enabled = true;
        RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        checkCached(fb);
        cached += measure(fb);
        o.texture.enabled = false;
        RenderFrameBuffers(rs, o, -0.04f, &fb);
        perHit += measure(fb);
    }
    return cached / perHit;
}

// Under soft light the cache can hold all of the diffuse lobe's light (cacheDiffuseLayer): then
// `shading` is the specular lobe's alone (0 on the diffuse objects, visible there), `indirect`
// holds the diffuse lobe's direct and indirect light, the cones shade to it, and the composed
// image keeps the per-hit split's expectation: its mean over 32 frames within 2% of per hit's.
TEST(FrameBuffers, TextureSpaceCacheHoldsTheDiffuseLight) {
    const double ratio = CachedOverPerHit(
        true,
        [](const FrameBuffers& fb) {
            double sum = 0.0;
            for (const glm::vec3& c : fb.Compose()) sum += Luminance(c);
            return sum;
        },
        [](const FrameBuffers& fb) {
            for (size_t p = 0; p < fb.NumPixels(); ++p) {
                if (fb.objectId[p] != 0 && fb.objectId[p] != 2) continue;  // the diffuse objects
                EXPECT_EQ(fb.shading[p], glm::vec3(0.0f)) << p;
                EXPECT_EQ(fb.visibility[p], 1.0f) << p;
                const glm::vec3 shaded =
                    fb.albedo[p] * screen::ShadeCones(&fb.cones[p * screen::kNumCones]);
                for (int c = 0; c < 3; ++c)
                    EXPECT_NEAR(shaded[c], fb.indirect[p][c], 1e-5f * (1.0f + fb.indirect[p][c]));
            }
        });
    std::printf("composed, cached diffuse light / per hit: %.4f\n", ratio);
    EXPECT_NEAR(ratio, 1.0, 0.02);
}

// With the cache, the glossy ray's hit takes its diffuse lobe's light from the cache instead of
// a path (the hit's light sample, shadow ray and bounces), for the cache's indirect light alone
// and for all of the diffuse lobe's light (cacheDiffuseLayer). The glossy torus reflects the
// ground and the occluder: its mean `glossy` over 32 frames (4 spp, unfiltered texels chosen at
// the lobe's footprint) is within 2% of the per-hit path's (measured 1.000 and 1.006). Most of
// the torus's glossy light is the quad's and the sky's, which the ray finds directly: a cached
// term 20% low gives 0.994 and 0.946, so the test sees the all-diffuse-light case's errors.
TEST(FrameBuffers, GlossyRaysTakeTheCachedDiffuseLight) {
    for (const bool layered : {false, true}) {
        const double ratio = CachedOverPerHit(
            layered,
            [](const FrameBuffers& fb) {
                double sum = 0.0;
                for (size_t p = 0; p < fb.NumPixels(); ++p)
                    if (fb.objectId[p] == 1) sum += Luminance(fb.glossy[p]);  // the torus
                return sum;
            },
            [](const FrameBuffers&) {});
        std::printf("%s: the torus's glossy, cached / per hit: %.4f\n",
                    layered ? "all diffuse light cached" : "indirect light cached", ratio);
        EXPECT_NEAR(ratio, 1.0, 0.02) << layered;
    }
}

// Every screen-space method keeps the cached diffuse light: with texture shading the cones are NaN
// (no diffuse ray), and a cone path that took them would set indirect to 0, darkening frame 0 by
// the mean indirect buffer. Three frames of the test scene, each denoised by every method: the
// denoised indirect light on the diffuse objects keeps 60-110% of the buffer's, Reliable's frame 0
// (no history: the a-trous alone) is within 5% of the spatial filter's (measured 0-2.5%), and the
// image is finite. Two caches: the store under the preview's trivial filter (measured 61-85%:
// a moving view reads one bin a pixel, noisier than the 2x2 around it), and the grid under a
// Gaussian of radius 2 (measured 77-92%): the a-trous's edge stopping loses some of the bright
// texels' light on this small scene, the more as grazing views shade their diffuse lobe (bsdf.h),
// which puts light in silhouette pixels. The store under that Gaussian keeps under 60% in some
// frames: it bins at the hit's own texel, about a pixel here, so its first frames' bins hold a path
// or two each, and the edge stopping takes the brightest out.
TEST(FrameBuffers, EveryDenoiserKeepsTheCachedIndirectLight) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    const struct {
        TextureSamples source;
        TextureFilterKind filter;
        int radius;
    } setups[] = {{TextureSamples::Hits, TextureFilterKind::None, -1},
                  {TextureSamples::Grid, TextureFilterKind::Gaussian, 2}};
    // One BRDF table for every denoiser (each would build its own on first use).
    const auto brdf = std::make_shared<const screen::BrdfPreintegration>(256);
    for (const auto& setup : setups) {
        SCOPED_TRACE(setup.source == TextureSamples::Hits ? "store" : "grid");
        RenderOptions o = CachedFrameOptions(48, 32, setup.filter, setup.radius);
        o.texture.frameBufferSamples = setup.source;
        // Small caches: mapping and zeroing the default 2 x 64 MB would cost more than the test.
        o.texture.cache.sampleCacheBytes = o.texture.cache.texelCacheBytes = size_t(4) << 20;
        TextureSpaceCache cache(rs, o.texture);
        std::vector<FrameBuffers> frames(3);
        for (int f = 0; f < 3; ++f) {
            cache.BeginFrame(uint32_t(f));
            o.seed = uint64_t(f);
            RenderFrameBuffers(rs, o, -0.04f, &frames[size_t(f)], &cache);
        }
        double lowest = INFINITY, highest = 0.0;
        for (screen::Demodulation d : {screen::Demodulation::Off, screen::Demodulation::On}) {
            double spatialFrame0 = 0.0;
            for (screen::Method m : {screen::Method::SpatialOnly, screen::Method::Baseline,
                                     screen::Method::BaselineClamp, screen::Method::Reliable}) {
                SCOPED_TRACE(std::string(screen::MethodName(m)) +
                             (d == screen::Demodulation::On ? ", demodulated" : ""));
                screen::ScreenSpaceDenoiser denoiser({}, brdf);
                for (int f = 0; f < 3; ++f) {
                    const FrameBuffers& fb = frames[size_t(f)];
                    const std::vector<glm::vec3> image = denoiser.Denoise(fb, m, d);
                    const std::vector<glm::vec3> indirect = denoiser.Indirect();
                    ASSERT_EQ(indirect.size(), fb.NumPixels());
                    double in = 0.0, out = 0.0;
                    for (size_t p = 0; p < fb.NumPixels(); ++p) {
                        ASSERT_TRUE(Finite(image[p])) << p;
                        if (fb.objectId[p] != 0 && fb.objectId[p] != 2) continue;
                        in += Luminance(fb.indirect[p]);
                        out += Luminance(indirect[p]);
                    }
                    ASSERT_GT(in, 0.0);
                    lowest = std::min(lowest, out / in), highest = std::max(highest, out / in);
                    EXPECT_GT(out / in, 0.6) << "frame " << f;
                    EXPECT_LT(out / in, 1.1) << "frame " << f;
                    if (f == 0 && m == screen::Method::SpatialOnly) spatialFrame0 = out;
                    if (f == 0 && m == screen::Method::Reliable) {
                        EXPECT_NEAR(out / spatialFrame0, 1.0, 0.05);
                    }
                }
            }
        }
        std::printf("%s: denoised / buffer indirect light %.2f-%.2f\n",
                    setup.source == TextureSamples::Hits ? "store" : "grid", lowest, highest);
    }
}

// The cached visibility (options.texture.cachedVisibility): present only with texture shading and
// the option; NaN exactly off the diffuse objects (background, the GGX torus), in [0, 1] on them;
// its mean over 16 frames, unfiltered (1x1 texels, 4 shadow rays per sample), is near the per-hit
// visibility's expectation (a 64-spp frame buffer: the ratio estimator's mean). Pixel by pixel
// they differ where a texel straddles the occluder's shadow edge (the texel's centre is not the
// pixel's hit) and by the noise left after 16 frames: RMS difference over the diffuse pixels
// < 0.08 (measured 0.044), mean difference < 0.02 (measured 0.0006). The buffer survives the EXR
// round trip (NaN included). Bad settings (a negative visibility radius other than -1, a cache
// built without the visibility grids) are InputErrors.
TEST(FrameBuffers, CachedVisibilityNearThePerHitExpectation) {
    Scene s = TestScene();
    RenderScene rs(s, {});
    const int W = 40, H = 30;
    RenderOptions o = CachedFrameOptions(W, H, TextureFilterKind::None, 0);
    o.texture.cache.sampleCacheBytes = o.texture.cache.texelCacheBytes = size_t(4) << 20;
    FrameBuffers fb;
    RenderFrameBuffers(rs, o, -0.04f, &fb);
    EXPECT_TRUE(fb.cachedVisibility.empty()) << "without the option";
    o.texture.cachedVisibility = true;
    o.texture.enabled = false;
    RenderFrameBuffers(rs, o, -0.04f, &fb);
    EXPECT_TRUE(fb.cachedVisibility.empty()) << "without texture shading";
    o.texture.enabled = true;
    {
        TextureSpaceOptions bad = o.texture;
        bad.visibilityRadius = -2;
        EXPECT_THROW(TextureSpaceCache(rs, bad), InputError);
        // A cache built without the visibility grids cannot serve it.
        bad = o.texture;
        bad.cachedVisibility = false;
        TextureSpaceCache without(rs, bad);
        EXPECT_THROW(RenderFrameBuffers(rs, o, -0.04f, &fb, &without), InputError);
    }
    TextureSpaceCache cache(rs, o.texture);
    const size_t n = size_t(W) * H;
    std::vector<double> mean(n, 0.0);
    const int frames = 16;
    for (int f = 0; f < frames; ++f) {
        cache.BeginFrame(uint32_t(f));
        o.seed = uint64_t(f);
        RenderFrameBuffers(rs, o, -0.04f, &fb, &cache);
        ASSERT_EQ(fb.cachedVisibility.size(), n);
        for (size_t p = 0; p < n; ++p) {
            const float v = fb.cachedVisibility[p];
            const bool diffuse = fb.objectId[p] == 0 || fb.objectId[p] == 2;
            if (!diffuse) {
                ASSERT_TRUE(std::isnan(v)) << p;
                continue;
            }
            ASSERT_TRUE(v >= 0.0f && v <= 1.0f) << p << ": " << v;
            mean[p] += v / frames;
        }
    }
    const std::string path = (TempDir() / "cached_visibility.exr").string();
    WriteFrameBuffers(path, fb);
    ExpectSameBuffer(ReadFrameBuffers(path).cachedVisibility, fb.cachedVisibility,
                     "cachedVisibility");

    RenderOptions ref = FrameOptions(W, H, 99);
    ref.spp = 64;
    FrameBuffers rfb;
    RenderFrameBuffers(rs, ref, -0.04f, &rfb);
    double se = 0.0, diff = 0.0;
    int count = 0, shadowed = 0;
    for (size_t p = 0; p < n; ++p) {
        if (fb.objectId[p] != 0 && fb.objectId[p] != 2) continue;
        const double d = mean[p] - double(rfb.visibility[p]);
        se += d * d, diff += d, ++count;
        shadowed += rfb.visibility[p] < 0.5f;
    }
    ASSERT_GT(count, 500);
    ASSERT_GT(shadowed, 20);  // the occluder's shadow is in view
    std::printf("cached visibility vs per hit: RMS difference %.4f, mean difference %.4f\n",
                std::sqrt(se / count), diff / count);
    EXPECT_LT(std::sqrt(se / count), 0.08);
    EXPECT_LT(std::abs(diff / count), 0.02);
}

// `--cached-visibility` fills the frame buffers' cachedVisibility layer (finite on the diffuse
// scene's geometry; the same with 1 and 2 threads as with the default count) and runs through
// the denoiser; without texture shading or without frame buffers it is an error naming the flag
// (exit 2).
TEST(FrameBuffers, CliCachedVisibility) {
    const fs::path out = TempDir() / "cli_cached_visibility";
    fs::remove_all(out);
    const std::string scene = test::SceneDir() + "/anim_disocclusion.json";
    const std::string small = " --resolution 24x16 --sample-cache-mb 2 --texel-cache-mb 2";
    const test::CliRun r = test::Texcache("render " + scene + " --frame-buffers " + out.string() +
                                          " --shading texture --cached-visibility" + small);
    ASSERT_EQ(r.code, 0) << r.out;
    const FrameBuffers fb = ReadFrameBuffers((out / "frame_0000.exr").string());
    ASSERT_EQ(fb.cachedVisibility.size(), fb.NumPixels());
    int finite = 0;
    for (size_t p = 0; p < fb.NumPixels(); ++p) {
        if (fb.objectId[p] < 0) continue;
        ASSERT_TRUE(std::isfinite(fb.cachedVisibility[p])) << p;
        ++finite;
    }
    EXPECT_GT(finite, 100);
    // Same seed, same buffer, for any thread count (the cache samples' streams are their keys').
    for (const char* threads : {"1", "2"}) {
        const fs::path dir = out / threads;
        const test::CliRun t =
            test::Texcache("render " + scene + " --frame-buffers " + dir.string() +
                           " --shading texture --cached-visibility --threads " + threads + small);
        ASSERT_EQ(t.code, 0) << t.out;
        ExpectSameBuffer(ReadFrameBuffers((dir / "frame_0000.exr").string()).cachedVisibility,
                         fb.cachedVisibility, threads);
    }
    const test::CliRun denoised = test::Texcache(
        "render " + scene + " --denoise reliable --frames 0:1 --shading texture " +
        "--cached-visibility --visibility-radius 1 -o " + (out / "d_#.png").string() + small);
    EXPECT_EQ(denoised.code, 0) << denoised.out;
    for (const std::string& bad :
         {std::string(" --frame-buffers ") + out.string(), std::string(" --shading texture")}) {
        const test::CliRun b = test::Texcache("render " + scene + bad + " --cached-visibility" +
                                              small + " -o " + (out / "x.png").string());
        EXPECT_EQ(b.code, 2) << bad << ": " << b.out;
        EXPECT_NE(b.out.find("--cached-visibility"), std::string::npos) << b.out;
    }
}

}  // namespace
}  // namespace texcache
