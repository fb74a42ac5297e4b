// SPDX-License-Identifier: Apache-2.0
// The primary-visibility filter: a screen-space pass for the noise that defocus and motion blur
// leave once shading is noise-free (texture-space shading makes a camera sample's colour a
// filtered texel, so what still varies between a pixel's samples is which surface each one saw:
// Munkberg et al. 2016, Sec. 6, "Primary Visibility Filter").
//
// Design note. A blurred pixel's value is the sharp image convolved with its blur kernel (a
// disk of the circle of confusion, a segment of the motion over the shutter), so it carries no
// frequency above the kernel's bandwidth (Egan et al. 2009; Mehta et al. 2014 size screen-space
// Gaussians from the same bound). Averaging it with neighbours over a Gaussian a fraction
// (`scale`) of that kernel's own covariance removes sampling noise and adds little bias; a pixel
// blurred by less than 0.83 pixel (std; a circle of confusion under 1.7 pixels) keeps its value
// exactly unless a blurred surface in front of it spreads over it, so focused, static regions
// are never blurred. Kernels are anisotropic: motion blur smooths along the motion only, and
// edges across it stay sharp.
// Occlusion follows the layered methods (Munkberg et al. 2014, Hasselgren et al. 2015, which split
// a tile's samples into depth layers and composite them front to back) in a per-pixel form, the
// classification of McGuire et al. 2012 ("A reconstruction filter for plausible motion blur"): a
// neighbour in front of the pixel (a nearer layer) spreads over it with its own kernel (a blurred
// foreground covers a sharp background), any other neighbour is gathered with the pixel's own
// kernel (a sharp foreground takes nothing from the blurred background behind it). Inputs are
// pixel buffers (colour, depth, blur covariance), as the GPU filter the paper uses takes colour,
// depth and motion buffers; no per-sample storage. The full layered reconstruction filters the
// samples themselves in the light field (lens position and time per sample), which the renderer
// does not keep; once texture space has removed the shading noise, pixel buffers suffice here:
// on the bundled blur scenes this filter lowers texture-space relMSE, most where the blur is
// motion (results/blur.md, docs/stereo-and-blur.md).
//
// Cost: windows reach a neighbourhood's largest kernel (McGuire's tile-max / neighbour-max with
// tiles of the largest radius), capped at `maxRadius`; pixels no kernel reaches are copied. CPU,
// multithreaded over rows with TBB; deterministic for any thread count.
//
// Non-finite inputs: a NaN or Inf colour is never gathered (it stays contained in its pixel, and
// is replaced by its neighbours' average when it has blurred neighbours); NaN depth or blur is
// read as a sharp pixel at infinite depth.
#pragma once
#include <cmath>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace texcache {

/// Which visibility filter a render applies after shading (--visibility-filter).
enum class VisibilityFilterKind { None, Layered };
/// "none" or "layered"; throws InputError naming `where` and the valid names otherwise.
VisibilityFilterKind ParseVisibilityFilter(const std::string& name, const std::string& where);

struct VisibilityFilterSettings {
    /// Filter std as a fraction of the blur kernel's own std (per axis of its covariance).
    float scale = 0.6f;
    /// Largest window radius in pixels (cost grows with its square).
    int maxRadius = 12;
    /// Relative depth difference beyond which a neighbour is in another layer.
    float depthTolerance = 0.05f;
};

/// Pixel buffers of one frame, row-major, width x height.
struct VisibilityBuffers {
    int width = 0, height = 0;
    const float* color = nullptr;  ///< 3 per pixel (linear RGB)
    const float* depth = nullptr;  ///< 1 per pixel: distance to the first hit, +inf for a miss
    /// 3 per pixel: the covariance (xx, xy, yy, pixels^2) of the pixel's blur kernel
    /// (BlurCovariance); zeros for a sharp pixel.
    const float* blur = nullptr;
};

/// Covariance of a blur kernel in pixels^2 as (xx, xy, yy): a segment `motion` (pixels moved
/// over the shutter; a box of variance |v|^2 / 12 along it) convolved with a disk of radius
/// `coc` (variance coc^2 / 4 per axis).
inline glm::vec3 BlurCovariance(glm::vec2 motion, float coc) {
    const float d = 0.25f * coc * coc;
    return glm::vec3(d + motion.x * motion.x / 12.0f, motion.x * motion.y / 12.0f,
                     d + motion.y * motion.y / 12.0f);
}

/// Radius in pixels of a thin lens's circle of confusion for a point at distance `depth`:
/// `lensPixels` |1/focus - 1/depth|, where lensPixels is the lens radius times the film's
/// pixels per unit of tan(angle) (height / (2 tan(fovY / 2))). 0 for a pinhole or a miss.
inline float CircleOfConfusion(float depth, float lensPixels, float focusDistance) {
    if (!(lensPixels > 0.0f) || !(depth > 0.0f) || !(focusDistance > 0.0f)) return 0.0f;
    const float c = lensPixels * std::abs(1.0f / focusDistance - 1.0f / depth);
    return std::isfinite(c) ? c : 0.0f;
}

/// Filters `in.color` into `out` (3 per pixel, resized); see the design note above.
void FilterVisibility(const VisibilityBuffers& in, const VisibilityFilterSettings& settings,
                      std::vector<float>* out);

}  // namespace texcache
