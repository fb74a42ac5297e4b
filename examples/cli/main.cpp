// SPDX-License-Identifier: Apache-2.0
// `texcache`: render, compare and benchmark texture-space cached shading on subdivision surfaces.
#include <cstdio>
#include <exception>

#include "commands.h"
#include "texcache/error.h"

int main(int argc, char** argv) {
    CLI::App app{"texcache: texture-space shading cache for ray-traced subdivision surfaces"};
    app.require_subcommand(1);
    int exitCode = 0;
    texcache::cli::AddRenderCommand(app, exitCode);
    texcache::cli::AddCompareCommand(app, exitCode);
    texcache::cli::AddMontageCommand(app, exitCode);
    texcache::cli::AddBenchCommand(app, exitCode);
    texcache::cli::AddExperimentCommand(app, exitCode);
    texcache::cli::AddPreviewCommand(app, exitCode);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // --help exits 0; malformed options exit 2 like any other bad input.
        int code = app.exit(e);
        return code == 0 ? 0 : 2;
    } catch (const texcache::InputError& e) {
        std::fprintf(stderr, "texcache: error: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "texcache: internal error: %s\n", e.what());
        return 1;
    }
    return exitCode;
}
