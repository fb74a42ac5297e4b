# Warnings and sanitizers as INTERFACE targets, linked by every project target.
add_library(texcache_warnings INTERFACE)
# -Wno-restrict: GCC 12 false positive in libstdc++ string concatenation (GCC PR 105329).
target_compile_options(texcache_warnings INTERFACE -Wall -Wextra -Wpedantic -Wno-unused-parameter -Wno-restrict)

add_library(texcache_sanitizers INTERFACE)
if(TEXCACHE_SANITIZE STREQUAL "address")
  target_compile_options(texcache_sanitizers INTERFACE -fsanitize=address,undefined -fno-omit-frame-pointer)
  target_link_options(texcache_sanitizers INTERFACE -fsanitize=address,undefined)
elseif(TEXCACHE_SANITIZE STREQUAL "thread")
  target_compile_options(texcache_sanitizers INTERFACE -fsanitize=thread -fno-omit-frame-pointer)
  target_link_options(texcache_sanitizers INTERFACE -fsanitize=thread)
endif()

add_library(texcache_options INTERFACE)
target_link_libraries(texcache_options INTERFACE texcache_warnings texcache_sanitizers)
