// SPDX-License-Identifier: Apache-2.0
// Camera samples shaded where they hit: a tile's samples traced in packets, then each one shaded
// by its integrator (debug views, ambient occlusion, direct light, path tracing; through the
// texture-space cache when it shades), in the order of a single-ray loop so that a pixel's sum
// does not depend on the tiling. Also the AOV layers those samples fill. The general path of a
// pass (render.cpp picks it when no specialised stage applies).
#include <cmath>
#include <string>
#include <utility>

#include "renderer/render_internal.h"

namespace texcache::internal {

namespace {

/// A colour per id, for the Ptex face view.
glm::vec3 HashColor(uint32_t id) {
    uint64_t h = MixBits(uint64_t(id) + 0x9E3779B97F4A7C15ull);
    return glm::vec3(float(h & 0xFF), float((h >> 8) & 0xFF), float((h >> 16) & 0xFF)) / 255.0f;
}

/// Adds what camera sample `ray`, hitting `si`, contributes to its pixel's AOVs.
void FillAovs(const Context& c, const Ray& ray, const Hit& hit, const SurfaceInteraction& si,
              PixelAovs* aov) {
    aov->albedo += c.rs.Albedo(si);
    aov->normal += si.N;
    aov->depth += hit.t;
    if (aov->hits++ == 0) aov->ptex = {float(si.ptex.face), si.ptex.u, si.ptex.v};
    if (c.shutterLength > 0.0f) {
        // Where this surface point is at shutter open and close, in film pixels.
        const glm::mat4 M = c.rs.ObjectToWorld(hit.object, ray.time);
        const glm::vec4 pObj = glm::inverse(M) * glm::vec4(si.P, 1.0f);
        glm::vec2 f0, f1;
        if (c.cameraOpen->Project(glm::vec3(c.rs.ObjectToWorld(hit.object, 0.0f) * pObj), &f0) &&
            c.cameraClose->Project(glm::vec3(c.rs.ObjectToWorld(hit.object, 1.0f) * pObj), &f1))
            aov->motion += f1 - f0;
    }
}

/// Differentials feed the cache's mip selection and the debug views; they are skipped otherwise.
bool NeedsDifferentials(const Context& c) {
    return c.tsc != nullptr || c.psrCache != nullptr ||
           c.opt.integrator == IntegratorKind::Normal || c.opt.integrator == IntegratorKind::Ptex ||
           c.opt.integrator == IntegratorKind::Uv;
}

/// What camera sample `cs` (pixel (x, y), sample s) sees, its ray already traced.
glm::vec3 ShadeCameraSample(const Context& c, int x, int y, int s, CameraSample& cs, PixelAovs* aov,
                            const PixelSequence& seq, RayCounts& rays) {
    const bool needDiff = NeedsDifferentials(c);
    const Ray& ray = cs.ray;
    const Hit& hit = cs.hit;
    const bool found = cs.found;
    Rng& rng = cs.rng;
    const RayDifferentials& diff = cs.diff;

    const IntegratorKind k = c.opt.integrator;
    if (k == IntegratorKind::Direct || k == IntegratorKind::Path) {
        // A camera ray that hits nothing sees the environment (and the suns' discs), whatever the
        // integrator does at
        // hits (LiPath's first miss: no MIS weight): most samples of an object under a sky. Not
        // through LiPath, whose call and 1 KB stack frame would weigh on a sky-only frame.
        if (!found) return c.Background(ray.dir);
        // Differentials tell LiPath that its first hit is a camera hit, which product sampling
        // needs; otherwise none, so that MIS does not compute a footprint it never uses.
        const RayDifferentials* productDiff =
            c.lightSampling != LightSampling::Mis ? &diff : nullptr;
        if (aov && found && hit.object >= 0) FillAovs(c, ray, hit, c.rs.Interact(ray, hit), aov);
        if (c.tsc && k == IntegratorKind::Path) {
            // Diffuse light is view-independent: diffuse materials and the diffuse base of
            // glossy ones take it from the cache (direct + indirect, or indirect only); the
            // specular lobe stays per hit (view-dependent).
            auto cached = [&](const SurfaceInteraction& si0, const Ray& r0, glm::vec3* term) {
                const bool all = c.opt.texture.cacheDirect;
                const bool glossy = c.scene.materials[si0.material].type != Material::Type::Diffuse;
                const SurfaceInteraction sd = c.rs.Interact(r0, hit, &diff);
                const glm::vec3 E = CachedLookup(
                    c, sd,
                    [&](const SampleRequest& r) { return ShadeDiffuseSample(c, r, all, rays); },
                    c.opt.texture.indirectSamples);
                if (glossy) {
                    *term = MakeBsdf(c, si0).DiffuseReflectance() * E;
                    return all ? CachedTerm::DiffuseBase : CachedTerm::BaseIndirect;
                }
                *term = c.rs.Albedo(si0) * E;
                return all ? CachedTerm::All : CachedTerm::Indirect;
            };
            return SplitAtHit(c, x, y, s, rng, [&](Rng& r, int h) {
                const FirstBounce first(seq, seq.First(x, y, s) + uint64_t(h));
                return LiPath(c, ray, hit, found, r, c.opt.maxDepth, rays, true, cached,
                              productDiff, nullptr, &first);
            });
        }
        if (c.tsc && k == IntegratorKind::Direct)
            return SplitAtHit(c, x, y, s, rng, [&](Rng& r, int) {
                return LiDirectCachedShadows(c, ray, hit, found, r, diff, rays);
            });
        return SplitAtHit(c, x, y, s, rng, [&](Rng& r, int h) {
            const FirstBounce first(seq, seq.First(x, y, s) + uint64_t(h));
            return LiPath(c, ray, hit, found, r, k == IntegratorKind::Direct ? 1 : c.opt.maxDepth,
                          rays, true, NoCachedTerm(), productDiff, nullptr, &first);
        });
    }
    if (!found) return glm::vec3(0.0f);
    if (hit.object < 0) return glm::vec3(1.0f);  // a light seen by a debug view: white
    const SurfaceInteraction si = c.rs.Interact(ray, hit, needDiff ? &diff : nullptr);
    if (aov) FillAovs(c, ray, hit, si, aov);
    switch (k) {
        case IntegratorKind::Normal:
            return si.N * 0.5f + 0.5f;
        case IntegratorKind::Ptex:
            return HashColor(uint32_t(si.ptex.face) * 7919u + uint32_t(si.object));
        case IntegratorKind::Uv:
            return glm::vec3(si.ptex.u, si.ptex.v, 0.0f);
        case IntegratorKind::EyeLight:
            return c.rs.Albedo(si) * std::abs(glm::dot(si.N, ray.dir));
        case IntegratorKind::AO:
            if (c.tsc)
                return CachedLookup(
                    c, si, [&](const SampleRequest& r) { return ShadeAoSample(c, r, rays); },
                    c.opt.aoSamples);
            return LiAO(c, ray, si, seq, seq.First(x, y, s), rays);
        default:
            return glm::vec3(0.0f);
    }
}

}  // namespace

/// Samples [s0, s1) of every pixel of a tile, added to the frame's sums. The camera rays go
/// to Embree 16 at a time (RenderScene::Intersect16), in blocks of 64 consecutive (pixel,
/// sample) pairs, then each sample is shaded in the order of the single-ray loop, with the same
/// random numbers. Camera rays are most of the rays of a path-traced frame of an object under a
/// sky, and traced one by one they cost several times a packet's per-ray time (`texcache bench
/// peer` measures both).
void ShadeTile(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
               FrameSums& sums, CacheStats* pixelStats, RayCounts& rays) {
    const int W = c.opt.width;
    const size_t total = r.rows().size() * r.cols().size() * size_t(s1 - s0);
    const bool needDiff = NeedsDifferentials(c);
    const PixelSequence seq(c.opt, s0, s1);
    CameraSample block[kCameraBlock];
    Cursor gen(r, s0), shade = gen;
    // A tile outside the scene's projection: every camera ray misses (Context::hitRect).
    const bool sky =
        c.hitRect.Outside(r.cols().begin(), r.rows().begin(), r.cols().end(), r.rows().end());
    const bool pinhole = c.camera.IsPinhole() && !c.cameraMoves && !needDiff;
    glm::dvec3 acc(0.0);  // the current pixel's sum
    CacheSnapshot before;
    for (size_t b = 0; b < total; b += kCameraBlock) {
        const size_t n = std::min(kCameraBlock, total - b);
        if (pinhole)
            PinholeCameraRays(c, r, s0, s1, gen, block, n);
        else
            for (size_t i = 0; i < n; ++i, gen.Next(r, s0, s1))
                CameraRay(c, gen.x, gen.y, gen.s, &block[i].rng, &block[i].ray,
                          needDiff ? &block[i].diff : nullptr);
        IntersectCameraRays(c, block, n, rays, sky);
        // Shade in the single-ray loop's order; a pixel's sum is added once, when its last
        // sample is done (its samples may span two blocks), so it does not depend on the tile.
        for (size_t i = 0; i < n; ++i, shade.Next(r, s0, s1)) {
            const size_t p = size_t(shade.y) * W + shade.x;
            PixelAovs* aov = sums.aovs.empty() ? nullptr : &sums.aovs[p];
            if (shade.s == s0) {
                acc = glm::dvec3(0.0);
                if (pixelStats) before = CacheSnapshot(*pixelStats);
            }
            const glm::vec3 L =
                ShadeCameraSample(c, shade.x, shade.y, shade.s, block[i], aov, seq, rays);
            // A NaN/Inf sample would poison the pixel forever: drop it.
            if (std::isfinite(L.x) && std::isfinite(L.y) && std::isfinite(L.z))
                acc += glm::dvec3(L);
            if (shade.s == s1 - 1) {
                double* px = &sums.rgb[3 * p];
                px[0] += acc.x, px[1] += acc.y, px[2] += acc.z;
                if (pixelStats) AddPixelCounts(&c.pixelCache[p], before, *pixelStats);
            }
        }
    }
}

/// The requested AOV layers: means over the `spp` samples of each pixel.
std::vector<ImageLayer> AovLayers(const std::vector<PixelAovs>& aovs, const AovFlags& flags, int W,
                                  int H, int spp) {
    std::vector<ImageLayer> layers;
    if (aovs.empty()) return layers;
    auto layer = [&](const char* name, int ch, std::vector<std::string> names, auto fill) {
        ImageLayer l{name, Image(W, H, ch), std::move(names)};
        for (size_t p = 0; p < aovs.size(); ++p) fill(aovs[p], &l.image.data[p * ch]);
        layers.push_back(std::move(l));
    };
    const float inv = 1.0f / float(spp);
    if (flags.albedo)
        layer("albedo", 3, {"R", "G", "B"}, [&](const PixelAovs& a, float* o) {
            for (int k = 0; k < 3; ++k) o[k] = a.albedo[k] * inv;
        });
    if (flags.normal)
        layer("normal", 3, {"X", "Y", "Z"}, [&](const PixelAovs& a, float* o) {
            const float l = glm::length(a.normal);
            for (int k = 0; k < 3; ++k) o[k] = l > 0.0f ? a.normal[k] / l : 0.0f;
        });
    if (flags.depth)
        layer("depth", 1, {"Z"}, [&](const PixelAovs& a, float* o) {
            o[0] = a.hits ? a.depth / float(a.hits) : INFINITY;
        });
    if (flags.ptex)
        layer("ptex", 3, {"face", "u", "v"}, [&](const PixelAovs& a, float* o) {
            o[0] = a.hits ? a.ptex.x : -1.0f, o[1] = a.ptex.y, o[2] = a.ptex.z;
        });
    if (flags.motion)
        layer("motion", 2, {"X", "Y"}, [&](const PixelAovs& a, float* o) {
            o[0] = a.hits ? a.motion.x / float(a.hits) : 0.0f;
            o[1] = a.hits ? a.motion.y / float(a.hits) : 0.0f;
        });
    return layers;
}

}  // namespace texcache::internal
