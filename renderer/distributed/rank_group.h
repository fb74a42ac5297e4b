// SPDX-License-Identifier: Apache-2.0
// The processes of one job (MPI ranks) as the renderer sees them: who I am, how many we are, and
// the few collective operations a render over many ranks needs. A program not launched by
// mpirun (or srun), or built without MPI, is a job of one rank whose collectives do nothing,
// so the renderer's code is the same either way.
//
// Design note — what the ranks exchange
// -------------------------------------
// A frame's pixels are split among the ranks by bands of rows (RowSplit), so every pixel's sums
// are added by one rank in the order one process adds them: the image needs no reduction, only
// a gather of the bands at the end. What the ranks do combine after each pass is the
// texture-space state every rank's reconstruction reads: accumulators keyed by texel, whose
// sums are integers (saturating), so that the combined value is the same whatever the order
// the ranks' contributions arrive in. A cache exposes them through ReducibleAccumulators: the
// exchange knows keys and words, nothing of bins, levels or caches.
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace texcache {

/// Accumulators keyed by 64-bit keys, each a fixed number of 64-bit words of integer sums (or
/// another combination, such as a bitwise or) whose total does not depend on the order they are
/// added in (what another process's copy adds to this one's to combine them).
class ReducibleAccumulators {
public:
    virtual ~ReducibleAccumulators() = default;
    /// Words of sums per key.
    virtual size_t WordsPerKey() const = 0;
    /// Appends every key that holds a sum as a record [key, words...] to `out`.
    virtual void Export(std::vector<uint64_t>* out) const = 0;
    /// Adds `n` records [key, words...] to the accumulators; the number that found no room.
    virtual uint64_t Import(const uint64_t* records, size_t n) = 0;
};

/// The ranks of a job. Every collective must be called by every rank, in the same order.
class RankGroup {
public:
    virtual ~RankGroup() = default;
    virtual int Rank() const = 0;
    virtual int Size() const = 0;
    /// Element-wise sum over the ranks, the result on every rank. Exact for values that are
    /// non-zero on one rank at most (x + 0 = x), whatever order MPI adds them in.
    virtual void SumDisjoint(double* v, size_t n) = 0;
    /// Element-wise integer sum (wrapping) and maximum over the ranks, on every rank.
    virtual void SumU64(uint64_t* v, size_t n) = 0;
    virtual void MaxU64(uint64_t* v, size_t n) = 0;
    /// Rank `root`'s bytes to every rank.
    virtual void Broadcast(void* data, size_t bytes, int root) = 0;
    /// Every rank's `mine`, concatenated in rank order, on every rank.
    virtual std::vector<uint64_t> AllGather(const std::vector<uint64_t>& mine) = 0;
    /// Every rank's bytes, in rank order, on rank 0 (empty elsewhere).
    virtual std::vector<std::vector<char>> Gather(const std::vector<char>& mine) = 0;
    /// Stops every rank of the job with exit code `code` (after this rank reported why).
    [[noreturn]] virtual void Abort(int code) = 0;

    /// Payload bytes this rank sent to and received from the others since it started (what the
    /// algorithm exchanges, not the transport's own traffic).
    uint64_t BytesSent() const { return sent_; }
    uint64_t BytesReceived() const { return received_; }

protected:
    void Count(uint64_t sent, uint64_t received) { sent_ += sent, received_ += received; }

private:
    uint64_t sent_ = 0, received_ = 0;
};

/// The job this process belongs to: MPI's world when the program was built with MPI and
/// launched by mpirun or srun (MPI initialised here, finalised by the destructor), otherwise a
/// job of one rank. Throws std::runtime_error when launched as one of several ranks by a program
/// built without MPI (every rank would render the whole job and write the same files).
std::unique_ptr<RankGroup> JoinJob(int* argc, char*** argv);

/// Whether the program was built with MPI.
bool BuiltWithMpi();

/// The rows of a frame a rank renders: bands of kRows rows from `begin`, band b to rank
/// b mod size, so that every rank gets parts of every region of the image (sky and ground
/// alike) and the work stays balanced.
struct RowSplit {
    static constexpr int kRows = 8;
    int begin = 0, end = 0, rank = 0, size = 1;
    int NumBands() const { return (end - begin + kRows - 1) / kRows; }
    /// Bands this rank renders.
    int OwnBands() const { return (NumBands() - rank + size - 1) / size; }
    /// Rows [first, last) of this rank's i-th band.
    int First(int i) const { return begin + (i * size + rank) * kRows; }
    int Last(int i) const { return std::min(First(i) + kRows, end); }
    bool Owns(int y) const { return ((y - begin) / kRows) % size == rank; }
};

/// Gathers on rank 0 the rows of a frame each rank rendered (`data`: rowBytes per row, from row
/// 0), leaving every other row as it is. Nothing to do for one rank.
void GatherRows(RankGroup& group, const RowSplit& split, void* data, size_t rowBytes);

/// Combines `acc` with every other rank's (all ranks end up with the sum of all); the number
/// of records that found no room on any rank.
uint64_t AllReduce(RankGroup& group, ReducibleAccumulators& acc);

}  // namespace texcache
