// The parts of the `fastslam._fastslam` extension module, each binding one area into the
// module at import: the Filter and its estimate (filter_binding.cc), and the command line's
// run and the native log reader (tools_binding.cc). Shared helpers for turning Python values
// into engine inputs live here too.
//
// Thread safety: import-time only, under the GIL. Costs: none at run time.
#pragma once

#include <string>

#include <pybind11/pybind11.h>

namespace fastslam::bindings::python {

void bind_filter(pybind11::module_& m);
void bind_tools(pybind11::module_& m);

// os.fspath(path) as a std::string (str or os.PathLike); TypeError otherwise.
std::string path_string(pybind11::handle path);

// Raises FileNotFoundError(ENOENT, ..., path).
[[noreturn]] void raise_file_not_found(const std::string& path);

}  // namespace fastslam::bindings::python
