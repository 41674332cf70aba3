// fastslam.Filter and fastslam.Estimate: engine::Filter behind numpy arrays and dicts. The
// configuration is a dict in the schema of bindings/config_json.h (keyword arguments override
// its keys, nested dicts merged); inputs are copied into engine types with the GIL held, then
// the GIL is released while the engine works, so other Python threads run meanwhile. A mutex
// per filter keeps the engine's one-call-at-a-time rule (engine/filter.h) when two Python
// threads share one filter: the second waits. A Python Filter owns its engine filter.
// Costs: the engine's, plus copies at the boundary: O(Z) for a scan of Z observations in,
// O(N) for a map or estimate out (an Estimate owns its arrays), O(state) for to_bytes.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings/config_json.h"
#include "bindings/python/module.h"
#include "bindings/python/py_json.h"
#include "bindings/python/records.h"
#include "engine/filter.h"
#include "engine/filter_config.h"
#include "tools/io/atomic_file.h"

namespace fastslam::bindings::python {
namespace {

namespace py = pybind11;
using engine::AssociationOutcome;

static_assert(static_cast<int>(AssociationOutcome::kAssociated) == 0 &&
                  static_cast<int>(AssociationOutcome::kNew) == 1 &&
                  static_cast<int>(AssociationOutcome::kDiscarded) == 2,
              "fastslam.Outcome (bindings/python/fastslam/__init__.py) mirrors these values");

// The engine filter and the lock that serialises calls into it.
class PyFilter {
 public:
  explicit PyFilter(std::unique_ptr<engine::Filter> filter) : filter_(std::move(filter)) {}

  // Runs `work(filter)` with the GIL released and the filter locked. `work` must not touch
  // Python objects.
  template <class Work>
  decltype(auto) call(Work&& work) {
    py::gil_scoped_release release;
    std::lock_guard lock(mutex_);
    return work(*filter_);
  }

  // For O(1) work (queueing a control): with the GIL held when the filter is free, since
  // releasing and taking back the GIL would cost more than the work; released only to wait for
  // another thread's call.
  template <class Work>
  decltype(auto) call_short(Work&& work) {
    std::unique_lock lock(mutex_, std::try_to_lock);
    if (lock.owns_lock()) return work(*filter_);
    py::gil_scoped_release release;
    lock.lock();
    return work(*filter_);
  }

 private:
  std::mutex mutex_;
  std::unique_ptr<engine::Filter> filter_;
};

// fastslam.Estimate: engine::Estimate as numbers and numpy arrays. The arrays are made when
// first read (then kept, so a read gives the same object each time): a front end that reads
// only the pose does not pay for the map's.
struct PyEstimate {
  engine::Estimate e;
  // Plain py::array members (array_t<Record> behind them): help() shows "numpy.ndarray".
  py::object mean_pose, covariance, best_pose, associations, map;
};

py::array_t<double> copy_array(const double* values, std::vector<py::ssize_t> shape) {
  py::array_t<double> out(shape);
  std::copy_n(values, out.size(), out.mutable_data());
  return out;
}

py::array_t<MapRecord> map_array(const std::vector<engine::MapLandmark>& map) {
  py::array_t<MapRecord> out(static_cast<py::ssize_t>(map.size()));
  MapRecord* row = out.mutable_data();
  for (const engine::MapLandmark& l : map) {
    *row++ = {l.id, l.x, l.y, l.sxx, l.sxy, l.syy, l.log_odds, l.last_seen};
  }
  return out;
}

py::array association_array(const std::vector<engine::ObservationAssociation>& report) {
  py::array_t<AssociationRecord> out(static_cast<py::ssize_t>(report.size()));
  AssociationRecord* row = out.mutable_data();
  for (const engine::ObservationAssociation& a : report) {
    *row++ = {a.observation, static_cast<std::uint32_t>(a.outcome), a.landmark_id, a.mahalanobis2};
  }
  return out;
}

PyEstimate to_python(engine::Estimate&& e) {
  PyEstimate out;
  out.e = std::move(e);
  return out;
}

// The cached array of an Estimate attribute, made by `make` on first read.
template <class Make>
py::object lazy(py::object& slot, Make&& make) {
  if (!slot) slot = make();
  return slot;
}


// `base` with `overrides` laid over it: objects merged key by key, anything else replaced.
void merge(nlohmann::json& base, const nlohmann::json& overrides) {
  for (const auto& [key, value] : overrides.items()) {
    if (value.is_object() && base.contains(key) && base[key].is_object()) {
      merge(base[key], value);
    } else {
      base[key] = value;
    }
  }
}

// config_from_json's messages start "config: "; so do ours for what JSON cannot hold.
engine::FilterConfig make_config(const py::object& config, const py::kwargs& overrides) {
  if (!config.is_none() && !py::isinstance<py::dict>(config)) {
    throw std::invalid_argument("config: must be a dict (or None), not " +
                                py::str(py::type::of(config).attr("__name__")).cast<std::string>());
  }
  nlohmann::json j = nlohmann::json::object();
  try {
    if (!config.is_none()) j = to_json(config);
    merge(j, to_json(overrides));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("config: ") + e.what());
  }
  return config_from_json(j.dump());
}

// A 1-D float64 array of `what` from any sequence of numbers; ValueError otherwise.
py::array_t<double> vector_argument(const py::handle& values, const char* what) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(values);
  if (!a) {
    PyErr_Clear();
    throw std::invalid_argument(std::string(what) + " must be a sequence of numbers");
  }
  if (a.ndim() != 1) {
    throw std::invalid_argument(std::string(what) + " must be one-dimensional, not of shape " +
                                py::str(a.attr("shape")).cast<std::string>());
  }
  return a;
}

