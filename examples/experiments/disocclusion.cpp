// SPDX-License-Identifier: Apache-2.0
// `texcache experiment disocclusion`: what the texture-space cache offers the screen-space stage
// where the stage has no history (issue 21). On anim_disocclusion, the frame buffers are rendered
// with diffuse indirect light per hit (one 1-spp path) and from the cache (texel values filtered
// in texture space; with temporal accumulation, also averaged over the frames the surface was
// seen in, on the surface itself), each denoised by Reliable. A pixel is disoccluded in the
// frame where its traditional motion vector finds no history (the stage's own test); its error
// against a high-sample reference is measured in that frame and the two after it, over the
// newly disoccluded pixels only: the frames where screen-space history cannot help yet.
#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <optional>

#include "experiment_util.h"
#include "filters/screen_space/brdf_table.h"
#include "filters/screen_space/screen_denoiser.h"
#include "renderer/frame_buffers_render.h"
#include "renderer/scene_loader.h"
#include "renderer/texture_space.h"

namespace texcache::experiments {

namespace {

namespace fs = std::filesystem;

constexpr float kFps = 24.0f;
constexpr int kAfter = 3;  // frames measured after a pixel appears (the frame itself included)

/// One way of rendering and denoising the sequence.
struct Config {
    const char* name;
    bool cache;
    float temporalAlpha;
    std::optional<RenderScene> rs{};  // re-posed per frame in place (the cache refers to it)
    std::unique_ptr<TextureSpaceCache> tsc{};
    std::unique_ptr<screen::ScreenSpaceDenoiser> denoiser{};
    std::vector<glm::vec3> image{};
    // Squared error sums and pixel counts of the newly disoccluded pixels, k frames after.
    std::array<double, kAfter> se{}, n{};
    std::array<double, kAfter> seIndirect{};
    std::vector<std::vector<uint8_t>> masks{};  // per frame: newly disoccluded pixels
};

}  // namespace

int Disocclusion(const Setup& s) {
    const std::string name = "anim_disocclusion";
    // Full size: what runs in about ten minutes on the shared 2-core machine (the references
    // are most of it).
    const int W = s.quick ? 96 : 160, H = s.quick ? 54 : 90;
    const int frames = s.quick ? 4 : 12;
    const int refSpp = s.quick ? 16 : 32;
    std::vector<std::string> warnings;
    const Scene scene = LoadScene((fs::path(s.scenesDir) / (name + ".json")).string(), &warnings);
    Say("[disocclusion] %s: %d frames at %.0f fps, %dx%d, reference %d spp", name.c_str(), frames,
        kFps, W, H, refSpp);
    const auto brdf = std::make_shared<const screen::BrdfPreintegration>();
    std::array<Config, 3> configs{
        {{"per hit", false, 0.0f}, {"cache", true, 0.0f}, {"cache, temporal 0.7", true, 0.7f}}};
    for (Config& c : configs)
        c.denoiser =
            std::make_unique<screen::ScreenSpaceDenoiser>(screen::DenoiserSettings{}, brdf);

    for (int f = 0; f < frames; ++f) {
        const float t = scene.settings.time + float(f) / kFps;
        RenderSceneOptions ro;
        ro.frameTime = t;
        RenderOptions o = BaseOptions(scene, IntegratorKind::Path, W, H);
        o.frameTime = t;
        o.spp = 1;
        o.seed = scene.settings.seed + uint64_t(f) * 0x9E3779B9ull;
        screen::FrameBuffers refFb;
        {
            const RenderScene rs(scene, ro);
            RenderOptions r = o;
            r.spp = refSpp;
            r.seed = o.seed ^ 0x5851F42D4C957F2Dull;
            RenderFrameBuffers(rs, r, t - 1.0f / kFps, &refFb);
        }
        const std::vector<glm::vec3> ref = refFb.Compose();
        for (Config& c : configs) {
            c.rs.emplace(scene, ro);
            RenderOptions co = o;
            co.texture.enabled = c.cache;
            co.texture.temporalAlpha = c.temporalAlpha;
            co.texture.passSpp = 0;
            if (c.cache && !c.tsc) c.tsc = std::make_unique<TextureSpaceCache>(*c.rs, co.texture);
            if (c.tsc) c.tsc->BeginFrame(uint32_t(f));
            screen::FrameBuffers fb;
            RenderFrameBuffers(*c.rs, co, t - 1.0f / kFps, &fb, c.tsc.get());
            c.denoiser->Denoise(fb, screen::Method::Reliable, screen::Demodulation::On, &c.image);
            const std::vector<glm::vec3> indirect = c.denoiser->Indirect();
            // Newly disoccluded: geometry, but no history along the traditional vector (frame 0
            // has no history anywhere: not a disocclusion).
            const std::vector<glm::vec2> from =
                c.denoiser->LastMotion(screen::MotionKind::Traditional);
            std::vector<uint8_t>& mask = c.masks.emplace_back(fb.NumPixels(), 0);
            for (size_t p = 0; p < fb.NumPixels(); ++p)
                mask[p] = f > 0 && fb.objectId[p] >= 0 && !std::isfinite(from[p].x);
            for (int k = 0; k < kAfter && k <= f; ++k) {
                const std::vector<uint8_t>& m = c.masks[size_t(f - k)];
                for (size_t p = 0; p < fb.NumPixels(); ++p) {
                    if (!m[p]) continue;
                    const glm::vec3 d = c.image[p] - ref[p];
                    const glm::vec3 di =
                        (indirect.empty() ? glm::vec3(0.0f) : indirect[p]) - refFb.indirect[p];
                    c.se[size_t(k)] += double(glm::dot(d, d)) / 3.0;
                    c.seIndirect[size_t(k)] += double(glm::dot(di, di)) / 3.0;
                    c.n[size_t(k)] += 1.0;
                }
            }
        }
        Say("  frame %2d (t = %.3f)", f, t);
    }

    std::string md = Format(
        "# Disocclusions from the texture-space cache\n\n%s, %d frames at %.0f fps, %dx%d, 1 "
        "spp, Reliable with demodulation; reference %d spp, composed. Diffuse indirect light per "
        "hit (one path) or from the cache (default filter, footprint all, one pass; with "
        "`--temporal-alpha 0.7` the texels also average over frames). Direct and glossy light "
        "are per hit in every row (the split needs the shadow ray). RMSE over the pixels newly "
        "disoccluded in a frame (geometry without history along the traditional motion vector), "
        "in that frame (k = 0) and the next ones.\n\n"
        "| indirect light | pixels | RMSE k=0 | k=1 | k=2 | indirect RMSE k=0 | k=1 | k=2 |\n"
        "|---|---|---|---|---|---|---|---|\n",
        name.c_str(), frames, kFps, W, H, refSpp);
    for (const Config& c : configs) {
        auto rmse = [&](const std::array<double, kAfter>& se, int k) {
            return c.n[size_t(k)] > 0 ? std::sqrt(se[size_t(k)] / c.n[size_t(k)]) : NAN;
        };
        md += Format("| %s | %.0f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f |\n", c.name, c.n[0],
                     rmse(c.se, 0), rmse(c.se, 1), rmse(c.se, 2), rmse(c.seIndirect, 0),
                     rmse(c.seIndirect, 1), rmse(c.seIndirect, 2));
    }
    if (s.quick) md += "\n**Quick mode: test-size images and few frames; not for conclusions.**\n";
    WriteText((fs::path(s.outDir) / "disocclusion.md").string(), md);
    Say("wrote disocclusion.md in %s", s.outDir.c_str());
    return 0;
}

}  // namespace texcache::experiments
