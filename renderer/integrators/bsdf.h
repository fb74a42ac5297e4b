// SPDX-License-Identifier: Apache-2.0
// The two materials the scenes need: Lambertian diffuse, and a GGX specular layer over a
// diffuse base. Evaluated in the shading frame (z = shading normal); header-only for inlining.
#pragma once
#include <algorithm>
#include <cmath>

#include <glm/glm.hpp>

#include "renderer/integrators/sampling.h"

namespace texcache {

inline float Luminance(glm::vec3 c) {
    return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
}
inline double Luminance(glm::dvec3 c) {
    return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
}

class Bsdf {
public:
    /// Diffuse when `ggx` is false; otherwise specular GGX + (1 - F0) diffuse, alpha =
    /// roughness^2 per axis: roughness.x along `tangent` (projected onto the normal's plane),
    /// roughness.y across it. Isotropic roughness ignores the tangent; so does a tangent
    /// parallel to n (then the frame's own tangent is used).
    Bsdf(glm::vec3 n, glm::vec3 ng, glm::vec3 albedo, bool ggx, glm::vec2 roughness, glm::vec3 f0,
         glm::vec3 tangent = glm::vec3(0.0f))
        : frame_(Frame::FromZ(n)), ng_(ng), albedo_(albedo), ggx_(ggx), f0_(f0) {
        alpha_ = glm::max(roughness * roughness, glm::vec2(1e-3f));
        kd_ = ggx ? 1.0f - std::max({f0.x, f0.y, f0.z}) : 1.0f;
        if (ggx && alpha_.x != alpha_.y) {
            const glm::vec3 t = tangent - n * glm::dot(n, tangent);
            const float len2 = glm::dot(t, t);
            if (len2 > 1e-12f && std::isfinite(len2)) {
                frame_.s = t / std::sqrt(len2);
                frame_.t = glm::cross(n, frame_.s);
            }
        }
    }

    /// BSDF value f(wo, wi) for world directions (both pointing away from the surface).
    ///
    /// wo may lie below the shading normal's plane while above the geometric one: a curved
    /// surface seen at a grazing angle, where the interpolated normal leans away from the eye.
    /// The diffuse lobe does not depend on wo and shades such a view as any other; the specular
    /// lobe needs wo above the shading plane and is 0 there. (Both 0 would leave dark fringes
    /// where a curved diffuse surface turns away: the clay car under a white sky, along the lower
    /// edge of its body, would be lit far below 0.8 x its ambient occlusion.)
    glm::vec3 Eval(glm::vec3 woW, glm::vec3 wiW) const {
        if (glm::dot(wiW, ng_) <= 0.0f) return glm::vec3(0.0f);
        const glm::vec3 wo = frame_.ToLocal(woW), wi = frame_.ToLocal(wiW);
        if (wi.z <= 0.0f) return glm::vec3(0.0f);
        glm::vec3 f = kd_ * albedo_ * kInvPi;
        if (ggx_ && wo.z > 0.0f) {
            const glm::vec3 wm = glm::normalize(wo + wi);
            const glm::vec3 F = FresnelSchlick(f0_, glm::dot(wo, wm));
            f += F * (GgxD(wm, alpha_) * GgxG(wo, wi, alpha_) / (4.0f * wo.z * wi.z));
        }
        return f;
    }

    /// Solid-angle pdf of Sample() producing wiW.
    float Pdf(glm::vec3 woW, glm::vec3 wiW) const {
        const glm::vec3 wo = frame_.ToLocal(woW), wi = frame_.ToLocal(wiW);
        if (wi.z <= 0.0f) return 0.0f;
        const float pDiffuse = CosineHemispherePdf(wi.z);
        if (!ggx_ || wo.z <= 0.0f) return pDiffuse;  // Sample() then draws the diffuse lobe
        const float ps = SpecularProbability(wo);
        return ps * GgxPdfReflect(wo, wi, alpha_) + (1.0f - ps) * pDiffuse;
    }

