// SPDX-License-Identifier: Apache-2.0
#include "renderer/preview/orbit_camera.h"

#include <algorithm>
#include <cmath>

#include "renderer/scene/scene_loader.h"

namespace texcache::preview {

namespace {

float Radians(float d) {
    return d * 0.017453292519943295f;
}
float Degrees(float r) {
    return r * 57.29577951308232f;
}

}  // namespace

Bounds ObjectBounds(const Scene& scene, int object, float time) {
    Bounds b;
    const Object& o = scene.objects[object];
    const glm::mat4 M = o.transform.Eval(time);
    for (const auto& p : scene.meshes[o.mesh].positions) {
        const glm::vec3 w = glm::vec3(M * glm::vec4(p[0], p[1], p[2], 1.0f));
        b.lo = glm::min(b.lo, w);
        b.hi = glm::max(b.hi, w);
    }
    return b;
}

Bounds SceneBounds(const Scene& scene, float time) {
    Bounds b;
    for (size_t o = 0; o < scene.objects.size(); ++o) {
        const Bounds ob = ObjectBounds(scene, int(o), time);
        if (ob.Empty()) continue;
        b.lo = glm::min(b.lo, ob.lo);
        b.hi = glm::max(b.hi, ob.hi);
    }
    return b;
}

void OrbitCamera::FromScene(const Scene& scene, float time) {
    const glm::mat4 camToWorld = scene.camera.pose.Eval(time);
    const glm::vec3 eye = glm::vec3(camToWorld[3]);
    const glm::vec3 fwd = -glm::normalize(glm::vec3(camToWorld[2]));
    const Bounds b = SceneBounds(scene, time);
    // Pivot on the view axis at the depth of the scene's centre (at least a tenth of its size
    // ahead, for an eye inside the box).
    float depth = glm::dot(b.Centre() - eye, fwd);
    depth = std::max(depth, 0.1f * b.Radius());
    target_ = eye + depth * fwd;
    distance_ = depth;
    const glm::vec3 d = (eye - target_) / distance_;
    yaw_ = Degrees(std::atan2(d.x, d.z));
    pitch_ = std::clamp(Degrees(std::asin(std::clamp(d.y, -1.0f, 1.0f))), -89.0f, 89.0f);
    fovY_ = scene.camera.fovYDegrees;
}

glm::vec3 OrbitCamera::Position() const {
    const float y = Radians(yaw_), p = Radians(pitch_);
    return target_ +
           distance_ * glm::vec3(std::cos(p) * std::sin(y), std::sin(p), std::cos(p) * std::cos(y));
}

glm::vec3 OrbitCamera::Right() const {
    return glm::normalize(glm::cross(Forward(), glm::vec3(0.0f, 1.0f, 0.0f)));
}

void OrbitCamera::Orbit(float yawDegrees, float pitchDegrees) {
    yaw_ = std::remainder(yaw_ + yawDegrees, 360.0f);
    pitch_ = std::clamp(pitch_ + pitchDegrees, -89.0f, 89.0f);
}

void OrbitCamera::Pan(float dxFraction, float dyFraction) {
    const float visible = 2.0f * distance_ * std::tan(Radians(0.5f * fovY_));
    target_ += visible * (dxFraction * Right() + dyFraction * Up());
}

void OrbitCamera::Dolly(float factor) {
    distance_ = std::clamp(distance_ * factor, 1e-4f, 1e7f);
}

void OrbitCamera::Fly(float forward, float right, float up) {
    target_ += forward * Forward() + right * Right() + up * glm::vec3(0.0f, 1.0f, 0.0f);
}

void OrbitCamera::Frame(const Bounds& b) {
    if (b.Empty()) return;
    target_ = b.Centre();
    // Distance at which the bounding sphere fits the vertical field of view, 10% margin.
    distance_ = 1.1f * b.Radius() / std::sin(Radians(0.5f * fovY_));
}

void OrbitCamera::ToCamera(Camera* cam) const {
    cam->pose.keys = {CameraLookAt(Position(), target_, glm::vec3(0.0f, 1.0f, 0.0f), "camera")};
    cam->fovYDegrees = fovY_;
}

}  // namespace texcache::preview
