// Python objects to and from nlohmann::json, for the module's dict-shaped values: a filter
// configuration (engine config <-> JSON text, bindings/config_json.h), statistics, a run's
// metrics and its options. Only what JSON holds crosses: dicts with str keys, lists and tuples
// (and 1-D numpy arrays), str, bool, int, float, None, numpy scalars, os.PathLike (as its str).
// Non-finite floats are refused rather than written as JSON's null.
//
// Thread safety: needs the GIL (it touches Python objects). Costs: O(size of the value).
#pragma once

#include <string>

#include <nlohmann/json.hpp>
#include <pybind11/pybind11.h>

namespace fastslam::bindings::python {

// Throws std::invalid_argument naming the key path ("sensor.sigma_range") of a value JSON cannot
// hold: a non-str key, an object of another type, a NaN or an infinity.
nlohmann::json to_json(pybind11::handle value, const std::string& path = "");

// dicts, lists, str, bool, int, float and None.
pybind11::object from_json(const nlohmann::json& value);

}  // namespace fastslam::bindings::python
