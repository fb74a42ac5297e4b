// SPDX-License-Identifier: Apache-2.0
// The visibility prepass of a texture-space pass: the camera samples traced before shading, the
// texel each one lands on marked in the pass's visible set (footprints of visible texels only
// gather those: texcache/visible_texels.h) and, for texture-space AO, kept with what the prepass
// could look up already, so that the shading pass reads them back without tracing its camera
// rays again (PassTexels).
#include <algorithm>
#include <vector>

#include "renderer/render_internal.h"

namespace texcache::internal {

/// The visibility prepass of a tile (see texcache/visible_texels.h): marks the texel each camera
/// sample lands on, with the rays, differentials and texel selection of the shading pass (the
/// same blocks of packets as ShadeTile), and keeps them in `out` if given.
///
/// With `out`, texels the texel cache holds already are looked up here (kFound), and only the
/// others wait for the shading pass, whose misses need the whole visible set. In a warm frame
/// that is nearly every sample, which the shading pass then only adds up: a second walk over
/// the pass's texels (unpack, address, prefetch, look up) would be most of what a warm frame
/// costs beyond a frame without lookups (`texcache bench cache --warm-only`). A texel's value
/// does not depend on when it is read (a hit returns what a miss would filter from the same
/// samples and visible set), so the image is the one of the lookups in the shading pass.
void MarkVisibleTexels(const Context& c, VisibleTexels& visible, const tbb::blocked_range2d<int>& r,
                       int s0, int s1, PassTexels* out, RayCounts& rays) {
    const size_t total = r.rows().size() * r.cols().size() * size_t(s1 - s0);
    CameraSample block[kCameraBlock];
    // Each hit's texel, hashed once for its mark and its lookup.
    struct Texel {
        TexelAddress at;  // at.key is kEmpty for a sample without a texel (sky, light)
        int32_t mesh;
        uint32_t probe;  // VisibleTexels::Probe
        uint64_t bit;    // VisibleTexels::Bit
    };
    Texel texels[kCameraBlock];
    SurfaceInteraction points[kCameraBlock];
    CacheStats* stats = out ? &c.cacheStats->local() : nullptr;
    const bool find = out && !out->cacheEmptied;
    Cursor gen(r, s0), mark = gen;
    for (size_t b = 0; b < total; b += kCameraBlock) {
        const size_t n = std::min(kCameraBlock, total - b);
        for (size_t i = 0; i < n; ++i, gen.Next(r, s0, s1))
            CameraRay(c, gen.x, gen.y, gen.s, &block[i].rng, &block[i].ray, &block[i].diff);
        IntersectCameraRays(c, block, n, rays);
        // The block's surface interactions, then its texels, then their hashes and prefetches,
        // then the marks and lookups. The interactions run in a loop of their own: with the
        // slots' and marks' prefetches issued between them, a warm frame spent more in the
        // interactions (the limit patches) than a frame without lookups does, presumably their
        // loads queued behind those misses; and a key computed right after its interaction
        // waited on the call's stores (InteractAll). Prefetching the slots one block ahead (their
        // lookups after the next block's interactions) was slower still, in either place. A
        // sample on the texel of the sample before it (a pixel's samples mostly share one) takes
        // that one's mark and lookup: nothing writes the texel cache during the prepass, so a
        // lookup again would find the same.
        InteractAll(c, block, n, points, true);
        for (size_t i = 0; i < n; ++i) {
            const CameraSample& cs = block[i];
            Texel& t = texels[i];
            t.at = TexelAddress{};
            if (!cs.found || cs.hit.object < 0) continue;
            t.at.key = c.tsc->TexelKeyOf(points[i], &t.mesh).Pack();
        }
        // A texel whose first slot holds another key gets its other two slots prefetched too,
        // kSecond samples later, when the first slot's line has arrived to tell (the hashing
        // loop is short: a few samples are not time enough).
        constexpr size_t kSecond = 16;
        auto prefetchOthers = [&](size_t i) {
            const Texel& t = texels[i];
            if (find && t.at.key != TexelKey::kEmpty &&
                !(i > 0 && t.at.key == texels[i - 1].at.key))
                c.tsc->PrefetchOtherSlots(t.at);
        };
        for (size_t i = 0; i < n; ++i) {
            if (i >= kSecond) prefetchOthers(i - kSecond);
            Texel& t = texels[i];
            // A repeat is neither marked nor looked up again: it needs no hashes.
            if (t.at.key == TexelKey::kEmpty || (i > 0 && t.at.key == texels[i - 1].at.key))
                continue;
            const TexelKey k = TexelKey::Unpack(t.at.key);
            t.at.hash = c.tsc->AddressOf(k).hash;
            t.probe = VisibleTexels::Probe(k), t.bit = VisibleTexels::Bit(k);
            visible.PrefetchAt(t.probe);
            if (find) c.tsc->Prefetch(t.at);
        }
        for (size_t i = n > kSecond ? n - kSecond : 0; i < n; ++i) prefetchOthers(i);
        bool foundLast = false;
        glm::vec3 found(0.0f);
        for (size_t i = 0; i < n; ++i, mark.Next(r, s0, s1)) {
            const Texel& t = texels[i];
            const bool hasTexel = t.at.key != TexelKey::kEmpty;
            const bool repeat = hasTexel && i > 0 && t.at.key == texels[i - 1].at.key;
            int32_t mesh = !block[i].found ? PassTexels::kMiss
                           : hasTexel      ? t.mesh
                                           : PassTexels::kLight;
            if (hasTexel && !repeat) visible.MarkAt(t.probe, t.bit);
            if (!out) continue;
            const size_t pixel = size_t(mark.y) * size_t(out->width) + size_t(mark.x);
            if (mark.s == s0) out->added[pixel] = 0;
            if (find && hasTexel) {
                if (!repeat) foundLast = c.tsc->FindTexel(t.at, &found);
                if (foundLast) {
                    mesh = PassTexels::kFound;
                    ++stats->lookups, ++stats->texelHits;
                    if (c.pixelCache) {
                        PixelCacheCounts& px = c.pixelCache[pixel];
                        ++px.lookups, ++px.texelHits;
                    }
                }
            }
            if (mesh < 0 && out->added[pixel] == uint32_t(mark.s - s0)) {
                // Every sample of the pixel before this one is added: add this one too.
                const glm::vec3 L = mesh == PassTexels::kFound   ? found
                                    : mesh == PassTexels::kLight ? glm::vec3(1.0f)
                                                                 : glm::vec3(0.0f);
                double* px = &out->sum[3 * pixel];
                px[0] += L.x, px[1] += L.y, px[2] += L.z;
                ++out->added[pixel];
                continue;
            }
            // Read first: a cold pass leaves every row, and a store each time would bounce the
            // flags' line between the threads.
            if (!out->rowLeft[mark.y].load(std::memory_order_relaxed))
                out->rowLeft[mark.y].store(1, std::memory_order_relaxed);
            PassTexel& p = (*out)[out->Index(mark.x, mark.y, mark.s)];
            p.key = t.at.key, p.mesh = mesh,
            p.found = mesh == PassTexels::kFound ? found : glm::vec3(0.0f);
        }
    }
}

/// Texture-space AO for a tile from the texels its prepass kept: AoTileTwoPhase's lookups, in
/// the same order, with the same texels, so the same image, without its camera rays. The
/// samples the prepass added itself (PassTexels::added) are skipped.
void AoTileFromPrepass(const Context& c, const tbb::blocked_range2d<int>& r, const PassTexels& pt,
                       RayCounts& rays) {
    // The samples left, all texels first, prefetching their slots, then the lookups (as
    // AoTileTwoPhase).
    struct Left {
        uint32_t x, y, s;
    };
    thread_local std::vector<Left> left;
    thread_local std::vector<SampleRequest> texels;
    left.clear();
    texels.clear();
    for (int y = r.rows().begin(); y < r.rows().end(); ++y) {
        if (!pt.rowLeft[y].load(std::memory_order_relaxed)) continue;
        for (int x = r.cols().begin(); x < r.cols().end(); ++x)
            for (int s = pt.s0 + int(pt.added[size_t(y) * size_t(pt.width) + size_t(x)]); s < pt.s1;
                 ++s) {
                const PassTexel& t = pt[pt.Index(x, y, s)];
                left.push_back({uint32_t(x), uint32_t(y), uint32_t(s)});
                texels.emplace_back();
                if (t.mesh < 0) continue;
                texels.back() = c.tsc->RequestOf(t.mesh, TexelKey::Unpack(t.key));
                c.tsc->Prefetch(texels.back());
            }
    }
    CacheStats& stats = c.cacheStats->local();
    for (size_t i = 0; i < left.size(); ++i) {
        const Left at = left[i];
        const PassTexel& t = pt[pt.Index(int(at.x), int(at.y), int(at.s))];
        const int32_t mesh = t.mesh;
        const size_t pixel = size_t(at.y) * size_t(c.opt.width) + size_t(at.x);
        const CacheSnapshot before = c.pixelCache ? CacheSnapshot(stats) : CacheSnapshot();
        glm::vec3 L(mesh == PassTexels::kLight ? 1.0f : 0.0f);
        if (mesh == PassTexels::kFound) L = t.found;
        if (mesh >= 0)
            L = c.tsc->Lookup(
                texels[i], c.tsc->ObjectOfMesh(mesh),
                [&](const SampleRequest& req) { return ShadeAoSample(c, req, rays); },
                c.opt.aoSamples, stats);
        if (c.pixelCache) AddPixelCounts(&c.pixelCache[pixel], before, stats);
        double* px = &pt.sum[3 * pixel];
        px[0] += L.x, px[1] += L.y, px[2] += L.z;
    }
}

}  // namespace texcache::internal
