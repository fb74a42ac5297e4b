// SPDX-License-Identifier: Apache-2.0
#include "progressive_renderer.h"

#include <algorithm>
#include <chrono>
#include <climits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/camera.h"
#include "renderer/render_scene.h"
#include "renderer/texture_space.h"

namespace texcache::preview {

namespace {

bool CachedIntegrator(IntegratorKind k) {
    return k == IntegratorKind::AO || k == IntegratorKind::Path;
}

/// Settings that change what the cache holds: any difference needs a fresh cache.
bool SameCacheContents(const PreviewSettings& a, const PreviewSettings& b) {
    return a.integrator == b.integrator && a.filter == b.filter && a.radius == b.radius &&
           a.materialFilter == b.materialFilter && a.materialRadius == b.materialRadius &&
           a.sampleCacheMb == b.sampleCacheMb && a.texelCacheMb == b.texelCacheMb &&
           a.lodBias == b.lodBias && a.aoSamples == b.aoSamples && a.aoDistance == b.aoDistance &&
           a.maxDepth == b.maxDepth && a.tessellationRate == b.tessellationRate;
}

/// Settings that change the picture (exposure and the accumulation cap do not).
bool SameImage(const PreviewSettings& a, const PreviewSettings& b) {
    PreviewSettings x = a, y = b;
    x.exposure = y.exposure = 0.0f;
    x.maxFrames = y.maxFrames = 0;
    return x == y;
}

TextureSpaceOptions TextureOptions(const PreviewSettings& s) {
    TextureSpaceOptions t;
    t.enabled = s.textureSpace;
    t.filter = s.filter;
    t.radius = s.radius;
    t.cache.sampleCacheBytes = size_t(double(s.sampleCacheMb) * (1 << 20));
    t.cache.texelCacheBytes = size_t(double(s.texelCacheMb) * (1 << 20));
    t.cache.lodBias = s.lodBias;
    t.cache.Validate();
    return t;
}

glm::vec3 HashColour(uint64_t h) {
    h ^= h >> 33;
    h *= 0xff51afd7ed558ccdull;
    h ^= h >> 33;
    h *= 0xc4ceb9fe1a85ec53ull;
    h ^= h >> 33;
    return glm::vec3(float(h & 255), float((h >> 8) & 255), float((h >> 16) & 255)) / 255.0f;
}

/// Blue (fine, mip 0) to red (coarse, mip 8+), so the eq. 1 level bands are easy to read.
glm::vec3 MipColour(int mip) {
    const float t = std::clamp(float(mip) / 8.0f, 0.0f, 1.0f);
    return glm::vec3(t, 1.0f - std::abs(2.0f * t - 1.0f), 1.0f - t);
}

}  // namespace

const char* ViewModeName(ViewMode m) {
    switch (m) {
        case ViewMode::Beauty:
            return "beauty";
        case ViewMode::FaceId:
            return "face id (ptex)";
        case ViewMode::TexelMip:
            return "texel mip level";
        case ViewMode::Texels:
            return "cache texels";
    }
    return "?";
}

void RenderCacheView(const RenderScene& rs, const TextureSpaceCache& cache, float frameTime,
                     ViewMode mode, Image* out) {
    const CameraModel camera(rs.scene().camera, frameTime, out->width, out->height);
    tbb::parallel_for(0, out->height, [&](int y) {
        for (int x = 0; x < out->width; ++x) {
            float* px = out->At(x, y);
            RayDifferentials diff;
            const Ray ray =
                camera.Generate(float(x) + 0.5f, float(y) + 0.5f, glm::vec2(0.5f), &diff);
            Hit hit;
            glm::vec3 c(0.0f);
            if (rs.Intersect(ray, &hit) && hit.object >= 0) {
                const SurfaceInteraction si = rs.Interact(ray, hit, &diff);
                const SampleRequest r = cache.cache().TexelAt(
                    {cache.MeshOf(si.object, si.backFacing), si.ptex.face, si.ptex.u, si.ptex.v,
                     si.dudx, si.dvdx, si.dudy, si.dvdy});
                // Shaded by the view angle so the shape stays readable under the false colour.
                const float shade = 0.35f + 0.65f * std::abs(glm::dot(si.N, ray.dir));
                c = shade *
                    (mode == ViewMode::TexelMip ? MipColour(r.mip) : HashColour(r.key.Pack()));
            }
            px[0] = c.x, px[1] = c.y, px[2] = c.z;
        }
    });
}

ProgressiveRenderer::ProgressiveRenderer(Scene scene, const PreviewSettings& settings,
                                         const OrbitCamera& camera)
    : scene_(std::move(scene)), postedSettings_(settings), postedCamera_(camera) {
    worker_ = std::thread([this] { Run(); });
}

ProgressiveRenderer::~ProgressiveRenderer() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        quit_ = true;
    }
    wake_.notify_all();
    worker_.join();
}

