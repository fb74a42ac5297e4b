// SPDX-License-Identifier: Apache-2.0
// A job of one rank, the choice between it and MPI's world, and the exchanges built on the
// collectives (a frame's rows, the texture-space accumulators).
#include "renderer/distributed/rank_group.h"

#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include "renderer/distributed/mpi_world.h"

namespace texcache {

namespace {

/// One process alone: every collective is the identity.
class LocalRankGroup final : public RankGroup {
public:
    int Rank() const override { return 0; }
    int Size() const override { return 1; }
    void SumDisjoint(double*, size_t) override {}
    void SumU64(uint64_t*, size_t) override {}
    void MaxU64(uint64_t*, size_t) override {}
    void Broadcast(void*, size_t, int) override {}
    std::vector<uint64_t> AllGather(const std::vector<uint64_t>& mine) override { return mine; }
    std::vector<std::vector<char>> Gather(const std::vector<char>& mine) override { return {mine}; }
    [[noreturn]] void Abort(int code) override { std::exit(code); }
};

/// The number of ranks the launcher started, from the environment it gives each rank (Open
/// MPI's mpirun, PMIx as under srun, MPICH's PMI); 1 when none is set. Not Slurm's own
/// variables: a batch script has them too, and a program it starts without srun is alone.
int LaunchedRanks() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "PMI_SIZE"})
        if (const char* v = std::getenv(name)) return std::max(1, std::atoi(v));
    return std::getenv("PMIX_RANK") ? 2 : 1;  // PMIx without its size: assume a job
}

}  // namespace

bool BuiltWithMpi() {
    return internal::MpiAvailable();
}

std::unique_ptr<RankGroup> JoinJob(int* argc, char*** argv) {
    const int ranks = LaunchedRanks();
    if (ranks > 1 && !internal::MpiAvailable())
        throw std::runtime_error("launched as one of " + std::to_string(ranks) +
                                 " ranks, but this texcache was built without MPI (install "
                                 "libopenmpi-dev and configure again)");
    if (internal::MpiAvailable() && (ranks > 1 || std::getenv("OMPI_COMM_WORLD_SIZE")))
        return internal::MpiWorld(argc, argv);
    return std::make_unique<LocalRankGroup>();
}

void GatherRows(RankGroup& group, const RowSplit& split, void* data, size_t rowBytes) {
    if (group.Size() == 1) return;
    char* const rows = static_cast<char*>(data);
    std::vector<char> mine;
    mine.reserve(size_t(split.OwnBands()) * RowSplit::kRows * rowBytes);
    for (int i = 0; i < split.OwnBands(); ++i)
        mine.insert(mine.end(), rows + size_t(split.First(i)) * rowBytes,
                    rows + size_t(split.Last(i)) * rowBytes);
    const std::vector<std::vector<char>> all = group.Gather(mine);
    for (int r = 1; r < int(all.size()); ++r) {
        RowSplit theirs = split;
        theirs.rank = r;
        size_t at = 0;
        for (int i = 0; i < theirs.OwnBands(); ++i) {
            const size_t bytes = size_t(theirs.Last(i) - theirs.First(i)) * rowBytes;
            if (at + bytes > all[size_t(r)].size())
                throw std::runtime_error("rank " + std::to_string(r) + " sent too few rows");
            std::memcpy(rows + size_t(theirs.First(i)) * rowBytes, all[size_t(r)].data() + at,
                        bytes);
            at += bytes;
        }
    }
}

uint64_t AllReduce(RankGroup& group, ReducibleAccumulators& acc) {
    if (group.Size() == 1) return 0;
    // Every rank's records to every rank, each then adding the others' to its own: the sums are
    // integers, so the order of the adds (rank order here) does not change them.
    std::vector<uint64_t> mine;
    acc.Export(&mine);
    const size_t recordWords = 1 + acc.WordsPerKey();
    std::vector<uint64_t> counts{uint64_t(mine.size())};
    const std::vector<uint64_t> sizes = group.AllGather(counts);
    const std::vector<uint64_t> all = group.AllGather(mine);
    uint64_t dropped = 0;
    size_t at = 0;
    for (int r = 0; r < group.Size(); ++r) {
        const size_t n = size_t(sizes[size_t(r)]);
        if (r != group.Rank()) dropped += acc.Import(all.data() + at, n / recordWords);
        at += n;
    }
    group.SumU64(&dropped, 1);
    return dropped;
}

}  // namespace texcache
