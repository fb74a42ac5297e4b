// SPDX-License-Identifier: Apache-2.0
#include "renderer/library_versions.h"

#include <OpenEXR/OpenEXRConfig.h>
#include <embree3/rtcore_config.h>
#include <opensubdiv/version.h>

#include <string>

// CMake defines both for this file: the project's version, and OpenImageIO's as pkg-config
// reported it when the module was configured.
#ifndef TEXCACHE_VERSION
#error "TEXCACHE_VERSION is set by renderer/CMakeLists.txt"
#endif
#ifndef TEXCACHE_OIIO_VERSION
#error "TEXCACHE_OIIO_VERSION is set by renderer/CMakeLists.txt"
#endif

namespace texcache {

const char* TexcacheVersion() {
    return TEXCACHE_VERSION;
}

std::vector<LibraryVersion> LibraryVersions() {
    const std::string osd = std::to_string(OPENSUBDIV_VERSION_MAJOR) + "." +
                            std::to_string(OPENSUBDIV_VERSION_MINOR) + "." +
                            std::to_string(OPENSUBDIV_VERSION_PATCH);
    return {{"Embree", RTC_VERSION_STRING},
            {"OpenSubdiv", osd},
            {"OpenEXR", OPENEXR_VERSION_STRING},
            {"OpenImageIO", TEXCACHE_OIIO_VERSION}};
}

}  // namespace texcache
