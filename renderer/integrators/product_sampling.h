// SPDX-License-Identifier: Apache-2.0
// Product importance sampling of glossy reflection under an environment map (Munkberg et al.
// 2016, Sec. 6): a product sampling record (PSR) is a piecewise-constant distribution whose
// density follows f(wo, wi) cos(wi) L(wi), built per hit (PIS) or per texel and cached in
// texture space (CPIS, through libtexcache's RecordCache). Internal to renderer/.
//
// Design: Clarberg and Akenine-Moller's (2008) product, with a fixed-size record. The BSDF is
// smooth where the environment is not, so the record keeps the product at a coarse resolution and
// the environment refines it: 16x16 cells of the environment's luminance pyramid, a window of the
// level whose cells are ~1/16 of the lobe's width, centred on the mirror direction (the level of
// detail chosen for the lobe: a rough lobe takes the whole sphere at 32x16, a lobe of alpha 0.06
// cells of ~3 degrees). Cell weight = (f cos averaged over 2x2 points of the cell) x the cell's
// mean luminance x its solid angle. A draw picks a cell by these weights, then walks down the
// pyramid to a texel of the map, choosing among each texel's 4 children by their luminance
// (hierarchical sample warping), and takes a uniform point of that texel. So within a cell the
// density follows the map at its full resolution (a small bright source in a broad lobe is found
// as the map's own sampling would find it), and across cells it follows lobe x light. A record is
// 568 bytes.
//
// (Why not a 16x16 grid warped through the GGX visible-normal sampler, so that every bin lies
// in the lobe: its bins in the lobe's tail span tens of degrees, where a soft box is a small
// part of one bin, and the variance at single shading points of brushed.json reaches 100x
// MIS's; see docs/cpis.md.)
//
// Unbiasedness. A record's density at any direction (Pdf) is exact for the distribution it draws
// from (the same walk down the pyramid), whichever hit built it: the estimator MIS-combines it
// with BSDF sampling, which covers every direction the BSDF reflects into, so what the record
// leaves out (directions outside its window, map texels of zero luminance next to bright ones,
// where the bilinear radiance is not zero) costs variance, not bias.
#pragma once
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "renderer/integrators/bsdf.h"
#include "renderer/integrators/sampling.h"
#include "renderer/scene/envmap.h"
#include "renderer/scene/render_scene.h"
#include "texcache/record_cache.h"

namespace texcache {

/// A product sampling record: a 16x16 piecewise-constant distribution over a window of cells of
/// one level of the environment's luminance pyramid, refined down the pyramid when sampled.
/// Plain data (copied in and out of the cache); the map is passed to Sample and Pdf.
struct ProductRecord {
    static constexpr int kN = 16;
    int32_t level;          ///< pyramid level of the cells
    int32_t x0, y0;         ///< window origin at that level (x wraps around the map)
    int32_t width, height;  ///< the level's size in texels
    /// Cumulative probabilities in units of 1/kOne (16 bits: a record is copied out of the
    /// cache at every camera hit, and halving it measurably cut that copy): of window rows 0..j,
    /// and of columns 0..i within row j; the last of each is kOne.
    static constexpr float kOne = 65535.0f;
    uint16_t marginal[kN];
    uint16_t rows[kN][kN];
    uint32_t valid;  ///< 0: no distribution (see BuildProductRecord): sample otherwise

    /// Probability of window cell (column i, row j).
    float CellProbability(int i, int j) const {
        const float pr = float(marginal[j]) - (j > 0 ? float(marginal[j - 1]) : 0.0f);
        const float pc = float(rows[j][i]) - (i > 0 ? float(rows[j][i - 1]) : 0.0f);
        return (pr / kOne) * (pc / kOne);
    }