uint64_t ProgressiveRenderer::SetSettings(const PreviewSettings& s) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (s == postedSettings_) return version_;
    postedSettings_ = s;
    wake_.notify_all();
    return ++version_;
}

uint64_t ProgressiveRenderer::SetCamera(const OrbitCamera& c) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (c == postedCamera_) return version_;
    postedCamera_ = c;
    wake_.notify_all();
    return ++version_;
}

void ProgressiveRenderer::RequestPick(int x, int y) {
    std::lock_guard<std::mutex> lock(mutex_);
    pickX_ = x, pickY_ = y;
    wake_.notify_all();
}

bool ProgressiveRenderer::PickResult(int* object) {
    std::lock_guard<std::mutex> lock(mutex_);
    *object = pickedObject_;
    const bool fresh = pickNew_;
    pickNew_ = false;
    return fresh;
}

bool ProgressiveRenderer::WaitForFrame(uint64_t version) {
    std::unique_lock<std::mutex> lock(mutex_);
    frameDone_.wait(lock, [&] { return failed_ || stats_.version >= version; });
    return !failed_;
}

FrameStats ProgressiveRenderer::Stats() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return stats_;
}

Image ProgressiveRenderer::CopyImage() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return shown_;
}

std::string ProgressiveRenderer::Error() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return error_;
}

bool ProgressiveRenderer::Ready() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return ready_;
}

