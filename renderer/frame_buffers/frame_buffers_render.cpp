// SPDX-License-Identifier: Apache-2.0
// The screen-space stage's frame buffers rendered with the path tracer's light sampling and paths
// (path_tracer.h); what each buffer holds is stated in frame_buffers_render.h.
#include "renderer/frame_buffers/frame_buffers_render.h"

#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <limits>
#include <memory>

#include <tbb/blocked_range.h>
#include <tbb/blocked_range2d.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <glm/gtc/matrix_transform.hpp>

#include "renderer/integrators/path_tracer.h"
#include "renderer/integrators/polygon_light.h"
#include "renderer/render.h"
#include "renderer/render_internal.h"
#include "renderer/texture_space/cached_shading.h"
#include "texcache/error.h"
#include "texcache/prefetch.h"

namespace texcache {

using namespace internal;

screen::FrameCamera MakeFrameCamera(const Camera& cam, float time, int width, int height) {
    screen::FrameCamera fc;
    const glm::mat4 camToWorld = cam.pose.Eval(time);
    // CameraModel looks down -Z with the vertical field of view over the height and square
    // pixels; the near plane only sets clip z, which Project() does not use.
    const glm::mat4 proj =
        glm::perspective(glm::radians(cam.fovYDegrees), float(width) / float(height), 1e-3f, 1e6f);
    fc.worldToClip = proj * glm::inverse(camToWorld);
    fc.position = glm::vec3(camToWorld[3]);
    fc.width = width;
    fc.height = height;
    return fc;
}

Image ToImage(const std::vector<glm::vec3>& colours, int width, int height) {
    Image img(width, height, 3);
    for (size_t p = 0; p < colours.size() && p < img.NumPixels(); ++p)
        for (int k = 0; k < 3; ++k) img.data[3 * p + k] = colours[p][k];
    return img;
}

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// Unshadowed light samples per frame-buffer sample for `shading` (no rays: BSDF and light
// evaluations only). Measured noise: frame_buffers_render.h.
constexpr int kShadingCandidates = 32;
// Light samples per frame-buffer sample when `shading` has a closed form (ClosedFormShading):
// they only pick the shadow ray and estimate the visibility ratio, whose noise the stage filters.
// Picked in proportion to the lights' closed-form terms, 6 give the error of 8 picked uniformly
// (which spend half of them on anim_shadow's dim sky), and 4 or 8 change the denoised error by
// less than its noise (`texcache preview scenes/anim_shadow.json --bench --denoise reliable
// --resolution 640x360`; results/preview.md).
constexpr int kRatioCandidates = 6;
const glm::vec3 kNaN3(kNaN);

/// Where everything that moves was at the previous frame: world at the frame time -> world at
/// prevTime, per object and per light that rays can hit, indexed as Hit::light (quad lights,
/// then point and spot lights) (T^-1 of Zeng eq. 1/3/5), and distant lights' direction
/// rotations.
struct FrameMotion {
    std::vector<glm::mat4> object, light;
    size_t numQuads = 0;  // the quad lights in `light`, the point lights after them
    std::vector<glm::mat3> objectN, lightN;        // their normal matrices
    std::vector<uint8_t> objectStill, lightStill;  // 1: the matrix is the identity
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
            objectStill.push_back(object.back() == glm::mat4(1.0f));
            for (const auto& p : scene.meshes[scene.objects[o].mesh].positions)
                extent = std::max(extent,
                                  glm::length(glm::vec3(now * glm::vec4(p[0], p[1], p[2], 1.0f))));
        }
        auto addLight = [&](const TransformTrack& t) {
            light.push_back(t.Eval(prevTime) * glm::inverse(t.Eval(opt.frameTime)));
            lightN.push_back(normalMatrix(light.back()));
            lightStill.push_back(light.back() == glm::mat4(1.0f));
        };
        for (const QuadLight& q : scene.quadLights) addLight(q.transform);
        numQuads = light.size();
        for (const PointLight& l : scene.pointLights) addLight(l.transform);
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
    /// A unit normal on what a ray hit, turned to the previous frame: itself where that did not
    /// move (renormalized, it could differ in the last bit, and the square root and division are
    /// on the path of every pixel's buffer writes).
    glm::vec3 Normal(const Hit& h, glm::vec3 n) const {
        if (h.object >= 0 ? objectStill[h.object] : lightStill[h.light]) return n;
        return glm::normalize((h.object >= 0 ? objectN[h.object] : lightN[h.light]) * n);
    }
};

/// One pixel's buffers while its samples are taken (but the shadow rays': PixelShadow).
struct FramePixel {
    glm::vec3 shadingSum{0.0f}, glossySum{0.0f}, diffuseSum{0.0f};
    glm::vec3 glossyHit = kNaN3, prevGlossyHit = kNaN3;
    std::array<glm::vec3, screen::kNumCones> coneSum{};
    bool hasCones = false;  ///< a diffuse ray was traced
};

/// What a pixel's shadow rays make of its visibility and blocker, kept until its tile's shadow
/// rays are traced.
struct PixelShadow {
    float weightSum, visibleWeightSum;
    float blockerWeight;  // shading luminance of the recorded blocked sample
    glm::vec3 blocker, prevBlocker, light, prevLight;
    glm::vec3 delta;  // the delta lights' shadowed light (DeltaDirect)

    /// No sample yet: visible, no blocker. (Set field by field: a temporary's copy of the
    /// whole struct per pixel showed in the profile.)
    void Reset() {
        weightSum = visibleWeightSum = 0.0f;
        blockerWeight = -1.0f;
        blocker = prevBlocker = light = prevLight = kNaN3;
        delta = glm::vec3(0.0f);
    }
};

glm::vec3 FiniteOrZero(glm::vec3 v) {
    return std::isfinite(v.x + v.y + v.z) ? v : glm::vec3(0.0f);
}

/// Each light's share of a pixel's closed-form shading (the luminance of its term), indexed as
/// SampleLight picks lights; n = 0 when the scene has more lights than kMax (then the pick stays
/// uniform).
struct LightWeights {
    static constexpr int kMax = 16;
    int n = 0;
    float w[kMax];
};

/// The scene's lights split for the frame buffers, as SampleLight indexes them. A delta light (a
/// distant light without angular size, a point or spot light of radius 0) lights a pixel centre
/// with no noise: its shadowed light is exact with one shadow ray (DeltaDirect) and goes to
/// `emitted`, which the stage does not filter, where its 0/1 visibility in `visibility` was
/// blurred by the stage's filters and lagged behind while the view moved. `shading` and
/// `visibility` are those of the other lights.
struct FrameLights {
    std::vector<int> delta, other;

    explicit FrameLights(const Context& c) {
        for (int i = 0; i < c.numLights; ++i) (IsDelta(c, i) ? delta : other).push_back(i);
    }
    static bool IsDelta(const Context& c, int i) {
        const int d = i - int(c.quads.size()), sp = i - c.FirstSphere();
        if (d >= 0 && d < int(c.distantDir.size())) return c.suns[size_t(d)].IsDelta();
        return sp >= 0 && sp < int(c.spheres.size()) && c.spheres[size_t(sp)].IsDelta();
    }
};

/// The unshadowed direct light of every light, integrated in closed form, or false when some
/// light and lobe have none here: a GGX lobe under an area light (quad or environment; LTCs and
/// prefiltered maps would give one). The diffuse lobe under a quad light is Lambert's polygon
/// formula (clipped to the shading normal's hemisphere), under the environment albedo / pi times
/// its irradiance (exact for a constant one, degree-2 spherical harmonics for a map); a distant
/// light's term is the BSDF times its irradiance. Unlike the light samples it ignores the
/// geometric normal's cut-off (the BSDF's ng test) and, for a map, the harmonics' error: the
/// visibility ratio below absorbs both in expectation.
bool ClosedFormShading(const Context& c, const SurfaceInteraction& si, const Bsdf& bsdf,
                       glm::vec3 wo, glm::vec3* out, LightWeights* weights) {
    // Delta lights are not in `shading` (FrameLights): their terms are left out.
    // Emissive objects have none; neither has a GGX lobe under a sphere of some size.
    if (!c.emitters.empty()) return false;
    bool areaSpheres = false;
    for (const SphereLight& l : c.spheres) areaSpheres |= !l.IsDelta();
    if (bsdf.HasSpecular() && (c.env || !c.quads.empty() || areaSpheres)) return false;
    glm::vec3 S(0.0f);
    weights->n = c.numLights <= LightWeights::kMax ? c.numLights : 0;
    std::fill_n(weights->w, weights->n, 0.0f);
    // Each light's term, in SampleLight's order (quads, distant lights, spheres, environment).
    auto add = [&](int light, glm::vec3 term) {
        S += term;
        if (light < weights->n) weights->w[light] = Luminance(FiniteOrZero(term));
    };
    if (glm::dot(wo, si.N) > 0.0f) {  // the BSDF is 0 otherwise
        constexpr float kInvPi = 0.31830988618379067f;
        const glm::vec3 R = bsdf.DiffuseReflectance();
        for (size_t i = 0; i < c.quads.size(); ++i) {
            const Context::Quad& q = c.quads[i];
            const glm::vec3 rel = q.corner - si.P;
            if (!q.twoSided && glm::dot(q.n, rel) >= 0.0f) continue;  // behind a one-sided quad
            const glm::vec3 v[4] = {rel, rel + q.e1, rel + q.e1 + q.e2, rel + q.e2};
            add(int(i), R * q.L * (PolygonProjectedSolidAngle(v, 4, si.N) * kInvPi));
        }
        if (c.env) add(c.numLights - 1, R * c.env->Irradiance(si.N) * kInvPi);
        const int firstDistant = int(c.quads.size());
        for (size_t i = 0; i < c.distantDir.size(); ++i) {
            if (c.suns[i].IsDelta()) continue;
            glm::vec3 fd, fs;
            bsdf.EvalLobes(wo, c.distantDir[i], &fd, &fs);
            add(firstDistant + int(i),
                (fd + fs) * c.distantE[i] * std::abs(glm::dot(c.distantDir[i], si.N)));
        }
        // A sphere's I cos / d^2 while it is wholly above the horizon (a Lambertian sphere
        // lights a plane as a point of its intensity does), with the spot's falloff taken at the
        // centre.
        for (size_t i = 0; i < c.spheres.size(); ++i) {
            const SphereLight& l = c.spheres[i];
            if (l.IsDelta()) continue;
            const glm::vec3 d = l.center - si.P;
            const float d2 = glm::dot(d, d);
            if (!(d2 > l.radius * l.radius)) continue;
            const glm::vec3 wi = d / std::sqrt(d2);
            glm::vec3 fd, fs;
            bsdf.EvalLobes(wo, wi, &fd, &fs);
            add(c.FirstSphere() + int(i),
                (fd + fs) * l.intensity *
                    (l.Falloff(-wi) * std::max(glm::dot(wi, si.N), 0.0f) / d2));
        }
    }
    *out = FiniteOrZero(S);
    return true;
}

