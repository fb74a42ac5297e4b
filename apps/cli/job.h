// SPDX-License-Identifier: Apache-2.0
// The MPI job a run of `texcache` belongs to (a job of one rank without mpirun): main() joins
// it before parsing, the subcommands that spread their work over the ranks ask it who they are,
// and a failure on any rank ends the job with one line that names the rank and the reason.
#pragma once
#include <exception>
#include <new>
#include <string>

#include "renderer/distributed/rank_group.h"
#include "texcache/error.h"

namespace texcache::cli {

/// The job of this process (set once by main()).
RankGroup& Job();
void SetJob(RankGroup* job);

/// A failure already reported (by rank 0, in one line): main() exits with `code`, printing
/// nothing more.
struct JobFailed : std::exception {
    int code;
    explicit JobFailed(int c) : code(c) {}
    const char* what() const noexcept override { return "job failed"; }
};

/// Collective: every rank says whether its part so far failed (`code` 0: no; else its exit code
/// and `reason`). When one did, rank 0 prints "texcache: error: rank R (...): reason" for the
/// lowest failing rank and every rank throws JobFailed, so that no rank renders or writes
/// anything. Nothing to do in a job of one rank.
void AgreeOrFail(int code, const std::string& reason);

/// Runs `step` on every rank and then AgreeOrFail on what it threw: a failure on one rank (a
/// scene it cannot read) stops them all before anything renders. In a job of one rank the
/// exception just propagates, as it always has.
template <typename Step>
void OnEveryRank(Step&& step) {
    if (Job().Size() == 1) return step();
    int code = 0;
    std::string reason;
    try {
        step();
    } catch (const InputError& e) {
        code = 2, reason = e.what();
    } catch (const std::bad_alloc&) {
        code = 1, reason = "out of memory";
    } catch (const std::exception& e) {
        code = 1, reason = std::string("internal error: ") + e.what();
    }
    AgreeOrFail(code, reason);
}

/// A test's failure injected on rank R by TEXCACHE_FAIL_RANK="R" (the scene cannot be read)
/// or "R:die" (the rank is killed mid-render): whether this rank has the `kind` of failure.
bool InjectedFailure(const char* kind);

}  // namespace texcache::cli
