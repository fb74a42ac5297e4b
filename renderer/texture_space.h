// SPDX-License-Identifier: Apache-2.0
// The renderer's use of libtexcache: one cache mesh per scene object (shading depends on where
// the object is), samples of ShadedSample, texels of filtered RGB.
#pragma once
#include <vector>

#include <glm/glm.hpp>

#include "filters/texture_filters.h"
#include "renderer/render_scene.h"
#include "texcache/shading_cache.h"

namespace texcache {

/// Texture-space shading settings of a render (command line / scene file).
struct TextureSpaceOptions {
    bool enabled = false;  ///< --shading texture
    TextureFilterKind filter = TextureFilterKind::Normal;
    int radius = 6;             ///< footprint (2r+1)^2: the paper's 13x13
    float cosThreshold = 0.9f;  ///< normal filter: keep taps with cos > threshold
    int indirectSamples = 1;    ///< paths per cached indirect sample
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

private:
    TextureSpaceOptions options_;
    RenderShadingCache cache_;
    std::vector<int> meshOf_, backMeshOf_;
    std::vector<int> meshObject_;
    std::vector<char> meshIsBack_;
    std::vector<TextureFilterKind> filterOf_;
    std::vector<int> radiusOf_;
};

}  // namespace texcache
