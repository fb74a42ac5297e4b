// SPDX-License-Identifier: Apache-2.0
// Render policy shared by every front end (the command line, the preview, the experiments):
// what a frame of an animation is, how large the texture-space caches are when nobody says,
// how the texture-space choices left to `auto` resolve, and the stereo rig's default. The
// renderers do what RenderOptions say; these functions say what the options should be, once,
// so that the front ends agree instead of repeating (or missing) the decisions.
#pragma once
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "renderer/render.h"
#include "renderer/scene/render_scene.h"
#include "renderer/texture_space/stereo.h"
#include "renderer/texture_space/texture_space.h"

namespace texcache {

/// Scene time of frame `frame` of an animation that starts at `start` and runs at `fps`.
float AnimationFrameTime(float start, int frame, float fps);

/// The seed of frame `frame` of a series of frames rendered from `seed`: fresh noise per frame,
/// so that frames (an animation's, or the preview's accumulated ones) are independent
/// estimates; frame 0 keeps `seed`.
uint64_t FrameSeed(uint64_t seed, uint64_t frame);

/// The texture-space cache of `rs` with options `t`, its allocation failure reported as an
/// InputError naming `where` (the options that sized it) rather than as bad_alloc.
std::unique_ptr<TextureSpaceCache> MakeTextureSpaceCache(const RenderScene& rs,
                                                         const TextureSpaceOptions& t,
                                                         const std::string& where);

/// The frames of an animation rendered one after the other: each posed at its own time (the
/// RenderScene built again: objects and lights move), the texture-space cache (made on the
/// first frame when the options enable it) kept across frames and told that a frame begins
/// (its temporal history then carries over; everything else is shaded again for the new pose),
/// and each frame's options with its time and fresh noise.
class AnimationFrames {
public:
    /// Frames of `scene` rendered with `options` (its frameTime is the animation's start, its
    /// seed frame 0's) at `fps`; `sceneOptions` says what each RenderScene builds, and
    /// `cacheWhere` names the cache's sizes in an error (MakeTextureSpaceCache).
    AnimationFrames(const texcache::Scene& scene, const RenderSceneOptions& sceneOptions,
                    const RenderOptions& options, float fps, std::string cacheWhere);
    /// Poses frame `frame`; the accessors below then describe it.
    void Pose(int frame);

