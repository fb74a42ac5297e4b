// SPDX-License-Identifier: Apache-2.0
// Image error metrics against a reference: relMSE (as in Munkberg et al. 2016), RMSE, PSNR, SSIM.
#pragma once
#include <cstddef>

#include "renderer/image.h"

namespace texcache {

struct ImageErrors {
    double relMSE = 0, rmse = 0, psnr = 0, ssim = 0;
    size_t nonFinite = 0;  ///< test pixels with a NaN/Inf channel (excluded from every metric)
};

/// relMSE of Rousselle et al. as used by Munkberg et al.: per pixel, the sum over colour channels
/// of (img - ref)^2 / (gray(ref)^2 + eps), averaged over pixels; gray = mean of R,G,B.
double RelMSE(const Image& test, const Image& ref, double eps = 1e-3);
/// Root mean square error over all channels.
double RMSE(const Image& test, const Image& ref);
/// 10 log10(peak^2 / MSE); +inf for identical images.
double PSNR(const Image& test, const Image& ref, double peak = 1.0);
/// Mean SSIM (Wang et al. 2004) of the luminance of values clamped to [0,1]: 11x11 Gaussian
/// window (sigma 1.5), K1 = 0.01, K2 = 0.03, L = 1.
double SSIM(const Image& test, const Image& ref);
/// All of the above; throws InputError when the sizes or channel counts differ.
ImageErrors CompareImages(const Image& test, const Image& ref);
/// Per-pixel relMSE through the inferno colour map on a log scale from 1e-4 (black) to 10
/// (yellow); non-finite test pixels are magenta.
Image FalseColorError(const Image& test, const Image& ref);

}  // namespace texcache
