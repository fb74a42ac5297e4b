// SPDX-License-Identifier: Apache-2.0
// Progressive rendering for the preview on a worker thread: the preview's rendering engine, without
// a window (apps/preview draws what it publishes; the tests drive it directly).
//
// Threading: the UI thread only posts settings and camera (Post, RequestPick)
// and reads results (WithDisplay, Stats, CopyImage); it never waits for a frame (except the
// headless mode's WaitForFrame). The worker owns the Scene, the RenderScene and the
// TextureSpaceCache; one mutex guards the posted state and the published results, and is never
// held while rendering. Every post bumps a version; a frame remembers the version it was rendered
// with, so a frame finished after a change is still shown (the view stays live) but starts a new
// accumulation instead of being averaged with stale frames.
//
// Ownership: the texture-space cache lives as long as the settings that shape it (filters, sizes,
// LOD bias, cached term); camera moves keep it, which is the point of the preview. A change of
// scene time (animation) re-poses the RenderScene and starts a cache frame (BeginFrame: every
// sample and texel re-shaded), as `texcache render --frames` does between frames; when only the
// camera is animated, shading does not change and the cache is kept, as for any camera move.
// With the stage, the cache is kept from frame to frame and refreshed progressively instead
// (TextureSpaceCache::Refresh: a part of it re-shaded each frame and blended into the texels'
// history, a running mean while the view is still); a new time at which something moved
// forgets every object's texels and history (InvalidateObject: the moved object's shadows and
// bounce light fall on the others), and a material edit in the panel the objects that use it.
//
// The screen-space stage (denoise on, or the motion-vector view): each frame renders the path
// tracer's split (RenderFrameBuffers, diffuse indirect light from the cache where texture-space
// shading is on) and one ScreenSpaceDenoiser, owned by the worker, denoises it. Its history is
// the point: it is kept while the camera orbits and while an animation plays (the previous
// frame's time is where "prev" points are moved to), and dropped when anything else changes what
// the stage sees (KeepsStageHistory). The image shown is the stage's latest output, not an
// average of frames: the stage's own temporal accumulation converges a still view.
#pragma once
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "renderer/image/image.h"
#include "renderer/preview/orbit_camera.h"
#include "renderer/render.h"
#include "renderer/scene/scene.h"
#include "screen_space/screen_denoiser.h"

