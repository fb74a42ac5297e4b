// SPDX-License-Identifier: Apache-2.0
#include "renderer/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "texcache/error.h"

namespace texcache {

namespace {

void CheckSameShape(const Image& a, const Image& b) {
    if (a.width != b.width || a.height != b.height)
        throw InputError("compare", "image sizes differ: " + std::to_string(a.width) + "x" +
                                        std::to_string(a.height) + " vs " +
                                        std::to_string(b.width) + "x" + std::to_string(b.height));
    if (a.channels < 3 || b.channels < 3)
        throw InputError("compare", "images need at least 3 colour channels");
}

bool FinitePixel(const float* p) {
    return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
}

double PixelRelMse(const float* t, const float* r, double eps) {
    const double gray = (double(r[0]) + r[1] + r[2]) / 3.0;
    const double denom = gray * gray + eps;
    double s = 0.0;
    for (int k = 0; k < 3; ++k) {
        const double d = double(t[k]) - r[k];
        s += d * d / denom;
    }
    return s;
}

// Luminance in [0,1] for SSIM (non-finite pixels count as black: they are reported separately).
std::vector<double> Luma(const Image& img) {
    std::vector<double> y(img.NumPixels());
    for (size_t p = 0; p < y.size(); ++p) {
        const float* c = &img.data[p * img.channels];
        double v = FinitePixel(c) ? 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2] : 0.0;
        y[p] = std::clamp(v, 0.0, 1.0);
    }
    return y;
}

// Separable Gaussian blur (11 taps, sigma 1.5) with clamped borders.
std::vector<double> Blur(const std::vector<double>& src, int w, int h) {
    double k[11], ksum = 0.0;
    for (int i = 0; i < 11; ++i)
        ksum += (k[i] = std::exp(-double((i - 5) * (i - 5)) / (2.0 * 1.5 * 1.5)));
    for (double& x : k) x /= ksum;
    std::vector<double> tmp(src.size()), dst(src.size());
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            double s = 0.0;
            for (int i = 0; i < 11; ++i)
                s += k[i] * src[size_t(y) * w + std::clamp(x + i - 5, 0, w - 1)];
            tmp[size_t(y) * w + x] = s;
        }
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            double s = 0.0;
            for (int i = 0; i < 11; ++i)
                s += k[i] * tmp[size_t(std::clamp(y + i - 5, 0, h - 1)) * w + x];
            dst[size_t(y) * w + x] = s;
        }
    return dst;
}

}  // namespace

double RelMSE(const Image& test, const Image& ref, double eps) {
    CheckSameShape(test, ref);
    double sum = 0.0;
    size_t n = 0;
    for (size_t p = 0; p < test.NumPixels(); ++p) {
        const float* t = &test.data[p * test.channels];
        const float* r = &ref.data[p * ref.channels];
        if (!FinitePixel(t) || !FinitePixel(r)) continue;
        sum += PixelRelMse(t, r, eps);
        ++n;
    }
    return n ? sum / double(n) : 0.0;
}

double RMSE(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    double sum = 0.0;
    size_t n = 0;
    for (size_t p = 0; p < test.NumPixels(); ++p) {
        const float* t = &test.data[p * test.channels];
        const float* r = &ref.data[p * ref.channels];
        if (!FinitePixel(t) || !FinitePixel(r)) continue;
        for (int k = 0; k < 3; ++k) sum += (double(t[k]) - r[k]) * (double(t[k]) - r[k]);
        n += 3;
    }
    return n ? std::sqrt(sum / double(n)) : 0.0;
}

double PSNR(const Image& test, const Image& ref, double peak) {
    const double rmse = RMSE(test, ref);
    if (rmse == 0.0) return std::numeric_limits<double>::infinity();
    return 20.0 * std::log10(peak / rmse);
}

double SSIM(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    const int w = test.width, h = test.height;
    const std::vector<double> a = Luma(test), b = Luma(ref);
    std::vector<double> aa(a.size()), bb(a.size()), ab(a.size());
    for (size_t i = 0; i < a.size(); ++i)
        aa[i] = a[i] * a[i], bb[i] = b[i] * b[i], ab[i] = a[i] * b[i];
    const auto ma = Blur(a, w, h), mb = Blur(b, w, h), saa = Blur(aa, w, h), sbb = Blur(bb, w, h),
               sab = Blur(ab, w, h);
    const double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;
    double sum = 0.0;
    for (size_t i = 0; i < a.size(); ++i) {
        const double va = saa[i] - ma[i] * ma[i], vb = sbb[i] - mb[i] * mb[i],
                     cov = sab[i] - ma[i] * mb[i];
        sum += ((2 * ma[i] * mb[i] + c1) * (2 * cov + c2)) /
               ((ma[i] * ma[i] + mb[i] * mb[i] + c1) * (va + vb + c2));
    }
    return sum / double(a.size());
}

ImageErrors CompareImages(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    ImageErrors e;
    for (size_t p = 0; p < test.NumPixels(); ++p)
        e.nonFinite += !FinitePixel(&test.data[p * test.channels]);
    e.relMSE = RelMSE(test, ref);
    e.rmse = RMSE(test, ref);
    e.psnr = PSNR(test, ref);
    e.ssim = SSIM(test, ref);
    return e;
}

Image FalseColorError(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    // Inferno, 9 control points, interpolated linearly.
    static const float kMap[9][3] = {
        {0.001f, 0.000f, 0.014f}, {0.122f, 0.047f, 0.283f}, {0.320f, 0.060f, 0.430f},
        {0.507f, 0.116f, 0.418f}, {0.694f, 0.182f, 0.339f}, {0.865f, 0.317f, 0.226f},
        {0.973f, 0.519f, 0.078f}, {0.988f, 0.755f, 0.145f}, {0.988f, 0.998f, 0.645f}};
    Image out(test.width, test.height, 3);
    for (size_t p = 0; p < test.NumPixels(); ++p) {
        const float* t = &test.data[p * test.channels];
        const float* r = &ref.data[p * ref.channels];
        float* o = &out.data[p * 3];
        if (!FinitePixel(t)) {
            o[0] = 1.0f, o[1] = 0.0f, o[2] = 1.0f;
            continue;
        }
        const double e = FinitePixel(r) ? PixelRelMse(t, r, 1e-3) : 0.0;
        const double x = std::clamp((std::log10(std::max(e, 1e-12)) + 4.0) / 5.0, 0.0, 1.0) * 8.0;
        const int i = std::min(int(x), 7);
        const float f = float(x - i);
        for (int k = 0; k < 3; ++k) o[k] = kMap[i][k] * (1.0f - f) + kMap[i + 1][k] * f;
        // The map is display-referred: undo the PNG writer's sRGB encode so the colours land.
        for (int k = 0; k < 3; ++k)
            o[k] = o[k] <= 0.04045f ? o[k] / 12.92f : std::pow((o[k] + 0.055f) / 1.055f, 2.4f);
    }
    return out;
}

}  // namespace texcache
