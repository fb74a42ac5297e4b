// SPDX-License-Identifier: Apache-2.0
// The lights beyond quads and the environment, posed at a frame's time, each with what next-event
// estimation and MIS need of it: a sample towards a shading point, and for a light that rays can
// hit, its radiance and the sample's density there.
//   SphereLight  point and spot lights: a sphere of uniform radiance, sampled by the cone of
//                directions it fills (uniform over the visible cap's solid angle), or a delta
//                light when its radius is 0;
//   SunDisc      a distant light of angular size: a disc of uniform radiance at infinity, the
//                same cone sampling (an angular size of 0 stays a delta light);
//   MeshEmitter  an object with an emission: the triangles of its Embree quads, sampled by area.
// Pure geometry, no Embree: the path tracer's Context (path_tracer.h) picks among them. Internal
// to renderer/.
#pragma once
#include <cmath>
#include <vector>

#include <glm/glm.hpp>

#include "renderer/integrators/distribution.h"
#include "renderer/integrators/sampling.h"
#include "renderer/scene/scene.h"

namespace texcache::internal {

/// A sample of a light seen from a point: the direction towards it, the distance to the point
/// sampled (infinite at infinity), the radiance arriving along wi, and the solid-angle density of
/// wi (0 for a delta light, whose Li is then the irradiance on a surface facing it).
struct LightPoint {
    glm::vec3 wi{0.0f};
    float dist = 0.0f;
    glm::vec3 Li{0.0f};
    float pdf = 0.0f;
};

/// The unit direction `wi` and distance `dist` from p to x; false when they coincide.
inline bool Towards(glm::vec3 p, glm::vec3 x, glm::vec3* wi, float* dist) {
    const glm::vec3 d = x - p;
    const float d2 = glm::dot(d, d);
    if (!(d2 > 0.0f)) return false;
    *dist = std::sqrt(d2);
    *wi = d / *dist;
    return true;
}

/// A direction uniform over the cone about f.n whose 1 - cos of its half-angle is
/// `oneMinusCosMax` (given as such: 1 - cos cancels in float for the sun's quarter degree); its
/// solid-angle density is 1 / (2 pi oneMinusCosMax). `cosTheta` and `sin2Theta` of the direction
/// to the axis, for callers that need them.
inline glm::vec3 SampleCone(const Frame& f, float oneMinusCosMax, glm::vec2 u, float* cosTheta,
                            float* sin2Theta) {
    const float omc = u.x * oneMinusCosMax;  // 1 - cos(theta), uniform in [0, oneMinusCosMax)
    *cosTheta = 1.0f - omc;
    *sin2Theta = std::max(0.0f, omc * (2.0f - omc));
    const float sinTheta = std::sqrt(*sin2Theta), phi = 2.0f * kPiF * u.y;
    return f.FromLocal(glm::vec3(sinTheta * std::cos(phi), sinTheta * std::sin(phi), *cosTheta));
}

/// A point or spot light at a frame's time (PointLight in world space).
struct SphereLight {
    glm::vec3 center{0.0f};
    float radius = 0.0f;
    glm::vec3 intensity{0.0f};  ///< W/sr, on the axis for a spot
    glm::vec3 radiance{0.0f};   ///< intensity / (pi radius^2); unused when radius is 0
    bool spot = false;
    glm::vec3 axis{0.0f, -1.0f, 0.0f};
    float cosInner = 1.0f, cosOuter = 1.0f;

    SphereLight() = default;
    SphereLight(const PointLight& p, const glm::mat4& toWorld);

