#include "bindings/python/py_json.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace fastslam::bindings::python {
namespace py = pybind11;

namespace {

std::string where(const std::string& path) {
  return path.empty() ? std::string("the value") : "'" + path + "'";
}

std::string child(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

}  // namespace

nlohmann::json to_json(py::handle value, const std::string& path) {
  // bool first: Python's bool is an int.
  if (value.is_none()) return nullptr;
  if (py::isinstance<py::bool_>(value)) return value.cast<bool>();
  if (py::isinstance<py::int_>(value)) {
    // Negative values as int64, the rest as uint64 (a seed may use all 64 bits).
    try {
      if (value.cast<py::int_>() < py::int_(0)) return value.cast<std::int64_t>();
      return value.cast<std::uint64_t>();
    } catch (const py::cast_error&) {
      throw std::invalid_argument(where(path) + " = " + py::repr(value).cast<std::string>() +
                                  " does not fit in 64 bits");
    }
  }
  if (py::isinstance<py::float_>(value)) {
    const double v = value.cast<double>();
    if (!std::isfinite(v)) {
      throw std::invalid_argument(where(path) + " is " + std::to_string(v) + ": not finite");
    }
    return v;
  }
  if (py::isinstance<py::str>(value)) return value.cast<std::string>();
  if (py::isinstance<py::dict>(value)) {
    nlohmann::json out = nlohmann::json::object();
    for (const auto& [k, v] : value.cast<py::dict>()) {
      if (!py::isinstance<py::str>(k)) {
        throw std::invalid_argument(
            where(path) + " has a key that is not a str: " + py::repr(k).cast<std::string>());
      }
      const std::string key = k.cast<std::string>();
      out[key] = to_json(v, child(path, key));
    }
    return out;
  }
  // numpy scalars and 0-d arrays: their Python value.
  if (py::hasattr(value, "item") && py::hasattr(value, "dtype") &&
      py::getattr(value, "ndim", py::int_(1)).cast<int>() == 0) {
    return to_json(value.attr("item")(), path);
  }
  if (py::hasattr(value, "__fspath__")) {
    return to_json(py::module_::import("os").attr("fspath")(value), path);
  }
  if (py::isinstance<py::list>(value) || py::isinstance<py::tuple>(value) ||
      py::hasattr(value, "tolist")) {
    const py::object items = py::hasattr(value, "tolist")
                                 ? value.attr("tolist")()
                                 : py::reinterpret_borrow<py::object>(value);
    nlohmann::json out = nlohmann::json::array();
    std::size_t i = 0;
    for (py::handle item : items)
      out.push_back(to_json(item, path + "[" + std::to_string(i++) + "]"));
    return out;
  }
  throw std::invalid_argument(where(path) + " is a " +
                              py::str(py::type::of(value).attr("__name__")).cast<std::string>() +
                              ", which JSON cannot hold");
}

py::object from_json(const nlohmann::json& value) {
  switch (value.type()) {
    case nlohmann::json::value_t::null:
    case nlohmann::json::value_t::discarded:
      return py::none();
    case nlohmann::json::value_t::boolean:
      return py::bool_(value.get<bool>());
    case nlohmann::json::value_t::number_integer:
      return py::int_(value.get<std::int64_t>());
    case nlohmann::json::value_t::number_unsigned:
      return py::int_(value.get<std::uint64_t>());
    case nlohmann::json::value_t::number_float:
      return py::float_(value.get<double>());
    case nlohmann::json::value_t::string:
      return py::str(value.get_ref<const std::string&>());
    case nlohmann::json::value_t::array: {
      py::list out;
      for (const nlohmann::json& item : value) out.append(from_json(item));
      return out;
    }
    case nlohmann::json::value_t::object: {
      py::dict out;
      for (const auto& [key, item] : value.items()) out[py::str(key)] = from_json(item);
      return out;
    }
    case nlohmann::json::value_t::binary:
      break;
  }
  throw std::invalid_argument("from_json: a binary JSON value has no Python form");
}

}  // namespace fastslam::bindings::python
