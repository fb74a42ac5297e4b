// SPDX-License-Identifier: Apache-2.0
// What the renderer hands the screen-space stage each frame (Zeng et al. 2021, Sec. 4; Zhuang et
// al. 2021): the image split into the components each denoiser filters separately, the guides,
// and what the reliable motion vectors are computed from.
//
// The final colour of a pixel is
//     emitted + shading * visibility + glossy + indirect
// where `shading` is the unshadowed direct light (the noise-free part, Zeng Sec. 4.1), `visibility`
// its shadowing (an estimate of shadowed / unshadowed: 0..1 in expectation, a single frame can
// exceed 1 where `shading` is in closed form), `glossy` the glossy reflection of microfacet
// materials and `indirect` the diffuse indirect light (albedo included; `albedo` is given for
// demodulation).
//
// Layout: one structure of arrays per frame, row-major, y down, `width * height` entries per
// array. An optional input (e.g. cones when nothing is diffuse) is left empty, and the stage then
// does not use what depends on it; a non-empty array of the wrong size is an error (Validate()).
// Positions are world space. Values that do not exist for a pixel (no blocker: the pixel is lit;
// no glossy hit; background) are NaN in every component, never a made-up number.
//
// "prev" quantities are the same world point moved to the previous frame by its own object's
// motion (T^-1 of Zeng eq. 1/3/5): the receiver, the blocker and the light sample can each move
// differently. The stage keeps the previous frame's camera itself (the previous FrameBuffers).
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace texcache::screen {

/// Incident radiance in 6 cones of equal solid angle pi/3 over the normal's hemisphere (Zeng
/// Sec. 4.3, Fig. 7 right): cone 0 along the normal, cones 1..5 at 60 degrees from it, 72 degrees
/// apart in azimuth, in the tangent frame ConeFrame() builds from the normal. The cone half angle
/// is acos(5/6) (solid angle 2 pi (1 - 5/6) = pi/3), so neighbouring cones overlap slightly.
inline constexpr int kNumCones = 6;
inline constexpr float kConeCosHalfAngle = 5.0f / 6.0f;

/// The tangent frame cone axes are built in (Duff et al. 2017, "Building an orthonormal basis,
/// revisited"): the renderer that records cones and the stage that filters them must agree.
inline void ConeFrame(glm::vec3 n, glm::vec3* s, glm::vec3* t) {
    const float sign = n.z >= 0.0f ? 1.0f : -1.0f;
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    *s = glm::vec3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    *t = glm::vec3(b, sign + n.y * n.y * a, -n.y);
}

/// World-space cone axes of a unit normal (see kNumCones).
inline std::array<glm::vec3, kNumCones> ConeAxes(glm::vec3 n) {
    glm::vec3 s, t;
    ConeFrame(n, &s, &t);
    std::array<glm::vec3, kNumCones> axes;
    axes[0] = n;
    constexpr float kSin60 = 0.86602540f, kCos60 = 0.5f;
    for (int k = 1; k < kNumCones; ++k) {
        const float phi = 2.0f * 3.14159265f * float(k - 1) / 5.0f;
        axes[k] = kSin60 * (std::cos(phi) * s + std::sin(phi) * t) + kCos60 * n;
    }
    return axes;
}

/// Index of the cone a world direction `w` (in the normal's hemisphere) is recorded in: the cone
/// whose axis is closest.
inline int ConeOf(const std::array<glm::vec3, kNumCones>& axes, glm::vec3 w) {
    int best = 0;
    float bestDot = -2.0f;
    for (int k = 0; k < kNumCones; ++k) {
        const float d = glm::dot(axes[k], w);
        if (d > bestDot) bestDot = d, best = k;
    }
    return best;
}

/// How a diffuse surface is shaded from its cones (Zeng eq. 11 with the cosine put back): cone k
/// stands for the directions closest to its axis (the ConeOf cell), and its weight is that cell's
/// cosine-weighted share of the hemisphere, (1/pi) int_cell cos dw; the weights sum to 1, so
///     indirect = albedo * sum_k kConeShadeWeight[k] * cones[k].
/// Computed once by quadrature (tests/screen_space_test.cpp checks them).
inline constexpr float kConeShadeWeight[kNumCones] = {0.2772876f, 0.1445425f, 0.1445425f,
                                                      0.1445425f, 0.1445425f, 0.1445425f};

/// Diffuse irradiance / pi from the 6 cones of one pixel (multiply by the albedo to shade).
inline glm::vec3 ShadeCones(const glm::vec3* cones) {
    glm::vec3 s(0.0f);
    for (int k = 0; k < kNumCones; ++k) s += kConeShadeWeight[k] * cones[k];
    return s;
}

/// Records one incident-radiance sample in the cones of a pixel: `estimate` is the sample's
/// estimate of irradiance / pi, L(w) cos(theta) / (pi pdf(w)) (= L for cosine-weighted
/// sampling). It goes to the cone of `w`, scaled by 1 / kConeShadeWeight, so that each cone's
/// expectation is the cosine-weighted mean radiance of its cell and ShadeCones() reproduces the
/// sample's own diffuse estimate exactly.
inline void AddConeSample(const std::array<glm::vec3, kNumCones>& axes, glm::vec3 w,
                          glm::vec3 estimate, glm::vec3* cones) {
    const int k = ConeOf(axes, w);
    cones[k] += estimate / kConeShadeWeight[k];
}

/// The camera of a frame: world -> raster with (0,0) the top-left corner of pixel (0,0) and
/// (width, height) the bottom-right corner of the last pixel; `w` of the clip position > 0 in
/// front of the camera.
struct FrameCamera {
    glm::mat4 worldToClip{1.0f};  ///< perspective projection * view
    glm::vec3 position{0.0f};
    int width = 0, height = 0;

    /// Raster position of a world point; false when it is behind the camera.
    bool Project(glm::vec3 p, glm::vec2* raster) const {
        const glm::vec4 c = worldToClip * glm::vec4(p, 1.0f);
        if (!(c.w > 0.0f)) return false;
        *raster = glm::vec2((c.x / c.w * 0.5f + 0.5f) * float(width),
                            (0.5f - c.y / c.w * 0.5f) * float(height));
        return true;
    }
};

/// One rendered frame, as the screen-space stage consumes it.
struct FrameBuffers {
    int width = 0, height = 0;
    FrameCamera camera;
    float time = 0.0f;  ///< frame time (seconds)
    /// The renderer's `indirect` (and cones) is already its own running mean over a still view
    /// (the frame buffers' store): the stage then keeps its moving-view blend for that component
    /// instead of a running mean of running means, which would weigh the first, worst frames as
    /// much as the last.
    bool indirectAccumulates = false;
    /// Nothing but the camera moved since the previous frame (no object, no light): every
    /// shadow lies where it lay in the world, and a shadowed pixel's shadow motion vector (Zeng
    /// eq. 3) is its own traditional one. The stage then takes the traditional vectors for
    /// visibility instead of computing eq. 3's (Reliable with VisibilityOrder::Svgf).
    bool shadowsStill = false;

    // The components (linear radiance, RGB).
    /// What the stage passes through unfiltered: light seen directly (environment, emitters),
    /// and whatever else the renderer knows without noise (texcache's frame buffers: the
    /// delta lights' shadowed direct light, exact at the pixel centre).
    std::vector<glm::vec3> emitted;
    std::vector<glm::vec3> shading;  ///< unshadowed direct light (low noise: no ray)
    std::vector<float> visibility;   ///< shadowed / unshadowed estimate (shadow rays), >= 0
    /// Optional: a low-noise visibility from elsewhere (the renderer's texture-space cache: the
    /// shadowed / unshadowed diffuse light at the surface point, filtered and accumulated on the
    /// surface), >= 0 and finite, NaN where there is none for a pixel. The temporal methods take
    /// it where their visibility has no history (disocclusions, the first frame) instead of
    /// the spatially filtered `visibility`; pixels with history ignore it.
    std::vector<float> cachedVisibility;
    std::vector<glm::vec3> glossy;    ///< glossy (microfacet) reflection, 1 path
    std::vector<glm::vec3> indirect;  ///< diffuse indirect light, albedo included, 1 path

    // Guides.
    std::vector<glm::vec3> position;  ///< primary hit, world (NaN: background)
    std::vector<glm::vec3> normal;    ///< shading normal, unit (NaN: background)
    std::vector<float> depth;         ///< distance from the camera (INF: background)
    std::vector<float> roughness;     ///< GGX alpha at the hit (0: diffuse)
    std::vector<glm::vec3> albedo;    ///< diffuse albedo
    std::vector<glm::vec3> specular;  ///< Schlick F0 of the glossy lobe (0: diffuse)
    std::vector<int32_t> objectId;    ///< scene object (-1: background)

    // Traditional motion (Zeng eq. 1): the primary hit moved to the previous frame by its object.
    // With shadowsStill (nothing but the camera moved) both may be empty: each is then the
    // current frame's (PrevPositionPlane, PrevNormalPlane), as is prevGlossyHit.
    std::vector<glm::vec3> prevPosition;  ///< T^-1 s_i, world, previous frame
    std::vector<glm::vec3> prevNormal;    ///< its normal in the previous frame

    // Shadow motion vectors (Sec. 4.1): the shadow ray's blocker and light sample, now and moved
    // to the previous frame by their own objects / lights. NaN when the shadow ray was not blocked.
    // Empty when shadowsStill and the stage's visibility order is VisibilityOrder::Svgf, which
    // then takes the traditional vectors and reads none of them.
    std::vector<glm::vec3> blocker, prevBlocker;
    std::vector<glm::vec3> lightSample, prevLightSample;

    // Glossy motion vectors (Sec. 4.2): the glossy ray's hit, now and in the previous frame.
    std::vector<glm::vec3> glossyHit, prevGlossyHit;

    // Dual motion vectors for occlusion (Sec. 4.3): incident indirect radiance per cone
    // (kNumCones entries per pixel, pixel-major), axes from ConeAxes(normal). Recorded with
    // AddConeSample(), so that indirect = albedo * ShadeCones(cones of the pixel).
    std::vector<glm::vec3> cones;

    size_t NumPixels() const { return size_t(width) * size_t(height); }
    /// prevPosition, or position where it was left empty (shadowsStill: nothing moved).
    const std::vector<glm::vec3>& PrevPositionPlane() const {
        return prevPosition.empty() ? position : prevPosition;
    }
    /// prevNormal, or normal where it was left empty.
    const std::vector<glm::vec3>& PrevNormalPlane() const {
        return prevNormal.empty() ? normal : prevNormal;
    }
    /// prevGlossyHit, or glossyHit where it was left empty.
    const std::vector<glm::vec3>& PrevGlossyHitPlane() const {
        return prevGlossyHit.empty() ? glossyHit : prevGlossyHit;
    }
    /// The composed image: emitted + shading * visibility + glossy + indirect.
    std::vector<glm::vec3> Compose() const;
    /// Throws InputError naming the buffer when a non-empty buffer has the wrong size, a required
    /// one (shading, visibility, position, normal, depth, objectId) is missing, the size is not
    /// positive, or cachedVisibility holds a negative or infinite value (naming the pixel).
    void Validate(const std::string& where) const;
};

}  // namespace texcache::screen