/// The environment map's light samples of one frame, drawn once and shared by the pixels'
/// candidates (FrameDirectSample), as ReSTIR's light tiles are (Wyman and Panteleev 2021,
/// "Rearchitecting spatiotemporal resampling for production"): a map's sample does not depend on
/// the shading point, and drawn per candidate each one was two dependent searches of the
/// inversion tables and a texel lookup, all out of the caches (most of a GGX pixel's time:
/// results/frame_buffers_profile.md). Here a candidate reads one entry of a table that stays in
/// the L2 cache, and a pixel's candidates are consecutive entries.
///
/// Entry i is the map's sample at the R2 point i shifted by the frame's random shift, so each
/// entry is distributed as a sample of the map and any run of entries is the shifted R2 run the
/// candidates took before: a pixel's estimate keeps its distribution and expectation. Pixels
/// that start their runs within kN entries of each other share samples (correlated noise within
/// a frame); a new frame draws a new shift.
class EnvironmentSamples {
public:
    static constexpr uint32_t kCount = 1u << 14;
    using Entry = EnvironmentSampleEntry;

    /// Empty unless the scene's environment is a map (a constant one samples about the normal).
    EnvironmentSamples(const Context& c, uint64_t seed) {
        if (!c.env || c.env->IsConstant()) return;
        entries_.resize(kCount);
        Rng rng(seed, 0x9E3779B97F4A7C15ull);
        const glm::vec2 shift = rng.Next2D();
        constexpr double kG1 = 0.7548776662466927, kG2 = 0.5698402909980532;  // R2
        const float pick = c.PickPdf();
        tbb::parallel_for(
            tbb::blocked_range<uint32_t>(0, kCount, 1024),
            [&](const tbb::blocked_range<uint32_t>& r) {
                for (uint32_t i = r.begin(); i < r.end(); ++i) {
                    // In double: kG * i has no fractional bits left in float
                    // for the large i.
                    const double rx = shift.x + kG1 * double(i), ry = shift.y + kG2 * double(i);
                    const glm::vec2 u(float(rx - std::floor(rx)), float(ry - std::floor(ry)));
                    Entry& e = entries_[i];
                    float pdf;
                    e.Li = c.env->Sample(glm::vec3(0.0f, 1.0f, 0.0f),
                                         glm::min(u, glm::vec2(kOneMinusEpsilon)), &e.wi, &pdf);
                    e.pdf = pdf * pick;
                }
            });
    }
    bool Empty() const { return entries_.empty(); }
    /// Entry i modulo kCount.
    const Entry& operator[](uint32_t i) const { return entries_[i & (kCount - 1u)]; }

private:
    std::vector<Entry> entries_;
};

/// A shadow ray of FrameDirectSample waiting for its packet (FinishShadow takes it from there):
/// the ray, the light sample it goes to and the weight of its frame-buffer sample.
struct PendingShadow {
    Ray ray;
    glm::vec3 P;   // the shading point: a quad's sampled point is P + dist wi
    glm::vec3 wi;  // towards the light
    float dist;
    float w;                                   // luminance of the sample's unshadowed shading
    int quad, distant, sphere, emitterObject;  // the light sampled (-1: not that kind)
    int pixel;                                 // the pixel's index in its tile
};

/// A shadow ray of DeltaDirect: towards a delta light, whose light `term` the pixel gets where the
/// ray is not blocked.
struct DeltaShadow {
    Ray ray;
    glm::vec3 term;
    int pixel;  // the pixel's index in its tile
};

