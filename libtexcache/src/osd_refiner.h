// SPDX-License-Identifier: Apache-2.0
// Internal: builds an OpenSubdiv topology refiner from a ControlCage.
#pragma once
#include <memory>

#include <opensubdiv/far/topologyRefiner.h>

#include "texcache/cage.h"

namespace texcache::internal {

/// Catmark refiner with the cage's creases, corners, holes and boundary mode; throws InputError.
/// With `withUvs` (and uvs in the cage) the uvs are face-varying channel 0, linear along
/// boundaries (as the renderer's Embree geometry pins them).
std::unique_ptr<OpenSubdiv::Far::TopologyRefiner> CreateRefiner(const ControlCage& cage,
                                                                bool withUvs = false);

/// A primvar OpenSubdiv's PrimvarRefiner and StencilTable can accumulate: 3 floats (positions)
/// or 2 with the third left 0 (uvs).
struct OsdVertex {
    float p[3];
    void Clear(void* = nullptr) { p[0] = p[1] = p[2] = 0.0f; }
    void AddWithWeight(const OsdVertex& s, float w) {
        p[0] += w * s.p[0];
        p[1] += w * s.p[1];
        p[2] += w * s.p[2];
    }
};

}  // namespace texcache::internal
