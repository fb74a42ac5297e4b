// SPDX-License-Identifier: Apache-2.0
#include "renderer/visibility_pass.h"

#include <chrono>
#include <cmath>
#include <stdexcept>

namespace texcache {

namespace {

const ImageLayer* FindLayer(const RenderResult& r, const char* name) {
    for (const ImageLayer& l : r.aovs)
        if (l.name == name) return &l;
    return nullptr;
}

}  // namespace

VisibilityPass::VisibilityPass(VisibilityFilterKind kind, RenderOptions* opt,
                               const VisibilityFilterSettings& settings)
    : kind_(kind), settings_(settings), asked_(opt->aovs) {
    if (kind_ == VisibilityFilterKind::None) return;
    opt->aovs.depth = opt->aovs.motion = true;
}

std::vector<float> VisibilityPass::BlurOf(const Scene& scene, const RenderOptions& opt,
                                          const RenderResult& r) {
    const ImageLayer* depth = FindLayer(r, "depth");
    const ImageLayer* motion = FindLayer(r, "motion");
    if (!depth || !motion)
        throw std::logic_error("the visibility filter needs the render's depth and motion layers");
    const Camera& cam = scene.camera;
    const float tanHalfY = std::tan(glm::radians(cam.fovYDegrees) * 0.5f);
    // The lens radius in pixels per unit of 1/depth (see CircleOfConfusion).
    const float lensPixels = cam.lensRadius * float(opt.height) / (2.0f * tanHalfY);
    const size_t n = r.beauty.NumPixels();
    std::vector<float> blur(3 * n);
    for (size_t p = 0; p < n; ++p) {
        const float coc = CircleOfConfusion(depth->image.data[p], lensPixels, cam.focusDistance);
        const glm::vec2 v(motion->image.data[2 * p], motion->image.data[2 * p + 1]);
        const glm::vec3 c = BlurCovariance(v, coc);
        blur[3 * p] = c.x, blur[3 * p + 1] = c.y, blur[3 * p + 2] = c.z;
    }
    return blur;
}

double VisibilityPass::Apply(const Scene& scene, const RenderOptions& opt, RenderResult* r) const {
    if (kind_ == VisibilityFilterKind::None) return 0.0;
    const auto start = std::chrono::steady_clock::now();
    const std::vector<float> blur = BlurOf(scene, opt, *r);
    VisibilityBuffers in;
    in.width = r->beauty.width, in.height = r->beauty.height;
    in.color = r->beauty.data.data();
    in.depth = FindLayer(*r, "depth")->image.data.data();
    in.blur = blur.data();
    std::vector<float> out;
    FilterVisibility(in, settings_, &out);
    r->beauty.data = std::move(out);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::erase_if(r->aovs, [&](const ImageLayer& l) {
        return (l.name == "depth" && !asked_.depth) || (l.name == "motion" && !asked_.motion);
    });
    return seconds;
}

}  // namespace texcache
