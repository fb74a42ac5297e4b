// SPDX-License-Identifier: Apache-2.0
// Image rendering: debug views, ambient occlusion, direct lighting and path tracing over a
// RenderScene, multithreaded with TBB and deterministic for a seed whatever the thread count.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "renderer/image/image.h"
#include "renderer/integrators/integrator_kind.h"
#include "renderer/integrators/sampling.h"
#include "renderer/scene/render_scene.h"
#include "renderer/texture_space/texture_space.h"

namespace texcache {

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

/// Both eyes of a stereo render shading at the camera's hits (options differing in the eye only)
/// through one store: each pass bins both eyes' hits together and reads each eye back from the
/// shared bins (stereo.h). Throws InputError unless texture space shades at the hits.
void RenderEyesAtHits(const RenderScene& scene, const RenderOptions& left,
                      const RenderOptions& right, TextureSpaceCache* cache, RenderResult* leftOut,
                      RenderResult* rightOut);

/// The rays a per-hit AO render with `options` traces (integrator AO, no texture space), in
/// pixel order, the same rays bit for bit: each camera ray, and after it the AO rays of its hit
/// (none for a miss or a light). For `texcache bench rays`, whose raw Embree loop must trace what
/// the integrator traces.
void RecordAoRays(const RenderScene& scene, const RenderOptions& options, std::vector<Ray>* camera,
                  std::vector<Ray>* occlusion);

/// Seed of the random stream of (pixel, sample): identical for any thread count or pass split.
/// Inline: every camera sample of every renderer starts from it.
inline uint64_t PixelSeed(uint64_t seed, int x, int y, int width) {
    return MixBits(seed * 0x9E3779B97F4A7C15ull + uint64_t(y) * uint64_t(width) + uint64_t(x));
}

namespace internal {
/// What a progressive texture-space render with a time budget does after a pass (Render's
/// loop): another pass of fresh shading; camera samples against the last pass's cache, one per
/// pixel at a time (Extend); or nothing. `left` is the budget left, `lastTime` and `lastSpp`
/// the time and camera samples of the pass just done, `passesRun` how many ran so far (all of
/// them full passes unless `extending`).
enum class BudgetStep { Stop, Pass, Extend };
BudgetStep NextBudgetStep(bool extending, int passesRun, double left, double lastTime, int lastSpp);
}  // namespace internal

}  // namespace texcache
