# Warnings and sanitizers as INTERFACE targets, linked by every project target.
add_library(texcache_warnings INTERFACE)
# -Wno-restrict: GCC 12 false positive in libstdc++ string concatenation (GCC PR 105329).
# -Wno-psabi: GCC's note that 32-byte vector arguments are passed differently since GCC 4.6, which
# the screen-space kernels' static helpers print in builds without AVX (the sanitizer builds); no
# such function crosses a library boundary.
target_compile_options(texcache_warnings INTERFACE -Wall -Wextra -Wpedantic -Wno-unused-parameter -Wno-restrict
                       -Wno-psabi)
# scripts/test.sh (so CI) turns this on: a new warning in project code fails the build there.
# Off by default, so that a newer compiler's new warnings don't break a developer's build.
option(TEXCACHE_WERROR "Treat compiler warnings in project code as errors" OFF)
if(TEXCACHE_WERROR)
  target_compile_options(texcache_warnings INTERFACE -Werror)
endif()

add_library(texcache_sanitizers INTERFACE)
if(NOT TEXCACHE_SANITIZE STREQUAL "")
  # One ISA for the screen-space kernels (screen_space/internal.h says why).
  target_compile_definitions(texcache_sanitizers INTERFACE TEXCACHE_NO_ISA_CLONES)
endif()
if(TEXCACHE_SANITIZE STREQUAL "address")
  # -fno-sanitize-recover: an UBSan finding aborts the program (so fails its test) instead of
  # printing a report and going on, as ASan findings already do. UBSan's null and
  # pointer-overflow checks are left out: they check every member access and pointer step, which
  # is most of UBSan's compile time (in Eigen's and the renderer's inlined code), and a null
  # pointer that is dereferenced still stops the test under ASan, with its stack.
  target_compile_options(texcache_sanitizers INTERFACE -fsanitize=address,undefined
                         -fno-sanitize=null,pointer-overflow -fno-sanitize-recover=all
                         -fno-omit-frame-pointer)
  target_link_options(texcache_sanitizers INTERFACE -fsanitize=address,undefined)
elseif(TEXCACHE_SANITIZE STREQUAL "thread")
  target_compile_options(texcache_sanitizers INTERFACE -fsanitize=thread -fno-omit-frame-pointer)
  target_link_options(texcache_sanitizers INTERFACE -fsanitize=thread)
elseif(NOT TEXCACHE_SANITIZE STREQUAL "")
  message(FATAL_ERROR "TEXCACHE_SANITIZE must be address, thread or empty, not '${TEXCACHE_SANITIZE}'")
endif()

add_library(texcache_options INTERFACE)
target_link_libraries(texcache_options INTERFACE texcache_warnings texcache_sanitizers)
# No code here reads errno after a math call; without this flag every std::sqrt carries a
# branch to the library's sqrtf for negative input, which also keeps loops of it scalar (with it
# the camera ray's normalize is a sixth of a sky-only frame's CPU time: `perf annotate`).
target_compile_options(texcache_options INTERFACE -fno-math-errno)

# Sanitizer builds compile code that only drives the libraries at -O0: the render tests, the CLI
# and the experiments' orchestration. Under ASan + UBSan that is a third of the compile time of
# -O1 (`time` on a test file's compile command from build-asan/'s compile_commands.json), and
# their run time stays with the libraries they call, which keep -O1 (a test file at -O0 runs
# about as fast as at -O1). The cache library's tests keep -O1: they instantiate its templates
# themselves.
function(texcache_driver_code target)
  if(NOT TEXCACHE_SANITIZE STREQUAL "")
    target_compile_options(${target} PRIVATE -O0)
  endif()
endfunction()

# The render tests' own code (scenes set up, checks, statistics of images) compiles at -O1 in the
# optimized builds too: their run time is in the libraries, which keep the build type's -O3, and
# the test files are near half of a fresh build's compile time at -O3. The cache library's tests
# keep -O3: they instantiate its templates themselves.
function(texcache_test_code target)
  if(TEXCACHE_SANITIZE STREQUAL "" AND CMAKE_BUILD_TYPE MATCHES "^(Release|RelWithDebInfo)$")
    target_compile_options(${target} PRIVATE -O1)
  endif()
endfunction()
