// SPDX-License-Identifier: Apache-2.0
// Internal to the screen-space stage: the small helpers its kernels share (row loops over TBB,
// NaN/Inf tests written so that GCC vectorizes them, a plain copy loop) and the attribute that
// compiles a row kernel once per x86-64 level.
#pragma once
#include <cmath>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <glm/glm.hpp>

// The row kernels are compiled for x86-64-v4 (AVX-512), x86-64-v3 (AVX2) and the baseline
// (SSE2), and the loader picks the CPU's clone once (ifunc), like Embree's per-ISA kernels: the
// build stays portable (no -march) while the vectorized loops use the widest registers there are.
#define TEXCACHE_SCREEN_CLONES \
    __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))

namespace texcache::screen::internal {

inline constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// body(y) for every row y in [0, h), rows in parallel (blocks of at least 4 rows).
template <class Body>
void ForRows(int h, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4), [&](const tbb::blocked_range<int>& r) {
        for (int y = r.begin(); y < r.end(); ++y) body(y);
    });
}

/// body(y0, y1) for blocks [y0, y1) of at least 4 rows covering [0, h), blocks in parallel.
template <class Body>
void ForRowBlocks(int h, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4),
                      [&](const tbb::blocked_range<int>& r) { body(r.begin(), r.end()); });
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

}  // namespace texcache::screen::internal