// predict's u: a tuple or list of two Python floats read directly (the common case, and a
// numpy conversion costs more than queueing the control), anything else through numpy.
engine::Control control_argument(const py::handle& u) {
  if ((PyTuple_Check(u.ptr()) || PyList_Check(u.ptr())) && PySequence_Fast_GET_SIZE(u.ptr()) == 2) {
    PyObject* const u0 = PySequence_Fast_GET_ITEM(u.ptr(), 0);
    PyObject* const u1 = PySequence_Fast_GET_ITEM(u.ptr(), 1);
    if (PyFloat_CheckExact(u0) && PyFloat_CheckExact(u1)) {
      return {PyFloat_AS_DOUBLE(u0), PyFloat_AS_DOUBLE(u1)};
    }
  }
  const py::array_t<double> a = vector_argument(u, "predict: u");
  if (a.size() != 2) {
    throw std::invalid_argument("predict: u must hold 2 values (u0, u1), not " +
                                std::to_string(a.size()));
  }
  return {a.at(0), a.at(1)};
}

std::vector<engine::Observation> scan_argument(const py::handle& ranges, const py::handle& bearings,
                                               const py::handle& ids) {
  const py::array_t<double> r = vector_argument(ranges, "observe: ranges");
  const py::array_t<double> b = vector_argument(bearings, "observe: bearings");
  if (r.size() != b.size()) {
    throw std::invalid_argument("observe: ranges has " + std::to_string(r.size()) +
                                " values and bearings " + std::to_string(b.size()));
  }
  std::vector<engine::Observation> scan(static_cast<std::size_t>(r.size()));
  for (std::size_t j = 0; j < scan.size(); ++j) {
    scan[j].range = r.data()[j];
    scan[j].bearing = b.data()[j];
  }
  if (ids.is_none()) return scan;
  const py::array any = py::array::ensure(ids);
  if (!any) {
    PyErr_Clear();
    throw std::invalid_argument("observe: ids must be a sequence of integers (or None)");
  }
  const char kind = any.dtype().kind();
  if (any.size() > 0 && kind != 'i' && kind != 'u') {
    throw std::invalid_argument("observe: ids must be integers (-1: none), not of dtype " +
                                py::str(any.dtype()).cast<std::string>());
  }
  if (any.ndim() != 1 || any.size() != r.size()) {
    throw std::invalid_argument("observe: ids must be one-dimensional with one id per range (" +
                                std::to_string(r.size()) + "), not of shape " +
                                py::str(any.attr("shape")).cast<std::string>());
  }
  const auto i = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(any);
  for (std::size_t j = 0; j < scan.size(); ++j) scan[j].id = i.data()[j];
  return scan;
}

