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

# MPI (Debian's Open MPI: libopenmpi-dev, openmpi-bin): one render, animation or experiment over
# many ranks (docs/cluster.md). Found, it is used; TEXCACHE_MPI=OFF builds without it, and the
# program is then the same as one launched without mpirun.
option(TEXCACHE_MPI "Use MPI when it is found (renders over many ranks)" ON)
set(TEXCACHE_HAVE_MPI OFF)
if(TEXCACHE_MPI)
  enable_language(C)  # FindMPI's C component looks for the C compiler wrapper
  find_package(MPI COMPONENTS C QUIET)
  if(MPI_C_FOUND)
    set(TEXCACHE_HAVE_MPI ON)
    find_program(TEXCACHE_MPIEXEC NAMES mpirun mpiexec HINTS ${MPIEXEC_EXECUTABLE})
  endif()
endif()
message(STATUS "texcache: MPI ${TEXCACHE_HAVE_MPI}")