    const RenderScene& PosedScene() const { return *rs_; }
    const RenderOptions& Options() const { return options_; }
    RenderOptions& Options() { return options_; }
    /// The cache kept across frames, or null without texture-space shading.
    TextureSpaceCache* Cache() const { return cache_.get(); }
    /// The scene time of the frame before the posed one (screen-space buffers' "prev" points).
    float PreviousTime() const { return options_.frameTime - 1.0f / fps_; }

private:
    const Scene& scene_;
    RenderSceneOptions sceneOptions_;
    const RenderOptions base_;
    const float fps_;
    const std::string cacheWhere_;
    std::optional<RenderScene> rs_;
    std::unique_ptr<TextureSpaceCache> cache_;
    RenderOptions options_;
};

/// Which cache sizes the caller set itself (kept as they are); the others are sized to the frame.
struct GivenCacheSizes {
    bool sample = false, texel = false;
};

/// Sizes the texture-space caches of a render of `opt` (`views` images: 2 for stereo) that the
/// caller did not set (SizeCachesToFrame; a second term per texel with cached visibility counts
/// as a second view; shading at the hits, which never fills them, gets a token 64 KiB each), and
/// checks that both fit in this machine's memory: the caches are allocated and zeroed up front,
/// and a size the machine cannot hold would end in bad_alloc or the OOM killer mid-render.
/// Throws InputError naming `where` when they do not fit. Nothing to do without texture-space
/// shading or with unbounded (reference) caches.
void SizeTextureCaches(RenderOptions* opt, int views, GivenCacheSizes given,
                       const std::string& where);

/// Throws InputError naming `where` when the eyes of `rig` are so far apart for its convergence
/// distance (more than 100 times) that their sheared frustums look away from each other: past
/// that the camera's ray directions lose their precision and then overflow.
void CheckStereoShear(const StereoRig& rig, const std::string& where);

/// This machine's physical memory in MiB.
double PhysicalMemoryMiB();

/// The memory one run may take, in MiB: `givenMiB` (--max-memory-mb) when positive, else the
/// TEXCACHE_MAX_MEMORY_MB environment variable when set (tests use it to refuse without
/// allocating), else 2048; never more than the memory available now (MemAvailable). A render
/// past that either pages the machine to a halt or is killed by the OOM killer long into its
/// run, so it is refused before it starts.
double MemoryBudgetMiB(double givenMiB);

/// The peak memory in MiB a render of `opt` over `views` images (2 for stereo) is expected to
/// take: its image buffers (the film, the tone-mapped copy and the file's buffers per pixel,
/// each AOV layer on top, the screen-space stage's buffers when `frameBuffers`) and its caches.
double RenderMemoryMiB(const RenderOptions& opt, int views, bool frameBuffers);

/// Throws InputError naming `where` when `needMiB` is more than `budgetMiB`, in one line saying
/// how much it would need (`what`: what takes it) and how to allow it (`allow` followed by the
/// MiB needed: "--max-memory-mb ", or "TEXCACHE_MAX_MEMORY_MB=" for commands without it).
void CheckMemoryBudget(double needMiB, double budgetMiB, const std::string& what,
                       const std::string& where,
                       const std::string& allow = "TEXCACHE_MAX_MEMORY_MB=");

/// RenderMemoryMiB checked against `budgetMiB`, naming the caches' options when they take most
/// of it and `resolution` otherwise.
void CheckRenderMemory(const RenderOptions& opt, int views, bool frameBuffers, double budgetMiB);

/// --ts-samples auto: where texture-space shading samples unless the caller asked for
/// something only the grid has (`gridAsked`: a filter, a filter radius, footprints, temporal
/// accumulation, stereo, the grid caches' sizes or modes): at the camera's hits, which reach a
/// lower error at equal time for AO and diffuse light (results/speed_vs_error.md).
TextureSamples AutoTextureSamples(bool gridAsked);

/// Which diffuse light the path (and direct) integrator caches in texture space: indirect only
/// (direct light stays per hit), all of it, or Auto (CachedDirectLight).
enum class CachedLight { Auto, All, Indirect };
/// "auto", "all" or "indirect"; throws InputError naming `where` and the valid names otherwise.
CachedLight ParseCachedLight(const std::string& name, const std::string& where);

/// The kinds of light a scene has: soft (an environment, quad lights, point and spot lights with
/// a radius, distant lights with an angular size, emissive objects: their shadows have
/// penumbrae) and delta (point and spot lights without a radius, distant lights without an
/// angular size: their shadows are sharp).
struct LightKinds {
    bool soft = false, delta = false;
};
LightKinds SceneLightKinds(const Scene& scene);

/// TextureSpaceOptions::cacheDirect and deltaDirectPerHit.
struct CachedDirect {
    bool cacheDirect = false, deltaDirectPerHit = false;
};
/// The direct light cached for `choice` on a scene with `kinds` of light shaded on `samples`.
/// All caches every light's; Indirect none. Auto caches, at the hits, the direct light of soft
/// lights and keeps delta lights' per hit (soft lights: all their light cached; delta lights:
/// their indirect light only): a bin averages a few texels, which costs a soft light's smooth
/// penumbrae nothing while its noise falls, and beats per-hit direct light at equal time, but
/// would blur a delta light's sharp shadow edge, which is noise-free per hit anyway (one
/// shadow ray). On the grid Auto caches no direct light: its filters would blur every shadow
/// (TextureSpaceOptions::cacheDirect).
CachedDirect CachedDirectLight(CachedLight choice, LightKinds kinds, TextureSamples samples);

/// Throws InputError naming the scene file and the material when a material's "filter" cannot
/// apply to the render `opt` describes (texture space with the ao, direct or path integrator).
/// softshadow filters area-light visibility, which only the direct integrator caches, and only
/// on the grid: the bins at the hits hold no occluder distances. The other filters filter
/// cached AO or light: the direct integrator caches its light only at the hits (its grid
/// caches the visibility softshadow filters, and shades everything else per hit).
void CheckMaterialFilters(const Scene& scene, const RenderOptions& opt);

}  // namespace texcache