std::vector<engine::MapLandmark> map_argument(const py::handle& landmarks, double log_odds) {
  const bool has_fields =
      py::hasattr(landmarks, "dtype") && !py::getattr(landmarks.attr("dtype"), "names").is_none();
  if (!has_fields && !py::isinstance<py::dict>(landmarks)) {
    throw std::invalid_argument(
        "set_map: landmarks must be a structured array or a dict of arrays with fields x, y, "
        "sxx, sxy, syy (and optionally id, log_odds)");
  }
  auto has = [&](const char* name) {
    if (has_fields) return landmarks.attr("dtype").attr("names").contains(name);
    return landmarks.cast<py::dict>().contains(name);
  };
  auto column = [&](const char* name) {
    if (!has(name)) throw std::invalid_argument(std::string("set_map: no field '") + name + "'");
    const py::object values = landmarks[py::str(name)];
    return vector_argument(values, (std::string("set_map: ") + name).c_str());
  };
  const py::array_t<double> x = column("x"), y = column("y"), sxx = column("sxx"),
                            sxy = column("sxy"), syy = column("syy");
  const std::size_t n = static_cast<std::size_t>(x.size());
  for (const py::array_t<double>* c : {&y, &sxx, &sxy, &syy}) {
    if (static_cast<std::size_t>(c->size()) != n) {
      throw std::invalid_argument("set_map: the fields differ in length");
    }
  }
  std::optional<py::array_t<double>> odds;
  if (has("log_odds")) odds = column("log_odds");
  std::optional<py::array_t<std::uint64_t>> ids;
  if (has("id")) {
    const py::object values = landmarks[py::str("id")];
    ids = py::array_t<std::uint64_t, py::array::forcecast>::ensure(values);
    if (!*ids) {
      PyErr_Clear();
      throw std::invalid_argument("set_map: id must be non-negative integers");
    }
  }
  if ((odds && static_cast<std::size_t>(odds->size()) != n) ||
      (ids && static_cast<std::size_t>(ids->size()) != n)) {
    throw std::invalid_argument("set_map: the fields differ in length");
  }
  std::vector<engine::MapLandmark> out(n);
  for (std::size_t k = 0; k < n; ++k) {
    engine::MapLandmark& l = out[k];
    l.id = ids ? ids->at(k) : k;
    l.x = x.at(k);
    l.y = y.at(k);
    l.sxx = sxx.at(k);
    l.sxy = sxy.at(k);
    l.syy = syy.at(k);
    l.log_odds = odds ? odds->at(k) : log_odds;
  }
  return out;
}

py::dict statistics_dict(const engine::FilterStatistics& s) {
  py::dict d;
  d["controls"] = s.controls;
  d["scans"] = s.scans;
  d["observations"] = s.observations;
  d["resamples"] = s.resamples;
  d["weight_resets"] = s.weight_resets;
  d["predict_seconds"] = s.predict_seconds;
  d["associate_seconds"] = s.associate_seconds;
  d["update_seconds"] = s.update_seconds;
  d["resample_seconds"] = s.resample_seconds;
  d["observe_wall_seconds"] = s.observe_wall_seconds;
  d["landmarks_created"] = s.landmarks_created;
  d["landmarks_removed"] = s.landmarks_removed;
  d["log_evidence"] = s.log_evidence;
  d["live_nodes"] = s.live_nodes;
  d["live_bytes"] = s.live_bytes;
  return d;
}

std::unique_ptr<PyFilter> load_stream(std::istream& in) {
  std::unique_ptr<engine::Filter> filter;
  {
    py::gil_scoped_release release;
    filter = engine::Filter::load(in);
  }
  return std::make_unique<PyFilter>(std::move(filter));
}

py::bytes to_bytes(PyFilter& self) {
  std::string text = self.call([](engine::Filter& f) {
    std::ostringstream out;
    f.save(out);
    return std::move(out).str();
  });
  return py::bytes(text);
}

std::unique_ptr<PyFilter> from_bytes(const py::buffer& data) {
  const py::buffer_info info = data.request();
  if (info.ndim != 1 || info.itemsize != 1) {
    throw std::invalid_argument("Filter.from_bytes: expected bytes (or a 1-D byte buffer)");
  }
  std::istringstream in(
      std::string(static_cast<const char*>(info.ptr), static_cast<std::size_t>(info.size)));
  return load_stream(in);
}

