// SPDX-License-Identifier: Apache-2.0
// Ambient occlusion in two phases over a tile: every camera ray first, then the AO rays of all
// its hits, 16 to a packet across hits (one hit's 4 rays would fill a quarter of a packet); in
// texture space, every shading point first, its texel slot prefetched, then the lookups. Tracing
// like rays together keeps Embree's working set and the cache's slots warm, as a wavefront
// renderer does. Also RecordAoRays: the same rays, for `texcache bench rays`.
#include <algorithm>
#include <vector>

#include "renderer/render_internal.h"

namespace texcache {
namespace internal {

namespace {

/// Per-hit AO for a tile in two phases: all camera rays first, then the AO rays of every hit.
/// Same samples, same random numbers, same result as ShadeTile; tracing like rays together keeps
/// Embree's working set (and the traversal's caches) warm, as a wavefront renderer would.
void AoSamplesTwoPhase(const Context& c, int y0, int y1, int x0, int x1, int s0, int s1,
                       const PixelSequence& seq, std::vector<double>& sum, RayCounts& rays) {
    struct Pending {
        Ray ray;
        Hit hit;
        Rng rng{0, 0};
        uint64_t first = 0;  // its first point in the pass's PixelSequence
        int pixel = 0;
        bool found = false;
        RayDifferentials diff;
    };
    // The thread's slots are reused from tile to tile, not value-initialised again (a 144-byte
    // clear per camera sample is a visible cost in a profile): CameraRay and IntersectCameraRays
    // write every field that is read.
    thread_local std::vector<Pending> storage;
    const size_t n = size_t(y1 - y0) * size_t(x1 - x0) * size_t(std::max(s1 - s0, 0));
    if (storage.size() < n) storage.resize(n);
    Pending* const queue = storage.data();
    size_t next = 0;
    const bool pinhole = c.camera.IsPinhole() && !c.cameraMoves && !c.tsc;
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x)
            for (int s = s0; s < s1; ++s) {
                // Written in place, not built on the stack and copied (see ForEachAoRay).
                Pending& p = queue[next++];
                p.pixel = y * c.opt.width + x, p.first = seq.First(x, y, s);
                if (!pinhole) CameraRay(c, x, y, s, &p.rng, &p.ray, c.tsc ? &p.diff : nullptr);
            }
    if (pinhole) {
        const tbb::blocked_range2d<int> r(y0, y1, x0, x1);
        Cursor gen(r, s0);
        for (size_t b = 0; b < n; b += kCameraBlock)
            PinholeCameraRays(c, r, s0, s1, gen, queue + b, std::min(kCameraBlock, n - b));
    }
    IntersectCameraRays(c, queue, n, rays, c.hitRect.Outside(x0, y0, x1, y1));
    auto add = [&](const Pending& p, glm::vec3 L) {
        double* px = &sum[3 * size_t(p.pixel)];
        px[0] += L.x, px[1] += L.y, px[2] += L.z;
    };
    if (!c.tsc) {
        // The AO rays of every hit of the tile, traced 16 at a time across hits: full packets
        // (4 rays of one hit fill a quarter of one).
        thread_local AoRayBatch batch;
        thread_local std::vector<uint32_t> open;
        batch.Clear();
        open.assign(n, 0);
        for (size_t i = 0; i < n; ++i) {
            Pending& p = queue[i];
            if (!p.found || p.hit.object < 0) continue;
            batch.Queue(c, p.ray, c.rs.Interact(p.ray, p.hit), seq, p.first, uint32_t(i));
        }
        batch.Trace(c, open.data(), rays);
        const float inv = 1.0f / float(c.opt.aoSamples);
        for (size_t i = 0; i < n; ++i) {
            const Pending& p = queue[i];
            add(p, !p.found           ? glm::vec3(0.0f)
                   : p.hit.object < 0 ? glm::vec3(1.0f)
                                      : glm::vec3(float(open[i]) * inv));
        }
        return;
    }
    // Texture space: all shading points first, prefetching their texel slots, then the lookups,
    // so the latency of a large texel table overlaps instead of stalling every hit.
    thread_local std::vector<SurfaceInteraction> points;
    thread_local std::vector<SampleRequest> texels;
    points.resize(n);
    texels.resize(n);
    const bool lookups = c.opt.texture.constantTerm < 0.0f;
    InteractAll(c, queue, n, points.data(), true);
    if (lookups)
        for (size_t i = 0; i < n; ++i) {
            const Pending& p = queue[i];
            if (!p.found || p.hit.object < 0) continue;
            texels[i] = c.tsc->TexelOf(points[i]);
            c.tsc->Prefetch(texels[i]);
        }
    CacheStats& stats = c.cacheStats->local();
    for (size_t i = 0; i < n; ++i) {
        const Pending& p = queue[i];
        const CacheSnapshot before = c.pixelCache ? CacheSnapshot(stats) : CacheSnapshot();
        glm::vec3 L(0.0f);
        if (p.found)
            L = p.hit.object < 0
                    ? glm::vec3(1.0f)
                    : CachedLookup(
                          c, points[i],
                          [&](const SampleRequest& r) { return ShadeAoSample(c, r, rays); },
                          c.opt.aoSamples, &stats, lookups ? &texels[i] : nullptr);
        if (c.pixelCache) AddPixelCounts(&c.pixelCache[p.pixel], before, stats);
        add(p, L);
    }
}

}  // namespace

/// AoSamplesTwoPhase over samples [s0, s1) of a tile, at most kMaxQueued camera samples at a
/// time: a queue of every sample of the pass would grow with the sample count (hundreds of MiB
/// for a high-spp reference), a bounded one stays a few MiB whatever the count. Each pixel still
/// adds its samples in order; only the grouping of rays into Embree's 16-ray packets changes,
/// which moves an image by rounding only.
void AoTileTwoPhase(const Context& c, int y0, int y1, int x0, int x1, int s0, int s1,
                    std::vector<double>& sum, RayCounts& rays) {
    const PixelSequence seq(c.opt, s0, s1);
    constexpr size_t kMaxQueued = 4096;
    const size_t pixels = size_t(y1 - y0) * size_t(x1 - x0);
    const int chunk = int(std::max<size_t>(1, kMaxQueued / std::max<size_t>(pixels, 1)));
    for (int a = s0; a < s1; a += chunk)
        AoSamplesTwoPhase(c, y0, y1, x0, x1, a, std::min(s1, a + chunk), seq, sum, rays);
}

}  // namespace internal

void RecordAoRays(const RenderScene& rs, const RenderOptions& opt, std::vector<Ray>* camera,
                  std::vector<Ray>* occlusion) {
    using namespace internal;
    const Context c(rs, opt);
    const PixelSequence seq(opt, 0, opt.spp);  // a render's single pass
    for (int y = 0; y < opt.height; ++y)
        for (int x = 0; x < opt.width; ++x)
            for (int s = 0; s < opt.spp; ++s) {
                Rng rng(0, 0);
                Ray ray;
                CameraRay(c, x, y, s, &rng, &ray, nullptr);
                camera->push_back(ray);
                Hit hit;
                if (!rs.Intersect(ray, &hit) || hit.object < 0) continue;
                ForEachAoRay(c, ray, rs.Interact(ray, hit), seq, seq.First(x, y, s),
                             [&]() -> Ray& { return occlusion->emplace_back(); });
            }
}

}  // namespace texcache
