// SPDX-License-Identifier: Apache-2.0
// Output files that appear complete or not at all, alone or as a group: a failed or interrupted
// run never leaves a partial file, and a run that writes several files (an EXR, the PNG beside
// it, --stats) replaces none of them unless all of them were written.
#pragma once
#include <string>
#include <vector>

namespace texcache {

/// A group of files written together. Stage(path) names the temporary file ("<path>.tmp-<pid>",
/// in the target's directory so that the rename stays within one file system) to write `path`
/// into; Commit() renames every staged file over its target once all are complete. Temporaries
/// not committed (an exception on the way) are removed by the destructor, so the targets keep
/// their old contents.
class AtomicFiles {
public:
    AtomicFiles() = default;
    AtomicFiles(const AtomicFiles&) = delete;
    AtomicFiles& operator=(const AtomicFiles&) = delete;
    ~AtomicFiles();

    /// The temporary path to write `path` into.
    std::string Stage(const std::string& path);
    /// Renames the staged files over their targets, in staging order. If a rename fails (the
    /// caller checked the outputs first, see cli::FileSet, so this means the disk changed under
    /// us) the remaining temporaries are removed and InputError names the path.
    void Commit();

private:
    struct Staged {
        std::string path, temp;
    };
    std::vector<Staged> staged_;
};

}  // namespace texcache