std::string repr(const PyEstimate& p) {
  const engine::Estimate& e = p.e;
  const double* pose = e.mean_pose;
  char text[256];
  std::snprintf(text, sizeof(text),
                "fastslam.Estimate(time=%g, mean_pose=[%g, %g, %g], best_particle=%u, "
                "effective_sample_size=%g, associations=%zd, map=%zd landmarks)",
                e.time, pose[0], pose[1], pose[2], e.best_particle, e.effective_sample_size,
                static_cast<py::ssize_t>(e.associations.size()),
                static_cast<py::ssize_t>(e.map.size()));
  return text;
}

constexpr const char* kFilterDoc =
    R"doc(A FastSLAM 1.0 / 2.0 filter (engine/filter.h): M particles, each with its own map.

Filter(config=None, **overrides) builds one from a configuration dict (the JSON schema of
docs/python.md, the same as the C API's); keyword arguments override its keys, nested dicts
merge: Filter({"particles": 200}, seed=3, sensor={"sigma_range": 0.2}). Missing keys keep their
defaults. Raises ValueError naming the key for an unknown key or an unusable value.

Feed predict() for every odometry sample and observe() for every scan, in time order; read
estimate(), map() and statistics() whenever you like. Bad input raises ValueError with the
engine's message and leaves the filter unchanged. The GIL is released while the engine works;
calls on one filter from several threads are serialised. Filters pickle (as their saved state),
so copy.deepcopy continues bit-identically.)doc";

}  // namespace

