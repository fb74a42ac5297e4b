// SPDX-License-Identifier: Apache-2.0
// The primary-visibility filter (filters/visibility_filter.h) on a render: the pixel blur it
// needs comes from the render's depth and motion layers and the camera's thin lens, so the pass
// asks the render for those layers and drops again the ones its caller did not ask for.
#pragma once
#include "filters/visibility_filter.h"
#include "renderer/render.h"

namespace texcache {

class VisibilityPass {
public:
    /// A pass of `kind` for renders with `opt`, which gets the depth and motion layers added
    /// (none for VisibilityFilterKind::None).
    VisibilityPass(VisibilityFilterKind kind, RenderOptions* opt,
                   const VisibilityFilterSettings& settings = {});

    /// Filters `r->beauty` of a render of `scene` with the options given to the constructor
    /// (after it changed them), then drops the layers the caller had not asked for. Returns the
    /// seconds the filter took (0 for None).
    double Apply(const Scene& scene, const RenderOptions& opt, RenderResult* r) const;

    /// Per-pixel blur covariance (xx, xy, yy in pixels^2) of a render with depth and motion
    /// layers: the motion over the shutter and the thin lens's circle of confusion at the
    /// pixel's mean depth.
    static std::vector<float> BlurOf(const Scene& scene, const RenderOptions& opt,
                                     const RenderResult& r);

private:
    VisibilityFilterKind kind_;
    VisibilityFilterSettings settings_;
    AovFlags asked_;
};

}  // namespace texcache
