// SPDX-License-Identifier: Apache-2.0
// The GGX + Schlick pre-integration table. Each entry is a Monte Carlo estimate with visible-
// normal sampling (Heitz 2018): w_i = reflect(w_o, m), m ~ D_wo, whose weight is
//     f_r cos / pdf = F(w_o.m) G2(w_o, w_i) / G1(w_o),
// so with F = F0 + (1 - F0) Fc, Fc = (1 - w_o.m)^5:
//     A = E[(1 - Fc) G2 / G1],  B = E[Fc G2 / G1].
// The sample set's (r cos phi, r sin phi) disk points do not depend on the entry, so they are
// computed once and the per-entry loop is branch-free arithmetic that vectorizes.
#include "screen_space/brdf_table.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "screen_space/internal.h"
#include "texcache/error.h"

namespace texcache::screen {
namespace {

constexpr float kPi = 3.14159265358979f;

float RadicalInverse2(uint32_t i) {
    i = (i << 16) | (i >> 16);
    i = ((i & 0x55555555u) << 1) | ((i & 0xAAAAAAAAu) >> 1);
    i = ((i & 0x33333333u) << 2) | ((i & 0xCCCCCCCCu) >> 2);
    i = ((i & 0x0F0F0F0Fu) << 4) | ((i & 0xF0F0F0F0u) >> 4);
    i = ((i & 0x00FF00FFu) << 8) | ((i & 0xFF00FF00u) >> 8);
    return float(i) * 2.3283064365386963e-10f;
}

// Disk points of the visible-normal warp: (sqrt(u1) cos 2 pi u2, sqrt(u1) sin 2 pi u2).
struct DiskSet {
    std::vector<float> p1, p2;
};

// Sum of (A, B) over the disk points for one (cos theta_o, alpha).
TEXCACHE_SCREEN_CLONES void Accumulate(const float* p1s, const float* p2s, int n, float cosTheta,
                                       float alpha, double* outA, double* outB) {
    const float c = std::max(cosTheta, 1e-4f);
    const float a = std::max(alpha, 1e-4f);
    const float sx = std::sqrt(std::max(0.0f, 1.0f - c * c));  // w_o = (sx, 0, c)
    // Stretched view direction vh = normalize(a sx, 0, c); tangents t1 = (0, 1, 0) x ... as in
    // renderer/integrators/sampling.h: t1 = (-vh.y, vh.x, 0)/|.| = (0, 1, 0), t2 = vh x t1.
    const float il = 1.0f / std::sqrt(a * a * sx * sx + c * c);
    const float vx = a * sx * il, vz = c * il;
    const float t2x = -vz, t2z = vx;  // vh x (0,1,0) = (-vz, 0, vx)
    const float s = 0.5f * (1.0f + vz);
    // Smith Lambda of w_o (height-correlated G2 = 1 / (1 + L_o + L_i), G1 = 1 / (1 + L_o)).
    const float lo = 0.5f * (std::sqrt(1.0f + a * a * (1.0f - c * c) / (c * c)) - 1.0f);
    // Per-sample terms into small arrays (a loop without a reduction, which GCC vectorizes
    // without -ffast-math), then summed in 8 independent lanes.
    constexpr int kBlock = 256;
    alignas(64) float ta[kBlock], tb[kBlock];
    double sumA = 0.0, sumB = 0.0;
    for (int k0 = 0; k0 < n; k0 += kBlock) {
        const int m = std::min(kBlock, n - k0);
        for (int k = 0; k < m; ++k) {
            const float p1 = p1s[k0 + k];
            float p2 = p2s[k0 + k];
            p2 = (1.0f - s) * std::sqrt(std::max(0.0f, 1.0f - p1 * p1)) + s * p2;
            const float p3 = std::sqrt(std::max(0.0f, 1.0f - p1 * p1 - p2 * p2));
            // nh = p1 t1 + p2 t2 + p3 vh, with t1 = (0, 1, 0)
            const float nhx = p2 * t2x + p3 * vx;
            const float nhy = p1;
            const float nhz = std::max(1e-6f, p2 * t2z + p3 * vz);
            float mx = a * nhx, my = a * nhy, mz = nhz;
            const float im = 1.0f / std::sqrt(mx * mx + my * my + mz * mz);
            mx *= im, my *= im, mz *= im;
            const float om = std::max(0.0f, sx * mx + c * mz);  // w_o . m
            const float wiz = 2.0f * om * mz - c;               // (reflect(w_o, m)).z
            const float wiz2 = std::max(wiz * wiz, 1e-12f);
            const float li =
                0.5f * (std::sqrt(1.0f + a * a * std::max(0.0f, 1.0f - wiz2) / wiz2) - 1.0f);
            const float g = wiz > 0.0f ? (1.0f + lo) / (1.0f + lo + li) : 0.0f;  // G2 / G1
            const float f1 = 1.0f - om, f2 = f1 * f1;
            const float fc = f2 * f2 * f1;
            ta[k] = (1.0f - fc) * g;
            tb[k] = fc * g;
        }
        for (int k = m; k < kBlock; ++k) ta[k] = tb[k] = 0.0f;
        float la[8] = {}, lb[8] = {};
        for (int k = 0; k < kBlock; k += 8)
            for (int l = 0; l < 8; ++l) la[l] += ta[k + l], lb[l] += tb[k + l];
        for (int l = 0; l < 8; ++l) sumA += la[l], sumB += lb[l];
    }
    *outA = sumA, *outB = sumB;
}

}  // namespace

BrdfPreintegration::BrdfPreintegration(int samples) : samples_(samples) {
    if (samples < 1)
        throw InputError("BrdfPreintegration",
                         "samples per entry must be at least 1, got " + std::to_string(samples));
    DiskSet d;
    d.p1.resize(size_t(samples)), d.p2.resize(size_t(samples));
    for (int k = 0; k < samples; ++k) {
        const float u1 = (float(k) + 0.5f) / float(samples), u2 = RadicalInverse2(uint32_t(k));
        const float r = std::sqrt(u1), phi = 2.0f * kPi * u2;
        d.p1[size_t(k)] = r * std::cos(phi), d.p2[size_t(k)] = r * std::sin(phi);
    }
    table_.resize(size_t(kSize) * kSize);
    tbb::parallel_for(tbb::blocked_range<int>(0, kSize), [&](const tbb::blocked_range<int>& r) {
        const internal::DenormalsAreZero mode;  // the same table whichever thread computes it
        for (int j = r.begin(); j < r.end(); ++j)
            for (int i = 0; i < kSize; ++i) {
                double a, b;
                Accumulate(d.p1.data(), d.p2.data(), samples, float(i) / float(kSize - 1),
                           float(j) / float(kSize - 1), &a, &b);
                table_[size_t(j) * kSize + i] = glm::vec2(float(a / samples), float(b / samples));
            }
    });
}

glm::vec2 BrdfPreintegration::ScaleBias(float cosTheta, float alpha) const {
    // NaN arguments clamp to 0 rather than indexing out of range.
    const float u = std::clamp(cosTheta, 0.0f, 1.0f) * float(kSize - 1);
    const float v = std::clamp(alpha, 0.0f, 1.0f) * float(kSize - 1);
    const float uu = u == u ? u : 0.0f, vv = v == v ? v : 0.0f;
    const int i = std::min(int(uu), kSize - 2), j = std::min(int(vv), kSize - 2);
    const float fu = uu - float(i), fv = vv - float(j);
    const glm::vec2 a = glm::mix(Entry(i, j), Entry(i + 1, j), fu);
    const glm::vec2 b = glm::mix(Entry(i, j + 1), Entry(i + 1, j + 1), fu);
    return glm::mix(a, b, fv);
}

glm::vec2 BrdfPreintegration::Reference(float cosTheta, float alpha, int samples, unsigned seed) {
    // Stratified jittered samples on a sqrt(n) x sqrt(n) grid, summed in double.
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    const int side = std::max(1, int(std::sqrt(double(samples))));
    std::vector<float> p1, p2;
    p1.reserve(size_t(side) * side), p2.reserve(size_t(side) * side);
    for (int y = 0; y < side; ++y)
        for (int x = 0; x < side; ++x) {
            const float u1 = (float(x) + uni(rng)) / float(side);
            const float u2 = (float(y) + uni(rng)) / float(side);
            const float r = std::sqrt(u1), phi = 2.0f * kPi * u2;
            p1.push_back(r * std::cos(phi)), p2.push_back(r * std::sin(phi));
        }
    // Sum in blocks so float accumulation error stays small.
    double a = 0.0, b = 0.0;
    const int n = int(p1.size());
    for (int k = 0; k < n; k += 1024) {
        double ba, bb;
        Accumulate(p1.data() + k, p2.data() + k, std::min(1024, n - k), cosTheta, alpha, &ba, &bb);
        a += ba, b += bb;
    }
    return glm::vec2(float(a / n), float(b / n));
}

}  // namespace texcache::screen