void bind_filter(py::module_& m) {
  py::class_<PyEstimate>(m, "Estimate", R"doc(A summary of the particles (engine::Estimate).

Attributes: time (s, the latest data's), mean_pose (5,) weighted mean pose (x, y, theta, and
the velocities of the Brownian motion models), covariance (3, 3) of (x, y, theta) about it,
best_pose (5,) of the particle of highest weight, best_particle (its index),
effective_sample_size, associations (structured array: observation, outcome (fastslam.Outcome),
landmark_id, mahalanobis2: the last scan, as the most likely particle took it), map (structured
array: id, x, y, sxx, sxy, syy, log_odds, last_seen: the best particle's map).)doc")
      .def_property_readonly("time", [](const PyEstimate& p) { return p.e.time; })
      .def_property_readonly(
          "mean_pose",
          [](PyEstimate& p) -> py::array {
            return lazy(p.mean_pose, [&] { return copy_array(p.e.mean_pose, {5}); });
          })
      .def_property_readonly(
          "covariance",
          [](PyEstimate& p) -> py::array {
            return lazy(p.covariance, [&] { return copy_array(p.e.pose_covariance, {3, 3}); });
          })
      .def_property_readonly(
          "best_pose",
          [](PyEstimate& p) -> py::array {
            return lazy(p.best_pose, [&] { return copy_array(p.e.best_pose, {5}); });
          })
      .def_property_readonly("best_particle", [](const PyEstimate& p) { return p.e.best_particle; })
      .def_property_readonly("effective_sample_size",
                             [](const PyEstimate& p) { return p.e.effective_sample_size; })
      .def_property_readonly(
          "associations",
          [](PyEstimate& p) -> py::array {
            return lazy(p.associations, [&] { return association_array(p.e.associations); });
          })
      .def_property_readonly(
          "map",
          [](PyEstimate& p) -> py::array {
            return lazy(p.map, [&] { return py::array(map_array(p.e.map)); });
          })
      .def("__repr__", &repr);

  py::class_<PyFilter>(m, "Filter", kFilterDoc)
      .def(py::init([](const py::object& config, const py::kwargs& overrides) {
             return std::make_unique<PyFilter>(
                 std::make_unique<engine::Filter>(make_config(config, overrides)));
           }),
           py::arg("config") = py::none())
      .def_property_readonly(
          "config",
          [](PyFilter& self) {
            const std::string text =
                self.call([](engine::Filter& f) { return config_to_json(f.config()); });
            return from_json(nlohmann::json::parse(text));
          },
          "The configuration as a dict (every key, defaults included): Filter(f.config) builds "
          "an identical filter.")
      .def(
          "predict",
          [](PyFilter& self, const py::object& u, double dt, std::optional<double> t) {
            const engine::Control control = control_argument(u);
            self.call_short([&](engine::Filter& f) {
              if (t) {
                f.predict(control, dt, *t);
              } else {
                f.predict(control, dt);
              }
            });
          },
          py::arg("u"), py::arg("dt"), py::arg("t") = py::none(),
          R"doc(Queues one odometry sample u = (u0, u1) held for dt seconds (the motion model's
meaning: speed and steering angle for the cars, v and omega for the unicycle). With t, the
filter's clock becomes t (not before the clock); without, it advances by dt. ValueError for a
non-finite value, dt < 0, t going backwards or u not of 2 values. O(1) amortised: the work
happens in the next observe() or estimate().)doc")
      .def(
          "predict",
          [](PyFilter& self, const py::array_t<double, py::array::c_style | py::array::forcecast>& u,
             const py::array_t<double, py::array::c_style | py::array::forcecast>& dt,
             const std::optional<py::array_t<double, py::array::c_style | py::array::forcecast>>&
                 t) {
            if (u.ndim() != 2 || u.shape(1) != 2) {
              throw std::invalid_argument(
                  "predict: a batch of controls u must have shape (K, 2), not " +
                  py::str(u.attr("shape")).cast<std::string>());
            }
            const auto k = static_cast<std::size_t>(u.shape(0));
            if (dt.ndim() != 1 || (t && t->ndim() != 1)) {
              throw std::invalid_argument("predict: with controls of shape (K, 2), dt and t "
                                          "must be one-dimensional arrays of K values");
            }
            static_assert(sizeof(engine::Control) == 2 * sizeof(double));
            const std::span<const engine::Control> controls(
                reinterpret_cast<const engine::Control*>(u.data()), k);
            const std::span<const double> dts(dt.data(), static_cast<std::size_t>(dt.size()));
            const std::span<const double> times =
                t ? std::span<const double>(t->data(), static_cast<std::size_t>(t->size()))
                  : std::span<const double>();
            self.call([&](engine::Filter& f) { f.predict(controls, dts, times); });
          },
          py::arg("u"), py::arg("dt"), py::arg("t") = py::none(),
          R"doc(The batch form: u of shape (K, 2), dt (and t, if given) of K values queue K
controls in one call, as K calls would, for the odometry between two scans. All or nothing:
ValueError naming the first bad control, and none is queued. O(K).)doc")
      .def(
          "observe",
          [](PyFilter& self, const py::object& ranges, const py::object& bearings,
             const py::object& ids, std::optional<double> t) {
            const std::vector<engine::Observation> scan = scan_argument(ranges, bearings, ids);
            self.call([&](engine::Filter& f) {
              if (t) {
                f.observe(scan, *t);
              } else {
                f.observe(scan);
              }
            });
          },
          py::arg("ranges"), py::arg("bearings"), py::arg("ids") = py::none(),
          py::arg("t") = py::none(),
          R"doc(Runs the queued controls and one scan through every particle, then resamples by
the configured policy. ranges (m, > 0) and bearings (rad, counter-clockwise from the sensor's
heading) are 1-D sequences of equal length; ids, the landmarks' identities (>= 0), are needed
with known association and ignored otherwise (None: -1, no id). With t the clock becomes t.
ValueError (and nothing changes) for a bad value, a missing or repeated id with known
association, mismatched lengths or t going backwards.)doc")
      .def(
          "estimate",
          [](PyFilter& self) {
            return to_python(self.call([](engine::Filter& f) { return f.estimate(); }));
          },
          "Drains the queued controls and summarises the particles: a fastslam.Estimate. "
          "O(M + N).")
      .def(
          "map",
          [](PyFilter& self) {
            return py::array(
                map_array(self.call([](engine::Filter& f) { return f.estimate().map; })));
          },
          "The best particle's map as a structured array (fastslam.MAP_DTYPE: id, x, y, sxx, "
          "sxy, syy, log_odds, last_seen), in slot order. O(M + N).")
      .def(
          "statistics",
          [](PyFilter& self) {
            return statistics_dict(self.call([](engine::Filter& f) { return f.statistics(); }));
          },
          "Counters and timings as a dict: controls, scans, observations, resamples, "
          "weight_resets, the phases' seconds, landmarks_created / removed, log_evidence, "
          "live_nodes, live_bytes.")
      .def(
          "take_trajectory",
          [](PyFilter& self) {
            const std::vector<engine::TrajectoryPoint> points =
                self.call([](engine::Filter& f) { return f.take_trajectory(); });
            py::array_t<TrajectoryRecord> out(static_cast<py::ssize_t>(points.size()));
            TrajectoryRecord* row = out.mutable_data();
            for (const engine::TrajectoryPoint& p : points) *row++ = {p.control, p.x, p.y, p.theta};
            return py::array(std::move(out));
          },
          "The weighted-mean pose after every control since the last call, as a structured "
          "array (control, x, y, theta); empty unless the config has record_trajectory.")
      .def(
          "particles",
          [](PyFilter& self) {
            const std::vector<ParticleRecord> rows = self.call([](engine::Filter& f) {
              const memory::ParticleStore& store = f.particles();
              std::vector<ParticleRecord> out(store.size());
              for (std::size_t i = 0; i < out.size(); ++i) {
                out[i] = {store.x()[i], store.y()[i], store.theta()[i], store.log_weight()[i],
                          store.landmark_count(i)};
              }
              return out;
            });
            py::array_t<ParticleRecord> out(static_cast<py::ssize_t>(rows.size()));
            std::copy(rows.begin(), rows.end(), out.mutable_data());
            return py::array(std::move(out));
          },
          "The particles, after draining the queue, as a structured array "
          "(fastslam.PARTICLE_DTYPE: x, y, theta, log_weight, landmarks). O(M).")
      .def(
          "set_map",
          [](PyFilter& self, const py::object& landmarks) {
            const double initial =
                self.call([](engine::Filter& f) { return f.config().existence.initial; });
            const std::vector<engine::MapLandmark> map = map_argument(landmarks, initial);
            self.call([&](engine::Filter& f) { f.set_map(map); });
          },
          py::arg("landmarks"),
          R"doc(Replaces every particle's map by one map: a structured array (such as map()
returns) or a dict of arrays with x, y, sxx, sxy, syy and optionally id (default 0..N-1) and
log_odds (default: the config's existence.initial). ValueError for a non-finite position, a
covariance that is not symmetric positive definite or a repeated id with known association.)doc")
      .def(
          "save",
          [](PyFilter& self, const py::object& path) {
            const std::string name = path_string(path);
            // A temporary renamed over the file: a failure or a kill mid-write leaves the
            // previous file whole.
            self.call([&](engine::Filter& f) {
              tools::AtomicFile out(name);
              try {
                f.save(out.stream());
              } catch (const std::runtime_error&) {
                if (out.failed()) out.flush();  // throws naming the file and the system's reason
                throw;
              }
              out.commit();
            });
          },
          py::arg("path"),
          "Writes the whole state (config, counters, queued controls, particles, maps) to a "
          "file; Filter.load(path) continues bit-identically.")
      .def_static(
          "load",
          [](const py::object& path) {
            const std::string name = path_string(path);
            std::ifstream in(name, std::ios::binary);
            if (!in) raise_file_not_found(name);
            return load_stream(in);
          },
          py::arg("path"),
          "A filter from a file save() wrote. RuntimeError when the file is not a saved state "
          "(the engine's message); FileNotFoundError when it cannot be opened.")
      .def("to_bytes", &to_bytes, "The whole state as bytes (what save() writes).")
      .def_static("from_bytes", &from_bytes, py::arg("data"),
                  "A filter from to_bytes()'s bytes. RuntimeError when they are not a state.")
      .def(py::pickle([](PyFilter& self) { return py::make_tuple(to_bytes(self)); },
                      [](const py::tuple& state) {
                        if (state.size() != 1) throw std::runtime_error("bad Filter pickle");
                        return from_bytes(state[0].cast<py::buffer>());
                      }))
      .def("__repr__", [](PyFilter& self) {
        return self.call([](engine::Filter& f) {
          const engine::FilterConfig& c = f.config();
          const engine::FilterStatistics s = f.statistics();
          return "fastslam.Filter(algorithm='" + std::string(engine::to_string(c.algorithm)) +
                 "', particles=" + std::to_string(c.particles) + ", association='" +
                 std::string(engine::to_string(c.association)) + "', motion='" +
                 std::string(engine::to_string(c.motion.kind)) +
                 "', controls=" + std::to_string(s.controls) +
                 ", scans=" + std::to_string(s.scans) + ")";
        });
      });
}

}  // namespace fastslam::bindings::python