    /// Samples wi; returns false when no direction was produced. `weight` = f * cos / pdf.
    bool Sample(glm::vec3 woW, float uChoice, glm::vec2 u, glm::vec3* wiW, glm::vec3* weight,
                float* pdf) const {
        const glm::vec3 wo = frame_.ToLocal(woW);
        glm::vec3 wi;
        if (ggx_ && wo.z > 0.0f && uChoice < SpecularProbability(wo)) {
            const glm::vec3 wm = GgxSampleVisibleNormal(wo, alpha_, u);
            wi = glm::reflect(-wo, wm);
        } else {
            wi = SampleCosineHemisphere(u);
        }
        if (wi.z <= 0.0f) return false;
        *wiW = frame_.FromLocal(wi);
        *pdf = Pdf(woW, *wiW);
        if (!(*pdf > 0.0f)) return false;
        *weight = Eval(woW, *wiW) * (std::abs(wi.z) / *pdf);
        return true;
    }

    // ---- The lobes separately (the screen-space frame buffers keep them apart) ----

    /// Whether there is a specular (GGX) lobe.
    bool HasSpecular() const { return ggx_; }
    /// GGX alpha of the specular lobe (0 without one); the geometric mean of the two axes'
    /// alphas when anisotropic.
    float Alpha() const { return ggx_ ? std::sqrt(alpha_.x * alpha_.y) : 0.0f; }
    /// GGX alphas along the frame's s and t axes.
    glm::vec2 AlphaXY() const { return alpha_; }
    /// Schlick F0 of the specular lobe.
    glm::vec3 F0() const { return f0_; }
    /// Reflectance of the diffuse lobe: albedo, times (1 - max F0) under a specular layer.
    glm::vec3 DiffuseReflectance() const { return kd_ * albedo_; }

    /// Eval() split into the diffuse and the specular lobe (their sum is Eval()).
    void EvalLobes(glm::vec3 woW, glm::vec3 wiW, glm::vec3* diffuse, glm::vec3* specular) const {
        *diffuse = *specular = glm::vec3(0.0f);
        if (glm::dot(wiW, ng_) <= 0.0f) return;
        const glm::vec3 wo = frame_.ToLocal(woW), wi = frame_.ToLocal(wiW);
        if (wi.z <= 0.0f) return;
        *diffuse = kd_ * albedo_ * kInvPi;
        if (ggx_ && wo.z > 0.0f) {
            const glm::vec3 wm = glm::normalize(wo + wi);
            *specular = FresnelSchlick(f0_, glm::dot(wo, wm)) *
                        (GgxD(wm, alpha_) * GgxG(wo, wi, alpha_) / (4.0f * wo.z * wi.z));
        }
    }

    /// EvalLobes() and PdfSpecular() in one: the same values, sharing the local directions, the
    /// half vector, D and wo's Smith Lambda (a light sample's BSDF and its MIS weight against
    /// the specular lobe, for every candidate of the frame buffers' light samples).
    void EvalLobesPdf(glm::vec3 woW, glm::vec3 wiW, glm::vec3* diffuse, glm::vec3* specular,
                      float* pdfSpecular) const {
        *diffuse = *specular = glm::vec3(0.0f);
        *pdfSpecular = 0.0f;
        const glm::vec3 wo = frame_.ToLocal(woW), wi = frame_.ToLocal(wiW);
        const bool above = glm::dot(wiW, ng_) > 0.0f;
        if (above && wi.z > 0.0f) *diffuse = kd_ * albedo_ * kInvPi;
        if (!ggx_ || wo.z <= 0.0f || wi.z <= 0.0f) return;
        const glm::vec3 wm = glm::normalize(wo + wi);
        const float D = GgxD(wm, alpha_), lambdaWo = GgxLambda(wo, alpha_);
        if (above)
            *specular =
                FresnelSchlick(f0_, glm::dot(wo, wm)) *
                (D * (1.0f / (1.0f + lambdaWo + GgxLambda(wi, alpha_))) / (4.0f * wo.z * wi.z));
        if (glm::dot(wo, wm) > 0.0f) *pdfSpecular = (1.0f / (1.0f + lambdaWo)) * D / (4.0f * wo.z);
    }