/// The light sample of one frame-buffer sample: unshadowed shading into `px` from
/// kShadingCandidates light samples, and one shadow ray to a candidate resampled in proportion to
/// its shading's luminance, appended to `shadows` (for tile pixel `pixel`) for FinishShadow,
/// which records the blocker and light point when blocked (see frame_buffers_render.h). With
/// `exact` (ClosedFormShading, luminance > 0) the shading is that and kRatioCandidates light
/// samples give the visibility as the ratio lum(mean of the candidates) * V / lum(exact), whose
/// expectation is the shadowed over the unshadowed light. With `specularOnly` (an object whose
/// diffuse lobe the cache lights, CachedDiffuseLight) the shading is the specular lobe's alone,
/// from opt.texture.specularLightSamples light samples.
void FrameDirectSample(const Context& c, const FrameLights& lights, const SurfaceInteraction& si,
                       const Bsdf& bsdf, glm::vec3 wo, const glm::vec3* exact,
                       const LightWeights& weights, Rng& rng, const EnvironmentSamples& envSamples,
                       FramePixel& px, PixelShadow& sh, int pixel,
                       std::vector<PendingShadow>& shadows, bool specularOnly = false) {
    // Candidates: the light pick stratified over [0, 1) (each light gets its share exactly; the
    // delta lights are DeltaDirect's, none here), the point on the light from the R2 sequence
    // (Roberts 2018: any run of it is evenly spread), both randomly shifted (Cranley-Patterson:
    // unbiased).
    constexpr int kMax = kShadingCandidates;
    // Fewer samples for the specular lobe alone pay where the cache takes the diffuse lobe's
    // light off the pixel; a material without a diffuse lobe (a metal) gives the cache nothing
    // and keeps the full count.
    const bool cacheLightsBase = specularOnly && bsdf.DiffuseReflectance() != glm::vec3(0.0f);
    const int kN = cacheLightsBase ? std::clamp(c.opt.texture.specularLightSamples, 1, kMax)
                   : exact         ? kRatioCandidates
                                   : kShadingCandidates;
    constexpr float kG1 = 0.75487766f, kG2 = 0.56984029f;  // 1/phi_2, 1/phi_2^2
    const float pickShift = rng.Next1D();
    const glm::vec2 shift = rng.Next2D();
    const float uResample = rng.Next1D();
    // The first of the pixel's run of the frame's environment samples (drawn only with a map, so
    // that other scenes' samples stay as they were).
    const uint32_t envStart =
        envSamples.Empty() ? 0u : uint32_t(rng.Next1D() * float(EnvironmentSamples::kCount));
    LightSample cand[kMax];
    glm::vec3 S[kMax];
    float lum[kMax];
    // The candidates whose BSDF is evaluated in the loop after this one (all but the diffuse
    // quads' closed form), packed: their light samples in structure-of-arrays form, and which
    // candidate each is. EvalLobesPdfN and the weights below then run over all of them in loops
    // the compiler vectorizes: one candidate at a time, the GGX lobe's divisions and square roots
    // were most of this function's time, itself one of the largest in a store frame's profile.
    alignas(64) float wx[kMax], wy[kMax], wz[kMax], Lr[kMax], Lg[kMax], Lb[kMax];
    alignas(64) float pdfLight[kMax], delta[kMax], pickScales[kMax];
    int pendingK[kMax];
    int np = 0;
    // With closed-form shading the pick follows each light's share of it instead of being
    // uniform, so that the candidates go where the light is (none to a dim sky next to a lamp):
    // candidate k's light is where (k + shift) / kN falls in the lights' cumulative shares.
    float wSum = 0.0f;
    if (exact)
        for (int i = 0; i < weights.n; ++i) wSum += weights.w[i];
    const bool weighted = wSum > 0.0f;
    // A diffuse BSDF under quad lights (the common case of closed-form shading): the candidate in
    // closed form below. wo is above the shading normal (the closed form is 0 otherwise).
    const bool diffuseQuads = weighted && !bsdf.HasSpecular();
    const glm::vec3 diffuseF = bsdf.DiffuseReflectance() * 0.31830988618379067f;
    int light = 0;
    float wAcc = weighted ? weights.w[0] : 0.0f;
    for (int k = 0; k < kN; ++k) {
        lum[k] = 0.0f, S[k] = glm::vec3(0.0f);
        float uPick = (float(k) + pickShift) / float(kN);
        float pickScale = 1.0f;  // SampleLight's pick probability over this one's
        if (weighted) {
            // The targets rise with k: the light index only moves on.
            const float target = uPick * wSum;
            while (light + 1 < weights.n && (wAcc <= target || weights.w[light] <= 0.0f))
                wAcc += weights.w[++light];
            while (weights.w[light] <= 0.0f) --light;  // rounding ran past the last share
            uPick = (float(light) + 0.5f) / float(c.numLights);
            pickScale = wSum / (weights.w[light] * float(c.numLights));
        } else if (!lights.delta.empty()) {
            // Uniform over the lights other than the delta ones (DeltaDirect's).
            const int m = int(lights.other.size());
            light = lights.other[size_t(std::min(int(uPick * float(m)), m - 1))];
            uPick = (float(light) + 0.5f) / float(c.numLights);
            pickScale = float(m) / float(c.numLights);
        }
        // The point on the light, for the lights that take one (not the environment's table):
        // x - float(int(x)) is fmod(x, 1) for 0 <= x < 2^31, exactly, without libm's fmodf (a
        // tenth of the bench profile with 32 candidates) or the baseline x86-64's floor (no
        // rounding instruction before SSE4.1).
        auto r2 = [&] {
            const float rx = shift.x + kG1 * float(k), ry = shift.y + kG2 * float(k);
            return glm::vec2(rx - float(int(rx)), ry - float(int(ry)));
        };
        LightSample& ls = cand[k];
        if (diffuseQuads && light < int(c.quads.size())) {
            // SampleLight's quad sample and the diffuse BSDF folded together (pdf and cosines
            // from the unnormalized direction): one square root and one division instead of
            // their six (these candidates are a large share of the frame buffers' render time).
            const Context::Quad& q = c.quads[size_t(light)];
            const glm::vec2 v = glm::min(r2(), glm::vec2(kOneMinusEpsilon));
            const glm::vec3 d = q.corner + v.x * q.e1 + v.y * q.e2 - si.P;
            const float dist2 = glm::dot(d, d);
            const float cosLight = -glm::dot(q.n, d), cosSurface = glm::dot(si.N, d);
            // Zero where SampleLight has no sample (behind a one-sided quad, pdf 0) or the
            // BSDF is 0 (below the shading or the geometric normal).
            if (!(dist2 > 0.0f) || !(cosSurface > 0.0f) || !(glm::dot(si.Ng, d) > 0.0f) ||
                !(q.twoSided ? cosLight != 0.0f : cosLight > 0.0f))
                continue;
            // 1 / sqrt by the estimate and one Newton step (relative error ~1e-7): the square
            // root and the division in a row would be the loop's longest latency.
            const float e = _mm_cvtss_f32(_mm_rsqrt_ss(_mm_set_ss(dist2)));
            const float invDist = e * (1.5f - 0.5f * dist2 * e * e);
            ls.wi = d * invDist;
            ls.dist = dist2 * invDist;
            ls.delta = false;
            ls.quad = light;
            // f Le cos / pdf, pdf = dist^2 / (area cosLight) * pick probability.
            const float g = cosSurface * std::abs(cosLight) * (invDist * invDist) *
                            (invDist * invDist) * (q.area * pickScale * float(c.numLights));
            S[k] = FiniteOrZero(diffuseF * q.L * g);
            lum[k] = Luminance(glm::abs(S[k]));
            continue;
        }
        if (!envSamples.Empty() &&
            std::min(int(uPick * float(c.numLights)), c.numLights - 1) == c.numLights - 1) {
            // The environment (the last light SampleLight picks): the frame's sample.
            const EnvironmentSamples::Entry& e = envSamples[envStart + uint32_t(k)];
            if (!(e.pdf > 0.0f)) continue;
            ls.wi = e.wi, ls.Li = e.Li, ls.pdf = e.pdf;
            ls.dist = INFINITY;
            ls.delta = false;
        } else if (!c.SampleLight(si.P, si.N, std::min(uPick, kOneMinusEpsilon),
                                  glm::min(r2(), glm::vec2(kOneMinusEpsilon)), &ls)) {
            continue;
        }
        wx[np] = ls.wi.x, wy[np] = ls.wi.y, wz[np] = ls.wi.z;
        Lr[np] = ls.Li.x, Lg[np] = ls.Li.y, Lb[np] = ls.Li.z;
        pdfLight[np] = ls.pdf, delta[np] = ls.delta ? 1.0f : 0.0f;
        pickScales[np] = pickScale;
        pendingK[np++] = k;
    }
    if (np > 0) {
        alignas(64) float diffuseOn[kMax], fr[kMax], fg[kMax], fb[kMax], pdfSpecular[kMax];
        bsdf.EvalLobesPdfN(wo, np, wx, wy, wz, diffuseOn, fr, fg, fb, pdfSpecular);
        // The diffuse lobe is the cache's where it lights the base (indirect).
        const glm::vec3 fdOn = specularOnly ? glm::vec3(0.0f) : diffuseF;
        const bool specular = bsdf.HasSpecular();
        const glm::vec3 N = si.N;
        alignas(64) float Sr[kMax], Sg[kMax], Sb[kMax], L[kMax];
        for (int i = 0; i < np; ++i) {
            const bool isDelta = delta[i] != 0.0f;
            // The specular ray may find this light too (in `glossy`): MIS between the two for
            // that lobe (PowerHeuristic, written so that the loop vectorizes).
            const float f2 = pdfLight[i] * pdfLight[i], pdfS = pdfSpecular[i];
            const float d = f2 + pdfS * pdfS;
            const float power = std::abs(f2) == INFINITY ? 1.0f : d > 0.0f ? f2 / d : 0.0f;
            const float wSpec = isDelta || !specular ? 1.0f : power;
            const float cosi = std::abs(wx[i] * N.x + wy[i] * N.y + wz[i] * N.z);
            const float scale = pickScales[i] * (isDelta ? cosi : cosi / pdfLight[i]);
            const bool on = diffuseOn[i] != 0.0f;
            const float r = ((on ? fdOn.x : 0.0f) + wSpec * fr[i]) * Lr[i] * scale;
            const float gr = ((on ? fdOn.y : 0.0f) + wSpec * fg[i]) * Lg[i] * scale;
            const float bl = ((on ? fdOn.z : 0.0f) + wSpec * fb[i]) * Lb[i] * scale;
            // FiniteOrZero: x - x is 0 exactly when x is finite.
            const float all = r + gr + bl;
            const bool finite = all - all == 0.0f;
            Sr[i] = finite ? r : 0.0f, Sg[i] = finite ? gr : 0.0f, Sb[i] = finite ? bl : 0.0f;
            L[i] =
                0.2126f * std::abs(Sr[i]) + 0.7152f * std::abs(Sg[i]) + 0.0722f * std::abs(Sb[i]);
        }
        for (int i = 0; i < np; ++i) {
            S[pendingK[i]] = glm::vec3(Sr[i], Sg[i], Sb[i]);
            lum[pendingK[i]] = L[i];
        }
    }
    // In candidate order, as one loop summed them.
    glm::vec3 sum(0.0f);
    float lumSum = 0.0f;
    for (int k = 0; k < kN; ++k) sum += S[k], lumSum += lum[k];
    if (exact) {
        px.shadingSum += *exact;
        sh.weightSum += Luminance(glm::abs(*exact));
        if (!(lumSum > 0.0f)) return;  // every candidate found 0: this sample's ratio is 0
    } else if (!(lumSum > 0.0f)) {
        return;  // no shadow ray: counts as visible (see the header)
    }
    const glm::vec3 Sbar = sum / float(kN);
    const float w = Luminance(glm::abs(Sbar));
    if (!exact) px.shadingSum += Sbar, sh.weightSum += w;
    // The shadow ray's candidate: index j with probability lum_j / sum lum.
    int j = 0;
    float acc = lum[0], target = uResample * lumSum;
    while (j + 1 < kN && (acc <= target || lum[j] <= 0.0f)) acc += lum[++j];
    while (lum[j] <= 0.0f) --j;  // rounding ran past the last candidate with shading
    const LightSample& ls = cand[j];
    // Written in place, field by field (whole temporaries stalled on store forwarding).
    PendingShadow& q = shadows.emplace_back();
    const Ray r = ShadowRay(si, ls, 0.0f);
    q.ray.org = r.org, q.ray.dir = r.dir;
    q.ray.tnear = r.tnear, q.ray.tfar = r.tfar, q.ray.time = r.time;
    q.P = si.P;
    q.wi = ls.wi;
    q.dist = ls.dist;
    q.w = w;
    q.quad = ls.quad;
    q.distant = ls.distant;
    q.sphere = ls.sphere;
    q.emitterObject = ls.emitter >= 0 ? c.emitters[size_t(ls.emitter)].Object() : -1;
    q.pixel = pixel;
}

/// The delta lights' light at the pixel (FrameLights): each light's unshadowed term, as the path
/// tracer's light sample takes it, with a shadow ray of its own appended to the light's list in
/// `shadows` (RenderTile traces each light's rays in packets and adds the term to the pixel's
/// `delta` where the ray is not blocked).
void DeltaDirect(const Context& c, const FrameLights& lights, const SurfaceInteraction& si,
                 const Bsdf& bsdf, glm::vec3 wo, int pixel,
                 std::vector<std::vector<DeltaShadow>>& shadows) {
    for (size_t k = 0; k < lights.delta.size(); ++k) {
        const int light = lights.delta[k];
        LightSample ls;
        const float uPick = (float(light) + 0.5f) / float(c.numLights);
        if (!c.SampleLight(si.P, si.N, uPick, glm::vec2(0.5f), &ls)) continue;
        glm::vec3 fd, fs;
        bsdf.EvalLobes(wo, ls.wi, &fd, &fs);
        // SampleLight divides by the pick probability: one light of numLights, here each.
        const glm::vec3 term =
            FiniteOrZero((fd + fs) * ls.Li * (std::abs(glm::dot(ls.wi, si.N)) * c.PickPdf()));
        if (!(Luminance(term) > 0.0f)) continue;
        DeltaShadow& q = shadows[k].emplace_back();
        const Ray r = ShadowRay(si, ls, 0.0f);
        q.ray.org = r.org, q.ray.dir = r.dir;
        q.ray.tnear = r.tnear, q.ray.tfar = r.tfar, q.ray.time = r.time;
        q.term = term;
        q.pixel = pixel;
    }
}

/// The outcome of a queued shadow ray (blocked: `bh` is its first hit) into its pixel's `sh`.
void FinishShadow(const FrameMotion& motion, const PendingShadow& s, bool blocked, const Hit& bh,
                  PixelShadow& sh) {
    if (!blocked) {
        sh.visibleWeightSum += s.w;
        return;
    }
    if (s.w <= sh.blockerWeight) return;
    sh.blockerWeight = s.w;
    sh.blocker = s.ray.org + bh.t * s.ray.dir;
    sh.prevBlocker = motion.Point(bh, sh.blocker);
    if (s.quad >= 0 || s.sphere >= 0 || s.emitterObject >= 0) {
        sh.light = s.P + s.dist * s.wi;  // the point sampled on the light
        const glm::mat4& m = s.quad >= 0     ? motion.light[size_t(s.quad)]
                             : s.sphere >= 0 ? motion.light[motion.numQuads + size_t(s.sphere)]
                                             : motion.object[size_t(s.emitterObject)];
        sh.prevLight = glm::vec3(m * glm::vec4(sh.light, 1.0f));
    } else {
        // At infinity: a far point along the light direction from the blocker, so the line from
        // the light point through the blocker has the light's direction in both frames.
        const glm::vec3 prevDir =
            s.distant >= 0 ? glm::normalize(motion.distant[s.distant] * s.wi) : s.wi;
        sh.light = sh.blocker + motion.infinity * s.wi;
        sh.prevLight = sh.prevBlocker + motion.infinity * prevDir;
    }
}

