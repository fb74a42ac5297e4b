// SPDX-License-Identifier: Apache-2.0
#include "job.h"

#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "texcache/error.h"

namespace texcache::cli {

namespace {
RankGroup* job = nullptr;
}

RankGroup& Job() {
    return *job;
}
void SetJob(RankGroup* j) {
    job = j;
}

void AgreeOrFail(int code, const std::string& reason) {
    RankGroup& g = Job();
    if (g.Size() == 1) return;
    std::vector<uint64_t> mine{uint64_t(code)};
    const std::vector<uint64_t> codes = g.AllGather(mine);
    int failed = 0, first = -1;
    for (int r = 0; r < g.Size(); ++r)
        if (codes[size_t(r)] != 0) failed += 1, first = first < 0 ? r : first;
    if (failed == 0) return;
    // The first failing rank's reason to rank 0, which reports it for the job.
    std::vector<char> text;
    if (g.Rank() == first) text.assign(reason.begin(), reason.end());
    const std::vector<std::vector<char>> all = g.Gather(text);
    if (g.Rank() == 0) {
        const std::vector<char>& why = all[size_t(first)];
        std::fprintf(stderr, "texcache: error: rank %d (%d of %d ranks failed): %s\n", first,
                     failed, g.Size(),
                     internal::OneLine(std::string(why.begin(), why.end())).c_str());
        std::fflush(stderr);
    }
    throw JobFailed(int(codes[size_t(first)]));
}

bool InjectedFailure(const char* kind) {
    const char* v = std::getenv("TEXCACHE_FAIL_RANK");
    if (!v) return false;
    const std::string_view s(v);
    const size_t colon = s.find(':');
    const std::string rank(s.substr(0, colon));
    const std::string_view what = colon == std::string_view::npos ? "read" : s.substr(colon + 1);
    return std::atoi(rank.c_str()) == Job().Rank() && what == kind;
}

}  // namespace texcache::cli
