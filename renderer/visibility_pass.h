// SPDX-License-Identifier: Apache-2.0
// The primary-visibility filter (filters/visibility_filter.h) on a render. Its guides (a depth
// and a blur covariance per pixel) come from a pass of one ray per pixel through the pixel
// centre, the lens centre and the middle of the shutter: the pinhole image at mid-shutter that
// the layered classification needs (what the GPU filter the paper uses takes as its depth and
// motion buffers), at the cost of one camera ray per pixel, and without asking the render for
// AOV layers (which take texture-space AO off its prepass path: 1.4x the frame time).
#pragma once
#include <vector>

#include "filters/visibility_filter.h"
#include "renderer/render.h"

namespace texcache {

/// Per-pixel guides of the visibility filter.
struct VisibilityGuides {
    std::vector<float> depth;  ///< distance along the guide ray, +inf for a miss
    std::vector<float> blur;   ///< (xx, xy, yy) covariance in pixels^2 (BlurCovariance)
};

/// Traces the guide rays of a frame of `opt`'s size and time: the depth of the surface each
/// pixel centre sees through the lens centre at mid-shutter, its motion over the shutter (the
/// point carried by its object from shutter open to close, projected by the cameras there) and
/// the thin lens's circle of confusion at that depth. Multithreaded (TBB).
VisibilityGuides TraceVisibilityGuides(const RenderScene& rs, const RenderOptions& opt);

/// Filters `image` (RGB, opt.width x opt.height) in place with guides traced for it; returns
/// the wall-clock seconds of guides and filter together. Nothing happens for None.
double ApplyVisibilityFilter(VisibilityFilterKind kind, const RenderScene& rs,
                             const RenderOptions& opt, Image* image,
                             const VisibilityFilterSettings& settings = {});

}  // namespace texcache