/// The texture-space cache's diffuse light at `si` (irradiance / pi): indirect, or with `layered`
/// (CachedDiffuseLight) direct and indirect; misses shaded as ShadeDiffuseSample does.
glm::vec3 CachedDiffuse(const Context& c, const SurfaceInteraction& si, bool layered,
                        RayCounts& rays) {
    const int paths = layered ? c.opt.texture.diffuseLayerPaths : c.opt.texture.indirectSamples;
    return CachedLookup(
        c, si,
        [&](const SampleRequest& r) { return ShadeDiffuseSample(c, r, layered, rays, paths); },
        paths);
}

/// A frame's use of the store (opt.texture.frameBufferSamples Hits; frame_buffers_render.h):
/// which camera hits trace their diffuse lobe's path into it, and each pixel's record for
/// reading it back once every hit is added.
struct FrameStore {
    const LightHitStore* store;  ///< as the previous frames left it (read only while shading)
    int bias = 0;                ///< the bins' levels above a hit's texel
    float blend = 0.0f;          ///< the share of hits that read the level above (PathHitsAdd)
    int budget = 1;              ///< one pixel in `budget` a frame traces its path
    uint32_t offset = 0;         ///< this frame's shift of the pixels' dither ranks (Traces)
    double minCount = 0.0;       ///< a cell with fewer counts needs its hits' paths
    double targetCount = 0.0;    ///< a cell with fewer counts takes paths faster (Traces)
    double termCount = 0.0;      ///< a cell with fewer counts is not read at a ray's hit
    double minPrior = 0.0;       ///< a cell with fewer counts is no traced hit's prior
    HitRecord* records;          ///< a pixel's record; mesh < 0: nothing to read
    BinnedHit* binned;           ///< its light to add (NaN: none) and albedo
    PixelOwnLight* own;          ///< a still view's own samples per pixel; null while moving
    uint64_t jitterSeed = 0;     ///< this frame's seed of the pixels' store read jitters

    /// Pixel (x, y)'s jitter of its stochastic store reads this frame (StoreCountAt and
    /// StoreLightAt with a jitter): the same for its count and its light, new every frame, so
    /// that the stage's temporal filter averages the single bins' reads into the bilinear
    /// reconstruction. A still view reads the 2x2 bins: its running mean of the pixel's own
    /// samples weighs them against a reconstruction whose noise its neighbours' show.
    glm::vec2 Jitter(int x, int y, int width) const {
        const uint64_t h = PixelSeed(jitterSeed, x, y, width);
        return {float(h >> 40) * 0x1p-24f - 0.5f, float((h >> 8) & 0xFFFFFFu) * 0x1p-24f - 0.5f};
    }

    /// Whether pixel (x, y), whose cell holds `count`, traces its path this frame. Its rate is
    /// one frame in `budget` where the cell holds budget x targetCount or more, and
    /// targetCount / count below that, up to every frame: the paths go first where the store
    /// holds few samples (surfaces seen anew, fine bins near the camera), and a cell nearly
    /// empty (minCount) takes one every frame. The pixel's rank in a 4x4 ordered-dither (Bayer)
    /// matrix, shifted by the frame's offset, falls in the rate's window or not, so a pixel at
    /// rate 1 / budget traces once in `budget` frames and every frame's pixels are spread evenly
    /// over the image.
    bool Traces(int x, int y, double count) const {
        if (count < minCount) return true;
        static constexpr uint8_t kBayer[4][4] = {
            {0, 8, 2, 10}, {12, 4, 14, 6}, {3, 11, 1, 9}, {15, 7, 13, 5}};
        const double rate = std::clamp(targetCount / count, 1.0 / double(budget), 1.0);
        const uint32_t rank = (uint32_t(kBayer[y & 3][x & 3]) + offset) & 15u;
        return double(rank) + 0.5 < 16.0 * rate;
    }
};

/// The samples the store needs behind a ray's hit for the ray's path to end there: with none, the
/// surface is one the camera does not see (or not yet); with fewer, one path's noise would reach
/// every ray that ends in that block.
constexpr double kStoreTermSamples = 4.0;

/// The store's diffuse light where a ray from a camera hit (the diffuse path traced into the
/// store, the glossy ray) first hits a surface that the camera's hits have filled, as LiPath's
/// cached term: the path ends there for a diffuse surface, or goes on with its specular lobe
/// only, as it does on the grid's texels. It reads the block of 4x4 bins around the point at
/// the camera's level for it (its distance from the camera sets the level; StoreBlockAt): the
/// light a diffuse bounce or a glossy lobe gathers there is smooth across a block, which holds
/// 16 times a bin's samples. A surface the camera does not see has none there, and the path goes
/// on past it. What the store holds already includes that surface's own bounces, so a path that
/// reads it gathers light over more bounces than max_depth, as the grid's cached samples do.
struct StoreTerm {
    const Context& c;
    const FrameStore& fs;
    bool layered;  ///< the store holds direct light too (CachedDiffuseLight)

    CachedTerm operator()(const SurfaceInteraction& h, const Ray& r, glm::vec3* term) const {
        HitRecord rec;
        int texelLevel = 0;
        FrameHitRecord(c, h, glm::distance(h.P, c.camera.Position()), fs.bias, &rec, &texelLevel);
        glm::vec3 E;
        if (StoreBlockAt(*c.tsc, *fs.store, rec, &E) < fs.termCount) return CachedTerm::None;
        const Bsdf hb = MakeBsdf(c, h);
        // The diffuse lobe is 0 where the shading normal faces away from the ray.
        *term = glm::dot(r.dir, h.N) < 0.0f ? FiniteOrZero(hb.DiffuseReflectance() * E)
                                            : glm::vec3(0.0f);
        if (hb.HasSpecular()) return layered ? CachedTerm::DiffuseBase : CachedTerm::BaseIndirect;
        return layered ? CachedTerm::All : CachedTerm::Indirect;
    }
};

/// The glossy ray's least probability (FrameGlossySample): its light's weight stays at most 4x.
constexpr float kMinGlossyProbability = 0.25f;

/// The specular lobe's path of one sample into px.glossySum (and its first hit). With the
/// texture-space cache, the diffuse lobe of the surface the ray hits takes its light from the
/// cache, as a camera hit's does (CachedTerm; with `layered` direct light included), and only
/// its specular lobe's path goes on: the hit's light samples, shadow ray and bounces were most
/// of this path's time, and the cache's texels are averaged over frames and neighbours where
/// one path is not. From the store (`fs`), the hit reads StoreTerm where the camera's hits have
/// filled it. From the grid, the texel is chosen for a footprint of the lobe's width (alpha
/// radians either side of the ray): what a glossy reflection blurs over anyway, and coarse
/// texels that the camera's lookups share.
///
/// The ray is traced with probability p, the specular lobe's share of the surface's reflectance
/// at wo (Bsdf::SpecularShare) but at least kMinGlossyProbability, and its light weighted by 1 / p
/// (Russian roulette by expected contribution: the same expectation). A dielectric coat reflects
/// a few percent of the light at its specular lobe, yet its glossy ray and the path behind it are
/// among the largest parts of a frame's render; on a rough coat the roulette's noise is small
/// against the stage's own error, on a sharp bright reflection it shows (results/preview.md, "The
/// glossy ray by its share"). A metal (share 1) traces every sample.
void FrameGlossySample(const Context& c, const FrameMotion& motion, const SurfaceInteraction& si,
                       const Bsdf& bsdf, glm::vec3 wo, bool layered, const FrameStore* fs, Rng& rng,
                       FramePixel& px, RayCounts& rays) {
    glm::vec3 wi, weight;
    float pdf;
    const glm::vec2 u = rng.Next2D();
    const float p = std::clamp(bsdf.SpecularShare(wo), kMinGlossyProbability, 1.0f);
    if (rng.Next1D() >= p || !bsdf.SampleSpecular(wo, u, &wi, &weight, &pdf)) return;
    weight /= p;
    const Ray ray = SpawnRay(si, wi);
    Hit hit;
    ++rays.bounce;
    const bool found = c.rs.Intersect(ray, &hit);
    glm::vec3 L(0.0f);
    if (!found) {
        // Direct light from the environment and the suns: the light sample's MIS partner.
        if (c.env) {
            float envPdf;
            L = c.env->EvalPdf(si.N, wi, &envPdf);
            L *= PowerHeuristic(1, pdf, 1, envPdf * c.PickPdf());
        }
        L += c.SunRadiance(wi, pdf);
    } else if (hit.light >= 0) {
        L = c.EmittedMis(ray, hit, pdf);
    } else {
        // Light found at the hit (NEE) and beyond, after an emissive surface's own.
        L = c.EmittedMis(ray, hit, pdf);
        if (fs) {
            L += LiPath(c, ray, hit, found, rng, c.opt.maxDepth - 1, rays, false,
                        StoreTerm{c, *fs, layered});
        } else if (c.tsc) {
            RayDifferentials lobe;
            const Frame f = Frame::FromZ(wi);
            lobe.dDdx = bsdf.Alpha() * f.s, lobe.dDdy = bsdf.Alpha() * f.t;
            auto cached = [&](const SurfaceInteraction& h, const Ray& r, glm::vec3* term) {
                const Bsdf hb = MakeBsdf(c, h);
                // The diffuse lobe is 0 where the shading normal faces away from the ray.
                *term =
                    glm::dot(r.dir, h.N) < 0.0f
                        ? FiniteOrZero(hb.DiffuseReflectance() * CachedDiffuse(c, h, layered, rays))
                        : glm::vec3(0.0f);
                if (hb.HasSpecular())
                    return layered ? CachedTerm::DiffuseBase : CachedTerm::BaseIndirect;
                return layered ? CachedTerm::All : CachedTerm::Indirect;
            };
            L += LiPath(c, ray, hit, found, rng, c.opt.maxDepth - 1, rays, false, cached, &lobe);
        } else {
            L += LiPath(c, ray, hit, found, rng, c.opt.maxDepth - 1, rays, false);
        }
    }
    px.glossySum += FiniteOrZero(weight * L);
    if (found && !std::isfinite(px.glossyHit.x)) {
        px.glossyHit = ray.org + hit.t * ray.dir;
        px.prevGlossyHit = motion.Point(hit, px.glossyHit);
    }
}

