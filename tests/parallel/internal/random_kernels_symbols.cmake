# cmake -P script: NM, COPIES=<a,b,...>, OBJECT_<copy>=<object file of that copy of
# parallel/internal/random_kernels.cc>. Fails when a copy's object defines a global or weak
# symbol outside fastslam::parallel::internal::kernels_<copy>: the linker keeps one definition of
# each such name for the whole program, so an inline function emitted out of line by the avx512
# copy could serve the baseline copy's callers on a CPU without AVX-512.
string(REPLACE "," ";" COPIES "${COPIES}")
foreach(copy IN LISTS COPIES)
  set(object "${OBJECT_${copy}}")
  execute_process(COMMAND "${NM}" -C --defined-only "${object}"
    RESULT_VARIABLE rc OUTPUT_VARIABLE symbols ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${NM} failed on ${object}: ${err}")
  endif()
  string(REPLACE "\n" ";" symbols "${symbols}")
  set(count 0)
  foreach(line IN LISTS symbols)
    # "<address> <type> <name>"; lower-case types are local, except u (unique global).
    if(NOT line MATCHES "^[0-9a-fA-F]* ([A-Za-z]) (.*)$")
      continue()
    endif()
    set(type "${CMAKE_MATCH_1}")
    set(name "${CMAKE_MATCH_2}")
    if(NOT type MATCHES "^[A-Zu]$")
      continue()
    endif()
    math(EXPR count "${count} + 1")
    if(name MATCHES "^fastslam::parallel::internal::kernels_${copy}::"
       OR name STREQUAL "DW.ref.__gxx_personality_v0")  # the C++ personality routine's pointer
      continue()
    endif()
    message(SEND_ERROR "kernels_${copy} (${object}) defines ${type} ${name}")
  endforeach()
  message(STATUS "kernels_${copy}: ${count} global or weak symbols, all its own")
endforeach()
