// SPDX-License-Identifier: Apache-2.0
// Synthetic frames for the screen-space stage's tests and benchmark: a tiny analytic ray caster
// (infinite planes, axis-aligned boxes, spheres; each object translates at its own velocity)
// that fills every FrameBuffers field the renderer will: primary-hit guides, the previous-frame
// positions, one point/sphere-light sample with its shadow ray (blocker), one GGX glossy bounce
// (visible-normal sampling) and one cosine-sampled diffuse bounce recorded in the 6 cones.
// Secondary hits are shaded with a constant "ambient" times their albedo, the sky is a vertical
// gradient, so every component has a closed-form noise-free limit the tests can average towards.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "filters/screen_space/frame_buffers.h"
#include "renderer/sampling.h"

namespace texcache::test {

using screen::FrameBuffers;

struct SynthObject {
    enum class Kind { Plane, Box, Sphere } kind = Kind::Plane;
    int id = 0;
    glm::vec3 a{0.0f};         ///< plane: a point; box: min corner; sphere: centre
    glm::vec3 b{0.0f};         ///< plane: unit normal; box: max corner; sphere: (radius, -, -)
    glm::vec3 velocity{0.0f};  ///< world units per frame
    glm::vec3 albedo{0.5f};
    glm::vec3 f0{0.0f};          ///< > 0: glossy GGX lobe (the glossy component), else diffuse
    float roughness = 0.3f;      ///< GGX alpha
    float roughness2 = -1.0f;    ///< >= 0: checkerboard of roughness / roughness2 in x-z ...
    float checkerPeriod = 1.0f;  ///< ... with this period (world units)
    float ambient = 1.0f;        ///< radiance = albedo * ambient when hit by a secondary ray
};

struct SynthScene {
    int width = 96, height = 64;
    float fovY = 0.8f;  ///< radians
    glm::vec3 eye{0.0f, 2.0f, 6.0f}, target{0.0f, 0.0f, 0.0f};
    glm::vec3 eyeVelocity{0.0f};  ///< camera translation per frame (target moves along)
    glm::vec3 light{0.0f, 5.0f, 0.0f}, lightVelocity{0.0f};
    float lightRadius = 0.0f;  ///< 0: point light (hard shadows)
    glm::vec3 lightIntensity{20.0f};
    glm::vec3 skyZenith{0.3f, 0.5f, 1.0f}, skyHorizon{1.0f, 0.9f, 0.8f};
    std::vector<SynthObject> objects;
    bool glossy = true, indirect = true, cones = true;
};

namespace synth {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();
constexpr float kPi = 3.14159265358979f;

struct Rng {
    uint32_t s;
    explicit Rng(uint32_t seed) : s(seed * 0x9E3779B9u + 0x7F4A7C15u) { Next(); }
    uint32_t Next() {
        s ^= s << 13, s ^= s >> 17, s ^= s << 5;
        return s;
    }
    float Uniform() { return float(Next() >> 8) * (1.0f / 16777216.0f); }
};

inline glm::vec3 Sky(const SynthScene& sc, glm::vec3 d) {
    const float t = std::clamp(d.y, 0.0f, 1.0f);
    return glm::mix(sc.skyHorizon, sc.skyZenith, t);
}

struct Hit {
    float t = kInf;
    int obj = -1;
    glm::vec3 p{0.0f}, n{0.0f};
};

inline void Intersect(const SynthObject& o, float frame, glm::vec3 org, glm::vec3 dir, float tMin,
                      Hit* h, int index) {
    const glm::vec3 off = o.velocity * frame;
    float t = kInf;
    glm::vec3 n(0.0f);
    if (o.kind == SynthObject::Kind::Plane) {
        const float den = glm::dot(dir, o.b);
        if (std::abs(den) > 1e-9f) {
            t = glm::dot(o.a + off - org, o.b) / den;
            n = o.b;
        }
    } else if (o.kind == SynthObject::Kind::Sphere) {
        const glm::vec3 oc = org - (o.a + off);
        const float r = o.b.x;
        const float bq = glm::dot(oc, dir), cq = glm::dot(oc, oc) - r * r;
        const float disc = bq * bq - cq;
        if (disc >= 0.0f) {
            const float sq = std::sqrt(disc);
            t = -bq - sq;
            if (t <= tMin) t = -bq + sq;
            n = glm::normalize(oc + t * dir);
        }
    } else {
        const glm::vec3 lo = o.a + off, hi = o.b + off;
        float t0 = -kInf, t1 = kInf;
        int axis0 = 0, axis1 = 0;
        for (int k = 0; k < 3; ++k) {
            const float inv = 1.0f / dir[k];
            float ta = (lo[k] - org[k]) * inv, tb = (hi[k] - org[k]) * inv;
            if (ta > tb) std::swap(ta, tb);
            if (ta > t0) t0 = ta, axis0 = k;
            if (tb < t1) t1 = tb, axis1 = k;
        }
        if (t0 <= t1) {
            const bool inside = t0 <= tMin;
            t = inside ? t1 : t0;
            const int ax = inside ? axis1 : axis0;
            n = glm::vec3(0.0f);
            n[ax] = dir[ax] > 0.0f ? -1.0f : 1.0f;
            if (inside) n = -n;
        }
    }
    if (t > tMin && t < h->t) {
        h->t = t, h->obj = index, h->p = org + t * dir;
        h->n = glm::dot(n, dir) > 0.0f ? -n : n;  // facing the ray
    }
}

inline Hit Trace(const SynthScene& sc, float frame, glm::vec3 org, glm::vec3 dir,
                 float tMin = 1e-4f) {
    Hit h;
    for (size_t k = 0; k < sc.objects.size(); ++k)
        Intersect(sc.objects[k], frame, org, dir, tMin, &h, int(k));
    return h;
}

inline float Roughness(const SynthObject& o, glm::vec3 p, float frame) {
    if (o.roughness2 < 0.0f) return o.roughness;
    const glm::vec3 q = p - o.velocity * frame;  // texture moves with the object
    const int cx = int(std::floor(q.x / o.checkerPeriod)),
              cz = int(std::floor(q.z / o.checkerPeriod));
    return ((cx + cz) & 1) ? o.roughness2 : o.roughness;
}

// GGX pieces (the renderer's: height-correlated Smith, Schlick Fresnel).
inline float Lambda(float c, float a) {
    const float c2 = std::max(c * c, 1e-12f);
    return 0.5f * (std::sqrt(1.0f + a * a * std::max(0.0f, 1.0f - c2) / c2) - 1.0f);
}
inline glm::vec3 SampleVndf(glm::vec3 wo, float a, float u1, float u2) {
    return GgxSampleVisibleNormal(wo, a, glm::vec2(u1, u2));
}

}  // namespace synth

/// The camera of frame `frame`.
inline screen::FrameCamera SynthCamera(const SynthScene& sc, float frame) {
    screen::FrameCamera cam;
    const glm::vec3 eye = sc.eye + sc.eyeVelocity * frame;
    const glm::vec3 target = sc.target + sc.eyeVelocity * frame;
    const glm::mat4 view = glm::lookAt(eye, target, glm::vec3(0.0f, 1.0f, 0.0f));
    const glm::mat4 proj =
        glm::perspective(sc.fovY, float(sc.width) / float(sc.height), 0.05f, 1000.0f);
    cam.worldToClip = proj * view;
    cam.position = eye;
    cam.width = sc.width, cam.height = sc.height;
    return cam;
}

/// Renders frame `frame` with `spp` samples per pixel averaged (spp > 1 approaches the noise-free
/// components; the motion-vector inputs are those of the first sample).
inline FrameBuffers SynthRender(const SynthScene& sc, int frame, uint32_t seed, int spp = 1) {
    using namespace synth;
    FrameBuffers f;
    const int w = sc.width, h = sc.height;
    const size_t n = size_t(w) * size_t(h);
    f.width = w, f.height = h;
    f.camera = SynthCamera(sc, float(frame));
    f.time = float(frame) / 30.0f;
    const glm::vec3 nanv(kNaNf);
    f.emitted.assign(n, glm::vec3(0.0f));
    f.shading.assign(n, glm::vec3(0.0f));
    f.visibility.assign(n, 0.0f);
    if (sc.glossy) f.glossy.assign(n, glm::vec3(0.0f));
    if (sc.indirect) f.indirect.assign(n, glm::vec3(0.0f));
    f.position.assign(n, nanv), f.normal.assign(n, nanv);
    f.depth.assign(n, kInf), f.roughness.assign(n, 0.0f);
    f.albedo.assign(n, glm::vec3(0.0f)), f.specular.assign(n, glm::vec3(0.0f));
    f.objectId.assign(n, -1);
    f.prevPosition.assign(n, nanv), f.prevNormal.assign(n, nanv);
    f.blocker.assign(n, nanv), f.prevBlocker.assign(n, nanv);
    f.lightSample.assign(n, nanv), f.prevLightSample.assign(n, nanv);
    f.glossyHit.assign(n, nanv), f.prevGlossyHit.assign(n, nanv);
    if (sc.cones && sc.indirect) f.cones.assign(n * screen::kNumCones, glm::vec3(0.0f));
    const glm::mat4 inv = glm::inverse(f.camera.worldToClip);
    const float fr = float(frame);
    const glm::vec3 light = sc.light + sc.lightVelocity * fr;

    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4), [&](const tbb::blocked_range<int>& rows) {
        for (int y = rows.begin(); y < rows.end(); ++y)
            for (int x = 0; x < w; ++x) {
                const size_t i = size_t(y) * size_t(w) + size_t(x);
                const glm::vec2 ndc((float(x) + 0.5f) / float(w) * 2.0f - 1.0f,
                                    1.0f - (float(y) + 0.5f) / float(h) * 2.0f);
                glm::vec4 a = inv * glm::vec4(ndc, -1.0f, 1.0f),
                          b = inv * glm::vec4(ndc, 1.0f, 1.0f);
                const glm::vec3 org = f.camera.position;
                const glm::vec3 dir = glm::normalize(glm::vec3(b) / b.w - glm::vec3(a) / a.w);
                const Hit hit = Trace(sc, fr, org, dir, 0.0f);
                if (hit.obj < 0) {
                    f.emitted[i] = Sky(sc, dir);
                    continue;
                }
                const SynthObject& o = sc.objects[size_t(hit.obj)];
                const glm::vec3 p = hit.p, nrm = hit.n;
                f.position[i] = p, f.normal[i] = nrm, f.depth[i] = hit.t;
                f.objectId[i] = o.id, f.albedo[i] = o.albedo, f.specular[i] = o.f0;
                const float rough = Roughness(o, p, fr);
                f.roughness[i] = glm::length(o.f0) > 0.0f ? rough : 0.0f;
                f.prevPosition[i] = p - o.velocity, f.prevNormal[i] = nrm;
                const bool isGlossy = glm::length(o.f0) > 0.0f;
                glm::vec3 shading(0.0f), gl(0.0f), ind(0.0f);
                float vis = 0.0f;
                glm::vec3 cones[screen::kNumCones] = {};
                const auto axes = screen::ConeAxes(nrm);
                glm::vec3 t1, t2;
                screen::ConeFrame(nrm, &t1, &t2);
                const glm::vec3 wo = -dir;
                const glm::vec3 wol(glm::dot(wo, t1), glm::dot(wo, t2), glm::dot(wo, nrm));
                for (int s = 0; s < spp; ++s) {
                    Rng rng(uint32_t(i) * 9781u + uint32_t(frame) * 6271u + seed * 7919u +
                            uint32_t(s) * 104729u);
                    // Direct light: one sample on the light's sphere (a point when radius 0).
                    glm::vec3 ls = light;
                    if (sc.lightRadius > 0.0f) {
                        const float z = 1.0f - 2.0f * rng.Uniform(),
                                    ph = 2.0f * kPi * rng.Uniform();
                        const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
                        ls += sc.lightRadius * glm::vec3(r * std::cos(ph), r * std::sin(ph), z);
                    }
                    const glm::vec3 tol = ls - p;
                    const float dist = glm::length(tol);
                    const glm::vec3 wl = tol / dist;
                    const float cosl = std::max(0.0f, glm::dot(nrm, wl));
                    if (!isGlossy)
                        shading += o.albedo / kPi * sc.lightIntensity * cosl / (dist * dist);
                    const Hit sh = Trace(sc, fr, p + 1e-4f * nrm, wl);
                    const bool blocked = sh.obj >= 0 && sh.t < dist - 1e-4f;
                    vis += blocked ? 0.0f : 1.0f;
                    if (s == 0) {
                        f.lightSample[i] = ls, f.prevLightSample[i] = ls - sc.lightVelocity;
                        if (blocked) {
                            f.blocker[i] = sh.p;
                            f.prevBlocker[i] = sh.p - sc.objects[size_t(sh.obj)].velocity;
                        }
                    }
                    if (isGlossy && sc.glossy) {
                        const glm::vec3 m =
                            SampleVndf(wol, std::max(rough, 1e-3f), rng.Uniform(), rng.Uniform());
                        const glm::vec3 wil = 2.0f * glm::dot(wol, m) * m - wol;
                        if (wil.z > 0.0f) {
                            const glm::vec3 wi = wil.x * t1 + wil.y * t2 + wil.z * nrm;
                            const Hit gh = Trace(sc, fr, p + 1e-4f * nrm, wi);
                            const glm::vec3 L = gh.obj >= 0 ? sc.objects[size_t(gh.obj)].albedo *
                                                                  sc.objects[size_t(gh.obj)].ambient
                                                            : Sky(sc, wi);
                            const float a = std::max(rough, 1e-3f);
                            const float lo = Lambda(wol.z, a), li = Lambda(wil.z, a);
                            const float g = (1.0f + lo) / (1.0f + lo + li);
                            const float om = std::max(0.0f, glm::dot(wol, m));
                            const float fc = std::pow(1.0f - om, 5.0f);
                            gl += (o.f0 + (1.0f - o.f0) * fc) * g * L;
                            if (s == 0 && gh.obj >= 0) {
                                f.glossyHit[i] = gh.p;
                                f.prevGlossyHit[i] = gh.p - sc.objects[size_t(gh.obj)].velocity;
                            }
                        }
                    }
                    if (!isGlossy && sc.indirect) {
                        const float u1 = rng.Uniform(), u2 = rng.Uniform();
                        const float r = std::sqrt(u1), ph = 2.0f * kPi * u2;
                        const glm::vec3 wi = r * std::cos(ph) * t1 + r * std::sin(ph) * t2 +
                                             std::sqrt(std::max(0.0f, 1.0f - u1)) * nrm;
                        const Hit ih = Trace(sc, fr, p + 1e-4f * nrm, wi);
                        const glm::vec3 L = ih.obj >= 0 ? sc.objects[size_t(ih.obj)].albedo *
                                                              sc.objects[size_t(ih.obj)].ambient
                                                        : Sky(sc, wi);
                        ind += o.albedo * L;
                        screen::AddConeSample(axes, wi, L, cones);
                    }
                }
                const float inv = 1.0f / float(spp);
                f.shading[i] = shading * inv;
                f.visibility[i] = vis * inv;
                if (sc.glossy) f.glossy[i] = gl * inv;
                if (sc.indirect) f.indirect[i] = ind * inv;
                if (!f.cones.empty())
                    for (int k = 0; k < screen::kNumCones; ++k)
                        f.cones[i * screen::kNumCones + size_t(k)] = cones[k] * inv;
            }
    });
    return f;
}

/// RMSE between two images over the pixels where `mask` (if given) is true.
inline double Rmse(const std::vector<glm::vec3>& a, const std::vector<glm::vec3>& b,
                   const std::vector<char>* mask = nullptr) {
    double s = 0.0;
    size_t n = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        if (mask && !(*mask)[i]) continue;
        const glm::vec3 d = a[i] - b[i];
        s += double(glm::dot(d, d)) / 3.0, ++n;
    }
    return n ? std::sqrt(s / double(n)) : 0.0;
}
inline double Rmse(const std::vector<float>& a, const std::vector<float>& b,
                   const std::vector<char>* mask = nullptr) {
    double s = 0.0;
    size_t n = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        if (mask && !(*mask)[i]) continue;
        const double d = double(a[i]) - double(b[i]);
        s += d * d, ++n;
    }
    return n ? std::sqrt(s / double(n)) : 0.0;
}

}  // namespace texcache::test
