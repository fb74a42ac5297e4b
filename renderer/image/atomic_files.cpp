// SPDX-License-Identifier: Apache-2.0
#include "renderer/image/atomic_files.h"

#include <unistd.h>

#include <filesystem>

#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;

AtomicFiles::~AtomicFiles() {
    std::error_code ignored;
    for (const Staged& s : staged_) fs::remove(s.temp, ignored);
}

std::string AtomicFiles::Stage(const std::string& path) {
    staged_.push_back({path, path + ".tmp-" + std::to_string(::getpid())});
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
