// SPDX-License-Identifier: Apache-2.0
#include "renderer/image/metrics.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "texcache/error.h"

namespace texcache {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string SizeString(const Image& img) {
    return std::to_string(img.width) + "x" + std::to_string(img.height);
}

void CheckSameShape(const Image& a, const Image& b) {
    if (a.width != b.width || a.height != b.height)
        throw InputError("compare",
                         "image sizes differ: " + SizeString(a) + " vs " + SizeString(b));
    if (a.channels != b.channels)
        throw InputError("compare", "channel counts differ: " + std::to_string(a.channels) +
                                        " vs " + std::to_string(b.channels));
    if (a.channels < 3) throw InputError("compare", "images need at least 3 colour channels");
    if (a.data.size() != a.NumPixels() * a.channels || b.data.size() != b.NumPixels() * b.channels)
        throw InputError("compare", "image data does not match the image size");
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
        s += d * d;
    }
    return s / denom;
}

// One pass over both images: what relMSE and RMSE need, and the excluded pixels.
struct Sums {
    double rel = 0.0, sq = 0.0;
    size_t n = 0, excluded = 0;
};

Sums Accumulate(const Image& test, const Image& ref, double eps) {
    const int c = test.channels;
    // Deterministic reduction: the same images give bit-identical metrics on any thread count.
    return tbb::parallel_deterministic_reduce(
        tbb::blocked_range<size_t>(0, test.NumPixels(), 1 << 14), Sums{},
        [&](const tbb::blocked_range<size_t>& r, Sums s) {
            for (size_t p = r.begin(); p != r.end(); ++p) {
                const float* t = &test.data[p * c];
                const float* f = &ref.data[p * c];
                if (!FinitePixel(t) || !FinitePixel(f)) {
                    ++s.excluded;
                    continue;
                }
                s.rel += PixelRelMse(t, f, eps);
                for (int k = 0; k < 3; ++k) s.sq += (double(t[k]) - f[k]) * (double(t[k]) - f[k]);
                ++s.n;
            }
            return s;
        },
        [](Sums a, const Sums& b) {
            a.rel += b.rel, a.sq += b.sq, a.n += b.n, a.excluded += b.excluded;
            return a;
        });
}

double SrgbEncode(double v) {
    v = std::clamp(v, 0.0, 1.0);
    return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
}

// Luma of the displayed (clamped, sRGB-encoded) colour: SSIM was designed for display values.
float DisplayLuma(const float* c) {
    return float(0.2126 * SrgbEncode(c[0]) + 0.7152 * SrgbEncode(c[1]) + 0.0722 * SrgbEncode(c[2]));
}

// Inferno (matplotlib, van der Walt & Smith), every 16th of its 256 entries plus the last.
constexpr float kInferno[17][3] = {
    {0.001462f, 0.000466f, 0.013866f}, {0.042253f, 0.028139f, 0.141141f},
    {0.129285f, 0.047293f, 0.290788f}, {0.238273f, 0.036621f, 0.396353f},
    {0.341500f, 0.062325f, 0.429425f}, {0.441207f, 0.099338f, 0.431594f},
    {0.540920f, 0.134729f, 0.415123f}, {0.640135f, 0.171438f, 0.381065f},
    {0.735683f, 0.215906f, 0.330245f}, {0.822386f, 0.275197f, 0.266085f},
    {0.894305f, 0.353399f, 0.193584f}, {0.946965f, 0.449191f, 0.115272f},
    {0.978422f, 0.557937f, 0.034931f}, {0.987874f, 0.675267f, 0.065257f},
    {0.974638f, 0.797692f, 0.206332f}, {0.947594f, 0.917399f, 0.410665f},
    {0.988362f, 0.998364f, 0.644924f}};

// t in [0,1] -> inferno colour (display-referred, i.e. sRGB-encoded values).
void Inferno(double t, float out[3]) {
    // Control point i sits at entry 16 i of the 256-entry table (the last one at entry 255).
    const double x = std::clamp(t, 0.0, 1.0) * 255.0;
    const int i = std::min(int(x / 16.0), 15);
    const double span = i == 15 ? 15.0 : 16.0;
    const float f = float(std::min((x - 16.0 * i) / span, 1.0));
    for (int k = 0; k < 3; ++k) out[k] = kInferno[i][k] * (1.0f - f) + kInferno[i + 1][k] * f;
}

float SrgbDecode(float v) {
    return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

}  // namespace

double RelMSE(const Image& test, const Image& ref, double eps) {
    CheckSameShape(test, ref);
    const Sums s = Accumulate(test, ref, eps);
    return s.n ? s.rel / double(s.n) : kNaN;
}

double RMSE(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    const Sums s = Accumulate(test, ref, 1e-3);
    return s.n ? std::sqrt(s.sq / (3.0 * double(s.n))) : kNaN;
}

double PSNR(const Image& test, const Image& ref, double peak) {
    const double rmse = RMSE(test, ref);
    if (rmse == 0.0) return std::numeric_limits<double>::infinity();
    return 20.0 * std::log10(peak / rmse);  // NaN stays NaN
}

