// SPDX-License-Identifier: Apache-2.0
// Runs the `texcache` program from a test and captures its output and exit code.
#pragma once
#include <sys/wait.h>

#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

namespace texcache::test {

struct CliRun {
    int code;         ///< exit code (-1 if it did not exit normally)
    std::string out;  ///< stdout + stderr
};

/// `texcache ARGS`; killed after `timeoutSeconds` when > 0 (exit code 137).
inline CliRun Texcache(const std::string& args, int timeoutSeconds = 0) {
    const std::string limit =
        timeoutSeconds > 0 ? "timeout -s KILL " + std::to_string(timeoutSeconds) + " " : "";
    const std::string cmd = limit + std::string(TEXCACHE_BIN_DIR) + "/texcache " + args + " 2>&1";
    FILE* p = popen(cmd.c_str(), "r");
    CliRun r{-1, ""};
    if (!p) return r;
    std::array<char, 4096> buf;
    size_t n;
    while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), n);
    const int status = pclose(p);
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

/// A directory of the test's temporary directory (created), for one test file's files.
inline std::filesystem::path CliTempDir(const std::string& name) {
    const std::filesystem::path d = std::filesystem::path(::testing::TempDir()) / name;
    std::filesystem::create_directories(d);
    return d;
}

}  // namespace texcache::test
