// SPDX-License-Identifier: Apache-2.0
#pragma once
#include <glm/glm.hpp>

#include "renderer/render_scene.h"
#include "renderer/scene.h"

namespace texcache {

/// A perspective (pinhole or thin-lens) camera posed at one scene time.
class CameraModel {
public:
    /// Poses `cam` at scene time `time` for an image of width x height pixels.
    CameraModel(const Camera& cam, float time, int width, int height);

    /// Primary ray through film position (px, py) in pixels (y down), lens sample in [0,1)^2,
    /// with differentials for one-pixel steps in x and y.
    Ray Generate(float px, float py, glm::vec2 lens, RayDifferentials* diff) const;
    /// World point -> film position in pixels (x right, y down); false when behind the camera.
    bool Project(glm::vec3 world, glm::vec2* film) const;

    glm::vec3 Position() const { return eye_; }
    /// Makes this one eye of a stereo pair (renderer/stereo.h): the eye moves `offset` along
    /// the camera's x axis and the frustum is sheared (off-axis) so that the plane at distance
    /// `convergence` projects as in the centred camera. Ray differentials do not change.
    void SetEye(float offset, float convergence);

private:
    glm::mat4 camToWorld_, worldToCam_;
    // Pinhole: the unnormalized world-space direction through film position (px, py) is
    // dirBase_ + px * dirX_ + py * dirY_ (one normalize per ray, no matrix: the camera's ray
    // generation was 10% of a path-traced frame's profile; `perf record` on `texcache bench peer`).
    glm::vec3 eye_, dirBase_, dirX_, dirY_;
    float tanHalfY_, aspect_;
    int width_, height_;
    float lensRadius_, focusDistance_;
    float eyeOffset_ = 0.0f, eyeShear_ = 0.0f;  // SetEye: x shift of the eye, of the film (z = -1)
};

}  // namespace texcache
