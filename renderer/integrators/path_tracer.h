// SPDX-License-Identifier: Apache-2.0
// The path tracer's core, shared by the renderers of this directory (render.cpp: images;
// frame_buffers_render.cpp: the screen-space stage's buffers; cached_shading.cpp: the samples of
// the texture-space cache): a frame's lights and camera resolved once (Context), next-event
// estimation with MIS (LiPath) and ambient occlusion (LiAO). Internal to renderer/.
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include <tbb/enumerable_thread_specific.h>

#include "renderer/integrators/bsdf.h"
#include "renderer/integrators/product_sampling.h"
#include "renderer/integrators/sampling.h"
#include "renderer/render_options.h"
#include "renderer/scene/camera.h"
#include "renderer/scene/envmap.h"
#include "renderer/scene/lights.h"
#include "renderer/scene/render_scene.h"

namespace texcache {

class TextureSpaceCache;

namespace internal {

struct RayCounts {
    uint64_t camera = 0, shadow = 0, bounce = 0;
    uint64_t cameraCulled = 0;  // camera samples not traced: outside Context::hitRect
};

/// Offsets a ray origin off the surface along the geometric normal, scaled to the coordinates'
/// magnitude so that float rounding of large scenes cannot re-hit the surface.
inline glm::vec3 OffsetOrigin(glm::vec3 p, glm::vec3 ng, glm::vec3 dir) {
    const float scale = std::max({1.0f, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
    const float eps = 2e-5f * scale;
    return p + (glm::dot(dir, ng) >= 0.0f ? eps : -eps) * ng;
}

struct LightSample {
    glm::vec3 wi;  // towards the light
    float dist;    // to the light (inf for env/distant)
    glm::vec3 Li;  // incident radiance (irradiance for delta lights)
    float pdf;     // solid angle, includes light selection; 0 for delta lights (no MIS)
    bool delta;
    int quad = -1;     // the quad light sampled, -1 for other lights
    int distant = -1;  // the distant light sampled, -1 for other lights
    int sphere = -1;   // the point or spot light sampled (Scene::pointLights), -1 for others
    int emitter = -1;  // the emissive object sampled (Context::emitters), -1 for others
};

/// A sample of an environment map drawn ahead of the rays that use it (a frame's table of them:
/// Context::envTable).
struct EnvironmentSampleEntry {
    glm::vec3 wi;
    float pdf;  // solid angle, light selection included; 0: no sample
    glm::vec3 Li;
};

/// Everything the per-sample code reads, resolved once per frame.
struct Context {
    const RenderScene& rs;
    const Scene& scene;
    const RenderOptions& opt;
    const EnvironmentMap* env;
    CameraModel camera;
    std::vector<glm::vec3> distantDir;  // towards the light, world space at frame time
    std::vector<glm::vec3> distantE;
    struct Quad {
        glm::vec3 corner, e1, e2, n, L;
        float area;
        bool twoSided;
    };
    std::vector<Quad> quads;
    std::vector<SunDisc> suns;         // per distant light (delta: an angular size of 0)
    bool sunDiscs = false;             // some distant light has an angular size
    std::vector<SphereLight> spheres;  // per Scene::pointLights
    std::vector<MeshEmitter> emitters;
    std::vector<int> emitterOf;  // per object: its index in `emitters`, -1 if it emits nothing
    // The lights SampleLight picks from, in its order: quads, distant lights, spheres, emitters,
    // the environment; each with probability 1 / numLights (uniform light selection).
    int numLights = 0;
    /// Some material emits (RenderScene::Emission): rays that find a surface add its emission.
    bool emissive = false;
    /// Some material reads a Ptex texture: camera hits compute their footprint (ray
    /// differentials), which picks the texture's filter width.
    bool textureFootprints = false;
    float shutterLength;
    TextureSpaceCache* tsc = nullptr;
    tbb::enumerable_thread_specific<CacheStats>* cacheStats = nullptr;
    PixelCacheCounts* pixelCache = nullptr;              // per-pixel cache traffic, when asked for
    std::optional<CameraModel> cameraOpen, cameraClose;  // for motion vectors
    bool cameraMoves = false;
    /// opt.lightSampling, or Mis without an environment map (nothing to take a product with).
    LightSampling lightSampling = LightSampling::Mis;
    ProductRecordCache* psrCache = nullptr;  // set by the renderer for Cpis
    tbb::enumerable_thread_specific<RecordStats>* psrStats = nullptr;
    /// A table of the map's samples, each distributed as EnvironmentMap::Sample's (for a map,
    /// whatever the normal), that SampleLight reads instead of inverting the map's tables: those
    /// two dependent searches and a texel lookup run out of the caches, a table entry of a
    /// frame's table stays in them. `envTableMask` + 1 entries, a power of two; null: none.
    const EnvironmentSampleEntry* envTable = nullptr;
    uint32_t envTableMask = 0;

    /// Pixels [x0, x1) x [y0, y1) hold every camera sample that can hit something: the
    /// projection of the scene's bounds, plus a margin. Samples of other pixels miss, and are
    /// not traced (most of an object under a sky: ShadeTile). Everything when the camera has a
    /// lens or moves, the scene moves, or the bounds reach behind the camera.
    struct PixelRect {
        int x0, y0, x1, y1;
        bool Outside(int bx0, int by0, int bx1, int by1) const {
            return bx1 <= x0 || bx0 >= x1 || by1 <= y0 || by0 >= y1;
        }
    } hitRect;

    Context(const RenderScene& r, const RenderOptions& o);

    float PickPdf() const { return numLights > 0 ? 1.0f / float(numLights) : 0.0f; }

    // Radiance emitted by quad light `l` towards -dir, seen from a surface.
    glm::vec3 QuadEmission(int l, glm::vec3 dir) const {
        const Quad& q = quads[l];
        const float c = glm::dot(q.n, -dir);
        return (c > 0.0f || q.twoSided) ? q.L : glm::vec3(0.0f);
    }
    float QuadPdf(int l, glm::vec3 dir, float dist) const {
        const Quad& q = quads[l];
        const float c = std::abs(glm::dot(q.n, dir));
        return c > 0.0f ? dist * dist / (q.area * c) * PickPdf() : 0.0f;
    }
    int FirstSphere() const { return int(quads.size() + distantDir.size()); }
    int FirstEmitter() const { return FirstSphere() + int(spheres.size()); }

    /// Radiance a ray receives from the sampled lights it hit: a light's (quad, sphere) or an
    /// emissive object's; 0 from any other surface.
    glm::vec3 SampledEmission(const Ray& ray, const Hit& hit) const {
        if (hit.light >= 0)
            return hit.light < int(quads.size())
                       ? QuadEmission(hit.light, ray.dir)
                       : spheres[size_t(hit.light) - quads.size()].Emission(ray.org, ray.dir);
        const int e = emitters.empty() ? -1 : emitterOf[size_t(hit.object)];
        if (e < 0) return glm::vec3(0.0f);
        return emitters[size_t(e)].Emission(MeshEmitter::Triangle(hit.primID, hit.U, hit.V),
                                            ray.dir);
    }
    /// What an emitting material (RenderScene::Emission) sends from the hit: found by rays only,
    /// never sampled as a light, so it takes no MIS weight.
    glm::vec3 SurfaceEmission(const Hit& hit) const {
        return emissive && hit.light < 0 ? rs.Emission(hit) : glm::vec3(0.0f);
    }
    /// Everything a ray receives from what it hit.
    glm::vec3 HitEmission(const Ray& ray, const Hit& hit) const {
        return SampledEmission(ray, hit) + SurfaceEmission(hit);
    }
    /// The solid-angle density with which SampleLight, from the ray's origin, samples the point
    /// the ray hit (the light's pick included): the MIS partner of a BSDF sample that found it.
    float HitLightPdf(const Ray& ray, const Hit& hit) const {
        if (hit.light >= 0)
            return hit.light < int(quads.size())
                       ? QuadPdf(hit.light, ray.dir, hit.t)
                       : spheres[size_t(hit.light) - quads.size()].Pdf(ray.org) * PickPdf();
        const int e = emitters.empty() ? -1 : emitterOf[size_t(hit.object)];
        if (e < 0) return 0.0f;
        return emitters[size_t(e)].Pdf(MeshEmitter::Triangle(hit.primID, hit.U, hit.V), ray.dir,
                                       hit.t) *
               PickPdf();
    }
    /// HitEmission weighted against the BSDF sample of density `bsdfPdf` that found it (power
    /// heuristic); unweighted for a ray that was not a BSDF sample (bsdfPdf 0: a camera ray).
    glm::vec3 EmittedMis(const Ray& ray, const Hit& hit, float bsdfPdf) const {
        const glm::vec3 Le = SampledEmission(ray, hit), own = SurfaceEmission(hit);
        if (!(bsdfPdf > 0.0f) || Le == glm::vec3(0.0f)) return Le + own;
        return Le * PowerHeuristic(1, bsdfPdf, 1, HitLightPdf(ray, hit)) + own;
    }
    /// Radiance of the suns' discs along `dir` (a ray that left the scene), weighted against
    /// the BSDF sample of density `bsdfPdf` (0: unweighted).
    glm::vec3 SunRadiance(glm::vec3 dir, float bsdfPdf) const {
        glm::vec3 L(0.0f);
        if (!sunDiscs) return L;
        for (const SunDisc& sun : suns)
            if (!sun.IsDelta() && sun.Contains(dir))
                L += sun.radiance *
                     (bsdfPdf > 0.0f ? PowerHeuristic(1, bsdfPdf, 1, sun.Pdf() * PickPdf()) : 1.0f);
        return L;
    }
    /// What a camera ray that hits nothing sees: the environment and the suns' discs.
    glm::vec3 Background(glm::vec3 dir) const {
        return (env ? env->Eval(dir) : glm::vec3(0.0f)) + SunRadiance(dir, 0.0f);
    }

    /// One light sample for the surface point `p` of shading normal `n` (facing the viewer); the
    /// environment is sampled from `psr` when given (a valid record).
    bool SampleLight(glm::vec3 p, glm::vec3 n, float uPick, glm::vec2 u, LightSample* s,
                     const ProductRecord* psr = nullptr) const {
        if (numLights == 0) return false;
        int i = std::min(int(uPick * float(numLights)), numLights - 1);
        if (i < int(quads.size())) {
            const Quad& q = quads[i];
            if (!Towards(p, q.corner + u.x * q.e1 + u.y * q.e2, &s->wi, &s->dist)) return false;
            s->Li = QuadEmission(i, s->wi);
            s->pdf = QuadPdf(i, s->wi, s->dist);
            s->delta = false;
            s->quad = i;
            return s->pdf > 0.0f && s->Li != glm::vec3(0.0f);
        }
        i -= int(quads.size());
        if (i < int(distantDir.size())) {
            const SunDisc& sun = suns[size_t(i)];
            s->dist = INFINITY;
            s->distant = i;
            if (!sun.IsDelta()) {
                s->wi = sun.Sample(u);
                s->Li = sun.radiance;
                s->pdf = sun.Pdf() * PickPdf();
                s->delta = false;
                return true;
            }
            s->wi = distantDir[i];
            s->Li = distantE[i] * float(numLights);  // divided by the pick probability
            s->pdf = 0.0f;
            s->delta = true;
            return true;
        }
        i -= int(distantDir.size());
        if (i < int(spheres.size() + emitters.size())) {
            LightPoint lp;
            const bool sphere = i < int(spheres.size());
            if (sphere ? !spheres[size_t(i)].Sample(p, u, &lp)
                       : !emitters[size_t(i) - spheres.size()].Sample(p, u, &lp))
                return false;
            s->wi = lp.wi;
            s->dist = lp.dist;
            s->delta = !(lp.pdf > 0.0f);
            // A delta light's irradiance, divided by the pick probability.
            s->Li = s->delta ? lp.Li * float(numLights) : lp.Li;
            s->pdf = lp.pdf * PickPdf();
            (sphere ? s->sphere : s->emitter) = sphere ? i : i - int(spheres.size());
            return true;
        }
        float pdf;
        if (psr) {
            // The pick's leftover: uniform and independent of u.
            const float uWalk =
                std::min(uPick * float(numLights) - float(numLights - 1), kOneMinusEpsilon);
            if (!SampleProductLight(*psr, *env, n, u, uWalk, &s->wi, &pdf, &s->Li)) return false;
        } else if (envTable) {
            // Entry u.x of the table: a sample of the map, as Sample's would be.
            const EnvironmentSampleEntry& e =
                envTable[uint32_t(u.x * float(envTableMask + 1u)) & envTableMask];
            s->wi = e.wi, s->Li = e.Li, s->pdf = e.pdf;
            s->dist = INFINITY;
            s->delta = false;
            return s->pdf > 0.0f;
        } else {
            s->Li = env->Sample(n, u, &s->wi, &pdf);
        }
        s->pdf = pdf * PickPdf();
        s->dist = INFINITY;
        s->delta = false;
        return s->pdf > 0.0f;
    }
};

inline Bsdf MakeBsdf(const Context& c, const SurfaceInteraction& si, bool diffuseLobe = true) {
    const Material& m = c.scene.materials[si.material];
    const bool ggx = m.type == Material::Type::GGX;
    const float r = ggx ? c.rs.Roughness(si) : 1.0f;
    // Anisotropic ("brushed"): roughness along the Ptex u direction, and across it.
    const glm::vec2 roughness(r, m.anisotropic ? m.roughnessV : r);
    // Without its diffuse lobe (a black base): a glossy hit whose base light is cached.
    const glm::vec3 albedo = diffuseLobe ? c.rs.Albedo(si) : glm::vec3(0.0f);
    return Bsdf(si.N, si.Ng, albedo, ggx, roughness, ggx ? c.rs.Specular(si) : glm::vec3(0.04f),
                si.dPdu);
}

/// A ray leaving the surface at `si` in direction `wi` (offset off the surface, unbounded).
inline Ray SpawnRay(const SurfaceInteraction& si, glm::vec3 wi) {
    Ray ray;
    ray.org = OffsetOrigin(si.P, si.Ng, wi);
    ray.dir = wi;
    return ray;
}

/// The shadow ray of a light sample, stopping just short of an area light's surface.
inline Ray ShadowRay(const SurfaceInteraction& si, const LightSample& ls, float time) {
    Ray shadow;
    shadow.org = OffsetOrigin(si.P, si.Ng, ls.wi);
    shadow.dir = ls.wi;
    shadow.tfar = std::isinf(ls.dist) ? INFINITY : ls.dist * (1.0f - 1e-4f);
    shadow.time = time;
    return shadow;
}

/// What a cached term at a camera hit replaces (LiPath's `cached`): nothing; the indirect
/// light of a diffuse surface (direct light still per hit); all its light; all the light of a
/// glossy material's diffuse base, the path going on with the specular lobe alone; or the
/// indirect light of a glossy material's diffuse base (both lobes' direct light per hit, the
/// path going on past the first BSDF ray's hit with the specular lobe's weight alone).
enum class CachedTerm { None, Indirect, All, DiffuseBase, BaseIndirect };

struct NoCachedTerm {
    CachedTerm operator()(const SurfaceInteraction&, const Ray&, glm::vec3*) const {
        return CachedTerm::None;
    }
};

/// The product sampling record of a camera hit, in `storage`, or null when the hit samples the
/// environment as MIS does (light sampling mis, no record for the lobe, see
/// BuildProductRecord). Records exist for camera hits only: a cached one is keyed by texel, and
/// it is built for the camera's view of the texel.
inline const ProductRecord* CameraHitRecord(const Context& c, const SurfaceInteraction& si,
                                            const Bsdf& bsdf, glm::vec3 wo,
                                            ProductRecord* storage) {
    if (c.lightSampling == LightSampling::Mis || !WantsProductSampling(bsdf)) return nullptr;
    if (!c.psrCache)  // Pis (or Cpis in a renderer that keeps no cache: the same records)
        BuildProductRecord(*c.env, bsdf, wo, storage);
    else
        c.psrCache->Lookup(si, bsdf, c.camera.Position(), storage, c.psrStats->local());
    return storage->valid ? storage : nullptr;
}

/// Where a pass's first-bounce directions come from (AO rays, and the light and BSDF samples at
/// the camera hits of the direct and path integrators): one Owen-scrambled Sobol' (0,2)-sequence
/// per dimension pair over the image (OwenSobol02), its points dealt out pixel by pixel in a
/// shuffled Morton order, then sample by sample, then ray (or path) by ray.
///
/// The order: a camera sample's number is its pixel's Morton index with the sample's slot in the
/// pass below it, and the base-4 digits of that number are permuted level by level from the top,
/// each by a permutation picked by a hash of the digits above it (ShuffledMorton; Ahmed and
/// Wonka 2020, as pbrt-v4's ZSobolSampler). A permutation of the digits keeps every aligned
/// block together, so every aligned 2^k x 2^k block of pixels gets consecutive points of the
/// sequence, a (0,m,2)-net: a pixel's samples of the pass stratify its hemisphere together, and so
/// do a block's, which is what a bin of hit-binned shading averages (a bin spans 4x4 pixels or
/// more). The shuffle is what keeps that stratification free of a pattern: in plain Morton order
/// the strata a pixel gets depend only on its place within its 2x2, 4x4, ... blocks (the scramble
/// of a point's leading digits depends on the index's low bits alone), so all pixels of one class
/// (x mod 2, y mod 2) sample the same strata and the noise shows a grid of period 2 to 4 pixels;
/// shuffled, each block deals its points in an order of its own, and a pixel's strata are random
/// whatever its class (tests/pixel_sequence_test.cpp). The sample slots are shuffled too, so a
/// pass of fewer samples than its power of two leaves a random slot of each pixel unused, not the
/// same slot everywhere. The shuffle is two hashes per camera sample for all levels at once, not
/// a hash per level, and nothing per ray.
///
/// A random shift per hit would stratify only one hit's own rays; the shared sequence lowers the
/// error of per-hit and binned shading alike, by up to half on path-traced light
/// (docs/texture-space.md, "Stratification"). The grid's cache samples keep their own nets
/// (CosineRays); later bounces draw from the sample's random stream. Each pass has its own
/// scramble and shuffle, so passes are independent and a pixel's result depends on its samples
/// and the pass split (a render with --spp is one pass unless shaded in texture space); never on
/// the threads or tiles.
struct PixelSequence {
    uint32_t seed;        ///< the pass's scramble
    int s0;               ///< the pass's first sample index
    uint32_t samples;     ///< points per pixel sample slot: the pass's samples, a power of two
    uint32_t perHit;      ///< points per camera sample, rounded up to a power of two
    MortonShuffle order;  ///< the pass's order of the pixels and of their slots

    /// Samples [passS0, passS1) of a pass: opt.aoSamples points (rays) per camera sample for AO,
    /// opt.hitSamples (paths) for the others.
    PixelSequence(const RenderOptions& opt, int passS0, int passS1)
        : seed(uint32_t(MixBits(opt.seed * 0xA24BAED4963EE407ull + uint64_t(passS0) + 1u))),
          s0(passS0),
          samples(std::bit_ceil(uint32_t(std::max(passS1 - passS0, 1)))),
          perHit(std::bit_ceil(uint32_t(
              std::max(opt.integrator == IntegratorKind::AO ? opt.aoSamples : opt.hitSamples, 1)))),
          // The image's Morton levels (pixels past them, if any, keep their blocks' order).
          order(seed, int(std::bit_width(uint32_t(std::max({opt.width, opt.height, 1}) - 1))),
                std::countr_zero(samples)) {}
    /// Index of the first point of camera sample (x, y, s).
    uint64_t First(int x, int y, int s) const {
        return ShuffledMorton(uint32_t(x), uint32_t(y), uint32_t(s - s0), order) * perHit;
    }
    /// The scramble of point j of dimension pair `pair`: past 2^32 points (e.g. 4096x4096
    /// pixels x 64 samples x 4 rays) the sequence restarts with another scramble, so no two
    /// pixels share their points. A camera sample's points share one (they are an aligned block
    /// of perHit <= 2^32 points): ForEachAoRay mixes it once per hit.
    OwenScramble ScrambleOf(uint64_t j, uint32_t pair = 0) const {
        return OwenScramble(seed ^ uint32_t(MixBits(j >> 32)) ^ pair * 0x9E3779B9u);
    }
    /// Point j of dimension pair `pair`.
    glm::vec2 At(uint64_t j, uint32_t pair = 0) const {
        return OwenSobol02(uint32_t(j), ScrambleOf(j, pair));
    }
};
/// What a caller that bins diffuse light at camera hits (texture_space/hit_binning.cpp,
/// PathHitsTrace) asks LiPath for: the first hit's light for a white diffuse surface (the caller
/// applies the hit's albedo, so a textured surface keeps its detail), with its interaction computed
/// already, and the direct part of that light (NEE at the first hit, and emission the first BSDF
/// ray finds, MIS- weighted) added to `direct` so that it can stay per hit while the indirect rest
/// is binned.
///
/// With `specular` set, the first hit keeps its own BSDF (a GGX layer over a diffuse base) and
/// one path estimates both lobes: the diffuse lobe's light is returned for a white lobe (the
/// caller applies Bsdf::DiffuseReflectance()), the specular lobe's, which depends on the view,
/// is added to `specular` with its reflectance applied. Each sample at the first hit (the light
/// sample, and the BSDF sample drawn from the lobes' mixture) is weighted by each lobe's
/// f cos / pdf with the mixture's pdf and MIS weight, so the two estimates are unbiased and sum
/// to per hit's estimate with the same rays, and neither needs rays of its own.
///
/// The first BSDF ray then picks the specular lobe at least `minSpecularProbability` of the
/// time (Bsdf::SetMinSpecularProbability; per hit's mixture gives it 10-20% on the scenes'
/// paints): the bins average the diffuse lobe's noise over many hits (and NEE estimates most of
/// its light), the specular lobe's noise stays in the pixel. Raising it from per hit's 0.1 to
/// 0.7-0.9 lowers the error on the glossy car and on the tests' GGX plane, and changes little on
/// chess (docs/texture-space.md, "Glossy hits"). With 0.1 the two lobes sum to per hit's
/// estimate exactly (the same mixture).
struct FirstHitLight {
    const SurfaceInteraction* si;
    glm::vec3* direct;
    glm::vec3* specular = nullptr;
    float minSpecularProbability = 0.75f;
    /// When given, the part of `direct` that delta lights (points, spots, distant lights
    /// without an angular size) give is added here too: their sharp shadows can stay per hit
    /// while soft lights' direct light is binned (TextureSpaceOptions::deltaDirectPerHit).
    glm::vec3* deltaDirect = nullptr;
};

/// A camera hit's light sample and BSDF sample, from the pass's PixelSequence (dimension pairs
/// kLightPair and kBsdfPair): stratified across the pixel's samples and its neighbours'.
struct FirstBounce {
    static constexpr uint32_t kLightPair = 1, kBsdfPair = 2;
    glm::vec2 light, bsdf;
    FirstBounce(const PixelSequence& seq, uint64_t j)
        : light(seq.At(j, kLightPair)), bsdf(seq.At(j, kBsdfPair)) {}
};

/// Direct lighting (depth 1) and path tracing: NEE with MIS against BSDF sampling.
/// `emitFirst` = false drops emission seen by the first ray (a cached indirect sample must not
/// count what NEE at the camera hit already did). `cached(si, ray, &term)` may replace light at
/// the first surface: Indirect adds the term and stops the path after the first BSDF ray's direct
/// hit (NEE and MIS still do direct light); All adds the term (direct + indirect) and stops.
/// `firstDiff` (the camera ray's differentials) says the first hit is a camera hit: with light
/// sampling pis or cpis it then samples the environment from its product sampling record
/// (CameraHitRecord; the differentials pick a cached record's texel), MIS-combined with BSDF
/// sampling as the map's own sampling is. `split`: see FirstHitLight. `first`: the first hit's
/// light and BSDF samples (else drawn from `rng`, as every later bounce's are).
template <typename CachedIndirect = NoCachedTerm>
glm::vec3 LiPath(const Context& c, Ray ray, const Hit& firstHit, bool hitFirst, Rng& rng,
                 int maxDepth, RayCounts& rays, bool emitFirst = true,
                 const CachedIndirect& cached = CachedIndirect(),
                 const RayDifferentials* firstDiff = nullptr, const FirstHitLight* split = nullptr,
                 const FirstBounce* first = nullptr) {
    glm::vec3 L(0.0f), beta(1.0f);
    float prevPdf = 0.0f;   // BSDF pdf of the ray being traced (0: camera ray, no MIS)
    glm::vec3 prevN(0.0f);  // shading normal where it left (the environment's pdf depends on it)
    ProductRecord psr;      // the camera hit's record (uninitialised unless used)
    const ProductRecord* prevPsr = nullptr;  // the record the ray being traced left from
    Hit hit = firstHit;
    bool found = hitFirst;
    // Split lobes at the first hit (FirstHitLight::specular): the first hit's own light for a
    // white diffuse lobe and for its specular lobe, and the two lobes' weights of the first BSDF
    // ray; the path on from there is traced with beta = 1 into L (as after a white first hit)
    // and split by the two weights at the end.
    const bool lobes = split && split->specular;
    // CachedTerm::BaseIndirect: past the first BSDF ray's hit the path goes on with that ray's
    // specular weight (lobeBetaS) alone.
    bool baseIndirect = false;
    glm::vec3 lobeL(0.0f), lobeS(0.0f), lobeBetaD(0.0f), lobeBetaS(0.0f);
    auto finish = [&](glm::vec3 l) {
        if (!lobes) return l;
        *split->specular += lobeS + lobeBetaS * l;
        return lobeL + lobeBetaD * l;
    };
    int depth = 0;
    // Light the ray being traced found (MIS-weighted already).
    auto emitted = [&](glm::vec3 Le) {
        L += beta * Le;
        if (split && depth == 1) *split->direct += (lobes ? lobeBetaD : beta) * Le;
    };
    for (;; ++depth) {
        if (depth > 0) {
            ++rays.bounce;
            found = c.rs.Intersect(ray, &hit);
        }
        if (depth == 0 && !emitFirst && (!found || hit.light >= 0)) break;
        if (!found) {
            if (c.env) {
                float envPdf = 0.0f;
                const glm::vec3 Le = prevPdf > 0.0f && !prevPsr
                                         ? c.env->EvalPdf(prevN, ray.dir, &envPdf)
                                         : c.env->Eval(ray.dir);
                float w = 1.0f;
                if (prevPdf > 0.0f) {
                    const float pl =
                        prevPsr ? ProductLightPdf(*prevPsr, *c.env, prevN, ray.dir) : envPdf;
                    w = PowerHeuristic(1, prevPdf, 1, pl * c.PickPdf());
                }
                L += beta * Le * w;
                if (split && depth == 1) *split->direct += (lobes ? lobeBetaD : beta) * Le * w;
            }
            if (c.sunDiscs) emitted(c.SunRadiance(ray.dir, prevPdf));
            break;
        }
        if (hit.light >= 0) {
            emitted(c.EmittedMis(ray, hit, prevPdf));
            break;
        }
        // An emissive object's light; a split first hit's goes to the caller (not to be
        // multiplied by the albedo applied to what this returns).
        if ((!c.emitters.empty() || c.emissive) && (depth > 0 || (emitFirst && !split)))
            emitted(c.EmittedMis(ray, hit, prevPdf));
        if (depth >= maxDepth) break;
        if (depth == 1 && baseIndirect) {
            // The first BSDF ray found its direct light for both lobes; the diffuse base's
            // indirect light is cached, so only the specular lobe's path goes on.
            beta = lobeBetaS;
            if (beta == glm::vec3(0.0f)) break;
        }
        const SurfaceInteraction si =
            depth == 0 && split ? *split->si
                                : c.rs.Interact(ray, hit, depth == 0 ? firstDiff : nullptr);
        bool specularOnly = false;
        if (depth == 0) {
            glm::vec3 term;
            const CachedTerm t = cached(si, ray, &term);
            if (t == CachedTerm::All) return finish(L + term);
            if (t == CachedTerm::Indirect) {
                L += term;
                maxDepth = 1;  // the BSDF ray below still finds direct light (MIS), then stops
            }
            if (t == CachedTerm::DiffuseBase) {
                L += term;
                specularOnly = true;
            }
            if (t == CachedTerm::BaseIndirect) {
                L += term;
                baseIndirect = true;
            }
        }
        // White at a split first hit: the caller multiplies by the albedo.
        Bsdf bsdf = depth == 0 && split && !lobes ? Bsdf(si.N, si.Ng, glm::vec3(1.0f), false,
                                                         glm::vec2(1.0f), glm::vec3(0.0f))
                                                  : MakeBsdf(c, si, !specularOnly);
        if (lobes && depth == 0) bsdf.SetMinSpecularProbability(split->minSpecularProbability);
        const glm::vec3 wo = -ray.dir;
        const ProductRecord* record =
            depth == 0 && firstDiff ? CameraHitRecord(c, si, bsdf, wo, &psr) : nullptr;

        LightSample ls;
        const float uPick = rng.Next1D();
        const glm::vec2 uLight = depth == 0 && first ? first->light : rng.Next2D();
        if (c.SampleLight(si.P, si.N, uPick, uLight, &ls, record)) {
            const glm::vec3 f = bsdf.Eval(wo, ls.wi);
            if (f != glm::vec3(0.0f)) {
                ++rays.shadow;
                if (!c.rs.Occluded(ShadowRay(si, ls, ray.time))) {
                    const float cosi = std::abs(glm::dot(ls.wi, si.N));
                    const float w =
                        ls.delta ? 1.0f : PowerHeuristic(1, ls.pdf, 1, bsdf.Pdf(wo, ls.wi));
                    const glm::vec3 Li = ls.Li * (ls.delta ? cosi : cosi * w / ls.pdf);
                    glm::vec3 Ld;
                    if (lobes && depth == 0) {
                        Ld = bsdf.DiffuseWhite(ls.wi) * Li;
                        lobeL += Ld;
                        lobeS += bsdf.EvalSpecular(wo, ls.wi) * Li;
                    } else {
                        Ld = beta * f * Li;
                        L += Ld;
                    }
                    if (split && depth == 0) {
                        *split->direct += Ld;
                        if (ls.delta && split->deltaDirect) *split->deltaDirect += Ld;
                    }
                }
            }
        }

        glm::vec3 wi, weight;
        float pdf;
        const float uChoice = rng.Next1D();
        const glm::vec2 uBsdf = depth == 0 && first ? first->bsdf : rng.Next2D();
        if (!bsdf.Sample(wo, uChoice, uBsdf, &wi, &weight, &pdf)) break;
        if (depth == 0 && (lobes || baseIndirect)) {
            // The first BSDF ray's weight per lobe (f cos / pdf of the mixture).
            const float cosOverPdf = std::abs(glm::dot(wi, si.N)) / pdf;
            lobeBetaS = bsdf.EvalSpecular(wo, wi) * cosOverPdf;
            if (lobes) {
                lobeBetaD = glm::vec3(bsdf.DiffuseWhite(wi) * cosOverPdf);
                weight = glm::vec3(1.0f);
            }
        }
        beta *= weight;
        prevPdf = pdf;
        prevN = si.N;
        prevPsr = record;
        ray.org = OffsetOrigin(si.P, si.Ng, wi);
        ray.dir = wi;
        ray.tnear = 0.0f;
        ray.tfar = INFINITY;
        if (depth >= 3) {
            // Russian roulette once paths are long enough to matter little.
            const float q = std::max(0.05f, 1.0f - std::max({beta.x, beta.y, beta.z}));
            if (rng.Next1D() < q) break;
            beta /= 1.0f - q;
        }
        if (!std::isfinite(beta.x + beta.y + beta.z)) break;
    }
    return finish(L);
}

/// The AO rays of a camera hit, in order: opt.aoSamples directions from `first` on in the
/// pass's PixelSequence, cosine-distributed about the shading normal, those below the tessellated
/// surface left out (they count as blocked). Each is written field by field into the Ray& that
/// slot() returns: building a Ray on the stack and copying it out makes the copy's 16-byte loads
/// wait on its 4-byte stores (failed store forwarding: a fifth of a per-hit AO render's samples
/// on those two instructions, perf annotate). LiAO and per-hit AO tiles trace them; `texcache
/// bench rays` records them for its raw Embree loop.
template <typename Slot>
void ForEachAoRay(const Context& c, const Ray& ray, const SurfaceInteraction& si,
                  const PixelSequence& seq, uint64_t first, Slot&& slot) {
    const Frame frame = Frame::FromZ(si.N);
    const OwenScramble key = seq.ScrambleOf(first);
    for (int i = 0; i < c.opt.aoSamples; ++i) {
        const glm::vec2 u = OwenSobol02(uint32_t(first) + uint32_t(i), key);
        const glm::vec3 wi = frame.FromLocal(SampleCosineHemisphere(u));
        if (glm::dot(wi, si.Ng) <= 0.0f) continue;
        Ray& r = slot();
        r.org = OffsetOrigin(si.P, si.Ng, wi);
        r.dir = wi;
        r.tnear = 0.0f;
        r.tfar = c.opt.aoDistance;
        r.time = ray.time;
    }
}

/// Ambient occlusion at a camera hit: the fraction of opt.aoSamples cosine-distributed rays
/// (up to opt.aoDistance) that escape.
glm::vec3 LiAO(const Context& c, const Ray& ray, const SurfaceInteraction& si,
               const PixelSequence& seq, uint64_t first, RayCounts& rays);

}  // namespace internal
}  // namespace texcache
