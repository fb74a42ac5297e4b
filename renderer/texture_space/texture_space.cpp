// SPDX-License-Identifier: Apache-2.0
#include "renderer/texture_space/texture_space.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>

#include "texcache/error.h"

namespace texcache {

namespace {
// Whether the limit normals cross(dPdu, dPdv) of a closed cage point into the solid it bounds,
// in world space. The cage sample shader shades each texel on the side its normal points to, and
// per-hit shading faces the ray, so a closed cage wound inward (clockwise seen from outside, as
// some exporters write) would be cached from inside: dark, where per-hit shading is right. The
// faces' signed volume (fans about each face's first vertex, relative to `centre`; the cage's
// sign is its limit surface's) is negative for an inward-wound cage, and a mirroring transform
// (negative determinant) turns the normals around again. The whole mesh decides: the inner wall
// of a hollow shell, wound towards its cavity, counts negative but the outer wall outweighs it.
bool NormalsPointInward(const ControlCage& cage, glm::vec3 centre, const glm::mat4& toWorld) {
    double volume = 0.0;
    size_t at = 0;
    auto point = [&](size_t i) {
        const auto& p = cage.positions[size_t(cage.faceVertexIndices[i])];
        return glm::dvec3(p[0] - centre.x, p[1] - centre.y, p[2] - centre.z);
    };
    for (const int n : cage.faceVertexCounts) {
        const glm::dvec3 p0 = point(at);
        for (int i = 1; i + 1 < n; ++i)
            volume += glm::dot(p0, glm::cross(point(at + size_t(i)), point(at + size_t(i) + 1)));
        at += size_t(n);
    }
    return (volume < 0.0) != (glm::determinant(glm::mat3(toWorld)) < 0.0f);
}

void CheckOptions(const TextureSpaceOptions& options) {
    if (options.radius != -1) CheckFilterRadius(options.radius, "filter radius");
    if (options.visibilityRadius != -1)
        CheckFilterRadius(options.visibilityRadius, "visibility filter radius");
    if (!(options.cosThreshold >= -1.0f && options.cosThreshold <= 1.0f))
        throw InputError("normal threshold", "must be a cosine in [-1, 1]");
}
}  // namespace

void CageBounds(const ControlCage& cage, glm::vec3* lo, glm::vec3* hi) {
    *lo = glm::vec3(1e30f), *hi = glm::vec3(-1e30f);
    for (const auto& p : cage.positions) {
        *lo = glm::min(*lo, glm::vec3(p[0], p[1], p[2]));
        *hi = glm::max(*hi, glm::vec3(p[0], p[1], p[2]));
    }
}

float MipZeroTexelSize(glm::vec3 lo, glm::vec3 hi, float texelFraction) {
    // Grids live in the cage's own (object) space, so texel size is relative to the cage.
    return std::max(glm::length(hi - lo) * texelFraction, 1e-12f);
}

bool TextureSpaceCache::Uses(TextureFilterKind kind) const {
    return std::find(filterOf_.begin(), filterOf_.end(), kind) != filterOf_.end();
}

size_t TextureSpaceCache::StoreTexelBytes(size_t blocks) const {
    const bool filtered = Uses(TextureFilterKind::Gaussian) || Uses(TextureFilterKind::Regression);
    return filtered ? blocks * 4 * AoHitStore::kTexelBytes : 64 * AoHitStore::kTexelBytes;
}

bool TextureSpaceCache::AnyFootprint() const {
    for (size_t o = 0; o < filterOf_.size(); ++o)
        if (filterOf_[o] != TextureFilterKind::None && radiusOf_[o] > 0) return true;
    return false;
}

VisibleTexels& TextureSpaceCache::Visibility(int width, int height, bool clear) {
    // Two words per pixel: the 8x8 blocks a frame marks are sparse (a line of 8 words serves a
    // 64-texel run of one face, mostly partly seen), and with a quarter of a word per pixel
    // blocks share words so often that the phantom marks make 21x21 footprints shade about a
    // third more samples than the unfiltered render, against a few percent with two words.
    const size_t words = std::clamp<size_t>(std::bit_ceil(size_t(width) * size_t(height) * 2),
                                            size_t(1) << 12, size_t(1) << 21);
    if (!visible_ || visible_->Bytes() != words * sizeof(uint64_t))
        visible_ = std::make_unique<VisibleTexels>(words * sizeof(uint64_t));
    else if (clear)
        visible_->Clear();
    return *visible_;
}

bool TextureSpaceCache::FindNeighbourTexel(const SampleRequest& t, glm::vec3* value) const {
    // The mean, not the first found: a one-texel blur instead of a one-texel shift (stereo.h).
    const int res = Resolution(t);
    glm::vec3 sum(0.0f);
    int n = 0;
    for (int dv = -1; dv <= 1; ++dv)
        for (int du = -1; du <= 1; ++du) {
            const int iu = int(t.key.iu) + du, iv = int(t.key.iv) + dv;
            if ((du == 0 && dv == 0) || iu < 0 || iv < 0 || iu >= res || iv >= res) continue;
            TexelKey k = t.key;
            k.iu = uint16_t(iu), k.iv = uint16_t(iv);
            glm::vec3 v;
            if (cache_.FindTexel(cache_.RequestOf(t.mesh, k), &v)) sum += v, ++n;
        }
    if (n == 0) return false;
    *value = sum / float(n);
    return true;
}

void TextureSpaceCache::BeginFrame(uint32_t frame) {
    frame_ = frame;
    Invalidate();
    pass_ = 0;
    passRadiusOf_ = radiusOf_;
    ownStale_ = true;  // objects moved: a pixel's hit is another point
}

void TextureSpaceCache::Refresh(uint32_t frame, uint32_t parts, bool still) {
    frame_ = frame;
    pass_ = frame;  // fresh random streams and jittered sample points for what is re-shaded
    passRadiusOf_ = radiusOf_;
    if (history_) history_->SetRunningMean(still);
    storeStill_ = still;
    ownStale_ |= !still;
    if (parts == 0) return;
    const uint64_t part = frame % parts;
    cache_.InvalidateKeys([parts, part](uint64_t k) {
        k ^= k >> 33, k *= 0xff51afd7ed558ccdull, k ^= k >> 33;  // neighbours in different parts
        return k % parts == part;
    });
}

void TextureSpaceCache::InvalidateObject(int object) {
    ownStale_ = true;  // the pixels' own paths saw the object as it was
    const size_t o = size_t(object);
    for (const std::vector<int>* meshes : {&meshOf_, &backMeshOf_, &visMeshOf_, &visBackMeshOf_}) {
        if (o >= meshes->size() || (*meshes)[o] < 0) continue;
        const int mesh = (*meshes)[o];
        cache_.InvalidateMesh(mesh);
        if (history_) history_->InvalidateIf(cache_.MeshKeys(mesh));
        const MeshGrids& g = cache_.Mesh(mesh);
        const uint64_t first = g.FaceOffset(), end = first + uint64_t(g.NumFaces());
        if (aoStore_) aoStore_->ForgetFaces(first, end);
        if (lightStore_) lightStore_->ForgetFaces(first, end);
    }
}

int TextureSpaceCache::PassRadius(int radius, uint32_t pass) {
    if (pass == 0) return radius;
    return int(std::lround(float(radius) * std::pow(float(pass) + 1.0f, -1.0f / 6.0f)));
}

float TextureSpaceCache::HitBinLevels(int raysPerHit, int passSpp, uint32_t pass, HitTerm term) {
    const double n = std::max(1.0, double(raysPerHit) * double(passSpp) * (double(pass) + 1.0));
    return float((term == HitTerm::Ao ? 2.5 : 3.5) - std::log2(n / 4.0) / 3.0);
}

float TextureSpaceCache::HitLightLevels(double noiseVar, double noiseMean2, int pathsPerHit,
                                        int passSpp, uint32_t pass) {
    if (!(noiseVar > 0.0 && noiseMean2 > 0.0 && std::isfinite(noiseVar / noiseMean2)))
        return HitBinLevels(pathsPerHit, passSpp, pass, HitTerm::Light);
    // See the note at the top: 3.6 + log2(relative variance) / 4 - log2(n / 4) / 3.
    const double rel = std::clamp(noiseVar / noiseMean2, 1e-9, 1e9);
    const double n = double(passSpp) * (double(pass) + 1.0);
    return float(std::clamp(3.6 + 0.25 * std::log2(rel) - std::log2(n / 4.0) / 3.0, 0.0, 12.0));
}

void TextureSpaceCache::PrepareGrid() {
    cache_.Allocate();
    if (options_.temporalAlpha != 0.0f && !history_)
        history_ = std::make_unique<TemporalHistory<glm::vec3>>(options_.cache.texelCacheBytes,
                                                                options_.temporalAlpha);
}

void TextureSpaceCache::BeginPass(uint32_t pass) {
    if (pass != pass_) Invalidate();
    BeginPassRadii(pass);
}

void TextureSpaceCache::BeginPassRadii(uint32_t pass) {
    pass_ = pass;
    passRadiusOf_.resize(radiusOf_.size());
    for (size_t o = 0; o < radiusOf_.size(); ++o) passRadiusOf_[o] = PassRadius(radiusOf_[o], pass);
}

TextureSpaceCache::TextureSpaceCache(const RenderScene& rs, const TextureSpaceOptions& options)
    : options_(options), cache_(options.cache, /*allocate=*/false) {
    CheckOptions(options);
    const Scene& scene = rs.scene();
    // The grids of every object (front, and back for open surfaces): the shading's, and with
    // cached visibility a second set (its own face ids, hence its own texel keys and history).
    auto addGrids = [&](std::vector<int>* front, std::vector<int>* back) {
        for (size_t o = 0; o < scene.objects.size(); ++o) {
            const ControlCage& cage = scene.meshes[scene.objects[o].mesh];
            glm::vec3 lo, hi;
            CageBounds(cage, &lo, &hi);
            const float texel = MipZeroTexelSize(lo, hi, options.texelFraction);
            // The scene's Ptex topology, shared: not built again (on a 1,000,000-quad cage it
            // is 44 MB, and building it takes an OpenSubdiv refinement of ~0.5 s and ~250 MB).
            front->push_back(cache_.AddMesh(cage, texel, rs.SharedTopology(int(o))));
            meshObject_.push_back(int(o));
            meshIsBack_.push_back(0);
            // Open surfaces get a second set of grids for their back side (model only what is
            // needed: closed surfaces are seen from outside only, whichever way they are wound).
            if (cache_.Mesh(front->back()).Topology().HasBoundary()) {
                meshAgainstNormal_.push_back(0);
                back->push_back(cache_.AddMesh(cage, texel, rs.SharedTopology(int(o))));
                meshObject_.push_back(int(o));
                meshIsBack_.push_back(1);
                meshAgainstNormal_.push_back(1);
            } else {
                meshAgainstNormal_.push_back(
                    NormalsPointInward(cage, 0.5f * (lo + hi), rs.ObjectToWorld(int(o), 0.0f)));
                back->push_back(-1);
            }
        }
    };
    addGrids(&meshOf_, &backMeshOf_);
    if (options.cachedVisibility) {
        firstVisMesh_ = int(meshObject_.size());
        addGrids(&visMeshOf_, &visBackMeshOf_);
    }
    AssignFilters(scene);
}

void TextureSpaceCache::AssignFilters(const Scene& scene) {
    filterOf_.clear();
    radiusOf_.clear();
    for (size_t o = 0; o < scene.objects.size(); ++o) {
        const Material& m = scene.materials[scene.objects[o].material];
        const std::string where = scene.path + ": material '" + m.name + "'";
        filterOf_.push_back(m.cacheFilter.empty() ? options_.filter
                                                  : ParseTextureFilter(m.cacheFilter, where));
        radiusOf_.push_back(m.cacheRadius >= 0     ? m.cacheRadius
                            : options_.radius >= 0 ? options_.radius
                                                   : DefaultFilterRadius(filterOf_.back()));
        CheckFilterRadius(radiusOf_.back(), where);
    }
    passRadiusOf_ = radiusOf_;
}

internal::PixelOwnLight* TextureSpaceCache::StillOwnLight(int width, int height) {
    if (!storeStill_) {
        // A moving view keeps no own samples: release them rather than hold a frame's worth.
        if (!ownLight_.empty()) std::vector<internal::PixelOwnLight>().swap(ownLight_);
        ownStale_ = true;
        return nullptr;
    }
    if (ownStale_ || width != ownWidth_ || height != ownHeight_) {
        ownLight_.assign(size_t(std::max(width, 0)) * size_t(std::max(height, 0)), {});
        ownWidth_ = width, ownHeight_ = height, ownStale_ = false;
    }
    return ownLight_.data();
}

bool TextureSpaceCache::Reconfigure(const RenderScene& rs, const TextureSpaceOptions& options) {
    const CacheSettings &a = options.cache, &b = options_.cache;
    const bool sameStorage =
        a.sampleCacheBytes == b.sampleCacheBytes && a.texelCacheBytes == b.texelCacheBytes &&
        a.lodBias == b.lodBias && a.referenceMode == b.referenceMode &&
        a.texelThreeChoices == b.texelThreeChoices &&
        a.sampleThreeChoices == b.sampleThreeChoices &&
        options.texelFraction == options_.texelFraction && options.temporalAlpha == 0.0f &&
        options_.temporalAlpha == 0.0f && options.cachedVisibility == options_.cachedVisibility;
    if (!sameStorage) return false;
    CheckOptions(options);
    options_ = options;
    AssignFilters(rs.scene());
    frame_ = 0;
    pass_ = 0;
    hitStoreFrame_ = -1, temporalHitBias_ = INT_MIN;
    storeStill_ = false, ownStale_ = true;
    Invalidate();
    return true;
}

}  // namespace texcache
