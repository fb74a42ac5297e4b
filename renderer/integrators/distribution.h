// SPDX-License-Identifier: Apache-2.0
// Piecewise-constant 1D and 2D distributions for importance sampling (pbrt's construction).
//
// Inverting a CDF starts from a guide table (cut-point method, Chen and Asau 1974): bucket k of
// G (a power of two) holds the first CDF index above k / G, so a sample u searches only between
// the guides of floor(u G) and the next bucket, a few entries, where a binary search over the
// whole CDF takes log2(n) dependent loads spread over the row. Since u G is exact for a power
// of two G, the bucket bounds the answer exactly and the result is the plain binary search's.
#pragma once
#include <cstddef>
#include <cstdint>
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
    int Count() const { return cdf_.empty() ? 0 : int(cdf_.size()) - 1; }
    float Integral() const { return integral_; }
    /// The CDF's index that Sample(u) inverts from: the first index whose CDF value is > u (the
    /// count of values <= u), through the guide table. For tests against a plain binary search.
    size_t UpperBound(float u) const;
    /// The CDF's n + 1 values (0, ..., 1).
    const std::vector<float>& Cdf() const { return cdf_; }
    size_t clampedCount = 0;

private:
    friend class Distribution2D;
    std::vector<float> cdf_;       // n + 1 values, cdf_[0] = 0, cdf_[n] = 1
    std::vector<uint32_t> guide_;  // G + 1 cut points (see the top of the file)
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
    /// Pdf() anywhere in bin (u, v) (the density is constant over a bin): the same float.
    float BinPdf(int u, int v) const;

private:
    // The rows' CDFs and guide tables, each kept in one contiguous array (row v at v * (nu + 1)
    // and v * (G + 1)): a sample touches one row's few cache lines, never a separate heap block.
    std::vector<float> rowCdf_;
    std::vector<uint32_t> rowGuide_;
    int rowGuides_ = 0;  // G of every row
    Distribution1D marginal_;
    int nu_ = 0, nv_ = 0;
};

}  // namespace texcache
