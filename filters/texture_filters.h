// SPDX-License-Identifier: Apache-2.0
// Texture-space reconstruction filters over a footprint of cached samples (Munkberg et al. 2016,
// Sec. 6.1): plug into ShadingCache::Lookup as the `filter` callable.
#pragma once
#include <cmath>
#include <string>

#include <glm/glm.hpp>

#include "texcache/shading_cache.h"

namespace texcache {

/// What the renderer caches per sample: the shaded term, the noise-free surface normal at the
/// texel centre, and the sample's variance (for filters that estimate error).
struct ShadedSample {
    glm::vec3 value;
    glm::vec3 normal;
    float variance;
};

enum class TextureFilterKind { None, Normal, Gaussian };

/// Parses a filter name; throws InputError listing the valid names.
TextureFilterKind ParseTextureFilter(const std::string& name, const std::string& where);
/// Valid filter names for help texts and errors.
const char* TextureFilterNames();

/// The paper's trivial filter: a box (or Gaussian) window averaging samples whose normals are
/// within the threshold of the centre sample's normal (cos > 0.9 in the paper). Non-finite
/// samples are skipped; the centre sample always counts, so the result is never empty.
struct NormalWeightedFilter {
    float cosThreshold = 0.9f;
    float sigma = 0.0f;  ///< 0: box window; > 0: Gaussian weights exp(-d^2 / (2 sigma^2)) in texels

    glm::vec3 operator()(const FilterInput<ShadedSample>& in) const {
        const glm::vec3 nc = in.samples[in.centre].normal;
        glm::vec3 sum(0.0f);
        float wsum = 0.0f;
        for (size_t i = 0; i < in.samples.size(); ++i) {
            const ShadedSample& s = in.samples[i];
            if (int(i) != in.centre && glm::dot(s.normal, nc) <= cosThreshold) continue;
            if (!std::isfinite(s.value.x + s.value.y + s.value.z)) continue;
            float w = 1.0f;
            if (sigma > 0.0f) {
                const float d2 =
                    float(in.taps[i].dx * in.taps[i].dx + in.taps[i].dy * in.taps[i].dy);
                w = std::exp(-d2 / (2.0f * sigma * sigma));
            }
            sum += w * s.value;
            wsum += w;
        }
        return wsum > 0.0f ? sum / wsum : glm::vec3(0.0f);
    }
};

/// The 1x1 "filter": the centre sample as shaded.
struct CentreFilter {
    glm::vec3 operator()(const FilterInput<ShadedSample>& in) const {
        const glm::vec3 v = in.samples[in.centre].value;
        return std::isfinite(v.x + v.y + v.z) ? v : glm::vec3(0.0f);
    }
};

}  // namespace texcache
