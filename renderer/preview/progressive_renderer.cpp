// SPDX-License-Identifier: Apache-2.0
#include "renderer/preview/progressive_renderer.h"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/render_policy.h"
#include "renderer/scene/camera.h"
#include "renderer/scene/render_scene.h"
#include "renderer/texture_space/stereo.h"
#include "renderer/texture_space/texture_space.h"
#include "texcache/enum_names.h"
#include "texcache/error.h"

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
           a.maxDepth == b.maxDepth && a.tessellationRate == b.tessellationRate &&
           a.limitQuads == b.limitQuads && a.cachedVisibility == b.cachedVisibility &&
           a.denoise == b.denoise && a.fbCache == b.fbCache && a.fbBudget == b.fbBudget;
}

/// Whether anything of the scene at time `a` is elsewhere at time `b`: per object, and whether a
/// light moved.
std::vector<char> MovedObjects(const Scene& scene, float a, float b, bool* lightMoved) {
    std::vector<char> moved(scene.objects.size(), 0);
    for (size_t o = 0; o < moved.size(); ++o) {
        const TransformTrack& t = scene.objects[o].transform;
        moved[o] = t.MovesBetween(a, b);
    }
    *lightMoved = false;
    auto check = [&](const TransformTrack& t) { *lightMoved |= t.MovesBetween(a, b); };
    for (const QuadLight& l : scene.quadLights) check(l.transform);
    for (const DistantLight& l : scene.distantLights) check(l.transform);
    for (const PointLight& l : scene.pointLights) check(l.transform);
    return moved;
}

/// Settings that change the picture (exposure and the accumulation cap do not).
bool SameImage(const PreviewSettings& a, const PreviewSettings& b) {
    PreviewSettings x = a, y = b;
    x.exposure = y.exposure = 0.0f;
    x.maxFrames = y.maxFrames = 0;
    return x == y;
}

}  // namespace

TextureSpaceOptions TextureOptionsOf(const PreviewSettings& s) {
    TextureSpaceOptions t;
    t.enabled = s.textureSpace;
    t.filter = s.filter;
    t.radius = s.radius;
    t.footprint = s.footprint;
    t.cache.sampleCacheBytes = size_t(double(s.sampleCacheMb) * (1 << 20));
    t.cache.texelCacheBytes = size_t(double(s.texelCacheMb) * (1 << 20));
    t.cache.lodBias = s.lodBias;
    t.cachedVisibility = s.cachedVisibility;
    t.frameBufferSamples = s.fbCache;
    t.frameBufferBudget = s.fbBudget;
    if (s.denoise) t.temporalAlpha = kStageTemporalAlpha;
    t.cache.Validate();
    return t;
}

screen::DenoiserSettings StageSettingsFor(int height) {
    screen::DenoiserSettings d;
    if (height < 720) d.atrousLevels = std::max(1, d.atrousLevels - 1);
    return d;
}

bool StageKeepsUp(int width, int height) {
    return int64_t(width) * int64_t(height) <= int64_t(2) * 640 * 360;
}

bool LimitQuadsFit(const Scene& scene) {
    std::vector<char> used(scene.meshes.size(), 0);
    for (const Object& o : scene.objects)
        if (o.subdivide && o.mesh >= 0 && size_t(o.mesh) < used.size()) used[size_t(o.mesh)] = 1;
    double faces = 0.0;
    for (size_t m = 0; m < used.size(); ++m)
        if (used[m]) faces += double(scene.meshes[m].numFaces());
    const double rate = std::max(double(scene.settings.tessellationRate), 1.0);
    return faces * rate * rate <= kMaxAutoLimitQuads;
}

