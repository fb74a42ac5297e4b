// SPDX-License-Identifier: Apache-2.0
// Closed-form light from a uniformly emitting polygon onto a Lambertian surface (Lambert 1760;
// Arvo 1995, "Applications of irradiance tensors"): the cosine-weighted solid angle
//     I = int_{polygon, n.w > 0} (n . w) dw = 1/2 sum_edges theta_i (n . g_i),
// theta_i the angle an edge subtends, g_i the unit normal of the plane through the edge and the
// shading point. The polygon is first clipped to the hemisphere about n (Sutherland-Hodgman
// against the tangent plane), as the surface sees nothing below it. The frame buffers' `shading`
// uses it for the diffuse lobe under quad lights instead of Monte Carlo light samples.
#pragma once
#include <algorithm>
#include <cmath>

#include <glm/glm.hpp>

namespace texcache {

/// theta / (2 pi sin theta) for the angle theta between two unit vectors whose dot product is x:
/// Hill and Heitz's rational fit ("Real-time area lighting: a journey from research to
/// production", SIGGRAPH 2016 course; relative error ~1.5e-6 over [-1, 1), checked against
/// acos), for x < 0 through theta / sin = pi / sin - (pi - theta) / sin(pi - theta). It replaces
/// an atan2 per edge, which with the clipping is a visible share of the preview bench's profile.
inline float EdgeFactor(float x) {
    const float y = std::abs(x);
    const float a = 0.8543985f + (0.4965155f + 0.0145206f * y) * y;
    const float b = 3.4175940f + (4.1616724f + y) * y;
    const float v = a / b;
    return x > 0.0f ? v : 0.5f / std::sqrt(std::max(1.0f - x * x, 1e-7f)) - v;
}

/// int max(0, n.w) dw over the directions of the convex polygon `v` (count <= 8 vertices, given
/// relative to the shading point, either winding), n unit: in [0, pi]. 0 for fewer than three
/// vertices or a polygon wholly below the tangent plane.
inline float PolygonProjectedSolidAngle(const glm::vec3* v, int count, glm::vec3 n) {
    constexpr int kMax = 9;  // a clipped 8-gon gains at most one vertex
    if (count < 3 || count > kMax - 1) return 0.0f;
    glm::vec3 c[kMax];
    int m = 0;
    for (int i = 0; i < count; ++i) {
        const glm::vec3 a = v[i], b = v[(i + 1) % count];
        const float da = glm::dot(n, a), db = glm::dot(n, b);
        if (da >= 0.0f) c[m++] = a;
        if ((da >= 0.0f) != (db >= 0.0f)) c[m++] = a + (b - a) * (da / (da - db));
    }
    if (m < 3) return 0.0f;
    // sum of theta_i (n . g_i) / (2 pi), with n . (a x b) = sin(theta_i) (n . g_i).
    float sum = 0.0f;
    glm::vec3 a = c[m - 1] / glm::length(c[m - 1]);
    for (int i = 0; i < m; ++i) {
        const float len = glm::length(c[i]);
        if (!(len > 0.0f)) return 0.0f;  // the point lies on the polygon's outline
        const glm::vec3 b = c[i] / len;
        sum += glm::dot(n, glm::cross(a, b)) * EdgeFactor(glm::dot(a, b));
        a = b;
    }
    return std::min(3.14159265f * std::abs(sum), 3.14159265f);
}

}  // namespace texcache