namespace texcache::preview {

/// What the preview window shows. HitMiss and Overshading are heat maps of the texel-cache
/// lookups of the frame rendered after the last change (camera, settings or time); Motion shows
/// the screen-space stage's motion vectors of the last frame (PreviewSettings::motionKind) as
/// colour (MotionColour).
enum class ViewMode { Beauty, FaceId, TexelMip, Texels, HitMiss, Overshading, Motion };
constexpr int kNumViewModes = 7;
/// The panel's name of a view.
const char* ViewModeName(ViewMode m);
/// The command line's name of a view (--view), e.g. "hitmiss".
const char* ViewModeKey(ViewMode m);
/// Parses a --view name; throws InputError listing the valid names.
ViewMode ParseViewMode(const std::string& key, const std::string& where);

/// Everything the panel can change. Compared field by field to decide what to rebuild.
struct PreviewSettings {
    IntegratorKind integrator = IntegratorKind::AO;
    bool textureSpace = true;
    TextureFilterKind filter = TextureFilterKind::None;
    int radius = 0;
    FootprintMode footprint = FootprintMode::Auto;  ///< see texture_space.h
    std::vector<std::string> materialFilter;        ///< per material; "" = the default filter
    std::vector<int> materialRadius;                ///< per material; -1 = the default radius
    /// Per material, the albedo the panel set (a missing entry: the scene's own). An edit
    /// forgets the cache of the objects with that material (TextureSpaceCache::
    /// InvalidateObject) and resets the stage.
    std::vector<glm::vec3> materialAlbedo;
    float sampleCacheMb = 64.0f, texelCacheMb = 64.0f;
    float lodBias = 1.0f;
    int sppPerFrame = 1;
    int aoSamples = 32;
    float aoDistance = 1e30f;
    int maxDepth = 4;
    float tessellationRate = 2.0f;
    /// Every mesh traced as quads on its limit surface (RenderSceneOptions::tessellateAll): the
    /// surface of Embree's subdivision geometry, traced faster where a cage's faces are irregular
    /// (results/preview.md, "Limit quads"); `texcache preview` picks it where LimitQuadsFit.
    bool limitQuads = true;
    int width = 512, height = 512;
    float exposure = 0.0f;
    ViewMode view = ViewMode::Beauty;
    int maxFrames = 256;  ///< accumulation stops here (the CPU then idles)
    float time = 0.0f;    ///< scene time rendered (seconds); a change starts a cache frame
    /// Re-shade the cache on every accumulated frame of a still view (a progressive pass:
    /// fresh random numbers, jittered sample positions, smaller footprints; texture_space.h),
    /// so texture-space noise and bias converge too; off, the first frame's cache is reused
    /// and only anti-aliasing improves while still (test Preview.StillViewConverges).
    bool refineCacheWhenStill = true;
    uint64_t seed = 0;
    /// The screen-space stage on the preview's frames (see the top of this file): off, or this
    /// method, with demodulation as `texcache render --demodulate`. While it is on, frames are
    /// the path tracer's split whatever `integrator` says.
    bool denoise = false;
    screen::Method denoiseMethod = screen::Method::Reliable;
    bool demodulate = true;
    /// With the stage and texture space: the direct light's visibility cached too, taken by the
    /// stage where it has no history (TextureSpaceOptions::cachedVisibility).
    bool cachedVisibility = false;
    /// With the stage and texture space: where the frame buffers' cached diffuse light comes
    /// from (TextureSpaceOptions::frameBufferSamples: Hits, the store filled from one camera hit
    /// in fbBudget a frame, more where the store holds few samples; Grid, the paper's lazily shaded
    /// grid samples).
    TextureSamples fbCache = TextureSamples::Hits;
    int fbBudget = 8;
    /// The motion vectors the Motion view shows (the stage runs Reliable for it when off).
    screen::MotionKind motionKind = screen::MotionKind::Traditional;
    /// Stereo (renderer/texture_space/stereo.h): the beauty and debug-integrator views show both
    /// eyes side by side, the right eye from the left eye's cache, converging at the orbit's pivot;
    /// the eyes `eyeSeparation` apart (< 0: DefaultEyeSeparation of the distance to the pivot).
    /// Cache and heat views and the screen-space stage stay mono.
    bool stereo = false;
    float eyeSeparation = -1.0f;

