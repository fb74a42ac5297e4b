// SPDX-License-Identifier: Apache-2.0
// Stereo rendering with one texture-space cache for both eyes (Munkberg et al. 2016, Sec. 6.2,
// "Shading Reuse for Stereo/VR").
//
// Design note. Shading at the camera's hits (TextureSamples::Hits) has no grid for the second
// eye to look up: each pass bins both eyes' hits into the one store (texcache/texture_store.h),
// each eye keeping its own records, and then reads each eye back from the shared bins
// (RenderEyesAtHits). The view-independent terms (AO, diffuse light) of a surface both eyes see
// then average both eyes' samples in bins of the mono render's level; each eye keeps its own
// per-hit terms and its own samples as the finest level. The bins' sums are integers, so the
// images are the same for any thread count; the time of the interleaved passes is split evenly
// between the eyes. The rest of this note is the paper's grid cache (TextureSamples::Grid).
//
// Texture space separates primary visibility from shading: what a texel holds is
// view-independent (AO, the diffuse light of diffuse materials, area-light visibility), so the
// second eye looks up the texels the first eye filled and shades only what it alone reaches;
// view-dependent light (glossy lobes, per-hit NEE) is computed per hit in each eye anyway.
//   * Rig: the eyes sit eyeSeparation apart along the camera's x axis, looking parallel, with
//     off-axis (sheared) frustums that agree at the convergence distance (CameraModel::SetEye),
//     the usual stereo camera of film and VR: no vertical parallax, no keystone.
//   * Order: the left eye renders first, then the right eye reuses its cache. With progressive
//     texture space (texture_space.h) the eyes take turns pass by pass: pass k of the left eye,
//     then pass k of the right eye, then the cache begins pass k + 1 (which re-shades
//     everything). Rendering all of the left eye's passes first would leave only its last pass
//     in the cache. Each eye renders its camera with the samples and random streams of a mono
//     render (RenderOptions::firstSample); with zero separation the right eye equals the left
//     and shades nothing.
//   * Bands. The second eye reuses the first eye's samples only while they are still in the
//     sample cache; when the left eye renders its whole frame first, its later tiles evict
//     much of what the right eye then looks up (on sunlit, path traced, the right eye re-shades
//     about a quarter of the left eye's samples with the default 64 MiB: results/stereo.md,
//     "neighbour-frames"; more at larger sizes). So the eyes take turns band
//     of rows by band of rows (RenderOptions::rowBegin/rowEnd): the left eye's band, then the
//     same rows of the right eye (the rig has no vertical parallax, so they see the same
//     surfaces). A band holds about an eighth of the sample cache's slots worth of shading,
//     sized from the left eye's rate over the bands so far: the reuse does not depend on the
//     cache size or the resolution, and a cache that holds the whole frame gets one band (the
//     whole-frame order). Visible footprints (texture-space AO by default) keep the whole-frame
//     order: each eye's footprints need its whole frame's visible texels marked first.
//   * What the second eye misses. Disocclusions and the strip beside the frame are few; most
//     misses are texels of surfaces both eyes see. eq. 1 makes a texel at most a pixel across
//     the footprint's narrow axis (less along the long one at grazing angles), so a few jittered
//     camera samples per pixel reach a random subset of a surface's texels, and a shifted eye a
//     different one: on the car (320x180, 4 spp) a quarter to a third of the second eye's texels
//     are not the first eye's at any separation above 0.01 (results/stereo.md). Two remedies
//     (StereoReuse):
//     - Texels: the right eye's visible texels are marked before the left eye renders
//       (VisibilityPrepass), so that the left eye's visible footprints shade their samples too,
//       and the right eye only filters them (a bigger sample cache then keeps them: at 64 MiB
//       its collisions evict about half of them);
//     - Neighbour (the default): a texel the first eye did not fill takes the mean of the
//       filtered texels among the 8 around it (its face and level) before filtering anew: new
//       texels fall from 50% to 7% and the second eye costs about a quarter of the first, at a
//       relMSE within a few percent of the eye rendered alone (results/stereo.md). The mean of
//       the neighbours found is a one-texel-wide blur of values already filtered over a wider
//       footprint; taking the first neighbour found instead (a shift of up to a texel) costs
//       more error (results/ablations.md, section 11).
//     Each eye's visible footprints are its own in Neighbour mode, so the left eye is exactly
//     the mono render of its camera.
//   * Cost: per eye, its own RenderStats: wall and CPU seconds, rays, and the cache's counters
//     (samplesShaded and texelMisses are what that eye shaded and filtered anew); the Texels
//     prepass of the right eye is the right eye's.
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

/// The eye separation of a rig given none: 1/30 of the convergence distance (the
/// stereographers' rule of thumb for comfortable parallax).
float DefaultEyeSeparation(float convergence);

/// Throws InputError naming `where` unless the separation is finite and >= 0 and the
/// convergence finite and > 0.
void CheckStereoRig(const StereoRig& rig, const std::string& where);

/// What the second eye takes from the first eye's cache:
///   Texels     the texels it looks up, where cached; any other texel is filtered anew from the
///              footprint's samples (those cached are reused, the rest shaded);
///   Neighbour  also, for a texel not cached, the mean of the cached texels among the 8 around
///              it (its face and level): camera samples of the two eyes land on different texels
///              of the same surface (a texel is at most a pixel across its narrow axis, so
///              jittered samples reach a random subset of them), and this skips most of those
///              filters at the price of a one-texel blur of the filtered shading.
enum class StereoReuse { Texels, Neighbour };

/// The order in which the eyes render (see Bands in the note at the top):
///   Bands   band of rows by band of rows (the default where it applies);
///   Frames  the left eye's whole frame, then the right eye's (the order of visible footprints
///           and single-pass time budgets; kept selectable for experiments and tests).
enum class StereoOrder { Bands, Frames };

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
                          TextureSpaceCache* cache = nullptr,
                          StereoReuse reuse = StereoReuse::Neighbour,
                          StereoOrder order = StereoOrder::Bands);

}  // namespace texcache
