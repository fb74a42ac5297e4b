// SPDX-License-Identifier: Apache-2.0
// Shading at the camera's hits (TextureSamples::Hits), phase 1 of a pass: each camera sample
// traced and shaded as per-hit shading shades it (same rays, same random streams), and what its
// hit receives added to bins of a coarser level of its object's texel grids, at two levels so
// that phase 2 (bin_reconstruction.cpp) can blend them. A sample's record keeps where it hit.
// The note at the top of texture_space.h says why the bins' estimate converges.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <vector>

#include <tbb/parallel_for.h>

#include "renderer/render_internal.h"

namespace texcache::internal {

namespace {

/// The camera rays of a hit-binned tile, traced: per-hit shading's rays and random streams,
/// without differentials unless `diff` (product sampling at camera hits needs them): the bins'
/// level needs only the footprint's size (BinHit).
void HitsCameraRays(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                    CameraSample* cs, size_t total, bool diff, RayCounts& rays) {
    Cursor gen(r, s0);
    if (c.camera.IsPinhole() && !c.cameraMoves && !diff) {
        for (size_t b = 0; b < total; b += kCameraBlock)
            PinholeCameraRays(c, r, s0, s1, gen, cs + b, std::min(kCameraBlock, total - b));
    } else {
        for (size_t i = 0; i < total; ++i, gen.Next(r, s0, s1))
            CameraRay(c, gen.x, gen.y, gen.s, &cs[i].rng, &cs[i].ray, diff ? &cs[i].diff : nullptr);
    }
    IntersectCameraRays(
        c, cs, total, rays,
        c.hitRect.Outside(r.cols().begin(), r.rows().begin(), r.cols().end(), r.rows().end()));
}

/// The level of the texel a camera hit at distance `t` lands on (eq. 1 with the pixel's
/// footprint taken as a disc across the ray: the minor axis of its ellipse on the surface, which
/// eq. 1's minimum picks), on the grids of `mesh`.
int HitTexelLevel(const Context& c, const SurfaceInteraction& si, float t, int mesh) {
    const MeshGrids& g = c.tsc->Grids(mesh);
    const float w = c.camera.FootprintAt(t);
    return ComputeMip(g.Log2Res(si.ptex.face), w / glm::length(si.dPdu), 0.0f, 0.0f,
                      w / glm::length(si.dPdv), c.opt.texture.cache.lodBias);
}
/// The bins of point (u,v) of `face` at the levels `bias` and `bias` + 1 above `texelLevel`.
void BinKeys(const MeshGrids& g, int face, float u, float v, int texelLevel, int bias,
             TexelKey keys[2]) {
    for (int k = 0; k < 2; ++k) {
        const int level = g.ClampMip(face, texelLevel + bias + k);
        const int res = g.Res(face, level);
        keys[k] = {g.FaceOffset() + uint32_t(face), uint8_t(level), uint16_t(QuantizeCoord(u, res)),
                   uint16_t(QuantizeCoord(v, res))};
    }
}
/// The levels above `texelLevel` of a hit of scene object `object`'s bins: the one its
/// material's filter sets, when that filter reads no other (both entries, then), or the two at
/// the schedule's `bias` and `bias` + 1; in the frame buffers' store (`frameStore`) at
/// StoreFilterLevels'. Returns whether there is one.
bool ObjectBinLevels(const Context& c, int object, int bias, bool frameStore, int levels[2]) {
    const TextureFilterKind kind = c.tsc->FilterOf(object);
    const int r = c.tsc->PassRadiusOf(object);
    const int own = frameStore ? StoreFilterLevels(kind, r) : HitFilterLevels(kind, r);
    levels[0] = own < 0 ? bias : own;
    levels[1] = own < 0 ? bias + 1 : own;
    return own >= 0;
}
/// The bins of a hit of scene object `object` (ObjectBinLevels).
void ObjectBinKeys(const Context& c, int object, const MeshGrids& g, int face, float u, float v,
                   int texelLevel, int bias, TexelKey keys[2], bool frameStore = false) {
    int levels[2];
    const bool one = ObjectBinLevels(c, object, bias, frameStore, levels);
    BinKeys(g, face, u, v, texelLevel, levels[0], keys);
    if (one) keys[1] = keys[0];
}
/// Whether camera sample (x, y, s) reads its upper bin level: with probability `blend`, the
/// lower one otherwise (stochastic filtering: in expectation the blend of the two, for one
/// reconstruction instead of two), decided by a hash of its pixel and index rather than its
/// random stream, which stays the one per-hit shading draws from.
bool ReadsUpperLevel(const Context& c, int x, int y, int s, float blend) {
    const uint64_t u =
        MixBits(PixelSeed(c.opt.seed, x, y, c.opt.width) ^ (uint64_t(s) * 0xD1B54A32D192ED03ull));
    return float(u >> 40) * (1.0f / float(1u << 24)) < blend;
}

/// Where a camera sample hitting `si` at distance `t` adds its AO: its bins at the two levels
/// `bias` and `bias` + 1 above its texel's (keys[0], keys[1]); and its record, which names the
/// finer (the reconstruction reads both, ReconstructAo).
void BinHit(const Context& c, const SurfaceInteraction& si, float t, int bias, TexelKey keys[2],
            HitRecord* h) {
    const int mesh = c.tsc->MeshOf(si.object, si.backFacing), face = si.ptex.face;
    ObjectBinKeys(c, si.object, c.tsc->Grids(mesh), face, si.ptex.u, si.ptex.v,
                  HitTexelLevel(c, si, t, mesh), bias, keys);
    *h = {HitRecord::Quantize(si.ptex.u), HitRecord::Quantize(si.ptex.v), mesh,
          uint32_t(face) << 4 | keys[0].mip};
}

}  // namespace

/// Hit-binned texture-space AO, phase 1 of a pass, for one tile: traces its camera rays, shades
/// AO at each hit exactly as per-hit AO does (same rays, same random numbers, 16-ray packets
/// across the tile's hits), and adds each hit's escaped rays to its bins at the two levels
/// `bias` and `bias` + 1 above its texel's. Records where each camera sample hit, for phase 2
/// (AoHitsResolve).
void AoHitsBin(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1, int bias,
               HitRecord* records, float* ownAo, HitBins& bins, RayCounts& rays) {
    const size_t total = r.rows().size() * r.cols().size() * size_t(s1 - s0);
    thread_local std::vector<CameraSample> cs;
    thread_local std::vector<TexelKey> keys;
    thread_local AoRayBatch aoRays;
    thread_local std::vector<uint32_t> open;
    thread_local std::vector<SurfaceInteraction> points;
    if (cs.size() < total) cs.resize(total);
    if (points.size() < total) points.resize(total);
    keys.resize(2 * total);
    HitsCameraRays(c, r, s0, s1, cs.data(), total, false, rays);
    InteractAll(c, cs.data(), total, points.data());
    aoRays.Clear();
    open.assign(total, 0);
    Cursor at(r, s0);
    const int spp = s1 - s0;
    const PixelSequence seq(c.opt, s0, s1);
    for (size_t i = 0; i < total; ++i, at.Next(r, s0, s1)) {
        CameraSample& p = cs[i];
        HitRecord& h = records[(size_t(at.y) * size_t(c.opt.width) + size_t(at.x)) * size_t(spp) +
                               size_t(at.s - s0)];
        if (!p.found || p.hit.object < 0) {
            h.mesh = !p.found ? PassTexels::kMiss : PassTexels::kLight;
            continue;
        }
        const SurfaceInteraction& si = points[i];
        BinHit(c, si, p.hit.t, bias, &keys[2 * i], &h);
        aoRays.Queue(c, p.ray, si, seq, seq.First(at.x, at.y, at.s), uint32_t(i));
    }
    aoRays.Trace(c, open.data(), rays);
    HitBins::Batch batch(bins);
    Cursor own(r, s0);
    const float perRay = 1.0f / float(std::max(c.opt.aoSamples, 1));
    const uint32_t unit = c.tsc->HitUnit();
    for (size_t i = 0; i < total; ++i, own.Next(r, s0, s1)) {
        const CameraSample& p = cs[i];
        if (!p.found || p.hit.object < 0) continue;
        ownAo[(size_t(own.y) * size_t(c.opt.width) + size_t(own.x)) * size_t(spp) +
              size_t(own.s - s0)] = float(open[i]) * perRay;
        const CountBin::Value v{open[i] * unit, uint32_t(c.opt.aoSamples) * unit};
        batch.Add(keys[2 * i], v);
        if (!(keys[2 * i + 1] == keys[2 * i])) batch.Add(keys[2 * i + 1], v);  // not clamped
    }
}

/// Hit-binned diffuse light (the path integrator, or the direct one: paths of one bounce), phase
/// 1 of a pass, for one tile. Every camera sample is path traced as per hit (same rays, same
/// random streams, opt.hitSamples paths at its hit), but at a diffuse hit the first surface is
/// white (LiPath's FirstHitLight): the light it receives, E, is binned as AO's escaped rays are, at
/// two levels above its texel, and the hit's albedo kept beside its record; phase 2
/// (PathHitsResolve) adds albedo x the bins' reconstruction. With opt.texture.cacheDirect false,
/// only E's indirect part is binned and its direct part (NEE and the first bounce's MIS-weighted
/// emission: sharp shadows) stays per hit; with deltaDirectPerHit too, the delta lights' direct
/// part stays per hit and the soft lights' is binned. An emissive surface's own emission is per
/// hit. A glossy material's diffuse base is binned the same way
/// (its albedo x (1 - F0) applied in phase 2); its specular lobe, which depends on the view, is
/// estimated by the same path (FirstHitLight::specular) and stays per hit. Everything per hit is
/// summed per pixel into `perHit` (misses, lights, specular lobes), which phase 2 adds with the
/// binned part: each pixel's sum then does not depend on the tiles, and a pass binned again (its
/// table overflowed) just writes it again.
///
/// The bins' level depends on the pass's noise, known only once every hit is shaded: this
/// phase keeps each binned hit's light and texel level (`binned`) and each pixel's noise
/// (`noise`: the variance of its samples' binned luminance, and their mean squared), and
/// PathHitsAdd bins them.
void PathHitsTrace(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                   HitRecord* records, BinnedHit* binnedHits, glm::dvec3* perHit, glm::dvec2* noise,
                   RayCounts& rays) {
    const size_t total = r.rows().size() * r.cols().size() * size_t(s1 - s0);
    thread_local std::vector<CameraSample> cs;
    if (cs.size() < total) cs.resize(total);
    // Differentials for product sampling's records and for Ptex textures' filter widths.
    const bool productDiff = c.lightSampling != LightSampling::Mis || c.textureFootprints;
    HitsCameraRays(c, r, s0, s1, cs.data(), total, productDiff, rays);
    const bool all = c.opt.texture.cacheDirect;
    const bool keepDelta = all && c.opt.texture.deltaDirectPerHit;
    const int spp = s1 - s0, paths = std::max(c.opt.hitSamples, 1);
    const int maxDepth = c.opt.integrator == IntegratorKind::Direct ? 1 : c.opt.maxDepth;
    const PixelSequence seq(c.opt, s0, s1);
    Cursor at(r, s0);
    glm::dvec3 acc(0.0);
    double sum = 0.0, sum2 = 0.0;  // the pixel's binned luminances
    int count = 0;
    for (size_t i = 0; i < total; ++i, at.Next(r, s0, s1)) {
        CameraSample& p = cs[i];
        const size_t pixel = size_t(at.y) * size_t(c.opt.width) + size_t(at.x);
        const size_t index = pixel * size_t(spp) + size_t(at.s - s0);
        HitRecord& h = records[index];
        h.mesh = PassTexels::kMiss;  // nothing binned to read (unless below)
        if (at.s == s0) acc = glm::dvec3(0.0), sum = sum2 = 0.0, count = 0;
        const RayDifferentials* diff = productDiff ? &p.diff : nullptr;
        glm::vec3 L(0.0f);
        if (!p.found) {
            L = c.Background(p.ray.dir);
        } else if (p.hit.object < 0) {
            L = SplitAtHit(c, at.x, at.y, at.s, p.rng, [&](Rng& rng, int hp) {
                const FirstBounce first(seq, seq.First(at.x, at.y, at.s) + uint64_t(hp));
                return LiPath(c, p.ray, p.hit, true, rng, maxDepth, rays, true, NoCachedTerm(),
                              diff, nullptr, &first);
            });
        } else {
            const SurfaceInteraction si = c.rs.Interact(p.ray, p.hit, diff);
            const bool glossy = c.scene.materials[si.material].type != Material::Type::Diffuse;
            glm::vec3 direct(0.0f), specular(0.0f), deltaDirect(0.0f);
            FirstHitLight split{&si, &direct, glossy ? &specular : nullptr};
            if (keepDelta) split.deltaDirect = &deltaDirect;
            const glm::vec3 E = SplitAtHit(c, at.x, at.y, at.s, p.rng, [&](Rng& rng, int hp) {
                const FirstBounce first(seq, seq.First(at.x, at.y, at.s) + uint64_t(hp));
                return LiPath(c, p.ray, p.hit, true, rng, maxDepth, rays, true, NoCachedTerm(),
                              diff, &split, &first);
            });
            // The direct light that stays per hit: none, the delta lights', or all of it.
            const glm::vec3 kept =
                (all ? (keepDelta ? deltaDirect : glm::vec3(0.0f)) : direct) / float(paths);
            // The glossy layer's specular lobe stays per hit; its diffuse base is binned.
            const glm::vec3 albedo =
                glossy ? MakeBsdf(c, si).DiffuseReflectance() : c.rs.Albedo(si);
            // An emissive surface's own light is seen per hit.
            L = specular / float(paths) + albedo * kept + c.HitEmission(p.ray, p.hit);
            const glm::vec3 binned = all && !keepDelta ? E : glm::max(E - kept, glm::vec3(0.0f));
            RadianceBin::Value v;
            // A NaN or infinite estimate is dropped, as per-hit drops such a sample.
            if (RadianceBin::FromRadiance(&binned.x, &v)) {
                const int mesh = c.tsc->MeshOf(si.object, si.backFacing);
                h = {HitRecord::Quantize(si.ptex.u), HitRecord::Quantize(si.ptex.v), mesh,
                     uint32_t(si.ptex.face) << 4};
                binnedHits[index] = {binned, albedo, HitTexelLevel(c, si, p.hit.t, mesh)};
                const double e = double(Luminance(binned));
                sum += e, sum2 += e * e, ++count;
            }
        }
        // A NaN/Inf sample would poison the pixel forever: drop it (as ShadeTile does).
        if (std::isfinite(L.x) && std::isfinite(L.y) && std::isfinite(L.z)) acc += glm::dvec3(L);
        if (at.s == s1 - 1) {
            perHit[pixel] = acc;
            const double mean = count ? sum / count : 0.0;
            noise[pixel] =
                count >= 2
                    ? glm::dvec2(std::max(0.0, sum2 - count * mean * mean) / double(count - 1),
                                 mean * mean)
                    : glm::dvec2(0.0);
        }
    }
}

/// Hit-binned diffuse light, phase 1 of a pass continued (PathHitsTrace shaded the hits): adds
/// each binned hit of the tile to its bins at the levels `bias` and `bias` + 1 above its texel's,
/// and sets the level its record reads. Binning again (the table overflowed) adds the same.
void PathHitsAdd(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1, int bias,
                 float blend, HitRecord* records, const BinnedHit* binnedHits, RadianceBins& bins,
                 bool frameStore) {
    RadianceBins::Batch batch(bins);
    const int spp = s1 - s0;
    const uint64_t unit = c.tsc->HitUnit();
    for (int y = r.rows().begin(); y < r.rows().end(); ++y)
        for (int x = r.cols().begin(); x < r.cols().end(); ++x)
            for (int s = s0; s < s1; ++s) {
                const size_t index =
                    (size_t(y) * size_t(c.opt.width) + size_t(x)) * size_t(spp) + size_t(s - s0);
                HitRecord& h = records[index];
                if (h.mesh < 0) continue;
                const BinnedHit& b = binnedHits[index];
                const MeshGrids& g = c.tsc->Grids(h.mesh);
                int levels[2];
                ObjectBinLevels(c, c.tsc->ObjectOfMesh(h.mesh), bias, frameStore, levels);
                // Nothing to add for a record that only reads (the frame buffers' hits outside
                // the frame's budget carry NaN light, most of a frame's): its level, not its
                // bins. Finite light was checked when shaded.
                RadianceBin::Value v;
                if (RadianceBin::FromRadiance(&b.light.x, &v)) {
                    TexelKey keys[2];
                    BinKeys(g, h.Face(), h.U(), h.V(), b.texelLevel, levels[0], keys);
                    if (levels[1] == levels[0]) keys[1] = keys[0];
                    for (uint64_t& w : v.sum) w *= unit;
                    v.count *= unit;
                    batch.Add(keys[0], v);
                    if (!(keys[1] == keys[0])) batch.Add(keys[1], v);  // not clamped
                }
                const int upper = levels[1] != levels[0] && ReadsUpperLevel(c, x, y, s, blend);
                h.faceLevel = uint32_t(h.Face()) << 4 |
                              uint32_t(g.ClampMip(h.Face(), b.texelLevel + levels[upper]));
            }
}

size_t BoundBrightHits(int width, int height, glm::vec3* light, const int32_t* group,
                       const float* prior, float ratio, StoreBoundScratch& scratch) {
    const size_t n = size_t(std::max(width, 0)) * size_t(std::max(height, 0));
    if (n == 0 || !(ratio > 0.0f)) return 0;
    // Every pass reads the previous one's arrays and writes its own pixel's entries only: the
    // result does not depend on how the rows are split between threads.
    scratch.luminance.resize(n);
    float* luminance = scratch.luminance.data();
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, n, 8192), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t p = r.begin(); p < r.end(); ++p) {
                const glm::vec3& L = light[p];
                const bool ok =
                    std::isfinite(L.x + L.y + L.z) && L.x >= 0.0f && L.y >= 0.0f && L.z >= 0.0f;
                luminance[p] = ok ? Luminance(L) : -1.0f;
            }
        });
    constexpr int R = kStoreBoundRadius;
    auto window = [&](int x, int y, auto&& visit) {
        const size_t p = size_t(y) * size_t(width) + size_t(x);
        for (int qy = std::max(0, y - R); qy <= std::min(height - 1, y + R); ++qy)
            for (int qx = std::max(0, x - R); qx <= std::min(width - 1, x + R); ++qx) {
                const size_t q = size_t(qy) * size_t(width) + size_t(qx);
                if (q != p && luminance[q] >= 0.0f && group[q] == group[p]) visit(q);
            }
    };
    // Each hit's share of its excess for each of its neighbours (0: not bounded), and the rows
    // that hold a bounded hit. Both are all 0 between calls (reset below where set).
    scratch.share.resize(n, glm::vec3(0.0f));
    glm::vec3* share = scratch.share.data();
    std::vector<uint8_t> rowBounded(size_t(height), 0);
    std::atomic<size_t> bounded{0};
    tbb::parallel_for(tbb::blocked_range<int>(0, height, 4), [&](const tbb::blocked_range<int>& r) {
        float others[(2 * R + 1) * (2 * R + 1)];
        size_t count = 0;
        for (int y = r.begin(); y < r.end(); ++y)
            for (int x = 0; x < width; ++x) {
                const size_t p = size_t(y) * size_t(width) + size_t(x);
                if (!(luminance[p] >= 0.0f)) continue;
                // The reference is at least the prior: a hit under ratio x its prior stays as it
                // is whatever its neighbours' median, which is then not sought (most traced hits
                // of a warm store).
                const float pr = prior ? prior[p] : 0.0f;
                if (pr < INFINITY && luminance[p] <= ratio * pr) continue;
                int k = 0, dimmer = 0;
                double sum = 0.0;
                const float L = luminance[p];
                window(x, y, [&](size_t q) {
                    others[k++] = luminance[q], sum += luminance[q];
                    dimmer += ratio * luminance[q] < L ? 1 : 0;
                });
                // The median others[k / 2] is within the bound (ratio x it >= L) exactly when
                // at most k / 2 of the others are under it (ratio x is monotonic): most hits of
                // a young store, which then need no selection.
                if (k >= kStoreBoundMinOthers && 2 * dimmer <= k) continue;
                float reference = 0.0f;
                if (k >= kStoreBoundMinOthers) {
                    std::nth_element(others, others + k / 2, others + k);
                    reference = others[k / 2];
                    // Mostly dark around it: their mean still says what light there is.
                    if (!(reference > 0.0f)) reference = float(sum / double(k));
                }
                if (pr > reference && pr < INFINITY) reference = pr;
                const float bound = ratio * reference;
                // Nothing to compare it with, or no one to give the excess to: left alone.
                if (!(bound > 0.0f) || luminance[p] <= bound || k == 0) continue;
                share[p] = light[p] * ((1.0f - bound / luminance[p]) / float(k));
                rowBounded[size_t(y)] = 1;
                ++count;
            }
        bounded.fetch_add(count, std::memory_order_relaxed);
    });
    if (bounded.load() == 0) return 0;
    // Each bounded hit keeps its bounded part and gives its share to each of its window's hits,
    // in pixel order (few: serial, so the sums are the same for any thread count). A share was
    // taken from its hit's light before any gift, so the order changes only the rounding.
    auto forBounded = [&](auto&& body) {
        for (int y = 0; y < height; ++y) {
            if (!rowBounded[size_t(y)]) continue;
            for (int x = 0; x < width; ++x) {
                const size_t p = size_t(y) * size_t(width) + size_t(x);
                if (share[p] != glm::vec3(0.0f)) body(x, y, p);
            }
        }
    };
    forBounded([&](int x, int y, size_t p) {
        int k = 0;
        window(x, y, [&](size_t q) { light[q] += share[p], ++k; });
        light[p] -= share[p] * float(k);
    });
    forBounded([&](int x, int y, size_t p) {
        light[p] = glm::max(light[p], glm::vec3(0.0f));
        window(x, y, [&](size_t q) { light[q] = glm::max(light[q], glm::vec3(0.0f)); });
    });
    for (int y = 0; y < height; ++y)
        if (rowBounded[size_t(y)])
            std::fill(share + size_t(y) * size_t(width), share + size_t(y + 1) * size_t(width),
                      glm::vec3(0.0f));
    return bounded.load();
}

