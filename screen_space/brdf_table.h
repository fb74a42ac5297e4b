// SPDX-License-Identifier: Apache-2.0
// BRDF pre-integration (Zhuang et al. 2021, Sec. 4.1, after Karis's split sum): the directional
// albedo of a GGX microfacet lobe with Schlick Fresnel,
//     F_beta(w_o) = int f_r(w_i, w_o) cos(theta_i) dw_i = F0 * A(cos theta_o, alpha) + B(...),
// tabulated as A (the F0 scale) and B (the bias) on a 256 x 256 grid. The denoiser divides the
// glossy component by F_beta before filtering and multiplies it back after (L = F_beta L_W), so
// roughness and F0 maps are not blurred. The BRDF is the renderer's (renderer/integrators/bsdf.h):
// GGX with height-correlated Smith masking-shadowing, alpha = the GGX alpha the frame's `roughness`
// holds.
#pragma once
#include <vector>

#include <glm/glm.hpp>

namespace texcache::screen {

/// The pre-integrated GGX + Schlick table, built once (multithreaded) and read-only after.
class BrdfPreintegration {
public:
    static constexpr int kSize = 256;  ///< entries per axis; axes at i / (kSize - 1)
    static constexpr int kDefaultSamples = 1024;

    /// Builds the table with `samples` visible-normal importance samples (a Hammersley set) per
    /// entry on the TBB pool. Throws InputError when samples < 1.
    explicit BrdfPreintegration(int samples = kDefaultSamples);

    /// (A, B) at (cos theta_o, alpha), bilinear between entries; arguments are clamped to [0, 1].
    glm::vec2 ScaleBias(float cosTheta, float alpha) const;
    /// F_beta = F0 * A + B.
    glm::vec3 Evaluate(glm::vec3 f0, float cosTheta, float alpha) const {
        const glm::vec2 ab = ScaleBias(cosTheta, alpha);
        return f0 * ab.x + ab.y;
    }
    /// The table entry (i = cos index, j = alpha index).
    glm::vec2 Entry(int i, int j) const { return table_[size_t(j) * kSize + i]; }
    /// All entries, alpha-major (entry (i, j) at j * kSize + i).
    const glm::vec2* Data() const { return table_.data(); }
    /// Samples per entry the table was built with.
    int Samples() const { return samples_; }

    /// One independent estimate of (A, B) with `samples` stratified random samples (a
    /// different point set than the table's), for checking the table.
    static glm::vec2 Reference(float cosTheta, float alpha, int samples, unsigned seed = 1);

private:
    std::vector<glm::vec2> table_;  // alpha-major
    int samples_;
};

}  // namespace texcache::screen