    bool operator==(const PreviewSettings&) const = default;
};

/// The parts of the cache that the stage's frames refresh one of each (TextureSpaceCache::
/// Refresh): while the view moves each texel is re-shaded every 16 frames, so a moving view pays
/// a sixteenth of a cold frame's shading for what it already saw; while it is still, every 4,
/// so its texels have averaged about 16 estimates after 64 frames (results/preview.md).
inline uint32_t RefreshParts(bool still) {
    return still ? 4u : 16u;
}
/// Eq. 6's weight of a texel's history while the view moves (the paper's 0.7).
inline constexpr float kStageTemporalAlpha = 0.7f;

/// The texture-space cache options of the settings (filter, radius, footprint, cache sizes,
/// LOD bias, and with the stage on (denoise) a temporal history of kStageTemporalAlpha);
/// `enabled` is settings.textureSpace.
TextureSpaceOptions TextureOptionsOf(const PreviewSettings& s);

/// The screen-space stage's settings for preview frames `height` rows tall: the library's
/// defaults, with one a-trous level fewer below 720 rows (steps 1, 2, 4 of the 3x3 kernel: a
/// 15-pixel footprint instead of 31), a quarter of the stage's filtering for little error at
/// that size (`preview scenes/anim_shadow.json --bench --denoise reliable` at 640x360; the
/// figures are in results/preview.md). Two levels fewer lose visibly more.
screen::DenoiserSettings StageSettingsFor(int height);

/// Whether the screen-space stage keeps up with an interactive frame rate at width x height,
/// which the preview's default (`--denoise auto`) asks: up to twice the pixels of 640x360, where
/// the stage takes about 20 ms on 2 cores (results/screen_space_benchmark.md); it grows with
/// the pixels, and at 1280x720 it alone would be most of a 10 fps frame.
bool StageKeepsUp(int width, int height);

/// Whether the limit quads of `scene`'s subdivided meshes at its tessellation rate (about
/// rate^2 quads a cage face) stay under kMaxAutoLimitQuads: they cost ~180 bytes each up front
/// (OpenSubdiv's refinement and patches, Embree's quads and BVH), where Embree's subdivision
/// geometry costs about half of that on a huge cage (a 1,000,000-quad torus at rate 2: 1.46
/// against 0.77 GiB peak; results/large_cages.md).
bool LimitQuadsFit(const Scene& scene);
inline constexpr double kMaxAutoLimitQuads = double(1 << 20);

/// Whether the screen-space stage's history survives going from settings `a` to `b`: only what
/// moves the view along (scene time), how it is shown (exposure, view, motion kind) and the
/// accumulation cap may differ; anything else (integrator, resolution, cache, filters,
/// tessellation, method, ...) changes what the stage sees and resets it. Camera moves are not
/// settings: they keep the history.
bool KeepsStageHistory(const PreviewSettings& a, const PreviewSettings& b);

/// The names of the motion-vector kinds ("traditional, shadow, glossy, occlusion") and the kind a
/// name stands for (InputError naming `where` and the valid names otherwise).
std::string MotionKindKeys();
screen::MotionKind ParseMotionKind(const std::string& key, const std::string& where);
const char* MotionKindKey(screen::MotionKind k);

/// Whether frames with settings `s` go through the screen-space stage.
inline bool UsesStage(const PreviewSettings& s) {
    return (s.denoise && s.view == ViewMode::Beauty) || s.view == ViewMode::Motion;
}

/// Colour of a motion vector: a pixel whose history comes from `offset` pixels away (previous
/// raster position minus this pixel's centre) gets the hue of its direction (right red, down
/// yellow-green, left cyan, up blue-violet) and a saturation growing with its length, full at
/// `fullPixels`; no motion is white, no history (NaN) black.
glm::vec3 MotionColour(glm::vec2 offset, float fullPixels);

/// Statistics of the last finished frame.
struct FrameStats {
    uint64_t frameNumber = 0;  ///< frames rendered since start
    uint64_t version = 0;      ///< settings/camera version the frame was rendered with
    double seconds = 0.0;      ///< render time of the frame
    double raysPerSecond = 0.0;
    int accumulated = 0;  ///< frames averaged in the image shown
    bool textureSpace = false;
    double texelHitRate = 0.0;
    uint64_t lookups = 0, samplesShaded = 0;
    size_t cacheBytes = 0;
    size_t ptexFaces = 0;                         ///< of the meshes the scene uses
    RenderScene::TessellationStats tessellation;  ///< meshes past Embree's limits
    float time = 0.0f;                            ///< scene time of the frame
    uint32_t cacheFrame = 0;    ///< cache frames begun so far (one per time change)
    uint32_t overshadeTop = 0;  ///< Overshading view: samples per pixel at the top of the scale
    // The screen-space stage (UsesStage), when it ran on this frame:
    bool staged = false;
    int stageHistory = 0;        ///< frames in the stage's history, this one included (1: reset)
    double renderSeconds = 0.0;  ///< the frame buffers' render (the rest of `seconds` is the stage)
    screen::StageTimings stage;  ///< the stage's passes, wall-clock ms
};

class ProgressiveRenderer {
public:
    /// Starts the worker; the scene's Embree build happens there, so the window opens at once.
    ProgressiveRenderer(Scene scene, const PreviewSettings& settings, const OrbitCamera& camera);
    ~ProgressiveRenderer();
    ProgressiveRenderer(const ProgressiveRenderer&) = delete;
    ProgressiveRenderer& operator=(const ProgressiveRenderer&) = delete;

    /// Posts new settings and camera together (no frame mixes new settings with an old camera);
    /// returns the version that frames with them will carry.
    uint64_t Post(const PreviewSettings& s, const OrbitCamera& c);
    /// Asks which object is under pixel (x, y) of the image; the answer comes with PickResult().
    void RequestPick(int x, int y);
    /// The object picked by the last request (-1: nothing), and whether it is new since the last
    /// call.
    bool PickResult(int* object);

