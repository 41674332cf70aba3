# cmake -P script: installs BUILD_DIR's python component into WORK_DIR/prefix, moves the prefix
# (the install must not depend on where it was put), then imports the package from there with
# a fresh interpreter and runs a filter: PACKAGE_DIR is where it must land, relative to the
# prefix.
file(REMOVE_RECURSE "${WORK_DIR}")
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}")
  endif()
  message(STATUS "${out}")
endfunction()
run(${CMAKE_COMMAND} --install "${BUILD_DIR}" --component python --prefix "${WORK_DIR}/prefix")
foreach(_file __init__.py _fastslam.pyi py.typed)
  if(NOT EXISTS "${WORK_DIR}/prefix/${PACKAGE_DIR}/fastslam/${_file}")
    message(FATAL_ERROR "${PACKAGE_DIR}/fastslam/${_file} was not installed")
  endif()
endforeach()
file(RENAME "${WORK_DIR}/prefix" "${WORK_DIR}/moved")
set(_site "${WORK_DIR}/moved/${PACKAGE_DIR}")
run(${CMAKE_COMMAND} -E env PYTHONPATH=${_site} PYTHONDONTWRITEBYTECODE=1 --
  ${PYTHON} -c "
import fastslam, sys
assert fastslam.__file__.startswith(sys.argv[1]), fastslam.__file__
f = fastslam.Filter(particles=5)
f.predict([1.0, 0.0], 0.1)
f.observe([5.0], [0.1], [0])
print(fastslam.__version__, f, f.estimate())
" ${_site})
