// SPDX-License-Identifier: Apache-2.0
// Stereo rendering with one texture-space cache for both eyes (Munkberg et al. 2016, Sec. 6.2,
// "Shading Reuse for Stereo/VR").
//
// Design note. Texture space separates primary visibility from shading: what a texel holds is
// view-independent (AO, the diffuse light of diffuse materials, area-light visibility), so the
// second eye looks up the texels the first eye filled and shades only those it alone reaches
// (disocclusions, the strip beside the frame, texels at another mip level); view-dependent light
// (glossy lobes, per-hit NEE) is computed per hit in each eye anyway.
//   * Rig: the eyes sit eyeSeparation apart along the camera's x axis, looking parallel, with
//     off-axis (sheared) frustums that agree at the convergence distance (CameraModel::SetEye),
//     the usual stereo camera of film and VR: no vertical parallax, no keystone.
//   * Order: the left eye renders first, then the right eye reuses its cache. With progressive
//     texture space (texture_space.h) the eyes take turns pass by pass: pass k of the left eye,
//     then pass k of the right eye, then the cache begins pass k + 1 (which re-shades
//     everything). Rendering all of the left eye's passes first would leave only its last pass
//     in the cache. Each eye is the mono render of its camera with the same samples and random
//     streams (RenderOptions::firstSample), so a left eye equals a mono render of that eye, and
//     with zero separation the right eye equals the left and shades nothing.
//   * Footprints: with visible-only footprints (AO) each eye's prepass marks its own visible
//     texels, so a texel the right eye shades anew is filtered over what the right eye sees, as
//     if it rendered alone; texels both eyes see keep the left eye's value.
//   * Cost: per eye, its own RenderStats: wall and CPU seconds, rays, and the cache's counters
//     (samplesShaded and texelMisses are what that eye shaded and filtered anew).
//   * Time budgets (opt.seconds): progressive renders run pairs of passes while the next pair
//     fits; otherwise the left eye gets half the budget and the right eye its sample count.
//   * AOV layers are those of each eye's first pass (ptex ids and depths do not average).
#pragma once
#include <string>

#include "renderer/render.h"

namespace texcache {

/// Eye separation and convergence distance, in scene units.
struct StereoRig {
    float eyeSeparation = 0.0f;
    float convergence = 1.0f;
};

/// The scene camera's rig (Camera::eyeSeparation, Camera::convergence).
StereoRig StereoRigOf(const Camera& camera);

/// Throws InputError naming `where` unless the separation is finite and >= 0 and the
/// convergence finite and > 0.
void CheckStereoRig(const StereoRig& rig, const std::string& where);

/// Both eyes of a stereo render: images, AOVs and each eye's own statistics.
struct StereoResult {
    RenderResult left, right;
};

/// The cost of both eyes together (times, rays and cache traffic summed; spp of one eye).
RenderStats BothEyes(const StereoResult& r);

/// The two eyes' images side by side (left | right), for a display or a montage.
Image SideBySide(const Image& left, const Image& right);

/// Renders the left eye, then the right eye through the same texture-space cache (`cache`, or
/// one made for the pair when null and options.texture.enabled). See the note at the top.
StereoResult RenderStereo(const RenderScene& rs, const RenderOptions& options, const StereoRig& rig,
                          TextureSpaceCache* cache = nullptr);

}  // namespace texcache