namespace {

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

namespace {
// Each view's panel name and command-line key (--view), in ViewMode order.
struct ViewNames {
    ViewMode mode;
    const char* name;
    const char* key;
};
constexpr ViewNames kViewNames[] = {
    {ViewMode::Beauty, "beauty", "beauty"},
    {ViewMode::FaceId, "face id (ptex)", "faceid"},
    {ViewMode::TexelMip, "texel mip level", "mip"},
    {ViewMode::Texels, "cache texels", "texels"},
    {ViewMode::HitMiss, "cache hit / miss", "hitmiss"},
    {ViewMode::Overshading, "overshading", "overshading"},
    {ViewMode::Motion, "motion vectors", "motion"},
};
const ViewNames* FindView(ViewMode m) {
    for (const ViewNames& v : kViewNames)
        if (v.mode == m) return &v;
    return nullptr;
}
}  // namespace

const char* ViewModeName(ViewMode m) {
    const ViewNames* v = FindView(m);
    return v ? v->name : "?";
}

const char* ViewModeKey(ViewMode m) {
    const ViewNames* v = FindView(m);
    return v ? v->key : "?";
}

ViewMode ParseViewMode(const std::string& key, const std::string& where) {
    std::string valid;
    for (int i = 0; i < kNumViewModes; ++i) {
        if (key == ViewModeKey(ViewMode(i))) return ViewMode(i);
        valid += std::string(i ? ", " : "") + ViewModeKey(ViewMode(i));
    }
    throw InputError(where, "unknown view '" + key + "' (valid: " + valid + ")");
}

glm::vec3 HitMissColour(float hit) {
    // Through yellow rather than a muddy brown, so a half-hit pixel reads as neither.
    const glm::vec3 miss(0.9f, 0.08f, 0.05f), half(0.9f, 0.8f, 0.05f), all(0.1f, 0.85f, 0.1f);
    hit = std::clamp(hit, 0.0f, 1.0f);
    return hit < 0.5f ? glm::mix(miss, half, 2.0f * hit) : glm::mix(half, all, 2.0f * hit - 1.0f);
}

glm::vec3 NoLookupColour() {
    return glm::vec3(0.45f);
}

glm::vec3 HeatColour(float t) {
    static const glm::vec3 stops[] = {{0.02f, 0.02f, 0.25f},
                                      {0.0f, 0.45f, 0.9f},
                                      {0.05f, 0.8f, 0.35f},
                                      {0.95f, 0.85f, 0.05f},
                                      {0.95f, 0.1f, 0.05f}};
    constexpr int n = int(sizeof stops / sizeof stops[0]);
    const float x = std::clamp(t, 0.0f, 1.0f) * float(n - 1);
    const int i = std::min(int(x), n - 2);
    return glm::mix(stops[i], stops[i + 1], x - float(i));
}

namespace {
constexpr EnumName<screen::MotionKind> kMotionKinds[] = {
    {"traditional", screen::MotionKind::Traditional},
    {"shadow", screen::MotionKind::Shadow},
    {"glossy", screen::MotionKind::Glossy},
    {"occlusion", screen::MotionKind::Occlusion}};
}  // namespace

std::string MotionKindKeys() {
    return EnumNames(kMotionKinds);
}

screen::MotionKind ParseMotionKind(const std::string& key, const std::string& where) {
    return ParseEnum(kMotionKinds, key, where, "motion-vector kind");
}

const char* MotionKindKey(screen::MotionKind k) {
    return EnumToName(kMotionKinds, k);
}

bool KeepsStageHistory(const PreviewSettings& a, const PreviewSettings& b) {
    PreviewSettings x = a, y = b;
    x.time = y.time = 0.0f;
    x.exposure = y.exposure = 0.0f;
    x.view = y.view = ViewMode::Beauty;
    x.motionKind = y.motionKind = screen::MotionKind::Traditional;
    x.maxFrames = y.maxFrames = 0;
    return x == y;
}

glm::vec3 MotionColour(glm::vec2 offset, float fullPixels) {
    if (!std::isfinite(offset.x + offset.y)) return glm::vec3(0.0f);
    const float len = glm::length(offset);
    const float sat = std::min(len / std::max(fullPixels, 1e-6f), 1.0f);
    // Hue from the direction (raster y is down), HSV with value 1.
    const float hue = (std::atan2(offset.y, offset.x) / (2.0f * 3.14159265f) + 1.0f) * 6.0f;
    glm::vec3 rgb;
    const float shift[3] = {0.0f, 4.0f, 2.0f};
    for (int k = 0; k < 3; ++k)
        rgb[k] = std::clamp(std::abs(std::fmod(hue + shift[k], 6.0f) - 3.0f) - 1.0f, 0.0f, 1.0f);
    return glm::mix(glm::vec3(1.0f), rgb, sat);
}

uint32_t OvershadeTop(uint32_t maxShaded) {
    uint32_t top = 1;
    while (top < maxShaded && top < (1u << 31)) top <<= 1;
    return top;
}

float OvershadeScale(float samples, uint32_t top) {
    return std::clamp(std::log1p(std::max(samples, 0.0f)) / std::log1p(float(top)), 0.0f, 1.0f);
}

float OvershadeAt(float t, uint32_t top) {
    return std::expm1(std::clamp(t, 0.0f, 1.0f) * std::log1p(float(top)));
}

uint32_t RenderHeatView(const RenderScene& rs, float frameTime,
                        const std::vector<PixelCacheCounts>& counts, ViewMode mode, Image* out) {
    uint32_t maxShaded = 0;
    if (mode == ViewMode::Overshading)
        for (const PixelCacheCounts& c : counts) maxShaded = std::max(maxShaded, c.samplesShaded);
    const uint32_t top = mode == ViewMode::Overshading ? OvershadeTop(maxShaded) : 0;
    const CameraModel camera(rs.scene().camera, frameTime, out->width, out->height);
    tbb::parallel_for(0, out->height, [&](int y) {
        for (int x = 0; x < out->width; ++x) {
            float* px = out->At(x, y);
            const Ray ray =
                camera.Generate(float(x) + 0.5f, float(y) + 0.5f, glm::vec2(0.5f), nullptr);
            Hit hit;
            glm::vec3 c(0.0f);
            if (rs.Intersect(ray, &hit)) {
                const PixelCacheCounts& n = counts[size_t(y) * out->width + x];
                glm::vec3 colour = NoLookupColour();
                if (n.lookups > 0)
                    colour = mode == ViewMode::HitMiss
                                 ? HitMissColour(float(n.texelHits) / float(n.lookups))
                                 : HeatColour(OvershadeScale(float(n.samplesShaded), top));
                // Shaded by the view angle, like the cache views, so the shape stays readable
                // under the false colour.
                const glm::vec3 N = hit.object >= 0 ? rs.Interact(ray, hit).N : -ray.dir;
                const float shade = 0.35f + 0.65f * std::abs(glm::dot(N, ray.dir));
                c = shade * colour;
            }
            px[0] = c.x, px[1] = c.y, px[2] = c.z;
        }
    });
    return top;
}

SceneAnimation AnimationOf(const Scene& scene) {
    SceneAnimation a;
    bool first = true;
    auto track = [&](const TransformTrack& t, bool camera) {
        if (!t.IsAnimated()) return;
        a.animated = true;
        a.cameraAnimated = a.cameraAnimated || camera;
        a.posesAnimated = a.posesAnimated || !camera;
        for (const Keyframe& k : t.keys) {
            a.start = first ? k.time : std::min(a.start, k.time);
            a.end = first ? k.time : std::max(a.end, k.time);
            first = false;
        }
    };
    track(scene.camera.pose, true);
    for (const Object& o : scene.objects) track(o.transform, false);
    for (const QuadLight& l : scene.quadLights) track(l.transform, false);
    for (const DistantLight& l : scene.distantLights) track(l.transform, false);
    for (const PointLight& l : scene.pointLights) track(l.transform, false);
    return a;
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
                const SampleRequest r = cache.TexelOf(si);
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

uint64_t ProgressiveRenderer::Post(const PreviewSettings& s, const OrbitCamera& c) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (s == postedSettings_ && c == postedCamera_) return version_;
    postedSettings_ = s, postedCamera_ = c;
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
    float builtTime = 0.0f;                     // scene time the RenderScene is posed at
    uint32_t cacheFrame = 0;                    // cache frames begun (time changes)
    std::vector<PixelCacheCounts> pixelCounts;  // heat views: the frame's per-pixel lookups
    // Before the orbit camera replaces the scene camera's keys below.
    const bool posesAnimated = AnimationOf(scene_).posesAnimated;
    std::vector<glm::vec3> sceneAlbedo;  // before the panel's edits
    for (const Material& m : scene_.materials) sceneAlbedo.push_back(m.albedo.value);
    uint32_t refreshFrame = 0;  // the stage's frames through the cache (Refresh)
    float shownExposure = 0.0f;
    // Worker-side buffers, swapped with the published ones (no allocation per frame once sized).
    std::vector<uint8_t> display;
    Image mean;
    // The screen-space stage (UsesStage): made on first use, its history kept across frames.
    std::unique_ptr<screen::ScreenSpaceDenoiser> denoiser;
    int denoiserLevels = 0;  // its a-trous levels (StageSettingsFor the frame's height)
    screen::FrameBuffers frameBuffers;
    std::vector<glm::vec3> denoised;
    PreviewSettings stageSettings;                  // what the stage's history was made with
    int stageHistory = 0;                           // frames in it (0: none)
    float stagePrevTime = 0.0f;                     // scene time of its last frame
    uint64_t stageFrames = 0;                       // frames the stage ran (a new seed each)
    uint64_t sceneBuilds = 0, stageSceneBuild = 0;  // RenderScene rebuilds (tessellation)

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
            const float frameTime = cur.time;
            const bool retessellate = !rs || cur.tessellationRate != built.tessellationRate ||
                                      cur.limitQuads != built.limitQuads;
            // Only moving objects and lights change the RenderScene and the shading; the camera
            // is the orbit camera's (an animated one is followed by the UI).
            const bool timeChanged = rs && frameTime != builtTime && posesAnimated;
            const float oldTime = builtTime;
            builtTime = frameTime;
            if (retessellate || timeChanged) {
                // A new time only re-poses objects and lights: the cache (object-space grids)
                // stays, but what it holds was shaded for the old pose (and the surroundings it
                // saw), so a cache frame begins and everything is re-shaded on demand.
                if (retessellate) cache.reset();
                rs.reset();
                scene_.settings.tessellationRate = cur.tessellationRate;
                scene_.settings.time = frameTime;
                RenderSceneOptions ro;
                ro.frameTime = frameTime;
                ro.tessellateAll = cur.limitQuads;
                // Lights always: the integrator can be switched to direct/path at any time.
                rs = std::make_unique<RenderScene>(scene_, ro);
                if (retessellate) ++sceneBuilds;
                built.tessellationRate = cur.tessellationRate;
                built.limitQuads = cur.limitQuads;
                if (timeChanged && cache) {
                    bool lightMoved = false;
                    const std::vector<char> moved =
                        MovedObjects(scene_, oldTime, frameTime, &lightMoved);
                    ++cacheFrame;
                    if (!built.denoise) {
                        cache->BeginFrame(cacheFrame);
                    } else if (lightMoved || std::count(moved.begin(), moved.end(), 1) > 0) {
                        // The stage's cache holds direct light under soft lights, and a moved
                        // object's shadows and bounce light fall on the others: every object's
                        // texels and history go, not only the moved ones' (a cache frame that
                        // kept the history would blend the old shadows in by eq. 6).
                        for (size_t o = 0; o < moved.size(); ++o) cache->InvalidateObject(int(o));
                    }
                }
                std::lock_guard<std::mutex> lock(mutex_);
                ready_ = true;
            }
            cam.ToCamera(&scene_.camera);
            // The panel's material edits: the scene's own albedo where it sets none.
            for (size_t m = 0; m < scene_.materials.size(); ++m) {
                const glm::vec3 want =
                    m < cur.materialAlbedo.size() ? cur.materialAlbedo[m] : sceneAlbedo[m];
                if (scene_.materials[m].albedo.value == want) continue;
                scene_.materials[m].albedo.value = want;
                // What the cache holds for the objects with it was shaded with the old one
                // (their own interreflections). Without the stage the others take the change of
                // their bounce light in over the next refreshes; the stage's store keeps a
                // running mean while nothing moves (TextureSpaceCache::FrameStoreKeep), which
                // would keep their old bounce light, so every object's bins go.
                if (cache)
                    for (size_t o = 0; o < scene_.objects.size(); ++o) {
                        bool uses = built.denoise;
                        for (const int used : scene_.objects[o].Materials())
                            uses |= size_t(used) == m;
                        if (uses) cache->InvalidateObject(int(o));
                    }
            }

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
            const bool heatView =
                cur.view == ViewMode::HitMiss || cur.view == ViewMode::Overshading;
            const bool staged = UsesStage(cur);
            // The stage renders the path tracer's split: its cache holds diffuse indirect light.
            PreviewSettings eff = cur;
            if (staged) eff.integrator = IntegratorKind::Path;
            const bool wantCache =
                (cur.textureSpace && CachedIntegrator(eff.integrator)) || cacheView;
            if (wantCache && (!cache || !SameCacheContents(eff, built))) {
                cache.reset();  // free the old slots before allocating new ones
                for (size_t m = 0; m < scene_.materials.size(); ++m) {
                    scene_.materials[m].cacheFilter =
                        m < cur.materialFilter.size() ? cur.materialFilter[m] : "";
                    scene_.materials[m].cacheRadius =
                        m < cur.materialRadius.size() ? cur.materialRadius[m] : -1;
                }
                cache = MakeTextureSpaceCache(*rs, TextureOptionsOf(eff), "sample/texel cache MiB");
                built = eff;
            }

            const bool stereo = cur.stereo && !cacheView && !heatView && !staged;
            const int imageWidth = stereo ? 2 * cur.width : cur.width;
            if (imageChanged) {
                accumulated = 0;
                accumSettings = cur, accumCamera = cam;
                accum_.assign(size_t(imageWidth) * cur.height * 3, 0.0);
            }
            if (mean.width != imageWidth || mean.height != cur.height)
                mean = Image(imageWidth, cur.height, 3);
            FrameStats frame;
            const auto t0 = std::chrono::steady_clock::now();
            if (cacheView) {
                // Deterministic: one frame says everything.
                RenderCacheView(*rs, *cache, frameTime, cur.view, &mean);
                accumulated = INT_MAX;
            } else if (staged) {
                const screen::DenoiserSettings ds = StageSettingsFor(cur.height);
                if (!denoiser || denoiserLevels != ds.atrousLevels) {
                    denoiser = std::make_unique<screen::ScreenSpaceDenoiser>(ds);
                    denoiserLevels = ds.atrousLevels;
                    stageHistory = 0;
                }
                if (stageHistory == 0 || !KeepsStageHistory(stageSettings, cur) ||
                    stageSceneBuild != sceneBuilds) {
                    denoiser->Reset();
                    stageHistory = 0;
                    stagePrevTime = frameTime;  // no previous frame: nothing moved
                }
                stageSettings = cur, stageSceneBuild = sceneBuilds;
                RenderOptions opt;
                opt.integrator = IntegratorKind::Path;
                opt.width = cur.width, opt.height = cur.height;
                opt.spp = cur.sppPerFrame;
                // A new seed per frame: the stage's history averages independent estimates.
                opt.seed = FrameSeed(cur.seed, stageFrames++);
                opt.maxDepth = cur.maxDepth;
                opt.frameTime = frameTime;
                opt.progress = false;
                opt.frameBufferCones = ds.indirectCones;  // only the stage's cone path reads them
                // Only Zeng's visibility order reads the shadow points while shadows stay put.
                opt.frameBufferShadowPoints =
                    ds.reliableVisibilityOrder == screen::VisibilityOrder::Zeng;
                opt.frameBufferPrevPoints = false;  // the stage reads the current ones instead
                opt.texture = cache ? cache->options() : TextureOptionsOf(cur);
                opt.texture.enabled = cur.textureSpace && cache != nullptr;
                // The cache from frame to frame: a part of it re-shaded, a still view's averaged.
                if (opt.texture.enabled) {
                    const bool still = accumulated > 0;
                    cache->Refresh(++refreshFrame, RefreshParts(still), still);
                }
                // "prev" points go to the previous frame's time: the stage's history was
                // rendered there (the same time while only the camera moves).
                const RenderStats st =
                    RenderFrameBuffers(*rs, opt, stagePrevTime, &frameBuffers,
                                       opt.texture.enabled ? cache.get() : nullptr);
                const screen::Method method =
                    cur.denoise ? cur.denoiseMethod : screen::Method::Reliable;
                // Only texture-space frames: a per-hit frame's rare bright samples would stay in
                // a running mean far longer than in the fixed blend, and its error rises.
                denoiser->SetStillView(accumulated > 0 && opt.texture.enabled);
                denoiser->Denoise(
                    frameBuffers, method,
                    cur.demodulate ? screen::Demodulation::On : screen::Demodulation::Off,
                    &denoised);
                stagePrevTime = frameTime;
                ++stageHistory;
                if (cur.view == ViewMode::Motion) {
                    const std::vector<glm::vec2> from = denoiser->LastMotion(cur.motionKind);
                    for (int y = 0; y < mean.height; ++y)
                        for (int x = 0; x < mean.width; ++x) {
                            const glm::vec2 centre(float(x) + 0.5f, float(y) + 0.5f);
                            const glm::vec3 c = MotionColour(
                                from[size_t(y) * size_t(mean.width) + size_t(x)] - centre, 8.0f);
                            float* px = mean.At(x, y);
                            px[0] = c.x, px[1] = c.y, px[2] = c.z;
                        }
                } else {
                    for (size_t p = 0; p < denoised.size(); ++p)
                        for (int k = 0; k < 3; ++k) mean.data[3 * p + k] = denoised[p][k];
                }
                ++accumulated;  // frames since the last change: a still view stops at maxFrames
                frame.staged = true;
                frame.stageHistory = stageHistory;
                frame.renderSeconds = st.seconds;
                frame.stage = denoiser->Timings();
                frame.raysPerSecond = st.seconds > 0.0 ? double(st.TotalRays()) / st.seconds : 0.0;
                frame.textureSpace = opt.texture.enabled;
                frame.texelHitRate = st.cache.TexelHitRate();
                frame.lookups = st.cache.lookups;
                frame.samplesShaded = st.cache.samplesShaded;
            } else {
                RenderOptions opt;
                opt.integrator =
                    cur.view == ViewMode::FaceId ? IntegratorKind::Ptex : cur.integrator;
                opt.width = cur.width, opt.height = cur.height;
                opt.spp = cur.sppPerFrame;
                // A new seed per accumulated frame: frames are independent estimates.
                opt.seed = FrameSeed(cur.seed, uint64_t(accumulated));
                opt.maxDepth = cur.maxDepth;
                opt.aoSamples = cur.aoSamples;
                opt.aoDistance = cur.aoDistance;
                opt.frameTime = frameTime;
                opt.progress = false;
                opt.texture = cache ? cache->options() : TextureOptionsOf(cur);
                opt.texture.enabled = cur.textureSpace && cache != nullptr;
                // Heat views record each pixel's lookups during this very frame (a probe of the
                // cache afterwards would find everything it just stored).
                opt.pixelCache = heatView ? &pixelCounts : nullptr;
                // Still: each accumulated frame is a progressive pass of the cache (fresh
                // shading, jittered samples, smaller footprints; see texture_space.h).
                if (cur.refineCacheWhenStill && accumulated > 0 && opt.texture.enabled)
                    cache->BeginPass(uint32_t(accumulated));
                // A new accumulation (the view moved) starts at pass 0's footprints again,
                // keeping the cache, the point of the preview.
                if (accumulated == 0 && opt.texture.enabled && cache->Pass() > 0)
                    cache->RestartPasses();
                TextureSpaceCache* tsc = opt.texture.enabled ? cache.get() : nullptr;
                RenderResult r;
                if (stereo) {
                    const float convergence = glm::length(cam.Target() - cam.Position());
                    const StereoRig rig{cur.eyeSeparation >= 0.0f
                                            ? cur.eyeSeparation
                                            : DefaultEyeSeparation(convergence),
                                        std::max(convergence, 1e-6f)};
                    const StereoResult both = RenderStereo(*rs, opt, rig, tsc);
                    r.beauty = SideBySide(both.left.beauty, both.right.beauty);
                    r.stats = BothEyes(both);
                } else {
                    r = Render(*rs, opt, tsc);
                }
                if (heatView) {
                    // One frame per change: the map shows what the frame after a move looked up;
                    // further frames of a still view would only show a warm cache.
                    frame.overshadeTop =
                        RenderHeatView(*rs, frameTime, pixelCounts, cur.view, &mean);
                    accumulated = INT_MAX;
                } else {
                    ++accumulated;
                    const double inv = 1.0 / double(accumulated);
                    tbb::parallel_for(tbb::blocked_range<size_t>(0, accum_.size(), 16384),
                                      [&](auto range) {
                                          for (size_t i = range.begin(); i < range.end(); ++i) {
                                              accum_[i] += double(r.beauty.data[i]);
                                              mean.data[i] = float(accum_[i] * inv);
                                          }
                                      });
                }
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
            frame.cacheBytes = cache ? cache->BytesUsed() : 0;
            frame.ptexFaces = rs->NumPtexFaces();
            frame.tessellation = rs->LimitTessellated();
            frame.time = frameTime;
            frame.cacheFrame = cacheFrame;
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
