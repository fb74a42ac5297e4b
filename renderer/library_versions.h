// SPDX-License-Identifier: Apache-2.0
// The version of texcache and of the libraries it renders with, for `texcache --version` and
// for bug reports.
#pragma once
#include <string>
#include <vector>

namespace texcache {

/// texcache's own version (the project's version in CMakeLists.txt).
const char* TexcacheVersion();

/// A library and the version texcache was built against.
struct LibraryVersion {
    std::string name, version;
};

/// Embree, OpenSubdiv, OpenEXR and OpenImageIO, in that order. OpenImageIO's is the version its
/// module (texcache_oiio) was built against, known without loading the module, which a process
/// opens only for its first image that is not an EXR (renderer/image/image_file.h says why).
std::vector<LibraryVersion> LibraryVersions();

}  // namespace texcache
