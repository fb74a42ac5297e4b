// SPDX-License-Identifier: Apache-2.0
// The primary-visibility filter (filters/visibility_filter.h) on a render. Its guides (a depth
// and a blur covariance per pixel) come from 4 rays per pixel through the pixel centre, 4 points
// of the lens and 4 times of the shutter (what the GPU filter the paper uses takes as its depth
// and motion buffers), at the cost of 4 camera rays per pixel (0.1-0.2 CPU s at 480x270), and
// without asking the render for AOV layers: those take texture-space AO off its prepass path,
// which makes the frame cost about 1.4x as much. With one ray through the lens centre at
// mid-shutter, the ground seen through a moving torus's hole reads as sharp and keeps its noise
// (docs/stereo-and-blur.md; results/blur.md, alternatives 2 and 3).
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

/// Traces the guide rays of a frame of `opt`'s size and time. A pixel takes the nearest surface
/// its rays see and the widest blur among them: the surface's motion over the shutter (the point
/// carried by its object from shutter open to close, projected by the cameras there) and the
/// thin lens's circle of confusion at its distance. Multithreaded (TBB).
VisibilityGuides TraceVisibilityGuides(const RenderScene& rs, const RenderOptions& opt);

/// Filters `image` (RGB, opt.width x opt.height) in place with guides traced for it; returns
/// the wall-clock seconds of guides and filter together. Nothing happens for None.
double ApplyVisibilityFilter(VisibilityFilterKind kind, const RenderScene& rs,
                             const RenderOptions& opt, Image* image,
                             const VisibilityFilterSettings& settings = {});

}  // namespace texcache
