// SPDX-License-Identifier: Apache-2.0
#include "renderer/integrator.h"

#include <pmmintrin.h>
#include <xmmintrin.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include <unistd.h>

#include <tbb/blocked_range2d.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "filters/regression_filter.h"
#include "filters/soft_shadow_filter.h"
#include "renderer/bsdf.h"
#include "renderer/camera.h"
#include "renderer/envmap.h"
#include "renderer/frame_buffers_render.h"
#include "renderer/sampling.h"
#include "texcache/error.h"

namespace texcache {

namespace {

constexpr float kPi = 3.14159265358979f;

struct Named {
    const char* name;
    IntegratorKind kind;
};
constexpr Named kIntegrators[] = {
    {"normal", IntegratorKind::Normal}, {"ptex", IntegratorKind::Ptex},
    {"uv", IntegratorKind::Uv},         {"eyelight", IntegratorKind::EyeLight},
    {"ao", IntegratorKind::AO},         {"direct", IntegratorKind::Direct},
    {"path", IntegratorKind::Path},
};

struct RayCounts {
    uint64_t camera = 0, shadow = 0, bounce = 0;
};

/// Offsets a ray origin off the surface along the geometric normal, scaled to the coordinates'
/// magnitude so that float rounding of large scenes cannot re-hit the surface.
glm::vec3 OffsetOrigin(glm::vec3 p, glm::vec3 ng, glm::vec3 dir) {
    const float scale = std::max({1.0f, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
    const float eps = 2e-5f * scale;
    return p + (glm::dot(dir, ng) >= 0.0f ? eps : -eps) * ng;
}

glm::vec3 HashColor(uint32_t id) {
    uint64_t h = MixBits(uint64_t(id) + 0x9E3779B97F4A7C15ull);
    return glm::vec3(float(h & 0xFF), float((h >> 8) & 0xFF), float((h >> 16) & 0xFF)) / 255.0f;
}

// One light sample for next-event estimation.
struct LightSample {
    glm::vec3 wi;  // towards the light
    float dist;    // to the light (inf for env/distant)
    glm::vec3 Li;  // incident radiance (irradiance for delta lights)
    float pdf;     // solid angle, includes light selection; 0 for delta lights (no MIS)
    bool delta;
    int quad = -1;     // the quad light sampled, -1 for other lights
    int distant = -1;  // the distant light sampled, -1 for other lights
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
    int numLights = 0;
    float shutterLength;
    TextureSpaceCache* tsc = nullptr;
    tbb::enumerable_thread_specific<CacheStats>* cacheStats = nullptr;
    PixelCacheCounts* pixelCache = nullptr;              // per-pixel cache traffic, when asked for
    std::optional<CameraModel> cameraOpen, cameraClose;  // for motion vectors
    bool cameraMoves = false;

    Context(const RenderScene& r, const RenderOptions& o)
        : rs(r),
          scene(r.scene()),
          opt(o),
          env(r.environment()),
          camera(r.scene().camera, o.frameTime, o.width, o.height) {
        shutterLength = scene.camera.shutterClose - scene.camera.shutterOpen;
        if (shutterLength > 0.0f) {
            cameraOpen.emplace(scene.camera, o.frameTime, o.width, o.height);
            cameraClose.emplace(scene.camera, o.frameTime + shutterLength, o.width, o.height);
            cameraMoves = scene.camera.pose.IsAnimated();
        }
        if (!IntegratorUsesLights(o.integrator)) return;
        for (const DistantLight& d : scene.distantLights) {
            const glm::mat3 M(d.transform.Eval(o.frameTime));
            distantDir.push_back(-glm::normalize(M * d.direction));
            distantE.push_back(d.irradiance);
        }
        for (const QuadLight& q : scene.quadLights) {
            const glm::mat4 M = q.transform.Eval(o.frameTime);
            Quad w;
            w.corner = glm::vec3(M * glm::vec4(q.corner, 1.0f));
            w.e1 = glm::mat3(M) * q.edge1;
            w.e2 = glm::mat3(M) * q.edge2;
            const glm::vec3 c = glm::cross(w.e1, w.e2);
            w.area = glm::length(c);
            w.n = c / w.area;
            w.L = q.radiance;
            w.twoSided = q.twoSided;
            quads.push_back(w);
        }
        numLights = int(quads.size() + distantDir.size()) + (env ? 1 : 0);
    }

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

    bool SampleLight(glm::vec3 p, float uPick, glm::vec2 u, LightSample* s) const {
        if (numLights == 0) return false;
        int i = std::min(int(uPick * float(numLights)), numLights - 1);
        if (i < int(quads.size())) {
            const Quad& q = quads[i];
            const glm::vec3 x = q.corner + u.x * q.e1 + u.y * q.e2;
            glm::vec3 d = x - p;
            const float dist2 = glm::dot(d, d);
            if (!(dist2 > 0.0f)) return false;
            s->dist = std::sqrt(dist2);
            s->wi = d / s->dist;
            s->Li = QuadEmission(i, s->wi);
            s->pdf = QuadPdf(i, s->wi, s->dist);
            s->delta = false;
            s->quad = i;
            return s->pdf > 0.0f && s->Li != glm::vec3(0.0f);
        }
        i -= int(quads.size());
        if (i < int(distantDir.size())) {
            s->wi = distantDir[i];
            s->dist = INFINITY;
            s->Li = distantE[i] * float(numLights);  // divided by the pick probability
            s->pdf = 0.0f;
            s->delta = true;
            s->distant = i;
            return true;
        }
        float pdf;
        s->Li = env->Sample(u, &s->wi, &pdf);
        s->pdf = pdf * PickPdf();
        s->dist = INFINITY;
        s->delta = false;
        return s->pdf > 0.0f;
    }
};

Bsdf MakeBsdf(const Context& c, const SurfaceInteraction& si) {
    const Material& m = c.scene.materials[si.material];
    const bool ggx = m.type == Material::Type::GGX;
    return Bsdf(si.N, si.Ng, c.rs.Albedo(si), ggx, ggx ? c.rs.Roughness(si) : 1.0f, m.specular);
}

/// The shadow ray of a light sample, stopping just short of an area light's surface.
Ray ShadowRay(const SurfaceInteraction& si, const LightSample& ls, float time) {
    Ray shadow;
    shadow.org = OffsetOrigin(si.P, si.Ng, ls.wi);
    shadow.dir = ls.wi;
    shadow.tfar = std::isinf(ls.dist) ? INFINITY : ls.dist * (1.0f - 1e-4f);
    shadow.time = time;
    return shadow;
}

enum class CachedTerm { None, Indirect, All };

struct NoCachedTerm {
    CachedTerm operator()(const SurfaceInteraction&, const Ray&, glm::vec3*) const {
        return CachedTerm::None;
    }
};

/// Direct lighting (depth 1) and path tracing: NEE with MIS against BSDF sampling.
/// `emitFirst` = false drops emission seen by the first ray (a cached indirect sample must not
/// count what NEE at the camera hit already did). `cached(si, ray, &term)` may replace light at
/// the first surface: Indirect adds the term and stops the path after the first BSDF ray's direct
/// hit (NEE and MIS still do direct light); All adds the term (direct + indirect) and stops.
template <typename CachedIndirect = NoCachedTerm>
glm::vec3 LiPath(const Context& c, Ray ray, const Hit& firstHit, bool hitFirst, Rng& rng,
                 int maxDepth, RayCounts& rays, bool emitFirst = true,
                 const CachedIndirect& cached = CachedIndirect()) {
    glm::vec3 L(0.0f), beta(1.0f);
    float prevPdf = 0.0f;  // BSDF pdf of the ray being traced (0: camera ray, no MIS)
    Hit hit = firstHit;
    bool found = hitFirst;
    for (int depth = 0;; ++depth) {
        if (depth > 0) {
            ++rays.bounce;
            found = c.rs.Intersect(ray, &hit);
        }
        if (depth == 0 && !emitFirst && (!found || hit.light >= 0)) break;
        if (!found) {
            if (c.env) {
                const glm::vec3 Le = c.env->Eval(ray.dir);
                float w = 1.0f;
                if (prevPdf > 0.0f)
                    w = PowerHeuristic(1, prevPdf, 1, c.env->Pdf(ray.dir) * c.PickPdf());
                L += beta * Le * w;
            }
            break;
        }
        if (hit.light >= 0) {
            const glm::vec3 Le = c.QuadEmission(hit.light, ray.dir);
            float w = 1.0f;
            if (prevPdf > 0.0f)
                w = PowerHeuristic(1, prevPdf, 1, c.QuadPdf(hit.light, ray.dir, hit.t));
            L += beta * Le * w;
            break;
        }
        if (depth >= maxDepth) break;
        const SurfaceInteraction si = c.rs.Interact(ray, hit);
        const Bsdf bsdf = MakeBsdf(c, si);
        const glm::vec3 wo = -ray.dir;
        if (depth == 0) {
            glm::vec3 term;
            const CachedTerm t = cached(si, ray, &term);
            if (t == CachedTerm::All) return L + term;
            if (t == CachedTerm::Indirect) {
                L += term;
                maxDepth = 1;  // the BSDF ray below still finds direct light (MIS), then stops
            }
        }

        LightSample ls;
        if (c.SampleLight(si.P, rng.Next1D(), rng.Next2D(), &ls)) {
            const glm::vec3 f = bsdf.Eval(wo, ls.wi);
            if (f != glm::vec3(0.0f)) {
                ++rays.shadow;
                if (!c.rs.Occluded(ShadowRay(si, ls, ray.time))) {
                    const float cosi = std::abs(glm::dot(ls.wi, si.N));
                    if (ls.delta) {
                        L += beta * f * ls.Li * cosi;
                    } else {
                        const float w = PowerHeuristic(1, ls.pdf, 1, bsdf.Pdf(wo, ls.wi));
                        L += beta * f * ls.Li * (cosi * w / ls.pdf);
                    }
                }
            }
        }

        glm::vec3 wi, weight;
        float pdf;
        const float uChoice = rng.Next1D();
        if (!bsdf.Sample(wo, uChoice, rng.Next2D(), &wi, &weight, &pdf)) break;
        beta *= weight;
        prevPdf = pdf;
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
    return L;
}

glm::vec3 LiAO(const Context& c, const Ray& ray, const SurfaceInteraction& si, Rng& rng,
               RayCounts& rays) {
    const Frame frame = Frame::FromZ(si.N);
    int open = 0;
    for (int i = 0; i < c.opt.aoSamples; ++i) {
        const glm::vec3 wi = frame.FromLocal(SampleCosineHemisphere(rng.Next2D()));
        // Directions below the tessellated surface are blocked by it.
        if (glm::dot(wi, si.Ng) <= 0.0f) continue;
        Ray r;
        r.org = OffsetOrigin(si.P, si.Ng, wi);
        r.dir = wi;
        r.tfar = c.opt.aoDistance;
        r.time = ray.time;
        ++rays.shadow;
        if (!c.rs.Occluded(r)) ++open;
    }
    return glm::vec3(float(open) / float(c.opt.aoSamples));
}

struct PixelAovs {
    glm::vec3 albedo{0.0f}, normal{0.0f}, ptex{0.0f};
    float depth = 0.0f;
    glm::vec2 motion{0.0f};
    int hits = 0;
};

// ---- texture-space shading (libtexcache) ---------------------------------------------------

/// The counters of a thread's CacheStats that a pixel's heat-map counts are the change of.
struct CacheSnapshot {
    uint64_t lookups = 0, texelHits = 0, samplesShaded = 0;
    CacheSnapshot() = default;
    explicit CacheSnapshot(const CacheStats& s)
        : lookups(s.lookups), texelHits(s.texelHits), samplesShaded(s.samplesShaded) {}
};

/// Adds what a pixel's lookups counted (the thread's stats after them minus `before`) to its
/// counts. Exact because the lookups run on one thread whose CacheStats nothing else touches
/// meanwhile: shading only traces rays, and Embree's queries spawn no TBB tasks that could run
/// another tile on this thread in between.
void AddPixelCounts(PixelCacheCounts* px, const CacheSnapshot& before, const CacheStats& after) {
    px->lookups += uint32_t(after.lookups - before.lookups);
    px->texelHits += uint32_t(after.texelHits - before.texelHits);
    px->samplesShaded += uint32_t(after.samplesShaded - before.samplesShaded);
}

/// Random stream of a cache sample: a function of its key, so the same texel gets the same
/// shading whichever thread shades it, and a re-shade after eviction reproduces it.
Rng SampleRng(const Context& c, const SampleRequest& r) {
    return Rng(MixBits(c.opt.seed ^ (r.key.Pack() * 0x9E3779B97F4A7C15ull)), 0x7ca7);
}

/// Limit-surface point of a cache sample, and the origin its secondary rays start from. The
/// rays hit the tessellated surface, which lies up to ~1.4% of an edge off the limit surface:
/// a short ray along -N against this object alone finds the tessellated surface under the
/// sample, and rays start just above it. (A fixed lift large enough for curved faces would put
/// samples on big flat faces above nearby objects, e.g. the ground under a car's sills; and
/// another object crossing the short ray must not be taken for the surface.)
bool SamplePoint(const Context& c, const SampleRequest& r, SurfaceSample* ss, glm::vec3* origin,
                 RayCounts& rays) {
    const int object = c.tsc->ObjectOfMesh(r.mesh);
    if (!c.rs.EvalSurface(object, {r.face, r.u, r.v}, 0.0f, ss)) return false;
    if (c.tsc->IsBackMesh(r.mesh)) ss->N = -ss->N;  // the back side of an open surface
    if (!std::isfinite(ss->P.x + ss->P.y + ss->P.z + ss->N.x + ss->N.y + ss->N.z)) return false;
    const float edge = std::max(glm::length(ss->dPdu), glm::length(ss->dPdv));
    const float scale = std::max({1.0f, std::abs(ss->P.x), std::abs(ss->P.y), std::abs(ss->P.z)});
    const float eps = 2e-5f * scale;
    const float lift = 0.03f * edge + eps;
    Ray snap;
    snap.org = ss->P + lift * ss->N;
    snap.dir = -ss->N;
    snap.tfar = 2.0f * lift;
    float t;
    ++rays.bounce;
    *origin = c.rs.IntersectObject(object, snap, &t) ? snap.org + t * snap.dir + eps * ss->N
                                                     : ss->P + eps * ss->N;
    return true;
}

/// Shades a cache sample with n cosine-distributed rays from its point; `trace(ray, rng, N)` gives
/// each ray's value. Returns the mean, the sample's normal and the variance of the mean
/// (luminance). Unreachable samples (holes, NaN surface) come back NaN: filters skip them.
template <typename TraceFn>
ShadedSample ShadeCosineRays(const Context& c, const SampleRequest& r, int n, RayCounts& rays,
                             TraceFn&& trace) {
    SurfaceSample ss;
    glm::vec3 origin;
    if (!SamplePoint(c, r, &ss, &origin, rays)) return {glm::vec3(NAN), glm::vec3(NAN), 0.0f};
    Rng rng = SampleRng(c, r);
    const Frame frame = Frame::FromZ(ss.N);
    glm::vec3 sum(0.0f);
    float sum2 = 0.0f;
    for (int i = 0; i < n; ++i) {
        Ray ray;
        ray.dir = frame.FromLocal(SampleCosineHemisphere(rng.Next2D()));
        ray.org = origin;
        const glm::vec3 L = trace(ray, rng, ss.N);
        sum += L;
        const float y = Luminance(L);
        sum2 += y * y;
    }
    const glm::vec3 mean = sum / float(n);
    const float ym = Luminance(mean);
    return {mean, ss.N, std::max(0.0f, sum2 / float(n) - ym * ym) / float(std::max(n - 1, 1))};
}

ShadedSample ShadeAoSample(const Context& c, const SampleRequest& r, RayCounts& rays) {
    return ShadeCosineRays(c, r, c.opt.aoSamples, rays, [&](Ray& ray, Rng&, glm::vec3) {
        ray.tfar = c.opt.aoDistance;
        ++rays.shadow;
        return glm::vec3(c.rs.Occluded(ray) ? 0.0f : 1.0f);
    });
}

/// Diffuse light at a cache sample, as (1/pi) * integral of L cos (the hit multiplies it by its
/// albedo). Indirect: cosine-sampled paths, whose first ray does not count emission (light
/// seen directly is NEE's). With `direct`, each of the n iterations also takes one NEE sample
/// (light sampling, shadow ray): (1/pi) Le V cos / pdf; otherwise direct light stays NEE's job
/// at the hit.
ShadedSample ShadeDiffuseSample(const Context& c, const SampleRequest& r, bool direct,
                                RayCounts& rays) {
    return ShadeCosineRays(
        c, r, c.opt.texture.indirectSamples, rays, [&](Ray& ray, Rng& rng, glm::vec3 N) {
            glm::vec3 Ld(0.0f);
            LightSample ls;
            if (direct && c.SampleLight(ray.org, rng.Next1D(), rng.Next2D(), &ls)) {
                const float cosi = glm::dot(ls.wi, N);
                if (cosi > 0.0f) {
                    Ray shadow;
                    shadow.org = ray.org;
                    shadow.dir = ls.wi;
                    shadow.tfar = std::isinf(ls.dist) ? INFINITY : ls.dist * (1.0f - 1e-4f);
                    ++rays.shadow;
                    if (!c.rs.Occluded(shadow))
                        Ld = ls.Li * (ls.delta ? cosi : cosi / ls.pdf) * (1.0f / kPiF);
                }
            }
            ++rays.bounce;
            Hit hit;
            const bool found = c.rs.Intersect(ray, &hit);
            const glm::vec3 L =
                Ld + LiPath(c, ray, hit, found, rng, std::max(c.opt.maxDepth - 1, 0), rays, false);
            return std::isfinite(L.x + L.y + L.z) ? L : glm::vec3(0.0f);
        });
}

/// Visibility of the scene's area lights from a cache sample (Mehta et al.'s soft-shadow input):
/// the fraction of shadow rays towards uniform points on the quad lights that reach them, and the
/// smallest blur std sigma_l * t / (d - t) the blocked rays allow (see soft_shadow_filter.h).
ShadedSample ShadeShadowSample(const Context& c, const SampleRequest& r, RayCounts& rays) {
    SurfaceSample ss;
    glm::vec3 origin;
    if (c.quads.empty() || !SamplePoint(c, r, &ss, &origin, rays))
        return {glm::vec3(NAN), glm::vec3(NAN), 0.0f};
    Rng rng = SampleRng(c, r);
    const int n = c.opt.texture.shadowSamples;
    int open = 0, counted = 0;
    float blur = INFINITY;
    for (int i = 0; i < n; ++i) {
        const int l = std::min(int(rng.Next1D() * float(c.quads.size())), int(c.quads.size()) - 1);
        const Context::Quad& q = c.quads[l];
        const glm::vec2 u = rng.Next2D();
        const glm::vec3 d = q.corner + u.x * q.e1 + u.y * q.e2 - origin;
        const float dist = glm::length(d);
        // Light points below the sample's tangent plane light nothing: not a visibility question.
        if (!(dist > 0.0f) || glm::dot(d, ss.N) <= 0.0f) continue;
        ++counted;
        Ray ray;
        ray.org = origin;
        ray.dir = d / dist;
        ray.tfar = dist * (1.0f - 1e-4f);
        ++rays.shadow;
        Hit hit;
        if (!c.rs.Intersect(ray, &hit) || hit.light >= 0) {
            ++open;
            continue;
        }
        const float sigmaL = std::sqrt(glm::length(q.e1) * glm::length(q.e2) / 12.0f);
        blur = std::min(blur, sigmaL * hit.t / std::max(dist - hit.t, 1e-6f * dist));
    }
    const float V = counted ? float(open) / float(counted) : 1.0f;
    const float res = float(c.tsc->cache().Mesh(r.mesh).Res(r.face, r.mip));
    const float texel = std::max(glm::length(ss.dPdu), glm::length(ss.dPdv)) / res;
    // The blur in texels of this sample's grid; a degenerate texel allows any width.
    const float blurTexels = texel > 0.0f && std::isfinite(texel) ? blur / texel : INFINITY;
    return {glm::vec3(V), ss.N, counted ? V * (1.0f - V) / float(counted) : 0.0f, blurTexels};
}

/// The texel a shading point maps to (eq. 1 and 2) in its object's (front or back) grids.
SampleRequest TexelOf(const Context& c, const SurfaceInteraction& si) {
    return c.tsc->cache().TexelAt({c.tsc->MeshOf(si.object, si.backFacing), si.ptex.face, si.ptex.u,
                                   si.ptex.v, si.dudx, si.dvdx, si.dudy, si.dvdy});
}

/// The cached term at a camera hit: texel-cache lookup with the material's filter.
/// `raysPerSample` is the number of rays behind each cached sample (the regression's n).
template <typename ShadeFn>
glm::vec3 CachedLookup(const Context& c, const SurfaceInteraction& si, ShadeFn&& shade,
                       int raysPerSample, CacheStats* stats = nullptr,
                       const SampleRequest* texel = nullptr) {
    const TextureSpaceOptions& t = c.tsc->options();
    if (c.opt.texture.constantTerm >= 0.0f) return glm::vec3(c.opt.texture.constantTerm);
    const SampleRequest h = texel ? *texel : TexelOf(c, si);
    // enumerable_thread_specific::local() hashes the thread id: callers with many lookups pass
    // their thread's stats in.
    CacheStats& st = stats ? *stats : c.cacheStats->local();
    TextureSpaceCache& tsc = *c.tsc;
    // One branch per lookup picks the material's filter; the filters themselves are inlined. The
    // temporal blend runs once per reconstructed texel, not per lookup.
    auto lookup = [&](int radius, const auto& filter,
                      FootprintTaps taps = FootprintTaps::VisibleSymmetric) {
        return tsc.cache().LookupTexel(
            h, radius, shade,
            [&](const FilterInput<ShadedSample>& in) {
                return tsc.Accumulate(in.request.key, filter(in));
            },
            st, taps);
    };
    const int radius = tsc.RadiusOf(si.object);
    switch (tsc.FilterOf(si.object)) {
        case TextureFilterKind::None:
            return lookup(0, CentreFilter{});
        case TextureFilterKind::Gaussian:
            // The paper's 20x20 Gaussian: sigma half the radius, same normal test.
            return lookup(radius, NormalWeightedFilter{t.cosThreshold, 0.5f * float(radius)});
        case TextureFilterKind::Regression:
            // A linear model fits the gradient a one-sided window sees: no symmetry needed.
            return lookup(radius, RegressionFilter{raysPerSample, false}, FootprintTaps::Visible);
        case TextureFilterKind::SoftShadow:
            return lookup(radius, SoftShadowFilter{t.cosThreshold});
        case TextureFilterKind::Normal:
            break;
    }
    return lookup(radius, NormalWeightedFilter{t.cosThreshold, 0.0f});
}

/// Direct lighting with area-light visibility from the texture-space cache (the soft-shadow
/// filter). Per hit, each quad light's unshadowed light is estimated from `shadowSamples` points
/// on it (no rays: the cheap, low-noise part) and multiplied by the texel's filtered visibility;
/// other lights (environment, distant) get one NEE sample with its shadow ray. No MIS with BSDF
/// sampling: a BSDF ray that finds the light would bring back unfiltered visibility. Objects whose
/// material uses another filter get the plain per-hit estimator.
glm::vec3 LiDirectCachedShadows(const Context& c, const Ray& ray, const Hit& hit, bool found,
                                Rng& rng, const RayDifferentials& diff, RayCounts& rays) {
    if (!found) return c.env ? c.env->Eval(ray.dir) : glm::vec3(0.0f);
    if (hit.light >= 0) return c.QuadEmission(hit.light, ray.dir);
    if (c.tsc->FilterOf(hit.object) != TextureFilterKind::SoftShadow)
        return LiPath(c, ray, hit, found, rng, 1, rays);
    const SurfaceInteraction si = c.rs.Interact(ray, hit, &diff);
    const Bsdf bsdf = MakeBsdf(c, si);
    const glm::vec3 wo = -ray.dir;
    glm::vec3 L(0.0f);
    // Area lights: unshadowed estimate times cached visibility.
    const int m = c.opt.texture.shadowSamples;
    glm::vec3 unshadowed(0.0f);
    for (size_t l = 0; l < c.quads.size(); ++l) {
        const Context::Quad& q = c.quads[l];
        for (int j = 0; j < m; ++j) {
            const glm::vec2 u = rng.Next2D();
            const glm::vec3 d = q.corner + u.x * q.e1 + u.y * q.e2 - si.P;
            const float dist2 = glm::dot(d, d);
            if (!(dist2 > 0.0f)) continue;
            const float dist = std::sqrt(dist2);
            const glm::vec3 wi = d / dist;
            const float cosl = glm::dot(q.n, -wi);
            if (!(cosl > 0.0f || q.twoSided)) continue;
            // Solid-angle pdf of a uniform point on the quad: dist^2 / (area |cos_l|).
            const float G = std::abs(cosl) * q.area / dist2;
            unshadowed += bsdf.Eval(wo, wi) * q.L * (std::abs(glm::dot(wi, si.N)) * G);
        }
    }
    if (unshadowed != glm::vec3(0.0f)) {
        const glm::vec3 V = CachedLookup(
            c, si, [&](const SampleRequest& r) { return ShadeShadowSample(c, r, rays); },
            c.opt.texture.shadowSamples);
        L += unshadowed / float(m) * V.x;
    }
    // Other lights: one shadowed NEE sample among them.
    const int others = c.numLights - int(c.quads.size());
    if (others > 0) {
        const int pick =
            int(c.quads.size()) + std::min(int(rng.Next1D() * float(others)), others - 1);
        LightSample ls;
        // SampleLight takes a uniform pick over all lights: map `pick` into its interval.
        if (c.SampleLight(si.P, (float(pick) + 0.5f) / float(c.numLights), rng.Next2D(), &ls)) {
            const glm::vec3 f = bsdf.Eval(wo, ls.wi);
            ++rays.shadow;
            if (f != glm::vec3(0.0f) && !c.rs.Occluded(ShadowRay(si, ls, ray.time))) {
                // SampleLight divides by the pick probability over all lights; ours is 1/others.
                const float pickFix = float(others) / float(c.numLights);
                const float cosi = std::abs(glm::dot(ls.wi, si.N));
                L += (ls.delta ? f * ls.Li * cosi : f * ls.Li * (cosi / ls.pdf)) * pickFix;
            }
        }
    }
    return L;
}

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

/// The mean of `hitSamples` estimates `li(rng)` from one camera hit: the first continues the
/// camera sample's own random stream (so hitSamples = 1 is the plain path tracer), the others get
/// streams of their own.
template <typename LiFn>
glm::vec3 SplitAtHit(const Context& c, int x, int y, int s, Rng& rng, LiFn&& li) {
    const int n = std::max(c.opt.hitSamples, 1);
    glm::vec3 sum = li(rng);
    for (int h = 1; h < n; ++h) {
        Rng split(MixBits(PixelSeed(c.opt.seed, x, y, c.opt.width) ^ (uint64_t(h) << 40)),
                  uint64_t(s));
        sum += li(split);
    }
    return sum / float(n);
}

/// The camera ray of pixel sample (x, y, s); `rng` continues the sample's random stream after it.
/// Every pass that traces a sample (the visibility prepass, the shading pass) gets the same ray.
Ray CameraRay(const Context& c, int x, int y, int s, Rng* rng, RayDifferentials* diff) {
    *rng = Rng(PixelSeed(c.opt.seed, x, y, c.opt.width), uint64_t(s));
    glm::vec2 jitter = rng->Next2D();
    if (c.opt.pixelCentre) jitter = glm::vec2(0.5f);  // drawn anyway: same streams either way
    const glm::vec2 lens = rng->Next2D();
    const float time = c.shutterLength > 0.0f ? rng->Next1D() : 0.0f;
    Ray ray = c.camera.Generate(float(x) + jitter.x, float(y) + jitter.y, lens, diff);
    if (c.cameraMoves) {
        // Camera motion blur: blend the rays of the open and close poses (rigid, short shutter).
        const Ray r1 =
            c.cameraClose->Generate(float(x) + jitter.x, float(y) + jitter.y, lens, nullptr);
        ray.org = glm::mix(ray.org, r1.org, time);
        ray.dir = glm::normalize(glm::mix(ray.dir, r1.dir, time));
    }
    ray.time = time;
    return ray;
}

glm::vec3 Sample(const Context& c, int x, int y, int s, PixelAovs* aov, RayCounts& rays) {
    // Differentials feed the cache's mip selection and the debug views; skip them otherwise.
    const bool needDiff = c.tsc != nullptr || c.opt.integrator == IntegratorKind::Normal ||
                          c.opt.integrator == IntegratorKind::Ptex ||
                          c.opt.integrator == IntegratorKind::Uv;
    RayDifferentials diff;
    Rng rng(0, 0);
    const Ray ray = CameraRay(c, x, y, s, &rng, needDiff ? &diff : nullptr);
    ++rays.camera;
    Hit hit;
    const bool found = c.rs.Intersect(ray, &hit);

    const IntegratorKind k = c.opt.integrator;
    if (k == IntegratorKind::Direct || k == IntegratorKind::Path) {
        if (aov && found && hit.object >= 0) FillAovs(c, ray, hit, c.rs.Interact(ray, hit), aov);
        if (c.tsc && k == IntegratorKind::Path) {
            // Diffuse indirect from the cache; glossy materials stay per hit (view-dependent).
            // Diffuse light is view-independent: diffuse materials take it from the cache
            // (direct + indirect, or indirect only); glossy ones stay per hit.
            auto cached = [&](const SurfaceInteraction& si0, const Ray& r0, glm::vec3* term) {
                if (c.scene.materials[si0.material].type != Material::Type::Diffuse)
                    return CachedTerm::None;
                const SurfaceInteraction sd = c.rs.Interact(r0, hit, &diff);
                const bool all = c.opt.texture.cacheDirect;
                const glm::vec3 E = CachedLookup(
                    c, sd,
                    [&](const SampleRequest& r) { return ShadeDiffuseSample(c, r, all, rays); },
                    c.opt.texture.indirectSamples);
                *term = c.rs.Albedo(si0) * E;
                return all ? CachedTerm::All : CachedTerm::Indirect;
            };
            return SplitAtHit(c, x, y, s, rng, [&](Rng& r) {
                return LiPath(c, ray, hit, found, r, c.opt.maxDepth, rays, true, cached);
            });
        }
        if (c.tsc && k == IntegratorKind::Direct)
            return SplitAtHit(c, x, y, s, rng, [&](Rng& r) {
                return LiDirectCachedShadows(c, ray, hit, found, r, diff, rays);
            });
        return SplitAtHit(c, x, y, s, rng, [&](Rng& r) {
            return LiPath(c, ray, hit, found, r, k == IntegratorKind::Direct ? 1 : c.opt.maxDepth,
                          rays);
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
            return LiAO(c, ray, si, rng, rays);
        default:
            return glm::vec3(0.0f);
    }
}

/// Per-hit AO for a tile in two phases: all camera rays first, then the AO rays of every hit.
/// Same samples, same random numbers, same result as Sample(); tracing like rays together keeps
/// Embree's working set (and the traversal's caches) warm, as a wavefront renderer would.
void AoTileTwoPhase(const Context& c, int y0, int y1, int x0, int x1, int s0, int s1,
                    std::vector<double>& sum, RayCounts& rays) {
    struct Pending {
        Ray ray;
        Hit hit;
        Rng rng;
        int pixel;
        bool found;
        RayDifferentials diff;
    };
    thread_local std::vector<Pending> queue;
    queue.clear();
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x)
            for (int s = s0; s < s1; ++s) {
                Pending p{Ray{}, Hit{}, Rng(0, 0), y * c.opt.width + x, false, {}};
                p.ray = CameraRay(c, x, y, s, &p.rng, c.tsc ? &p.diff : nullptr);
                ++rays.camera;
                p.found = c.rs.Intersect(p.ray, &p.hit);
                queue.push_back(p);
            }
    auto add = [&](const Pending& p, glm::vec3 L) {
        double* px = &sum[3 * size_t(p.pixel)];
        px[0] += L.x, px[1] += L.y, px[2] += L.z;
    };
    if (!c.tsc) {
        for (Pending& p : queue) {
            glm::vec3 L(0.0f);
            if (p.found)
                L = p.hit.object < 0 ? glm::vec3(1.0f)
                                     : LiAO(c, p.ray, c.rs.Interact(p.ray, p.hit), p.rng, rays);
            add(p, L);
        }
        return;
    }
    // Texture space: all shading points first, prefetching their texel slots, then the lookups,
    // so the latency of a large texel table overlaps instead of stalling every hit.
    thread_local std::vector<SurfaceInteraction> points;
    thread_local std::vector<SampleRequest> texels;
    points.resize(queue.size());
    texels.resize(queue.size());
    const bool lookups = c.opt.texture.constantTerm < 0.0f;
    for (size_t i = 0; i < queue.size(); ++i) {
        const Pending& p = queue[i];
        if (!p.found || p.hit.object < 0) continue;
        points[i] = c.rs.Interact(p.ray, p.hit, &p.diff);
        if (lookups) {
            texels[i] = TexelOf(c, points[i]);
            c.tsc->cache().Prefetch(texels[i]);
        }
    }
    CacheStats& stats = c.cacheStats->local();
    for (size_t i = 0; i < queue.size(); ++i) {
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

/// The visibility prepass of a tile (see texcache/visible_texels.h): marks the texel each camera
/// sample lands on, with the rays, differentials and texel selection of the shading pass.
void MarkVisibleTexels(const Context& c, VisibleTexels& visible, int y0, int y1, int x0, int x1,
                       int s0, int s1, RayCounts& rays) {
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x)
            for (int s = s0; s < s1; ++s) {
                Rng rng(0, 0);
                RayDifferentials diff;
                const Ray ray = CameraRay(c, x, y, s, &rng, &diff);
                ++rays.camera;
                Hit hit;
                if (!c.rs.Intersect(ray, &hit) || hit.object < 0) continue;
                visible.Mark(TexelOf(c, c.rs.Interact(ray, hit, &diff)).key);
            }
}

/// Restricts a cache's footprints for the duration of a render (whatever way it ends).
class FootprintRestriction {
public:
    FootprintRestriction(RenderShadingCache* cache, const VisibleTexels* visible) : cache_(cache) {
        if (cache_) cache_->RestrictFootprints(visible);
    }
    ~FootprintRestriction() {
        if (cache_) cache_->RestrictFootprints(nullptr);
    }
    FootprintRestriction(const FootprintRestriction&) = delete;
    FootprintRestriction& operator=(const FootprintRestriction&) = delete;

private:
    RenderShadingCache* cache_;
};

/// Prints a progress bar on stderr once a render has run for a second.
class Progress {
public:
    Progress(bool enabled, std::function<double()> fraction)
        : fraction_(std::move(fraction)), start_(Clock::now()) {
        if (enabled) thread_ = std::thread([this] { Loop(); });
    }
    ~Progress() {
        {
            std::lock_guard<std::mutex> lock(m_);
            done_ = true;
        }
        cv_.notify_all();
        if (thread_.joinable()) thread_.join();
        if (printed_) std::fprintf(stderr, "\n");
    }

private:
    using Clock = std::chrono::steady_clock;
    void Loop() {
        std::unique_lock<std::mutex> lock(m_);
        while (!cv_.wait_for(lock, std::chrono::milliseconds(250), [this] { return done_; })) {
            const double t = std::chrono::duration<double>(Clock::now() - start_).count();
            if (t < 1.0) continue;
            const double f = std::clamp(fraction_(), 0.0, 1.0);
            const double eta = f > 0.0 ? t / f - t : 0.0;
            if (!tty_) {
                // A log file gets a plain line every 10 s, not a redrawn bar every 250 ms.
                if (t < nextLine_) continue;
                nextLine_ = t + 10.0;
                std::fprintf(stderr, "render %3d%%  %.0fs elapsed, %.0fs left\n", int(f * 100.0), t,
                             eta);
                continue;
            }
            const int w = 30, n = int(f * w);
            std::fprintf(stderr, "\rrender [%.*s%*s] %3d%%  %.1fs elapsed, %.1fs left  ", n,
                         "==============================", w - n, "", int(f * 100.0), t, eta);
            std::fflush(stderr);
            printed_ = true;
        }
    }
    std::function<double()> fraction_;
    Clock::time_point start_;
    std::thread thread_;
    std::mutex m_;
    std::condition_variable cv_;
    bool done_ = false, printed_ = false;
    bool tty_ = isatty(fileno(stderr)) != 0;
    double nextLine_ = 0.0;
};

}  // namespace

uint64_t PixelSeed(uint64_t seed, int x, int y, int width) {
    return MixBits(seed * 0x9E3779B97F4A7C15ull + uint64_t(y) * uint64_t(width) + uint64_t(x));
}

IntegratorKind ParseIntegrator(const std::string& name, const std::string& where) {
    for (const Named& n : kIntegrators)
        if (name == n.name) return n.kind;
    throw InputError(where, "unknown integrator '" + name + "' (valid: " + IntegratorNames() + ")");
}

const char* IntegratorNames() {
    return "normal, ptex, uv, eyelight, ao, direct, path";
}

bool IntegratorUsesLights(IntegratorKind k) {
    return k == IntegratorKind::Direct || k == IntegratorKind::Path;
}

RenderResult Render(const RenderScene& rs, const RenderOptions& opt, TextureSpaceCache* cache) {
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    const std::clock_t cpuStart = std::clock();
    Context ctx(rs, opt);
    std::unique_ptr<TextureSpaceCache> frameCache;
    tbb::enumerable_thread_specific<CacheStats> cacheStats;
    const bool cachedIntegrator = opt.integrator == IntegratorKind::AO ||
                                  opt.integrator == IntegratorKind::Path ||
                                  opt.integrator == IntegratorKind::Direct;
    if (opt.texture.enabled && cachedIntegrator) {
        if (!cache) {
            frameCache = std::make_unique<TextureSpaceCache>(rs, opt.texture);
            cache = frameCache.get();
        }
        ctx.tsc = cache;
        ctx.cacheStats = &cacheStats;
    }
    const int W = opt.width, H = opt.height;
    // Footprints of visible texels only: the prepass of each pass below marks them.
    const FootprintMode fm = opt.texture.footprint;
    const bool visibleOnly = fm == FootprintMode::Visible ||
                             (fm == FootprintMode::Auto && opt.integrator == IntegratorKind::AO);
    VisibleTexels* visible =
        ctx.tsc && visibleOnly && opt.texture.constantTerm < 0.0f && ctx.tsc->AnyFootprint()
            ? &ctx.tsc->Visibility(W, H)
            : nullptr;
    const FootprintRestriction restriction(visible ? &ctx.tsc->cache() : nullptr, visible);
    const size_t numPixels = size_t(W) * H;
    if (opt.pixelCache) {
        opt.pixelCache->assign(numPixels, PixelCacheCounts{});
        if (ctx.tsc) ctx.pixelCache = opt.pixelCache->data();
    }

    std::vector<double> sum(numPixels * 3, 0.0);
    std::vector<PixelAovs> aovs(opt.aovs.Any() ? numPixels : 0);
    // Per-hit AO traces a tile's camera rays first, then its AO rays (see AoTileTwoPhase).
    bool twoPhaseAo = opt.integrator == IntegratorKind::AO && aovs.empty();
    tbb::enumerable_thread_specific<RayCounts> counts;

    // Passes of whole sample indices: a pixel's result depends only on its sample indices, so
    // the image is the same for any thread count or pass split.
    const int sppCap = std::max(opt.spp, 1);
    std::atomic<uint64_t> pixelSamplesDone{0};
    const double totalWork = double(numPixels) * sppCap;
    auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
    int done = 0;
    {
        Progress progress(opt.progress, [&] {
            if (opt.seconds > 0.0f)
                return std::max(elapsed() / opt.seconds, double(pixelSamplesDone) / totalWork);
            return double(pixelSamplesDone.load()) / totalWork;
        });
        int passSpp = opt.seconds > 0.0f ? 1 : sppCap;
        while (done < sppCap) {
            const int s0 = done, s1 = std::min(sppCap, done + passSpp);
            const auto passStart = Clock::now();
            if (visible)
                tbb::parallel_for(tbb::blocked_range2d<int>(0, H, 8, 0, W, 8),
                                  [&](const tbb::blocked_range2d<int>& r) {
                                      _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
                                      _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
                                      MarkVisibleTexels(ctx, *visible, r.rows().begin(),
                                                        r.rows().end(), r.cols().begin(),
                                                        r.cols().end(), s0, s1, counts.local());
                                  });
            tbb::parallel_for(
                tbb::blocked_range2d<int>(0, H, 8, 0, W, 8),
                [&](const tbb::blocked_range2d<int>& r) {
                    // Denormals off in every worker: Embree wants it and it saves stalls in
                    // shading.
                    _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
                    _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
                    RayCounts& rc = counts.local();
                    if (twoPhaseAo) {
                        AoTileTwoPhase(ctx, r.rows().begin(), r.rows().end(), r.cols().begin(),
                                       r.cols().end(), s0, s1, sum, rc);
                        pixelSamplesDone +=
                            uint64_t(r.rows().size()) * r.cols().size() * uint64_t(s1 - s0);
                        return;
                    }
                    // The thread's cache counters, read around each pixel for its heat-map counts.
                    CacheStats* pixelStats = ctx.pixelCache ? &cacheStats.local() : nullptr;
                    for (int y = r.rows().begin(); y < r.rows().end(); ++y)
                        for (int x = r.cols().begin(); x < r.cols().end(); ++x) {
                            const size_t p = size_t(y) * W + x;
                            PixelAovs* aov = aovs.empty() ? nullptr : &aovs[p];
                            const CacheSnapshot before =
                                pixelStats ? CacheSnapshot(*pixelStats) : CacheSnapshot();
                            glm::dvec3 acc(0.0);
                            for (int s = s0; s < s1; ++s) {
                                glm::vec3 L = Sample(ctx, x, y, s, aov, rc);
                                // A NaN/Inf sample would poison the pixel forever: drop it.
                                if (std::isfinite(L.x) && std::isfinite(L.y) && std::isfinite(L.z))
                                    acc += glm::dvec3(L);
                            }
                            sum[3 * p] += acc.x, sum[3 * p + 1] += acc.y, sum[3 * p + 2] += acc.z;
                            if (pixelStats) AddPixelCounts(&ctx.pixelCache[p], before, *pixelStats);
                        }
                    pixelSamplesDone +=
                        uint64_t(r.rows().size()) * r.cols().size() * uint64_t(s1 - s0);
                });
            done = s1;
            if (opt.seconds > 0.0f) {
                const double passTime =
                    std::chrono::duration<double>(Clock::now() - passStart).count();
                const double left = opt.seconds - elapsed();
                if (left <= 0.0) break;
                // Size the next pass to fit the remaining budget (at most doubling).
                const double perSample = passTime / double(s1 - s0);
                passSpp = std::clamp(int(left / std::max(perSample, 1e-9)), 0, 2 * (s1 - s0));
                if (passSpp == 0) break;
            }
        }
    }

    RenderResult result;
    result.beauty = Image(W, H, 3);
    for (size_t p = 0; p < numPixels * 3; ++p) result.beauty.data[p] = float(sum[p] / done);
    if (!aovs.empty()) {
        auto layer = [&](const char* name, int ch, std::vector<std::string> names, auto fill) {
            ImageLayer l{name, Image(W, H, ch), std::move(names)};
            for (size_t p = 0; p < numPixels; ++p) fill(aovs[p], &l.image.data[p * ch]);
            result.aovs.push_back(std::move(l));
        };
        const float inv = 1.0f / float(done);
        if (opt.aovs.albedo)
            layer("albedo", 3, {"R", "G", "B"}, [&](const PixelAovs& a, float* o) {
                for (int k = 0; k < 3; ++k) o[k] = a.albedo[k] * inv;
            });
        if (opt.aovs.normal)
            layer("normal", 3, {"X", "Y", "Z"}, [&](const PixelAovs& a, float* o) {
                const float l = glm::length(a.normal);
                for (int k = 0; k < 3; ++k) o[k] = l > 0.0f ? a.normal[k] / l : 0.0f;
            });
        if (opt.aovs.depth)
            layer("depth", 1, {"Z"}, [&](const PixelAovs& a, float* o) {
                o[0] = a.hits ? a.depth / float(a.hits) : INFINITY;
            });
        if (opt.aovs.ptex)
            layer("ptex", 3, {"face", "u", "v"}, [&](const PixelAovs& a, float* o) {
                o[0] = a.hits ? a.ptex.x : -1.0f, o[1] = a.ptex.y, o[2] = a.ptex.z;
            });
        if (opt.aovs.motion)
            layer("motion", 2, {"X", "Y"}, [&](const PixelAovs& a, float* o) {
                o[0] = a.hits ? a.motion.x / float(a.hits) : 0.0f;
                o[1] = a.hits ? a.motion.y / float(a.hits) : 0.0f;
            });
    }
    for (const RayCounts& rc : counts) {
        result.stats.cameraRays += rc.camera;
        result.stats.shadowRays += rc.shadow;
        result.stats.bounceRays += rc.bounce;
    }
    for (const CacheStats& cs : cacheStats) result.stats.cache.Merge(cs);
    result.stats.sppDone = done;
    result.stats.seconds = elapsed();
    result.stats.cpuSeconds = double(std::clock() - cpuStart) / CLOCKS_PER_SEC;
    return result;
}

// ---- screen-space frame buffers (frame_buffers_render.h) ------------------------------------

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// Unshadowed light samples per frame-buffer sample for `shading` (no rays: BSDF and light
// evaluations only). Measured noise: frame_buffers_render.h.
constexpr int kShadingCandidates = 32;
const glm::vec3 kNaN3(kNaN);

/// Where everything that moves was at the previous frame: world at the frame time -> world at
/// prevTime, per object and per quad light (T^-1 of Zeng eq. 1/3/5), and distant lights'
/// direction rotations.
struct FrameMotion {
    std::vector<glm::mat4> object, light;
    std::vector<glm::mat3> objectN, lightN;  // their normal matrices
    std::vector<glm::mat3> distant;
    float infinity = 1e4f;  // distance at which points of lights at infinity are put

    FrameMotion(const RenderScene& rs, const RenderOptions& opt, float prevTime) {
        const Scene& scene = rs.scene();
        auto normalMatrix = [](const glm::mat4& m) {
            return glm::transpose(glm::inverse(glm::mat3(m)));
        };
        float extent = glm::length(glm::vec3(scene.camera.pose.Eval(opt.frameTime)[3]));
        for (size_t o = 0; o < scene.objects.size(); ++o) {
            // The frame's pose is the render scene's (shutter time 0), so moved points start
            // exactly where the rays found them.
            const glm::mat4 now = rs.ObjectToWorld(int(o), 0.0f);
            object.push_back(scene.objects[o].transform.Eval(prevTime) * glm::inverse(now));
            objectN.push_back(normalMatrix(object.back()));
            for (const auto& p : scene.meshes[scene.objects[o].mesh].positions)
                extent = std::max(extent,
                                  glm::length(glm::vec3(now * glm::vec4(p[0], p[1], p[2], 1.0f))));
        }
        for (const QuadLight& q : scene.quadLights) {
            light.push_back(q.transform.Eval(prevTime) *
                            glm::inverse(q.transform.Eval(opt.frameTime)));
            lightN.push_back(normalMatrix(light.back()));
        }
        for (const DistantLight& d : scene.distantLights)
            distant.push_back(glm::mat3(d.transform.Eval(prevTime)) *
                              glm::inverse(glm::mat3(d.transform.Eval(opt.frameTime))));
        // Far enough that the line from a blocker to it has the light's direction to ~1e-4.
        infinity = 1e4f * std::max(extent, 1e-3f);
    }

    /// A point on what a ray hit, moved to the previous frame.
    glm::vec3 Point(const Hit& h, glm::vec3 p) const {
        const glm::mat4& m = h.object >= 0 ? object[h.object] : light[h.light];
        return glm::vec3(m * glm::vec4(p, 1.0f));
    }
    glm::vec3 Normal(const Hit& h, glm::vec3 n) const {
        return glm::normalize((h.object >= 0 ? objectN[h.object] : lightN[h.light]) * n);
    }
};

/// One pixel's buffers while its samples are taken.
struct FramePixel {
    glm::vec3 shadingSum{0.0f}, glossySum{0.0f}, diffuseSum{0.0f};
    float weightSum = 0.0f, visibleWeightSum = 0.0f;
    float blockerWeight = -1.0f;  // shading luminance of the recorded blocked sample
    glm::vec3 blocker = kNaN3, prevBlocker = kNaN3, light = kNaN3, prevLight = kNaN3;
    glm::vec3 glossyHit = kNaN3, prevGlossyHit = kNaN3;
    std::array<glm::vec3, screen::kNumCones> coneSum{};
    bool hasCones = false;  ///< a diffuse ray was traced
};

glm::vec3 FiniteOrZero(glm::vec3 v) {
    return std::isfinite(v.x + v.y + v.z) ? v : glm::vec3(0.0f);
}

/// The light sample of one frame-buffer sample: unshadowed shading into `px` from
/// kShadingCandidates light samples, and one shadow ray to a candidate resampled in proportion to
/// its shading's luminance, with the blocker and light point when blocked (see
/// frame_buffers_render.h).
void FrameDirectSample(const Context& c, const FrameMotion& motion, const SurfaceInteraction& si,
                       const Bsdf& bsdf, glm::vec3 wo, Rng& rng, FramePixel& px, RayCounts& rays) {
    // Candidates: the light pick stratified over [0, 1) (each light gets its share exactly, so a
    // delta light's term is exact), the point on the light from the R2 sequence (Roberts 2018:
    // any run of it is evenly spread), both randomly shifted (Cranley-Patterson: unbiased).
    constexpr int kN = kShadingCandidates;
    constexpr float kG1 = 0.75487766f, kG2 = 0.56984029f;  // 1/phi_2, 1/phi_2^2
    const float pickShift = rng.Next1D();
    const glm::vec2 shift = rng.Next2D();
    const float uResample = rng.Next1D();
    LightSample cand[kN];
    glm::vec3 S[kN];
    float lum[kN];
    glm::vec3 sum(0.0f);
    float lumSum = 0.0f;
    for (int k = 0; k < kN; ++k) {
        lum[k] = 0.0f, S[k] = glm::vec3(0.0f);
        const float uPick = (float(k) + pickShift) / float(kN);
        const glm::vec2 u(std::fmod(shift.x + kG1 * float(k), 1.0f),
                          std::fmod(shift.y + kG2 * float(k), 1.0f));
        LightSample& ls = cand[k];
        if (!c.SampleLight(si.P, std::min(uPick, kOneMinusEpsilon),
                           glm::min(u, glm::vec2(kOneMinusEpsilon)), &ls))
            continue;
        glm::vec3 fd, fs;
        bsdf.EvalLobes(wo, ls.wi, &fd, &fs);
        // The specular ray may find this light too (in `glossy`): MIS between the two for that
        // lobe.
        const float wSpec = ls.delta || !bsdf.HasSpecular()
                                ? 1.0f
                                : PowerHeuristic(1, ls.pdf, 1, bsdf.PdfSpecular(wo, ls.wi));
        const float cosi = std::abs(glm::dot(ls.wi, si.N));
        S[k] = FiniteOrZero((fd + wSpec * fs) * ls.Li * (ls.delta ? cosi : cosi / ls.pdf));
        lum[k] = Luminance(glm::abs(S[k]));
        sum += S[k], lumSum += lum[k];
    }
    if (!(lumSum > 0.0f)) return;  // no shadow ray: counts as visible (see the header)
    const glm::vec3 Sbar = sum / float(kN);
    px.shadingSum += Sbar;
    const float w = Luminance(glm::abs(Sbar));
    px.weightSum += w;
    // The shadow ray's candidate: index j with probability lum_j / sum lum.
    int j = 0;
    float acc = lum[0], target = uResample * lumSum;
    while (j + 1 < kN && (acc <= target || lum[j] <= 0.0f)) acc += lum[++j];
    while (lum[j] <= 0.0f) --j;  // rounding ran past the last candidate with shading
    const LightSample& ls = cand[j];
    const Ray shadow = ShadowRay(si, ls, 0.0f);
    Hit bh;
    ++rays.shadow;
    if (!c.rs.Intersect(shadow, &bh)) {
        px.visibleWeightSum += w;
        return;
    }
    if (w <= px.blockerWeight) return;
    px.blockerWeight = w;
    px.blocker = shadow.org + bh.t * shadow.dir;
    px.prevBlocker = motion.Point(bh, px.blocker);
    if (ls.quad >= 0) {
        px.light = si.P + ls.dist * ls.wi;  // the sampled point of the quad
        px.prevLight = glm::vec3(motion.light[ls.quad] * glm::vec4(px.light, 1.0f));
    } else {
        // At infinity: a far point along the light direction from the blocker, so the line from
        // the light point through the blocker has the light's direction in both frames.
        const glm::vec3 prevDir =
            ls.distant >= 0 ? glm::normalize(motion.distant[ls.distant] * ls.wi) : ls.wi;
        px.light = px.blocker + motion.infinity * ls.wi;
        px.prevLight = px.prevBlocker + motion.infinity * prevDir;
    }
}

/// The specular lobe's path of one sample into px.glossySum (and its first hit).
void FrameGlossySample(const Context& c, const FrameMotion& motion, const SurfaceInteraction& si,
                       const Bsdf& bsdf, glm::vec3 wo, Rng& rng, FramePixel& px, RayCounts& rays) {
    glm::vec3 wi, weight;
    float pdf;
    if (!bsdf.SampleSpecular(wo, rng.Next2D(), &wi, &weight, &pdf)) return;
    Ray ray;
    ray.org = OffsetOrigin(si.P, si.Ng, wi);
    ray.dir = wi;
    Hit hit;
    ++rays.bounce;
    const bool found = c.rs.Intersect(ray, &hit);
    glm::vec3 L(0.0f);
    if (!found) {
        // Direct light from the environment: the light sample's MIS partner.
        if (c.env) L = c.env->Eval(wi) * PowerHeuristic(1, pdf, 1, c.env->Pdf(wi) * c.PickPdf());
    } else if (hit.light >= 0) {
        L = c.QuadEmission(hit.light, wi) *
            PowerHeuristic(1, pdf, 1, c.QuadPdf(hit.light, wi, hit.t));
    } else {
        // Light found at the hit (NEE) and beyond; emission at this hit was handled above.
        L = LiPath(c, ray, hit, found, rng, c.opt.maxDepth - 1, rays, false);
    }
    px.glossySum += FiniteOrZero(weight * L);
    if (found && !std::isfinite(px.glossyHit.x)) {
        px.glossyHit = ray.org + hit.t * ray.dir;
        px.prevGlossyHit = motion.Point(hit, px.glossyHit);
    }
}

/// The diffuse lobe's path of one sample: incident indirect radiance into px.diffuseSum and its
/// cone.
void FrameDiffuseSample(const Context& c, const SurfaceInteraction& si, const Bsdf& bsdf,
                        glm::vec3 wo, const std::array<glm::vec3, screen::kNumCones>& axes,
                        Rng& rng, FramePixel& px, RayCounts& rays) {
    glm::vec3 wi;
    glm::vec3 L(0.0f);
    if (bsdf.SampleDiffuse(wo, rng.Next2D(), &wi)) {
        Ray ray;
        ray.org = OffsetOrigin(si.P, si.Ng, wi);
        ray.dir = wi;
        Hit hit;
        ++rays.bounce;
        const bool found = c.rs.Intersect(ray, &hit);
        // Light hit directly is the light sample's: emitFirst = false.
        L = FiniteOrZero(LiPath(c, ray, hit, found, rng, c.opt.maxDepth - 1, rays, false));
    }
    px.diffuseSum += L;
    // Cosine-sampled: L is this sample's estimate of irradiance / pi (see AddConeSample).
    screen::AddConeSample(axes, wi, L, px.coneSum.data());
    px.hasCones = true;
}

/// All buffers of pixel (x, y).
void FramePixelBuffers(const Context& c, const FrameMotion& motion, int x, int y,
                       screen::FrameBuffers& fb, RayCounts& rays) {
    const size_t p = size_t(y) * size_t(c.opt.width) + size_t(x);
    RayDifferentials diff;
    // Pixel centre, lens centre, shutter open: exact guides (see the header).
    Ray ray = c.camera.Generate(float(x) + 0.5f, float(y) + 0.5f, glm::vec2(0.5f),
                                c.tsc ? &diff : nullptr);
    ray.time = 0.0f;
    ++rays.camera;
    Hit hit;
    if (!c.rs.Intersect(ray, &hit)) {
        if (c.env) fb.emitted[p] = c.env->Eval(ray.dir);
        return;
    }
    if (hit.light >= 0) {
        fb.emitted[p] = c.QuadEmission(hit.light, ray.dir);
        const glm::vec3 P = ray.org + hit.t * ray.dir;
        glm::vec3 n = c.quads[hit.light].n;
        if (glm::dot(n, ray.dir) > 0.0f) n = -n;
        fb.position[p] = P;
        fb.normal[p] = n;
        fb.depth[p] = hit.t;
        fb.prevPosition[p] = motion.Point(hit, P);
        fb.prevNormal[p] = motion.Normal(hit, n);
        return;
    }
    const SurfaceInteraction si = c.rs.Interact(ray, hit, c.tsc ? &diff : nullptr);
    const Bsdf bsdf = MakeBsdf(c, si);
    const Material& m = c.scene.materials[si.material];
    fb.position[p] = si.P;
    fb.normal[p] = si.N;
    fb.depth[p] = hit.t;
    fb.roughness[p] = bsdf.Alpha();
    fb.albedo[p] = bsdf.DiffuseReflectance();
    fb.specular[p] = bsdf.HasSpecular() ? m.specular : glm::vec3(0.0f);
    fb.objectId[p] = si.object;
    fb.prevPosition[p] = motion.Point(hit, si.P);
    fb.prevNormal[p] = motion.Normal(hit, si.N);
    if (c.opt.maxDepth < 1) return;  // the path tracer sees emission only

    const glm::vec3 wo = -ray.dir;
    // The shading normal can face away from the camera where the tessellation does not: the
    // BSDF is 0 there, and there is no diffuse ray (nor cone sample).
    const bool diffuse = bsdf.DiffuseReflectance() != glm::vec3(0.0f) && c.opt.maxDepth >= 2 &&
                         glm::dot(wo, si.N) > 0.0f;
    // Diffuse materials take indirect light from the texture-space cache, as Render() does.
    const bool cachedIndirect = diffuse && c.tsc && m.type == Material::Type::Diffuse;
    if (cachedIndirect) {
        const glm::vec3 E = CachedLookup(
            c, si, [&](const SampleRequest& r) { return ShadeDiffuseSample(c, r, false, rays); },
            c.opt.texture.indirectSamples);
        fb.indirect[p] = FiniteOrZero(bsdf.DiffuseReflectance() * E);
    }
    const std::array<glm::vec3, screen::kNumCones> axes = screen::ConeAxes(si.N);
    FramePixel px;
    const int spp = std::max(c.opt.spp, 1);
    for (int s = 0; s < spp; ++s) {
        Rng rng(PixelSeed(c.opt.seed, x, y, c.opt.width), uint64_t(s));
        FrameDirectSample(c, motion, si, bsdf, wo, rng, px, rays);
        if (bsdf.HasSpecular()) FrameGlossySample(c, motion, si, bsdf, wo, rng, px, rays);
        if (diffuse && !cachedIndirect) FrameDiffuseSample(c, si, bsdf, wo, axes, rng, px, rays);
    }
    const float inv = 1.0f / float(spp);
    fb.shading[p] = px.shadingSum * inv;
    fb.visibility[p] = px.weightSum > 0.0f ? px.visibleWeightSum / px.weightSum : 1.0f;
    fb.glossy[p] = px.glossySum * inv;
    if (!cachedIndirect) fb.indirect[p] = bsdf.DiffuseReflectance() * px.diffuseSum * inv;
    if (fb.visibility[p] < 1.0f) {
        fb.blocker[p] = px.blocker;
        fb.prevBlocker[p] = px.prevBlocker;
        fb.lightSample[p] = px.light;
        fb.prevLightSample[p] = px.prevLight;
    }
    fb.glossyHit[p] = px.glossyHit;
    fb.prevGlossyHit[p] = px.prevGlossyHit;
    if (px.hasCones)
        for (int k = 0; k < screen::kNumCones; ++k)
            fb.cones[p * screen::kNumCones + k] = px.coneSum[k] * inv;
}

}  // namespace

RenderStats RenderFrameBuffers(const RenderScene& rs, const RenderOptions& options, float prevTime,
                               screen::FrameBuffers* out, TextureSpaceCache* cache) {
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    if (options.width <= 0 || options.height <= 0)
        throw InputError("frame buffers", "frame size must be positive, got " +
                                              std::to_string(options.width) + "x" +
                                              std::to_string(options.height));
    if (!std::isfinite(prevTime))
        throw InputError("frame buffers", "the previous frame's time is not finite");
    RenderOptions opt = options;
    opt.integrator = IntegratorKind::Path;  // the Context builds the lights for it
    Context ctx(rs, opt);
    std::unique_ptr<TextureSpaceCache> frameCache;
    tbb::enumerable_thread_specific<CacheStats> cacheStats;
    if (opt.texture.enabled) {
        if (!cache) {
            frameCache = std::make_unique<TextureSpaceCache>(rs, opt.texture);
            cache = frameCache.get();
        }
        ctx.tsc = cache;
        ctx.cacheStats = &cacheStats;
    }
    const FrameMotion motion(rs, opt, prevTime);

    screen::FrameBuffers& fb = *out;
    const int W = opt.width, H = opt.height;
    fb.width = W;
    fb.height = H;
    fb.time = opt.frameTime;
    fb.camera = MakeFrameCamera(rs.scene().camera, opt.frameTime, W, H);
    const size_t n = fb.NumPixels();
    // assign() keeps the capacity of a FrameBuffers reused across frames.
    const glm::vec3 zero(0.0f);
    fb.emitted.assign(n, zero);
    fb.shading.assign(n, zero);
    fb.visibility.assign(n, 1.0f);
    fb.glossy.assign(n, zero);
    fb.indirect.assign(n, zero);
    fb.position.assign(n, kNaN3);
    fb.normal.assign(n, kNaN3);
    fb.depth.assign(n, INFINITY);
    fb.roughness.assign(n, 0.0f);
    fb.albedo.assign(n, zero);
    fb.specular.assign(n, zero);
    fb.objectId.assign(n, -1);
    fb.prevPosition.assign(n, kNaN3);
    fb.prevNormal.assign(n, kNaN3);
    for (auto* v : {&fb.blocker, &fb.prevBlocker, &fb.lightSample, &fb.prevLightSample,
                    &fb.glossyHit, &fb.prevGlossyHit})
        v->assign(n, kNaN3);
    fb.cones.assign(n * screen::kNumCones, kNaN3);

    tbb::enumerable_thread_specific<RayCounts> counts;
    tbb::parallel_for(tbb::blocked_range2d<int>(0, H, 8, 0, W, 8),
                      [&](const tbb::blocked_range2d<int>& r) {
                          _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
                          _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
                          RayCounts& rc = counts.local();
                          for (int y = r.rows().begin(); y < r.rows().end(); ++y)
                              for (int x = r.cols().begin(); x < r.cols().end(); ++x)
                                  FramePixelBuffers(ctx, motion, x, y, fb, rc);
                      });

    RenderStats stats;
    for (const RayCounts& rc : counts) {
        stats.cameraRays += rc.camera;
        stats.shadowRays += rc.shadow;
        stats.bounceRays += rc.bounce;
    }
    for (const CacheStats& cs : cacheStats) stats.cache.Merge(cs);
    stats.sppDone = std::max(opt.spp, 1);
    stats.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return stats;
}

}  // namespace texcache
