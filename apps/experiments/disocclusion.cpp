// SPDX-License-Identifier: Apache-2.0
// `texcache experiment disocclusion`: what the texture-space cache offers the screen-space stage
// where the stage has no history (issue 21). On anim_disocclusion, the frame buffers are rendered
// with diffuse indirect light per hit (one 1-spp path) and from the cache (texel values filtered
// in texture space; with temporal accumulation, also averaged over the frames the surface was
// seen in, on the surface itself), each denoised by Reliable. A pixel is disoccluded in the
// frame where its traditional motion vector finds no history (the stage's own test); its error
// against a high-sample reference is measured in that frame and the two after it, over the
// newly disoccluded pixels only: the frames where screen-space history cannot help yet. The rows
// with cached visibility also take the direct light's visibility from the cache where the stage
// has none (FrameBuffers::cachedVisibility); each row's frame cost is the CPU time of its
// frame-buffer renders (RenderStats::cpuSeconds), in this one process.
#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <optional>
#include <span>

#include "experiment_util.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/image/image.h"
#include "renderer/render_policy.h"
#include "renderer/scene/scene_loader.h"
#include "renderer/texture_space/texture_space.h"
#include "screen_space/brdf_table.h"
#include "screen_space/screen_denoiser.h"

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
    bool cachedVisibility = false;
    int shadowSamples = TextureSpaceOptions{}.shadowSamples;        // per cached visibility sample
    int visibilityRadius = TextureSpaceOptions{}.visibilityRadius;  // -1: the object's
    std::optional<AnimationFrames> frames{};  // its scene and cache, posed frame by frame
    std::unique_ptr<screen::ScreenSpaceDenoiser> denoiser{};
    std::vector<glm::vec3> image{};
    // Squared error sums and pixel counts of the newly disoccluded pixels, k frames after.
    std::array<double, kAfter> se{}, n{};
    std::array<double, kAfter> seIndirect{}, seDirect{};
    double seDirect0 = 0.0, n0 = 0.0;  // frame 0, every geometry pixel (no history anywhere)
    std::vector<double> cpu{};         // frame-buffer render CPU seconds per frame
    Image direct0{};                   // frame 0's denoised direct light
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
    // The cached visibility's rows: the defaults (4 rays, 5x5), with temporal accumulation, one
    // ray per sample, and the footprint of the other terms (13x13) or none (1x1).
    std::array<Config, 8> configs{{
        {.name = "per hit", .cache = false, .temporalAlpha = 0.0f},
        {.name = "cache", .cache = true, .temporalAlpha = 0.0f},
        {.name = "cache, temporal 0.7", .cache = true, .temporalAlpha = 0.7f},
        {.name = "cache, indirect + visibility",
         .cache = true,
         .temporalAlpha = 0.0f,
         .cachedVisibility = true},
        {.name = "cache, indirect + visibility, temporal 0.7",
         .cache = true,
         .temporalAlpha = 0.7f,
         .cachedVisibility = true},
        {.name = "cache, indirect + visibility, 1 ray",
         .cache = true,
         .temporalAlpha = 0.0f,
         .cachedVisibility = true,
         .shadowSamples = 1},
        {.name = "cache, indirect + visibility 13x13",
         .cache = true,
         .temporalAlpha = 0.0f,
         .cachedVisibility = true,
         .visibilityRadius = -1},
        {.name = "cache, indirect + visibility 1x1",
         .cache = true,
         .temporalAlpha = 0.0f,
         .cachedVisibility = true,
         .visibilityRadius = 0},
    }};
    // Quick mode (the test's): the first four, one of each kind.
    const std::span<Config> rows(configs.data(), s.quick ? 4 : configs.size());
    for (Config& c : rows)
        c.denoiser =
            std::make_unique<screen::ScreenSpaceDenoiser>(screen::DenoiserSettings{}, brdf);

    Image refDirect0;
    for (int f = 0; f < frames; ++f) {
        const float t = AnimationFrameTime(scene.settings.time, f, kFps);
        RenderSceneOptions ro;
        ro.frameTime = t;
        RenderOptions o = BaseOptions(scene, IntegratorKind::Path, W, H);
        o.frameTime = t;
        o.spp = 1;
        o.seed = FrameSeed(scene.settings.seed, uint64_t(f));
        screen::FrameBuffers refFb;
        {
            const RenderScene rs(scene, ro);
            RenderOptions r = o;
            r.spp = refSpp;
            r.seed = o.seed ^ 0x5851F42D4C957F2Dull;
            RenderFrameBuffers(rs, r, t - 1.0f / kFps, &refFb);
        }
        const std::vector<glm::vec3> ref = refFb.Compose();
        if (f == 0) {
            std::vector<glm::vec3> direct(refFb.NumPixels());
            for (size_t p = 0; p < direct.size(); ++p)
                direct[p] = refFb.shading[p] * refFb.visibility[p];
            refDirect0 = ToImage(direct, W, H);
        }
        for (Config& c : rows) {
            if (!c.frames) {
                RenderOptions co = BaseOptions(scene, IntegratorKind::Path, W, H);
                co.spp = 1;
                co.texture.enabled = c.cache;
                co.texture.temporalAlpha = c.temporalAlpha;
                co.texture.passSpp = 0;
                co.texture.cachedVisibility = c.cachedVisibility;
                co.texture.shadowSamples = c.shadowSamples;
                co.texture.visibilityRadius = c.visibilityRadius;
                c.frames.emplace(scene, RenderSceneOptions{}, co, kFps, c.name);
            }
            AnimationFrames& posed = *c.frames;
            posed.Pose(f);
            screen::FrameBuffers fb;
            c.cpu.push_back(RenderFrameBuffers(posed.PosedScene(), posed.Options(),
                                               posed.PreviousTime(), &fb, posed.Cache())
                                .cpuSeconds);
            c.denoiser->Denoise(fb, screen::Method::Reliable, screen::Demodulation::On, &c.image);
            const std::vector<glm::vec3> indirect = c.denoiser->Indirect();
            const std::vector<float> vis = c.denoiser->Visibility();
            // Direct light: the denoised visibility times the unshadowed shading, against the
            // reference's own product.
            auto directError = [&](size_t p) {
                const glm::vec3 d = fb.shading[p] * vis[p] - refFb.shading[p] * refFb.visibility[p];
                return double(glm::dot(d, d)) / 3.0;
            };
            if (f == 0) {
                std::vector<glm::vec3> direct(fb.NumPixels());
                for (size_t p = 0; p < fb.NumPixels(); ++p) {
                    direct[p] = fb.shading[p] * vis[p];
                    if (fb.objectId[p] >= 0) c.seDirect0 += directError(p), c.n0 += 1.0;
                }
                c.direct0 = ToImage(direct, W, H);
            }
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
                    c.seDirect[size_t(k)] += directError(p);
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
        "`--temporal-alpha 0.7` the texels also average over frames). Direct light is "
        "`shading * visibility`: the visibility per hit (1 spp, denoised) in every row; in the "
        "\"indirect + visibility\" rows the frame also carries the cache's visibility "
        "(`cachedVisibility`: %d shadow rays per cache sample towards all lights, the same "
        "filter on a %dx%d footprint unless the row says otherwise), which the stage takes where "
        "its visibility has no history. RMSE over the pixels "
        "newly disoccluded in a frame (geometry without history along the traditional motion "
        "vector), in that frame (k = 0) and the next ones; direct RMSE also over every pixel of "
        "frame 0 (no history anywhere: there the cache's visibility replaces the stage's spatial "
        "filter on every diffuse pixel, shadow edges included). Frame CPU: the frame-buffer "
        "render's process CPU time, mean and standard deviation over frames 1-%d (frame 0 maps "
        "the cache's memory), all rows in this one process.\n\n"
        "| shading | pixels | RMSE k=0 | k=1 | k=2 | indirect k=0 | k=1 | k=2 | direct k=0 | k=1 "
        "| k=2 | direct, frame 0, all | frame CPU (ms) |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        name.c_str(), frames, kFps, W, H, refSpp, TextureSpaceOptions{}.shadowSamples,
        2 * TextureSpaceOptions{}.visibilityRadius + 1,
        2 * TextureSpaceOptions{}.visibilityRadius + 1, frames - 1);
    for (const Config& c : rows) {
        auto rmse = [&](const std::array<double, kAfter>& se, int k) {
            return c.n[size_t(k)] > 0 ? std::sqrt(se[size_t(k)] / c.n[size_t(k)]) : NAN;
        };
        double mean = 0.0, var = 0.0;
        const size_t m = c.cpu.size() - 1;
        for (size_t f = 1; f < c.cpu.size(); ++f) mean += c.cpu[f] / double(m);
        for (size_t f = 1; f < c.cpu.size(); ++f)
            var += (c.cpu[f] - mean) * (c.cpu[f] - mean) / double(std::max<size_t>(m - 1, 1));
        md += Format(
            "| %s | %.0f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | "
            "%.0f +- %.0f |\n",
            c.name, c.n[0], rmse(c.se, 0), rmse(c.se, 1), rmse(c.se, 2), rmse(c.seIndirect, 0),
            rmse(c.seIndirect, 1), rmse(c.seIndirect, 2), rmse(c.seDirect, 0), rmse(c.seDirect, 1),
            rmse(c.seDirect, 2), c.n0 > 0 ? std::sqrt(c.seDirect0 / c.n0) : NAN, 1e3 * mean,
            1e3 * std::sqrt(var));
    }
    // Frame 0's direct light: where the cached visibility replaces the stage's spatial filter
    // everywhere (per hit | 5x5 | 13x13, when run | reference).
    const std::string png = "disocclusion_direct_frame0.png";
    std::vector<const Image*> shown;
    std::string names;
    for (size_t r : {size_t(0), size_t(3), size_t(6)}) {
        if (r >= rows.size()) continue;
        shown.push_back(&rows[r].direct0);
        names += std::string(rows[r].name) + " | ";
    }
    shown.push_back(&refDirect0);
    WriteImage((fs::path(s.outDir) / png).string(), SideBySide(shown, Rect{0, 0, W, H}, 2));
    md += Format(
        "\n![frame 0, direct light](%s)\n\n**%s: frame 0's denoised direct light, "
        "%sreference.**\n",
        png.c_str(), png.c_str(), names.c_str());
    if (s.quick) md += "\n**Quick mode: test-size images and few frames; not for conclusions.**\n";
    WriteText((fs::path(s.outDir) / "disocclusion.md").string(), md);
    Say("wrote disocclusion.md in %s", s.outDir.c_str());
    return 0;
}

}  // namespace texcache::experiments