double SSIM(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    const int w = test.width, h = test.height, c = test.channels;
    const size_t n = test.NumPixels();

    // Luma planes; an excluded pixel takes the reference's value in both (0 if that is not finite).
    std::vector<float> a(n), b(n);
    std::vector<uint8_t> valid(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const auto& r) {
        for (size_t p = r.begin(); p != r.end(); ++p) {
            const float* t = &test.data[p * c];
            const float* f = &ref.data[p * c];
            const bool refOk = FinitePixel(f);
            valid[p] = refOk && FinitePixel(t);
            b[p] = refOk ? DisplayLuma(f) : 0.0f;
            a[p] = valid[p] ? DisplayLuma(t) : b[p];
        }
    });

    constexpr int kR = 5;  // 11 taps
    double kernel[2 * kR + 1], ksum = 0.0;
    for (int i = -kR; i <= kR; ++i) ksum += kernel[i + kR] = std::exp(-i * i / (2.0 * 1.5 * 1.5));
    for (double& v : kernel) v /= ksum;
    const double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;

    // Separable blur of a, b, a^2, b^2, ab in bands of rows: each band blurs its rows plus kR
    // above and below horizontally, then vertically, and sums its SSIM map. Bands keep memory
    // small and give a deterministic sum (per-band partial sums added in order).
    constexpr int kBand = 32;
    const int bands = (h + kBand - 1) / kBand;
    std::vector<double> bandSum(bands, 0.0);
    std::vector<size_t> bandCount(bands, 0);
    tbb::parallel_for(0, bands, [&](int band) {
        const int y0 = band * kBand, y1 = std::min(h, y0 + kBand);
        const int r0 = y0 - kR, rows = (y1 + kR) - r0;
        std::vector<double> hz(size_t(rows) * w * 5);
        std::vector<double> pa(w + 2 * kR), pb(w + 2 * kR);  // one row, edge-replicated
        for (int yy = r0; yy < r0 + rows; ++yy) {
            const size_t src = size_t(std::clamp(yy, 0, h - 1)) * w;
            for (int x = -kR; x < w + kR; ++x) {
                const size_t sx = src + std::clamp(x, 0, w - 1);
                pa[x + kR] = a[sx], pb[x + kR] = b[sx];
            }
            double* o = &hz[size_t(yy - r0) * w * 5];
            for (int x = 0; x < w; ++x, o += 5) {
                double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
                for (int i = 0; i <= 2 * kR; ++i) {
                    const double k = kernel[i], va = pa[x + i], vb = pb[x + i];
                    sa += k * va, sb += k * vb;
                    saa += k * va * va, sbb += k * vb * vb, sab += k * va * vb;
                }
                o[0] = sa, o[1] = sb, o[2] = saa, o[3] = sbb, o[4] = sab;
            }
        }
        double sum = 0.0;
        size_t count = 0;
        for (int y = y0; y < y1; ++y)
            for (int x = 0; x < w; ++x) {
                if (!valid[size_t(y) * w + x]) continue;
                double m[5] = {0, 0, 0, 0, 0};
                for (int i = 0; i <= 2 * kR; ++i) {
                    const double* v = &hz[(size_t(y - y0 + i) * w + x) * 5];
                    for (int q = 0; q < 5; ++q) m[q] += kernel[i] * v[q];
                }
                const double ma = m[0], mb = m[1];
                const double va = m[2] - ma * ma, vb = m[3] - mb * mb, cov = m[4] - ma * mb;
                sum += ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) /
                       ((ma * ma + mb * mb + c1) * (va + vb + c2));
                ++count;
            }
        bandSum[band] = sum;
        bandCount[band] = count;
    });
    double sum = 0.0;
    size_t count = 0;
    for (int i = 0; i < bands; ++i) sum += bandSum[i], count += bandCount[i];
    return count ? sum / double(count) : kNaN;
}

ImageErrors CompareImages(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    const Sums s = Accumulate(test, ref, 1e-3);
    if (s.n == 0)
        throw InputError("compare", "no pixel is finite in both images (" +
                                        std::to_string(s.excluded) + " with NaN/Inf)");
    ImageErrors e;
    e.nonFinite = s.excluded;
    e.relMSE = s.rel / double(s.n);
    e.rmse = std::sqrt(s.sq / (3.0 * double(s.n)));
    e.psnr = e.rmse == 0.0 ? std::numeric_limits<double>::infinity() : -20.0 * std::log10(e.rmse);
    e.ssim = SSIM(test, ref);
    return e;
}

Image FalseColorError(const Image& test, const Image& ref) {
    CheckSameShape(test, ref);
    const int c = test.channels;
    Image out(test.width, test.height, 3);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, test.NumPixels(), 1 << 14), [&](const auto& r) {
        for (size_t p = r.begin(); p != r.end(); ++p) {
            const float* t = &test.data[p * c];
            const float* f = &ref.data[p * c];
            float* o = &out.data[p * 3];
            if (!FinitePixel(t) || !FinitePixel(f)) {
                o[0] = 1.0f, o[1] = 0.0f, o[2] = 1.0f;
                continue;
            }
            const double e = PixelRelMse(t, f, 1e-3);
            // log10(e) from -4 to 1 -> [0,1]; exactly 0 error is below the scale.
            Inferno((std::log10(std::max(e, 1e-30)) + 4.0) / 5.0, o);
            // The colour map is display-referred: undo the sRGB encode WriteImage will apply.
            for (int k = 0; k < 3; ++k) o[k] = SrgbDecode(o[k]);
        }
    });
    return out;
}

}  // namespace texcache
