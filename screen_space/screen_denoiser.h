// SPDX-License-Identifier: Apache-2.0
// The screen-space stage: per-frame denoisers for the components of FrameBuffers, holding their
// history across frames (Zeng et al. 2021, "Temporally reliable motion vectors for real-time ray
// tracing"; Zhuang et al. 2021, "Real-time denoising using BRDF pre-integration factorization";
// Schied et al. 2017, SVGF).
//
// Each component is filtered on its own and the image is recomposed:
//     emitted + shading * visibility' + glossy' + indirect'
// The methods differ in how they reuse the previous frame:
//   SpatialOnly    no history: SVGF's edge-avoiding a-trous (depth, normal, luminance) with a
//                  spatial variance estimate.
//   Baseline       SVGF: traditional motion vectors (the primary hit back-projected, eq. 1) with a
//                  disocclusion test, temporal blend (eq. 2), luminance moments -> variance
//                  (spatial estimate for histories shorter than 4 frames), a-trous.
//   BaselineClamp  Baseline with the history clamped to mu +- k sigma of the current 3x3
//                  neighbourhood (TAA-style, Salvi 2015).
//   Reliable       Zeng et al.: visibility follows shadow motion vectors (eq. 3, splatted to the
//                  pixels around shadows), accumulated first as SVGF does and clamped to mu +-
//                  3 sigma only where a shadow vector parts from the traditional one
//                  (VisibilityOrder::Svgf, the default), or in Zeng's order (VisibilityOrder::Zeng:
//                  filtered spatially first, the SpatialOnly a-trous, its history clamped and
//                  cleaned up with std min(w_A + w_C, 5), eqs. 7-8; eq. 4's alpha^V only with
//                  shadowFalloff); glossy follows glossy motion vectors (eq. 5's virtual
//                  image; jittered over the lobe's footprint, Zeng's stochastic vectors, only
//                  with maxGlossyJitter > 0); diffuse indirect follows dual motion vectors (eq. 6)
//                  where the traditional ones fail and is reused as incident radiance per cone with
//                  overlap weights (eqs. 9-11) when indirectCones; glossy and indirect accumulate
//                  before their a-trous filter, unclamped by default (why: screen_denoiser.cpp and
//                  DenoiserSettings).
// Disocclusions: where a temporal method's visibility finds no history for a pixel (Reliable:
// no usable shadow vector; Baseline / BaselineClamp: the disocclusion test; everywhere in the
// first frame) and the frame has `cachedVisibility` there, that value replaces the pixel's raw
// (SVGF order) or spatially filtered (Zeng's order) 1-spp visibility and starts its history
// (SVGF order: with variance 0, so the a-trous keeps it). Pixels with history
// are unchanged up to the filters that read their neighbours (a-trous, clean-up).
// Demodulation::On divides glossy by the pre-integrated GGX + Schlick albedo F_beta and diffuse
// indirect by the albedo before filtering and multiplies them back after (Zhuang et al.).
//
// Threading: Denoise() runs its passes on the TBB pool; one denoiser must not be used from two
// threads at once. Errors: bad frames and settings throw texcache::InputError naming the buffer or
// setting; nothing else throws.
#pragma once
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <glm/glm.hpp>

#include "screen_space/frame_buffers.h"

