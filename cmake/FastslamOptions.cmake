# Compiler flags shared by every target, and the helpers that declare libraries, executables,
# tests and benchmarks the same way everywhere.
include_guard(GLOBAL)

add_library(fastslam_warnings INTERFACE)
target_compile_options(fastslam_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Wcast-align -Woverloaded-virtual
  -Wnull-dereference -Wimplicit-fallthrough
  # GCC 12 reports Eigen's AVX2 packet loads of fixed-size vectors as out of bounds (a false
  # positive of its array-bounds analysis after inlining; GCC bug 106247 and kin).
  $<$<CXX_COMPILER_ID:GNU>:-Wno-array-bounds>
  # With AVX-512 (-march=native on such a machine) GCC 12 reports Eigen's masked packet loads as
  # reading an uninitialised register inside avx512fintrin.h: the same kind of false positive.
  $<$<CXX_COMPILER_ID:GNU>:-Wno-maybe-uninitialized>
  $<$<BOOL:${FASTSLAM_WERROR}>:-Werror>)

# A portable build (FASTSLAM_PORTABLE) compiles every target for FASTSLAM_PORTABLE_ARCH and
# refuses flags that would tie it to this machine or to a newer instruction set: only the
# random-stream kernels go beyond the baseline, each copy behind a run-time check
# (parallel/CMakeLists.txt). FASTSLAM_X86_64 says whether those copies exist.
set(FASTSLAM_X86_64 OFF)
if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
  set(FASTSLAM_X86_64 ON)
endif()
if(FASTSLAM_PORTABLE)
  string(TOUPPER "${CMAKE_BUILD_TYPE}" _fastslam_type)
  foreach(_fastslam_flags CMAKE_CXX_FLAGS CMAKE_CXX_FLAGS_${_fastslam_type})
    if(" ${${_fastslam_flags}} " MATCHES " -(march|mtune|mcpu)=|native| -m(avx|fma|sse|bmi)")
      message(FATAL_ERROR "FASTSLAM_PORTABLE: ${_fastslam_flags} ('${${_fastslam_flags}}') "
        "chooses an instruction set; remove it (the package preset's flags are -O3 -DNDEBUG) and "
        "set FASTSLAM_PORTABLE_ARCH instead")
    endif()
  endforeach()
  if(FASTSLAM_X86_64)
    add_compile_options(-march=${FASTSLAM_PORTABLE_ARCH})
  endif()
endif()

add_library(fastslam_sanitize INTERFACE)
if(FASTSLAM_SANITIZE)
  list(JOIN FASTSLAM_SANITIZE "," _fastslam_san)
  target_compile_options(fastslam_sanitize INTERFACE -fsanitize=${_fastslam_san}
    -fno-omit-frame-pointer -fno-sanitize-recover=all)
  target_link_options(fastslam_sanitize INTERFACE -fsanitize=${_fastslam_san})
endif()

# fastslam_library(NAME [NO_INSTALL] SOURCES ... DEPS ...): the library of one source folder,
# fastslam::NAME, installed and exported unless NO_INSTALL (a part of the build only, as the
# bindings' shared code); includes are by path from the repository root
# ("memory/landmark_tree.h").
# Installed, the headers sit in include/fastslam/<folder>/ (cmake/FastslamInstall.cmake) and
# consumers write <fastslam/engine/filter.h>, which needs include/ on their path. The headers
# include one another as the sources do, by path from the root ("engine/filter_config.h"),
# which needs include/fastslam too: both are exported, and the installed headers are the
# sources unchanged (rewriting their includes at install time would make the installed text
# differ from the tested one). The cost: memory/, parallel/ and engine/ are top-level names on
# a consumer's include path (as -isystem, searched after its own -I directories), so a header
# of the consumer's at the same relative path as one of ours (engine/pose.h in one of its -I
# directories) would be found first, by our headers too. Consumers spell ours fastslam/....
function(fastslam_library name)
  cmake_parse_arguments(ARG "NO_INSTALL" "" "SOURCES;DEPS" ${ARGN})
  add_library(fastslam_${name} ${ARG_SOURCES})
  add_library(fastslam::${name} ALIAS fastslam_${name})
  set_target_properties(fastslam_${name} PROPERTIES EXPORT_NAME ${name} OUTPUT_NAME fastslam_${name})
  target_include_directories(fastslam_${name} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>
    $<INSTALL_INTERFACE:include>
    $<INSTALL_INTERFACE:include/fastslam>)
  target_link_libraries(fastslam_${name} PUBLIC ${ARG_DEPS}
    PRIVATE $<BUILD_INTERFACE:fastslam_warnings> $<BUILD_INTERFACE:fastslam_sanitize>)
  target_compile_features(fastslam_${name} PUBLIC cxx_std_20)
  if(NOT ARG_NO_INSTALL)
    set_property(GLOBAL APPEND PROPERTY FASTSLAM_LIBRARIES fastslam_${name})
  endif()
endfunction()

# Every executable we ship (CLI, tests, benchmarks) gets jemalloc as its malloc, unless a
# sanitizer brings its own allocator.
function(fastslam_executable_setup target)
  target_link_libraries(${target} PRIVATE fastslam_warnings fastslam_sanitize)
  if(FASTSLAM_WITH_JEMALLOC)
    target_link_libraries(${target} PRIVATE PkgConfig::JEMALLOC)
  endif()
endfunction()

# fastslam_test(NAME SOURCES ... DEPS ... LABELS ...): one GoogleTest executable, one CTest entry.
function(fastslam_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  fastslam_executable_setup(${name})
  add_test(NAME ${name} COMMAND ${name} --gtest_brief=1)
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 900)
  endif()
  set_tests_properties(${name} PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    ENVIRONMENT "FASTSLAM_SHARED_DIR=${PROJECT_SOURCE_DIR}/../shared")
endfunction()

# fastslam_benchmark(NAME SOURCES ... DEPS ...): one Google Benchmark executable, plus a CTest
# smoke entry (label "bench-smoke") that runs every benchmark once at its smallest size.
function(fastslam_benchmark name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} benchmark::benchmark benchmark::benchmark_main)
  fastslam_executable_setup(${name})
  add_test(NAME ${name}_smoke COMMAND ${name} --benchmark_min_time=0)
  # A benchmark that calls SkipWithError still exits 0: fail on its message.
  set_tests_properties(${name}_smoke PROPERTIES LABELS "bench-smoke" TIMEOUT 600
    FAIL_REGULAR_EXPRESSION "ERROR OCCURRED"
    ENVIRONMENT "FASTSLAM_BENCH_SMOKE=1")
endfunction()