    /// EvalLobesPdf() for `n` world directions at once, in structure-of-arrays form: lane k is
    /// wi = (wx[k], wy[k], wz[k]); diffuseOn[k] is 1 where the diffuse lobe is
    /// DiffuseReflectance() / pi there (else 0), (sr, sg, sb)[k] the specular lobe, pdf[k] its pdf.
    /// Bit for bit EvalLobesPdf()'s values, the same operations in the same order, written
    /// without branches (every lane computes every term, then keeps what EvalLobesPdf's branches
    /// would) so that the compiler vectorizes the loop: the frame buffers' light candidates are
    /// evaluated so, 8 to 32 a pixel.
    void EvalLobesPdfN(glm::vec3 woW, int n, const float* __restrict wx, const float* __restrict wy,
                       const float* __restrict wz, float* __restrict diffuseOn,
                       float* __restrict sr, float* __restrict sg, float* __restrict sb,
                       float* __restrict pdf) const {
        const glm::vec3 wo = frame_.ToLocal(woW);
        const glm::vec3 s = frame_.s, t = frame_.t, nz = frame_.n, ng = ng_, f0 = f0_;
        const glm::vec2 a = alpha_;
        // The specular lobe is 0 everywhere without GGX or with wo below the shading plane.
        const bool specular = ggx_ && !(wo.z <= 0.0f);
        const float lambdaWo = GgxLambda(wo, a);
        const float dPrefix = kPiF * a.x * a.y;  // GgxD's denominator, as it multiplies
        for (int k = 0; k < n; ++k) {
            const float x = wx[k], y = wy[k], z = wz[k];
            // Frame::ToLocal and the dot with ng, as glm::dot sums: (x + y) + z.
            const float lx = x * s.x + y * s.y + z * s.z;
            const float ly = x * t.x + y * t.y + z * t.z;
            const float lz = x * nz.x + y * nz.y + z * nz.z;
            const bool above = x * ng.x + y * ng.y + z * ng.z > 0.0f;
            diffuseOn[k] = above && lz > 0.0f ? 1.0f : 0.0f;
            // glm::normalize(wo + wi): v * (1 / sqrt(dot(v, v))).
            const float hx = wo.x + lx, hy = wo.y + ly, hz = wo.z + lz;
            const float inv = 1.0f / std::sqrt(hx * hx + hy * hy + hz * hz);
            const float mx = hx * inv, my = hy * inv, mz = hz * inv;
            // GgxD(wm, alpha).
            const float dx = mx / a.x, dy = my / a.y;
            const float d = dx * dx + dy * dy + mz * mz;
            const float D = mz <= 0.0f ? 0.0f : 1.0f / (dPrefix * d * d);
            // GgxLambda(wi, alpha).
            const float c2 = lz * lz;
            const float a2t2 = (a.x * a.x * lx * lx + a.y * a.y * ly * ly) / c2;
            const float lambdaWi = c2 <= 0.0f ? 1e30f : 0.5f * (std::sqrt(1.0f + a2t2) - 1.0f);
            // FresnelSchlick(f0, dot(wo, wm)).
            const float cosWoM = wo.x * mx + wo.y * my + wo.z * mz;
            const float m = std::min(std::max(1.0f - cosWoM, 0.0f), 1.0f);
            const float m2 = m * m;
            const float q = m2 * m2 * m;
            const float g = D * (1.0f / (1.0f + lambdaWo + lambdaWi)) / (4.0f * wo.z * lz);
            const bool on = specular && !(lz <= 0.0f);
            const bool shaded = on && above;
            sr[k] = shaded ? (f0.x + (1.0f - f0.x) * q) * g : 0.0f;
            sg[k] = shaded ? (f0.y + (1.0f - f0.y) * q) * g : 0.0f;
            sb[k] = shaded ? (f0.z + (1.0f - f0.z) * q) * g : 0.0f;
            pdf[k] = on && cosWoM > 0.0f ? (1.0f / (1.0f + lambdaWo)) * D / (4.0f * wo.z) : 0.0f;
        }
    }

