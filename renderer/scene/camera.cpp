// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/camera.h"

#include <cmath>

#include "renderer/integrators/sampling.h"

namespace texcache {

CameraModel::CameraModel(const Camera& cam, float time, int width, int height)
    : camToWorld_(cam.pose.Eval(time)),
      worldToCam_(glm::inverse(camToWorld_)),
      tanHalfY_(std::tan(glm::radians(cam.fovYDegrees) * 0.5f)),
      aspect_(float(width) / float(height)),
      width_(width),
      height_(height),
      lensRadius_(cam.lensRadius),
      focusDistance_(cam.focusDistance) {
    const glm::mat3 R(camToWorld_);
    eye_ = glm::vec3(camToWorld_[3]);
    dirBase_ = R * glm::vec3(-tanHalfY_ * aspect_, tanHalfY_, -1.0f);
    dirX_ = R * glm::vec3(2.0f * tanHalfY_ * aspect_ / float(width_), 0.0f, 0.0f);
    dirY_ = R * glm::vec3(0.0f, -2.0f * tanHalfY_ / float(height_), 0.0f);
}

Ray CameraModel::GenerateThinLens(float px, float py, glm::vec2 lens,
                                  RayDifferentials* diff) const {
    // Camera space: looking down -Z, +Y up; film plane at z = -1.
    const float sx = (2.0f * px / float(width_) - 1.0f) * tanHalfY_ * aspect_ - eyeShear_;
    const float sy = (1.0f - 2.0f * py / float(height_)) * tanHalfY_;
    const glm::vec3 stepX(2.0f * tanHalfY_ * aspect_ / float(width_), 0.0f, 0.0f);
    const glm::vec3 stepY(0.0f, -2.0f * tanHalfY_ / float(height_), 0.0f);
    const glm::vec3 film(sx, sy, -1.0f);
    const glm::mat3 R(camToWorld_);
    const glm::vec3 eye = eye_;

    Ray ray;
    glm::vec3 o(0.0f), d = film;
    glm::vec3 dOx(0.0f), dOy(0.0f), filmX = film + stepX, filmY = film + stepY;
    if (lensRadius_ > 0.0f) {
        // Thin lens: all rays through a film point meet at the focus plane z = -focusDistance.
        const glm::vec2 l = lensRadius_ * SampleUniformDiskConcentric(lens);
        o = glm::vec3(l, 0.0f);
        d = film * focusDistance_ - o;
        filmX = filmX * focusDistance_ - o;
        filmY = filmY * focusDistance_ - o;
    }
    const glm::vec3 dn = glm::normalize(d);
    ray.org = eye + R * o;
    ray.dir = glm::normalize(R * dn);
    if (diff) {
        diff->dOdx = dOx;
        diff->dOdy = dOy;
        diff->dDdx = R * (glm::normalize(filmX) - dn);
        diff->dDdy = R * (glm::normalize(filmY) - dn);
        // The focus plane is z = -focusDistance in camera space.
        diff->lensRadius = lensRadius_;
        diff->focusT = lensRadius_ > 0.0f && dn.z < 0.0f ? -(focusDistance_ + o.z) / dn.z : 0.0f;
    }
    return ray;
}

void CameraModel::SetEye(float offset, float convergence) {
    // The eye at x = offset sees the film point (sx, sy, -1) of the centred camera through
    // convergence * (sx, sy, -1), i.e. along (sx - offset / convergence, sy, -1): a shear.
    const glm::mat3 R(camToWorld_);
    eyeOffset_ = offset;
    eyeShear_ = offset / convergence;
    eye_ = glm::vec3(camToWorld_[3]) + R * glm::vec3(offset, 0.0f, 0.0f);
    dirBase_ = R * glm::vec3(-tanHalfY_ * aspect_ - eyeShear_, tanHalfY_, -1.0f);
}

bool CameraModel::Project(glm::vec3 world, glm::vec2* film) const {
    const glm::vec3 c = glm::vec3(worldToCam_ * glm::vec4(world, 1.0f));
    if (c.z >= -1e-6f) return false;
    const float sx = (c.x - eyeOffset_) / -c.z + eyeShear_, sy = c.y / -c.z;
    film->x = (sx / (tanHalfY_ * aspect_) + 1.0f) * 0.5f * float(width_);
    film->y = (1.0f - sy / tanHalfY_) * 0.5f * float(height_);
    return true;
}

}  // namespace texcache
