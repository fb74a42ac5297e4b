// SPDX-License-Identifier: Apache-2.0
// The units a scene is rendered in, and the range of positions the ray tracer can take.
//
// Design note. Embree and the renderer compute in float, and float is exact under a change of
// scale by a power of two but not at its ends: cross products of derivatives overflow past
// about 1e9, products of three coordinates underflow below about 1e-13 (and every denormal is
// flushed to zero in the render threads), a handful of constants (ray offsets, degenerate-normal
// thresholds) are absolute, and Embree asserts that ray origins lie within +-1.8e18. A cage
// scaled by 1e10 lost its normals, one scaled by 1e-8 vanished and one scaled by 5e17 ended in
// Embree's assertion. So a loaded scene is moved and scaled by a power of two into render
// units: its objects span between 2^-8 and 2^24 and, when they lie far from the origin for
// their size, are centred on it. A scene already in that range is left exactly as it is (the
// bundled scenes are), and any other renders as the same scene of ordinary size would, bit for
// bit where the scale is the only change. Cages get the same treatment on their own
// (ControlCage::unitExponent), folded into their objects' transforms here.
//
// What stays out of reach is refused with one line naming the scene (CheckSceneReach): a camera
// or light too far from the objects for float to place rays between them, an object too small
// next to the rest for Embree's object space. RenderScene still refuses, at the last moment,
// any ray Embree would assert on (RenderScene::UntracedRays counts them; none should exist).
#pragma once
#include <string>

#include "renderer/scene/scene.h"

namespace texcache {

/// Rays may start at most this far from the origin, in render units (the objects span at most
/// 2^24 there). Embree takes 1.8e18; the margin is for the objects' own spaces.
inline constexpr double kMaxRenderReach = 17592186044416.0;  // 2^44

/// Moves and scales a loaded scene into render units (the design note above): object, camera,
/// quad, point and spot light poses (with point lights' radii and intensities), lens and stereo
/// distances, the AO distance; folds each cage's unitExponent into its objects' transforms; records
/// the change in scene->unitOrigin and unitScale. Throws InputError naming the scene file when the
/// objects reach beyond +-1e18 or a camera or light lies too far from them. Call before a default
/// camera is made.
void NormalizeSceneUnits(Scene* scene);

/// Throws InputError naming `where` unless every ray the scene makes can start where Embree takes
/// it: the camera (at every key, widened by `cameraSpread`: a lens radius, half an eye
/// separation), the quad, point and spot lights within kMaxRenderReach of the origin, and every
/// object large enough that rays from that far stay within Embree's range in its own space.
void CheckSceneReach(const Scene& scene, float cameraSpread, const std::string& where);

/// Why the scene's camera at scene time `time`, making a width x height image, shows none of the
/// objects: every one outside its view or behind it, or all of them within less than a pixel.
/// Empty when it may show some (the objects' bounding boxes, so "may").
std::string CameraViewProblem(const Scene& scene, float time, int width, int height);

/// A length in render units as the scene file gives it (for messages and outputs).
inline double FileLength(const Scene& scene, double renderLength) {
    return renderLength / scene.unitScale;
}

}  // namespace texcache
