// SPDX-License-Identifier: Apache-2.0
// Progressive rendering for the preview on a worker thread.
//
// Threading: the UI thread only posts settings and camera (SetSettings, SetCamera, RequestPick)
// and reads results (WithDisplay, Stats, CopyImage); it never waits for a frame (except the
// headless mode's WaitForFrame). The worker owns the Scene, the RenderScene and the
// TextureSpaceCache; one mutex guards the posted state and the published results, and is never
// held while rendering. Every post bumps a version; a frame remembers the version it was rendered
// with, so a frame finished after a change is still shown (the view stays live) but starts a new
// accumulation instead of being averaged with stale frames.
//
// Ownership: the texture-space cache lives as long as the settings that shape it (filters, sizes,
// LOD bias, cached term); camera moves keep it, which is the point of the preview.
#pragma once
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "orbit_camera.h"
#include "renderer/image.h"
#include "renderer/integrator.h"
#include "renderer/scene.h"

namespace texcache::preview {

/// What the preview window shows.
enum class ViewMode { Beauty, FaceId, TexelMip, Texels };
const char* ViewModeName(ViewMode m);

/// Everything the panel can change. Compared field by field to decide what to rebuild.
struct PreviewSettings {
    IntegratorKind integrator = IntegratorKind::AO;
    bool textureSpace = true;
    TextureFilterKind filter = TextureFilterKind::None;
    int radius = 0;
    std::vector<std::string> materialFilter;  ///< per material; "" = the default filter
    std::vector<int> materialRadius;          ///< per material; -1 = the default radius
    float sampleCacheMb = 64.0f, texelCacheMb = 64.0f;
    float lodBias = 1.0f;
    int sppPerFrame = 1;
    int aoSamples = 32;
    float aoDistance = 1e30f;
    int maxDepth = 4;
    float tessellationRate = 2.0f;
    int width = 512, height = 512;
    float exposure = 0.0f;
    ViewMode view = ViewMode::Beauty;
    int maxFrames = 256;  ///< accumulation stops here (the CPU then idles)
    /// Re-shade the cache on every accumulated frame of a still view, so texture-space noise
    /// converges too (otherwise only anti-aliasing improves while still).
    bool refineCacheWhenStill = false;
    uint64_t seed = 0;

    bool operator==(const PreviewSettings&) const = default;
};

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
};

class ProgressiveRenderer {
public:
    /// Starts the worker; the scene's Embree build happens there, so the window opens at once.
    ProgressiveRenderer(Scene scene, const PreviewSettings& settings, const OrbitCamera& camera);
    ~ProgressiveRenderer();
    ProgressiveRenderer(const ProgressiveRenderer&) = delete;
    ProgressiveRenderer& operator=(const ProgressiveRenderer&) = delete;

    /// Posts new settings / camera; returns the version that frames with them will carry.
    uint64_t SetSettings(const PreviewSettings& s);
    uint64_t SetCamera(const OrbitCamera& c);
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

}  // namespace texcache::preview
