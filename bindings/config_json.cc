#include "bindings/config_json.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/enum_names.h"
#include "engine/motion_dispatch.h"

namespace fastslam::bindings {
namespace {

// Document order, so the first offending key reported is the first one written.
using Json = nlohmann::ordered_json;
using engine::FilterConfig;

// A field added to FilterConfig changes its size: add its key to visit_config, then update this.
static_assert(sizeof(FilterConfig) == 408, "FilterConfig changed: update visit_config's keys");

// FilterConfig's keys in struct order, for the reader and the writer alike, so the two cannot
// drift apart. `C` is FilterConfig or const FilterConfig.
template <class C, class V>
void visit_config(C& c, V& v) {
  v.field("algorithm", c.algorithm);
  v.field("particles", c.particles);
  v.field("association", c.association);
  v.object("motion", [&](V& m) {
    m.field("kind", c.motion.kind);
    m.field("wheelbase", c.motion.wheelbase);
    m.object("geometry", [&](V& g) {
      g.field("a", c.motion.geometry.a);
      g.field("b", c.motion.geometry.b);
      g.field("l", c.motion.geometry.l);
      g.field("h", c.motion.geometry.h);
    });
    m.field("sigma_control", c.motion.sigma_control);
  });
  v.object("sensor", [&](V& s) {
    s.field("sigma_range", c.sensor.sigma_range);
    s.field("sigma_bearing", c.sensor.sigma_bearing);
    s.object("offset", [&](V& o) {
      o.field("x", c.sensor.offset.x);
      o.field("y", c.sensor.offset.y);
      o.field("yaw", c.sensor.offset.yaw);
    });
    s.field("max_range", c.sensor.max_range);
    s.field("field_of_view", c.sensor.field_of_view);
  });
  v.field("log_new_landmark", c.log_new_landmark);
  v.object("gating", [&](V& g) {
    g.field("gate", c.gating.gate);
    g.field("search_scale", c.gating.search_scale);
  });
  v.object("existence", [&](V& e) {
    e.field("negative_information", c.existence.negative_information);
    e.field("initial", c.existence.initial);
    e.field("seen", c.existence.seen);
    e.field("missed", c.existence.missed);
    e.field("remove_below", c.existence.remove_below);
    e.field("confirm_at", c.existence.confirm_at);
    e.field("range_margin", c.existence.range_margin);
  });
  v.object("resample", [&](V& r) {
    r.field("when", c.resample.when);
    r.field("ess_fraction", c.resample.ess_fraction);
    r.field("scheme", c.resample.scheme);
  });
  v.field("seed", c.seed);
  v.field("threads", c.threads);
  v.field("grain", c.grain);
  v.seconds_or_never("split_seconds", c.split_seconds);
  v.field("record_trajectory", c.record_trajectory);
  v.field("motion_draw", c.motion_draw);
  v.object("ekf", [&](V& e) {
    e.field("gate_accept", c.ekf.gate_accept);
    e.field("gate_new", c.ekf.gate_new);
    e.field("joint_compatibility", c.ekf.joint_compatibility);
  });
  v.field("initial_pose", c.initial_pose, 3);  // x, y, theta; v and omega (kappa) optional
  v.object("detection", [&](V& d) {
    d.field("probability", c.detection.probability);
    d.field("clutter_density", c.detection.clutter_density);
  });
  v.object("loop_closure", [&](V& l) {
    l.field("reach", c.loop_closure.reach);
    l.field("min_age", c.loop_closure.min_age);
    l.field("separation", c.loop_closure.separation);
    l.field("max_turn", c.loop_closure.max_turn);
    l.field("merge_gate", c.loop_closure.merge_gate);
  });
  v.field("error_correlation", c.error_correlation);
}

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::invalid_argument("config: \"" + path + "\" " + what);
}

// A JSON value for a message: scalars as written (shortened), containers by kind and size.
std::string describe(const Json& value) {
  if (value.is_object()) return "an object";
  if (value.is_array()) return "an array of " + std::to_string(value.size()) + " elements";
  std::string text = value.dump(-1, ' ', false, Json::error_handler_t::replace);
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  return text;
}

// The shortest text that reads back as `value`.
std::string shortest(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] != b[j - 1] ? 1 : 0)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