/// The diffuse lobe's path of one sample: incident indirect radiance into px.diffuseSum and,
/// with the cones' `axes` (RenderOptions::frameBufferCones), its cone.
void FrameDiffuseSample(const Context& c, const SurfaceInteraction& si, const Bsdf& bsdf,
                        const std::array<glm::vec3, screen::kNumCones>* axes, Rng& rng,
                        FramePixel& px, RayCounts& rays) {
    glm::vec3 wi;
    glm::vec3 L(0.0f);
    if (bsdf.SampleDiffuse(rng.Next2D(), &wi)) {
        const Ray ray = SpawnRay(si, wi);
        Hit hit;
        ++rays.bounce;
        const bool found = c.rs.Intersect(ray, &hit);
        // Light hit directly is the light sample's: emitFirst = false.
        L = FiniteOrZero(LiPath(c, ray, hit, found, rng, c.opt.maxDepth - 1, rays, false));
    }
    px.diffuseSum += L;
    if (!axes) return;  // no cones asked for
    // Cosine-sampled: L is this sample's estimate of irradiance / pi (see AddConeSample).
    screen::AddConeSample(*axes, wi, L, px.coneSum.data());
    px.hasCones = true;
}

/// The values of a pixel that nothing was found at (background), in every buffer but the
/// shadow rays' (WriteShadowBuffers): each pixel writes all of its entries, so the buffers need
/// no clearing pass before a frame (a serial fill of ~40 MB at 640x360).
void ClearPixel(screen::FrameBuffers& fb, size_t p) {
    const glm::vec3 zero(0.0f);
    fb.emitted[p] = zero;
    fb.shading[p] = zero;
    if (!fb.glossy.empty()) {
        fb.glossy[p] = zero;
        fb.glossyHit[p] = kNaN3;
        if (!fb.prevGlossyHit.empty()) fb.prevGlossyHit[p] = kNaN3;
    }
    fb.indirect[p] = zero;
    fb.position[p] = kNaN3;
    fb.normal[p] = kNaN3;
    fb.depth[p] = INFINITY;
    fb.roughness[p] = 0.0f;
    fb.albedo[p] = zero;
    fb.specular[p] = zero;
    fb.objectId[p] = -1;
    if (!fb.prevPosition.empty()) fb.prevPosition[p] = kNaN3, fb.prevNormal[p] = kNaN3;
    if (!fb.cones.empty())
        for (int k = 0; k < screen::kNumCones; ++k) fb.cones[p * screen::kNumCones + k] = kNaN3;
    if (!fb.cachedVisibility.empty()) fb.cachedVisibility[p] = kNaN;
}

/// Visibility, blocker and light point of a pixel whose shadow rays are all finished (a pixel
/// without any: visible, NaN points).
void WriteShadowBuffers(screen::FrameBuffers& fb, size_t p, const PixelShadow& sh) {
    fb.visibility[p] = sh.weightSum > 0.0f ? sh.visibleWeightSum / sh.weightSum : 1.0f;
    fb.emitted[p] += sh.delta;
    if (fb.blocker.empty()) return;  // no shadow points asked for (frameBufferShadowPoints)
    // NaN unless a sample was blocked (the ratio can be < 1 without).
    fb.blocker[p] = sh.blocker;
    fb.prevBlocker[p] = sh.prevBlocker;
    fb.lightSample[p] = sh.light;
    fb.prevLightSample[p] = sh.prevLight;
}

/// Every buffer of pixel (x, y) from its camera ray and hit but the shadow rays' (see
/// WriteShadowBuffers): the samples' shadow rays are appended to `shadows`, for pixel `pixel` of
/// the tile, and `px` keeps what they need.
void ShadePixel(const Context& c, const FrameLights& lights, const FrameMotion& motion,
                const EnvironmentSamples& envSamples, bool layered, const FrameStore* fs, int x,
                int y, int pixel, const Ray& ray, bool found, const Hit& hit,
                const SurfaceInteraction& si, const HitRecord& storeRecord, int texelLevel,
                screen::FrameBuffers& fb, PixelShadow& sh, std::vector<PendingShadow>& shadows,
                std::vector<std::vector<DeltaShadow>>& deltaShadows, RayCounts& rays) {
    const size_t p = size_t(y) * size_t(c.opt.width) + size_t(x);
    ClearPixel(fb, p);
    if (fs) fs->records[p].mesh = PassTexels::kMiss;
    if (!found) {
        fb.emitted[p] = c.Background(ray.dir);
        return;
    }
    if (hit.light >= 0) {
        fb.emitted[p] = c.HitEmission(ray, hit);
        const glm::vec3 P = ray.org + hit.t * ray.dir;
        glm::vec3 n = hit.light < int(c.quads.size()) ? c.quads[size_t(hit.light)].n
                                                      : glm::normalize(hit.Ng);  // a sphere
        if (glm::dot(n, ray.dir) > 0.0f) n = -n;
        fb.position[p] = P;
        fb.normal[p] = n;
        fb.depth[p] = hit.t;
        if (!fb.prevPosition.empty())
            fb.prevPosition[p] = motion.Point(hit, P), fb.prevNormal[p] = motion.Normal(hit, n);
        return;
    }
    const Bsdf bsdf = MakeBsdf(c, si);
    const Material& m = c.scene.materials[si.material];
    fb.emitted[p] = c.HitEmission(ray, hit);  // an emissive object's own light
    fb.position[p] = si.P;
    fb.normal[p] = si.N;
    fb.depth[p] = hit.t;
    fb.roughness[p] = bsdf.Alpha();
    fb.albedo[p] = bsdf.DiffuseReflectance();
    fb.specular[p] = bsdf.HasSpecular() ? c.rs.Specular(si) : glm::vec3(0.0f);
    fb.objectId[p] = si.object;
    if (!fb.prevPosition.empty())
        fb.prevPosition[p] = motion.Point(hit, si.P), fb.prevNormal[p] = motion.Normal(hit, si.N);
    if (c.opt.maxDepth < 1) return;  // the path tracer sees emission only

    const glm::vec3 wo = -ray.dir;
    // The shading normal can face away from the camera where the tessellation does not: the
    // BSDF is 0 there, and there is no diffuse ray (nor cone sample).
    const bool diffuse = bsdf.DiffuseReflectance() != glm::vec3(0.0f) && c.opt.maxDepth >= 2 &&
                         glm::dot(wo, si.N) > 0.0f;
    // The diffuse lobe takes indirect light from the texture-space cache, as Render() does for
    // diffuse materials (the cached irradiance does not depend on the material: a GGX base's
    // is the same); `layered` (CachedDiffuseLight), its direct light too.
    const bool cachedIndirect = diffuse && c.tsc;
    // From the store: the pixel's record, and its path traced (below) when in the frame's
    // budget or when its bin holds too few samples yet (disocclusions, a first frame); the
    // light is read back once every hit is added (ResolveStore).
    bool storePath = false;
    if (cachedIndirect && fs) {
        fs->records[p] = storeRecord;
        fs->binned[p] = {glm::vec3(kNaN), bsdf.DiffuseReflectance(), texelLevel};
        // The store's count at the record (its bin prefetched by RenderTile), and for a traced
        // hit the light it holds there: BoundStoreHits' reference.
        if (fs->own) {
            const double count = StoreCountAt(*c.tsc, *fs->store, fs->records[p]);
            storePath = fs->Traces(x, y, count);
            if (storePath && count >= fs->minPrior)
                fs->binned[p].prior = Luminance(StoreLightAt(*c.tsc, *fs->store, fs->records[p]));
        } else {
            glm::vec3 E;
            const double count = StoreCountAt(*c.tsc, *fs->store, fs->records[p],
                                              fs->Jitter(x, y, c.opt.width), fs->targetCount, &E);
            storePath = fs->Traces(x, y, count);
            if (storePath && count >= fs->minPrior) fs->binned[p].prior = Luminance(E);
        }
    } else if (cachedIndirect) {
        const glm::vec3 E = CachedDiffuse(c, si, layered, rays);
        fb.indirect[p] = FiniteOrZero(bsdf.DiffuseReflectance() * E);
        // The cache knows irradiance, not its direction: the same radiance in every cone, so
        // that indirect = albedo * ShadeCones(cones) holds here too and the stage's cone
        // history (Reliable) carries the cached light instead of finding no cones.
        const glm::vec3 Epi = FiniteOrZero(E);
        if (!fb.cones.empty())
            for (int k = 0; k < screen::kNumCones; ++k) fb.cones[p * screen::kNumCones + k] = Epi;
    }
    // The diffuse lobe's visibility from the cache (view-independent, so diffuse materials
    // only; GGX ones keep NaN: none).
    if (!fb.cachedVisibility.empty() && m.type == Material::Type::Diffuse && !layered &&
        glm::dot(wo, si.N) > 0.0f) {
        const SampleRequest texel = c.tsc->VisibilityTexelOf(si);
        const glm::vec3 V = CachedLookup(
            c, si, [&](const SampleRequest& r) { return ShadeVisibilitySample(c, r, rays); },
            c.opt.texture.shadowSamples, nullptr, &texel);
        fb.cachedVisibility[p] = std::isfinite(V.x) ? std::max(V.x, 0.0f) : kNaN;
    }
    const bool diffuseRay = diffuse && !cachedIndirect;
    std::array<glm::vec3, screen::kNumCones> axes;
    const bool cones = diffuseRay && !fb.cones.empty();
    if (cones) axes = screen::ConeAxes(si.N);
    glm::vec3 exactShading;
    LightWeights weights;
    const bool closedForm = !layered &&
                            ClosedFormShading(c, si, bsdf, wo, &exactShading, &weights) &&
                            Luminance(glm::abs(exactShading)) > 0.0f;
    FramePixel px;
    const int spp = std::max(c.opt.spp, 1);
    // The delta lights' light is the same for every sample: traced once.
    if (!layered) DeltaDirect(c, lights, si, bsdf, wo, pixel, deltaShadows);
    glm::vec3 storeSum(0.0f);
    for (int s = 0; s < spp; ++s) {
        Rng rng(PixelSeed(c.opt.seed, x, y, c.opt.width), uint64_t(s));
        // With the diffuse lobe's light all cached, only a specular lobe samples lights here
        // (none on diffuse materials: shading 0, visible); with delta lights only, none.
        if ((!layered || bsdf.HasSpecular()) && !lights.other.empty())
            FrameDirectSample(c, lights, si, bsdf, wo, closedForm ? &exactShading : nullptr,
                              weights, rng, envSamples, px, sh, pixel, shadows, layered);
        if (bsdf.HasSpecular())
            FrameGlossySample(c, motion, si, bsdf, wo, layered, fs, rng, px, rays);
        if (diffuseRay) FrameDiffuseSample(c, si, bsdf, cones ? &axes : nullptr, rng, px, rays);
        glm::vec3 wi;
        if (storePath && bsdf.SampleDiffuse(rng.Next2D(), &wi))
            storeSum += DiffuseRayLight(c, SpawnRay(si, wi), si.N, layered, rng, rays,
                                        StoreTerm{c, *fs, layered});
    }
    const float inv = 1.0f / float(spp);
    // NaN or infinite stays NaN: the store never takes it (RadianceBin::FromRadiance).
    if (storePath) fs->binned[p].light = storeSum * inv;
    fb.shading[p] = px.shadingSum * inv;
    if (bsdf.HasSpecular()) fb.glossy[p] = px.glossySum * inv;
    if (!cachedIndirect) fb.indirect[p] = bsdf.DiffuseReflectance() * px.diffuseSum * inv;
    if (bsdf.HasSpecular()) {
        fb.glossyHit[p] = px.glossyHit;
        if (!fb.prevGlossyHit.empty()) fb.prevGlossyHit[p] = px.prevGlossyHit;
    }
    if (px.hasCones && !fb.cones.empty())
        for (int k = 0; k < screen::kNumCones; ++k)
            fb.cones[p * screen::kNumCones + k] = px.coneSum[k] * inv;
}

