// SPDX-License-Identifier: Apache-2.0
// Internal to the screen-space stage: what a ScreenSpaceDenoiser keeps, and the temporal passes
// (temporal.cpp) that read and write it.
//
// Ownership. Two sets of guides and of component histories (index `cur` = this frame's, cur ^ 1
// = the previous frame's) are swapped after every frame; nothing is copied between frames. All
// planes are allocated when the size changes, never per frame.
#pragma once
#include <functional>
#include <memory>
#include <vector>

#include "screen_space/brdf_table.h"
#include "screen_space/cone_overlap.h"
#include "screen_space/motion_vectors.h"
#include "screen_space/planes.h"
#include "screen_space/screen_denoiser.h"

namespace texcache::screen {
namespace internal {

inline constexpr int kVis = 0, kGlossy = 1, kIndirect = 2;

/// One component's input and result.
struct ComponentPlanes {
    int nc = 1;
    bool present = false;
    Plane v[3];      ///< the input, demodulated (0 where unusable)
    Plane valid;     ///< 1 where the input sample and the pixel's geometry are usable
    Plane remod[3];  ///< glossy: the remodulation factor F_beta (1 where not demodulated)
    const Plane* res[3] = {nullptr, nullptr, nullptr};  ///< the result (demodulated)
};

/// What a component carries to the next frame.
struct History {
    Plane c[3];              ///< colour (demodulated); SVGF: the first a-trous level's output
    Plane m1, m2;            ///< SVGF: luminance moments
    Plane len;               ///< frames accumulated (0: none)
    HugeArray<float> cones;  ///< Reliable indirect: per pixel 3 x 8 floats (RGB x 6 cones + 2)
    bool valid = false;
};

/// Scratch planes of one component for the filters: two ping-pong sets and a temporal output.
struct ComponentScratch {
    Plane t[3], tVar;  ///< temporal output / filter input
    Plane a[3], aVar;  ///< a-trous ping
    Plane b[3], bVar;  ///< a-trous pong
    Plane out[3], outVar;
};

}  // namespace internal

struct ScreenSpaceDenoiser::State {
    DenoiserSettings set;
    std::shared_ptr<const BrdfPreintegration> brdf;
    ConeOverlapTable coneTable;
    std::vector<float> gauss;  // 2 x 4096 standard normal numbers (glossy vectors)
    int w = 0, h = 0;
    bool hasPrev = false;
    Method method = Method::SpatialOnly;
    Demodulation demod = Demodulation::Off;
    uint32_t frameIndex = 0;
    int stillFrames = -1;              ///< frames denoised since SetStillView(true); -1: moving
    float blendAlpha = 0.2f;           ///< this frame's alpha of the temporal blends (BlendAlpha)
    bool indirectAccumulates = false;  ///< this frame's FrameBuffers::indirectAccumulates
    internal::Guides guides[2];
    int cur = 0;
    FrameCamera prevCam;
    internal::ComponentPlanes comp[3];
    internal::History hist[3][2];
    internal::ComponentScratch scratch[3];
    bool conesPath = false, prevConesPath = false;
    internal::MotionField trad, shadow, glossy, occl;
    bool motionValid[4] = {false, false, false, false};
    internal::Plane shadowAlpha, sigma;
    internal::Plane visClampK;  ///< Reliable, VisibilityOrder::Svgf: per-pixel clamp k
    internal::Plane cachedVis;  ///< the frame's cachedVisibility (< 0: none), when it has one
    bool hasCachedVis = false;
    internal::IntPlane occluder;
    internal::Plane splat[8];
    std::vector<uint8_t> zeroRow;  // validity flags of a row outside the image
    StageTimings timings, cpuTimings;
    /// Half resolution (DenoiserSettings::halfResolutionRows): the denoiser of the reduced
    /// frames, which keeps the history, and the reduced frame, reused from frame to frame.
    std::unique_ptr<ScreenSpaceDenoiser> half;
    FrameBuffers halfFrame;
    std::vector<glm::vec3> halfImage;
    std::vector<uint32_t> halfSource;  ///< each block's representative pixel
    bool lastHalf = false;             ///< the last frame was denoised at half resolution
    bool composes = true;              ///< false in the half denoiser: its image is never read
    std::vector<float> rowScratch;     ///< per-thread rows of UpsampleCompose
    std::vector<int32_t> rowIds;       ///< per-thread object-id rows of UpsampleCompose