    /// Draws a direction with its solid-angle density (u picks the cell and the point in the
    /// texel, uWalk the walk down the pyramid); false when nothing can be drawn.
    bool Sample(const EnvironmentMap& env, glm::vec2 u, float uWalk, glm::vec3* wi,
                float* pdf) const {
        glm::vec2 uv;
        return SampleUv(env, u, uWalk, &uv, wi, pdf);
    }
    /// Sample() that also returns the direction's lat-long coordinates.
    bool SampleUv(const EnvironmentMap& env, glm::vec2 u, float uWalk, glm::vec2* uvOut,
                  glm::vec3* wi, float* pdf) const {
        const EnvironmentMap::LuminancePyramid& p = env.Pyramid();
        const float ty = u.y * kOne, tx = u.x * kOne;
        int j = 0;
        while (j < kN - 1 && float(marginal[j]) <= ty) ++j;
        const float r0 = j > 0 ? float(marginal[j - 1]) : 0.0f, pr = float(marginal[j]) - r0;
        const uint16_t* row = rows[j];
        int i = 0;
        while (i < kN - 1 && float(row[i]) <= tx) ++i;
        const float c0 = i > 0 ? float(row[i - 1]) : 0.0f, pc = float(row[i]) - c0;
        if (!(pr > 0.0f && pc > 0.0f)) return false;
        const float fy = std::clamp((ty - r0) / pr, 0.0f, kOneMinusEpsilon);
        const float fx = std::clamp((tx - c0) / pc, 0.0f, kOneMinusEpsilon);
        int x = (x0 + i) % width, y = y0 + j;
        float prob = (pr / kOne) * (pc / kOne);
        for (int l = level - 1; l >= 0; --l) {
            x *= 2, y *= 2;
            const float c[4] = {p.Texel(l, x, y), p.Texel(l, x + 1, y), p.Texel(l, x, y + 1),
                                p.Texel(l, x + 1, y + 1)};
            const float sum = c[0] + c[1] + c[2] + c[3];
            if (!(sum > 0.0f)) return false;
            float t = uWalk * sum;
            int k = 0;
            while (k < 3 && (t >= c[k] || !(c[k] > 0.0f))) t -= c[k++];
            while (!(c[k] > 0.0f)) --k;  // rounding ran past the last child with light
            uWalk = std::clamp(t / c[k], 0.0f, kOneMinusEpsilon);
            prob *= c[k] / sum;
            x += k & 1, y += k >> 1;
        }
        const auto& base = p.levels.front();
        const glm::vec2 uv((float(x) + fx) / float(base.width),
                           (float(y) + fy) / float(base.height));
        const float sinTheta = std::sin(kPiF * uv.y);
        if (!(prob > 0.0f && sinTheta > 0.0f)) return false;
        *uvOut = uv;
        *wi = env.UvToDir(uv);
        *pdf = prob * float(base.width) * float(base.height) / (2.0f * kPiF * kPiF * sinTheta);
        return true;
    }