/// Whether the cache holds all of the diffuse lobe's light, direct included
/// (opt.texture.cacheDiffuseLayer): with texture space on, under soft light only.
/// The diffuse lobe's direct light is view-independent and, under an environment or area lights,
/// soft: the cache shades it once per texel and keeps it from frame to frame, where per pixel it
/// took most of the 32 light samples of a GGX material's `shading` and the 6 of a diffuse one's
/// with a shadow ray (results/frame_buffers_profile.md). Delta and distant lights' shadows are
/// sharp: the cache's filter and texels would blur them, so with any of them direct light stays
/// per pixel.
bool CachedDiffuseLight(const Context& c, const RenderOptions& opt) {
    // The cached light includes a bounce: with max_depth 1 (direct light only) the diffuse
    // lobe has no cached term.
    return c.tsc && opt.texture.cacheDiffuseLayer && opt.maxDepth >= 2 && c.distantDir.empty() &&
           c.spheres.empty();
}

// Frames are rendered in tiles of kTile x kTile pixels, fixed whatever the thread count (the
// packets below are the same for any, and so is the image).
constexpr int kTile = 8;
constexpr int kTilePixels = kTile * kTile;

/// What a pixel writes, plane by plane: every frame buffer and the store's record and binned
/// hit, as {first byte, bytes a pixel}. A pixel writes about 300 bytes to some 24 planes, and a
/// tile's rows lie a frame's width apart, a pattern the hardware prefetchers do not follow.
/// Without a prefetch each of those lines is a demand miss for ownership; the misses fill the
/// store buffer, and the shading stalls behind them (in a profile, on the plain stack stores
/// that follow a pixel's buffer writes).
struct PixelPlanes {
    static constexpr int kMax = 32;
    const char* base[kMax];
    size_t bytes[kMax];
    int n = 0;

    PixelPlanes(const screen::FrameBuffers& fb, const FrameStore* fs) {
        auto add = [&](const auto& plane, size_t perPixel = 1) {
            if (plane.empty()) return;
            base[n] = reinterpret_cast<const char*>(plane.data());
            bytes[n++] = perPixel * sizeof(plane[0]);
        };
        for (const auto* plane : {&fb.emitted, &fb.shading, &fb.glossy, &fb.indirect, &fb.position,
                                  &fb.normal, &fb.albedo, &fb.specular, &fb.prevPosition,
                                  &fb.prevNormal, &fb.blocker, &fb.prevBlocker, &fb.lightSample,
                                  &fb.prevLightSample, &fb.glossyHit, &fb.prevGlossyHit})
            add(*plane);
        for (const auto* plane : {&fb.visibility, &fb.cachedVisibility, &fb.depth, &fb.roughness})
            add(*plane);
        add(fb.objectId);
        add(fb.cones, screen::kNumCones);
        if (fs) {
            base[n] = reinterpret_cast<const char*>(fs->records), bytes[n++] = sizeof(HitRecord);
            base[n] = reinterpret_cast<const char*>(fs->binned), bytes[n++] = sizeof(BinnedHit);
        }
    }
    /// Prefetches for writing planes part, part + parts, ... of pixels [p, p + count).
    void PrefetchForWrite(size_t p, int count, int part = 0, int parts = 1) const {
        for (int i = part; i < n; i += parts)
            PrefetchBytesForWrite(base[i] + p * bytes[i], size_t(count) * bytes[i]);
    }
};

/// A thread's scratch for its tiles (sized once: nothing is allocated per tile).
struct TileScratch {
    std::array<Ray, kTilePixels> ray;
    std::array<RayDifferentials, kTilePixels> diff;
    std::array<Hit, kTilePixels> hit;
    std::array<bool, kTilePixels> found;
    std::array<SurfaceInteraction, kTilePixels> si;
    std::array<HitRecord, kTilePixels> storeRecord;  ///< where the pixel reads the store
    std::array<int, kTilePixels> texelLevel;
    std::array<PixelShadow, kTilePixels> shadow;
    std::vector<PendingShadow> shadows;
    std::vector<std::vector<DeltaShadow>> deltaShadows;  ///< per delta light (FrameLights)
};

/// The tile with top-left pixel (x0, y0). Its camera rays and then its shadow rays are traced 16
/// at a time (RenderScene::Intersect16): neighbouring pixels' camera rays share most of their
/// BVH nodes, and so do their shadow rays to the same light; Embree's packet traversal is
/// cheaper per ray for such rays than single rays.
void RenderTile(const Context& c, const FrameLights& lights, const FrameMotion& motion,
                const EnvironmentSamples& envSamples, bool layered, const FrameStore* fs,
                const PixelPlanes& planes, int x0, int y0, screen::FrameBuffers& fb,
                TileScratch& ts, RayCounts& rays) {
    const int x1 = std::min(x0 + kTile, c.opt.width), y1 = std::min(y0 + kTile, c.opt.height);
    // The first row's buffers while the camera rays are traced, each next row's while a row is
    // shaded (PixelPlanes).
    const size_t W = size_t(c.opt.width);
    planes.PrefetchForWrite(size_t(y0) * W + size_t(x0), x1 - x0);
    // Ray differentials: a Ptex texture's filter width (the pixel's footprint, as the path
    // tracer's camera hits take it), and the level of the grid's texels the pixel looks up (its
    // cached light without the store, the cached visibility). The store's records take their
    // level from the camera's footprint at the hit's distance (FrameHitRecord): store frames
    // without Ptex textures trace no differentials (the planes, solves and divisions of every
    // camera hit's Interact).
    const bool diff = c.textureFootprints || (c.tsc && (!fs || !fb.cachedVisibility.empty()));
    int n = 0;
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x, ++n) {
            // Pixel centre, lens centre, shutter open: exact guides (see the header).
            const Ray r = c.camera.Generate(float(x) + 0.5f, float(y) + 0.5f, glm::vec2(0.5f),
                                            diff ? &ts.diff[n] : nullptr);
            // Field by field: copying the whole temporary stalls on store forwarding (visible in
            // this function's profile).
            Ray& ray = ts.ray[n];
            ray.org = r.org, ray.dir = r.dir;
            ray.tnear = r.tnear, ray.tfar = r.tfar;
            ray.time = 0.0f;
        }
    for (int i = 0; i < n; i += 16)
        c.rs.Intersect16(&ts.ray[i], std::min(16, n - i), &ts.hit[i], &ts.found[i]);
    rays.camera += uint64_t(n);

    // The tile's surface interactions first, and with the store, each hit's record and a
    // prefetch of its bins: the store's table is far larger than the caches, and the pixel's
    // read of it (StoreCountAt) waited on memory right after its record was known.
    const int tileWidth = x1 - x0;
    for (int i = 0; i < n; ++i) {
        if (!ts.found[i] || ts.hit[i].light >= 0) continue;
        ts.si[i] = c.rs.Interact(ts.ray[i], ts.hit[i], diff ? &ts.diff[i] : nullptr);
        if (!fs) continue;
        FrameHitRecord(c, ts.si[i], ts.hit[i].t, fs->bias, &ts.storeRecord[i], &ts.texelLevel[i]);
        if (fs->own)
            PrefetchStoreAt(*c.tsc, *fs->store, ts.storeRecord[i]);
        else
            PrefetchStoreAt(*c.tsc, *fs->store, ts.storeRecord[i],
                            fs->Jitter(x0 + i % tileWidth, y0 + i / tileWidth, c.opt.width));
    }
    ts.shadows.clear();
    ts.deltaShadows.resize(lights.delta.size());
    for (auto& d : ts.deltaShadows) d.clear();
    for (int i = 0, y = y0; y < y1; ++y) {
        for (int x = x0; x < x1; ++x, ++i) {
            // The next row's planes, a few at each pixel: all at once, the prefetches queue
            // behind each other for the line fill buffers.
            if (y + 1 < y1)
                planes.PrefetchForWrite(size_t(y + 1) * W + size_t(x0), x1 - x0, x - x0, x1 - x0);
            ts.shadow[i].Reset();
            ShadePixel(c, lights, motion, envSamples, layered, fs, x, y, i, ts.ray[i], ts.found[i],
                       ts.hit[i], ts.si[i], ts.storeRecord[i], ts.texelLevel[i], fb, ts.shadow[i],
                       ts.shadows, ts.deltaShadows, rays);
        }
    }

    // The delta lights' rays, light by light: a packet's rays go to one light from neighbouring
    // pixels, and only whether they are blocked is asked.
    for (const std::vector<DeltaShadow>& d : ts.deltaShadows) {
        Ray packet[16];
        bool occluded[16];
        for (size_t i = 0; i < d.size(); i += 16) {
            const int m = int(std::min<size_t>(16, d.size() - i));
            for (int j = 0; j < m; ++j) packet[j] = d[i + size_t(j)].ray;
            c.rs.Occluded16(packet, m, occluded);
            for (int j = 0; j < m; ++j)
                if (!occluded[j]) ts.shadow[d[i + size_t(j)].pixel].delta += d[i + size_t(j)].term;
        }
        rays.shadow += d.size();
    }

    // In queue order: a pixel's samples finish in their order, as if traced one by one. Without
    // shadow points only whether a ray is blocked is asked: Embree stops at any hit.
    Ray packet[16];
    Hit hits[16];
    bool blocked[16];
    const size_t ns = ts.shadows.size();
    const bool points = !fb.blocker.empty();
    for (size_t i = 0; i < ns; i += 16) {
        const int m = int(std::min<size_t>(16, ns - i));
        for (int j = 0; j < m; ++j) packet[j] = ts.shadows[i + size_t(j)].ray;
        if (points)
            c.rs.Intersect16(packet, m, hits, blocked);
        else
            c.rs.Occluded16(packet, m, blocked);
        for (int j = 0; j < m; ++j) {
            const PendingShadow& s = ts.shadows[i + size_t(j)];
            PixelShadow& sh = ts.shadow[s.pixel];
            if (points)
                FinishShadow(motion, s, blocked[j], hits[j], sh);
            else if (!blocked[j])
                sh.visibleWeightSum += s.w;
        }
    }
    rays.shadow += ns;
    for (int i = 0, y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x, ++i)
            WriteShadowBuffers(fb, size_t(y) * size_t(c.opt.width) + size_t(x), ts.shadow[i]);
}

