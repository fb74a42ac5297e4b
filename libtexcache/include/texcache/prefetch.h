// SPDX-License-Identifier: Apache-2.0
// A software prefetch that the optimizer keeps, for the caches' and the visible set's lookups.
#pragma once

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

}  // namespace texcache
