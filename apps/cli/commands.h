// SPDX-License-Identifier: Apache-2.0
// Subcommands of the `texcache` program. Each Add*Command registers a CLI11 subcommand whose
// callback stores its exit code in `exitCode`; user errors are thrown as texcache::InputError and
// turned into a message + exit code 2 by main().
#pragma once
#include <CLI/CLI.hpp>

namespace texcache::cli {

void AddRenderCommand(CLI::App& app, int& exitCode);
void AddCompareCommand(CLI::App& app, int& exitCode);
void AddMontageCommand(CLI::App& app, int& exitCode);
void AddBenchCommand(CLI::App& app, int& exitCode);
/// `bench peer` (cmd_bench_peer.cpp), registered by AddBenchCommand under `bench`.
void AddBenchPeerCommand(CLI::App& bench, int& exitCode);
void AddPreviewCommand(CLI::App& app, int& exitCode);
void AddExperimentCommand(CLI::App& app, int& exitCode);
/// `ptex info` (cmd_ptex.cpp).
void AddPtexCommand(CLI::App& app, int& exitCode);
/// `bake` (cmd_bake.cpp).
void AddBakeCommand(CLI::App& app, int& exitCode);

}  // namespace texcache::cli
