// SPDX-License-Identifier: Apache-2.0
// Output files that appear complete or not at all, alone or as a group: a failed or interrupted
// run never leaves a partial file, and a run that writes several files (an EXR, the PNG beside
// it, --stats) replaces none of them unless all of them were written.
#pragma once
#include <string>
#include <vector>

namespace texcache {

/// The temporary file "<path>.<tag>-<pid>" of this process for `path` (tag "tmp", "probe"), in
/// the target's directory so that a rename stays within one file system. A file name too long
/// for that (file names hold 255 bytes) is cut and a hash of the whole added, so that any legal
/// output name has a legal temporary.
std::string TemporaryPath(const std::string& path, const char* tag);

/// Removes the temporaries (TemporaryPath: "<name>.tmp-<pid>", "<name>.probe-<pid>") in
/// `path`'s directory whose process is gone: a killed run leaves them behind. Each directory is
/// scanned once per process; files of live processes (or of any other form) are left alone.
void RemoveStaleTemporaries(const std::string& path);

/// A group of files written together. Stage(path) names the temporary file (TemporaryPath,
/// after RemoveStaleTemporaries) to write `path` into; Commit() renames every staged file over its
/// target once all are complete. Temporaries not committed (an exception on the way) are removed by
/// the destructor, so the targets keep their old contents.
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