StoreHitBounds BoundStoreHits(const Context& c, const HitRecord* records, float ratio,
                              BinnedHit* binned) {
    const int W = c.opt.width, H = c.opt.height;
    const size_t n = size_t(W) * size_t(H);
    StoreBoundScratch& scratch = c.tsc->BoundScratch();
    scratch.light.resize(n), scratch.prior.resize(n), scratch.group.resize(n);
    glm::vec3* light = scratch.light.data();
    float* prior = scratch.prior.data();
    int32_t* group = scratch.group.data();
    // Each row's traced hits and their summed luminance before and after, per block of rows
    // (added in block order: the same sums for any thread count).
    const int rowsPerBlock = 16, blocks = (H + rowsPerBlock - 1) / rowsPerBlock;
    std::vector<double> before(size_t(blocks), 0.0), after(size_t(blocks), 0.0);
    std::vector<uint64_t> traced(size_t(blocks), 0);
    auto rows = [&](auto&& body) {
        tbb::parallel_for(tbb::blocked_range<int>(0, blocks),
                          [&](const tbb::blocked_range<int>& r) {
                              for (int b = r.begin(); b < r.end(); ++b)
                                  body(b, size_t(b * rowsPerBlock) * size_t(W),
                                       size_t(std::min(H, (b + 1) * rowsPerBlock)) * size_t(W));
                          });
    };
    rows([&](int b, size_t p0, size_t p1) {
        for (size_t p = p0; p < p1; ++p) {
            group[p] = records[p].mesh;
            // NaN: a hit that only reads, or no hit.
            light[p] = records[p].mesh >= 0 ? binned[p].light : glm::vec3(NAN);
            prior[p] = records[p].mesh >= 0 ? binned[p].prior : 0.0f;
            if (std::isfinite(light[p].x + light[p].y + light[p].z))
                ++traced[size_t(b)], before[size_t(b)] += Luminance(light[p]);
        }
    });
    StoreHitBounds out;
    out.bounded = BoundBrightHits(W, H, light, group, prior, ratio, scratch);
    rows([&](int b, size_t p0, size_t p1) {
        for (size_t p = p0; p < p1; ++p)
            if (records[p].mesh >= 0 && std::isfinite(light[p].x + light[p].y + light[p].z)) {
                binned[p].light = light[p];
                after[size_t(b)] += Luminance(light[p]);
            }
    });
    double sumBefore = 0.0, sumAfter = 0.0;
    for (int b = 0; b < blocks; ++b)
        out.traced += traced[size_t(b)], sumBefore += before[size_t(b)],
            sumAfter += after[size_t(b)];
    out.keptLight = sumBefore > 0.0 ? sumAfter / sumBefore : 1.0;
    return out;
}

void FrameHitRecord(const Context& c, const SurfaceInteraction& si, float t, int bias, HitRecord* h,
                    int* texelLevel) {
    const int mesh = c.tsc->MeshOf(si.object, si.backFacing);
    *texelLevel = HitTexelLevel(c, si, t, mesh);
    *h = {HitRecord::Quantize(si.ptex.u), HitRecord::Quantize(si.ptex.v), mesh,
          uint32_t(si.ptex.face) << 4};
    TexelKey keys[2];
    ObjectBinKeys(c, si.object, c.tsc->Grids(mesh), si.ptex.face, h->U(), h->V(), *texelLevel, bias,
                  keys, true);
    h->faceLevel |= keys[0].mip;
}

}  // namespace texcache::internal

namespace texcache {

size_t BoundBrightHits(int width, int height, glm::vec3* light, const int32_t* group,
                       const float* prior, float ratio) {
    internal::StoreBoundScratch scratch;
    return internal::BoundBrightHits(width, height, light, group, prior, ratio, scratch);
}

}  // namespace texcache
