// SPDX-License-Identifier: Apache-2.0
#include "renderer/texture_space/cached_shading.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "renderer/texture_space/ptex_mapping.h"

namespace texcache::internal {

namespace {

/// Seed of a cache sample's random streams: a function of its key and the cache's pass, so the
/// same texel gets the same shading whichever thread shades it, a re-shade after eviction
/// reproduces it, and each progressive pass shades it anew.
uint64_t SampleSeed(const Context& c, const SampleRequest& r) {
    const uint64_t pass = c.tsc->Pass();
    return MixBits(c.opt.seed ^ (r.key.Pack() * 0x9E3779B97F4A7C15ull) ^
                   (pass * 0xD1B54A32D192ED03ull));
}

Rng SampleRng(const Context& c, const SampleRequest& r) {
    return Rng(SampleSeed(c, r), 0x7ca7);
}

/// Where in its texel a sample is shaded: the centre in pass 0 (the paper's grid), a uniform
/// point of the texel in later passes, so that the mean over passes is the texel's mean shading
/// rather than its centre's (see the consistency note in texture_space.h).
PtexCoord SamplePosition(const Context& c, const SampleRequest& r) {
    if (c.tsc->Pass() == 0) return {r.face, r.u, r.v};
    Rng rng(SampleSeed(c, r), 0x1177e7);
    const float texel = 1.0f / float(c.tsc->Resolution(r));
    const glm::vec2 j = rng.Next2D() - 0.5f;
    return {r.face, std::clamp(r.u + j.x * texel, 0.0f, 1.0f),
            std::clamp(r.v + j.y * texel, 0.0f, 1.0f)};
}

/// Whether a hit of a sample's snap ray is on the sample's own sheet of the tessellation: on its
/// Ptex face `face`, tessellated facing the same way as the limit surface there (`n`, the limit
/// normal before any back-side flip; object transforms keep orientation), or on a face across an
/// edge of it (texels at a face's border may snap onto the neighbour) that continues the surface
/// smoothly (within 60 degrees) or lies `above` the limit point. Not onto the far side of a
/// crease below the point: rays would start on a wall across their hemisphere.
bool OnOwnSheet(const RenderScene& rs, const PtexTopology& topo, int face, glm::vec3 n,
                const Hit& h, bool above) {
    const float cosine = glm::dot(glm::normalize(h.Ng), n);
    if (!(cosine > 0.0f)) return false;
    const int f = rs.HitPtex(h).face;
    if (f == face) return true;
    if (!(cosine > 0.5f || above)) return false;
    for (int e = 0; e < 4; ++e) {
        const PtexTopology::EdgeLink& link = topo.Edge(face, e);
        for (int k = 0; k < link.count; ++k)
            if (link.face[k] == f) return true;
    }
    return false;
}

/// Limit-surface point of a cache sample, and the origin its secondary rays start from. The
/// rays hit the tessellated surface, which at the default tessellation rate (2) lies off the
/// limit surface by up to 2.2% of the face's size (99th percentile of texel centres over the
/// bundled cages), 4.8% (99.9th) and 22% (a crease of the car), above the limit point where the
/// surface is concave. A ray along -N against this object alone, from 25% of the face's size
/// above the point to as far below, finds the tessellated surface under the sample (OnOwnSheet),
/// and rays start just above it; other sheets of the object on the way are passed through (a
/// thin part over the face, the inner wall of a folded seam), at most kSheets rays in all.
/// (Taking the first hit within 3% put origins inside the car wherever the tessellation lay
/// higher: the ray started under it and missed, or found an inner wall, and every AO ray was
/// blocked: dark texels at any ray count.) With no own sheet in reach (a hole's border, a texel
/// centre beyond the tessellated edge of a crease), rays start at the limit point. Cost: one ray
/// per sample, plus one per sheet passed through (1-2% more over all texels of the bundled cages,
/// 0.1% in the car view). No ray-free offset is as robust: a fixed lift of 4.8% would still leave
/// 0.1% of the samples inside, and would put samples on big flat faces above nearby objects, e.g.
/// the ground under a car's sills; and the ground crossing the ray is not the car's surface: other
/// objects are not intersected. Where parts of a cage interpenetrate, a texel centre inside
/// another part still shades its own sheet there: dark, while the camera sees the part of the
/// texel on the other side of the seam.
bool SamplePoint(const Context& c, const SampleRequest& r, SurfaceSample* ss, glm::vec3* origin,
                 RayCounts& rays) {
    constexpr int kSheets = 4;
    const int object = c.tsc->ObjectOfMesh(r.mesh);
    if (!c.rs.EvalSurface(object, SamplePosition(c, r), 0.0f, ss)) return false;
    const glm::vec3 limitN = ss->N;
    // The back side of an open surface, or the outside of an inside-out closed one.
    if (c.tsc->SamplesAgainstNormal(r.mesh)) ss->N = -ss->N;
    if (!std::isfinite(ss->P.x + ss->P.y + ss->P.z + ss->N.x + ss->N.y + ss->N.z)) return false;
    const float edge = std::max(glm::length(ss->dPdu), glm::length(ss->dPdv));
    const float scale = std::max({1.0f, std::abs(ss->P.x), std::abs(ss->P.y), std::abs(ss->P.z)});
    const float eps = 2e-5f * scale;
    const float reach = 0.25f * edge + eps;
    Ray snap;
    snap.org = ss->P + reach * ss->N;
    snap.dir = -ss->N;
    snap.tfar = 2.0f * reach;
    const PtexTopology& topo = c.rs.Topology(object);
    float t = reach;  // the limit point, unless the own sheet is found
    Hit hit;
    for (int sheets = 0; sheets < kSheets; ++sheets) {
        ++rays.bounce;
        if (!c.rs.IntersectObject(object, snap, &hit)) break;
        if (OnOwnSheet(c.rs, topo, r.face, limitN, hit, hit.t < reach)) {
            t = hit.t;
            break;
        }
        snap.tnear = hit.t + eps;
    }
    *origin = snap.org + t * snap.dir + eps * ss->N;
    return true;
}

/// Motion blur: what a texel holds (issue 19). A texel holds the shutter's average, not one
/// instant: every ray a cache sample traces gets its own shutter time (stratified over the
/// sample's n rays, random per sample), as a camera hit's rays do per hit. The scene's objects,
/// occluders and receivers alike, are where they are at that time: the contact shadow of a
/// moving object on a static ground is then smeared over the shutter as in the per-hit render
/// (tests/blur_test.cpp). A sample of a moving object lives in its object's texture space (the
/// texel key is the object's Ptex face and (u,v), not a world position), so camera hits at any
/// time of the shutter share its texels; its rays start from the sample's point carried rigidly
/// from shutter open (where SamplePoint finds it) to the ray's time. The cached shading is
/// therefore the paper's "shading reused over the shutter", averaged like the reference's
/// rather than frozen at shutter open, which would leave moving shadows sharp. Without a shutter
/// no extra random number is drawn: static renders keep their streams.
class ShutterMotion {
public:
    ShutterMotion(const Context& c, int object)
        : c_(c), object_(object), blur_(c.shutterLength > 0.0f) {
        moves_ = blur_ && c.scene.objects[size_t(object)].transform.IsAnimated();
        if (moves_) toObject_ = glm::inverse(c.rs.ObjectToWorld(object, 0.0f));
    }
    /// Shutter time of ray i of n (stratified), 0 without motion blur.
    float Time(Rng& rng, int i, int n) const {
        return blur_ ? (float(i) + rng.Next1D()) / float(n) : 0.0f;
    }
    /// `ray` (origin and direction where the sample is at shutter open) and the sample's normal
    /// `n`, moved to where the sample is at `time`; the ray is stamped with the time.
    void Pose(float time, Ray* ray, glm::vec3* n) const {
        ray->time = time;
        if (!moves_) return;
        const glm::mat4 M = c_.rs.ObjectToWorld(object_, time) * toObject_;
        const glm::mat3 R(M);  // rigid: keyframes animate rotation and translation only
        ray->org = glm::vec3(M * glm::vec4(ray->org, 1.0f));
        ray->dir = glm::normalize(R * ray->dir);
        *n = glm::normalize(R * *n);
    }

private:
    const Context& c_;
    int object_;
    bool blur_, moves_ = false;
    glm::mat4 toObject_{1.0f};
};

/// The n cosine-distributed rays of a cache sample, in order: each with its shutter time and
/// posed (ShutterMotion), drawn from the sample's own random stream.
///
/// The directions are the Sobol' (0,2)-sequence (Sobol02), digitally shifted by a random pair of
/// the sample's own: each ray alone is cosine-distributed (the shift is uniform), so the sample is
/// an unbiased estimate, and its n rays form a (0,log2 n,2)-net when n is a power of two, whose
/// error falls faster than independent rays' (docs/texture-space.md, "Stratification"). One net
/// over the 16 samples of a 4x4 texel block (the filter averages them), shifted per block, gains
/// nothing at one ray per sample, where the filter's footprint sees parts of several blocks.
class CosineRays {
public:
    CosineRays(const Context& c, const SampleRequest& r, const SurfaceSample& ss, glm::vec3 origin,
               int n)
        : rng_(SampleRng(c, r)),
          frame_(Frame::FromZ(ss.N)),
          motion_(c, c.tsc->ObjectOfMesh(r.mesh)),
          origin_(origin),
          normal_(ss.N),
          n_(n),
          shift_(MixBits(SampleSeed(c, r) ^ 0x50b01ull)) {}
    /// Ray i (in order), and the sample's normal at its time in `N`.
    Ray Next(int i, glm::vec3* N) {
        const float time = motion_.Time(rng_, i, n_);
        Ray ray;
        ray.dir = frame_.FromLocal(
            SampleCosineHemisphere(Sobol02(uint32_t(i), uint32_t(shift_), uint32_t(shift_ >> 32))));
        ray.org = origin_;
        *N = normal_;
        motion_.Pose(time, &ray, N);
        return ray;
    }
    Rng& rng() { return rng_; }

private:
    Rng rng_;
    Frame frame_;
    ShutterMotion motion_;
    glm::vec3 origin_, normal_;
    int n_;
    uint64_t shift_;  ///< the digital shift of the sample's net: x in the low 32 bits
};

/// The mean of a sample's n ray values and the variance of that mean (luminance).
///
/// The rays are a (0,m,2)-net when n = 2^m (CosineRays), and the independent-ray formula
/// (sum of squares) overstates the variance of their mean by far: it ignores the
/// stratification (at 16 rays per sample the unfiltered car AO has half the error of
/// independent rays). For such n the two halves, nets of n/2 points each, estimate it instead:
/// (mean_1 - mean_2)^2 / 4, which the regression filter's bias-variance choice needs (with the
/// independent-ray formula it smooths too much once samples have many rays, and loses the
/// net's gain and more).
struct RayMean {
    explicit RayMean(int n) : n(n), half(n >= 2 && std::has_single_bit(unsigned(n)) ? n / 2 : 0) {}
    int n, half, added = 0;
    glm::vec3 sum{0.0f}, firstHalf{0.0f};
    float sum2 = 0.0f;
    void Add(glm::vec3 L) {
        sum += L;
        const float y = Luminance(L);
        sum2 += y * y;
        if (++added == half) firstHalf = sum;
    }
    ShadedSample Sample(glm::vec3 normal) const {
        const glm::vec3 mean = sum / float(n);
        const float ym = Luminance(mean);
        if (half > 0) {
            const float d = Luminance(firstHalf - (sum - firstHalf)) / float(half);
            return {mean, normal, 0.25f * d * d};
        }
        return {mean, normal,
                std::max(0.0f, sum2 / float(n) - ym * ym) / float(std::max(n - 1, 1))};
    }
};

/// Shades a cache sample with n cosine-distributed rays from its point; `trace(ray, rng, N)` gives
/// each ray's value. Returns the mean, the sample's normal and the variance of the mean
/// (luminance). Unreachable samples (holes, NaN surface) come back NaN: filters skip them.
template <typename TraceFn>
ShadedSample ShadeCosineRays(const Context& c, const SampleRequest& r, int n, RayCounts& rays,
                             TraceFn&& trace) {
    SurfaceSample ss;
    glm::vec3 origin;
    if (!SamplePoint(c, r, &ss, &origin, rays)) return {glm::vec3(NAN), glm::vec3(NAN), 0.0f};
    CosineRays gen(c, r, ss, origin, n);
    RayMean mean(n);
    for (int i = 0; i < n; ++i) {
        glm::vec3 N;
        Ray ray = gen.Next(i, &N);
        mean.Add(trace(ray, gen.rng(), N));
    }
    return mean.Sample(ss.N);
}

}  // namespace

ShadedSample ShadeAoSample(const Context& c, const SampleRequest& r, RayCounts& rays) {
    SurfaceSample ss;
    glm::vec3 origin;
    if (!SamplePoint(c, r, &ss, &origin, rays)) return {glm::vec3(NAN), glm::vec3(NAN), 0.0f};
    // The rays leave one point: traced as packets of up to 16 (RenderScene::Occluded16), with
    // the random numbers and in the order of one ray at a time (the same sample).
    const int n = c.opt.aoSamples;
    CosineRays gen(c, r, ss, origin, n);
    RayMean mean(n);
    Ray batch[16];
    bool blocked[16];
    int queued = 0;
    auto flush = [&] {
        c.rs.Occluded16(batch, queued, blocked);
        for (int k = 0; k < queued; ++k) mean.Add(glm::vec3(blocked[k] ? 0.0f : 1.0f));
        rays.shadow += uint64_t(queued);
        queued = 0;
    };
    for (int i = 0; i < n; ++i) {
        glm::vec3 N;
        batch[queued] = gen.Next(i, &N);
        batch[queued++].tfar = c.opt.aoDistance;
        if (queued == 16) flush();
    }
    flush();
    return mean.Sample(ss.N);
}

/// Diffuse light at a cache sample, as (1/pi) * integral of L cos (the hit multiplies it by its
/// albedo): DiffuseRayLight's mean over the sample's rays.
ShadedSample ShadeDiffuseSample(const Context& c, const SampleRequest& r, bool direct,
                                RayCounts& rays, int paths) {
    return ShadeCosineRays(c, r, paths > 0 ? paths : c.opt.texture.indirectSamples, rays,
                           [&](Ray& ray, Rng& rng, glm::vec3 N) {
                               const glm::vec3 L = DiffuseRayLight(c, ray, N, direct, rng, rays);
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
    const ShutterMotion motion(c, c.tsc->ObjectOfMesh(r.mesh));
    const glm::vec3 origin0 = origin, normal0 = ss.N;
    int open = 0, counted = 0;
    float blur = INFINITY;
    for (int i = 0; i < n; ++i) {
        Ray ray;
        ray.org = origin0;
        ray.dir = normal0;
        glm::vec3 N = normal0;
        motion.Pose(motion.Time(rng, i, n), &ray, &N);
        origin = ray.org;
        const int l = std::min(int(rng.Next1D() * float(c.quads.size())), int(c.quads.size()) - 1);
        const Context::Quad& q = c.quads[l];
        const glm::vec2 u = rng.Next2D();
        const glm::vec3 d = q.corner + u.x * q.e1 + u.y * q.e2 - origin;
        const float dist = glm::length(d);
        // Light points below the sample's tangent plane light nothing: not a visibility question.
        if (!(dist > 0.0f) || glm::dot(d, N) <= 0.0f) continue;
        ++counted;
        ray.org = origin;
        ray.dir = d / dist;
        ray.tfar = dist * (1.0f - 1e-4f);
        ++rays.shadow;
        Hit hit;
        // Quad lights are see-through here (a sphere light is not).
        if (!c.rs.Intersect(ray, &hit) || (hit.light >= 0 && hit.light < int(c.quads.size()))) {
            ++open;
            continue;
        }
        const float sigmaL = std::sqrt(glm::length(q.e1) * glm::length(q.e2) / 12.0f);
        blur = std::min(blur, sigmaL * hit.t / std::max(dist - hit.t, 1e-6f * dist));
    }
    const float V = counted ? float(open) / float(counted) : 1.0f;
    const float res = float(c.tsc->Resolution(r));
    const float texel = std::max(glm::length(ss.dPdu), glm::length(ss.dPdv)) / res;
    // The blur in texels of this sample's grid; a degenerate texel allows any width.
    const float blurTexels = texel > 0.0f && std::isfinite(texel) ? blur / texel : INFINITY;
    return {glm::vec3(V), ss.N, counted ? V * (1.0f - V) / float(counted) : 0.0f, blurTexels};
}

ShadedSample ShadeVisibilitySample(const Context& c, const SampleRequest& r, RayCounts& rays) {
    SurfaceSample ss;
    glm::vec3 origin;
    if (!SamplePoint(c, r, &ss, &origin, rays)) return {glm::vec3(NAN), glm::vec3(NAN), 0.0f};
    Rng rng = SampleRng(c, r);
    const int n = c.opt.texture.shadowSamples;
    const ShutterMotion motion(c, c.tsc->ObjectOfMesh(r.mesh));
    // As the frame buffers' light samples (FrameDirectSample): the light pick stratified, so
    // each light gets its share of the n rays exactly, the point on it from the R2 sequence,
    // both randomly shifted.
    constexpr float kG1 = 0.75487766f, kG2 = 0.56984029f;
    const float pickShift = rng.Next1D();
    const glm::vec2 shift = rng.Next2D();
    float lit = 0.0f, all = 0.0f;
    for (int k = 0; k < n; ++k) {
        Ray ray;
        ray.org = origin;
        ray.dir = ss.N;
        glm::vec3 N = ss.N;
        motion.Pose(motion.Time(rng, k, n), &ray, &N);
        const float uPick = std::min((float(k) + pickShift) / float(n), kOneMinusEpsilon);
        const float rx = shift.x + kG1 * float(k), ry = shift.y + kG2 * float(k);
        const glm::vec2 u = glm::min(glm::vec2(rx - std::floor(rx), ry - std::floor(ry)),
                                     glm::vec2(kOneMinusEpsilon));
        LightSample ls;
        // Delta lights are not in the frame buffers' visibility (their light is exact there).
        if (!c.SampleLight(ray.org, N, uPick, u, &ls) || ls.delta) continue;
        const float cosi = glm::dot(ls.wi, N);
        if (!(cosi > 0.0f)) continue;  // below the horizon: no light, not a visibility question
        const float ck = Luminance(ls.Li) * cosi / ls.pdf;
        if (!(ck > 0.0f) || !std::isfinite(ck)) continue;
        all += ck;
        Ray shadow;
        shadow.org = ray.org;
        shadow.dir = ls.wi;
        shadow.tfar = std::isinf(ls.dist) ? INFINITY : ls.dist * (1.0f - 1e-4f);
        shadow.time = ray.time;
        ++rays.shadow;
        if (!c.rs.Occluded(shadow)) lit += ck;
    }
    // No light above the horizon: visible, as the frame buffers count a sample with no shading.
    const float V = all > 0.0f ? lit / all : 1.0f;
    return {glm::vec3(V), ss.N, all > 0.0f ? V * (1.0f - V) / float(n) : 0.0f};
}

/// Direct lighting with area-light visibility from the texture-space cache (the soft-shadow
/// filter). Per hit, each quad light's unshadowed light is estimated from `shadowSamples` points
/// on it (no rays: the cheap, low-noise part) and multiplied by the texel's filtered visibility;
/// other lights (environment, distant) get one NEE sample with its shadow ray. No MIS with BSDF
/// sampling: a BSDF ray that finds the light would bring back unfiltered visibility. Objects whose
/// material uses another filter get the plain per-hit estimator.
glm::vec3 LiDirectCachedShadows(const Context& c, const Ray& ray, const Hit& hit, bool found,
                                Rng& rng, const RayDifferentials& diff, RayCounts& rays) {
    if (!found) return c.Background(ray.dir);
    if (hit.light >= 0) return c.HitEmission(ray, hit);
    if (c.tsc->FilterOf(hit.object) != TextureFilterKind::SoftShadow)
        return LiPath(c, ray, hit, found, rng, 1, rays);
    const SurfaceInteraction si = c.rs.Interact(ray, hit, &diff);
    const Bsdf bsdf = MakeBsdf(c, si);
    const glm::vec3 wo = -ray.dir;
    glm::vec3 L = c.HitEmission(ray, hit);  // an emissive object's own light
    // Area lights: unshadowed estimate times cached visibility.
    const int m = c.opt.texture.shadowSamples;
    glm::vec3 unshadowed(0.0f);
    for (size_t l = 0; l < c.quads.size(); ++l) {
        const Context::Quad& q = c.quads[l];
        // The m points are a digitally shifted Sobol' net on the quad (as AO rays are): the
        // unshadowed term is the product's noisy factor wherever the filtered visibility is
        // blurred past a shadow's edge, and independent points there left single-pixel
        // fireflies (chess-softshadow of `texcache experiment speed-vs-error`: one pixel of the
        // rook at 1.06 against 0.019 carried half of budget 8's error).
        const uint32_t sx = rng.NextU32(), sy = rng.NextU32();
        for (int j = 0; j < m; ++j) {
            const glm::vec2 u = Sobol02(uint32_t(j), sx, sy);
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
        if (c.SampleLight(si.P, si.N, (float(pick) + 0.5f) / float(c.numLights), rng.Next2D(),
                          &ls)) {
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

}  // namespace texcache::internal
