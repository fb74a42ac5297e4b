// SPDX-License-Identifier: Apache-2.0
// Internal to the screen-space stage: the motion vectors (Zeng et al. 2021, Sec. 3-4).
//
// A MotionField says, per pixel of the current frame, where in the previous frame its history is
// (a raster position, pixel centres at +0.5) and which of the 4 bilinear taps around that position
// may be used. Each kind decides what a usable tap is:
//   traditional  same object, on the pixel's previous tangent plane, similar normal (the
//                disocclusion test: a disoccluded pixel's taps are on the occluder and fail);
//   shadow       any surface on the receiver's previous plane, or the same object;
//   glossy, dual the same object as the pixel (a reflection is reused from the same reflector;
//                a disoccluded pixel from its own surface, never from the occluder).
// A pixel without any usable tap has no history.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "screen_space/frame_buffers.h"
#include "screen_space/planes.h"

namespace texcache::screen::internal {

/// Previous-frame positions and usable bilinear taps of one kind of motion vector.
struct MotionField {
    Plane x, y;      ///< previous-frame raster position (NaN: none)
    BytePlane taps;  ///< bit k: tap k of the 2x2 footprint (k = dx + 2 dy) is usable
    void Resize(int w, int h) {
        x.Resize(w, h), y.Resize(w, h);
        taps.Resize(w, h, 0);
    }
};

/// The previous frame as the motion vectors see it.
struct PrevFrame {
    const Guides* g = nullptr;
    FrameCamera camera;
};

/// Traditional motion vectors: eq. 1 from `prevPosition` and the disocclusion test.
void TraditionalMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                       MotionField* out);

/// Shadow motion vectors (eq. 3) for in-shadow pixels, splatted through a (2r+1)^2 box to the
/// pixels near shadows; elsewhere the traditional ones. `alphaV` gets eq. 4's blend weight.
/// `scratch` needs 8 planes.
void ShadowMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                  const MotionField& trad, float alpha, float falloffSigma, int splatRadius,
                  MotionField* out, Plane* alphaV, Plane* scratch);

/// Stochastic glossy motion vectors (eq. 5); the traditional ones where there is no glossy hit.
/// `gauss` holds 2 * 4096 standard normal numbers.
void GlossyMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                  const MotionField& trad, float lobeScale, float maxJitter, uint32_t frameSeed,
                  const float* gauss, MotionField* out);

/// Dual motion vectors (eq. 6) where the traditional ones fail; the traditional ones elsewhere.
/// Objects' motion from the previous to the current frame is fitted (affine, least squares) to
/// the current frame's prevPosition -> position pairs of the objects that need it.
void OcclusionMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                     const MotionField& trad, IntPlane* scratch, MotionField* out);

/// Bilinear footprint of a raster position: top-left tap and the weights of the 4 taps.
struct Footprint {
    int x0, y0;
    float w[4];
};
/// False when the position is NaN or too far outside the image to have any tap.
inline bool MakeFootprint(float sx, float sy, int width, int height, Footprint* fp) {
    if (!(sx > -1.0f && sy > -1.0f && sx < float(width) + 1.0f && sy < float(height) + 1.0f))
        return false;
    const float fx = sx - 0.5f, fy = sy - 0.5f;
    const float bx = std::floor(fx), by = std::floor(fy);
    const float ax = fx - bx, ay = fy - by;
    fp->x0 = int(bx), fp->y0 = int(by);
    fp->w[0] = (1.0f - ax) * (1.0f - ay), fp->w[1] = ax * (1.0f - ay);
    fp->w[2] = (1.0f - ax) * ay, fp->w[3] = ax * ay;
    return true;
}

/// Gather addresses and weights of a pixel's history, for planes laid out like `Plane` (index
/// relative to Row(0) - kPad): the 4 taps of the footprint of (sx, sy), the weights of the
/// unusable ones (mask bit clear) zeroed and the rest renormalized. Branch-free, so loops over
/// a row vectorize (with gathers). `ok` is 0 when the usable taps carry less than 5% of the
/// bilinear weight (mostly rejected surfaces: no history rather than an extrapolation).
struct Bilinear {
    int i00, i10, i01, i11;
    float w00, w10, w01, w11;
    float ok;  ///< 1 or 0 (a float, not a bool: keeps callers' loops vectorizable)
};
inline Bilinear BilinearTaps(float sx, float sy, int mask, int width, int height, int stride) {
    // Integer and float arithmetic only (no 8-bit booleans), so that GCC vectorizes callers.
    // A pixel without usable taps may have a NaN or far-away position: use a safe one.
    sx = mask != 0 ? sx : 0.5f, sy = mask != 0 ? sy : 0.5f;
    const float fx = sx - 0.5f, fy = sy - 0.5f;
    const float bx = std::floor(fx), by = std::floor(fy);
    const float ax = fx - bx, ay = fy - by;
    const int x0 = std::min(std::max(int(bx), -2), width);  // columns -2..width+1 are padding
    const int y0 = int(by);
    // Rows outside the image carry no weight (mask); address a valid row instead.
    const int r0 = std::min(std::max(y0, 0), height - 1);
    const int r1 = std::min(std::max(y0 + 1, 0), height - 1);
    Bilinear b;
    b.i00 = r0 * stride + kPad + x0, b.i10 = b.i00 + 1;
    b.i01 = r1 * stride + kPad + x0, b.i11 = b.i01 + 1;
    const float m0 = float(mask & 1), m1 = float((mask >> 1) & 1);
    const float m2 = float((mask >> 2) & 1), m3 = float((mask >> 3) & 1);
    b.w00 = (1.0f - ax) * (1.0f - ay) * m0, b.w10 = ax * (1.0f - ay) * m1;
    b.w01 = (1.0f - ax) * ay * m2, b.w11 = ax * ay * m3;
    const float sum = b.w00 + b.w10 + b.w01 + b.w11;
    b.ok = sum >= 0.05f ? 1.0f : 0.0f;
    const float inv = sum >= 0.05f ? 1.0f / sum : 0.0f;
    b.w00 *= inv, b.w10 *= inv, b.w01 *= inv, b.w11 *= inv;
    return b;
}
/// Usable-tap mask of a footprint: bit k set when tap k is inside the image, has usable
/// geometry in the previous frame and passes `accept(x, y)`.
template <class Accept>
inline uint8_t TapMask(const Footprint& fp, const Guides& prev, Accept&& accept) {
    const int w = prev.depth.Width(), h = prev.depth.Height();
    uint8_t m = 0;
    for (int k = 0; k < 4; ++k) {
        const int tx = fp.x0 + (k & 1), ty = fp.y0 + (k >> 1);
        if (tx < 0 || ty < 0 || tx >= w || ty >= h || !prev.valid.At(tx, ty)) continue;
        if (accept(tx, ty)) m |= uint8_t(1u << k);
    }
    return m;
}

}  // namespace texcache::screen::internal
