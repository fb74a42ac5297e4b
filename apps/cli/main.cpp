// SPDX-License-Identifier: Apache-2.0
// `texcache`: render, compare and benchmark texture-space cached shading on subdivision surfaces.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <memory>
#include <new>
#include <string>
#include <vector>

#if defined(__linux__) && defined(__GLIBC__)
#include <unistd.h>
#endif

#include "commands.h"
#include "job.h"
#include "renderer/library_versions.h"
#include "texcache/error.h"

namespace {

/// An empty value ("--threads ''") would otherwise read as "not given" or as 0: every option of
/// every subcommand rejects it, naming itself (CLI11 runs validators before converting).
void RejectEmptyValues(CLI::App* app) {
    for (CLI::Option* opt : app->get_options())
        opt->check(CLI::Validator(
            [](std::string& v) { return v.empty() ? std::string("empty value") : std::string(); },
            "", "non-empty"));
    for (CLI::App* sub : app->get_subcommands([](CLI::App*) { return true; }))
        RejectEmptyValues(sub);
}

/// What `texcache --version` prints: texcache's version, then each library's.
std::string VersionReport() {
    std::string s = std::string("texcache ") + texcache::TexcacheVersion();
    for (const texcache::LibraryVersion& v : texcache::LibraryVersions())
        s += "\n  " + v.name + " " + v.version;
    return s;
}

/// The name of the (innermost) subcommand being parsed, for the usage hint.
std::string CommandPath(const CLI::App& app) {
    std::string path = "texcache";
    const CLI::App* at = &app;
    for (;;) {
        const std::vector<const CLI::App*> parsed =
            at->get_subcommands([](const CLI::App* s) { return s->parsed(); });
        if (parsed.empty()) return path;
        at = parsed.front();
        path += " " + at->get_name();
    }
}

/// When the innermost parsed command needs a subcommand and was given an unknown word instead
/// (`texcache bench bogus`), a message naming the word and the valid ones; else empty.
std::string UnknownSubcommand(const CLI::App& app) {
    const CLI::App* at = &app;
    for (;;) {
        const std::vector<const CLI::App*> parsed =
            at->get_subcommands([](const CLI::App* s) { return s->parsed(); });
        if (parsed.empty()) break;
        at = parsed.front();
    }
    const std::vector<const CLI::App*> subs = at->get_subcommands({});
    const std::vector<std::string> rest = at->remaining();
    if (subs.empty() || rest.empty() || rest.front().starts_with("-")) return "";
    std::string valid;
    for (const CLI::App* s : subs) valid += (valid.empty() ? "" : ", ") + s->get_name();
    return CommandPath(app) + ": unknown subcommand '" + rest.front() + "' (valid: " + valid + ")";
}

/// Large allocations on 2 MiB pages: the process runs again at once, with glibc's malloc asked
/// to advise transparent huge pages for the memory it maps (the tunable is read only at start),
/// where the kernel gives them on advice alone (the usual "madvise" setting). The frame buffers,
/// the store's tables and the stage's planes, tens of MB together, are read and written all
/// over every frame: on 4 KiB pages their accesses miss the TLB, whose walks cost most in a
/// virtual machine and under load (results/preview.md, "Store frames on 2 MiB pages", measures
/// the orbit bench both ways; the images are the same). GLIBC_TUNABLES naming the tunable
/// already (=0 to opt out) leaves the process as it is; so does a failed exec. A program that
/// links the libraries itself sets the tunable in its own environment to get the same.
void UseHugePages(char** argv) {
#if defined(__linux__) && defined(__GLIBC__)
    constexpr const char* kTunable = "glibc.malloc.hugetlb";
    const char* tunables = std::getenv("GLIBC_TUNABLES");
    if (tunables && std::strstr(tunables, kTunable)) return;
    std::ifstream mode("/sys/kernel/mm/transparent_hugepage/enabled");
    std::string line;
    if (!std::getline(mode, line) || line.find("[madvise]") == std::string::npos) return;
    const std::string value =
        (tunables && *tunables ? std::string(tunables) + ":" : std::string()) + kTunable + "=1";
    // The program's own path, not /proc/self/exe: the process keeps its name ("texcache" in
    // ps, top and perf, where /proc/self/exe would name it "exe").
    char path[4096];
    const ssize_t n = readlink("/proc/self/exe", path, sizeof path - 1);
    if (n <= 0) return;
    path[n] = '\0';
    if (setenv("GLIBC_TUNABLES", value.c_str(), 1) != 0) return;
    execv(path, argv);
#else
    (void)argv;
#endif
}

}  // namespace

int main(int argc, char** argv) {
    UseHugePages(argv);
    // The job first: MPI may take its own arguments out of argv.
    std::unique_ptr<texcache::RankGroup> job;
    try {
        job = texcache::JoinJob(&argc, &argv);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "texcache: error: %s\n",
                     texcache::internal::OneLine(e.what()).c_str());
        return 2;
    }
    texcache::cli::SetJob(job.get());
    const int rank = job->Rank();
    // Over many ranks, an error on the way (not agreed on by every rank: OnEveryRank) is this
    // rank's alone: named with its rank, then the job stopped, as the others wait for it.
    auto fail = [&](const char* kind, const std::string& what, int code) {
        if (job->Size() == 1) {
            std::fprintf(stderr, "texcache: %s: %s\n", kind, what.c_str());
            return code;
        }
        std::fprintf(stderr, "texcache: %s: rank %d of %d: %s\n", kind, rank, job->Size(),
                     what.c_str());
        std::fflush(stderr);
        job->Abort(code);
        return code;  // not reached
    };
    CLI::App app{"texcache: texture-space shading cache for ray-traced subdivision surfaces"};
    app.require_subcommand(1);
    app.set_version_flag("--version", VersionReport,
                         "Print texcache's version and its libraries' (Embree, OpenSubdiv, "
                         "OpenEXR, OpenImageIO), then exit");
    int exitCode = 0;
    texcache::cli::AddRenderCommand(app, exitCode);
    texcache::cli::AddCompareCommand(app, exitCode);
    texcache::cli::AddMontageCommand(app, exitCode);
    texcache::cli::AddBenchCommand(app, exitCode);
    texcache::cli::AddExperimentCommand(app, exitCode);
    texcache::cli::AddPreviewCommand(app, exitCode);
    texcache::cli::AddPtexCommand(app, exitCode);
    texcache::cli::AddBakeCommand(app, exitCode);
    RejectEmptyValues(&app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::Success& e) {  // --help, --version: every rank parses the same argv
        return rank == 0 ? app.exit(e) : 0;
    } catch (const CLI::ParseError& e) {
        // Malformed options exit 2 like any other bad input, in the same one-line form (once).
        if (rank != 0) return 2;
        if (const std::string unknown = UnknownSubcommand(app); !unknown.empty()) {
            std::fprintf(stderr, "texcache: error: %s\n",
                         texcache::internal::OneLine(unknown).c_str());
            return 2;
        }
        std::fprintf(stderr, "texcache: error: %s (see %s --help)\n",
                     texcache::internal::OneLine(e.what()).c_str(), CommandPath(app).c_str());
        return 2;
    } catch (const texcache::cli::JobFailed& e) {  // reported by rank 0 (AgreeOrFail)
        return e.code;
    } catch (const texcache::InputError& e) {
        return fail("error", e.what(), 2);
    } catch (const std::bad_alloc&) {
        return fail("error", "out of memory", 1);
    } catch (const std::exception& e) {
        return fail("internal error", texcache::internal::OneLine(e.what()), 1);
    }
    return exitCode;
}
