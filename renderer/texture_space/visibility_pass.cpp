// SPDX-License-Identifier: Apache-2.0
#include "renderer/texture_space/visibility_pass.h"

#include <chrono>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/integrators/sampling.h"
#include "renderer/scene/camera.h"

namespace texcache {

VisibilityGuides TraceVisibilityGuides(const RenderScene& rs, const RenderOptions& opt) {
    const Camera& cam = rs.scene().camera;
    const int W = opt.width, H = opt.height;
    const float shutter = std::max(cam.shutterClose - cam.shutterOpen, 0.0f);
    const CameraModel mid(cam, opt.frameTime + 0.5f * shutter, W, H);
    const CameraModel open(cam, opt.frameTime, W, H);
    const CameraModel close(cam, opt.frameTime + shutter, W, H);
    const float tanHalfY = std::tan(glm::radians(cam.fovYDegrees) * 0.5f);
    // The lens radius in pixels per unit of 1/depth (see CircleOfConfusion).
    const float lensPixels = cam.lensRadius * float(H) / (2.0f * tanHalfY);
    VisibilityGuides g;
    g.depth.assign(size_t(W) * H, INFINITY);
    g.blur.assign(3 * size_t(W) * H, 0.0f);
    // Guide rays per pixel: kGuides points of the lens (a ring at half its radius) and of the
    // shutter (stratified). A pixel takes the nearest surface any of them sees and the widest
    // blur of any of them: a pixel that some samples see a moving or defocused surface through
    // is blurred by it, whatever its centre ray sees (e.g. the ground through a moving torus's
    // hole).
    constexpr int kGuides = 4;
    tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
        for (int y = rows.begin(); y < rows.end(); ++y)
            for (int x = 0; x < W; ++x) {
                const size_t p = size_t(y) * W + x;
                float widest = -1.0f;
                for (int k = 0; k < kGuides; ++k) {
                    const float a = 2.0f * kPiF * (float(k) + 0.5f) / float(kGuides);
                    // Concentric mapping: (0.5, 0.5) is the lens centre; +-0.25 half the radius.
                    const glm::vec2 lens(0.5f + 0.25f * std::cos(a), 0.5f + 0.25f * std::sin(a));
                    const float time = shutter > 0.0f ? (float(k) + 0.5f) / float(kGuides) : 0.0f;
                    Ray ray = mid.Generate(float(x) + 0.5f, float(y) + 0.5f, lens, nullptr);
                    ray.time = time;
                    Hit hit;
                    if (!rs.Intersect(ray, &hit)) continue;
                    g.depth[p] = std::min(g.depth[p], hit.t);
                    glm::vec2 motion(0.0f);
                    if (shutter > 0.0f && hit.object >= 0) {
                        const glm::vec4 pObj = glm::inverse(rs.ObjectToWorld(hit.object, time)) *
                                               glm::vec4(ray.org + hit.t * ray.dir, 1.0f);
                        glm::vec2 f0, f1;
                        if (open.Project(glm::vec3(rs.ObjectToWorld(hit.object, 0.0f) * pObj),
                                         &f0) &&
                            close.Project(glm::vec3(rs.ObjectToWorld(hit.object, 1.0f) * pObj),
                                          &f1))
                            motion = f1 - f0;
                    }
                    const glm::vec3 c = BlurCovariance(
                        motion, CircleOfConfusion(hit.t, lensPixels, cam.focusDistance));
                    if (c.x + c.z > widest) {
                        widest = c.x + c.z;
                        g.blur[3 * p] = c.x, g.blur[3 * p + 1] = c.y, g.blur[3 * p + 2] = c.z;
                    }
                }
            }
    });
    return g;
}

double ApplyVisibilityFilter(VisibilityFilterKind kind, const RenderScene& rs,
                             const RenderOptions& opt, Image* image,
                             const VisibilityFilterSettings& settings) {
    if (kind == VisibilityFilterKind::None) return 0.0;
    const auto start = std::chrono::steady_clock::now();
    const VisibilityGuides g = TraceVisibilityGuides(rs, opt);
    VisibilityBuffers in;
    in.width = image->width, in.height = image->height;
    in.color = image->data.data();
    in.depth = g.depth.data();
    in.blur = g.blur.data();
    std::vector<float> out;
    FilterVisibility(in, settings, &out);
    image->data = std::move(out);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace texcache
