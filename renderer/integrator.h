// SPDX-License-Identifier: Apache-2.0
// Image rendering: debug views, ambient occlusion, direct lighting and path tracing over a
// RenderScene, multithreaded with TBB and deterministic for a seed whatever the thread count.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "renderer/image.h"
#include "renderer/render_scene.h"
#include "renderer/texture_space.h"

namespace texcache {

enum class IntegratorKind { Normal, Ptex, Uv, EyeLight, AO, Direct, Path };

/// Parses an integrator name; throws InputError listing the valid names.
IntegratorKind ParseIntegrator(const std::string& name, const std::string& where);
/// Valid integrator names, comma separated (for help texts).
const char* IntegratorNames();
/// Whether an integrator needs lights (environment, area, distant) to be built.
bool IntegratorUsesLights(IntegratorKind k);

/// Extra per-pixel layers written beside the beauty image; none are allocated unless asked for.
struct AovFlags {
    bool albedo = false, normal = false, depth = false, ptex = false, motion = false;
    bool Any() const { return albedo || normal || depth || ptex || motion; }
};

/// One pixel's texel-cache traffic in a frame (texture-space shading): what its camera samples'
/// lookups found and how many samples their misses shaded.
struct PixelCacheCounts {
    uint32_t lookups = 0, texelHits = 0, samplesShaded = 0;
};

struct RenderOptions {
    IntegratorKind integrator = IntegratorKind::Path;
    int width = 640, height = 360;
    int spp = 16;          ///< samples per pixel (a cap when seconds > 0)
    float seconds = 0.0f;  ///< time budget; 0 = render exactly spp
    uint64_t seed = 0;
    int maxDepth = 5;
    int aoSamples = 1;
    /// Direct and path integrators: light paths continued from each camera hit (splitting). With
    /// the same spp and seed, renders then share their camera rays and differ in shading only,
    /// which isolates shading error (Munkberg et al. Fig. 7 fix the primary positions likewise).
    int hitSamples = 1;
    float aoDistance = 1e30f;
    float frameTime = 0.0f;  ///< scene time at shutter open
    /// Every camera ray through its pixel's centre (no antialiasing), as the screen-space frame
    /// buffers trace them (frame_buffers_render.h): for comparing the two pixel by pixel.
    bool pixelCentre = false;
    AovFlags aovs;
    TextureSpaceOptions texture;  ///< cached AO / diffuse indirect when texture.enabled
    bool progress = true;         ///< progress bar on stderr for renders longer than a second
    /// When set, filled with width x height PixelCacheCounts of this frame's lookups (all zero
    /// without texture-space shading); null costs one predictable branch per lookup (the
    /// preview's cache heat maps).
    std::vector<PixelCacheCounts>* pixelCache = nullptr;
};

struct RenderStats {
    double seconds = 0.0;     ///< wall clock
    double cpuSeconds = 0.0;  ///< process CPU time, all threads: the work, however busy the machine
    int sppDone = 0;
    uint64_t cameraRays = 0, shadowRays = 0, bounceRays = 0;
    uint64_t TotalRays() const { return cameraRays + shadowRays + bounceRays; }
    CacheStats cache;  ///< texture-space shading only
};

struct RenderResult {
    Image beauty;                  ///< linear RGB
    std::vector<ImageLayer> aovs;  ///< only the requested layers
    RenderStats stats;
};

/// Renders one frame. Thread count is whatever the caller's TBB arena allows. With
/// options.texture.enabled, shading goes through `cache` (kept by the caller across frames), or
/// through a cache made for this frame when `cache` is null.
RenderResult Render(const RenderScene& scene, const RenderOptions& options,
                    TextureSpaceCache* cache = nullptr);

/// Seed of the random stream of (pixel, sample): identical for any thread count or pass split.
uint64_t PixelSeed(uint64_t seed, int x, int y, int width);

}  // namespace texcache
