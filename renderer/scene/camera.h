// SPDX-License-Identifier: Apache-2.0
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>

#include <glm/glm.hpp>

#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene.h"

namespace texcache {

/// A perspective (pinhole or thin-lens) camera posed at one scene time.
class CameraModel {
public:
    /// Poses `cam` at scene time `time` for an image of width x height pixels.
    CameraModel(const Camera& cam, float time, int width, int height);

    /// Primary ray through film position (px, py) in pixels (y down), lens sample in [0,1)^2,
    /// with differentials for one-pixel steps in x and y.
    Ray Generate(float px, float py, glm::vec2 lens, RayDifferentials* diff) const {
        Ray ray;
        Generate(px, py, lens, &ray, diff);
        return ray;
    }
    /// The same, written into `*ray` field by field: the renderer's camera rays (see below).
    ///
    /// Why in place and inline: returned by value from an out-of-line call, the Ray is built on
    /// the stack with 4- and 8-byte stores and copied out with 16-byte loads, which the CPU
    /// cannot forward from the pending stores; in a frame whose camera rays all miss, perf puts
    /// over a quarter of the CPU time on those loads.
    void Generate(float px, float py, glm::vec2 lens, Ray* ray, RayDifferentials* diff) const {
        if (!(lensRadius_ <= 0.0f)) {
            *ray = GenerateThinLens(px, py, lens, diff);
            return;
        }
        const glm::vec3 d = dirBase_ + px * dirX_ + py * dirY_;
        ray->org = eye_;
        ray->dir = glm::normalize(d);
        ray->tnear = 0.0f, ray->tfar = 1e30f, ray->time = 0.0f;
        if (diff) {
            diff->dOdx = diff->dOdy = glm::vec3(0.0f);
            diff->dDdx = glm::normalize(d + dirX_) - ray->dir;
            diff->dDdy = glm::normalize(d + dirY_) - ray->dir;
        }
    }
    /// Generate for n pinhole rays at film positions (px[i], py[i]) (IsPinhole(); no
    /// differentials), written field by field into rayAt(i): the same rays bit for bit, with
    /// the normalizes in one loop the compiler vectorizes. One ray at a time, the sqrt and the
    /// division behind it are a quarter of a sky-only frame's CPU time (`perf annotate`).
    template <typename RayAt>
    void GeneratePinhole(const float* px, const float* py, size_t n, RayAt&& rayAt) const {
        constexpr size_t kChunk = 64;
        float dx[kChunk], dy[kChunk], dz[kChunk];
        for (size_t b = 0; b < n; b += kChunk) {
            const size_t m = std::min(kChunk, n - b);
            // As glm evaluates dirBase_ + px * dirX_ + py * dirY_ and normalize (v times
            // 1 / sqrt(dot(v, v)), the dot summed x, y, z): the same roundings.
            for (size_t i = 0; i < m; ++i) {
                const float u = px[b + i], v = py[b + i];
                dx[i] = (dirBase_.x + u * dirX_.x) + v * dirY_.x;
                dy[i] = (dirBase_.y + u * dirX_.y) + v * dirY_.y;
                dz[i] = (dirBase_.z + u * dirX_.z) + v * dirY_.z;
            }
            for (size_t i = 0; i < m; ++i) {
                const float inv = 1.0f / std::sqrt((dx[i] * dx[i] + dy[i] * dy[i]) + dz[i] * dz[i]);
                dx[i] *= inv, dy[i] *= inv, dz[i] *= inv;
            }
            for (size_t i = 0; i < m; ++i) {
                Ray& ray = rayAt(b + i);
                ray.org = eye_;
                ray.dir = glm::vec3(dx[i], dy[i], dz[i]);
                ray.tnear = 0.0f, ray.tfar = 1e30f, ray.time = 0.0f;
            }
        }
    }
    /// The width of a pixel's footprint at distance `t` along a camera ray, across the ray: t
    /// times a pixel's angle at the image centre, widened to a thin lens's circle of confusion
    /// (as RenderScene::Interact widens differentials). An isotropic stand-in for ray
    /// differentials where only a level of detail is wanted (hit-binned AO,
    /// texture_space/hit_binning.cpp).
    float FootprintAt(float t) const {
        const float w = t * 2.0f * tanHalfY_ / float(height_);
        if (!(lensRadius_ > 0.0f) || !(focusDistance_ > 0.0f)) return w;
        return std::max(w, lensRadius_ * std::abs(1.0f - t / focusDistance_));
    }
    /// World point -> film position in pixels (x right, y down); false when behind the camera.
    bool Project(glm::vec3 world, glm::vec2* film) const;

    glm::vec3 Position() const { return eye_; }
    /// True without a lens: every ray leaves Position() (Project is then exact for them).
    bool IsPinhole() const { return lensRadius_ <= 0.0f; }
    /// Makes this one eye of a stereo pair (renderer/texture_space/stereo.h): the eye moves
    /// `offset` along the camera's x axis and the frustum is sheared (off-axis) so that the plane
    /// at distance `convergence` projects as in the centred camera. Ray differentials do not
    /// change.
    void SetEye(float offset, float convergence);

private:
    Ray GenerateThinLens(float px, float py, glm::vec2 lens, RayDifferentials* diff) const;

    glm::mat4 camToWorld_, worldToCam_;
    // Pinhole: the unnormalized world-space direction through film position (px, py) is
    // dirBase_ + px * dirX_ + py * dirY_ (one normalize per ray, no matrix: with a matrix per
    // ray, ray generation is a tenth of a path-traced frame's profile in `texcache bench peer`).
    glm::vec3 eye_, dirBase_, dirX_, dirY_;
    float tanHalfY_, aspect_;
    int width_, height_;
    float lensRadius_, focusDistance_;
    float eyeOffset_ = 0.0f, eyeShear_ = 0.0f;  // SetEye: x shift of the eye, of the film (z = -1)
};

}  // namespace texcache
