// SPDX-License-Identifier: Apache-2.0
// Large tables on transparent huge pages: 2 MB-aligned and advised, so that lookups at random in
// tens of MB do not miss the TLB on nearly every access, and a first touch faults in 2 MB at a
// time rather than 4 KB (a page fault costs microseconds in a virtual machine: hit-binned AO's
// records and bins, 1920x1080 at 4 spp, spent 7% of a render in faults on 4 KB pages).
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <new>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace texcache {

/// `bytes` of uninitialised memory, 2 MB-aligned and on huge pages when it is at least 2 MB
/// (else 64-byte aligned); release with std::free. Throws std::bad_alloc.
inline void* AllocateHugePages(size_t bytes) {
    constexpr size_t kHuge = size_t(2) << 20;
    // aligned_alloc wants a size that is a multiple of the alignment (ASan checks it): the tail
    // past `bytes` is never touched, so it takes no memory.
    const size_t align = bytes >= kHuge ? kHuge : 64;
    void* mem = std::aligned_alloc(align, (std::max<size_t>(bytes, 1) + align - 1) / align * align);
    if (!mem) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (bytes >= kHuge) madvise(mem, bytes, MADV_HUGEPAGE);
#endif
    return mem;
}

}  // namespace texcache
