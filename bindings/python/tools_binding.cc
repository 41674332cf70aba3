// fastslam.run, fastslam.run_config and fastslam.read_log: the command line's `fastslam run`
// (tools/cli/run_command.h) and the native log reader (tools/io/log_format.h). Keyword
// options are the command line's long flags with '_' for '-', parsed by the command line's own
// option table (tools/cli/command_line.h) so that they check and mean exactly what the flags
// do. The GIL is released while a run works or a log is read; each call is independent.
// Costs: a run's; read_log holds the whole log (as tools::Log does) and copies it once into
// the returned arrays; run_config opens the source (a log is read whole).
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <utility>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "bindings/config_json.h"
#include "bindings/python/module.h"
#include "bindings/python/py_json.h"
#include "bindings/python/records.h"
#include "engine/filter_config.h"
#include "tools/cli/command_line.h"
#include "tools/cli/run_command.h"
#include "tools/io/log_format.h"

namespace fastslam::bindings::python {
namespace {

namespace py = pybind11;

// Options the Python functions refuse: --seeds runs a sweep (call run once per seed), and
// --config reads a file (pass the options instead).
constexpr const char* kRefused[] = {"seeds", "config"};

// The RunOptions `fastslam run` would build from the flags the keyword arguments name: the
// source is a native log at `log_path` unless `source` says otherwise; no progress bar and no
// picture unless asked for. Throws std::invalid_argument naming a bad option.
tools::RunOptions run_options(const char* function, const py::object& log_path,
                              const py::kwargs& kwargs) {
  nlohmann::json options = {{"no-progress", true}};
  if (!log_path.is_none()) {
    const std::string path = path_string(log_path);
    if (!std::filesystem::exists(path)) raise_file_not_found(path);
    options["source"] = "log";
    options["data"] = path;
  }
  CLI::App app;
  tools::RunOptions run;
  tools::RunWords words;
  tools::add_run_options(app, run, words);
  for (const auto& [key, value] : kwargs) {
    const std::string name = key.cast<std::string>();
    std::string flag = name;
    std::replace(flag.begin(), flag.end(), '_', '-');
    const bool refused =
        std::find(std::begin(kRefused), std::end(kRefused), flag) != std::end(kRefused);
    if (refused || app.get_option_no_throw("--" + flag) == nullptr) {
      throw std::invalid_argument(std::string(function) + ": unknown option '" + name +
                                  "' (the options are `fastslam run`'s long flags with '_' for "
                                  "'-', except seeds and config)");
    }
    nlohmann::json v = to_json(value, name);
    if (v.is_array()) {  // a list of numbers or words: comma separated, as the flags take them
      std::string joined;
      for (const nlohmann::json& item : v) {
        joined += (joined.empty() ? "" : ",") +
                  (item.is_string() ? item.get<std::string>() : item.dump());
      }
      v = joined;
    }
    options[flag] = std::move(v);
  }
  if (!options.contains("plot") && !options.contains("no-plot")) options["plot"] = "none";
  const char* argv[] = {function};
  app.parse(1, argv);
  try {
    tools::apply_json_config(app, options, function);
    tools::finish_run_options(app, words, run);
  } catch (const std::runtime_error& e) {  // a bad value, named with its key
    throw std::invalid_argument(e.what());
  }
  return run;
}

py::dict to_dict(const nlohmann::json& j) { return from_json(j).cast<py::dict>(); }

// fastslam.Log. Plain py::array members (array_t<Record> behind them): help() shows
// "numpy.ndarray".
struct PyLog {
  double start_time = 0.0;
  py::array start_pose;
  std::string motion;
  py::dict config;
  py::array events, observations, landmarks;
  bool unterminated = false;
};

PyLog to_python(const tools::Log& log) {
  PyLog out;
  out.start_time = log.header.start_time;
  py::array_t<double> start(3);
  std::copy_n(log.header.start_pose, 3, start.mutable_data());
  out.start_pose = std::move(start);
  out.motion = std::string(engine::to_string(log.header.motion.kind));
  engine::FilterConfig config;
  config.motion = log.header.motion;
  config.sensor = log.header.sensor;
  for (int k = 0; k < 3; ++k) config.initial_pose[k] = log.header.start_pose[k];
  out.config = to_dict(nlohmann::json::parse(config_to_json(config)));
  py::array_t<EventRecord> events(static_cast<py::ssize_t>(log.events.size()));
  EventRecord* e = events.mutable_data();
  for (const tools::Event& v : log.events) {
    *e++ = {v.time,       static_cast<std::uint32_t>(v.kind),
            v.count,      v.first,
            v.dt,         v.control.u0,
            v.control.u1, v.x,
            v.y,          v.theta};
  }
  out.events = std::move(events);
  py::array_t<ObservationRecord> observations(static_cast<py::ssize_t>(log.observations.size()));
  ObservationRecord* z = observations.mutable_data();
  for (const engine::Observation& o : log.observations) *z++ = {o.range, o.bearing, o.id};
  out.observations = std::move(observations);
  py::array_t<TruthRecord> landmarks(static_cast<py::ssize_t>(log.landmarks.size()));
  TruthRecord* l = landmarks.mutable_data();
  for (const tools::TruthLandmark& t : log.landmarks) *l++ = {t.id, t.x, t.y};
  out.landmarks = std::move(landmarks);
  out.unterminated = log.unterminated;
  return out;
}

}  // namespace

void bind_tools(py::module_& m) {
  m.def(
      "run",
      [](const py::object& log_path, bool verbose, const py::kwargs& kwargs) {
        tools::RunOptions options = run_options("fastslam.run", log_path, kwargs);
        options.quiet = !verbose;
        nlohmann::json metrics;
        {
          py::gil_scoped_release release;
          metrics = tools::run_once(options);
        }
        return to_dict(metrics);
      },
      py::arg("log_path") = py::none(), py::kw_only(), py::arg("verbose") = false,
      R"doc(Runs `fastslam run --source log --data LOG_PATH` and returns its metrics.json as a dict
(docs/evaluation.md lists the keys). Keyword options are the command line's long flags with '_'
for '-' (particles=200, algorithm="fastslam2", association="ml", seed=3, out="dir", ...); a flag
without a value takes True. With log_path None, `source` (and its options) say what to run,
e.g. run(source="sim", world="loop"). No progress bar and no picture unless no_progress=False /
plot="svg" (or "png", or no_plot=False for the default svg); verbose=True prints the command
line's summary. ValueError for an unknown option or a bad value, FileNotFoundError for a missing
log, RuntimeError for an unreadable one.)doc");

  m.def(
      "run_config",
      [](const py::object& log_path, const py::kwargs& kwargs) {
        const tools::RunOptions options = run_options("fastslam.run_config", log_path, kwargs);
        engine::FilterConfig config;
        {
          py::gil_scoped_release release;
          config = tools::run_filter_config(options);
        }
        return to_dict(nlohmann::json::parse(config_to_json(config)));
      },
      py::arg("log_path") = py::none(),
      R"doc(The filter configuration run() would use with the same arguments, as a dict for
Filter(): the log header's models and noises, the options' algorithm, particles, association
(resolved from "auto"), seed, ... and record_trajectory on. Feeding the log's controls and scans
to Filter(run_config(log)) reproduces run(log)'s poses exactly.)doc");

  py::class_<PyLog>(m, "Log", R"doc(A native log file (docs/log-format.md), read by read_log().

Attributes: start_time, start_pose (x, y, theta), motion (the model's name), config (a filter
configuration dict holding the header's motion and sensor models and the start pose), events
(structured array in file order: time, kind (fastslam.EventKind), count, first, dt, u0, u1, x,
y, theta), observations (range, bearing, id; a scan's are observations[first:first + count]),
landmarks (the true landmarks: id, x, y), unterminated (True when the file ended without its end
marker: it may be truncated). records() iterates the events as tuples.)doc")
      .def_readonly("start_time", &PyLog::start_time)
      .def_readonly("start_pose", &PyLog::start_pose)
      .def_readonly("motion", &PyLog::motion)
      .def_readonly("config", &PyLog::config)
      .def_readonly("events", &PyLog::events)
      .def_readonly("observations", &PyLog::observations)
      .def_readonly("landmarks", &PyLog::landmarks)
      .def_readonly("unterminated", &PyLog::unterminated)
      .def("__len__", [](const PyLog& log) { return log.events.size(); })
      .def("__repr__", [](const PyLog& log) {
        return "fastslam.Log(motion='" + log.motion +
               "', events=" + std::to_string(log.events.size()) +
               ", observations=" + std::to_string(log.observations.size()) +
               ", landmarks=" + std::to_string(log.landmarks.size()) + ")";
      });

  m.def(
      "read_log",
      [](const py::object& path) {
        const std::string name = path_string(path);
        if (!std::filesystem::exists(name)) raise_file_not_found(name);
        tools::Log log;
        {
          py::gil_scoped_release release;
          log = tools::read_log(name);
        }
        return to_python(log);
      },
      py::arg("path"),
      "Reads a native log file into a fastslam.Log. RuntimeError naming the file, the line and "
      "the reason for anything the format refuses.");
}

}  // namespace fastslam::bindings::python
