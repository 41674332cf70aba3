// The JSON form of engine::FilterConfig, shared by the bindings (the C API, the Python module):
// one object whose keys are FilterConfig's fields in snake_case, nested as the struct nests
// ("motion": {"kind": "bailey-car", "wheelbase": 4, "sigma_control": [0.3, 0.05]}), enums by
// the names of their tables (engine/enum_names.h), SI units and radians. Every key is
// optional (a missing one keeps FilterConfig{}'s value); `split_seconds` also takes "never"
// (infinity) and `initial_pose` 3 to 5 numbers. docs/c-api.md lists the keys.
// Thread safety: pure functions. Costs: O(text length); both allocate.
#pragma once

#include <string>
#include <string_view>

#include "engine/filter_config.h"

namespace fastslam::bindings {

// Parses and validates a configuration. Throws std::invalid_argument with a message starting
// "config: " that names the key path: invalid JSON (the parser's message, with line and
// column), a top level that is not an object, an unknown key (with the nearest known one when
// one is close), a repeated key, a wrong type or array length, an integer out of range, an
// unknown enum name, and any combination engine::validate refuses.
engine::FilterConfig config_from_json(std::string_view text);

// Every key of `config`, indented; config_from_json gives back the same config bit for bit
// (doubles are written in a form that parses to the same bits). Throws std::invalid_argument
// naming the key for what JSON cannot hold: an enum outside its table, a NaN or infinity
// (except split_seconds = +infinity, written "never").
std::string config_to_json(const engine::FilterConfig& config);

}  // namespace fastslam::bindings
