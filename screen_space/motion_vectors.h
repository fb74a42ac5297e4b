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
inline float Gather(const float* base, const Bilinear& b) {
    return b.w00 * base[b.i00] + b.w10 * base[b.i10] + b.w01 * base[b.i01] + b.w11 * base[b.i11];
}

// ---- Runs of pixels with one tap offset --------------------------------------------------------
//
// Motion is smooth, so along a run of consecutive pixels the history taps' column offset (tap
// index - x) is usually a single value. Such a run reads every plane with contiguous vector loads
// at x + d00 (+1) and x + d01 (+1) instead of 4 gathers: on the AMD Zen 4 machines a 16-lane
// gather costs about as much as the rest of a temporal kernel's arithmetic (gathering every tap,
// the temporal pass spends more than half its time in them: build/bin/screen_space_benchmark
// --benchmark_filter=clamp, cpu_temporal_ms). The sums are the same expression
// in the same order as Gather(), so a run's results do not depend on which path it took.

/// Pixels per run: long enough to amortize the test, short enough that most runs of a row are
/// uniform where the motion changes.
inline constexpr int kTapRun = 64;

/// Offsets of a run's bilinear taps, as BilinearTaps addresses them.
struct TapRun {
    int d00 = 0, d01 = 0;  ///< tap 00 / 01 index minus x
    bool uniform = false;  ///< every pixel of the run has these offsets
};

/// The TapRun of pixels x0 .. x0 + n - 1 of a row whose motion is (mx, my, mt). Pixels without
/// usable taps have zero weights and take the run's offsets; the run is uniform only if every
/// address it implies lies inside a plane of `size` floats from its base.
inline __attribute__((always_inline)) TapRun RunTaps(const float* mx, const float* my,
                                                     const uint8_t* mt, int x0, int n, int width,
                                                     int height, int stride, size_t size) {
    int lo0 = 1 << 30, hi0 = -(1 << 30), lo1 = 1 << 30, hi1 = -(1 << 30);
    for (int x = x0; x < x0 + n; ++x) {
        const int mask = mt[x];
        // The index arithmetic of BilinearTaps.
        const float fx = (mask != 0 ? mx[x] : 0.5f) - 0.5f, fy = (mask != 0 ? my[x] : 0.5f) - 0.5f;
        const int c0 = std::min(std::max(int(std::floor(fx)), -2), width);
        const int y0 = int(std::floor(fy));
        const int r0 = std::min(std::max(y0, 0), height - 1);
        const int r1 = std::min(std::max(y0 + 1, 0), height - 1);
        const int d0 = r0 * stride + kPad + c0 - x, d1 = r1 * stride + kPad + c0 - x;
        lo0 = mask != 0 ? std::min(lo0, d0) : lo0, hi0 = mask != 0 ? std::max(hi0, d0) : hi0;
        lo1 = mask != 0 ? std::min(lo1, d1) : lo1, hi1 = mask != 0 ? std::max(hi1, d1) : hi1;
    }
    TapRun r;
    if (lo0 > hi0) {  // no usable tap: any address inside the plane (row 0) will do
        r.uniform = true;
        return r;
    }
    r.d00 = lo0, r.d01 = lo1;
    r.uniform = lo0 == hi0 && lo1 == hi1 && lo0 + x0 >= 0 && lo1 + x0 >= 0 &&
                size_t(std::max(lo0, lo1) + x0 + n) < size;
    return r;
}

/// Gather() in a run: contiguous loads when the run is uniform.
template <bool Uniform>
inline __attribute__((always_inline)) float RunGather(const float* base, const Bilinear& b,
                                                      const TapRun& r, int x) {
    if constexpr (Uniform) {
        const float* p0 = base + r.d00 + x;
        const float* p1 = base + r.d01 + x;
        return b.w00 * p0[0] + b.w10 * p0[1] + b.w01 * p1[0] + b.w11 * p1[1];
    } else {
        return Gather(base, b);
    }
}

/// Calls pixels(std::bool_constant<uniform>, i0, i1, run) for the runs of chunk positions
/// [0, n) (pixel x = x0 + i), so that each run's loop is compiled for its kind of fetch.
template <class Pixels>
inline __attribute__((always_inline)) void ForTapRuns(const float* mx, const float* my,
                                                      const uint8_t* mt, int x0, int n, int width,
                                                      int height, int stride, size_t size,
                                                      Pixels&& pixels) {
    for (int i0 = 0; i0 < n; i0 += kTapRun) {
        const int i1 = std::min(n, i0 + kTapRun);
        const TapRun r = RunTaps(mx, my, mt, x0 + i0, i1 - i0, width, height, stride, size);
        if (r.uniform)
            pixels(std::true_type{}, i0, i1, r);
        else
            pixels(std::false_type{}, i0, i1, r);
    }
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
