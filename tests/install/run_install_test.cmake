# cmake -P script behind the install_find_package test (tests/install/CMakeLists.txt).
#  1. Builds the package as the `package` preset does (FASTSLAM_PORTABLE, no tests) from
#     SOURCE_DIR in WORK_DIR/package, and checks its compile lines: no -march=native, and on
#     x86-64 every file compiled for the baseline, only the kernel copies for more.
#  2. Installs it to WORK_DIR/a and checks the tree: the three libraries, the C API
#     (libfastslam.so, include/fastslam/fastslam.h, its pkg-config file), the Python package and
#     the command line; headers only under include/fastslam/{memory,parallel,engine}/ and none of
#     engine/internal/, no instruction-set
#     flag and no absolute path (of the prefix, the sources or the build) in any package file;
#     on x86-64, no AVX instruction in the libraries outside the dispatched copies (check_isa.py).
#  3. Moves the prefix to WORK_DIR/b, then builds against b only: every installed header on its
#     own (tests/install/headers) and the consumers (C++ and C); imports the Python package.
#  4. Runs each consumer everywhere (run_everywhere): on this CPU with its best random-stream
#     kernels and with each copy forced by FASTSLAM_ISA, and under qemu-user on x86-64 hosts on
#     emulated CPUs: qemu64 (the x86-64 baseline: no SSE4, no AVX) must run the baseline copy
#     and Haswell (AVX2, no AVX-512) the avx2 copy. A consumer prints its kernels ("isa: ...")
#     and a digest of the bits it computed ("digest: ..."), which must be the same in every run.
# Inputs: SOURCE_DIR, WORK_DIR, CONSUMER_DIR, HEADERS_DIR, CXX_COMPILER, COMPILER_LAUNCHER
# (may be empty), OBJDUMP, X86_64 (ON/OFF). Builds use 2 jobs unless CMAKE_BUILD_PARALLEL_LEVEL
# is set.
cmake_minimum_required(VERSION 3.25)

set(package_build "${WORK_DIR}/package")
set(prefix_a "${WORK_DIR}/a")
set(prefix_b "${WORK_DIR}/b")
file(REMOVE_RECURSE "${prefix_a}" "${prefix_b}" "${WORK_DIR}/headers" "${WORK_DIR}/consumer"
  "${WORK_DIR}/sweep")
set(parallel --parallel 2)
if(DEFINED ENV{CMAKE_BUILD_PARALLEL_LEVEL})
  set(parallel)
endif()
set(launcher)
if(COMPILER_LAUNCHER)
  set(launcher "-DCMAKE_CXX_COMPILER_LAUNCHER=${COMPILER_LAUNCHER}")
endif()

# run(COMMAND...): runs it, stops the test with its output if it fails; the output goes to
# `run_output` in the caller.
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  set(run_output "${out}" PARENT_SCOPE)
endfunction()

# --- 1. The package build --------------------------------------------------------------------
string(TIMESTAMP start "%s")
run(${CMAKE_COMMAND} -S "${SOURCE_DIR}" -B "${package_build}" --preset package
    "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}" ${launcher})
run(${CMAKE_COMMAND} --build "${package_build}" ${parallel})
file(STRINGS "${package_build}/compile_commands.json" commands REGEX "\"command\":")
foreach(command IN LISTS commands)
  if(command MATCHES "-m(arch|tune)=native")
    message(FATAL_ERROR "the package build compiles with -march=native: ${command}")
  endif()
  if(X86_64 AND NOT command MATCHES " -march=x86-64 ")
    message(FATAL_ERROR "not compiled for the x86-64 baseline: ${command}")
  endif()
  if(command MATCHES " -march=x86-64-v[234]" AND NOT command MATCHES "random_kernels\.cc")
    message(FATAL_ERROR "compiled beyond the baseline outside the kernel copies: ${command}")
  endif()
endforeach()
string(TIMESTAMP now "%s")
math(EXPR seconds "${now} - ${start}")
message(STATUS "package built in ${seconds} s")

# --- 2. Install and check the tree -----------------------------------------------------------
run(${CMAKE_COMMAND} --install "${package_build}" --prefix "${prefix_a}")
if(NOT EXISTS "${prefix_a}/lib/cmake/fastslam/fastslamConfig.cmake")
  message(FATAL_ERROR "fastslamConfig.cmake was not installed")