/// The samples a pixel's reconstruction needs behind it in the store (StoreCountAt) for a frame
/// not to trace the pixel's path every frame: fewer, and it is a disocclusion or a first frame's.
constexpr double kStoreMinSamples = 0.5;

/// The rate at which a pixel traces its path, at `count` samples behind its reconstruction, is
/// this many over `count` (FrameStore::Traces), from every frame down to the budget's. A bin's
/// noise is its own samples' (one per path), so a path added where a bin holds few lowers the
/// image's error far more than one added where it holds many; under the store's decay each bin
/// settles where its paths balance what the decay forgets (about sqrt(this x its pixels x the
/// frames the decay keeps) samples), and the fine bins near the camera, which hold the fewest
/// and show as blotches the stage cannot tell from texture, take more of the frame's paths.
constexpr double kStoreTargetSamples = 4.0;

/// The store's budget while the view is still: one pixel in this many traces its path a frame.
/// Every pixel: the store's running mean and the pixels' own samples then gather paths
/// frameBufferBudget times as fast as while moving, for that much more of the paths' render time
/// (results/preview.md, "A still view's own samples").
constexpr int kStillStoreBudget = 1;

/// How many levels finer than the still renderer's schedule (HitBinLevels) the store's bins lie.
/// The still renderer removes its bins' bias with each pixel's own samples
/// (CombineWithOwnSamples); the frame buffers have one sample a pixel at most, so the store's
/// bins must be small enough that their bias is not what the stage is left with, and a still
/// view's running mean keeps converging (Preview.StageStillViewErrorFallsOverFrames).
constexpr float kStoreFinerLevels = 2.0f;

/// The frame buffers' store's most blocks (520 MiB of radiance bins).
constexpr size_t kMaxStoreBlocks = size_t(1) << 20;

/// The cache's light store moved into one of at least `blocks` blocks, its sums scaled by
/// keep / 2^16 on the way and the blocks that fell to zero released.
LightHitStore& GrowStore(TextureSpaceCache& tsc, size_t blocks, uint32_t keep) {
    std::vector<uint64_t> records;
    if (const LightHitStore* old = tsc.LightStoreIfAny()) old->Samples().ExportBlocks(&records);
    if (keep < (1u << 16)) RadianceBins::ScaleRecords(&records, keep);
    LightHitStore& store = tsc.LightStore(blocks);
    store.Clear();
    store.Samples().AddBlocks(records.data(), records.size() / RadianceBins::kRecordWords);
    return store;
}

/// The store as a new frame of the frame buffers takes it: the previous frames' sums decayed by
/// keep / 2^16 (eq. 6; all kept while the view is still or nothing moves: FrameStoreKeep), in
/// place while at most half its blocks are in use, else moved into a table twice the blocks in
/// use (released the zeros); `firstBlocks` for a cache that has none yet.
LightHitStore& DecayStore(TextureSpaceCache& tsc, size_t firstBlocks, uint32_t keep) {
    LightHitStore* store = tsc.LightStoreIfAny();
    if (!store) return GrowStore(tsc, std::max(firstBlocks, size_t(1024)), keep);
    const RadianceBins& bins = store->Samples();
    if (2 * bins.BlocksUsed() > bins.NumBlocks())
        return GrowStore(tsc, std::min(4 * bins.BlocksUsed(), kMaxStoreBlocks), keep);
    if (keep < (1u << 16))
        store->DecayInPlace(keep, [](size_t n, auto&& body) {
            tbb::parallel_for(
                tbb::blocked_range<size_t>(0, n, 4096),
                [&](const tbb::blocked_range<size_t>& r) { body(r.begin(), r.end()); });
        });
    else
        store->AddsDone();  // a new generation: nothing read before is kept
    return *store;
}

/// Each stored pixel's diffuse light read back from the store, now holding the frame's hits:
/// `indirect` is albedo x the reconstruction, and the six cones all hold it (as the grid's). In a
/// still view (fs.own) the reconstruction is first blended with the pixel's own samples
/// (BlendWithOwnLight), which needs its neighbours' estimates: a second pass.
void ResolveStore(const Context& c, const FrameStore& fs, const LightHitStore& store,
                  screen::FrameBuffers& fb) {
    const int W = c.opt.width, H = c.opt.height;
    auto write = [&](size_t p, glm::vec3 E) {
        E = FiniteOrZero(E);
        fb.indirect[p] = FiniteOrZero(fs.binned[p].albedo * E);
        if (!fb.cones.empty())
            for (int k = 0; k < screen::kNumCones; ++k) fb.cones[p * screen::kNumCones + k] = E;
    };
    // In tiles: a thread's memo of the bins it read (ThreadCells) holds a tile's, where a row's
    // would be evicted before the next row reads them again.
    auto tiles = [&](auto&& pixel) {
        tbb::parallel_for(tbb::blocked_range2d<int>(0, H, 16, 0, W, 16),
                          [&](const tbb::blocked_range2d<int>& r) {
                              for (int y = r.rows().begin(); y < r.rows().end(); ++y)
                                  for (int x = r.cols().begin(); x < r.cols().end(); ++x)
                                      pixel(x, y, size_t(y) * size_t(W) + size_t(x));
                          });
    };
    if (!fs.own) {
        // One bin a pixel (the stochastic read, FrameStore::Jitter): no memo to keep by tiles.
        tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& r) {
            for (int y = r.begin(); y < r.end(); ++y)
                for (int x = 0; x < W; ++x) {
                    const size_t p = size_t(y) * size_t(W) + size_t(x);
                    if (const HitRecord& h = fs.records[p]; h.mesh >= 0)
                        write(p,
                              StoreLightAt(*c.tsc, store, h, fs.Jitter(x, y, W), fs.targetCount));
                }
        });
        return;
    }
    tiles([&](int, int, size_t p) {
        const HitRecord& h = fs.records[p];
        if (h.mesh >= 0) {
            PrepareOwnLight(fs.own[p], FiniteOrZero(StoreLightAt(*c.tsc, store, h)));
        } else {
            fs.own[p] = {};  // nothing to read: nor to weigh in a neighbour's window
        }
    });
    tiles([&](int x, int y, size_t p) {
        if (fs.records[p].mesh >= 0) write(p, BlendWithOwnLight(fs.own, W, H, x, y));
    });
}

}  // namespace

std::string FrameBufferCameraProblem(const Camera& cam) {
    // Only what a render would show: a lens or an open shutter the buffers would silently drop.
    char buf[64];
    if (cam.lensRadius > 0.0f) {
        std::snprintf(buf, sizeof buf, "%g", cam.lensRadius);
        return std::string("its camera has a lens (lens_radius ") + buf +
               ") but frame buffers trace through the lens centre (no defocus blur): set "
               "lens_radius 0 or render without the screen-space buffers";
    }
    if (cam.shutterClose > cam.shutterOpen) {
        std::snprintf(buf, sizeof buf, "%g", cam.shutterClose - cam.shutterOpen);
        return std::string("its camera shutter is open for ") + buf +
               " s but frame buffers are traced at shutter open (no motion blur): close the "
               "shutter or render without the screen-space buffers";
    }
    return "";
}