    internal::Guides& G() { return guides[cur]; }
    const internal::Guides& PrevG() const { return guides[cur ^ 1]; }
    void Resize(int width, int height);
};

namespace internal {

/// SVGF's temporal step for component `ci`: the history (if `mf`) reprojected bilinearly over
/// the usable taps, clamped to mu +- clampK sigma of the current 3x3 neighbourhood when
/// clampK > 0, blended with weight max(alpha, 1 / length), luminance moments alike; writes the
/// integrated colour and its variance (moments, or the 3x3 spatial variance for histories
/// shorter than 4 frames; -1 where unusable) to scratch[ci].t / tVar and the moments and length
/// to this frame's history. With `clampKPerPixel` (one-channel components only) each pixel's
/// history is clamped with its own k from that plane instead.
void SvgfTemporal(ScreenSpaceDenoiser::State& s, int ci, const MotionField* mf, float clampK,
                  const Plane* clampKPerPixel = nullptr);

/// Zeng's temporal step for component `ci` whose spatially filtered frame is in `sp` / `spVar`
/// (variance < 0: unusable): history reprojected with `mf`, clamped to mu +- clampK sigma of
/// sp's 3x3 neighbourhood, blended with alpha or `alphaV` (eq. 4); the clean-up std
/// min(w_A + w_C, 5) (eqs. 7-8) goes to s.sigma. Writes the blend to scratch[ci].t / tVar
/// (variance 0 or -1: validity only) and the length to this frame's history.
void ReliableTemporal(ScreenSpaceDenoiser::State& s, int ci, Plane* const* sp, const Plane& spVar,
                      const MotionField* mf, const Plane* alphaV);

/// Zeng's per-cone temporal step for diffuse indirect (Sec. 4.3, eqs. 9-10) along `mf`; writes
/// the shaded result to scratch[kIndirect].t / tVar and the cones, moments and length to this
/// frame's history.
void ConesTemporal(ScreenSpaceDenoiser::State& s, const FrameBuffers& f, const MotionField* mf);

/// Where this frame's visibility has no history (its sample is usable and the temporal step
/// found none: a history length of 1) and s.cachedVis has a value, that value replaces the
/// temporal output in scratch[kVis].t, and so starts the history. With `svgf` (SVGF order: the
/// a-trous runs next) its variance is set to 0, which keeps the a-trous from mixing the noisy
/// neighbours into it, and its moments to those of the cached value.
void CachedWhereNoHistory(ScreenSpaceDenoiser::State& s, bool svgf);

/// The frame reduced to one sample per 2x2 block (half_resolution.cpp's design note) into `half`,
/// whose allocations are reused; `source` receives each block's representative pixel. The cones
/// are copied only `withCones` (the only pass that reads them is Reliable's cone path).
/// fullRow(y) is called once for every row y of `f`, on the thread that reduces that row's
/// blocks and just before it does, so that a pass over the same rows of the frame reads them
/// from the caches rather than from memory.
void DownsampleFrame(const FrameBuffers& f, bool withCones, FrameBuffers* half,
                     std::vector<uint32_t>* source, const std::function<void(int)>& fullRow);

/// Row y of this frame's full-resolution guides where they are read (PrepComponentRows,
/// UpsampleRow): the planes' rows, or at half resolution per-thread rows prepared just before
/// (the depth, its tolerance and the validity are planes at either resolution).
struct GuideRowView {
    const float *px, *py, *pz, *nx, *ny, *nz;
    const int32_t* id;
};

/// How many result planes UpsampleRow brings back from `half`: the channels of the components
/// present in both denoisers, in the order visibility, glossy, indirect.
int UpsampledPlanes(const ScreenSpaceDenoiser::State& s, const ScreenSpaceDenoiser::State& half);

/// Row y of the demodulated results of `half` (a denoiser that has just denoised
/// DownsampleFrame(frame)) brought to s's full-resolution guides (prepared for the same frame),
/// one row per UpsampledPlanes() plane into out[k]; own[k] is the pixel's own input of plane k
/// (what a pixel keeps where no half-resolution sample of its surface is near; readable one
/// entry past the row's end).
void UpsampleRow(const ScreenSpaceDenoiser::State& s, const ScreenSpaceDenoiser::State& half, int y,
                 const GuideRowView& gv, const float* const* own, float* const* out);

}  // namespace internal
}  // namespace texcache::screen