endif()
file(GLOB_RECURSE installed RELATIVE "${prefix_a}" "${prefix_a}/*")
set(headers 0)
set(python_files 0)
foreach(file IN LISTS installed)
  if(file MATCHES "^include/")
    if(NOT (file MATCHES "^include/fastslam/(memory|parallel|engine)/[^ ]*\\.h$"
            OR file STREQUAL "include/fastslam/fastslam.h")
       OR file MATCHES "^include/fastslam/engine/internal/")
      message(FATAL_ERROR "not a public header of the package: ${file}")
    endif()
    math(EXPR headers "${headers} + 1")
  elseif(file MATCHES "^lib/cmake/fastslam/")
    file(READ "${prefix_a}/${file}" text)
    if(text MATCHES "-m(arch|tune|avx|fma|sse)")
      message(FATAL_ERROR "${file} passes an instruction-set flag to consumers")
    endif()
  elseif(file MATCHES "^lib/python3[^/]*/dist-packages/fastslam/")
    math(EXPR python_files "${python_files} + 1")  # the Python package
  elseif(NOT file MATCHES "^lib/libfastslam_(memory|parallel|engine)\\.a$"
         AND NOT file MATCHES "^lib/libfastslam\\.so(\\.[0-9.]+)?$"  # the C API
         AND NOT file STREQUAL "lib/pkgconfig/fastslam.pc"
         AND NOT file STREQUAL "bin/fastslam"  # the command line
         AND NOT file STREQUAL "lib/fastslam/fastslam_mpi.so")  # its MPI module
    message(FATAL_ERROR "not part of the package: ${file}")  # tools' libraries, tests, ...
  endif()
  if(file MATCHES "\\.(h|cmake|pc|py)$")
    file(READ "${prefix_a}/${file}" text)
    foreach(path "${prefix_a}" "${SOURCE_DIR}" "${WORK_DIR}")
      string(FIND "${text}" "${path}" at)
      if(NOT at EQUAL -1)
        message(FATAL_ERROR "${file} names ${path}: the package would not survive a move")
      endif()
    endforeach()
  endif()
endforeach()
if(python_files EQUAL 0)
  message(FATAL_ERROR "the Python package was not installed")
endif()
foreach(file include/fastslam/fastslam.h lib/libfastslam.so lib/pkgconfig/fastslam.pc bin/fastslam)
  if(NOT EXISTS "${prefix_a}/${file}")
    message(FATAL_ERROR "${file} was not installed")
  endif()
endforeach()
message(STATUS "installed ${headers} headers, the libraries, the C API, the command line and "
  "${python_files} files of the Python package")
if(X86_64)
  file(GLOB libraries "${prefix_a}/lib/libfastslam_*.a" "${prefix_a}/lib/libfastslam.so")
  run(/usr/bin/python3 "${CMAKE_CURRENT_LIST_DIR}/check_isa.py" "${OBJDUMP}" ${libraries})
  message(STATUS "${run_output}")
endif()

# --- 3. Move the prefix; build the headers against it ----------------------------------------
file(RENAME "${prefix_a}" "${prefix_b}")
run(${CMAKE_COMMAND} -S "${HEADERS_DIR}" -B "${WORK_DIR}/headers" -G Ninja
    -DCMAKE_BUILD_TYPE=Release "-DCMAKE_PREFIX_PATH=${prefix_b}"
    "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}" ${launcher})
run(${CMAKE_COMMAND} --build "${WORK_DIR}/headers" ${parallel})
message(STATUS "every public header compiles on its own against the moved prefix")

# --- 4. Consumers, run everywhere ------------------------------------------------------------
find_program(qemu qemu-x86_64)
if(X86_64 AND NOT qemu)
  message(FATAL_ERROR "qemu-x86_64 (Debian package qemu-user, which tools/lib/setup.sh "
    "installs) is needed to run the consumer on CPUs without AVX")
endif()

# The copies in a portable x86-64 build, least capable first.
set(copies baseline)
if(X86_64)
  set(copies baseline avx2 avx512)
endif()

# run_one(NAME LABEL EXPECTED_ISA COMMAND...): runs it; checks that it reports EXPECTED_ISA
# (unless empty) and prints the digest of NAME's first run; sets `isa` in the caller.
function(run_one name label expected)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${name} (${label}) failed (${rc}):\n${out}\n${err}")
  endif()
  if(NOT out MATCHES "isa: ([a-z0-9]+)")
    message(FATAL_ERROR "${name} (${label}) printed no isa:\n${out}")
  endif()
  set(got "${CMAKE_MATCH_1}")
  if(NOT out MATCHES "digest: ([0-9a-f]+)")
    message(FATAL_ERROR "${name} (${label}) printed no digest:\n${out}")
  endif()
  set(digest "${CMAKE_MATCH_1}")
  if(expected AND NOT got STREQUAL expected)
    message(FATAL_ERROR "${name} (${label}) ran the ${got} kernels, not ${expected}:\n${err}")
  endif()
  get_property(reference GLOBAL PROPERTY fastslam_digest_${name})
  if(NOT reference)
    set_property(GLOBAL PROPERTY fastslam_digest_${name} "${digest}")
  elseif(NOT digest STREQUAL reference)
    message(FATAL_ERROR "${name} (${label}, ${got} kernels): digest ${digest}, but ${reference} "
      "in its first run: the kernel copies or CPUs do not give the same bits")
  endif()
  message(STATUS "${name} ${label}: ${got} kernels, digest ${digest}")
  set(isa "${got}" PARENT_SCOPE)
