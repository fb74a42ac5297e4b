// SPDX-License-Identifier: Apache-2.0
// `texcache`: render, compare and benchmark texture-space cached shading on subdivision surfaces.
#include <cstdio>
#include <exception>
#include <new>

#include "commands.h"
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

}  // namespace

int main(int argc, char** argv) {
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
    RejectEmptyValues(&app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::Success& e) {  // --help, --version
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        // Malformed options exit 2 like any other bad input, in the same one-line form.
        std::fprintf(stderr, "texcache: error: %s (see %s --help)\n",
                     texcache::internal::OneLine(e.what()).c_str(), CommandPath(app).c_str());
        return 2;
    } catch (const texcache::InputError& e) {
        std::fprintf(stderr, "texcache: error: %s\n", e.what());
        return 2;
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "texcache: error: out of memory\n");
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "texcache: internal error: %s\n",
                     texcache::internal::OneLine(e.what()).c_str());
        return 1;
    }
    return exitCode;
}
