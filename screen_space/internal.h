// SPDX-License-Identifier: Apache-2.0
// Internal to the screen-space stage: the small helpers its kernels share (row loops over TBB,
// NaN/Inf tests written so that GCC vectorizes them, a plain copy loop) and the attribute that
// compiles a row kernel once per x86-64 level.
#pragma once
#include <cmath>
#include <cstdint>
#include <limits>

#include <emmintrin.h>
#include <xmmintrin.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <glm/glm.hpp>

// The row kernels are compiled for x86-64-v4 (AVX-512), x86-64-v3 (AVX2) and the baseline
// (SSE2), and the loader picks the CPU's clone once (ifunc), like Embree's per-ISA kernels: the
// build stays portable (no -march) while the vectorized loops use the widest registers there are.
// Sanitizer builds compile the baseline only (TEXCACHE_NO_ISA_CLONES, cmake/Warnings.cmake):
// the clones are one source, so the checks see the same code, in a third of the compile time.
#ifdef TEXCACHE_NO_ISA_CLONES
#define TEXCACHE_SCREEN_CLONES
#else
#define TEXCACHE_SCREEN_CLONES \
    __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif

namespace texcache::screen::internal {

inline constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// Flush-to-zero and denormals-are-zero for a scope, the caller's mode restored after. Every
/// task of the stage runs in this mode: a TBB worker that ran a render tile has it on (the
/// renderer sets it for Embree) and one that did not has it off, so without this a row's result
/// depended on which thread filtered it (runs differed by RMSE ~1e-43 with --denoise clamp
/// --demodulate on anim_glossy.json).
class DenormalsAreZero {
public:
    DenormalsAreZero() : saved_(_mm_getcsr()) { _mm_setcsr(saved_ | kFtzDaz); }
    ~DenormalsAreZero() { _mm_setcsr(saved_); }
    DenormalsAreZero(const DenormalsAreZero&) = delete;
    DenormalsAreZero& operator=(const DenormalsAreZero&) = delete;

private:
    static constexpr unsigned kFtzDaz = 0x8040;  // MXCSR bits 15 (FTZ) and 6 (DAZ)
    unsigned saved_;
};

/// body(y0, y1) for blocks [y0, y1) of at least `grain` rows covering [0, h), blocks in
/// parallel, each with denormals off (DenormalsAreZero). A block ends with a store fence: the
/// non-temporal stores of StoreRow are weakly ordered, and the next pass may read the rows on
/// another thread.
template <class Body>
void ForRowBlocks(int h, Body&& body, int grain = 4) {
    tbb::parallel_for(tbb::blocked_range<int>(0, h, grain), [&](const tbb::blocked_range<int>& r) {
        const DenormalsAreZero mode;
        body(r.begin(), r.end());
        _mm_sfence();
    });
}

/// body(y) for every row y in [0, h), rows in parallel (blocks of at least 4 rows).
template <class Body>
void ForRows(int h, Body&& body) {
    ForRowBlocks(h, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) body(y);
    });
}

/// 1 for a finite value, 0 for NaN / Inf: validity as a 0/1 float, to multiply into chains.
inline float Fin(float v) {
    return std::fabs(v) < 3.0e38f ? 1.0f : 0.0f;
}

inline bool Finite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

/// A plain copy loop rather than std::copy_n: memcpy would take the address of a kernel's local
/// result arrays, after which GCC assumes any incoming pointer may alias them.
template <class T>
inline __attribute__((always_inline)) void CopyRow(const T* src, int n, T* dst) {
    for (int i = 0; i < n; ++i) dst[i] = src[i];
}

/// Copies n 4-byte values from src to dst, whole 64-byte lines of dst with non-temporal stores
/// (StoreRow). Not inlined: the kernels call it once per chunk of a row, and it stays out of
/// their loops' code.
__attribute__((noinline)) inline void StreamRow(const void* src, int n, void* dst) {
    const auto* s = static_cast<const uint32_t*>(src);
    auto* d = static_cast<uint32_t*>(dst);
    int i = 0;
    for (; i < n && (reinterpret_cast<uintptr_t>(d + i) & 63) != 0; ++i) d[i] = s[i];
    for (; i + 16 <= n; i += 16)
        for (int k = 0; k < 16; k += 4)
            _mm_stream_si128(reinterpret_cast<__m128i*>(d + i + k),
                             _mm_loadu_si128(reinterpret_cast<const __m128i*>(s + i + k)));
    for (; i < n; ++i) d[i] = s[i];
}

/// CopyRow of 4-byte values into a plane's row; with `stream`, through non-temporal stores. A
/// pass over a large frame writes several planes that the next pass reads long after they have
/// left the caches: an ordinary store first reads each line it misses (and evicts another),
/// which makes such writes about 3x slower than streaming ones at 1920x1080, while planes small
/// enough to stay in the caches until the next pass are better written the ordinary way
/// (StreamPlanes() in planes.h decides).
template <class T>
inline __attribute__((always_inline)) void StoreRow(const T* src, int n, T* dst, bool stream) {
    static_assert(sizeof(T) == 4);
    if (stream)
        StreamRow(src, n, dst);
    else
        CopyRow(src, n, dst);
}

}  // namespace texcache::screen::internal
