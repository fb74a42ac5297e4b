# All dependencies come from Debian packages (scripts/setup.sh installs them).
find_package(embree 3 REQUIRED)
find_package(TBB CONFIG REQUIRED)
find_package(glm CONFIG REQUIRED)
find_package(OpenEXR CONFIG REQUIRED)
find_package(PNG REQUIRED)
find_package(Eigen3 CONFIG REQUIRED)
find_package(nlohmann_json CONFIG REQUIRED)
find_package(CLI11 CONFIG QUIET)
find_package(GTest CONFIG REQUIRED)
find_package(benchmark CONFIG QUIET)
find_package(PkgConfig REQUIRED)

# OpenImageIO's CMake config on Debian drags in openimageio-tools and OpenCV: use pkg-config.
pkg_check_modules(OIIO REQUIRED IMPORTED_TARGET OpenImageIO)

# OpenSubdiv's CMake config names libosdCPU.a, which Debian does not ship: find the shared lib.
find_path(OSD_INCLUDE_DIR opensubdiv/far/topologyRefiner.h REQUIRED)
find_library(OSD_CPU_LIBRARY osdCPU REQUIRED)
add_library(opensubdiv::osdcpu SHARED IMPORTED)
set_target_properties(opensubdiv::osdcpu PROPERTIES
  IMPORTED_LOCATION ${OSD_CPU_LIBRARY}
  INTERFACE_INCLUDE_DIRECTORIES ${OSD_INCLUDE_DIR})

if(NOT TARGET CLI11::CLI11)
  find_path(CLI11_INCLUDE_DIR CLI/CLI.hpp REQUIRED)
  add_library(CLI11::CLI11 INTERFACE IMPORTED)
  set_target_properties(CLI11::CLI11 PROPERTIES INTERFACE_INCLUDE_DIRECTORIES ${CLI11_INCLUDE_DIR})
endif()
