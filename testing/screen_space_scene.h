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

#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "renderer/integrators/sampling.h"
#include "screen_space/frame_buffers.h"

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
/// components; the motion-vector inputs are those of the first sample). Defined in
/// screen_space_scene.cpp, which every build compiles optimized: the caster is most of the
/// screen-space tests' time, the more so at the -O0 of the sanitizer builds' test files (glm not
/// inlined).
FrameBuffers SynthRender(const SynthScene& sc, int frame, uint32_t seed, int spp = 1);

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

/// relMSE as renderer/image/metrics.h defines it (Rousselle et al. 2011): per pixel, the sum
/// over R, G, B of (test - ref)^2 / (gray(ref)^2 + 1e-3), averaged over the pixels.
inline double RelMse(const std::vector<glm::vec3>& test, const std::vector<glm::vec3>& ref) {
    double sum = 0.0;
    for (size_t i = 0; i < ref.size(); ++i) {
        const glm::dvec3 r(ref[i]), d = glm::dvec3(test[i]) - r;
        const double g = (r.x + r.y + r.z) / 3.0;
        sum += glm::dot(d, d) / (g * g + 1e-3);
    }
    return sum / double(ref.size());
}

}  // namespace texcache::test
