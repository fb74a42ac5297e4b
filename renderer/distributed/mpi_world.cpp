// SPDX-License-Identifier: Apache-2.0
// MPI's world (MPI_COMM_WORLD) as a RankGroup. Only the thread that initialised MPI calls it
// (the render loop's, between its parallel phases): MPI_THREAD_FUNNELED is all it needs.
//
// Waiting. A rank that reaches a collective first waits for the others, and MPI waits by
// polling without pause: on a node whose cores the ranks (or other programs) share, the waiting
// rank's polls take a core from the rank it waits for. So every collective here starts with
// Arrive(): a non-blocking barrier whose wait polls for a moment and then sleeps between polls.
// Once every rank has arrived, the collective itself runs in MPI's blocking call, polling only
// while the data moves (which, in pieces through shared memory, needs both sides polling), and
// yielding its core between polls (Open MPI's mpi_yield_when_idle, set unless the environment
// sets it), so that a rank the scheduler took off the core gets it back to send its pieces.
// TEXCACHE_MPI_WAIT=poll leaves both out, waiting as MPI does by default (to measure the
// difference: scripts/mpi_scaling.sh ab).
// MPI's C API only: mpi.h otherwise brings the long-deprecated C++ bindings, whose library
// (libmpi_cxx) the C target does not link.
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <thread>

#include "renderer/distributed/mpi_world.h"

namespace texcache::internal {

namespace {

void Check(int err, const char* what) {
    if (err == MPI_SUCCESS) return;
    char text[MPI_MAX_ERROR_STRING];
    int len = 0;
    MPI_Error_string(err, text, &len);
    throw std::runtime_error(std::string(what) + ": " + std::string(text, size_t(len)));
}

/// Whether to wait as MPI does by default (TEXCACHE_MPI_WAIT=poll; see the design note above).
bool PollAsMpiDoes() {
    static const bool poll = [] {
        const char* v = std::getenv("TEXCACHE_MPI_WAIT");
        return v && std::strcmp(v, "poll") == 0;
    }();
    return poll;
}

/// Returns once every rank has called it (see the design note above).
void Arrive() {
    if (PollAsMpiDoes()) return;
    MPI_Request request;
    Check(MPI_Ibarrier(MPI_COMM_WORLD, &request), "MPI_Ibarrier");
    int done = 0;
    for (int i = 0; i < 64 && !done; ++i)
        Check(MPI_Test(&request, &done, MPI_STATUS_IGNORE), "MPI_Ibarrier");
    // Sleeps growing from 10 us to 0.5 ms: a wait costs at most about 0.5 ms a round of the
    // barrier more than polling, against passes of tens of milliseconds and more.
    for (auto nap = std::chrono::microseconds(10); !done;
         nap = std::min(2 * nap, std::chrono::microseconds(500))) {
        std::this_thread::sleep_for(nap);
        Check(MPI_Test(&request, &done, MPI_STATUS_IGNORE), "MPI_Ibarrier");
    }
}

int Elements(size_t n) {
    if (n > size_t(INT_MAX)) throw std::runtime_error("an MPI message of over 2^31 elements");
    return int(n);
}

class MpiRankGroup final : public RankGroup {
public:
    MpiRankGroup(int* argc, char*** argv) {
        if (!PollAsMpiDoes()) setenv("OMPI_MCA_mpi_yield_when_idle", "1", /*overwrite=*/0);
        int provided = 0;
        Check(MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
        MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
        MPI_Comm_size(MPI_COMM_WORLD, &size_);
    }
    ~MpiRankGroup() override { MPI_Finalize(); }

    int Rank() const override { return rank_; }
    int Size() const override { return size_; }

    void SumDisjoint(double* v, size_t n) override {
        Arrive();
        Check(MPI_Allreduce(MPI_IN_PLACE, v, Elements(n), MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD),
              "MPI_Allreduce");
        Count(n * sizeof(double), n * sizeof(double));
    }
    void SumU64(uint64_t* v, size_t n) override {
        Arrive();
        Check(MPI_Allreduce(MPI_IN_PLACE, v, Elements(n), MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD),
              "MPI_Allreduce");
        Count(n * 8, n * 8);
    }
    void MaxU64(uint64_t* v, size_t n) override {
        Arrive();
        Check(MPI_Allreduce(MPI_IN_PLACE, v, Elements(n), MPI_UINT64_T, MPI_MAX, MPI_COMM_WORLD),
              "MPI_Allreduce");
        Count(n * 8, n * 8);
    }
    void Broadcast(void* data, size_t bytes, int root) override {
        Arrive();
        Check(MPI_Bcast(data, Elements(bytes), MPI_BYTE, root, MPI_COMM_WORLD), "MPI_Bcast");
        Count(rank_ == root ? bytes : 0, rank_ == root ? 0 : bytes);
    }
    std::vector<uint64_t> AllGather(const std::vector<uint64_t>& mine) override {
        Arrive();
        const int n = Elements(mine.size());
        std::vector<int> counts(size_t(size_), 0), offsets(size_t(size_), 0);
        Check(MPI_Allgather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, MPI_COMM_WORLD),
              "MPI_Allgather");
        size_t total = 0;
        for (int r = 0; r < size_; ++r) offsets[size_t(r)] = Elements(total), total += counts[r];
        std::vector<uint64_t> all(total);
        Check(MPI_Allgatherv(mine.data(), n, MPI_UINT64_T, all.data(), counts.data(),
                             offsets.data(), MPI_UINT64_T, MPI_COMM_WORLD),
              "MPI_Allgatherv");
        Count(mine.size() * 8, (total - mine.size()) * 8);
        return all;
    }
    std::vector<std::vector<char>> Gather(const std::vector<char>& mine) override {
        Arrive();
        const int n = Elements(mine.size());
        std::vector<int> counts(size_t(size_), 0), offsets(size_t(size_), 0);
        Check(MPI_Gather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, MPI_COMM_WORLD),
              "MPI_Gather");
        size_t total = 0;
        for (int r = 0; r < size_; ++r) offsets[size_t(r)] = Elements(total), total += counts[r];
        std::vector<char> all(rank_ == 0 ? total : 0);
        Check(MPI_Gatherv(mine.data(), n, MPI_BYTE, all.data(), counts.data(), offsets.data(),
                          MPI_BYTE, 0, MPI_COMM_WORLD),
              "MPI_Gatherv");
        if (rank_ != 0) {
            Count(mine.size(), 0);
            return {};
        }
        Count(0, total - mine.size());
        std::vector<std::vector<char>> out(static_cast<size_t>(size_));
        for (int r = 0; r < size_; ++r)
            out[size_t(r)].assign(all.begin() + offsets[size_t(r)],
                                  all.begin() + offsets[size_t(r)] + counts[size_t(r)]);
        return out;
    }
    [[noreturn]] void Abort(int code) override {
        MPI_Abort(MPI_COMM_WORLD, code);
        std::_Exit(code);  // MPI_Abort does not return; this keeps [[noreturn]] honest
    }

private:
    int rank_ = 0, size_ = 1;
};

}  // namespace

bool MpiAvailable() {
    return true;
}
std::unique_ptr<RankGroup> MpiWorld(int* argc, char*** argv) {
    return std::make_unique<MpiRankGroup>(argc, argv);
}

}  // namespace texcache::internal