    bool IsDelta() const { return radius <= 0.0f; }
    /// The spot's falloff for light leaving along `w` (unit, away from the light): 1 inside the
    /// inner cone, 0 outside the outer one, a smoothstep in cos between; 1 for a point light.
    float Falloff(glm::vec3 w) const {
        if (!spot) return 1.0f;
        const float c = glm::dot(w, axis);
        if (c >= cosInner) return 1.0f;
        if (c <= cosOuter) return 0.0f;
        const float t = (c - cosOuter) / (cosInner - cosOuter);
        return t * t * (3.0f - 2.0f * t);
    }
    /// A sample for the point p: the sphere's visible cap by its cone of directions, or the
    /// centre of a delta light; false inside the sphere (it emits outwards only) or where the
    /// spot sends nothing.
    bool Sample(glm::vec3 p, glm::vec2 u, LightPoint* s) const;
    /// The solid-angle density of Sample(o, ...) for any direction that meets the sphere: the
    /// MIS partner of a ray from o that hit it. 0 inside it.
    float Pdf(glm::vec3 o) const;
    /// Radiance a ray from `o` along `dir` receives where it hits the sphere (0 from inside).
    glm::vec3 Emission(glm::vec3 o, glm::vec3 dir) const {
        const glm::vec3 d = o - center;
        if (!(glm::dot(d, d) > radius * radius)) return glm::vec3(0.0f);
        return radiance * Falloff(-dir);
    }
};

/// A distant light of angular size (DistantLight with angleDegrees > 0) at a frame's time.
struct SunDisc {
    Frame frame;                  ///< frame.n: towards the light
    float oneMinusCosMax = 0.0f;  ///< of the half-angle; 0 for a delta light
    glm::vec3 radiance{0.0f};     ///< irradiance / (pi sin^2 halfAngle): a facing surface gets it

    SunDisc() = default;
    /// `towards`: unit direction towards the light; `irradiance` on a surface facing it.
    SunDisc(glm::vec3 towards, glm::vec3 irradiance, float angleDegrees);

    bool IsDelta() const { return !(oneMinusCosMax > 0.0f); }
    float Pdf() const { return 1.0f / (2.0f * kPiF * oneMinusCosMax); }
    /// Whether a direction lies within the disc.
    bool Contains(glm::vec3 dir) const { return 1.0f - glm::dot(dir, frame.n) <= oneMinusCosMax; }
    /// A direction within the disc.
    glm::vec3 Sample(glm::vec2 u) const {
        float c, s2;
        return SampleCone(frame, oneMinusCosMax, u, &c, &s2);
    }
};

/// An emissive object at a frame's time: the triangles of its Embree quads (two per quad, split
/// as Embree splits them: corners 0,1,3 and 2,3,1), picked in proportion to their area and
/// sampled uniformly, so that every point of the surface has the density 1 / area. The surface
/// sampled is the surface rays hit (plain meshes' polygons, a subdivision surface's limit
/// tessellation: RenderScene renders emissive subdivision objects as such), so a shadow ray
/// ends exactly on it, and the density of a point a BSDF ray finds is exactly what Sample gives.
class MeshEmitter {
public:
    /// `corners`: 4 world-space corners per Embree quad, in primitive order.
    MeshEmitter(int object, const std::vector<glm::vec3>& corners, glm::vec3 radiance,
                bool twoSided);

    int Object() const { return object_; }
    float Area() const { return area_; }
    glm::vec3 Radiance() const { return radiance_; }
    /// A point uniform over the surface seen from p; false for a point that emits nothing
    /// towards p (its back, one-sided) or coincides with p.
    bool Sample(glm::vec3 p, glm::vec2 u, LightPoint* s) const;
    /// The triangle a hit on quad `prim` at Embree's (u,v) lies in.
    static int Triangle(unsigned prim, float u, float v) {
        return int(2 * prim) + (u + v > 1.0f ? 1 : 0);
    }
    /// Radiance a ray along `dir` receives where it hits triangle `tri`.
    glm::vec3 Emission(int tri, glm::vec3 dir) const {
        return twoSided_ || glm::dot(normal_[size_t(tri)], dir) < 0.0f ? radiance_
                                                                       : glm::vec3(0.0f);
    }
    /// The solid-angle density of Sample for a ray that hit triangle `tri` after `t` along
    /// `dir` (unit): t^2 / (area |cos|), without the light's pick probability.
    float Pdf(int tri, glm::vec3 dir, float t) const {
        const float c = std::abs(glm::dot(normal_[size_t(tri)], dir));
        return c > 0.0f ? t * t / (area_ * c) : 0.0f;
    }

private:
    int object_;
    glm::vec3 radiance_;
    bool twoSided_;
    float area_ = 0.0f;
    std::vector<glm::vec3> vertex_;  ///< 3 per triangle
    std::vector<glm::vec3> normal_;  ///< unit, along the winding's normal (the front)
    Distribution1D pick_;            ///< triangles by area
};

}  // namespace texcache::internal
