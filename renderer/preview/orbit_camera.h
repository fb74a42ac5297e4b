// SPDX-License-Identifier: Apache-2.0
// The preview's camera: an orbit around a pivot (yaw/pitch about world +Y, distance), with pan,
// dolly and WASD fly, converted to and from the scene's look-at camera.
#pragma once
#include <glm/glm.hpp>

#include "renderer/scene/scene.h"

namespace texcache::preview {

/// Axis-aligned box in world space.
struct Bounds {
    glm::vec3 lo{1e30f}, hi{-1e30f};
    bool Empty() const { return lo.x > hi.x; }
    glm::vec3 Centre() const { return 0.5f * (lo + hi); }
    float Radius() const { return Empty() ? 1.0f : 0.5f * glm::length(hi - lo); }
};

/// World bounds of one object's control cage at scene time `time` (the limit surface lies inside
/// the cage's hull, so this is a safe framing box).
Bounds ObjectBounds(const Scene& scene, int object, float time);
/// World bounds of all objects.
Bounds SceneBounds(const Scene& scene, float time);

class OrbitCamera {
public:
    /// Takes the scene camera's pose at `time`; the pivot is where the view axis passes closest
    /// to the scene's centre, so orbiting turns around what the camera looks at.
    void FromScene(const Scene& scene, float time);

    glm::vec3 Position() const;
    glm::vec3 Target() const { return target_; }
    glm::vec3 Forward() const { return glm::normalize(target_ - Position()); }
    glm::vec3 Right() const;
    glm::vec3 Up() const { return glm::cross(Right(), Forward()); }
    float FovY() const { return fovY_; }

    /// Turns around the pivot by the given angles (degrees); pitch stays within +-89 so the view
    /// never becomes parallel to the up axis.
    void Orbit(float yawDegrees, float pitchDegrees);
    /// Moves pivot and eye in the view plane by a fraction of the visible height at the pivot.
    void Pan(float dxFraction, float dyFraction);
    /// Scales the distance to the pivot (factor < 1: closer).
    void Dolly(float factor);
    /// Moves pivot and eye along the view axes (world units).
    void Fly(float forward, float right, float up);
    /// Looks at a box from the current direction, fitting its bounding sphere in the view.
    void Frame(const Bounds& b);

    /// Writes this view as a single-key look-at pose into a scene camera (fov too).
    void ToCamera(Camera* cam) const;

    bool operator==(const OrbitCamera&) const = default;

private:
    glm::vec3 target_{0.0f};
    float distance_ = 5.0f;
    float yaw_ = 0.0f, pitch_ = 0.0f;  // degrees; yaw about +Y, 0 = eye on +Z of the pivot
    float fovY_ = 40.0f;
};

}  // namespace texcache::preview
