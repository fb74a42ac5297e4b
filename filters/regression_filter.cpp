// SPDX-License-Identifier: Apache-2.0
// Texture-space linear regression. The formulas, in the order the code applies them:
//
// Features. x_i = (dx_i / R, dy_i / R, n_i - n_c, [r_i - r_c]) for footprint tap i at texel
// offset (dx, dy) from the centre c, R the footprint radius, n the noise-free surface normal at
// the texel centre, r the roughness. Every component lies in [-2, 2], so one tolerance fits all.
//
// Truncated SVD. C = (1/N) sum_i x_i x_i^T (second moment about the centre: the model is expanded
// around x_c). Its eigenvectors are the right singular vectors of the design matrix and
// sqrt(lambda_j) its singular values / sqrt(N). We keep directions with
//   sqrt(lambda_j) > 1e-2 * sqrt(lambda_max)   and   sqrt(lambda_j) > 1e-4.
// The relative bound caps the reduced problem's condition number at 1e2 (the variance of a fitted
// slope grows as 1/sigma_j^2: along a direction the footprint barely spans, a slope would only fit
// noise); the absolute bound removes what is left of float round-off in the normals (~1e-7) on
// flat or collinear footprints. z_i = U^T x_i, design row a_i = (1, z_i), p = rank + 1 <= 7.
//
// Recursive least squares (Moon et al. 2015), taps ordered by ring k = max(|dx|, |dy|):
//   e_i = y_i - theta^T a_i                     (a-priori error: the model has not seen tap i)
//   h_i = a_i^T P a_i,  g = P a_i / (1 + h_i),  theta += g e_i^T,  P -= g (P a_i)^T
// from theta = 0, P = I / delta (delta = 1e-6: a vanishing ridge that keeps P defined before the
// footprint spans every direction). In double precision: RLS's downdate of P loses about
// log10(cond) digits per pass, which float (7 digits) cannot afford at cond ~1e4 of the
// unreduced normal equations.
//
// Error estimate of the model on rings 0..k at the centre (Moon et al.'s a-priori-error estimate,
// with the noise it contains removed so that it compares with the k = 0 variance):
//   bias^2_k = max(0, mean_i[e_i^2 - s_i^2 (1 + h_i)])   over taps of rings 1..k with h_i <= 1
//   xi_k     = bias^2_k + sbar^2 * P_00                  (P_00 ~ 1 / N_k: variance of the
//   intercept)
// where s_i^2 is tap i's noise variance (luminance) and sbar^2 their mean. Taps with h_i > 1 are
// ones the model could not yet predict (its own uncertainty exceeds the noise): they would only
// inflate the estimate. k = 0 uses Munkberg et al.'s modified variance over the 3x3 window:
//   xi_0 = (s_c^2 + beta sum_{ring 1} s_i^2) / (1 + m beta),  beta = clamp(1 - n / 256, 0, 1),
// m the number of ring-1 taps. With one ray per sample (n = 1) a sample has no variance estimate
// of its own; all s_i^2 are then sigma^2 = (1/2) mean (y_i - y_j)^2 over 4-neighbour tap pairs of
// the footprint (a difference estimator: smooth signal cancels, noise remains).
// The chosen prediction is theta_0 (z_c = 0) of the ring with the smallest xi, held to the range
// of the values that ring was fitted on (no overshoot beyond the data, so never negative for
// radiance), and replaced by the centre's value if it is not finite.
#include "filters/regression_filter.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Dense>

namespace texcache {

namespace {

constexpr int kMaxFeatures = 6;
using FeatureVec = Eigen::Matrix<double, kMaxFeatures, 1>;
using FeatureMat = Eigen::Matrix<double, kMaxFeatures, kMaxFeatures>;
using Basis = Eigen::Matrix<double, kMaxFeatures, Eigen::Dynamic, 0, kMaxFeatures, kMaxFeatures>;

constexpr double kRelativeSingular = 1e-2;
constexpr double kAbsoluteSingular = 1e-4;
constexpr double kRidge = 1e-6;

bool Finite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

double Lum(double r, double g, double b) {
    return 0.2126 * r + 0.7152 * g + 0.0722 * b;
}

// Mean of the usable taps whose normal agrees with the centre's (or of all usable taps when the
// centre has no normal): the answer when the centre sample itself is unusable.
glm::vec3 FallbackMean(const FilterInput<ShadedSample>& in, const std::vector<int>& usable) {
    const glm::vec3 nc = in.samples[in.centre].normal;
    const bool haveNormal = Finite(nc) && glm::dot(nc, nc) > 0.5f;
    glm::dvec3 sum(0.0);
    int n = 0;
    for (int i : usable) {
        if (haveNormal && glm::dot(in.samples[i].normal, nc) <= 0.9f) continue;
        sum += glm::dvec3(in.samples[i].value);
        ++n;
    }
    return n ? glm::max(glm::vec3(sum / double(n)), glm::vec3(0.0f)) : glm::vec3(0.0f);
}

// The recursive least squares over rings 1..R (see the top of the file) for p = 1 + rank
// parameters; Feature and Noise are the callables Reconstruct builds.
template <class Feature, class Noise>
struct RlsRings {
    const FilterInput<ShadedSample>& in;
    const std::vector<int>& sorted;
    const std::vector<int>& ringStart;
    int R, rank;
    const Basis& U;
    const Noise& noise;
    const Feature& feature;