namespace texcache::screen {

class BrdfPreintegration;

enum class Method { SpatialOnly, Baseline, BaselineClamp, Reliable };
enum class Demodulation { Off, On };

/// Short name of a method ("spatial", "baseline", "baseline+clamp", "reliable").
const char* MethodName(Method m);
/// The command lines' names of the methods (`--denoise`): "spatial", "baseline", "clamp",
/// "reliable", comma separated.
std::string MethodKeys();
/// The method a command-line name stands for; throws InputError naming `where` and the valid
/// names otherwise.
Method ParseMethodKey(std::string_view key, const std::string& where);
/// The command-line name of a method (MethodKeys()).
const char* MethodKey(Method m);

/// Which motion vectors LastMotion() returns.
enum class MotionKind {
    Traditional,  ///< the primary hit back-projected (Baseline, and every fallback)
    Shadow,       ///< visibility (Reliable): eq. 3, splatted around shadows
    Glossy,       ///< glossy (Reliable): eq. 5, one stochastic sample
    Occlusion,    ///< diffuse indirect (Reliable): traditional where valid, dual (eq. 6) elsewhere
};

/// The order of Reliable's visibility passes.
enum class VisibilityOrder {
    /// Zeng et al.: this frame filtered spatially first, the history along the shadow vectors
    /// clamped to mu +- reliableClampK sigma of the filtered frame, blended, cleaned up.
    Zeng,
    /// SVGF's order along the shadow vectors: accumulate first, then the variance-guided
    /// a-trous. Where a shadow vector is within a quarter pixel of the traditional one (no
    /// shadow moved over its receiver) the traditional vector is used, unclamped: there it is
    /// the baseline's visibility. Elsewhere the history is clamped to mu +- reliableClampK
    /// sigma of the 3x3. LastMotion(Shadow) returns the vectors so merged.
    Svgf,
};

/// Parameters; defaults follow the papers. Validated by the denoiser (InputError).
struct DenoiserSettings {
    float alpha = 0.2f;           ///< weight of the current frame in the temporal blend (eq. 2)
    float baselineClampK = 1.0f;  ///< BaselineClamp: history in mu +- k sigma (3x3)
    float reliableClampK = 3.0f;  ///< Reliable visibility: history in mu +- k sigma (Sec. 5)
    /// Svgf by default: Zeng's order keeps Reliable above the plain baseline on a camera flying
    /// over a static scene (where the shadow vectors are the traditional ones), and elsewhere the
    /// two are within a few percent (`texcache experiment temporal --ablation --out DIR`,
    /// results/temporal_ablation.md).
    VisibilityOrder reliableVisibilityOrder = VisibilityOrder::Svgf;
    /// Reliable glossy and diffuse indirect: history in mu +- k sigma of the current 3x3, 0 for
    /// none. Zeng et al. clamp every component at 3 sigma, but their clamp is against a spatially
    /// filtered frame; ours (accumulate first, see screen_denoiser.cpp) is against 1-spp samples,
    /// whose 3x3 sigma is often 0 where the light is sparse, so the clamp throws valid history
    /// away where the vectors are right and makes Reliable worse than the unclamped baseline
    /// (`texcache experiment temporal --ablation --out DIR`, results/temporal_ablation.md).
    float reliableGlossyClampK = 0.0f;
    float reliableIndirectClampK = 0.0f;  ///< (see reliableGlossyClampK)
    /// Reliable: keep diffuse indirect as incident radiance in 6 cones (Sec. 4.3) when the frame
    /// has cones. Off by default: the cone history is the blend of raw 1-spp cones, where SVGF's
    /// colour history is the first a-trous level's output, and it is the noisier of the two on
    /// every scene of the temporal experiment (results/temporal_ablation.md).
    bool indirectCones = false;
    int atrousLevels = 4;         ///< a-trous iterations, steps 1, 2, 4, 8 (1..5)
    float sigmaLuminance = 4.0f;  ///< SVGF's sigma_l
    float sigmaDepth = 1.0f;      ///< SVGF's sigma_z (relative to the local depth slope)
    float normalPower = 128.0f;   ///< SVGF's sigma_n (weight max(0, n.n')^sigma_n)
    int shadowSplatRadius = 8;    ///< Reliable: window shadow vectors and sizes splat through
    /// Reliable with VisibilityOrder::Zeng (InputError otherwise): eq. 4's non-planarity
    /// falloff (alpha^V) on the visibility blend. Off by default:
    /// it raises the direct-light RMSE on every ghosting scene of the temporal experiment
    /// (results/ablations.md, section 14), i.e. it sends pixels back to the spatial filter where
    /// the shadow vectors are usable.
    bool shadowFalloff = false;
    float shadowFalloffSigma = 0.1f;  ///< Reliable: eq. 4's sigma (radians)
    float glossyLobeScale = 1.0f;     ///< Reliable: glossy lobe's angular std = scale * GGX alpha
    /// Reliable: cap (pixels) on the glossy vector's Gaussian axes. Zeng's Sigma spans the
    /// lobe's footprint, tens of pixels at 1080p for alpha > 0.2; history that far away is
    /// another part of the reflection, and in a static scene the jitter is a blur that never
    /// converges (the scene of ctest -R ScreenSpaceTemporal.StaticNoisySceneConverges; figures
    /// in results/ablations.md, section 13). 0 by default (the glossy vector is then eq. 5's
    /// virtual-image reprojection alone): with the jitter capped at 4 px Reliable is above the
    /// plain baseline on a camera flying over a static scene, and no scene gains from it (`texcache
    /// experiment temporal --ablation --out DIR`, results/temporal_ablation.md, "glossy jitter 4").
    float maxGlossyJitter = 0.0f;
    /// Frames with at least this many rows (0: none) are denoised at half resolution: each 2x2
    /// block reduced to one sample of its main surface (its noisy components averaged over that
    /// surface), every temporal and a-trous pass run on that quarter of the pixels, and the
    /// results brought back with a joint-bilateral upsample over the full-resolution normal,
    /// depth and objectId, then remodulated and composed with the full-resolution shading,
    /// albedo and F_beta. The a-trous then runs atrousLevels - 1 levels (at least 1), which
    /// span the same full-resolution pixels. LastMotion() then returns each block's vector. On from
    /// 1080 rows: there it is as accurate as the full-resolution stage for a third less work
    /// (results/screen_space_benchmark.md); below, the full-resolution stage is the more
    /// accurate and already fast enough.
    int halfResolutionRows = 1080;
    int brdfSamples = 1024;  ///< samples per BRDF-table entry (Zhuang et al.'s count)
    unsigned seed = 1;       ///< glossy motion-vector sampling
};

/// Milliseconds of the passes of the last Denoise() (all components together).
struct StageTimings {
    double prepare = 0.0;            ///< validation, guide planes, (de)modulation inputs
    double traditionalMotion = 0.0;  ///< back-projection + disocclusion test
    double reliableMotion = 0.0;     ///< shadow (+ splat), glossy, dual (+ object motion) vectors
    double temporal = 0.0;           ///< reprojection, clamping, blending, moments, cones
    double spatial = 0.0;            ///< a-trous / joint bilateral filters, variance estimates
    double cleanup = 0.0;            ///< Reliable: the clean-up filter
    double compose = 0.0;            ///< remodulation and the final sum
    double total = 0.0;
};

/// Denoises a sequence of frames, keeping what it needs of the previous one.
class ScreenSpaceDenoiser {
public:
    /// Throws InputError for impossible settings.
    explicit ScreenSpaceDenoiser(const DenoiserSettings& settings = {});
    /// Uses `brdf` (shared between denoisers) instead of building a table on first use.
    ScreenSpaceDenoiser(const DenoiserSettings& settings,
                        std::shared_ptr<const BrdfPreintegration> brdf);
    ~ScreenSpaceDenoiser();
    ScreenSpaceDenoiser(const ScreenSpaceDenoiser&) = delete;
    ScreenSpaceDenoiser& operator=(const ScreenSpaceDenoiser&) = delete;

