// SPDX-License-Identifier: Apache-2.0
// The renderer's use of libtexcache: one cache mesh per scene object (shading depends on where
// the object is), samples of ShadedSample, texels of filtered RGB.
#pragma once
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "filters/texture_filters.h"
#include "renderer/render_scene.h"
#include "texcache/shading_cache.h"
#include "texcache/temporal_history.h"
#include "texcache/visible_texels.h"

namespace texcache {

/// Which texels of a filter footprint a render shades and averages.
///   Visible  only those the render's camera rays reach (a prepass traces the camera rays and
///            marks them: texcache/visible_texels.h), point-symmetric for the averaging filters.
///            A 21x21 window then shades 1.3x the samples of no filter instead of 5.2x (car AO,
///            640x360, 4 spp) at lower error: AO has sharp detail (contact shadows), and the
///            hidden texels a full window averages in are biased, not just costly.
///   All      every texel of the window (the paper's footprint). Smooth, noisy signals gain from
///            the unseen texels: they are still samples of nearly the same shading (path-traced
///            indirect light on sunlit.json, 480x270, 4 spp, one path per sample: relMSE 0.0068
///            in 0.74 s with full windows, 0.0212 in 0.56 s visible).
///   Auto     Visible for ambient occlusion, All for the direct and path integrators: the
///            paper's footprint where the evidence is mixed (speed-vs-error's best equal-time
///            ratios, visible / all: sunlit-indirect 2.69x / 4.00x, but car-diffuse 2.54x /
///            2.07x and chess-diffuse 1.58x / 1.34x).
enum class FootprintMode { Auto, Visible, All };
/// "auto", "visible" or "all"; throws InputError naming `where` and the valid names otherwise.
FootprintMode ParseFootprintMode(const std::string& name, const std::string& where);

/// Texture-space shading settings of a render (command line / scene file).
struct TextureSpaceOptions {
    bool enabled = false;  ///< --shading texture
    TextureFilterKind filter = TextureFilterKind::Normal;
    int radius = -1;            ///< footprint (2r+1)^2; -1: the filter's default (see below)
    float cosThreshold = 0.9f;  ///< normal filter: keep taps with cos > threshold
    int indirectSamples = 1;    ///< paths per cached indirect sample
    /// Path integrator: diffuse materials cache their direct light too (one NEE sample per
    /// cached path), not just indirect. Both are view-independent for a diffuse surface, but
    /// direct light has the sharp shadows: filtering them blurs hard shadow edges (measured on
    /// sunlit.json: relMSE 0.40 with the 13x13 normal filter against 0.16 unfiltered), so this is
    /// for soft lighting (environment, large area lights) and off by default.
    bool cacheDirect = false;
    int shadowSamples = 4;  ///< shadow rays per cached visibility sample (soft shadows)
    /// Which texels a footprint keeps: see FootprintMode. --footprint auto|visible|all.
    FootprintMode footprint = FootprintMode::Auto;
    /// Temporal accumulation across frames (eq. 6): weight of the history, 0 = off. Texels then
    /// keep a history table the size of the texel cache.
    float temporalAlpha = 0.0f;
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

using RenderShadingCache = ShadingCache<ShadedSample, glm::vec3>;

/// A shading cache for a scene: lives as long as its owner wants (e.g. across frames).
class TextureSpaceCache {
public:
    /// Registers every object of the scene; throws InputError on impossible settings.
    TextureSpaceCache(const RenderScene& rs, const TextureSpaceOptions& options);

    RenderShadingCache& cache() { return cache_; }
    const RenderShadingCache& cache() const { return cache_; }
    const TextureSpaceOptions& options() const { return options_; }
    /// Cache mesh id of a scene object's front side, or of its back side (open surfaces are
    /// seen from both sides and shade differently on each; closed ones have no back mesh).
    int MeshOf(int object, bool backFacing = false) const {
        return backFacing && backMeshOf_[object] >= 0 ? backMeshOf_[object] : meshOf_[object];
    }
    /// The object a cache mesh belongs to, and whether it is that object's back side.
    int ObjectOfMesh(int mesh) const { return meshObject_[mesh]; }
    bool IsBackMesh(int mesh) const { return meshIsBack_[mesh]; }
    /// The filter of an object's material (its override, else the render's default).
    TextureFilterKind FilterOf(int object) const { return filterOf_[object]; }
    /// Footprint radius of an object's material (its override, else the render's default).
    int RadiusOf(int object) const { return radiusOf_[object]; }
    /// Whether any object uses a filter (e.g. to skip what only that filter needs).
    bool Uses(TextureFilterKind kind) const;
    /// Whether any object's filter reads more than its centre texel.
    bool AnyFootprint() const;
    /// The visibility set for a render of width x height pixels, empty: about a quarter of a
    /// word per pixel (see visible_texels.h), between 32 KB and 16 MB; kept from render to
    /// render and only reallocated when the size changes.
    VisibleTexels& Visibility(int width, int height);

    /// Takes new options and starts empty, keeping the cache storage when its layout is the same
    /// (sizes, LOD bias, texel size; no temporal history): a renderer comparing settings then
    /// clears 2 x 64 MB instead of having the kernel map and zero them again for every render
    /// (measured: 0.3 s of CPU on a 480x270 render, more than its shading). Returns false, and
    /// changes nothing, when the storage does not match: build a new cache then.
    bool Reconfigure(const RenderScene& rs, const TextureSpaceOptions& options);

    /// Starts a frame of an animation: shading changes when objects move, so samples and texels
    /// are re-shaded, while the temporal history (if any) carries over.
    void BeginFrame(uint32_t frame);
    uint32_t Frame() const { return frame_; }
    /// This frame's filtered value of a texel blended into its history (eq. 6); `value` as is
    /// when temporal accumulation is off.
    glm::vec3 Accumulate(const TexelKey& key, glm::vec3 value) {
        return history_ ? history_->Blend(key, frame_, value) : value;
    }
    /// Bytes of all cache storage (sample and texel caches, temporal history, visibility set).
    size_t BytesUsed() const {
        return cache_.BytesUsed() + (history_ ? history_->BytesUsed() : 0) +
               (visible_ ? visible_->Bytes() : 0);
    }

private:
    void AssignFilters(const Scene& scene);

    TextureSpaceOptions options_;
    RenderShadingCache cache_;
    std::vector<int> meshOf_, backMeshOf_;
    std::vector<int> meshObject_;
    std::vector<char> meshIsBack_;
    std::vector<TextureFilterKind> filterOf_;
    std::vector<int> radiusOf_;
    std::unique_ptr<TemporalHistory<glm::vec3>> history_;
    std::unique_ptr<VisibleTexels> visible_;
    uint32_t frame_ = 0;
};

}  // namespace texcache
