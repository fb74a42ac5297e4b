// SPDX-License-Identifier: Apache-2.0
#include "renderer/integrators/distribution.h"

#include <algorithm>
#include <cmath>

namespace texcache {

Distribution1D::Distribution1D(const std::vector<float>& weights)
    : func_(weights), cdf_(weights.size() + 1) {
    const size_t n = func_.size();
    for (float& f : func_)
        if (!(f >= 0.0f) || !std::isfinite(f)) f = 0.0f, ++clampedCount;
    // Integrate in double: 512K bins of widely ranging env-map luminance lose precision in float.
    double acc = 0.0;
    std::vector<double> c(n + 1, 0.0);
    for (size_t i = 0; i < n; ++i) c[i + 1] = (acc += double(func_[i]) / double(n));
    integral_ = float(acc);
    for (size_t i = 0; i <= n; ++i) cdf_[i] = acc > 0.0 ? float(c[i] / acc) : float(i) / float(n);
    cdf_[n] = 1.0f;
    if (!(acc > 0.0)) std::fill(func_.begin(), func_.end(), 1.0f), integral_ = 1.0f;
}

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

}  // namespace

float Distribution1D::Sample(float u, float* pdf, int* offset) const {
    const int n = int(func_.size());
    // Last bin whose cdf <= u, skipping empty bins.
    int o = int(UpperBound(cdf_.data(), cdf_.size(), u)) - 1;
    o = std::clamp(o, 0, n - 1);
    while (o < n - 1 && cdf_[o + 1] - cdf_[o] <= 0.0f) ++o;
    if (offset) *offset = o;
    const float width = cdf_[o + 1] - cdf_[o];
    float du = width > 0.0f ? (u - cdf_[o]) / width : 0.5f;
    du = std::clamp(du, 0.0f, 1.0f);
    if (pdf) *pdf = width * float(n);
    return std::min((float(o) + du) / float(n), 0x1.fffffep-1f);
}

float Distribution1D::Pdf(float x) const {
    const int n = int(func_.size());
    const int o = std::clamp(int(x * float(n)), 0, n - 1);
    return (cdf_[o + 1] - cdf_[o]) * float(n);
}

Distribution2D::Distribution2D(const std::vector<float>& weights, int nu, int nv)
    : nu_(nu), nv_(nv) {
    std::vector<float> rowSums(nv);
    conditional_.reserve(nv);
    for (int v = 0; v < nv; ++v) {
        std::vector<float> row(weights.begin() + size_t(v) * nu,
                               weights.begin() + size_t(v + 1) * nu);
        conditional_.emplace_back(row);
        double s = 0.0;
        for (float w : row) s += (w >= 0.0f && std::isfinite(w)) ? w : 0.0f;
        rowSums[v] = float(s / nu);
    }
    marginal_ = Distribution1D(rowSums);
}

glm::vec2 Distribution2D::Sample(glm::vec2 u, float* pdf) const {
    float pv, pu;
    int v;
    const float sv = marginal_.Sample(u.y, &pv, &v);
    const float su = conditional_[v].Sample(u.x, &pu, nullptr);
    *pdf = pu * pv;
    return {su, sv};
}

float Distribution2D::Pdf(glm::vec2 uv) const {
    const int v = std::clamp(int(uv.y * float(nv_)), 0, nv_ - 1);
    return marginal_.Pdf(uv.y) * conditional_[v].Pdf(uv.x);
}

}  // namespace texcache
