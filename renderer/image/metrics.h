// SPDX-License-Identifier: Apache-2.0
// Image error metrics against a reference: relMSE (as in Munkberg et al. 2016), RMSE, PSNR, SSIM.
//
// Policy for non-finite values: a pixel with a NaN/Inf colour channel in the test or the reference
// image is counted in ImageErrors::nonFinite and excluded from every metric (from the means of
// relMSE, RMSE and SSIM; inside SSIM windows it takes the reference's value, so it adds no
// structure). A metric with no comparable pixel left is NaN, and CompareImages throws instead.
// Only the first 3 channels (R, G, B) are compared.
#pragma once
#include <cstddef>

#include "renderer/image/image.h"

namespace texcache {

struct ImageErrors {
    double relMSE = 0, rmse = 0, psnr = 0, ssim = 0;
    size_t nonFinite = 0;  ///< pixels with a NaN/Inf channel in test or reference (excluded)
};

/// relMSE of Rousselle et al. 2011 as used by Munkberg et al. 2016: per pixel, the sum over R,G,B
/// of (test - ref)^2 / (gray(ref)^2 + eps), averaged over pixels; gray = mean of R,G,B.
double RelMSE(const Image& test, const Image& ref, double eps = 1e-3);
/// Root mean square error over the R,G,B values of all comparable pixels.
double RMSE(const Image& test, const Image& ref);
/// 20 log10(peak / RMSE) in dB; +inf for identical images.
double PSNR(const Image& test, const Image& ref, double peak = 1.0);
/// Mean SSIM (Wang et al. 2004) of what the PNG shows: each channel clamped to [0,1] and sRGB
/// encoded, then luma Y' = 0.2126 R' + 0.7152 G' + 0.0722 B'; 11x11 Gaussian window (sigma 1.5)
/// with edge-replicated borders, K1 = 0.01, K2 = 0.03, L = 1 (the 8-bit constants scaled to 1).
double SSIM(const Image& test, const Image& ref);
/// All of the above in one call; throws InputError on a size or channel-count mismatch or when
/// no pixel is finite in both images.
ImageErrors CompareImages(const Image& test, const Image& ref);
/// Per-pixel relMSE (eps 1e-3) on a log scale from 1e-4 (black) to 10 (pale yellow) through the
/// inferno colour map; excluded (non-finite) pixels are magenta. Linear values, for WriteImage.
Image FalseColorError(const Image& test, const Image& ref);

}  // namespace texcache