    /// The diffuse lobe for a white albedo: 1/pi where Eval() shades wiW at all, else 0
    /// (DiffuseReflectance() x this is the diffuse lobe). It does not depend on the view.
    float DiffuseWhite(glm::vec3 wiW) const {
        return glm::dot(wiW, ng_) > 0.0f && glm::dot(wiW, frame_.n) > 0.0f ? kInvPi : 0.0f;
    }
    /// The specular lobe alone (Eval() = DiffuseReflectance() x DiffuseWhite() + this).
    glm::vec3 EvalSpecular(glm::vec3 woW, glm::vec3 wiW) const {
        glm::vec3 d, s;
        EvalLobes(woW, wiW, &d, &s);
        return s;
    }

    /// Solid-angle pdf of SampleSpecular() producing wiW.
    float PdfSpecular(glm::vec3 woW, glm::vec3 wiW) const {
        if (!ggx_) return 0.0f;
        return GgxPdfReflect(frame_.ToLocal(woW), frame_.ToLocal(wiW), alpha_);
    }

    /// Samples the specular lobe alone (visible normals); `weight` = f_spec * cos / pdf.
    bool SampleSpecular(glm::vec3 woW, glm::vec2 u, glm::vec3* wiW, glm::vec3* weight,
                        float* pdf) const {
        const glm::vec3 wo = frame_.ToLocal(woW);
        if (!ggx_ || wo.z <= 0.0f) return false;
        const glm::vec3 wm = GgxSampleVisibleNormal(wo, alpha_, u);
        const glm::vec3 wi = glm::reflect(-wo, wm);
        if (wi.z <= 0.0f) return false;
        *wiW = frame_.FromLocal(wi);
        if (glm::dot(*wiW, ng_) <= 0.0f) return false;
        *pdf = GgxPdfReflect(wo, wi, alpha_);
        if (!(*pdf > 0.0f)) return false;
        // f cos / pdf of visible-normal sampling: F G2 / G1(wo).
        *weight =
            FresnelSchlick(f0_, glm::dot(wo, wm)) * (GgxG(wo, wi, alpha_) / GgxG1(wo, alpha_));
        return true;
    }

    /// Samples the diffuse lobe alone (cosine); `weight` = DiffuseReflectance(). False when the
    /// direction lies below the geometric surface, where Eval() is 0 (wiW is set in either case).
    bool SampleDiffuse(glm::vec2 u, glm::vec3* wiW) const {
        *wiW = frame_.FromLocal(SampleCosineHemisphere(u));
        return glm::dot(*wiW, ng_) > 0.0f;
    }

    const Frame& frame() const { return frame_; }

    /// Sample() picks the specular lobe at least this often (in [0.1, 0.9]; 0.1 by default).
    /// A caller that averages the diffuse lobe's light over many hits (binning at camera hits)
    /// but not the specular lobe's spends more of its samples on the latter.
    void SetMinSpecularProbability(float p) { minSpecular_ = std::clamp(p, 0.1f, 0.9f); }

    /// The specular lobe's share of the surface's reflectance seen from world direction woW:
    /// Schlick's Fresnel at woW over itself plus the diffuse base's albedo, in [0, 1] (the
    /// weights Sample() picks its lobe by, unclamped); 0 without a specular lobe.
    float SpecularShare(glm::vec3 woW) const {
        return ggx_ ? ShareAt(std::max(glm::dot(woW, frame_.n), 0.0f)) : 0.0f;
    }

private:
    float ShareAt(float cosWo) const {
        const float s = Luminance(FresnelSchlick(f0_, cosWo));
        const float d = kd_ * Luminance(albedo_);
        return s / std::max(s + d, 1e-6f);
    }
    float SpecularProbability(glm::vec3 wo) const {
        return std::clamp(ShareAt(wo.z), minSpecular_, 0.9f);
    }
    static constexpr float kInvPi = 0.31830988618379067f;

    Frame frame_;
    glm::vec3 ng_, albedo_;
    bool ggx_;
    glm::vec3 f0_;
    glm::vec2 alpha_;
    float kd_;
    float minSpecular_ = 0.1f;
};

}  // namespace texcache
