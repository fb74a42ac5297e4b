// SPDX-License-Identifier: Apache-2.0
// What a render is asked to do (RenderOptions, with its texture-space shading settings) and what
// it reports (RenderStats). Plain data, below the renderers and the cache adapter, so that the
// scene loader, the command line and the preview fill one struct.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "filters/texture_filters.h"
#include "renderer/integrators/integrator_kind.h"
#include "renderer/scene/scene.h"
#include "texcache/record_cache.h"
#include "texcache/shading_cache.h"

namespace texcache {

class RankGroup;

/// Which texels of a filter footprint a render shades and averages.
///   Visible  only those the render's camera rays reach (a prepass traces the camera rays and
///            marks them: texcache/visible_texels.h), point-symmetric for the averaging filters.
///            A 21x21 window then shades little more than no filter, where the full window
///            shades five times as many samples (results/filter_size.md), at lower error: AO
///            has sharp detail (contact shadows), and the hidden texels a full window averages
///            in are biased, not just costly.
///   All      every texel of the window (the paper's footprint). Smooth, noisy signals gain from
///            the unseen texels: they are still samples of nearly the same shading (path-traced
///            indirect light on sunlit.json: docs/texture-space.md, "Visible footprints").
///   Auto     Visible for ambient occlusion, All for the direct and path integrators: the
///            paper's footprint where the evidence is mixed (visible footprints win on
///            sunlit-indirect's grid filters and lose on car-diffuse and chess-diffuse in
///            `texcache experiment speed-vs-error`; docs/texture-space.md has the figures).
enum class FootprintMode { Auto, Visible, All };
/// Whether footprints of `mode` keep only the texels the camera sees: Visible, and Auto for AO.
bool VisibleOnly(FootprintMode mode, IntegratorKind integrator);
/// "auto", "visible" or "all"; throws InputError naming `where` and the valid names otherwise.
FootprintMode ParseFootprintMode(const std::string& name, const std::string& where);
/// "auto, visible, all" (for help texts and menus).
std::string FootprintModeNames();

/// Where texture-space ambient occlusion and path-traced diffuse light shade (--ts-samples):
///   Grid  the paper's: a sample per texel of the footprint, at its limit point (found again
///         with a snap ray), shaded on demand and reconstructed by the material's filter.
///   Hits  at the camera's own hits, as per-hit shading shades them (same rays, same random
///         numbers), added up per bin of a coarser level of the same grids and read back by a
///         bilinear reconstruction over the 2x2 bins around each hit (the renderer's AoHitsBin,
///         PathHitsTrace): no limit evaluation, snap ray or footprint gather, and every ray traced
///         lands in some bin. The path integrator bins the light its diffuse hits receive (all
///         of it, or its indirect part: TextureSpaceOptions::cacheDirect) and applies each hit's
///         albedo when it reads the bins; a glossy hit bins its diffuse base's light and keeps
///         its specular lobe per hit; the direct integrator bins its light when cacheDirect.
///         The bins lie HitBinLevels above the hit's texel (HitLightLevels for diffuse light:
///         from the pass's measured noise; fewer as rays per pixel grow), and each pixel's
///         result moves towards its own samples' mean where the bins' bias shows
///         (texture_space.h argues why the result converges at per hit's rate). One pass per
///         render: passSpp does not apply.
/// The command line's `--ts-samples auto` (its default) takes Hits for AO, path and cached direct
/// light unless a filter, a filter radius or temporal accumulation is asked for (those belong to
/// the grid); the API's default is the paper's Grid. At one ray per hit or sample the grid
/// costs several times per-hit AO's CPU time, which no filter's gain makes up, while hits cost
/// little more than per hit (results/speed_vs_error.md, methods ts-hits and ts-normal).
enum class TextureSamples { Grid, Hits };
/// "grid" or "hits"; throws InputError naming `where` and the valid names otherwise.
TextureSamples ParseTextureSamples(const std::string& name, const std::string& where);

/// How the direct and path integrators sample an environment light at camera hits on glossy
/// materials (Munkberg et al. 2016, Sec. 6; renderer/integrators/product_sampling.h):
///   Mis   light sampling (the map's luminance) and BSDF sampling, combined by MIS;
///   Pis   product importance sampling: a product sampling record (PSR) of lobe x environment
///         built at every hit, MIS-combined with BSDF sampling;
///   Cpis  the same records built per texel and cached in texture space (a RecordCache), so the
///         hits of a texel share one.
enum class LightSampling { Mis, Pis, Cpis };
/// "mis", "pis" or "cpis"; throws InputError naming `where` and the valid names otherwise.
LightSampling ParseLightSampling(const std::string& name, const std::string& where);
/// "mis, pis, cpis".
std::string LightSamplingNames();
/// The name ParseLightSampling takes.
const char* LightSamplingName(LightSampling s);

/// Texture-space shading settings of a render (command line / scene file).
struct TextureSpaceOptions {
    bool enabled = false;  ///< --shading texture
    TextureFilterKind filter = TextureFilterKind::Normal;
    int radius = -1;            ///< footprint (2r+1)^2; -1: the filter's default (see below)
    float cosThreshold = 0.9f;  ///< normal filter: keep taps with cos > threshold
    int indirectSamples = 1;    ///< paths per cached indirect sample
    /// Path integrator: diffuse materials cache their direct light too (one NEE sample per
    /// cached path), not just indirect. Both are view-independent for a diffuse surface, but
    /// direct light has the sharp shadows: filtering them blurs hard shadow edges (on
    /// sunlit.json the 13x13 normal filter more than doubles the relMSE of the unfiltered cache:
    /// docs/texture-space.md, "Which light is cached"), so this is for soft lighting
    /// (environment, large area lights) and off by default.
    bool cacheDirect = false;
    /// With cacheDirect and samples at the hits: the direct light of delta lights (point and
    /// spot lights without a radius, distant lights without an angular size), whose shadows are
    /// sharp, stays per hit, and only soft lights' is binned (`--cached-light auto` on a scene
    /// with both kinds: CachedLightOptions). The grid ignores it (it caches all direct light).
    bool deltaDirectPerHit = false;
    int shadowSamples = 4;  ///< shadow rays per cached visibility sample (soft shadows)
    /// Screen-space frame buffers (RenderFrameBuffers): also fill FrameBuffers::cachedVisibility
    /// for diffuse materials from a cached visibility (shadowSamples shadow rays per sample
    /// towards all lights, filtered and accumulated like the other cached terms), which the
    /// stage takes where its visibility has no history (disocclusions). The cache then keeps a
    /// second set of grids per object for it. Off by default: see results/disocclusion.md.
    bool cachedVisibility = false;
    /// Footprint radius of the cached visibility's filter (the object's filter kind), -1 for
    /// the object's own radius as the other cached terms. Shadows have edges the other terms
    /// lack: on anim_disocclusion a 5x5 footprint gives the lowest direct-light RMSE over
    /// frame 0, below 1x1, 13x13 and the stage's own spatial filter, at less than the 13x13's
    /// cost (`texcache experiment disocclusion --out DIR`; results/disocclusion.md).
    int visibilityRadius = 2;
    /// Screen-space frame buffers under soft light only (no distant, point or spot light): the
    /// diffuse lobe (of GGX materials too) takes all of its light, direct and indirect, from
    /// the cache (diffuseLayerPaths cosine paths, each with one light sample, per cached sample),
    /// and `shading` is the specular lobe's alone, from specularLightSamples light samples a
    /// pixel (frame_buffers_render.h). Off: the diffuse lobe's direct light stays per pixel.
    bool cacheDiffuseLayer = true;
    int diffuseLayerPaths = 2;
    int specularLightSamples = 8;
    /// Screen-space frame buffers: where the diffuse lobe's cached light comes from. Hits: the
    /// one store (texcache/texture_store.h) filled from the frame's own camera hits, one pixel
    /// in frameBufferBudget a frame (a pattern that rotates over frames) where the store holds
    /// many samples, more where it holds few, read back by hit binning's reconstruction
    /// (frame_buffers_render.h). Grid: the paper's grid samples, each shaded lazily with paths
    /// of its own.
    TextureSamples frameBufferSamples = TextureSamples::Hits;
    /// One pixel in this many traces its diffuse lobe's path into the store each frame where the
    /// store holds many samples (1, 2, 4, 8 or 16: an ordered-dither pattern of the pixels);
    /// where it holds few, more do (frame_buffers_render.h).
    int frameBufferBudget = 8;
    /// Where AO shades: see TextureSamples. --ts-samples auto|grid|hits.
    TextureSamples samples = TextureSamples::Grid;
    /// Which texels a footprint keeps: see FootprintMode. --footprint auto|visible|all.
    FootprintMode footprint = FootprintMode::Auto;
    /// Temporal accumulation across frames (eq. 6): weight of the history, 0 = off. Texels then
    /// keep a history table the size of the texel cache.
    float temporalAlpha = 0.0f;
    /// Progressive texture space (see texture_space.h): a render of more camera samples than
    /// this runs passes of this many, each re-shading the cache with fresh random numbers,
    /// sample positions jittered inside their texels and a filter radius shrinking with the pass
    /// count, so that error keeps falling with the budget. 0 = one pass (the paper's cache,
    /// shaded once). Off with temporal accumulation, which accumulates over frames instead,
    /// and with samples at the hits (TextureSamples::Hits), which bin a render in one pass.
    int passSpp = 4;
    CacheSettings cache;
    /// Mip-0 texel size as a fraction of each object's bounding-box diagonal; eq. 1 then picks
    /// the level whose texels are about a pixel.
    float texelFraction = 1.0f / 4096.0f;
    /// Benchmark baseline: the cached term is replaced by this constant (no lookup at all) when
    /// >= 0, so a frame measures primary visibility and the uncached terms alone.
    float constantTerm = -1.0f;
};

/// Throws InputError when a filter radius is negative or larger than the footprint allows.
void CheckFilterRadius(int radius, const std::string& where);
/// The paper's footprint for each filter: 13x13 normal-weighted (Sec. 6.1), 21x21 Gaussian (its
/// "20x20" centred on the texel), 17x17 regression, 17x17 soft shadows; 1x1 without a filter.
int DefaultFilterRadius(TextureFilterKind kind);

/// Texture-space cache tables sized to a frame, for a render that gives no size: the sample and
/// texel tables' bytes for `views` images of width x height rendered with `integrator` and
/// footprint mode `footprint`, between 4 MiB and the paper's fixed 64 MiB. Eq. 1 picks texels
/// of about a pixel, so a frame looks up about as many texels as it has pixels (car AO,
/// 480x270, 4 spp: 1.8 per pixel) and shades as many samples with footprints of visible texels
/// (AO: 1.8), several times more with footprints of every texel of the window (direct and path
/// light; car path 640x360: 5.6 per pixel). The tables are zeroed when made, which at the fixed
/// 64 MiB takes longer than a small render itself (docs/cache.md, "Memory budget").
void SizeCachesToFrame(CacheSettings* cache, int width, int height, int views,
                       IntegratorKind integrator, FootprintMode footprint);

/// Extra per-pixel layers written beside the beauty image; none are allocated unless asked for.
struct AovFlags {
    bool albedo = false, normal = false, depth = false, ptex = false, motion = false;
    bool Any() const { return albedo || normal || depth || ptex || motion; }
};

/// One pixel's texel-cache traffic in a frame (texture-space shading): what its camera samples'
/// lookups found and how many samples their misses shaded.
struct PixelCacheCounts {
    uint32_t lookups = 0, texelHits = 0, samplesShaded = 0;
};

/// The visibility prepass of visible-only footprints (FootprintMode::Visible):
///   Own   the set starts empty and holds this render's texels (a mono render);
///   Keep  this render marks its texels on top of the set an earlier render left;
///   Only  as Keep, and nothing is shaded (the image stays black): marks for a render to come.
/// Stereo (renderer/texture_space/stereo.h) marks the right eye's texels (Only), then renders the
/// left eye (Keep), whose footprints then shade the samples the right eye will look up, then the
/// right.
enum class VisibilityPrepass { Own, Keep, Only };

struct RenderOptions {
    IntegratorKind integrator = IntegratorKind::Path;
    int width = 640, height = 360;
    int spp = 16;          ///< samples per pixel (a cap when seconds > 0)
    float seconds = 0.0f;  ///< time budget; 0 = render exactly spp
    uint64_t seed = 0;
    int maxDepth = 5;
    int aoSamples = 1;
    /// Direct and path integrators: light paths continued from each camera hit (splitting). With
    /// the same spp and seed, renders then share their camera rays and differ in shading only,
    /// which isolates shading error (Munkberg et al. Fig. 7 fix the primary positions likewise).
    int hitSamples = 1;
    float aoDistance = 1e30f;
    float frameTime = 0.0f;  ///< scene time at shutter open
    /// Every camera ray through its pixel's centre (no antialiasing), as the screen-space frame
    /// buffers trace them (frame_buffers_render.h): for comparing the two pixel by pixel.
    bool pixelCentre = false;
    /// Screen-space frame buffers (RenderFrameBuffers): fill FrameBuffers::cones, six cones of
    /// indirect light a pixel (72 bytes, the largest buffer), which only the stage's cone path
    /// reads (screen::DenoiserSettings::indirectCones) and a frame-buffer file keeps. Off: the
    /// buffer stays empty, and no pixel spends a write or a cone sample on it.
    bool frameBufferCones = true;
    /// Screen-space frame buffers: fill the shadow rays' blocker and light points
    /// (FrameBuffers::blocker, prevBlocker, lightSample, prevLightSample: 48 bytes a pixel), which
    /// the stage's shadow motion vectors read. Off: in a frame whose shadows stayed where they
    /// were (FrameBuffers::shadowsStill, only the camera moved) the four stay empty and the
    /// shadow rays ask only whether they are blocked; the stage's default visibility order takes
    /// the traditional vectors there and reads none of them (Zeng's order needs them:
    /// screen::DenoiserSettings::reliableVisibilityOrder). Frames where anything moved fill them.
    bool frameBufferShadowPoints = true;
    /// Screen-space frame buffers: fill prevPosition, prevNormal and prevGlossyHit in a frame
    /// where only the camera moved (FrameBuffers::shadowsStill), where each is its current
    /// buffer. Off: they stay empty there, and the stage reads the current buffers in their place
    /// (FrameBuffers::PrevPositionPlane); frames where anything moved fill them.
    bool frameBufferPrevPoints = true;
    /// Camera samples of pixels outside the projection of the scene's bounds are not traced:
    /// they miss (internal::Context::hitRect). The image is the same either way.
    bool cullMissingPixels = true;
    AovFlags aovs;
    TextureSpaceOptions texture;  ///< cached AO / diffuse indirect when texture.enabled
    bool progress = true;         ///< progress bar on stderr for renders longer than a second
    LightSampling lightSampling = LightSampling::Mis;
    /// Cpis: the record cache's budget (its slot array: 584 bytes a record). 16 MiB holds 28K
    /// records; brushed.json at 256x192 builds ~3K at the default LOD (results/cpis.md).
    size_t psrCacheBytes = size_t(16) << 20;
    /// Cpis: mip levels above the pixel-sized texel (eq. 1) at which records are cached, before
    /// the lobe's own term (see product_sampling.h, RecordLevelBias).
    float psrLodBias = 1.0f;
    /// Stereo (renderer/texture_space/stereo.h): this render is the eye `eyeOffset` along the
    /// camera's x axis (0: the centred camera), its frustum converging at `eyeConvergence`.
    float eyeOffset = 0.0f, eyeConvergence = 1.0f;
    /// Renders samples [firstSample, spp) of each pixel (their random streams are those of a
    /// whole render), without beginning a progressive pass itself: a caller interleaving
    /// renders that share a cache pass by pass (stereo) begins the passes.
    int firstSample = 0;
    /// Renders only rows [rowBegin, rowEnd) of the image (rowEnd 0: to the last row); the other
    /// rows stay black. Stereo takes turns band by band (renderer/texture_space/stereo.h).
    int rowBegin = 0, rowEnd = 0;
    VisibilityPrepass visibilityPrepass = VisibilityPrepass::Own;
    /// When set, filled with width x height PixelCacheCounts of this frame's lookups (all zero
    /// without texture-space shading); null costs one predictable branch per lookup (the
    /// preview's cache heat maps).
    std::vector<PixelCacheCounts>* pixelCache = nullptr;
    /// The ranks of a job that share this render (renderer/distributed/rank_group.h), null or
    /// of one rank: this process renders it alone. Every rank renders its bands of rows and the
    /// ranks combine the texture-space accumulators after each pass; rank 0's result holds the
    /// whole image and statistics summed over the ranks, the others' only their own rows.
    RankGroup* ranks = nullptr;
};

struct RenderStats {
    double seconds = 0.0;  ///< wall clock
    /// Process CPU time, all threads (over many ranks: of all ranks): the work, however busy
    /// the machine.
    double cpuSeconds = 0.0;
    int sppDone = 0;
    uint64_t cameraRays = 0, shadowRays = 0, bounceRays = 0;
    uint64_t cameraRaysCulled = 0;  ///< camera samples known to miss, not traced (not in TotalRays)
    uint64_t TotalRays() const { return cameraRays + shadowRays + bounceRays; }
    CacheStats cache;     ///< texture-space shading only
    RecordStats psr;      ///< cached product sampling records (light sampling cpis) only
    size_t psrBytes = 0;  ///< bytes of the product record cache (0 unless cpis)
    /// Hit-binned AO (TextureSamples::Hits): hits whose bin found no room in the largest table
    /// allowed (256 MiB), left out of the reconstruction. 0 unless a frame is enormous.
    uint64_t hitBinsDropped = 0;
    size_t hitBinBytes = 0;  ///< bytes of the hit bins (0 unless hits)
    int passes = 0;          ///< passes of camera samples run
    /// Over many ranks (RenderOptions::ranks): payload bytes this rank sent to and received
    /// from the others during the render, and of those the passes' (the texture-space
    /// accumulators, the noise, the budget; the rest is the rows gathered at the end).
    uint64_t bytesSent = 0, bytesReceived = 0, passBytes = 0;
};

/// A scene file's render settings as options: size, spp, time budget, integrator, seed, depth,
/// AO rays and distance, frame time (the tessellation rate is the RenderScene's). Every front end
/// starts from this and overrides what its own options say.
RenderOptions RenderOptionsFrom(const RenderSettings& settings);

/// Whether a render with these options shades its texture-space term at the camera hits
/// (TextureSamples::Hits): the AO or path integrator, or the direct one with its light cached
/// (TextureSpaceOptions::cacheDirect), with samples at the hits, no AOV layers
/// (they take the per-sample shading path, on the grid) and a cached term (not a benchmark's
/// constant). The renderer, its frame set-up and the command line's cache sizes all ask this one
/// question.
bool ShadesAtHits(const RenderOptions& o);

}  // namespace texcache
