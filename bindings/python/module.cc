// `fastslam._fastslam`: the extension module behind the `fastslam` package
// (bindings/python/fastslam/__init__.py re-exports it). Registers the record dtypes, then each
// area's bindings (bindings/python/module.h). C++ exceptions become Python ones with the same
// message through pybind11's translation: std::invalid_argument -> ValueError (bad input; the
// filter is unchanged), std::runtime_error -> RuntimeError (a corrupt state or log).
#include "bindings/python/module.h"

#include <cerrno>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "bindings/python/records.h"

namespace fastslam::bindings::python {
namespace py = pybind11;

void register_record_dtypes() {
  PYBIND11_NUMPY_DTYPE(MapRecord, id, x, y, sxx, sxy, syy, log_odds, last_seen);
  PYBIND11_NUMPY_DTYPE(AssociationRecord, observation, outcome, landmark_id, mahalanobis2);
  PYBIND11_NUMPY_DTYPE(TrajectoryRecord, control, x, y, theta);
  PYBIND11_NUMPY_DTYPE(ParticleRecord, x, y, theta, log_weight, landmarks);
  PYBIND11_NUMPY_DTYPE(EventRecord, time, kind, count, first, dt, u0, u1, x, y, theta);
  PYBIND11_NUMPY_DTYPE(ObservationRecord, range, bearing, id);
  PYBIND11_NUMPY_DTYPE(TruthRecord, id, x, y);
}

std::string path_string(py::handle path) {
  return py::str(py::module_::import("os").attr("fspath")(path)).cast<std::string>();
}

void raise_file_not_found(const std::string& path) {
  errno = ENOENT;
  PyErr_SetFromErrnoWithFilename(PyExc_FileNotFoundError, path.c_str());
  throw py::error_already_set();
}

}  // namespace fastslam::bindings::python

PYBIND11_MODULE(_fastslam, m) {
  namespace py = pybind11;
  namespace python = fastslam::bindings::python;
  m.doc() =
      "The fastslam engine's extension module; import the `fastslam` package instead, which "
      "re-exports everything here.";
  m.attr("__version__") = FASTSLAM_VERSION;
  python::register_record_dtypes();
  m.attr("MAP_DTYPE") = py::dtype::of<python::MapRecord>();
  m.attr("ASSOCIATION_DTYPE") = py::dtype::of<python::AssociationRecord>();
  m.attr("TRAJECTORY_DTYPE") = py::dtype::of<python::TrajectoryRecord>();
  m.attr("PARTICLE_DTYPE") = py::dtype::of<python::ParticleRecord>();
  m.attr("EVENT_DTYPE") = py::dtype::of<python::EventRecord>();
  m.attr("OBSERVATION_DTYPE") = py::dtype::of<python::ObservationRecord>();
  m.attr("LANDMARK_DTYPE") = py::dtype::of<python::TruthRecord>();
  python::bind_filter(m);
  python::bind_tools(m);
}