    /// Denoises one frame and returns the composed image. The history is dropped (the frame is
    /// treated as the first) when the size, method or demodulation changes. Throws InputError for
    /// a frame Validate() rejects or that lacks a buffer the method needs.
    std::vector<glm::vec3> Denoise(const FrameBuffers& frame, Method method,
                                   Demodulation demodulation = Demodulation::On);
    /// The same into `image` (resized), whose allocation is reused from frame to frame: on
    /// machines where first-touch page faults are slow, a fresh 1080p image can cost more than
    /// the whole stage (build/bin/screen_space_benchmark shows it).
    void Denoise(const FrameBuffers& frame, Method method, Demodulation demodulation,
                 std::vector<glm::vec3>* image);
    /// Forgets the history: the next frame is treated as the first.
    void Reset();
    /// Whether the next frames show a still view (camera and scene unchanged since the previous
    /// frame). While still, the temporal blends turn from alpha into a running mean of the
    /// frames since the view stopped, so the noise keeps falling instead of stopping at alpha's
    /// floor; false (the default) restores alpha at once.
    void SetStillView(bool still);

    /// Pass timings of the last Denoise(), wall clock.
    const StageTimings& Timings() const;
    /// The same in process CPU time (all threads): what the passes cost regardless of how much
    /// of the machine other processes leave us.
    const StageTimings& CpuTimings() const;
    /// The denoised visibility of the last frame (0 where the pixel has no usable geometry).
    std::vector<float> Visibility() const;
    /// The denoised, remodulated glossy component of the last frame (empty if it had none).
    std::vector<glm::vec3> Glossy() const;
    /// The denoised, remodulated indirect component of the last frame (empty if it had none).
    std::vector<glm::vec3> Indirect() const;
    /// Previous-frame raster position each pixel of the last frame took history from, for one
    /// kind of motion vector (NaN where there was none: disoccluded, outside the image, first
    /// frame, or a kind the method did not compute).
    std::vector<glm::vec2> LastMotion(MotionKind kind) const;
    /// The BRDF table (built on first use).
    const BrdfPreintegration& Brdf();

    struct State;  ///< opaque; defined in screen_denoiser.cpp

private:
    std::unique_ptr<State> s_;
};

}  // namespace texcache::screen
