// SPDX-License-Identifier: Apache-2.0
// A program built without MPI: there is no world to join.
#include "renderer/distributed/mpi_world.h"

namespace texcache::internal {

bool MpiAvailable() {
    return false;
}
std::unique_ptr<RankGroup> MpiWorld(int*, char***) {
    return nullptr;
}

}  // namespace texcache::internal
