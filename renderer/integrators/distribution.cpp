// SPDX-License-Identifier: Apache-2.0
#include "renderer/integrators/distribution.h"

#include <algorithm>
#include <bit>
#include <cmath>

namespace texcache {

namespace {

// std::upper_bound's index (the first element > u) without a branch per step: the halving
// compiles to a conditional move, where std::upper_bound's branches are mispredicted about
// every other step (environment-map light samples: with 32 unshadowed samples a pixel,
// Distribution1D::Sample is a large share of the car's frame-buffer render in `perf`).
size_t UpperBound(const float* a, size_t count, float u) {
    const float* base = a;
    size_t n = count;
    while (n > 1) {
        const size_t half = n / 2;
        base = base[half] <= u ? base + half : base;
        n -= half;
    }
    return size_t(base - a) + (count > 0 && base[0] <= u ? 1 : 0);
}

// About four bins a bucket: the search within a bucket stays in one or two cache lines, and
// the table is a quarter of the CDF's size.
int GuideCount(size_t bins) {
    return int(std::max<size_t>(std::bit_ceil(bins) / 4, 1));
}

// guide[k] = UpperBound(cdf, k / G) for k < G, guide[0] = 0 (a u below 0 inverts to index 0)
// and guide[G] = the CDF's size. k / G is exact in float for a power of two G.
void BuildGuide(const float* cdf, size_t size, int count, uint32_t* guide) {
    size_t i = 0;
    guide[0] = 0;
    for (int k = 1; k < count; ++k) {
        const float t = float(k) / float(count);
        while (i < size && cdf[i] <= t) ++i;
        guide[k] = uint32_t(i);
    }
    guide[count] = uint32_t(size);
}

// UpperBound(cdf, size, u), searching only between the cut points of u's bucket: every CDF
// value before guide[k] is <= k / G <= u and the one at guide[k + 1] is > (k + 1) / G > u.
// NaN and u < 1 / G fall in bucket 0, u >= 1 in the last one, whose end is the CDF's end.
size_t GuidedUpperBound(const float* cdf, const uint32_t* guide, int count, float u) {
    const float s = u * float(count);
    const int k = s >= 1.0f ? std::min(int(std::min(s, float(count))), count - 1) : 0;
    const size_t lo = guide[k], hi = guide[k + 1];
    return lo + UpperBound(cdf + lo, hi - lo, u);
}

// Inverts one CDF of n bins (n + 1 values) at u: the continuous sample, its density and bin.
float SampleCdf(const float* cdf, const uint32_t* guide, int guides, int n, float u, float* pdf,
                int* offset) {
    // Last bin whose cdf <= u, skipping empty bins.
    int o = int(GuidedUpperBound(cdf, guide, guides, u)) - 1;
    o = std::clamp(o, 0, n - 1);
    while (o < n - 1 && cdf[o + 1] - cdf[o] <= 0.0f) ++o;
    if (offset) *offset = o;
    const float width = cdf[o + 1] - cdf[o];
    float du = width > 0.0f ? (u - cdf[o]) / width : 0.5f;
    du = std::clamp(du, 0.0f, 1.0f);
    if (pdf) *pdf = width * float(n);
    return std::min((float(o) + du) / float(n), 0x1.fffffep-1f);
}

float PdfCdf(const float* cdf, int n, float x) {
    const int o = std::clamp(int(x * float(n)), 0, n - 1);
    return (cdf[o + 1] - cdf[o]) * float(n);
}

}  // namespace

Distribution1D::Distribution1D(const std::vector<float>& weights) : cdf_(weights.size() + 1) {
    const size_t n = weights.size();
    // Integrate in double: 512K bins of widely ranging env-map luminance lose precision in float.
    double acc = 0.0;
    std::vector<double> c(n + 1, 0.0);
    for (size_t i = 0; i < n; ++i) {
        float f = weights[i];
        if (!(f >= 0.0f) || !std::isfinite(f)) f = 0.0f, ++clampedCount;
        c[i + 1] = (acc += double(f) / double(n));
    }
    integral_ = float(acc);
    for (size_t i = 0; i <= n; ++i) cdf_[i] = acc > 0.0 ? float(c[i] / acc) : float(i) / float(n);
    cdf_[n] = 1.0f;
    if (!(acc > 0.0)) integral_ = 1.0f;
    const int g = GuideCount(n);
    guide_.resize(size_t(g) + 1);
    BuildGuide(cdf_.data(), cdf_.size(), g, guide_.data());
}

size_t Distribution1D::UpperBound(float u) const {
    return GuidedUpperBound(cdf_.data(), guide_.data(), int(guide_.size()) - 1, u);
}

float Distribution1D::Sample(float u, float* pdf, int* offset) const {
    return SampleCdf(cdf_.data(), guide_.data(), int(guide_.size()) - 1, Count(), u, pdf, offset);
}

float Distribution1D::Pdf(float x) const {
    return PdfCdf(cdf_.data(), Count(), x);
}

Distribution2D::Distribution2D(const std::vector<float>& weights, int nu, int nv)
    : rowGuides_(GuideCount(size_t(nu))), nu_(nu), nv_(nv) {
    std::vector<float> rowSums(nv);
    rowCdf_.resize(size_t(nv) * size_t(nu + 1));
    rowGuide_.resize(size_t(nv) * size_t(rowGuides_ + 1));
    for (int v = 0; v < nv; ++v) {
        const Distribution1D row(std::vector<float>(weights.begin() + size_t(v) * nu,
                                                    weights.begin() + size_t(v + 1) * nu));
        std::copy(row.cdf_.begin(), row.cdf_.end(), rowCdf_.begin() + size_t(v) * (nu + 1));
        std::copy(row.guide_.begin(), row.guide_.end(),
                  rowGuide_.begin() + size_t(v) * (rowGuides_ + 1));
        double s = 0.0;
        for (size_t i = size_t(v) * nu; i < size_t(v + 1) * nu; ++i) {
            const float w = weights[i];
            s += (w >= 0.0f && std::isfinite(w)) ? w : 0.0f;
        }
        rowSums[v] = float(s / nu);
    }
    marginal_ = Distribution1D(rowSums);
}

glm::vec2 Distribution2D::Sample(glm::vec2 u, float* pdf) const {
    float pv, pu;
    int v;
    const float sv = marginal_.Sample(u.y, &pv, &v);
    const float su = SampleCdf(rowCdf_.data() + size_t(v) * (nu_ + 1),
                               rowGuide_.data() + size_t(v) * (rowGuides_ + 1), rowGuides_, nu_,
                               u.x, &pu, nullptr);
    *pdf = pu * pv;
    return {su, sv};
}

float Distribution2D::Pdf(glm::vec2 uv) const {
    const int v = std::clamp(int(uv.y * float(nv_)), 0, nv_ - 1);
    return marginal_.Pdf(uv.y) * PdfCdf(rowCdf_.data() + size_t(v) * (nu_ + 1), nu_, uv.x);
}

float Distribution2D::BinPdf(int u, int v) const {
    const float* row = rowCdf_.data() + size_t(v) * (nu_ + 1);
    return (marginal_.cdf_[size_t(v) + 1] - marginal_.cdf_[size_t(v)]) * float(nv_) *
           ((row[u + 1] - row[u]) * float(nu_));
}

}  // namespace texcache
