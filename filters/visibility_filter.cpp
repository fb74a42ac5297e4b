// SPDX-License-Identifier: Apache-2.0
#include "filters/visibility_filter.h"

#include <algorithm>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "texcache/enum_names.h"

namespace texcache {

namespace {

constexpr EnumName<VisibilityFilterKind> kVisibilityNames[] = {
    {"none", VisibilityFilterKind::None},
    {"layered", VisibilityFilterKind::Layered},
};

/// A pixel's filter kernel: the inverse of its scaled blur covariance (for the Gaussian's
/// exponent) and the window radius that holds its 3-sigma ellipse; radius 0: a sharp pixel.
struct Kernel {
    float ixx = 0.0f, ixy = 0.0f, iyy = 0.0f;
    int radius = 0;
};

/// Kernels this small (std under half a pixel along both axes, i.e. a blur std under 0.83
/// pixel at scale 0.6: a circle of confusion under 1.7 pixels) are treated as sharp: the pixel is
/// copied. Their neighbours would weigh exp(-2) or less, and a pixel blurred this little is
/// sampled well by its own 8-16 camera samples; averaging it only risks blurring what is in
/// focus (on the car's in-focus crop, a threshold of a quarter pixel changes 41% of its pixels
/// and raises its relMSE: results/blur.md, "Alternatives").
constexpr float kSharpVariance = 1.0f / 4.0f;
/// Added to the covariance before inverting it: a motion blur is a segment (rank 1), whose
/// Gaussian still needs a width across it (1/8 pixel std: neighbours across get exp(-32)).
constexpr float kMinVariance = 1.0f / 64.0f;

Kernel MakeKernel(const float* blur, float scale2, int maxRadius) {
    Kernel k;
    float xx = blur[0] * scale2, xy = blur[1] * scale2, yy = blur[2] * scale2;
    if (!(std::isfinite(xx) && std::isfinite(xy) && std::isfinite(yy))) return k;
    if (!(std::max(xx, yy) > kSharpVariance)) return k;
    xx += kMinVariance, yy += kMinVariance;
    const float det = xx * yy - xy * xy;
    if (!(det > 0.0f)) return k;
    k.ixx = yy / det, k.ixy = -xy / det, k.iyy = xx / det;
    // Largest eigenvalue of the covariance: the ellipse's long semi-axis is its square root.
    const float mean = 0.5f * (xx + yy), dev = std::sqrt(0.25f * (xx - yy) * (xx - yy) + xy * xy);
    k.radius = std::min(maxRadius, int(std::ceil(3.0f * std::sqrt(mean + dev))));
    return k;
}

/// Gaussian weight of offset (dx, dy) under a kernel (1 at the centre, 0 past 3 sigma).
inline float Weight(const Kernel& k, float dx, float dy) {
    const float q = k.ixx * dx * dx + 2.0f * k.ixy * dx * dy + k.iyy * dy * dy;
    return q < 9.0f ? std::exp(-0.5f * q) : 0.0f;
}

/// Whether a surface at depth `zq` is in front of one at `zp`, beyond the layer tolerance (a
/// miss, +inf or NaN, is behind everything).
inline bool InFront(float zq, float zp, float tolerance) {
    if (!(zq < INFINITY)) return false;
    if (!(zp < INFINITY)) return true;
    return zq < zp * (1.0f - tolerance);
}

inline bool Finite3(const float* c) {
    return std::isfinite(c[0]) && std::isfinite(c[1]) && std::isfinite(c[2]);
}

}  // namespace

VisibilityFilterKind ParseVisibilityFilter(const std::string& name, const std::string& where) {
    return ParseEnum(kVisibilityNames, name, where, "visibility filter");
}

void FilterVisibility(const VisibilityBuffers& in, const VisibilityFilterSettings& settings,
                      std::vector<float>* out) {
    const int W = in.width, H = in.height;
    const size_t n = size_t(std::max(W, 0)) * size_t(std::max(H, 0));
    out->assign(in.color, in.color + 3 * n);
    if (n == 0) return;
    const int maxRadius = std::clamp(settings.maxRadius, 0, 64);
    const float scale2 = settings.scale * settings.scale;
    const float tol = settings.depthTolerance;

    std::vector<Kernel> kernels(n);
    tbb::parallel_for(size_t(0), n, [&](size_t p) {
        kernels[p] = MakeKernel(&in.blur[3 * p], scale2, maxRadius);
    });
    // Tile max / neighbour max (McGuire et al. 2012): with tiles of the largest radius, every
    // pixel whose kernel can reach p lies in p's tile or one of its 8 neighbours.
    const int T = std::max(maxRadius, 1);
    const int TW = (W + T - 1) / T, TH = (H + T - 1) / T;
    std::vector<int> tileMax(size_t(TW) * TH, 0), reach(size_t(TW) * TH, 0);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            int& m = tileMax[size_t(y / T) * TW + x / T];
            m = std::max(m, kernels[size_t(y) * W + x].radius);
        }
    for (int ty = 0; ty < TH; ++ty)
        for (int tx = 0; tx < TW; ++tx) {
            int m = 0;
            for (int j = std::max(ty - 1, 0); j <= std::min(ty + 1, TH - 1); ++j)
                for (int i = std::max(tx - 1, 0); i <= std::min(tx + 1, TW - 1); ++i)
                    m = std::max(m, tileMax[size_t(j) * TW + i]);
            reach[size_t(ty) * TW + tx] = m;
        }

    tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
        for (int y = rows.begin(); y < rows.end(); ++y)
            for (int x = 0; x < W; ++x) {
                const int R = reach[size_t(y / T) * TW + x / T];
                if (R == 0) continue;  // no kernel reaches this pixel: copied
                const size_t p = size_t(y) * W + x;
                const Kernel& kp = kernels[p];
                const float zp = in.depth[p];
                double sum[3] = {0.0, 0.0, 0.0}, wsum = 0.0;
                for (int qy = std::max(y - R, 0); qy <= std::min(y + R, H - 1); ++qy)
                    for (int qx = std::max(x - R, 0); qx <= std::min(x + R, W - 1); ++qx) {
                        const size_t q = size_t(qy) * W + qx;
                        const float* c = &in.color[3 * q];
                        if (!Finite3(c)) continue;
                        const float dx = float(qx - x), dy = float(qy - y);
                        // A nearer layer spreads over p with its own kernel; p's own layer and
                        // the layers behind it are gathered with p's kernel.
                        const Kernel& k = InFront(in.depth[q], zp, tol) ? kernels[q] : kp;
                        const float w = q == p ? 1.0f : k.radius ? Weight(k, dx, dy) : 0.0f;
                        if (w <= 0.0f) continue;
                        sum[0] += w * c[0], sum[1] += w * c[1], sum[2] += w * c[2];
                        wsum += w;
                    }
                if (wsum > 0.0)
                    for (int ch = 0; ch < 3; ++ch) (*out)[3 * p + ch] = float(sum[ch] / wsum);
            }
    });
}

}  // namespace texcache
