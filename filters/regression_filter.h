// SPDX-License-Identifier: Apache-2.0
// Linear regression in texture space (Munkberg et al. 2016, Sec. 6.1, after Moon et al.'s ARLP):
// a first-order model f(x_i) ~ f(x_c) + grad f . (x_i - x_c) over features x = (quantized patch
// offset, surface normal[, roughness]), fitted on square rings k = 0..R around the centre texel by
// recursive least squares; the ring with the smallest estimated error wins.
#pragma once
#include <cstdint>

#include <glm/glm.hpp>

#include "filters/texture_filters.h"

namespace texcache {

/// What one reconstruction did (for tests and statistics).
struct RegressionInfo {
    int rank = 0;           ///< dimension of the truncated feature space (0..6)
    int ring = 0;           ///< chosen model: rings 0..ring, i.e. (2 ring + 1)^2 texels
    int rejected = 0;       ///< taps dropped for non-finite values, normals or variances
    bool fallback = false;  ///< the centre was unusable: a normal-weighted mean was returned
};

/// The regression filter. Plug into ShadingCache::Lookup as the filter; the footprint radius R
/// (the paper's 17x17 gather is R = 8) bounds the rings.
struct RegressionFilter {
    /// Rays per cached sample (n in the k = 0 blend beta = clamp(1 - n/256, 0, 1)).
    int samplesPerTexel = 1;
    /// Use ShadedSample::roughness as a sixth feature (materials whose roughness varies).
    bool roughnessFeature = false;

    glm::vec3 operator()(const FilterInput<ShadedSample>& in) const {
        return Reconstruct(in, nullptr);
    }
    /// The filtered value; `info` (optional) says how it was obtained. Never NaN or negative.
    glm::vec3 Reconstruct(const FilterInput<ShadedSample>& in, RegressionInfo* info) const;
};

}  // namespace texcache