    /// Solid-angle density of Sample() at a direction.
    float Pdf(const EnvironmentMap& env, glm::vec3 wi) const { return PdfUv(env, env.DirToUv(wi)); }
    /// Pdf() at the lat-long coordinates of a direction.
    float PdfUv(const EnvironmentMap& env, glm::vec2 uv) const {
        const EnvironmentMap::LuminancePyramid& p = env.Pyramid();
        const auto& base = p.levels.front();
        const int x = std::min(int(uv.x * float(base.width)), base.width - 1);
        const int y = std::min(int(uv.y * float(base.height)), base.height - 1);
        const int cx = x >> level, cy = y >> level;
        if (cx >= width || cy >= height) return 0.0f;  // an odd map's left-out edge
        const int i = (cx - x0 + width) % width, j = cy - y0;
        if (i >= kN || j < 0 || j >= kN) return 0.0f;
        float prob = CellProbability(i, j);
        for (int l = level - 1; l >= 0 && prob > 0.0f; --l) {
            const int px = (x >> (l + 1)) * 2, py = (y >> (l + 1)) * 2;
            const float sum = p.Texel(l, px, py) + p.Texel(l, px + 1, py) + p.Texel(l, px, py + 1) +
                              p.Texel(l, px + 1, py + 1);
            prob *= sum > 0.0f ? p.Texel(l, x >> l, y >> l) / sum : 0.0f;
        }
        const float sinTheta = std::sin(kPiF * uv.y);
        if (!(prob > 0.0f && sinTheta > 0.0f)) return 0.0f;
        return prob * float(base.width) * float(base.height) / (2.0f * kPiF * kPiF * sinTheta);
    }
};

/// Share of the light samples that product sampling leaves to the map's own sampling (a
/// defensive mixture, Hesterberg 1995): light from outside a record's window, e.g. a bright
/// source in the far tail of a rough lobe, would otherwise be found by BSDF sampling alone.
/// Measured at single shading points of brushed.json's lobe (tests/product_sampling_test.cpp,
/// EstimatorAgreesWithMis prints them): without it, a point whose light comes from outside the
/// window has two orders of magnitude more variance than MIS; with it, the test's six points
/// have a third of MIS's variance or less. Shares of 0.05 and 0.3 give no better image
/// (results/cpis.md, "Alternatives").
constexpr float kEnvShare = 0.15f;

/// A light sample of product sampling: from `record` with probability 1 - kEnvShare, else from
/// the map's own distribution (for a surface of normal n); the pdf is the mixture's, `Li` the
/// radiance from wi. `uChoice` is uniform and independent of u.
inline bool SampleProductLight(const ProductRecord& record, const EnvironmentMap& env, glm::vec3 n,
                               glm::vec2 u, float uChoice, glm::vec3* wi, float* pdf,
                               glm::vec3* Li) {
    float p;
    if (uChoice < kEnvShare) {
        *Li = env.Sample(n, u, wi, &p);
        if (!(p > 0.0f)) return false;
        *pdf = kEnvShare * p + (1.0f - kEnvShare) * record.Pdf(env, *wi);
        return true;
    }
    const float uWalk = std::min((uChoice - kEnvShare) / (1.0f - kEnvShare), kOneMinusEpsilon);
    glm::vec2 uv;
    if (!record.SampleUv(env, u, uWalk, &uv, wi, &p)) return false;
    *Li = env.EvalUv(uv);  // one lat-long conversion for the radiance and both pdfs
    *pdf =
        (1.0f - kEnvShare) * p + kEnvShare * (env.IsConstant() ? env.Pdf(n, *wi) : env.PdfUv(uv));
    return true;
}
/// Density of SampleProductLight at a direction.
inline float ProductLightPdf(const ProductRecord& record, const EnvironmentMap& env, glm::vec3 n,
                             glm::vec3 wi) {
    if (env.IsConstant())
        return (1.0f - kEnvShare) * record.Pdf(env, wi) + kEnvShare * env.Pdf(n, wi);
    const glm::vec2 uv = env.DirToUv(wi);
    return (1.0f - kEnvShare) * record.PdfUv(env, uv) + kEnvShare * env.PdfUv(uv);
}

/// Lobes narrower than this (max alpha) get no record: a near-mirror reflects a sliver of the
/// environment that BSDF sampling already follows exactly.
constexpr float kMinProductAlpha = 0.01f;

/// Builds the record of the specular lobe of `bsdf` seen from `woWorld` under `env`. Returns
/// false and leaves out->valid = 0 (callers then sample the environment as MIS does) for a
/// lobe without a specular part or narrower than kMinProductAlpha, a wo below the surface,
/// non-finite inputs, or an environment that is black over the whole lobe. Never stores a
/// non-finite value: non-finite weights count as 0.
bool BuildProductRecord(const EnvironmentMap& env, const Bsdf& bsdf, glm::vec3 woWorld,
                        ProductRecord* out);

/// Whether product sampling applies to a BSDF: a GGX lobe with no diffuse part (metals). A
/// diffuse base reflects light from directions a record over the specular lobe never visits,
/// which MIS's environment sampling covers better.
inline bool WantsProductSampling(const Bsdf& bsdf) {
    return bsdf.HasSpecular() && Luminance(bsdf.DiffuseReflectance()) <= 0.0f;
}

/// Whether any material of a scene may be product sampled (WantsProductSampling at some hit): a
/// GGX material whose diffuse albedo is black or textured.
inline bool AnyProductSampled(const Scene& scene) {
    for (const Material& m : scene.materials)
        if (m.type == Material::Type::GGX &&
            (m.albedo.texture >= 0 || m.albedo.value == glm::vec3(0.0f)))
            return true;
    return false;
}

/// Mip levels above the pixel-sized texel at which a lobe's record is cached: `bias` plus one
/// level per doubling of the lobe's width beyond alpha 0.1 (a record is shared by the texels
/// whose normals differ by a fraction of the lobe's width, and a wider lobe tolerates more).
inline float RecordLevelBias(float bias, glm::vec2 alpha) {
    const float a = std::sqrt(alpha.x * alpha.y);
    return bias + std::max(0.0f, std::floor(std::log2(a / 0.1f)) + 1.0f);
}

/// Cached product sampling (CPIS): the records of a render, one per texel of each object's
/// shading grids at the hit's level plus RecordLevelBias, built at the texel's centre and kept in
/// a RecordCache of `bytes` (the budget counts whole slots: record + key). Made only for renders
/// that use them; thread-safe.
class ProductRecordCache {
public:
    /// Registers every object of `rs` (which must have an environment map).
    ProductRecordCache(const RenderScene& rs, size_t bytes, float lodBias);

    /// Copies the record of `si`'s texel into `out` (si with its footprint, see
    /// RenderScene::Interact), building it on a miss for a camera at `eye`. out->valid is 0
    /// when the lobe has no record (see BuildProductRecord). No allocation, no virtual call.
    void Lookup(const SurfaceInteraction& si, const Bsdf& bsdf, glm::vec3 eye, ProductRecord* out,
                RecordStats& stats) {
        const CacheHit h{meshOf_[si.object],
                         si.ptex.face,
                         si.ptex.u,
                         si.ptex.v,
                         si.dudx,
                         si.dvdx,
                         si.dudy,
                         si.dvdy};
        const SampleRequest texel = cache_.TexelAt(h, RecordLevelBias(lodBias_, bsdf.AlphaXY()));
        cache_.Lookup(
            texel,
            [&](const SampleRequest& r, ProductRecord* rec) { Build(si, bsdf, eye, r, rec); }, out,
            stats);
    }
    /// Bytes of the record cache (its whole slot array).
    size_t BytesUsed() const { return cache_.BytesUsed(); }

private:
    void Build(const SurfaceInteraction& si, const Bsdf& bsdf, glm::vec3 eye,
               const SampleRequest& texel, ProductRecord* out) const;

    const RenderScene& rs_;
    RecordCache<ProductRecord> cache_;
    std::vector<int> meshOf_;
    float lodBias_;
};

}  // namespace texcache
