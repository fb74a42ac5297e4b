// SPDX-License-Identifier: Apache-2.0
// The renderer's side of the screen-space stage: a frame rendered as screen::FrameBuffers (see
// screen_space/frame_buffers.h for what each buffer means), and their EXR files.
//
// What RenderFrameBuffers puts in the buffers (the decisions frame_buffers.h leaves open):
//
// * Samples. One camera ray per pixel through the pixel centre (no jitter, no lens, no motion
//   blur: the guides are exact and noise-free, and projecting `position` with `camera` lands on
//   the centre). Each of the `spp` samples (default 1: the papers' real-time setting) traces from
//   that primary hit 32 light samples without rays + one shadow ray, one specular-lobe ray (GGX
//   materials) and one diffuse-lobe ray, each continued by the path tracer below (NEE + MIS,
//   max_depth).
// * The split is unbiased: emitted + shading * visibility + glossy + indirect has the path
//   tracer's expectation (at 1 spp exactly; with spp > 1 see `visibility`). Direct light is
//   counted once: by the light sample, except that the specular lobe's share is MIS-weighted
//   (power heuristic) between the light sample (in `shading`) and the specular ray hitting the
//   light (in `glossy`, where a highlight moves like a reflection); the diffuse ray and the paths
//   below the first bounce do not count light they hit directly at their first hit.
// * emitted: light seen directly (the environment, lights, emissive surfaces), and the delta
//   lights' direct light (distant lights without angular size, point and spot lights of radius
//   0): their unshadowed term (f Le cos) times the 0/1 of a shadow ray of its own, exact at the
//   pixel centre, so the stage passes it through instead of filtering a visibility that has no
//   noise (its filters blurred a sun's hard shadow and, while the view moved, lagged it).
//   `shading` and `visibility` below are those of the other lights.
// * shading: the unshadowed direct light (f_diffuse + w_mis f_specular) Le cos / pdf. In closed
//   form where every light and lobe has one (ClosedFormShading in frame_buffers_render.cpp): the
//   diffuse lobe under quad lights (Lambert's polygon formula,
//   renderer/integrators/polygon_light.h), an environment (pi L for a constant one, degree-2
//   spherical harmonics of a map: up to ~15% off next to a sun, which only the visibility ratio
//   sees, EnvironmentMap::Irradiance), suns of some size (E f cos) and point and spot lights of
//   some size (I f cos / d^2: exact for a diffuse lobe under a sphere wholly above the horizon
//   but for the spot's falloff, taken at the centre), and a GGX lobe under those suns and
//   spheres only; never with an emissive object in the scene;
//   the ratio estimator of Heitz et al. 2018 ("Combining analytic direct illumination and
//   stochastic shadows"), with the analytic term Zhuang et al. and Zeng et al. take as the
//   noise-free factor. Elsewhere (a GGX lobe under an area light or an environment) estimated
//   per sample from 32 light samples without shadow rays (BSDF and light evaluations only): the
//   light pick stratified (a distant light's term is exact) and the point on an area light or
//   the environment from a randomly shifted R2 sequence (an environment map's from a table of
//   its samples drawn once per frame from options.seed and shared by the pixels, each reading a
//   run of it from a random start: every sample is distributed as before, but the pixels' samples
//   correlate within a frame); mean over spp. The stage takes it as
//   noise-free; the light samples' relative per-pixel error at 1 spp is ~5% RMS
//   (FrameBuffers.ShadingIsLowNoise; one light sample would be about sqrt(32) times noisier).
//   0 where no light was sampled (no lights, one-sided quad seen from behind) or every sample
//   lies below the surface.
// * visibility: with light-sampled shading, the 0/1 of one shadow ray, to one of those light
//   samples picked with probability proportional to its shading's luminance (resampling), so
//   that shading * visibility keeps the path tracer's expectation (exactly for white light,
//   consistent for coloured: the sample colours' chromaticities differ). A sample with zero
//   shading traces no shadow ray and counts as visible (1): its product is 0 anyway, and a 1
//   keeps the attached shadows of a surface turning away from the light from bleeding into lit
//   pixels when the stage filters visibility. With closed-form shading, 6 light samples are
//   taken instead of 32, their lights picked in proportion to each light's closed-form term
//   (stratified; a dim sky beside a lamp gets none; with more than 16 lights the pick stays
//   uniform), and visibility is the ratio lum(their mean) * V / lum(shading), V the
//   0/1 of the shadow ray resampled as above: its expectation is the shadowed over the
//   unshadowed light (the luminance of shading * visibility is unbiased; measured, the
//   ComposeIsUnbiased test; taking V alone is visibly biased in penumbrae, z^2 1.54 there), so
//   it is 0 where the ray was blocked and near 1, above or below, where not; it is 0 without a
//   shadow ray when all 6 samples fell where the BSDF is 0. With spp > 1 it is the mean of the
//   samples weighted by the luminance of their shading (the ratio estimator), so shading *
//   visibility is the mean of the shadowed samples for white light (consistent, not unbiased,
//   for coloured light).
// * blocker / lightSample: the first surface the shadow ray hit (quad lights block too, as in the
//   path tracer) and the sampled light point; NaN exactly where no shadow ray was blocked. With spp
//   > 1 they are those of the blocked sample with the most shading. Lights at infinity (distant,
//   environment) get the point 1e4 scene extents from the blocker along the light direction.
//   prevBlocker / prevLightSample: moved to `prevTime` by the blocker's object (or light) and by
//   the light's keyframes (an emissive object's: its object's; distant lights: the direction
//   rotated; the environment does not move). All four are left empty, and the shadow rays
//   traced as occlusion rays, when the frame's shadows did not move (shadowsStill) and
//   RenderOptions::frameBufferShadowPoints is off.
// * prevPosition, prevNormal, prevGlossyHit: left empty in such a frame with
//   RenderOptions::frameBufferPrevPoints off (each would be its current buffer).
// * glossy: GGX materials only (0 elsewhere; empty, with glossyHit and prevGlossyHit, when the
//   scene has no GGX material): the specular lobe's visible-normal-sampled ray,
//   path-traced below (light hit directly MIS-weighted, see above), traced with probability the
//   lobe's share of the reflectance (at least 1/4) and weighted by its inverse, so a dielectric
//   coat's pixels skip most of their glossy rays. glossyHit: its first hit (a surface or a quad
//   light; NaN when it left the scene, was not traced or there is no specular lobe), of the
//   first sample that hit something; prevGlossyHit: moved by that hit's object or light.
// * indirect: the diffuse lobe's cosine-sampled path (direct light at its first hit excluded),
//   times the diffuse reflectance. GGX materials have a diffuse base too: their indirect is that
//   of the base, so `albedo` is the diffuse lobe's reflectance ((1 - max F0) * albedo for GGX) and
//   indirect / albedo is the indirect irradiance / pi for every material.
// * cones (kNumCones per pixel): the radiance that the diffuse rays brought back (light that
//   bounced at least once: the `indirect` path before the reflectance), recorded with
//   screen::AddConeSample in the cone of each ray's direction and averaged over the spp, so that
//   indirect = albedo * ShadeCones(cones) and each cone's expectation is the cosine-weighted mean
//   radiance of its cell; a cone no ray fell in is 0. All six are NaN where there is no diffuse
//   ray (background, lights, a shading normal facing away); with cached indirect all six are
//   the cache's irradiance / pi (see below). A ray below the tessellated surface brings back 0
//   and still counts. Sampling density is cos/pi about the normal.
// * guides: position = primary hit (tessellated surface), normal = limit shading normal facing
//   the camera, depth = ray distance, roughness = the GGX alpha used (max(r^2, 1e-3); 0 for
//   diffuse), specular = F0 (0 for diffuse), objectId = scene object. prevPosition / prevNormal:
//   moved by the object's keyframes from the frame time to `prevTime`.
// * A quad or sphere light seen directly: `emitted` only, with position / normal / depth /
//   prevPosition / prevNormal of the light's surface (moved by its keyframes) and objectId -1
//   (not an object). The environment (and suns' discs) seen directly: `emitted` only, every guide
//   NaN / INF / -1. An emissive object: its emission in `emitted`, and every buffer as for any
//   object (its own light adds to what it reflects).
// * Texture-space shading (options.texture.enabled): the diffuse lobe of every material takes
//   `indirect` from the cache, as the path integrator does (albedo * cached indirect irradiance
//   / pi, a GGX base's albedo too; no diffuse ray; the six cones all hold the cached irradiance
//   / pi, so indirect = albedo * ShadeCones(cones) still holds and the stage's cone history keeps
//   the cached light: NaN cones would send Reliable's indirect to 0 there);
//   options.texture.cacheDirect is ignored. Under soft light only (no distant, point or spot
//   light) and with options.texture.cacheDiffuseLayer, the diffuse lobe takes all of its light
//   from the cache, direct included (its soft visibility with it): `indirect` is albedo * the
//   cached direct + indirect irradiance / pi (the cones hold it too), and `shading` is the
//   specular lobe's alone (0 on diffuse materials, visibility 1), from
//   options.texture.specularLightSamples light samples, `visibility` that lobe's. The sum keeps
//   the path tracer's expectation. Otherwise direct light stays per pixel (the split needs its
//   visibility).
//   Where the cached light comes from (options.texture.frameBufferSamples): by default (Hits) the
//   one store (texcache/texture_store.h, the cache's LightStore) that the frames' own camera hits
//   fill. Each frame, some pixels trace the diffuse lobe's path at their hit (cosine-sampled, with
//   one light sample when the cache holds direct light too: DiffuseRayLight, what a grid sample's
//   rays estimate): a pixel traces at a rate of kStoreTargetSamples over the samples behind its
//   reconstruction, at least one frame in frameBufferBudget and at most every frame (its rank in
//   a 4x4 ordered-dither pattern, shifted with the cache's frame, against the rate: the frame's
//   pixels spread evenly over the image), so the paths go first where the store holds few (new
//   surfaces, fine bins near the camera), and every pixel whose reconstruction the store backs
//   with under half a sample traces (a disocclusion, a first frame: a sample is shaded only where
//   no hit gave it one); NaN or infinite paths are dropped. Once every
//   such hit is added at its bins (hit binning's two levels, chosen once per cache,
//   kStoreFinerLevels below the still renderer's schedule, whose bias that renderer removes with
//   each pixel's own samples; under the trivial filter too, which in the still renderer bins a hit
//   at its own texel: here that texel, about a pixel, would hold one or two paths,
//   StoreFilterLevels), every pixel reads the store back through the still renderer's
//   reconstruction. Before the adds, a hit brighter than kStoreBoundRatio x the larger of the
//   median of its mesh's traced hits around it and what the store held there is scaled down to
//   that, the rest shared by those hits (BoundBrightHits): a lone path that finds a highlight or
//   the sun would reach every pixel reading its bin for as many frames as the decay keeps it.
//   Between frames the store decays by 1 - (1 - temporalAlpha) / frameBufferBudget while an
//   object or a light moves (a bin then holds 1 / (1 - alpha) samples of each of its pixels, as a
//   grid texel's history holds that many frames, and what moved fades from the bins that saw it),
//   and not at all while nothing does, however the camera moves, nor while
//   TextureSpaceCache::Refresh says the view is still (a running mean, which converges: the
//   diffuse light it holds does not depend on the view), unless the store holds more than twice
//   its first table's blocks (a long flight: eq. 6 then lets the bins no longer seen fade and the
//   table release them as it grows); an edited object's bins are forgotten
//   (TextureSpaceCache::InvalidateObject). A running mean of bins converges to the bins' blurred
//   value, not the pixel's, so while the view is still every pixel traces its path every frame
//   (kStillStoreBudget) and also keeps its own traced paths' light
//   (TextureSpaceCache::StillOwnLight: their mean, the spread of their luminance and their
//   count, as traced, before the bound; NaN or infinite paths are dropped; released while the view
//   moves, started again after a move, a resize, an animation's frame or an edit), and its
//   read-back is the store's reconstruction moved towards its own mean by 1 - CoarseWeight of their
//   difference and of the own mean's variance, each summed over the 5x5 pixels around it
//   (BlendWithOwnLight): the step from the bins to the pixels' own samples that the still renderer
//   takes (CombineWithOwnSamples), so that with few own samples it reads the bins and with many,
//   where the bins are biased (an edge, a contact shadow within a bin), its own mean, and the error
//   keeps falling. The store's integer sums are read only between the frame's phases, and a
//   pixel's own sums take one path a frame: the image is the same for any thread count. With Grid,
//   the paper's grid samples, each shaded lazily with diffuseLayerPaths (or indirectSamples) paths
//   of its own on a miss. The specular lobe's ray takes the diffuse lobe's light at its hit from
//   the cache too (that lobe's indirect light, or with cacheDiffuseLayer all of it), as a camera
//   hit's would; only the hit's specular lobe goes on. From the store, so does the first hit of a
//   path traced into it: both read the store's block of 4x4 bins for that point at the camera's
//   level where it holds four samples or more, and go on as paths elsewhere (surfaces the camera
//   does not see), so the store's frame buffers never allocate the grid (unless cachedVisibility
//   asks for it). From the grid, the texel is chosen for a footprint of the lobe's width. The
//   paths' light samples of an environment map come from the frame's table of the map's samples
//   (Context::envTable), as the pixels' own do.
// * cachedVisibility (options.texture.enabled and options.texture.cachedVisibility; empty
//   otherwise): for diffuse materials facing the camera, the texel-cache lookup of the pixel's
//   texel in the object's visibility grids (TextureSpaceCache::VisibilityTexelOf; a cache
//   sample is ShadeVisibilitySample: the shadowed / unshadowed irradiance ratio of
//   options.texture.shadowSamples stratified light samples of all lights, one shadow ray each),
//   filtered by the object's filter kind over a footprint of options.texture.visibilityRadius
//   (5x5 by default: shadows have edges) and blended over frames with temporalAlpha; NaN
//   elsewhere (background, lights, GGX materials, whose visibility is weighted by a
//   view-dependent lobe). It is the diffuse lobe's cosine-weighted ratio where `visibility` is
//   weighted by the BSDF, and the filter blurs shadow edges over its footprint (measured:
//   results/disocclusion.md). The stage uses it only where its visibility has no history.
#pragma once
#include <string>