    /// Calls fn(rgba8, width, height) under the lock when a frame newer than `*seen` is ready;
    /// updates `*seen`. Returns whether fn was called.
    template <typename Fn>
    bool WithDisplay(uint64_t* seen, Fn&& fn) {
        std::lock_guard<std::mutex> lock(mutex_);
        if (stats_.frameNumber == *seen || display_.empty()) return false;
        *seen = stats_.frameNumber;
        fn(display_.data(), displayWidth_, displayHeight_);
        return true;
    }
    /// Blocks until a frame rendered with at least `version` is published (headless mode).
    /// Returns false if the worker failed (see Error()).
    bool WaitForFrame(uint64_t version);
    FrameStats Stats() const;
    /// The accumulated linear image shown (for saving).
    Image CopyImage() const;
    /// Last error (bad settings, scene build failure); empty when fine.
    std::string Error() const;
    /// True once the scene is built and the first frame is under way.
    bool Ready() const;
    /// Called after each published frame (e.g. to wake a waiting UI loop); set before frames run.
    void SetOnFrame(void (*fn)()) { onFrame_.store(fn); }

private:
    void Run();

    Scene scene_;  // worker-owned after construction (RenderScene keeps a reference to it)

    mutable std::mutex mutex_;
    std::condition_variable wake_, frameDone_;
    // Posted by the UI (under mutex_).
    PreviewSettings postedSettings_;
    OrbitCamera postedCamera_;
    uint64_t version_ = 1;
    int pickX_ = -1, pickY_ = -1;
    bool quit_ = false;
    // Published by the worker (under mutex_).
    std::vector<uint8_t> display_;
    int displayWidth_ = 0, displayHeight_ = 0;
    Image shown_;
    FrameStats stats_;
    std::string error_;
    bool ready_ = false, failed_ = false;
    int pickedObject_ = -1;
    bool pickNew_ = false;

    // Worker-only accumulation state.
    std::vector<double> accum_;
    std::atomic<void (*)()> onFrame_{nullptr};
    std::thread worker_;
};

/// Renders a debug view of the cache (mip level / texel grid) into `out` (linear RGB), one ray
/// per pixel centre; `cache` only addresses texels (nothing is shaded or stored).
void RenderCacheView(const RenderScene& rs, const TextureSpaceCache& cache, float frameTime,
                     ViewMode mode, Image* out);

/// Hit/miss colour of a pixel whose lookups hit a fraction `hit` of the time: red (all missed)
/// through yellow to green (all hit).
glm::vec3 HitMissColour(float hit);
/// Colour of a pixel whose lookups found no texel (the cache is off, or the material shades per
/// hit): neutral grey.
glm::vec3 NoLookupColour();
/// Heat ramp for t in [0, 1]: dark blue (none) through cyan, green and yellow to red (the top).
glm::vec3 HeatColour(float t);
/// Top of the overshading scale for a frame whose busiest pixel shaded `maxShaded` samples: the
/// next power of two (at least 1), so the legend stays put while the maximum wobbles.
uint32_t OvershadeTop(uint32_t maxShaded);
/// Position of a count on the log overshading scale: log(1 + n) / log(1 + top), in [0, 1].
float OvershadeScale(float samples, uint32_t top);
/// Inverse of OvershadeScale: the count at scale position t (for the legend's numbers).
float OvershadeAt(float t, uint32_t top);

/// Renders a heat map of a frame's per-pixel cache counts (HitMiss or Overshading) into `out`,
/// shaded by the view angle of a ray through each pixel centre (the geometry is traced again;
/// the cache is not touched). Returns the overshading scale's top (0 for HitMiss).
uint32_t RenderHeatView(const RenderScene& rs, float frameTime,
                        const std::vector<PixelCacheCounts>& counts, ViewMode mode, Image* out);

/// What of a scene moves over time, and the span of its keyframes (for the preview's timeline).
struct SceneAnimation {
    bool animated = false;        ///< any object, light or the camera moves
    bool cameraAnimated = false;  ///< the camera moves
    bool posesAnimated = false;   ///< an object or a light moves (shading changes over time)
    float start = 0.0f, end = 0.0f;
};
/// Looks at every keyframe track of the scene.
SceneAnimation AnimationOf(const Scene& scene);

}  // namespace texcache::preview
