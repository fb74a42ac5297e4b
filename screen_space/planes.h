// SPDX-License-Identifier: Apache-2.0
// Internal to the screen-space stage: padded float planes (structure of arrays) and the
// vectorized per-row kernels every denoiser is built from.
//
// Design note. Every pass is a loop over a row whose innermost loop runs over x with contiguous
// loads, so GCC vectorizes it; the kernels are compiled for x86-64-v4, v3 and the baseline and
// the right clone is picked once by the loader (ifunc), like Embree's per-ISA kernels. A
// plane keeps kPad zero columns left and right of every row: horizontal taps up to kPad away need
// no bounds test, and the padding's validity is 0, so it never contributes. Rows outside the
// image are skipped per tap in the vertical passes. Pixels whose guides are unusable (background,
// NaN/Inf) have a zero normal, so every edge-stopping weight towards them is 0; samples that are
// unusable (NaN/Inf in a component) have validity 0 and value 0.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <utility>

#include <sys/mman.h>

namespace texcache::screen::internal {

/// Columns of zero padding on each side of a row: the widest horizontal tap offset (a-trous
/// level 4: 2 x 16).
inline constexpr int kPad = 32;

/// Whether a pass over a w x h frame that writes `planes` float planes writes them with
/// non-temporal stores (StoreRow): when they add up to 24 MB or more. Less than that is still
/// in the 32 MB L3 cache (shared with the other core) when the next pass reads it; at 640x360
/// (1 MB planes) no pass writes that much, at 1920x1080 (8.5 MB planes) every pass of three
/// planes or more does.
inline bool StreamPlanes(int w, int h, int planes) {
    const size_t plane = (size_t(w) + 2 * kPad) * size_t(h) * sizeof(float);
    return plane * size_t(planes) >= (size_t(24) << 20);
}

/// Heap array for large per-frame buffers: 2 MB aligned and advised onto transparent huge pages
/// when it spans at least one, because first-touch page faults are what a fresh 8 MB plane costs
/// most (tens of microseconds per 4 KB fault on a virtual machine, over 100 ms for a 24 MB
/// buffer: build/bin/screen_space_benchmark). Allocated once per size; never per frame.
template <class T>
class HugeArray {
public:
    HugeArray() = default;
    HugeArray(const HugeArray&) = delete;
    HugeArray& operator=(const HugeArray&) = delete;
    ~HugeArray() { std::free(data_); }
    /// Reallocates when the size changes; every entry becomes `fill`.
    void Assign(size_t n, T fill) {
        if (n != size_) {
            std::free(data_);
            data_ = nullptr, size_ = 0;
            if (n) {
                // Only a buffer of at least one huge page is rounded up to whole huge pages:
                // rounding every plane up would make a 96x54 denoiser touch 2 MB per plane,
                // 300 MB per denoiser, and `texcache experiment temporal --quick` (dozens of
                // denoisers) spend half its time in the kernel's clear_page.
                constexpr size_t kHuge = size_t(2) << 20;
                const size_t raw = n * sizeof(T);
                const size_t align = raw >= kHuge ? kHuge : 64;
                const size_t bytes = (raw + align - 1) / align * align;
                data_ = static_cast<T*>(std::aligned_alloc(align, bytes));
                if (!data_) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
                if (align == kHuge) madvise(data_, bytes, MADV_HUGEPAGE);
#endif
                size_ = n;
            }
        }
        std::fill_n(data_, size_, fill);
    }
    void Swap(HugeArray& o) {
        std::swap(data_, o.data_), std::swap(size_, o.size_);
    }
    T* data() {
        return data_;
    }
    const T* data() const {
        return data_;
    }
    size_t size() const {
        return size_;
    }
    bool empty() const {
        return size_ == 0;
    }
    T& operator[](size_t i) {
        return data_[i];
    }
    const T& operator[](size_t i) const {
        return data_[i];
    }

private:
    T* data_ = nullptr;
    size_t size_ = 0;
};

/// A width x height image with kPad zero columns on both sides of every row.
template <class T>
class BasicPlane {
public:
    /// Sets the size; contents (and padding) become `fill`.
    void Resize(int w, int h, T fill = T(0)) {
        width_ = w, height_ = h;
        stride_ = size_t(w) + 2 * kPad;
        data_.Assign(stride_ * size_t(h), fill);
    }
    /// Sets every entry (padding included) to `v`.
    void Fill(T v) { std::fill_n(data_.data(), data_.size(), v); }
    T* Row(int y) { return data_.data() + size_t(y) * stride_ + kPad; }
    const T* Row(int y) const { return data_.data() + size_t(y) * stride_ + kPad; }
    /// Start of the allocation: index r * Stride() + kPad + x addresses (x, r).
    const T* Base() const { return data_.data(); }
    T* Base() { return data_.data(); }
    T& At(int x, int y) { return Row(y)[x]; }
    T At(int x, int y) const { return Row(y)[x]; }
    int Width() const { return width_; }
    int Height() const { return height_; }
    size_t Stride() const { return stride_; }
    bool Empty() const { return data_.empty(); }
    void Swap(BasicPlane& o) {
        data_.Swap(o.data_);
        std::swap(width_, o.width_), std::swap(height_, o.height_), std::swap(stride_, o.stride_);
    }

private:
    HugeArray<T> data_;
    int width_ = 0, height_ = 0;
    size_t stride_ = 0;
};
using Plane = BasicPlane<float>;
using IntPlane = BasicPlane<int32_t>;
using BytePlane = BasicPlane<uint8_t>;

/// Guides of one frame, as planes: what every edge-stopping weight reads.
struct Guides {
    Plane px, py, pz;   ///< world position (0 where invalid)
    Plane nx, ny, nz;   ///< unit normal; (0,0,0) where the pixel's geometry is unusable
    Plane depth;        ///< distance from the camera (0 where invalid)
    Plane invDz;        ///< 1 / (local depth step per pixel + 1e-3 depth): depth tolerance
    IntPlane objectId;  ///< -2 where invalid (never matches a real id or the background's -1)
    BytePlane valid;    ///< 1 where the geometry is usable
    void Resize(int w, int h);
};

// ---- Kernels (kernels.cpp) ----------------------------------------------------------------

/// One separable pass of a joint bilateral filter (depth + normal guides) over `nc` (1 or 3)
/// channels whose spatial weights are a Gaussian of per-pixel std (Zeng's shadow filter and
/// clean-up): taps at `offset`, weight exp(-offset^2 / (2 sigma_p^2)) * edge-stopping.
struct PassArgs {
    int nc = 1;
    bool vertical = false;
    const Plane* in[3] = {nullptr, nullptr, nullptr};
    Plane* out[3] = {nullptr, nullptr, nullptr};
    const Plane* valid = nullptr;  ///< sample validity (0/1) of `in`
    Plane* outValid = nullptr;     ///< optional: 1 where any tap had weight (the output is usable)
    const Plane* sigma = nullptr;  ///< per-pixel Gaussian std in pixels (< 0.05: copy)
    const Guides* g = nullptr;
    int taps = 0;                ///< number of taps (<= 33)
    int offset[33] = {};         ///< tap offsets in pixels along the pass direction
    float normalPower = 128.0f;  ///< weight ~ max(0, n.n')^normalPower
    float depthSigma = 1.0f;     ///< depth weight ~ exp(-|dz| invDz / (depthSigma |offset|))
};

/// One component of an a-trous level: `nc` (1 or 3) planes and their luminance variance. A
/// negative variance marks an unusable sample (no weight); the output's variance is
/// sum w^2 var / (sum w)^2, or -1 where no tap had weight.
struct AtrousComponent {
    int nc = 0;  ///< 0: unused slot
    const Plane* in[3] = {nullptr, nullptr, nullptr};
    const Plane* var = nullptr;
    Plane* out[3] = {nullptr, nullptr, nullptr};
    Plane* outVar = nullptr;  ///< null: the variance is not computed
    bool luminance = true;    ///< SVGF's luminance stopping; false: geometry only (joint bilateral)
};

/// One a-trous level (Dammertz et al.; SVGF's edge-stopping functions) over up to 3 components
/// at once: a 3x3 B-spline kernel with taps `step` pixels apart. The depth and normal weights
/// of a tap are computed once and shared by the components.
struct AtrousArgs {
    const Guides* g = nullptr;
    int step = 1;
    float normalPower = 128.0f, depthSigma = 1.0f, luminanceSigma = 4.0f;
    AtrousComponent comp[3];
};

/// Runs one a-trous level over the whole image on the TBB pool. Outputs must not alias inputs.
void AtrousLevel(const AtrousArgs& a);

/// Runs a separable pass over the whole image on the TBB pool.
void FilterPlanes(const PassArgs& a);

/// Sum over a (2r+1) x (2r+1) box of each of `nc` planes, unweighted, clamped at the borders
/// (out-of-image taps contribute nothing). `tmp` holds the horizontal sums.
void BoxSum(int nc, const Plane* const* in, Plane* const* out, Plane* const* tmp, int r);

/// max(0, 1 - x/16)^16: a cheap, vectorizable stand-in for exp(-x) on x >= 0 (within a few
/// percent for x < 2; exactly 0 from x = 16 on, where exp(-x) < 1e-7).
inline float ExpNeg16(float x) {
    float t = 1.0f - x * (1.0f / 16.0f);
    t = t > 0.0f ? t : 0.0f;
    t *= t, t *= t, t *= t;
    return t * t;
}
/// max(0, 1 - x/8)^8: the same, coarser (luminance weights).
inline float ExpNeg8(float x) {
    float t = 1.0f - x * (1.0f / 8.0f);
    t = t > 0.0f ? t : 0.0f;
    t *= t, t *= t;
    return t * t;
}

/// Rec. 709 luminance.
inline float Luma(float r, float g, float b) {
    return 0.2126f * r + 0.7152f * g + 0.0722f * b;
}

}  // namespace texcache::screen::internal