// Reads the keys of one JSON object into the config, remembering which keys it knows so that
// `finish` can name the others.
class Reader {
 public:
  Reader(const Json& object, std::string prefix) : object_(object), prefix_(std::move(prefix)) {}

  template <class E>
  requires std::is_enum_v<E>
  void field(std::string_view key, E& out) {
    const Json* v = find(key);
    if (v == nullptr) return;
    if (!v->is_string()) {
      fail(path(key),
           "must be a string: " + engine::enum_name_list<E>() + " (got " + describe(*v) + ")");
    }
    try {
      out = engine::parse_enum<E>(v->get_ref<const std::string&>());
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("config: \"" + path(key) + "\": " + e.what());
    }
  }

  void field(std::string_view key, bool& out) {
    const Json* v = find(key);
    if (v == nullptr) return;
    if (!v->is_boolean()) fail(path(key), "must be true or false (got " + describe(*v) + ")");
    out = v->get<bool>();
  }

  // An integral float (1e3, 100.0) is taken too: some writers print every number as a double.
  template <std::unsigned_integral U>
  requires(!std::same_as<U, bool>) void field(std::string_view key, U& out) {
    const Json* v = find(key);
    if (v == nullptr) return;
    constexpr U kMax = std::numeric_limits<U>::max();
    if (v->is_number_unsigned()) {
      const auto n = v->get<std::uint64_t>();
      if (n <= kMax) {
        out = static_cast<U>(n);
        return;
      }
    } else if (v->is_number_float()) {
      const double d = v->get<double>();
      if (d >= 0 && d == std::floor(d) && d < std::ldexp(1.0, std::numeric_limits<U>::digits)) {
        out = static_cast<U>(d);
        return;
      }
    }
    fail(path(key),
         "must be an integer in [0, " + std::to_string(kMax) + "] (got " + describe(*v) + ")");
  }

  void field(std::string_view key, double& out) {
    const Json* v = find(key);
    if (v != nullptr) out = number(*v, path(key));
  }

  // Exactly N numbers, or from `min_count` to N (the rest keep their values).
  template <std::size_t N>
  void field(std::string_view key, double (&out)[N], std::size_t min_count = N) {
    const Json* v = find(key);
    if (v == nullptr) return;
    if (!v->is_array() || v->size() < min_count || v->size() > N) {
      const std::string count = min_count == N
                                    ? std::to_string(N)
                                    : std::to_string(min_count) + " to " + std::to_string(N);
      fail(path(key), "must be an array of " + count + " numbers (got " +
                          (v->is_array() ? std::to_string(v->size()) + " elements" : describe(*v)) +
                          ")");
    }
    for (std::size_t i = 0; i < v->size(); ++i) {
      out[i] = number((*v)[i], path(key) + "[" + std::to_string(i) + "]");
    }
  }

  void seconds_or_never(std::string_view key, double& out) {
    const Json* v = find(key);
    if (v == nullptr) return;
    if (v->is_string() && v->get_ref<const std::string&>() == "never") {
      out = std::numeric_limits<double>::infinity();
      return;
    }
    if (!v->is_number()) {
      fail(path(key), "must be a number of seconds or \"never\" (got " + describe(*v) + ")");
    }
    out = number(*v, path(key));
  }

  template <class F>
  void object(std::string_view key, F&& f) {
    const Json* v = find(key);
    if (v == nullptr) return;
    if (!v->is_object()) fail(path(key), "must be an object (got " + describe(*v) + ")");
    Reader child(*v, path(key) + ".");
    std::forward<F>(f)(child);
    child.finish();
  }

