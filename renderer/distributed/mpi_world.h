// SPDX-License-Identifier: Apache-2.0
// MPI's world as a RankGroup: mpi_world.cpp when the program is built with MPI, no_mpi_world.cpp
// otherwise. Internal to renderer/distributed/.
#pragma once
#include <memory>

#include "renderer/distributed/rank_group.h"

namespace texcache::internal {

/// Whether this program was built with MPI.
bool MpiAvailable();
/// MPI initialised (finalised when the group is destroyed); null without MPI.
std::unique_ptr<RankGroup> MpiWorld(int* argc, char*** argv);

}  // namespace texcache::internal