#include "renderer/render.h"
#include "renderer/scene/scene.h"
#include "screen_space/frame_buffers.h"

namespace texcache {

class AtomicFiles;

/// Renders the frame at options.frameTime (the time `scene` was built for) into `out` (every
/// buffer filled, the cones only with options.frameBufferCones; sizes options.width x
/// options.height, options.spp samples per pixel); "prev"
/// buffers are moved to `prevTime` (usually frameTime - 1/fps). options.integrator, seconds,
/// aovs and the camera's lens and shutter are ignored. With options.texture.enabled the cache
/// is `cache`, or one made for this frame when null. Throws InputError on bad options.
RenderStats RenderFrameBuffers(const RenderScene& scene, const RenderOptions& options,
                               float prevTime, screen::FrameBuffers* out,
                               TextureSpaceCache* cache = nullptr);

/// Why frame buffers cannot honour `cam` (they trace every pixel through the lens centre at
/// shutter open: exact guides for the screen-space stage), e.g. "its camera has a lens
/// (lens_radius 0.05): ..."; empty when they can (pinhole, closed shutter).
std::string FrameBufferCameraProblem(const Camera& cam);

/// The screen-space camera of `cam` at scene time `time` for a width x height raster: the pinhole
/// projection CameraModel traces (lens and shutter ignored).
screen::FrameCamera MakeFrameCamera(const Camera& cam, float time, int width, int height);

/// A frame's colours (FrameBuffers::Compose(), a denoised image) as a width x height RGB image.
Image ToImage(const std::vector<glm::vec3>& colours, int width, int height);

/// Writes a frame's buffers as one multi-layer EXR (32-bit float, lossless): R,G,B = Compose(),
/// then a layer per buffer ("shading.R", "visibility.Y", "position.X", "objectId.Y", "cone3.G",
/// ...; empty buffers are left out) and the camera and time as header attributes
/// ("texcache:worldToClip", "texcache:cameraPosition", "texcache:time"). Writes a temporary file
/// and renames it over `path` (with a `group`: the group's Commit() does). Throws InputError
/// naming the path.
void WriteFrameBuffers(const std::string& path, const screen::FrameBuffers& fb,
                       AtomicFiles* group = nullptr);

/// Reads a file WriteFrameBuffers wrote (missing layers stay empty); throws InputError naming the
/// path when it cannot be read, claims a size it cannot hold (CheckImageSizeClaim) or lacks the
/// camera attributes.
screen::FrameBuffers ReadFrameBuffers(const std::string& path);

}  // namespace texcache