endfunction()

# run_everywhere(NAME COMMAND...): see 4. above. A forced copy this CPU lacks must fall back to
# its best one (with a warning).
function(run_everywhere name)
  run_one(${name} "this CPU" "" ${CMAKE_COMMAND} -E env --unset=FASTSLAM_ISA ${ARGN})
  set(best "${isa}")
  list(FIND copies "${best}" best_index)
  foreach(copy IN LISTS copies)
    list(FIND copies "${copy}" index)
    set(expected "${copy}")
    if(index GREATER best_index)
      set(expected "${best}")
    endif()
    run_one(${name} "FASTSLAM_ISA=${copy}" "${expected}"
            ${CMAKE_COMMAND} -E env FASTSLAM_ISA=${copy} ${ARGN})
  endforeach()
  if(X86_64)
    run_one(${name} "qemu -cpu qemu64" baseline
            ${CMAKE_COMMAND} -E env --unset=FASTSLAM_ISA ${qemu} -cpu qemu64 ${ARGN})
    run_one(${name} "qemu -cpu Haswell" avx2
            ${CMAKE_COMMAND} -E env --unset=FASTSLAM_ISA ${qemu} -cpu Haswell ${ARGN})
  endif()
endfunction()

# The C++ consumer: find_package(fastslam), #include <fastslam/...>.
run(${CMAKE_COMMAND} -S "${CONSUMER_DIR}" -B "${WORK_DIR}/consumer" -G Ninja
    -DCMAKE_BUILD_TYPE=Release "-DCMAKE_PREFIX_PATH=${prefix_b}"
    "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}" ${launcher})
run(${CMAKE_COMMAND} --build "${WORK_DIR}/consumer" ${parallel})
run_everywhere(consumer "${WORK_DIR}/consumer/consumer")

# The C consumer, through libfastslam.so: on this CPU and on an emulated baseline one.
run("${WORK_DIR}/consumer/c_consumer")
message(STATUS "c_consumer: ${run_output}")
if(X86_64)
  run(${qemu} -cpu qemu64 "${WORK_DIR}/consumer/c_consumer")
  message(STATUS "c_consumer under qemu -cpu qemu64: ${run_output}")
endif()

# The Python package, imported from the moved prefix by the interpreter it was built for.
file(GLOB python_dirs LIST_DIRECTORIES true "${prefix_b}/lib/python3*/dist-packages")
run(${CMAKE_COMMAND} -E env "PYTHONPATH=${python_dirs}" /usr/bin/python3
    "${CMAKE_CURRENT_LIST_DIR}/python_import.py" "${prefix_b}")
message(STATUS "${run_output}")

# The command line from the moved prefix; under mpirun it loads its MPI module from
# lib/fastslam/ beside bin/ (tools/cli/mpi_transport.h), which a sweep's ranks then use.
run("${prefix_b}/bin/fastslam" --version)
find_program(mpirun mpirun)
if(EXISTS "${prefix_b}/lib/fastslam/fastslam_mpi.so" AND mpirun)
  set(as_root)
  execute_process(COMMAND id -u OUTPUT_VARIABLE uid OUTPUT_STRIP_TRAILING_WHITESPACE)
  if(uid STREQUAL "0")
    set(as_root --allow-run-as-root)
  endif()
  run(${mpirun} --oversubscribe ${as_root} -n 2 "${prefix_b}/bin/fastslam" sweep
      --out "${WORK_DIR}/sweep" --seeds 1-2 --max-steps 20)
  if(NOT run_output MATCHES "2 ranks")
    message(FATAL_ERROR "the moved prefix's fastslam did not sweep over 2 ranks:\n${run_output}")
  endif()
  message(STATUS "bin/fastslam under mpirun -n 2: its MPI module loaded from the moved prefix")
endif()

string(TIMESTAMP now "%s")
math(EXPR seconds "${now} - ${start}")
message(STATUS "install test done in ${seconds} s")