RenderStats RenderFrameBuffers(const RenderScene& rs, const RenderOptions& options, float prevTime,
                               screen::FrameBuffers* out, TextureSpaceCache* cache) {
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    const std::clock_t cpuStart = std::clock();
    if (options.width <= 0 || options.height <= 0)
        throw InputError("frame buffers", "frame size must be positive, got " +
                                              std::to_string(options.width) + "x" +
                                              std::to_string(options.height));
    if (!std::isfinite(prevTime))
        throw InputError("frame buffers", "the previous frame's time is not finite");
    RenderOptions opt = options;
    opt.integrator = IntegratorKind::Path;  // the Context builds the lights for it
    Context ctx(rs, opt);
    FrameCache frameCache(ctx, opt, cache, FrameCache::Prepass::None);
    const FrameMotion motion(rs, opt, prevTime);
    const EnvironmentSamples envSamples(ctx, opt.seed);
    const FrameLights lights(ctx);
    // The paths' light samples (the store's, the glossy ray's) read the frame's table too.
    if (!envSamples.Empty()) {
        ctx.envTable = &envSamples[0];
        ctx.envTableMask = EnvironmentSamples::kCount - 1u;
    }

    screen::FrameBuffers& fb = *out;
    const int W = opt.width, H = opt.height;
    fb.width = W;
    fb.height = H;
    fb.time = opt.frameTime;
    fb.indirectAccumulates = false;  // set below for a still view of the store
    fb.camera = MakeFrameCamera(rs.scene().camera, opt.frameTime, W, H);
    const size_t n = fb.NumPixels();
    // Sized only: every pixel writes all of its entries (ClearPixel), so a FrameBuffers reused
    // across frames is neither cleared nor reallocated.
    for (auto* v : {&fb.emitted, &fb.shading, &fb.indirect, &fb.position, &fb.normal, &fb.albedo,
                    &fb.specular})
        v->resize(n);
    for (auto* v : {&fb.visibility, &fb.depth, &fb.roughness}) v->resize(n);
    fb.objectId.resize(n);
    // Whether only the camera moved since prevTime: the stage's shadow vectors are then its
    // traditional ones.
    fb.shadowsStill = !rs.scene().MovesBetween(prevTime, opt.frameTime);
    // The points moved to the previous frame, unless nothing but the camera moved and the caller
    // takes the current ones for them (RenderOptions::frameBufferPrevPoints).
    const bool prevPoints = opt.frameBufferPrevPoints || !fb.shadowsStill;
    fb.prevPosition.resize(prevPoints ? n : 0);
    fb.prevNormal.resize(prevPoints ? n : 0);
    // The shadow rays' blocker and light points, unless the frame's shadows stayed where they
    // were and the caller's stage takes the traditional vectors there
    // (RenderOptions::frameBufferShadowPoints): then the shadow rays only ask whether they are
    // blocked.
    const bool shadowPoints = opt.frameBufferShadowPoints || !fb.shadowsStill;
    for (auto* v : {&fb.blocker, &fb.prevBlocker, &fb.lightSample, &fb.prevLightSample})
        v->resize(shadowPoints ? n : 0);
    // Only what the scene has: without a GGX material `glossy` and its hits stay empty, and the
    // stage skips that component (its motion vectors, history and a-trous channels: 17% of the
    // stage's CPU time on anim_shadow at 640x360, `texcache preview --bench --denoise reliable`).
    const Scene& scene = rs.scene();
    bool anyGlossy = false;
    for (const Object& o : scene.objects)
        for (const int m : o.Materials())
            anyGlossy |= scene.materials[size_t(m)].type == Material::Type::GGX;
    for (auto* v : {&fb.glossy, &fb.glossyHit}) v->resize(anyGlossy ? n : 0);
    fb.prevGlossyHit.resize(anyGlossy && prevPoints ? n : 0);
    fb.cones.resize(opt.frameBufferCones ? n * screen::kNumCones : 0);
    // Only when asked for and there is a cache to look it up in (ctx.tsc: texture shading).
    if (ctx.tsc && opt.texture.cachedVisibility && !ctx.tsc->options().cachedVisibility)
        throw InputError("frame buffers",
                         "cached visibility asked for, but the texture-space cache was built "
                         "without it (TextureSpaceOptions::cachedVisibility): it has no "
                         "visibility grids");
    fb.cachedVisibility.resize(ctx.tsc && opt.texture.cachedVisibility ? n : 0);

    const bool layered = CachedDiffuseLight(ctx, opt);

    // The store (frame_buffers_render.h): the previous frames' bins, decayed if anything moved.
    const bool useStore = ctx.tsc && opt.texture.frameBufferSamples == TextureSamples::Hits;
    std::unique_ptr<FrameStore> fs;
    if (useStore) {
        const int k = opt.texture.frameBufferBudget;
        if (k < 1 || k > 16 || (k & (k - 1)) != 0)
            throw InputError("frame buffers",
                             "the store's budget must be one pixel in 1, 2, 4, "
                             "8 or 16, got " +
                                 std::to_string(k));
        TextureSpaceCache& tsc = *ctx.tsc;
        // The bins' level, chosen once for the cache (a level that moved would orphan the
        // history): for the camera samples a bin's pixels hold, 1 / (1 - alpha) each
        // (FrameStoreKeep).
        int& bias = tsc.TemporalHitBias();
        const float alpha = std::clamp(opt.texture.temporalAlpha, 0.0f, 0.99f);
        const float levels =
            std::max(0.0f, TextureSpaceCache::HitBinLevels(
                               1, std::max(1, int(std::lround(1.0 / (1.0 - double(alpha))))), 0,
                               TextureSpaceCache::HitTerm::Light) -
                               kStoreFinerLevels);
        if (bias == INT_MIN) bias = int(std::floor(levels));
        fs = std::make_unique<FrameStore>();
        fs->bias = bias;
        fs->blend = std::clamp(levels - float(bias), 0.0f, 1.0f);
        fs->budget = k;
        fs->offset = (tsc.Frame() * uint32_t(16 / k)) & 15u;
        fs->jitterSeed = MixBits(opt.seed ^ (uint64_t(tsc.Frame()) << 32) ^ 0x5851F42D4C957F2Dull);
        fs->minCount = kStoreMinSamples * double(tsc.HitUnit());
        fs->targetCount = kStoreTargetSamples * double(tsc.HitUnit());
        fs->termCount = kStoreTermSamples * double(tsc.HitUnit());
        fs->minPrior = double(tsc.HitUnit());
        fs->records = tsc.HitRecords(n);
        fs->binned = tsc.BinnedHits(n);
        fs->own = tsc.StillOwnLight(W, H);
        fb.indirectAccumulates = fs->own != nullptr;
        // A still view traces every pixel's path every frame (kStillStoreBudget).
        if (fs->own) fs->budget = kStillStoreBudget, fs->offset = 0;
        // A first guess of four blocks per Ptex face plus the pixels' bins, 16 to a block.
        const size_t guess =
            4 * tsc.NumFaces() + 2 * n / (size_t(16) << (2 * std::clamp(bias, 0, 8)));
        const size_t firstBlocks = std::min(2 * guess, kMaxStoreBlocks);
        // A running mean keeps every bin it was given (FrameStoreKeep). Once the store holds
        // far more than a view's bins (twice the first table: a long flight through a large
        // scene), the frame decays by eq. 6 as if something moved, so that the bins the camera
        // no longer sees fade and the table releases them when it next grows, instead of
        // growing towards kMaxStoreBlocks.
        const LightHitStore* held = tsc.LightStoreIfAny();
        const bool crowded = held && held->Samples().BlocksUsed() > 2 * firstBlocks;
        const bool moves = rs.scene().MovesBetween(prevTime, opt.frameTime);
        fs->store = &DecayStore(tsc, firstBlocks, tsc.FrameStoreKeep(k, moves || crowded));
    }

    const int tilesX = (W + kTile - 1) / kTile, tilesY = (H + kTile - 1) / kTile;
    tbb::enumerable_thread_specific<RayCounts> counts;
    tbb::enumerable_thread_specific<TileScratch> scratch;
    const PixelPlanes planes(fb, fs.get());
    tbb::parallel_for(tbb::blocked_range<int>(0, tilesX * tilesY),
                      [&](const tbb::blocked_range<int>& r) {
                          _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
                          _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
                          RayCounts& rc = counts.local();
                          TileScratch& ts = scratch.local();
                          for (int t = r.begin(); t < r.end(); ++t)
                              RenderTile(ctx, lights, motion, envSamples, layered, fs.get(), planes,
                                         (t % tilesX) * kTile, (t / tilesX) * kTile, fb, ts, rc);
                      });
    size_t storeReads = 0, storeTraced = 0;
    if (fs) {
        // Every traced hit added (integer sums: the same bins for any thread count), then every
        // stored pixel read back. The table is kept at most half full, counting a new block
        // for every eighth traced hit (a frame's hits mostly fall in blocks the store has;
        // an add that finds no room is dropped and counted, and the next frame's table grows).
        // A still view's pixels keep their paths' light as traced, before BoundStoreHits: their
        // own mean is the unbiased end of the blend (a lone bright path shows in its variance).
        using Counts = std::pair<size_t, size_t>;  // reads, traced
        const Counts counted = tbb::parallel_reduce(
            tbb::blocked_range<size_t>(0, n, 16384), Counts(0, 0),
            [&](const tbb::blocked_range<size_t>& r, Counts acc) {
                for (size_t p = r.begin(); p < r.end(); ++p)
                    if (fs->records[p].mesh >= 0) {
                        ++acc.first;
                        const bool traced = !std::isnan(fs->binned[p].light.x);
                        acc.second += traced ? 1 : 0;
                        if (traced && fs->own) AddOwnLight(fs->own[p], fs->binned[p].light);
                    }
                return acc;
            },
            [](Counts a, const Counts& b) {
                return Counts(a.first + b.first, a.second + b.second);
            });
        storeReads = counted.first, storeTraced = counted.second;
        const size_t traced = storeTraced;
        const RadianceBins& before = fs->store->Samples();
        const size_t need = 2 * (before.BlocksUsed() + traced / 8);
        LightHitStore& store = need > before.NumBlocks() && before.NumBlocks() < kMaxStoreBlocks
                                   ? GrowStore(*ctx.tsc, std::min(need, kMaxStoreBlocks), 1u << 16)
                                   : *ctx.tsc->LightStoreIfAny();
        // A lone bright path bounded, its excess spread over its neighbours' hits, before it
        // reaches every pixel that reads its bin.
        BoundStoreHits(ctx, fs->records, kStoreBoundRatio, fs->binned);
        tbb::parallel_for(tbb::blocked_range2d<int>(0, H, kTile, 0, W, kTile * 8),
                          [&](const tbb::blocked_range2d<int>& r) {
                              PathHitsAdd(ctx, r, 0, 1, fs->bias, fs->blend, fs->records,
                                          fs->binned, store.Samples(), true);
                          });
        store.AddsDone();
        ResolveStore(ctx, *fs, store, fb);
    }

    RenderStats stats;
    for (const RayCounts& rc : counts) {
        stats.cameraRays += rc.camera;
        stats.shadowRays += rc.shadow;
        stats.bounceRays += rc.bounce;
    }
    for (const CacheStats& cs : frameCache.Stats()) stats.cache.Merge(cs);
    // The store's reads as lookups: a hit where the pixel's light came from earlier frames'
    // hits alone, a miss (a sample shaded) where the pixel traced its path.
    stats.cache.lookups += storeReads, stats.cache.texelHits += storeReads - storeTraced;
    stats.cache.texelMisses += storeTraced, stats.cache.samplesShaded += storeTraced;
    stats.sppDone = std::max(opt.spp, 1);
    stats.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    stats.cpuSeconds = double(std::clock() - cpuStart) / CLOCKS_PER_SEC;
    return stats;
}

}  // namespace texcache
