// SPDX-License-Identifier: Apache-2.0
#include "renderer/integrators/path_tracer.h"

#include <algorithm>
#include <cmath>

namespace texcache::internal {

Context::Context(const RenderScene& r, const RenderOptions& o)
    : rs(r),
      scene(r.scene()),
      opt(o),
      env(r.environment()),
      camera(r.scene().camera, o.frameTime, o.width, o.height) {
    shutterLength = scene.camera.shutterClose - scene.camera.shutterOpen;
    if (shutterLength > 0.0f) {
        cameraOpen.emplace(scene.camera, o.frameTime, o.width, o.height);
        cameraClose.emplace(scene.camera, o.frameTime + shutterLength, o.width, o.height);
        cameraMoves = scene.camera.pose.IsAnimated();
    }
    if (o.eyeOffset != 0.0f)
        for (CameraModel* m :
             {&camera, cameraOpen ? &*cameraOpen : nullptr, cameraClose ? &*cameraClose : nullptr})
            if (m) m->SetEye(o.eyeOffset, o.eyeConvergence);
    hitRect = {0, 0, o.width, o.height};
    glm::vec3 lo, hi;
    if (o.cullMissingPixels && camera.IsPinhole() && !cameraMoves && r.StaticBounds(&lo, &hi)) {
        // A pinhole's rays through a pixel's square meet the box only if the square meets the
        // box's projection, inside the bounds of its corners' projections (all in front).
        glm::vec2 fmin(INFINITY), fmax(-INFINITY);
        bool front = true;
        for (int k = 0; k < 8 && front; ++k) {
            const glm::vec3 p(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z);
            glm::vec2 f;
            front = camera.Project(p, &f) && std::isfinite(f.x + f.y);
            fmin = glm::min(fmin, f), fmax = glm::max(fmax, f);
        }
        // Two pixels of margin: float rounding of the projection and of Generate's rays.
        // Clamped before converting: a box far off screen projects to any float.
        auto px = [](float v, int size) { return int(std::clamp(v, -4.0f, float(size) + 4.0f)); };
        if (front)
            hitRect = {std::clamp(px(std::floor(fmin.x), o.width) - 2, 0, o.width),
                       std::clamp(px(std::floor(fmin.y), o.height) - 2, 0, o.height),
                       std::clamp(px(std::ceil(fmax.x), o.width) + 2, 0, o.width),
                       std::clamp(px(std::ceil(fmax.y), o.height) + 2, 0, o.height)};
    }
    if (!IntegratorUsesLights(o.integrator)) return;
    for (const DistantLight& d : scene.distantLights) {
        const glm::mat3 M(d.transform.Eval(o.frameTime));
        distantDir.push_back(-glm::normalize(M * d.direction));
        distantE.push_back(d.irradiance);
        suns.emplace_back(distantDir.back(), d.irradiance, d.angleDegrees);
        sunDiscs |= !suns.back().IsDelta();
    }
    for (const PointLight& p : scene.pointLights)
        spheres.emplace_back(p, p.transform.Eval(o.frameTime));
    emitterOf.assign(scene.objects.size(), -1);
    for (size_t i = 0; i < scene.objects.size(); ++i) {
        const Object& obj = scene.objects[i];
        if (!obj.Emissive()) continue;
        MeshEmitter e(int(i), r.QuadCorners(int(i)), obj.emission, obj.emissionTwoSided);
        if (!(e.Area() > 0.0f)) continue;  // nothing to sample (every face a hole)
        emitterOf[i] = int(emitters.size());
        emitters.push_back(std::move(e));
    }
    for (const QuadLight& q : scene.quadLights) {
        const glm::mat4 M = q.transform.Eval(o.frameTime);
        Quad w;
        w.corner = glm::vec3(M * glm::vec4(q.corner, 1.0f));
        w.e1 = glm::mat3(M) * q.edge1;
        w.e2 = glm::mat3(M) * q.edge2;
        const glm::vec3 c = glm::cross(w.e1, w.e2);
        w.area = glm::length(c);
        w.n = c / w.area;
        w.L = q.radiance;
        w.twoSided = q.twoSided;
        quads.push_back(w);
    }
    numLights =
        int(quads.size() + distantDir.size() + spheres.size() + emitters.size()) + (env ? 1 : 0);
    if (env) lightSampling = o.lightSampling;
}

glm::vec3 LiAO(const Context& c, const Ray& ray, const SurfaceInteraction& si,
               const PixelSequence& seq, uint64_t first, RayCounts& rays) {
    // The rays leave one point: traced as packets of up to 16 (RenderScene::Occluded16).
    Ray batch[16];
    bool blocked[16];
    int open = 0, queued = 0;
    auto flush = [&] {
        c.rs.Occluded16(batch, queued, blocked);
        for (int k = 0; k < queued; ++k) open += !blocked[k];
        rays.shadow += uint64_t(queued);
        queued = 0;
    };
    ForEachAoRay(c, ray, si, seq, first, [&]() -> Ray& {
        if (queued == 16) flush();
        return batch[queued++];
    });
    flush();
    return glm::vec3(float(open) / float(c.opt.aoSamples));
}

}  // namespace texcache::internal
