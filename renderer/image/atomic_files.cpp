// SPDX-License-Identifier: Apache-2.0
#include "renderer/image/atomic_files.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <mutex>
#include <set>
#include <string_view>

#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;

namespace {

constexpr size_t kMaxFileName = 255;  // NAME_MAX of Linux's file systems

/// The pid of a temporary's name ("<name>.tmp-<pid>" or "<name>.probe-<pid>"), or 0.
pid_t TemporaryPid(std::string_view name) {
    for (const std::string_view tag : {".tmp-", ".probe-"}) {
        const size_t at = name.rfind(tag);
        if (at == std::string_view::npos || at == 0) continue;
        const std::string_view digits = name.substr(at + tag.size());
        if (digits.empty() || digits.size() > 9 ||
            digits.find_first_not_of("0123456789") != std::string_view::npos)
            continue;
        return pid_t(std::stol(std::string(digits)));
    }
    return 0;
}

}  // namespace

std::string TemporaryPath(const std::string& path, const char* tag) {
    const fs::path p(path);
    const std::string name = p.filename().string();
    const std::string suffix = "." + std::string(tag) + "-" + std::to_string(::getpid());
    if (name.size() + suffix.size() <= kMaxFileName) return path + suffix;
    char hash[24];
    std::snprintf(hash, sizeof hash, "~%016zx", std::hash<std::string>{}(name));
    const std::string cut = name.substr(0, kMaxFileName - suffix.size() - 17) + hash;
    return (p.parent_path() / (cut + suffix)).string();
}

void RemoveStaleTemporaries(const std::string& path) {
    const fs::path parent = fs::path(path).parent_path();
    const fs::path dir = parent.empty() ? fs::path(".") : parent;
    static std::mutex mutex;
    static std::set<std::string> scanned;
    std::error_code ec;
    {
        const std::lock_guard<std::mutex> lock(mutex);
        if (!scanned.insert(fs::absolute(dir, ec).lexically_normal().string()).second) return;
    }
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        const pid_t pid = TemporaryPid(it->path().filename().string());
        if (pid <= 0 || pid == ::getpid()) continue;
        // ESRCH: no such process. EPERM means it exists (another user's): keep its files.
        if (::kill(pid, 0) == 0 || errno != ESRCH) continue;
        std::error_code ignored;
        if (it->is_regular_file(ignored)) fs::remove(it->path(), ignored);
    }
}

AtomicFiles::~AtomicFiles() {
    std::error_code ignored;
    for (const Staged& s : staged_) fs::remove(s.temp, ignored);
}

std::string AtomicFiles::Stage(const std::string& path) {
    RemoveStaleTemporaries(path);
    staged_.push_back({path, TemporaryPath(path, "tmp")});
    return staged_.back().temp;
}

void AtomicFiles::Commit() {
    for (size_t i = 0; i < staged_.size(); ++i) {
        std::error_code ec;
        fs::rename(staged_[i].temp, staged_[i].path, ec);
        if (ec) {
            const std::string path = staged_[i].path;
            staged_.erase(staged_.begin(), staged_.begin() + std::ptrdiff_t(i));
            throw InputError(path, "cannot write file: " + ec.message());  // ~ removes the rest
        }
    }
    staged_.clear();
}

}  // namespace texcache