    template <int P>
    void Run(double* bestError, glm::vec3* best, int* bestRing) const {
        using Vec = Eigen::Matrix<double, P, 1>;
        using Mat = Eigen::Matrix<double, P, P>;
        using Theta = Eigen::Matrix<double, P, 3>;
        const auto& S = in.samples;
        Mat Pm = Mat::Identity() / kRidge;
        Theta theta = Theta::Zero();
        Vec a;
        double sumBias = 0.0, sumNoise = 0.0;
        int informative = 0, seen = 0;
        glm::vec3 lo(INFINITY), hi(-INFINITY);  // range of the values fitted so far
        for (int k = 0; k <= R; ++k) {
            for (int q = ringStart[k]; q < ringStart[k + 1]; ++q) {
                const int i = sorted[q];
                a(0) = 1.0;
                if constexpr (P > 1) {
                    const FeatureVec x = feature(i);
                    for (int j = 0; j < P - 1; ++j) a(j + 1) = U.col(j).dot(x);
                }
                const glm::vec3& y = S[i].value;
                lo = glm::min(lo, y), hi = glm::max(hi, y);
                const Eigen::RowVector3d e =
                    Eigen::RowVector3d(y.x, y.y, y.z) - a.transpose() * theta;
                const Vec Pa = Pm * a;
                const double h = a.dot(Pa);
                const double s2 = noise(i);
                sumNoise += s2;
                ++seen;
                if (k >= 1 && h <= 1.0) {
                    const double el = Lum(e(0), e(1), e(2));
                    sumBias += el * el - s2 * (1.0 + h);
                    ++informative;
                }
                const Vec g = Pa / (1.0 + h);
                theta.noalias() += g * e;
                Pm.noalias() -= g * Pa.transpose();
            }
            if (k == 0 || informative == 0) continue;
            const double bias2 = std::max(0.0, sumBias / informative);
            const double error = bias2 + sumNoise / seen * std::max(Pm(0, 0), 0.0);
            // A linear model can overshoot at its centre (extrapolating a curved signal): it is
            // held to the range of the values it was fitted on.
            const glm::vec3 pred = glm::clamp(
                glm::vec3(float(theta(0, 0)), float(theta(0, 1)), float(theta(0, 2))), lo, hi);
            if (error < *bestError && Finite(pred)) {
                *bestError = error;
                *best = pred;
                *bestRing = k;
            }
        }
    }
};

}  // namespace

glm::vec3 RegressionFilter::Reconstruct(const FilterInput<ShadedSample>& in,
                                        RegressionInfo* info) const {
    RegressionInfo local;
    RegressionInfo& inf = info ? *info : local;
    inf = RegressionInfo{};
    const auto& S = in.samples;
    const auto& T = in.taps;

    // Usable taps, ordered by ring (a counting sort: rings are small integers).
    auto usable = [&](const ShadedSample& s) {
        return Finite(s.value) && Finite(s.normal) && std::isfinite(s.variance) &&
               s.variance >= 0.0f && (!roughnessFeature || std::isfinite(s.roughness));
    };
    thread_local std::vector<int> order, ringStart;
    order.clear();
    int R = 0;
    for (size_t i = 0; i < S.size(); ++i) {
        if (!usable(S[i])) {
            ++inf.rejected;
            continue;
        }
        R = std::max({R, std::abs(T[i].dx), std::abs(T[i].dy)});
        order.push_back(int(i));
    }
    if (!usable(S[in.centre])) {
        inf.fallback = true;
        return FallbackMean(in, order);
    }
    ringStart.assign(size_t(R) + 2, 0);
    for (int i : order) ++ringStart[size_t(std::max(std::abs(T[i].dx), std::abs(T[i].dy))) + 1];
    for (int k = 1; k <= R + 1; ++k) ringStart[k] += ringStart[k - 1];
    thread_local std::vector<int> sorted;
    sorted.resize(order.size());
    {
        thread_local std::vector<int> fill;
        fill.assign(ringStart.begin(), ringStart.end() - 1);
        for (int i : order)
            sorted[size_t(fill[size_t(std::max(std::abs(T[i].dx), std::abs(T[i].dy)))]++)] = i;
    }

    const ShadedSample& c = S[in.centre];
    const int D = roughnessFeature ? 6 : 5;
    const double sxy = 1.0 / double(std::max(R, 1));
    auto feature = [&](int i) {
        FeatureVec x = FeatureVec::Zero();
        x(0) = T[i].dx * sxy;
        x(1) = T[i].dy * sxy;
        for (int k = 0; k < 3; ++k) x(2 + k) = double(S[i].normal[k]) - double(c.normal[k]);
        if (roughnessFeature) x(5) = double(S[i].roughness) - double(c.roughness);
        return x;
    };

    // Truncated SVD of the footprint's features.
    FeatureMat C = FeatureMat::Zero();
    for (int i : sorted) {
        const FeatureVec x = feature(i);
        C.noalias() += x * x.transpose();
    }
    C /= double(sorted.size());
    Eigen::SelfAdjointEigenSolver<FeatureMat> eig(C);
    const auto& lambda = eig.eigenvalues();  // ascending
    const double lmax = std::max(lambda(kMaxFeatures - 1), 0.0);
    int rank = 0;
    for (int j = kMaxFeatures - 1; j >= kMaxFeatures - D; --j) {
        const double l = std::max(lambda(j), 0.0);
        if (l > kRelativeSingular * kRelativeSingular * lmax &&
            l > kAbsoluteSingular * kAbsoluteSingular)
            ++rank;
    }
    Basis U(kMaxFeatures, rank);
    for (int j = 0; j < rank; ++j) U.col(j) = eig.eigenvectors().col(kMaxFeatures - 1 - j);
    inf.rank = rank;
    const int p = rank + 1;

    // Noise variances: the samples' own, or (n = 1) a footprint-wide difference estimate.
    double pooledVar = 0.0;
    if (samplesPerTexel < 2) {
        // Half the mean squared difference of 4-neighbour taps (a von Neumann estimator): smooth
        // signal cancels in the differences and only the noise remains, whatever its level.
        const int W = 2 * R + 1;
        thread_local std::vector<int> grid;
        grid.assign(size_t(W) * W, -1);
        for (int i : sorted) grid[size_t(T[i].dy + R) * W + (T[i].dx + R)] = i;
        auto lum = [&](int i) {
            const glm::vec3 v = S[i].value;
            return Lum(v.x, v.y, v.z);
        };
        thread_local std::vector<double> d2;
        d2.clear();
        for (int y = 0; y < W; ++y)
            for (int x = 0; x < W; ++x) {
                const int i = grid[size_t(y) * W + x];
                if (i < 0) continue;
                const int right = x + 1 < W ? grid[size_t(y) * W + x + 1] : -1;
                const int down = y + 1 < W ? grid[size_t(y + 1) * W + x] : -1;
                for (int j : {right, down}) {
                    if (j < 0 || glm::dot(S[i].normal, S[j].normal) <= 0.9f) continue;
                    const double d = lum(i) - lum(j);
                    d2.push_back(d * d);
                }
            }
        // A plain mean: a firefly then reads as noise and is spread over a large ring, which
        // keeps its energy (it is a legitimate, rare sample of the integral) at 1/N the peak.
        double sum = 0.0;
        for (double d : d2) sum += d;
        pooledVar = d2.empty() ? 0.0 : 0.5 * sum / double(d2.size());
    }
    auto noise = [&](int i) { return samplesPerTexel < 2 ? pooledVar : double(S[i].variance); };

    // k = 0: the centre alone, with the beta-blended 3x3 variance.
    const double beta = std::clamp(1.0 - double(samplesPerTexel) / 256.0, 0.0, 1.0);
    double var0 = noise(in.centre);
    int ring1 = 0;
    for (int q = ringStart[1]; q < ringStart[std::min(R, 1) + 1]; ++q) {
        var0 += beta * noise(sorted[q]);
        ++ring1;
    }
    double bestError = var0 / (1.0 + ring1 * beta);
    glm::vec3 best = c.value;

    // Rings 1..R by recursive least squares, at the model's size known at compile time (p is
    // 1..7: with dynamic sizes Eigen loops over every product, and this loop runs for every tap).
    RlsRings rings{in, sorted, ringStart, R, rank, U, noise, feature};
    switch (p) {
        case 1:
            rings.Run<1>(&bestError, &best, &inf.ring);
            break;
        case 2:
            rings.Run<2>(&bestError, &best, &inf.ring);
            break;
        case 3:
            rings.Run<3>(&bestError, &best, &inf.ring);
            break;
        case 4:
            rings.Run<4>(&bestError, &best, &inf.ring);
            break;
        case 5:
            rings.Run<5>(&bestError, &best, &inf.ring);
            break;
        case 6:
            rings.Run<6>(&bestError, &best, &inf.ring);
            break;
        default:
            rings.Run<7>(&bestError, &best, &inf.ring);
            break;
    }
    if (!Finite(best)) best = c.value;
    return glm::max(best, glm::vec3(0.0f));
}

}  // namespace texcache
