// SPDX-License-Identifier: Apache-2.0
// Internal: builds an OpenSubdiv topology refiner from a ControlCage.
#pragma once
#include <memory>

#include <opensubdiv/far/topologyRefiner.h>

#include "texcache/cage.h"

namespace texcache::internal {

/// Catmark refiner with the cage's creases, corners, holes and boundary mode; throws InputError.
std::unique_ptr<OpenSubdiv::Far::TopologyRefiner> CreateRefiner(const ControlCage& cage);

}  // namespace texcache::internal
