// SPDX-License-Identifier: Apache-2.0
// `texcache experiment <name> --out DIR [--quick]`: reproduce a claim of the paper on our scenes
// and write CSV + PNG plots + a markdown summary into DIR.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "cli_util.h"
#include "commands.h"
#include "experiment_util.h"
#include "job.h"
#include "texcache/error.h"

namespace texcache::cli {

namespace {

struct ExperimentArgs {
    std::string name;
    std::string out;
    std::string scenes = TEXCACHE_SCENES_DIR;
    bool quick = false;
    std::string only;
    std::string methods;
    int cameraSpp = 0;
    bool ablation = false;
    std::string set =
        (std::filesystem::path(TEXCACHE_SCENES_DIR).parent_path() / "validation").string();
    std::set<std::string> given;  ///< options on the command line
};

const std::map<std::string, std::function<int(const experiments::Setup&)>>& Experiments() {
    static const std::map<std::string, std::function<int(const experiments::Setup&)>> m = {
        {"speed-vs-error", experiments::SpeedVsError},
        {"cache-size", experiments::CacheSize},
        {"filter-size", experiments::FilterSize},
        {"threads", experiments::Threads},
        {"lod-bias", experiments::LodBias},
        {"temporal", experiments::Temporal},
        {"disocclusion", experiments::Disocclusion},
        {"cpis", experiments::Cpis},
        {"stereo", experiments::Stereo},
        {"stereo-store", experiments::StereoStore},
        {"blur", experiments::Blur},
        {"equal-time", experiments::EqualTime},
    };
    return m;
}

/// Whether an experiment spreads its renders over the ranks of a job (experiments::RenderQueue).
bool Spreads(const std::string& name) {
    return name == "speed-vs-error" || name == "equal-time" || name == "cache-size" ||
           name == "lod-bias" || name == "cpis" || name == "filter-size";
}

std::string ExperimentNames() {
    std::string s;
    for (const auto& [name, fn] : Experiments()) s += (s.empty() ? "" : ", ") + name;
    return s + ", all";
}

/// The experiments "a,b" or "all" names, in the order `all` runs them.
std::vector<std::string> Names(const std::string& list) {
    std::vector<std::string> names;
    for (size_t at = 0; at <= list.size();) {
        const size_t comma = std::min(list.find(',', at), list.size());
        const std::string name = list.substr(at, comma - at);
        if (name == "all")
            for (const auto& [n, fn] : Experiments()) names.push_back(n);
        else
            names.push_back(name);
        at = comma + 1;
    }
    std::sort(names.begin(), names.end());
    names.erase(std::unique(names.begin(), names.end()), names.end());
    return names;
}

/// The arguments checked, the output directory made; true when this call made it.
bool CheckExperiment(const ExperimentArgs& a) {
    for (const std::string& name : Names(a.name))
        if (!Experiments().count(name))
            throw InputError("experiment", "unknown experiment '" + name +
                                               "' (valid: " + ExperimentNames() + ")");
    // Options of some experiments only: given to another, they would do nothing.
    const std::pair<const char*, std::vector<std::string>> scoped[] = {
        {"--only", {"speed-vs-error", "temporal", "equal-time"}},
        {"--methods", {"speed-vs-error"}},
        {"--camera-spp", {"speed-vs-error"}},
        {"--ablation", {"temporal"}},
        {"--set", {"equal-time"}}};
    for (const auto& [option, experiments] : scoped) {
        if (a.name == "all" || !a.given.count(option)) continue;
        for (const std::string& name : Names(a.name)) {
            if (std::find(experiments.begin(), experiments.end(), name) != experiments.end())
                continue;
            std::string list;
            for (const std::string& e : experiments) list += (list.empty() ? "" : ", ") + e;
            throw InputError(option, "applies to " + list + ", not '" + name + "'");
        }
    }
    namespace fs = std::filesystem;
    std::error_code ec;
    const bool created = !fs::exists(a.out, ec);
    fs::create_directories(a.out, ec);
    if (!fs::is_directory(a.out))
        throw InputError("--out", "cannot create directory '" + a.out + "'");
    if (!fs::is_directory(a.scenes))
        throw InputError("--scenes", "no scene directory '" + a.scenes + "'");
    if (a.cameraSpp < 0 || a.cameraSpp > 1024)
        throw InputError("--camera-spp",
                         "must be in 1..1024 (got " + std::to_string(a.cameraSpp) + ")");
    return created;
}

int RunExperiment(const ExperimentArgs& a) {
    // Over many ranks every rank checks first (one line if one fails).
    bool created = false;
    OnEveryRank([&] { created = CheckExperiment(a); });
    experiments::Setup s{a.out,     a.scenes,    a.quick,    a.only,
                         a.methods, a.cameraSpp, a.ablation, a.set};
    const double t0 = NowSeconds();
    int code = 0;
    // Over many ranks the experiments whose renders spread over the ranks (RenderQueue) run one
    // after another on every rank, rank 0 writing their files; the others are dealt
    // round-robin, each writing its own files in --out and timing its renders under one
    // rank's load (ranks sharing a machine's cores slow each other alike).
    RankGroup& job = Job();
    int index = 0;
    std::string mine;
    // The spreading ones first: a rank does not wait in one for another rank's dealt experiment.
    std::vector<std::string> names = Names(a.name);
    std::stable_partition(names.begin(), names.end(), Spreads);
    try {
        for (const std::string& name : names) {
            const bool spread = job.Size() > 1 && Spreads(name);
            if (!spread && index++ % job.Size() != job.Rank()) continue;
            experiments::Setup run = s;
            run.ranks = spread ? &job : nullptr;
            if (spread) {
                experiments::Setup check = run;
                check.checkOnly = true;
                OnEveryRank([&] { Experiments().at(name)(check); });
            }
            const double te = NowSeconds();
            code = std::max(code, Experiments().at(name)(run));
            if (spread && job.Rank() != 0) continue;
            mine += spread ? experiments::Format("experiment %s on %d ranks: %.1f s\n",
                                                 name.c_str(), job.Size(), NowSeconds() - te)
                           : experiments::Format("experiment %s on rank %d of %d: %.1f s\n",
                                                 name.c_str(), job.Rank(), job.Size(),
                                                 NowSeconds() - te);
        }
    } catch (...) {
        // A refused option (an unknown --methods name, say) leaves no empty --out behind.
        namespace fs = std::filesystem;
        std::error_code ec;
        if (created && fs::is_empty(a.out, ec)) fs::remove(a.out, ec);
        throw;
    }
    if (job.Size() > 1) {
        // Rank 0 reports every rank's experiments (their files are already in --out).
        const std::vector<std::vector<char>> lines = job.Gather({mine.begin(), mine.end()});
        std::vector<uint64_t> codes = job.AllGather({uint64_t(code)});
        for (const uint64_t c : codes) code = std::max(code, int(c));
        if (job.Rank() != 0) return code;
        for (const std::vector<char>& l : lines) std::fwrite(l.data(), 1, l.size(), stdout);
        std::printf(
            "(each rank timed its own renders; an experiment on all ranks names the rank "
            "of each render in its markdown)\n");
    }
    std::printf("experiment %s finished in %.1f s\n", a.name.c_str(), NowSeconds() - t0);
    return code;
}

}  // namespace

void AddExperimentCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<ExperimentArgs>();
    CLI::App* cmd = app.add_subcommand(
        "experiment", "Run one of the paper's experiments: CSV + PNG plots + markdown summary");
    cmd->add_option(
           "name", args->name,
           "One of: " + ExperimentNames() +
               "; or several, comma separated (over MPI ranks, speed-vs-error, equal-time, "
               "cache-size, lod-bias, filter-size and cpis spread their renders over all ranks, "
               "the others are dealt round-robin; threads always runs whole on one rank, since "
               "it measures how one process scales with its threads)")
        ->required();
    cmd->add_option("--out", args->out, "Output directory (created if missing)")->required();
    cmd->add_flag("--quick", args->quick,
                  "Test size: small images and budgets (under a minute); not for conclusions");
    cmd->add_option("--only", args->only,
                    "speed-vs-error: run only these cases (comma separated, e.g. car-ao,chess-ao); "
                    "temporal, equal-time: only these scenes (e.g. anim_shadow,anim_glossy)");
    cmd->add_option("--methods", args->methods,
                    "speed-vs-error: run only these methods (comma separated, e.g. "
                    "per-hit,ts-hits); an earlier run's other rows in --out are kept");
    cmd->add_option("--camera-spp", args->cameraSpp,
                    "speed-vs-error: camera samples per pixel, the same rays for every render "
                    "(default 4; Munkberg et al. Fig. 7 use 16)");
    cmd->add_flag("--ablation", args->ablation,
                  "temporal: also Reliable (demodulation on) with issue 5's defaults (glossy "
                  "and indirect clamped, indirect in cones), alpha 0.1 (the paper's), the glossy "
                  "jitter cap at 4 and 16 px, without clamping, and with its visibility in "
                  "SVGF's and in Zeng's order, summarised in temporal_ablation.md");
    cmd->add_option("--scenes", args->scenes, "Directory of the bundled scenes")
        ->capture_default_str();
    cmd->add_option("--set", args->set,
                    "equal-time: the directory of scenes it compares per hit and texture space on "
                    "(scenes no setting was chosen on)")
        ->capture_default_str();
    cmd->callback([args, cmd, &exitCode] {
        for (const CLI::Option* o : cmd->get_options())
            if (o->count() > 0) args->given.insert(o->get_name());
        exitCode = RunExperiment(*args);
    });
}

}  // namespace texcache::cli
