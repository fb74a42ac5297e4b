// SPDX-License-Identifier: Apache-2.0
// Software prefetches that the optimizer keeps: for the caches' and the visible set's lookups,
// and for writes the hardware prefetchers do not see coming.
#pragma once

#include <cstddef>
#include <cstdint>

namespace texcache {

/// Starts loading the cache line at `p` (a hint: never faults, never changes memory).
///
/// Not __builtin_prefetch: GCC gives it no side effects, so its IPA pure-const pass finds a
/// function whose only effect is a prefetch "const", and deletes every call to it that is not
/// inlined first. GCC 12 -O3 had deleted them all: the renderer's binary held not one prefetch
/// instruction, and every Prefetch() of the caches did nothing. A volatile asm is never deleted.
/// (A warm frame's texel lookups then stalled on memory: `texcache bench cache --warm-only`,
/// warm / constant CPU 1.53x, 1.15x with the lookups removed.)
inline void PrefetchLine(const void* p) {
#if defined(__x86_64__) || defined(__i386__)
    asm volatile("prefetcht0 %0" : : "m"(*static_cast<const char*>(p)));
#else
    __builtin_prefetch(p);
#endif
}

/// Starts loading the cache line at `p` for writing (the line arrives owned, so that a store to
/// it does not wait for the ownership request): for scattered writes that the hardware
/// prefetchers do not follow. A hint as PrefetchLine; a NOP on processors without PREFETCHW.
inline void PrefetchLineForWrite(const void* p) {
#if defined(__x86_64__) || defined(__i386__)
    asm volatile("prefetchw %0" : : "m"(*static_cast<const char*>(p)));
#else
    __builtin_prefetch(p, 1);
#endif
}

/// PrefetchLineForWrite over the lines of bytes [p, p + bytes).
inline void PrefetchBytesForWrite(const void* p, size_t bytes) {
    if (bytes == 0) return;
    const uintptr_t first = reinterpret_cast<uintptr_t>(p) & ~uintptr_t(63);
    const uintptr_t last = reinterpret_cast<uintptr_t>(p) + bytes - 1;
    for (uintptr_t line = first; line <= last; line += 64)
        PrefetchLineForWrite(reinterpret_cast<const void*>(line));
}

}  // namespace texcache
