# Writes the build's facts for `fastslam --version` and metrics.json (tools/cli/build_info.h):
# run as a script at every build (`cmake -P`), so the commit is the one built, not the one
# configured; configure_file rewrites the header only when a value changed, so an unchanged
# tree recompiles nothing.
#
# Inputs (-D): SOURCE_DIR, TEMPLATE, OUTPUT, FASTSLAM_VERSION, FASTSLAM_BUILD_TYPE,
# FASTSLAM_COMPILER.
set(FASTSLAM_GIT_COMMIT "unknown")
set(FASTSLAM_GIT_DIRTY "false")
find_package(Git QUIET)
if(GIT_FOUND)
  execute_process(COMMAND ${GIT_EXECUTABLE} -C ${SOURCE_DIR} rev-parse HEAD
    OUTPUT_VARIABLE _commit OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE _status
    ERROR_QUIET)
  if(_status EQUAL 0)
    set(FASTSLAM_GIT_COMMIT "${_commit}")
    # Tracked files changed since the commit: the build is not exactly that commit.
    execute_process(COMMAND ${GIT_EXECUTABLE} -C ${SOURCE_DIR} status --porcelain
      --untracked-files=no OUTPUT_VARIABLE _changes RESULT_VARIABLE _status ERROR_QUIET)
    if(_status EQUAL 0 AND NOT _changes STREQUAL "")
      set(FASTSLAM_GIT_DIRTY "true")
    endif()
  endif()
endif()
configure_file(${TEMPLATE} ${OUTPUT} @ONLY)
