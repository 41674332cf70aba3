# Installs the libraries, their public headers (under include/fastslam/<folder>/) and a
# relocatable package config, so a consumer writes find_package(fastslam), links
# fastslam::engine and includes <fastslam/engine/filter.h>. What to install is the portable
# build's (FASTSLAM_PORTABLE, the `package` preset); installing a build tuned with -march=native
# works but ties the package to CPUs like this one, so it says so.
include_guard(GLOBAL)
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

if(NOT FASTSLAM_PORTABLE)
  install(CODE "message(STATUS \"fastslam: installing a build with FASTSLAM_PORTABLE=OFF: its \
flags decide which CPUs run it (the package preset builds the portable libraries)\")")
endif()

get_property(_fastslam_libs GLOBAL PROPERTY FASTSLAM_LIBRARIES)
install(TARGETS ${_fastslam_libs} EXPORT fastslamTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

# The public headers: each library folder's own (memory/*.h, parallel/*.h, engine/*.h) and the
# internal/ headers they include, directly or through one another (memory/internal/*, three of
# parallel/internal/, none of engine/internal/), found by following the includes, so a header
# that starts to need another internal one brings it along; tools/ has none (not API).
# tests/install builds a consumer and every installed header against the installed package.
set(_fastslam_todo)
foreach(_dir memory parallel engine)
  file(GLOB _public RELATIVE ${PROJECT_SOURCE_DIR} ${PROJECT_SOURCE_DIR}/${_dir}/*.h)
  list(APPEND _fastslam_todo ${_public})
endforeach()
set(_fastslam_headers)
while(_fastslam_todo)
  list(POP_FRONT _fastslam_todo _header)
  if(_header IN_LIST _fastslam_headers)
    continue()
  endif()
  list(APPEND _fastslam_headers ${_header})
  file(STRINGS ${PROJECT_SOURCE_DIR}/${_header} _includes
    REGEX "^#include \"(memory|parallel|engine)/[^\"]+\"")
  foreach(_include IN LISTS _includes)
    string(REGEX REPLACE "^#include \"([^\"]+)\".*" "\\1" _include "${_include}")
    list(APPEND _fastslam_todo ${_include})
  endforeach()
endwhile()
foreach(_header IN LISTS _fastslam_headers)
  get_filename_component(_subdir ${_header} DIRECTORY)
  install(FILES ${PROJECT_SOURCE_DIR}/${_header} DESTINATION include/fastslam/${_subdir})
endforeach()

# fastslamTargets.cmake locates everything from its own directory (_IMPORT_PREFIX), and the
# config and its dependencies name imported targets only, so the prefix can be moved after
# installing (tests/install moves it).
install(EXPORT fastslamTargets NAMESPACE fastslam:: FILE fastslamTargets.cmake
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/fastslam)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/fastslamConfig.cmake.in
  ${PROJECT_BINARY_DIR}/fastslamConfig.cmake
  INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/fastslam)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/fastslamConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/fastslamConfig.cmake
  ${PROJECT_BINARY_DIR}/fastslamConfigVersion.cmake
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/fastslam)
