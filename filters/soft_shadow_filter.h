// SPDX-License-Identifier: Apache-2.0
// The axis-aligned soft-shadow filter of Mehta et al. 2012, applied in texture space to the
// visibility term of area-light direct lighting (Munkberg et al. 2016, Sec. 6.1 "Soft Shadows").
//
// Formulas. A shadow ray from receiver x to light point y, of length d, hits its first occluder at
// distance t. With d1 = d (light to receiver) and d2 = d - t (light to occluder), the occluder's
// slope is s = d1 / d2 - 1 = t / (d - t). Visibility V(x, y) = g(x d2/d1 + y (1 - d2/d1)) has its
// spectrum on the line Omega_x = Omega_y / s; a light of world-space standard deviation sigma_l
// (a Gaussian fit to the emitter: a uniform a x b rectangle has sigma_l = sqrt(a b / 12)) limits
// Omega_y to 1 / sigma_l, so V over x is band-limited to Omega_x = 1 / (sigma_l s). The
// axis-aligned filter that keeps the widest such band is a Gaussian on the receiver with
//   beta = sigma_l * s_min   (world units),  s_min = smallest slope among the occluders seen,
// which the sample shader stores per sample in texels of its own grid, beta / texelSize, as
// ShadedSample::blurTexels (inf when no shadow ray was blocked; the texels of neighbouring faces
// have about the same world size, see MeshGrids). As Mehta et al. do for pixels with no occluded
// sample of their own, a texel takes the smallest blur over a small window (radius 2) around it;
// with no occluder anywhere there the light is unblocked and any width is right, so the widest is
// used. The width is clamped to [0.5, R / 2] texels so that the Gaussian fits the footprint of
// radius R. Taps whose normal differs
// from the centre's (cos <= cosThreshold) are skipped like the normal filter's.
#pragma once
#include <algorithm>
#include <cmath>

#include "filters/texture_filters.h"

namespace texcache {

struct SoftShadowFilter {
    float cosThreshold = 0.9f;
    int slopeWindow = 2;  ///< radius of the window s_min is taken over

    glm::vec3 operator()(const FilterInput<ShadedSample>& in) const {
        const ShadedSample& c = in.samples[in.centre];
        int R = 0;
        float blur = INFINITY;
        for (size_t i = 0; i < in.samples.size(); ++i) {
            const FootprintSample& t = in.taps[i];
            R = std::max({R, std::abs(t.dx), std::abs(t.dy)});
            if (std::abs(t.dx) <= slopeWindow && std::abs(t.dy) <= slopeWindow &&
                in.samples[i].blurTexels >= 0.0f)  // NaN fails the test: skipped
                blur = std::min(blur, in.samples[i].blurTexels);
        }
        const float maxSigma = std::max(0.5f * float(R), 0.5f);
        float sigma = maxSigma;
        if (std::isfinite(blur)) sigma = std::clamp(blur, 0.5f, maxSigma);
        const float inv2s2 = 1.0f / (2.0f * sigma * sigma);
        const glm::vec3 nc = c.normal;
        glm::vec3 sum(0.0f);
        float wsum = 0.0f;
        for (size_t i = 0; i < in.samples.size(); ++i) {
            const ShadedSample& s = in.samples[i];
            if (int(i) != in.centre && !(glm::dot(s.normal, nc) > cosThreshold)) continue;
            if (!std::isfinite(s.value.x + s.value.y + s.value.z)) continue;
            const float d2 = float(in.taps[i].dx * in.taps[i].dx + in.taps[i].dy * in.taps[i].dy);
            const float w = std::exp(-d2 * inv2s2);
            sum += w * s.value;
            wsum += w;
        }
        return wsum > 0.0f ? sum / wsum : glm::vec3(0.0f);
    }
};

}  // namespace texcache
