// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/scene_units.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>

#include <glm/gtc/quaternion.hpp>

#include "renderer/scene/camera.h"
#include "texcache/error.h"

namespace texcache {

namespace {

/// Objects spanning [2^kMinExponent, 2^kMaxExponent) keep their scale (ControlCage's range).
constexpr int kMinExponent = -8, kMaxExponent = 24;
/// Objects farther from the origin than 2^kCentreExponent times their span are centred on it.
constexpr int kCentreExponent = 12;
/// Embree asserts on ray origins beyond FLT_LARGE (1.8e18, about 2^60.7) in an object's space.
constexpr double kMaxObjectSpace = 576460752303423488.0;  // 2^59

std::string Fmt(double v) {
    char buf[32];
    return std::string(buf, std::to_chars(buf, buf + sizeof buf, float(v)).ptr);
}

double MaxAbs(glm::dvec3 v) {
    return std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
}

/// `track`'s keys, an identity key added when it has none (so that a pose can be changed).
std::vector<Keyframe>& Keys(TransformTrack* track) {
    if (track->keys.empty()) track->keys.emplace_back();
    return track->keys;
}

/// Calls f(world point) for the corners of [lo, hi] posed by every key of `track` (identity
/// without keys), `unit` scaling the box first; in double.
template <typename F>
void ForPosedCorners(const TransformTrack& track, glm::dvec3 lo, glm::dvec3 hi, double unit,
                     F&& f) {
    const Keyframe identity;
    const size_t n = std::max<size_t>(track.keys.size(), 1);
    for (size_t i = 0; i < n; ++i) {
        const Keyframe& k = track.keys.empty() ? identity : track.keys[i];
        const glm::dmat3 R = glm::mat3_cast(glm::dquat(k.rotation));
        for (int c = 0; c < 8; ++c) {
            const glm::dvec3 p((c & 1 ? hi : lo).x, (c & 2 ? hi : lo).y, (c & 4 ? hi : lo).z);
            f(glm::dvec3(k.translation) + R * (glm::dvec3(k.scale) * unit * p));
        }
    }
}

void CageBox(const ControlCage& cage, glm::dvec3* lo, glm::dvec3* hi) {
    *lo = glm::dvec3(std::numeric_limits<double>::infinity());
    *hi = -*lo;
    for (const auto& p : cage.positions) {
        *lo = glm::min(*lo, glm::dvec3(p[0], p[1], p[2]));
        *hi = glm::max(*hi, glm::dvec3(p[0], p[1], p[2]));
    }
}

/// The parallelogram of a quad light as a box's corners would be: corner + {0, e1} + {0, e2}.
template <typename F>
void ForPosedLightCorners(const QuadLight& q, F&& f) {
    const Keyframe identity;
    const size_t n = std::max<size_t>(q.transform.keys.size(), 1);
    for (size_t i = 0; i < n; ++i) {
        const Keyframe& k = q.transform.keys.empty() ? identity : q.transform.keys[i];
        const glm::dmat3 R = glm::mat3_cast(glm::dquat(k.rotation));
        for (int c = 0; c < 4; ++c) {
            const glm::dvec3 p = glm::dvec3(q.corner) +
                                 (c & 1 ? glm::dvec3(q.edge1) : glm::dvec3(0.0)) +
                                 (c & 2 ? glm::dvec3(q.edge2) : glm::dvec3(0.0));
            f(glm::dvec3(k.translation) + R * (glm::dvec3(k.scale) * p));
        }
    }
}

/// "point light 2", "spot light 1": the scene's point lights by their place in the list.
std::string PointLightName(const PointLight& p, size_t i) {
    return (p.spot ? "spot light " : "point light ") + std::to_string(i + 1);
}

}  // namespace

void NormalizeSceneUnits(Scene* scene) {
    Scene& s = *scene;
    // The objects' box in the file's units, over all their keys.
    glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi = -lo;
    bool cageScaled = false;
    for (const Object& o : s.objects) {
        const ControlCage& cage = s.meshes[size_t(o.mesh)];
        cageScaled = cageScaled || cage.unitExponent != 0;
        glm::dvec3 clo, chi;
        CageBox(cage, &clo, &chi);
        ForPosedCorners(o.transform, clo, chi, std::ldexp(1.0, cage.unitExponent),
                        [&](glm::dvec3 w) { lo = glm::min(lo, w), hi = glm::max(hi, w); });
    }
    const double reach = std::max(MaxAbs(lo), MaxAbs(hi));
    if (!(reach <= 1e18))
        throw InputError(s.path, "the objects reach " + Fmt(reach) +
                                     " from the origin (beyond +-1e18): too large to frame with "
                                     "the default camera or to ray trace");
    const glm::dvec3 extent = hi - lo;
    const double span = std::max({extent.x, extent.y, extent.z});
    const int e = span > 0.0 ? std::ilogb(span) : 0;
    const double k = e >= kMinExponent && e < kMaxExponent ? 1.0 : std::ldexp(1.0, -e);
    const glm::dvec3 origin = reach > std::ldexp(std::max(span, 1e-300), kCentreExponent)
                                  ? 0.5 * (lo + hi)
                                  : glm::dvec3(0.0);
    if (k == 1.0 && origin == glm::dvec3(0.0) && !cageScaled) return;

    const auto where = [&](const std::string& key) { return s.path + ": key '" + key + "'"; };
    // A position in render units; beyond kMaxRenderReach it would not even fit a float.
    const auto place = [&](glm::dvec3 p, const std::string& key, const char* what) {
        const glm::dvec3 r = (p - origin) * k;
        if (!(MaxAbs(r) <= kMaxRenderReach))
            throw InputError(where(key),
                             std::string(what) + " is " + Fmt(glm::length(p - 0.5 * (lo + hi))) +
                                 " from the objects, which are " + Fmt(span) +
                                 " across: too far for float to place rays between them (keep "
                                 "it within " +
                                 Fmt(kMaxRenderReach / k) + " of them)");
        return glm::vec3(r);
    };
    for (Object& o : s.objects) {
        const double unit = std::ldexp(k, s.meshes[size_t(o.mesh)].unitExponent);
        for (Keyframe& key : Keys(&o.transform)) {
            key.translation = glm::vec3((glm::dvec3(key.translation) - origin) * k);
            key.scale = glm::vec3(glm::dvec3(key.scale) * unit);
        }
    }
    Camera& cam = s.camera;
    for (Keyframe& key : cam.pose.keys)
        key.translation = place(glm::dvec3(key.translation), "camera", "the camera");
    const auto length = [&](float v, const char* key) {
        const double r = double(v) * k;
        if (!(r <= kMaxRenderReach))
            throw InputError(where(key), "value " + Fmt(v) + " is too large next to objects " +
                                             Fmt(span) + " across (at most " +
                                             Fmt(kMaxRenderReach / k) + ")");
        return float(r);
    };
    cam.lensRadius = length(cam.lensRadius, "camera.lens_radius");
    cam.eyeSeparation = length(cam.eyeSeparation, "camera.stereo.eye_separation");
    // Distances along the view: past the objects by any amount they are as good as infinite.
    cam.focusDistance = float(std::min(double(cam.focusDistance) * k, 1e30));
    cam.convergence = float(std::min(double(cam.convergence) * k, 1e30));
    s.settings.aoDistance = float(std::min(double(s.settings.aoDistance) * k, 1e30));
    for (size_t i = 0; i < s.quadLights.size(); ++i) {
        QuadLight& q = s.quadLights[i];
        ForPosedLightCorners(q, [&](glm::dvec3 w) {
            place(w, "lights", ("quad light " + std::to_string(i + 1)).c_str());
        });
        for (Keyframe& key : Keys(&q.transform)) {
            key.translation = glm::vec3((glm::dvec3(key.translation) - origin) * k);
            key.scale = glm::vec3(glm::dvec3(key.scale) * k);
        }
    }
    // Point and spot lights: their position moves with their transform, their radius is a
    // length, and their intensity keeps its irradiance (I / d^2) at distances scaled by k.
    for (size_t i = 0; i < s.pointLights.size(); ++i) {
        PointLight& p = s.pointLights[i];
        const std::string name = PointLightName(p, i);
        const glm::dvec3 at(p.position);
        ForPosedCorners(p.transform, at, at, 1.0,
                        [&](glm::dvec3 w) { place(w, "lights", name.c_str()); });
        for (Keyframe& key : Keys(&p.transform)) {
            key.translation = glm::vec3((glm::dvec3(key.translation) - origin) * k);
            key.scale = glm::vec3(glm::dvec3(key.scale) * k);
        }
        p.radius = length(p.radius, "lights");
        const glm::dvec3 intensity = glm::dvec3(p.intensity) * k * k;
        const double brightest = MaxAbs(intensity);
        if (!(brightest <= 1e30) ||
            (brightest < double(std::numeric_limits<float>::min()) && MaxAbs(p.intensity) > 0.0))
            throw InputError(where("lights"),
                             name + ": its intensity cannot be kept in float next to objects " +
                                 Fmt(span) + " across (the irradiance scales as 1/distance^2)");
        p.intensity = glm::vec3(intensity);
    }
    s.unitOrigin = origin;
    s.unitScale = k;
}

void CheckSceneReach(const Scene& scene, float cameraSpread, const std::string& where) {
    const double toFile = 1.0 / scene.unitScale;
    double reach = 0.0;
    for (const Keyframe& key : scene.camera.pose.keys) {
        const double r = MaxAbs(glm::dvec3(key.translation)) + double(cameraSpread);
        if (!(r <= kMaxRenderReach))
            throw InputError(where, "the camera reaches " + Fmt(r * toFile) +
                                        " from the objects' centre: too far for float to place "
                                        "rays (keep it within " +
                                        Fmt(kMaxRenderReach * toFile) + ")");
        reach = std::max(reach, r);
    }
    for (size_t i = 0; i < scene.quadLights.size(); ++i)
        ForPosedLightCorners(scene.quadLights[i], [&](glm::dvec3 w) {
            if (!(MaxAbs(w) <= kMaxRenderReach))
                throw InputError(where, "quad light " + std::to_string(i + 1) + " reaches " +
                                            Fmt(MaxAbs(w) * toFile) +
                                            " from the objects' centre: too far for float to "
                                            "place rays (keep it within " +
                                            Fmt(kMaxRenderReach * toFile) + ")");
            reach = std::max(reach, MaxAbs(w));
        });
    for (size_t i = 0; i < scene.pointLights.size(); ++i) {
        const PointLight& p = scene.pointLights[i];
        const glm::dvec3 at(p.position);
        ForPosedCorners(p.transform, at, at, 1.0, [&](glm::dvec3 w) {
            const double r = MaxAbs(w) + double(p.radius);
            if (!(r <= kMaxRenderReach))
                throw InputError(where, PointLightName(p, i) + " reaches " + Fmt(r * toFile) +
                                            " from the objects' centre: too far for float to "
                                            "place rays (keep it within " +
                                            Fmt(kMaxRenderReach * toFile) + ")");
            reach = std::max(reach, r);
        });
    }
    for (const Object& o : scene.objects) {
        glm::dvec3 lo, hi;
        CageBox(scene.meshes[size_t(o.mesh)], &lo, &hi);
        ForPosedCorners(o.transform, lo, hi, 1.0,
                        [&](glm::dvec3 w) { reach = std::max(reach, MaxAbs(w)); });
    }
    // In an object's own space a ray starts at inverse(M) * origin: at most (reach + |t|) / the
    // smallest scale (times sqrt(3) for the rotation) from its origin.
    for (const Object& o : scene.objects) {
        const Keyframe identity;
        const size_t n = std::max<size_t>(o.transform.keys.size(), 1);
        for (size_t i = 0; i < n; ++i) {
            const Keyframe& key = o.transform.keys.empty() ? identity : o.transform.keys[i];
            const glm::dvec3 sc = glm::abs(glm::dvec3(key.scale));
            const double smallest = std::min({sc.x, sc.y, sc.z});
            const double local =
                1.7320508075688772 * (reach + MaxAbs(glm::dvec3(key.translation))) / smallest;
            if (!(local <= kMaxObjectSpace) ||
                !(smallest >= double(std::numeric_limits<float>::min())))
                throw InputError(where, "object '" + o.name + "' is scaled by " + Fmt(smallest) +
                                            " (its cage in render units) next to "
                                            "a scene reaching " +
                                            Fmt(reach) +
                                            ": too small for the ray tracer's object space "
                                            "(Embree's range is +-1.8e18 there)");
        }
    }
}

std::string CameraViewProblem(const Scene& scene, float time, int width, int height) {
    const CameraModel camera(scene.camera, time, width, height);
    const float lens = scene.camera.lensRadius;
    double covered = 0.0;  // pixels of the image inside the objects' projected boxes
    for (const Object& o : scene.objects) {
        glm::dvec3 clo, chi;
        CageBox(scene.meshes[size_t(o.mesh)], &clo, &chi);
        const glm::mat4 M = o.transform.Eval(time);
        glm::vec3 lo(std::numeric_limits<float>::infinity()), hi = -lo;
        for (int c = 0; c < 8; ++c) {
            const glm::vec4 p(float((c & 1 ? chi : clo).x), float((c & 2 ? chi : clo).y),
                              float((c & 4 ? chi : clo).z), 1.0f);
            const glm::vec3 w(M * p);
            lo = glm::min(lo, w), hi = glm::max(hi, w);
        }
        // A lens sees a little around the pinhole's view: widen the box by its radius.
        lo -= glm::vec3(lens), hi += glm::vec3(lens);
        glm::vec2 flo(std::numeric_limits<float>::infinity()), fhi = -flo;
        int behind = 0;
        for (int c = 0; c < 8; ++c) {
            const glm::vec3 w((c & 1 ? hi : lo).x, (c & 2 ? hi : lo).y, (c & 4 ? hi : lo).z);
            glm::vec2 film;
            if (!camera.Project(w, &film)) {
                ++behind;
                continue;
            }
            flo = glm::min(flo, film), fhi = glm::max(fhi, film);
        }
        if (behind == 8) continue;  // wholly behind the camera
        if (behind > 0) return "";  // around the camera: may fill the view
        const double x0 = std::max(double(flo.x), 0.0), x1 = std::min(double(fhi.x), double(width));
        const double y0 = std::max(double(flo.y), 0.0),
                     y1 = std::min(double(fhi.y), double(height));
        if (!(x0 < x1 && y0 < y1)) continue;  // outside the image
        covered += (x1 - x0) * (y1 - y0);
    }
    if (covered >= 1.0) return "";
    return covered > 0.0 ? "the objects cover less than a pixel of the image"
                         : "the camera sees none of the objects (all are outside its view): "
                           "the image would show only the background";
}

}  // namespace texcache
