// SPDX-License-Identifier: Apache-2.0
// `texcache experiment <name> --out DIR [--quick]`: reproduce a claim of the paper on our scenes
// and write CSV + PNG plots + a markdown summary into DIR.
#include <algorithm>
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
        {"blur", experiments::Blur},
    };
    return m;
}

std::string ExperimentNames() {
    std::string s;
    for (const auto& [name, fn] : Experiments()) s += (s.empty() ? "" : ", ") + name;
    return s + ", all";
}

int RunExperiment(const ExperimentArgs& a) {
    const auto& all = Experiments();
    if (a.name != "all" && !all.count(a.name))
        throw InputError("experiment",
                         "unknown experiment '" + a.name + "' (valid: " + ExperimentNames() + ")");
    // Options of some experiments only: given to another, they would do nothing.
    const std::pair<const char*, std::vector<std::string>> scoped[] = {
        {"--only", {"speed-vs-error", "temporal"}},
        {"--methods", {"speed-vs-error"}},
        {"--camera-spp", {"speed-vs-error"}},
        {"--ablation", {"temporal"}}};
    for (const auto& [option, experiments] : scoped) {
        if (a.name == "all" || !a.given.count(option)) continue;
        if (std::find(experiments.begin(), experiments.end(), a.name) != experiments.end())
            continue;
        std::string list;
        for (const std::string& e : experiments) list += (list.empty() ? "" : " and ") + e;
        throw InputError(option, "applies to the " + list + " experiment" +
                                     (experiments.size() > 1 ? "s" : "") + ", not '" + a.name +
                                     "'");
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
    experiments::Setup s{a.out, a.scenes, a.quick, a.only, a.methods, a.cameraSpp, a.ablation};
    const double t0 = NowSeconds();
    int code = 0;
    try {
        for (const auto& [name, fn] : all)
            if (a.name == "all" || a.name == name) code = std::max(code, fn(s));
    } catch (...) {
        // A refused option (an unknown --methods name, say) leaves no empty --out behind.
        if (created && fs::is_empty(a.out, ec)) fs::remove(a.out, ec);
        throw;
    }
    std::printf("experiment %s finished in %.1f s\n", a.name.c_str(), NowSeconds() - t0);
    return code;
}

}  // namespace

void AddExperimentCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<ExperimentArgs>();
    CLI::App* cmd = app.add_subcommand(
        "experiment", "Run one of the paper's experiments: CSV + PNG plots + markdown summary");
    cmd->add_option("name", args->name, "One of: " + ExperimentNames())->required();
    cmd->add_option("--out", args->out, "Output directory (created if missing)")->required();
    cmd->add_flag("--quick", args->quick,
                  "Test size: small images and budgets (under a minute); not for conclusions");
    cmd->add_option("--only", args->only,
                    "speed-vs-error: run only these cases (comma separated, e.g. car-ao,chess-ao); "
                    "temporal: only these scenes (e.g. anim_shadow,anim_glossy)");
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
    cmd->callback([args, cmd, &exitCode] {
        for (const CLI::Option* o : cmd->get_options())
            if (o->count() > 0) args->given.insert(o->get_name());
        exitCode = RunExperiment(*args);
    });
}

}  // namespace texcache::cli
