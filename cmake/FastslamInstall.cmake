# Installs the libraries, their headers (under include/fastslam/<folder>/) and the package
# config, so a consumer writes find_package(fastslam) and links fastslam::engine.
include_guard(GLOBAL)
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

get_property(_fastslam_libs GLOBAL PROPERTY FASTSLAM_LIBRARIES)
install(TARGETS ${_fastslam_libs} EXPORT fastslamTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
foreach(_dir memory parallel engine)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${_dir}/ DESTINATION include/fastslam/${_dir}
    FILES_MATCHING PATTERN "*.h")
endforeach()
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