  // Throws for the first key of the object that no field asked for.
  void finish() const {
    for (const auto& item : object_.items()) {
      const std::string& key = item.key();
      if (std::find(known_.begin(), known_.end(), key) != known_.end()) continue;
      std::string message = "config: unknown key \"" + prefix_ + key + "\"";
      std::string_view nearest;
      std::size_t best = std::max<std::size_t>(1, key.size() / 3) + 1;
      for (std::string_view k : known_) {
        const std::size_t d = edit_distance(key, k);
        if (d < best && d < key.size()) {
          best = d;
          nearest = k;
        }
      }
      if (!nearest.empty()) {
        message.append(" (did you mean \"").append(prefix_).append(nearest).append("\"?)");
      } else {
        message += " (known keys";
        if (!prefix_.empty()) {
          message.append(" of \"").append(prefix_, 0, prefix_.size() - 1).append("\"");
        }
        message += ":";
        for (std::size_t i = 0; i < known_.size(); ++i) {
          message.append(i == 0 ? " " : ", ").append(known_[i]);
        }
        message += ")";
      }
      throw std::invalid_argument(message);
    }
  }

 private:
  const Json* find(std::string_view key) {
    known_.push_back(key);
    const auto it = object_.find(std::string(key));
    return it == object_.end() ? nullptr : &*it;
  }

  std::string path(std::string_view key) const { return prefix_ + std::string(key); }

  static double number(const Json& v, const std::string& path) {
    if (!v.is_number()) fail(path, "must be a number (got " + describe(v) + ")");
    const double d = v.get<double>();
    if (!std::isfinite(d)) fail(path, "must be finite");
    return d;
  }

  const Json& object_;
  std::string prefix_;  // the object's path and a dot, "" at the top
  std::vector<std::string_view> known_;
};

// Writes every key of the config into one JSON object.
class Writer {
 public:
  explicit Writer(std::string prefix) : prefix_(std::move(prefix)) {}

  template <class E>
  requires std::is_enum_v<E>
  void field(std::string_view key, const E& value) {
    if (!engine::enum_known(value)) {
      throw std::invalid_argument("config_to_json: \"" + path(key) + "\" is not a known " +
                                  std::string(engine::EnumNames<E>::kWhat));
    }
    json_[std::string(key)] = std::string(engine::enum_name(value));
  }

  void field(std::string_view key, const bool& value) { json_[std::string(key)] = value; }

  template <std::unsigned_integral U>
  requires(!std::same_as<U, bool>) void field(std::string_view key, const U& value) {
    json_[std::string(key)] = static_cast<std::uint64_t>(value);
  }

  void field(std::string_view key, const double& value) {
    json_[std::string(key)] = finite(value, path(key));
  }

  template <std::size_t N>
  void field(std::string_view key, const double (&values)[N], std::size_t /*min_count*/ = N) {
    Json array = Json::array();
    for (std::size_t i = 0; i < N; ++i) {
      array.push_back(finite(values[i], path(key) + "[" + std::to_string(i) + "]"));
    }
    json_[std::string(key)] = std::move(array);
  }

  void seconds_or_never(std::string_view key, const double& value) {
    if (value == std::numeric_limits<double>::infinity()) {
      json_[std::string(key)] = "never";
    } else {
      field(key, value);
    }
  }

  template <class F>
  void object(std::string_view key, F&& f) {
    Writer child(path(key) + ".");
    std::forward<F>(f)(child);
    json_[std::string(key)] = std::move(child.json_);
  }

  const Json& json() const { return json_; }

 private:
  std::string path(std::string_view key) const { return prefix_ + std::string(key); }

  static double finite(double value, const std::string& path) {
    if (!std::isfinite(value)) {
      throw std::invalid_argument("config_to_json: \"" + path + "\" is not finite (" +
                                  shortest(value) + ")");
    }
    return value;
  }

  std::string prefix_;
  Json json_ = Json::object();
};

