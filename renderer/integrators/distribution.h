// SPDX-License-Identifier: Apache-2.0
// Piecewise-constant 1D and 2D distributions for importance sampling (pbrt's construction).
#pragma once
#include <cstddef>
#include <vector>

#include <glm/glm.hpp>

namespace texcache {

class Distribution1D {
public:
    Distribution1D() = default;
    /// Weights must be >= 0; negative and NaN weights count as 0 (see clampedCount); all-zero
    /// weights give the uniform distribution.
    explicit Distribution1D(const std::vector<float>& weights);
    /// Continuous sample in [0,1) with its density; `offset` is the chosen bin.
    float Sample(float u, float* pdf, int* offset) const;
    /// Density at x in [0,1).
    float Pdf(float x) const;
    /// Probability of bin i.
    float BinProbability(int i) const { return (cdf_[i + 1] - cdf_[i]); }
    int Count() const { return int(func_.size()); }
    float Integral() const { return integral_; }
    size_t clampedCount = 0;

private:
    std::vector<float> func_, cdf_;
    float integral_ = 0.0f;
};

class Distribution2D {
public:
    Distribution2D() = default;
    /// `weights` is row-major nu x nv (row v, column u).
    Distribution2D(const std::vector<float>& weights, int nu, int nv);
    /// Sample in [0,1)^2 with its density with respect to (u,v) area.
    glm::vec2 Sample(glm::vec2 u, float* pdf) const;
    float Pdf(glm::vec2 uv) const;

private:
    std::vector<Distribution1D> conditional_;
    Distribution1D marginal_;
    int nu_ = 0, nv_ = 0;
};

}  // namespace texcache