void ProgressiveRenderer::Run() {
    std::unique_ptr<RenderScene> rs;
    std::unique_ptr<TextureSpaceCache> cache;
    PreviewSettings built, accumSettings;
    OrbitCamera accumCamera;
    int accumulated = 0;
    float shownExposure = 0.0f;
    // Worker-side buffers, swapped with the published ones (no allocation per frame once sized).
    std::vector<uint8_t> display;
    Image mean;

    // Tone-maps `mean` and publishes it with the frame's statistics (null: keep the last ones).
    auto publish = [&](const PreviewSettings& cur, uint64_t version, const FrameStats* frame) {
        display.resize(mean.NumPixels() * 4);
        const float scale = std::exp2(cur.exposure);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, mean.NumPixels(), 4096), [&](auto r) {
            for (size_t p = r.begin(); p < r.end(); ++p) {
                for (int k = 0; k < 3; ++k)
                    display[4 * p + k] = LinearToSrgb8(mean.data[3 * p + k] * scale);
                display[4 * p + 3] = 255;
            }
        });
        shownExposure = cur.exposure;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            display_.swap(display);
            displayWidth_ = mean.width, displayHeight_ = mean.height;
            shown_.width = mean.width, shown_.height = mean.height, shown_.channels = 3;
            shown_.data.assign(mean.data.begin(), mean.data.end());
            const uint64_t number = stats_.frameNumber + 1;
            if (frame) stats_ = *frame;
            stats_.frameNumber = number;
            stats_.version = version;
            error_.clear();
        }
        frameDone_.notify_all();
        if (void (*fn)() = onFrame_.load()) fn();
    };

    for (;;) {
        PreviewSettings cur;
        OrbitCamera cam;
        uint64_t version;
        int pickX = -1, pickY = -1;
        {
            std::unique_lock<std::mutex> lock(mutex_);
            wake_.wait(lock, [&] {
                const bool changed = !rs || !SameImage(postedSettings_, accumSettings) ||
                                     !(postedCamera_ == accumCamera);
                return quit_ || changed || pickX_ >= 0 || accumulated < postedSettings_.maxFrames ||
                       postedSettings_.exposure != shownExposure;
            });
            if (quit_) return;
            cur = postedSettings_, cam = postedCamera_, version = version_;
            std::swap(pickX, pickX_), std::swap(pickY, pickY_);
        }
        try {
            const float frameTime = scene_.settings.time;
            if (!rs || cur.tessellationRate != built.tessellationRate) {
                cache.reset();
                rs.reset();
                scene_.settings.tessellationRate = cur.tessellationRate;
                RenderSceneOptions ro;
                ro.frameTime = frameTime;
                // Lights always: the integrator can be switched to direct/path at any time.
                rs = std::make_unique<RenderScene>(scene_, ro);
                built.tessellationRate = cur.tessellationRate;
                std::lock_guard<std::mutex> lock(mutex_);
                ready_ = true;
            }
            cam.ToCamera(&scene_.camera);

            if (pickX >= 0) {
                const CameraModel model(scene_.camera, frameTime, cur.width, cur.height);
                const Ray ray = model.Generate(float(pickX) + 0.5f, float(pickY) + 0.5f,
                                               glm::vec2(0.5f), nullptr);
                Hit hit;
                const int object = rs->Intersect(ray, &hit) ? hit.object : -1;
                std::lock_guard<std::mutex> lock(mutex_);
                pickedObject_ = object, pickNew_ = true;
            }

            const bool imageChanged = !SameImage(cur, accumSettings) || !(cam == accumCamera);
            if (!imageChanged && accumulated >= cur.maxFrames) {
                // Nothing to render: a pick, or an exposure change to re-tone-map.
                if (cur.exposure != shownExposure && mean.width > 0) publish(cur, version, nullptr);
                shownExposure = cur.exposure;
                continue;
            }

            const bool cacheView = cur.view == ViewMode::TexelMip || cur.view == ViewMode::Texels;
            const bool wantCache =
                (cur.textureSpace && CachedIntegrator(cur.integrator)) || cacheView;
            if (wantCache && (!cache || !SameCacheContents(cur, built))) {
                cache.reset();  // free the old slots before allocating new ones
                for (size_t m = 0; m < scene_.materials.size(); ++m) {
                    scene_.materials[m].cacheFilter =
                        m < cur.materialFilter.size() ? cur.materialFilter[m] : "";
                    scene_.materials[m].cacheRadius =
                        m < cur.materialRadius.size() ? cur.materialRadius[m] : -1;
                }
                cache = std::make_unique<TextureSpaceCache>(*rs, TextureOptions(cur));
                built = cur;
            }

            if (imageChanged) {
                accumulated = 0;
                accumSettings = cur, accumCamera = cam;
                accum_.assign(size_t(cur.width) * cur.height * 3, 0.0);
            }
            if (mean.width != cur.width || mean.height != cur.height)
                mean = Image(cur.width, cur.height, 3);
            FrameStats frame;
            const auto t0 = std::chrono::steady_clock::now();
            if (cacheView) {
                // Deterministic: one frame says everything.
                RenderCacheView(*rs, *cache, frameTime, cur.view, &mean);
                accumulated = INT_MAX;
            } else {
                RenderOptions opt;
                opt.integrator =
                    cur.view == ViewMode::FaceId ? IntegratorKind::Ptex : cur.integrator;
                opt.width = cur.width, opt.height = cur.height;
                opt.spp = cur.sppPerFrame;
                // A new seed per accumulated frame: frames are independent estimates.
                opt.seed = cur.seed + uint64_t(accumulated) * 0x9E3779B9ull;
                opt.maxDepth = cur.maxDepth;
                opt.aoSamples = cur.aoSamples;
                opt.aoDistance = cur.aoDistance;
                opt.frameTime = frameTime;
                opt.progress = false;
                opt.texture = cache ? cache->options() : TextureOptions(cur);
                opt.texture.enabled = cur.textureSpace && cache != nullptr;
                if (cur.refineCacheWhenStill && accumulated > 0 && opt.texture.enabled)
                    cache->cache().InvalidateAll();
                const RenderResult r =
                    Render(*rs, opt, opt.texture.enabled ? cache.get() : nullptr);
                ++accumulated;
                const double inv = 1.0 / double(accumulated);
                tbb::parallel_for(tbb::blocked_range<size_t>(0, accum_.size(), 16384),
                                  [&](auto range) {
                                      for (size_t i = range.begin(); i < range.end(); ++i) {
                                          accum_[i] += double(r.beauty.data[i]);
                                          mean.data[i] = float(accum_[i] * inv);
                                      }
                                  });
                frame.raysPerSecond =
                    r.stats.seconds > 0.0 ? double(r.stats.TotalRays()) / r.stats.seconds : 0.0;
                frame.textureSpace = opt.texture.enabled && CachedIntegrator(opt.integrator);
                frame.texelHitRate = r.stats.cache.TexelHitRate();
                frame.lookups = r.stats.cache.lookups;
                frame.samplesShaded = r.stats.cache.samplesShaded;
            }
            frame.seconds =
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            frame.accumulated = accumulated == INT_MAX ? 1 : accumulated;
            frame.cacheBytes = cache ? cache->cache().BytesUsed() : 0;
            publish(cur, version, &frame);
        } catch (const std::exception& e) {
            std::lock_guard<std::mutex> lock(mutex_);
            error_ = e.what();
            if (!rs) failed_ = true;  // no scene: nothing will ever render
            // Wait for the next change instead of retrying the same bad settings.
            accumSettings = cur, accumCamera = cam, accumulated = INT_MAX;
            shownExposure = cur.exposure;
            stats_.version = version;
            frameDone_.notify_all();
            if (failed_) return;
        }
    }
}

}  // namespace texcache::preview
