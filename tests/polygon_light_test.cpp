// SPDX-License-Identifier: Apache-2.0
// The projected solid angle of a polygonal light (renderer/integrators/polygon_light.h), which
// gives the frame buffers' unshadowed shading in closed form.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>

#include "renderer/integrators/polygon_light.h"
#include "renderer/integrators/sampling.h"

namespace texcache {
namespace {

// Lambert's formula (renderer/integrators/polygon_light.h): a quad covering the sky gives pi, a
// small one straight above its area over the squared distance, either winding the same, one wholly
// below the tangent plane 0, and a tilted quad crossing the plane what 400k cosine-distributed
// directions find (the fraction hitting it, times pi; standard error ~0.1% of the value).
TEST(PolygonLight, ProjectedSolidAngleMatchesKnownValuesAndSampling) {
    // The edge factor's fit against theta / (2 pi sin theta) (relative error ~1.5e-6; 1e-5).
    for (int i = 1; i < 2000; ++i) {
        const double x = -1.0 + 2.0 * i / 2000.0, theta = std::acos(x);
        const double exact = theta / (2.0 * 3.14159265358979 * std::sin(theta));
        EXPECT_NEAR(EdgeFactor(float(x)), exact, 1e-5 * exact) << x;
    }
    const glm::vec3 n(0.0f, 0.0f, 1.0f);
    auto quad = [](glm::vec3 c, glm::vec3 e1, glm::vec3 e2) {
        return std::array<glm::vec3, 4>{c, c + e1, c + e1 + e2, c + e2};
    };
    const auto sky = quad({-1e4f, -1e4f, 1.0f}, {2e4f, 0, 0}, {0, 2e4f, 0});
    EXPECT_NEAR(PolygonProjectedSolidAngle(sky.data(), 4, n), 3.14159f, 1e-3f);
    const auto small = quad({-0.01f, -0.01f, 2.0f}, {0.02f, 0, 0}, {0, 0.02f, 0});
    EXPECT_NEAR(PolygonProjectedSolidAngle(small.data(), 4, n), 0.0004f / 4.0f, 1e-6f);
    const auto reversed = quad({-0.01f, -0.01f, 2.0f}, {0, 0.02f, 0}, {0.02f, 0, 0});
    EXPECT_FLOAT_EQ(PolygonProjectedSolidAngle(reversed.data(), 4, n),
                    PolygonProjectedSolidAngle(small.data(), 4, n));
    const auto below = quad({-1, -1, -0.5f}, {2, 0, 0}, {0, 2, 0});
    EXPECT_EQ(PolygonProjectedSolidAngle(below.data(), 4, n), 0.0f);
    EXPECT_EQ(PolygonProjectedSolidAngle(below.data(), 2, n), 0.0f);
    // Tilted, from z = -0.6 to z = 0.9: the tangent plane cuts it.
    const glm::vec3 c(0.3f, -0.5f, -0.6f), e1(0.0f, 1.0f, 0.0f), e2(0.4f, 0.2f, 1.5f);
    const auto crossing = quad(c, e1, e2);
    const float closed = PolygonProjectedSolidAngle(crossing.data(), 4, n);
    const glm::vec3 qn = glm::normalize(glm::cross(e1, e2));
    const int kSamples = 400000;
    int hits = 0;
    for (int i = 0; i < kSamples; ++i) {
        // The Hammersley set: i / N and the base-2 radical inverse of i.
        uint32_t r = uint32_t(i);
        r = (r << 16) | (r >> 16);
        r = ((r & 0x55555555u) << 1) | ((r & 0xAAAAAAAAu) >> 1);
        r = ((r & 0x33333333u) << 2) | ((r & 0xCCCCCCCCu) >> 2);
        r = ((r & 0x0F0F0F0Fu) << 4) | ((r & 0xF0F0F0F0u) >> 4);
        r = ((r & 0x00FF00FFu) << 8) | ((r & 0xFF00FF00u) >> 8);
        const glm::vec2 u((float(i) + 0.5f) / kSamples, float(r) * 2.3283064e-10f);
        const glm::vec3 w = SampleCosineHemisphere(u);
        const float t = glm::dot(qn, c) / glm::dot(qn, w);
        if (!(t > 0.0f)) continue;
        const glm::vec3 x = t * w - c;
        // x = a e1 + b e2 (e1 . e2 = 0.2: solve the 2x2 normal equations).
        const float g11 = glm::dot(e1, e1), g12 = glm::dot(e1, e2), g22 = glm::dot(e2, e2);
        const float r1 = glm::dot(x, e1), r2 = glm::dot(x, e2), det = g11 * g22 - g12 * g12;
        const float a = (r1 * g22 - r2 * g12) / det, b = (r2 * g11 - r1 * g12) / det;
        hits += a >= 0.0f && a <= 1.0f && b >= 0.0f && b <= 1.0f;
    }
    const float sampled = 3.14159265f * float(hits) / float(kSamples);
    EXPECT_GT(closed, 0.1f);
    EXPECT_NEAR(closed, sampled, 0.005f * sampled);
}

}  // namespace
}  // namespace texcache