std::string strip_exception_id(const char* what) {
  // "[json.exception.parse_error.101] parse error at line 1, ..." -> "parse error at line 1, ..."
  std::string_view text = what;
  if (text.starts_with("[json.exception.")) {
    const std::size_t end = text.find("] ");
    if (end != std::string_view::npos) text.remove_prefix(end + 2);
  }
  return std::string(text);
}

// Parses strictly (no comments) and refuses a key repeated in one object, which the library
// would otherwise resolve silently to the last value.
Json parse(std::string_view text) {
  struct Frame {
    bool object = false;
    std::string key;  // the latest key of an object
    std::set<std::string> keys;
  };
  std::vector<Frame> frames;
  // The path of the latest key read, "" at the top.
  const auto path = [&frames] {
    std::string out;
    for (const Frame& f : frames) {
      if (!f.object || f.key.empty()) continue;
      if (!out.empty()) out += '.';
      out += f.key;
    }
    return out;
  };
  const auto callback = [&frames, &path](int /*depth*/, Json::parse_event_t event, Json& parsed) {
    switch (event) {
      case Json::parse_event_t::object_start:
        frames.push_back(Frame{true, {}, {}});
        break;
      case Json::parse_event_t::array_start:
        frames.push_back(Frame{false, {}, {}});
        break;
      case Json::parse_event_t::object_end:
      case Json::parse_event_t::array_end:
        frames.pop_back();
        break;
      case Json::parse_event_t::key: {
        Frame& frame = frames.back();
        frame.key = parsed.get<std::string>();
        if (!frame.keys.insert(frame.key).second) {
          throw std::invalid_argument("config: repeated key \"" + path() + "\"");
        }
        break;
      }
      case Json::parse_event_t::value:
        break;
    }
    return true;
  };
  try {
    return Json::parse(text.begin(), text.end(), callback);
  } catch (const Json::out_of_range& e) {
    // A number beyond the doubles (1e999): the only way JSON spells a non-finite one.
    const std::string where = path();
    if (where.empty()) {
      throw std::invalid_argument("config: invalid JSON: " + strip_exception_id(e.what()));
    }
    fail(where, "must be a finite number (" + strip_exception_id(e.what()) + ")");
  } catch (const Json::exception& e) {
    throw std::invalid_argument("config: invalid JSON: " + strip_exception_id(e.what()));
  }
}

// The checks of engine::validate, with the messages that do not name a key re-worded so that
// they do: the motion model's own and the resampling policy's.
void check(const FilterConfig& c) {
  try {
    engine::visit_motion(c.motion, [](const auto& /*model*/) {});
  } catch (const std::invalid_argument& e) {
    // Only the Ackermann car (geometry) and Bailey's car (wheelbase) have parameters.
    const char* key =
        c.motion.kind == engine::MotionKind::kAckermann ? "motion.geometry" : "motion.wheelbase";
    throw std::invalid_argument("config: \"" + std::string(key) + "\": " + e.what());
  }
  if (!(c.resample.ess_fraction >= 0 && c.resample.ess_fraction <= 1)) {
    fail("resample.ess_fraction",
         "must be in [0, 1] (got " + shortest(c.resample.ess_fraction) + ")");
  }
  try {
    engine::validate(c);
  } catch (const std::invalid_argument& e) {
    std::string_view what = e.what();
    if (what.starts_with("FilterConfig: ")) what.remove_prefix(14);
    throw std::invalid_argument("config: " + std::string(what));
  }
}

}  // namespace

FilterConfig config_from_json(std::string_view text) {
  const Json root = parse(text);
  if (!root.is_object()) {
    throw std::invalid_argument("config: the configuration must be a JSON object (got " +
                                describe(root) + ")");
  }
  FilterConfig config;
  Reader reader(root, "");
  visit_config(config, reader);
  reader.finish();
  check(config);
  return config;
}

std::string config_to_json(const FilterConfig& config) {
  Writer writer("");
  visit_config(config, writer);
  return writer.json().dump(2);
}

}  // namespace fastslam::bindings
