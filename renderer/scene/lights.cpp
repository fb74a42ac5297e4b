// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/lights.h"

#include <algorithm>

namespace texcache::internal {

SphereLight::SphereLight(const PointLight& p, const glm::mat4& toWorld)
    : center(toWorld * glm::vec4(p.position, 1.0f)),
      radius(p.radius),
      intensity(p.intensity),
      spot(p.spot) {
    // Pi r^2 L: the intensity of a sphere of radiance L, in any direction.
    if (radius > 0.0f) radiance = intensity / (kPiF * radius * radius);
    if (spot) {
        axis = glm::normalize(glm::mat3(toWorld) * p.direction);
        cosInner = std::cos(glm::radians(p.innerDegrees));
        cosOuter = std::cos(glm::radians(p.outerDegrees));
    }
}

bool SphereLight::Sample(glm::vec3 p, glm::vec2 u, LightPoint* s) const {
    const glm::vec3 d = center - p;
    const float d2 = glm::dot(d, d);
    if (!(d2 > radius * radius)) return false;  // inside, or on a delta light's centre
    const float dist = std::sqrt(d2);
    const glm::vec3 wc = d / dist;
    if (IsDelta()) {
        s->wi = wc;
        s->dist = dist;
        s->Li = intensity * (Falloff(-wc) / d2);
        s->pdf = 0.0f;
        return s->Li != glm::vec3(0.0f);
    }
    // The cone of directions that meet the sphere: sin^2 of its half-angle is r^2 / d^2.
    const float sin2Max = radius * radius / d2;
    const float cosMax = std::sqrt(std::max(0.0f, 1.0f - sin2Max));
    const float oneMinusCosMax = sin2Max / (1.0f + cosMax);
    float cosTheta, sin2Theta;
    s->wi = SampleCone(Frame::FromZ(wc), oneMinusCosMax, u, &cosTheta, &sin2Theta);
    // The nearer of the ray's two intersections with the sphere.
    s->dist = dist * cosTheta - std::sqrt(std::max(0.0f, radius * radius - d2 * sin2Theta));
    s->Li = radiance * Falloff(-s->wi);
    s->pdf = 1.0f / (2.0f * kPiF * oneMinusCosMax);
    return s->Li != glm::vec3(0.0f) && std::isfinite(s->pdf);
}

float SphereLight::Pdf(glm::vec3 o) const {
    const glm::vec3 d = center - o;
    const float d2 = glm::dot(d, d);
    if (IsDelta() || !(d2 > radius * radius)) return 0.0f;
    const float sin2Max = radius * radius / d2;
    const float cosMax = std::sqrt(std::max(0.0f, 1.0f - sin2Max));
    return (1.0f + cosMax) / (2.0f * kPiF * sin2Max);
}

SunDisc::SunDisc(glm::vec3 towards, glm::vec3 irradiance, float angleDegrees)
    : frame(Frame::FromZ(towards)) {
    const float half = 0.5f * glm::radians(angleDegrees);
    if (!(half > 0.0f)) return;
    const float s = std::sin(0.5f * half);
    oneMinusCosMax = 2.0f * s * s;
    // A surface facing a disc of radiance L that spans the half-angle a receives pi L sin^2 a.
    radiance = irradiance / (kPiF * std::sin(half) * std::sin(half));
}

MeshEmitter::MeshEmitter(int object, const std::vector<glm::vec3>& corners, glm::vec3 radiance,
                         bool twoSided)
    : object_(object), radiance_(radiance), twoSided_(twoSided) {
    const size_t quads = corners.size() / 4;
    vertex_.reserve(6 * quads);
    normal_.reserve(2 * quads);
    std::vector<float> areas;
    areas.reserve(2 * quads);
    double total = 0.0;
    auto add = [&](glm::vec3 a, glm::vec3 b, glm::vec3 c) {
        const glm::vec3 n = glm::cross(b - a, c - a);
        const float twice = glm::length(n);
        vertex_.insert(vertex_.end(), {a, b, c});
        const bool ok = twice > 0.0f && std::isfinite(twice);
        normal_.push_back(ok ? n / twice : glm::vec3(0.0f));
        areas.push_back(ok ? 0.5f * twice : 0.0f);
        total += ok ? 0.5 * double(twice) : 0.0;
    };
    for (size_t q = 0; q < quads; ++q) {
        const glm::vec3* c = &corners[4 * q];
        add(c[0], c[1], c[3]);
        add(c[2], c[3], c[1]);
    }
    area_ = float(total);
    pick_ = Distribution1D(areas);
}

bool MeshEmitter::Sample(glm::vec3 p, glm::vec2 u, LightPoint* s) const {
    if (!(area_ > 0.0f)) return false;
    float pdf;
    int tri;
    const float x = pick_.Sample(u.x, &pdf, &tri);
    // The pick's leftover: uniform in [0, 1) and independent of the triangle picked.
    const float ux = std::clamp(x * float(pick_.Count()) - float(tri), 0.0f, kOneMinusEpsilon);
    const float su = std::sqrt(ux);
    const float b0 = 1.0f - su, b1 = u.y * su;
    const glm::vec3* v = &vertex_[3 * size_t(tri)];
    if (!Towards(p, b0 * v[0] + b1 * v[1] + (1.0f - b0 - b1) * v[2], &s->wi, &s->dist))
        return false;
    s->Li = Emission(tri, s->wi);
    s->pdf = Pdf(tri, s->wi, s->dist);
    return s->Li != glm::vec3(0.0f) && s->pdf > 0.0f && std::isfinite(s->pdf);
}

}  // namespace texcache::internal
