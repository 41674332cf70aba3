#include "tools/cli/command_line.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>
#include <sys/resource.h>
#include <thread>
#include <utility>

#include <nlohmann/json.hpp>

#include "engine/enum_names.h"
#include "tools/cli/memory_budget.h"
#include "tools/cli/run_sweep.h"

namespace fastslam::tools {
namespace {

using engine::Algorithm;
using engine::Association;
using parallel::ResamplePolicy;
using parallel::ResampleScheme;

// At most this much of a bad value is quoted back.
constexpr std::size_t kMaxQuoted = 80;

std::string clip(const std::string& text) {
  if (text.size() <= kMaxQuoted) return text;
  return text.substr(0, kMaxQuoted) + "... (" + std::to_string(text.size()) + " bytes)";
}

// A bound for a message, in its shortest exact form (0.001, 3600).
std::string format_bound(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

// Decimal integers within T's range, checked on the text: CLI11's own conversion clamps
// 18446744073709551616 to 2^64 - 1 and wraps -1 round to it for unsigned options.
template <class T>
CLI::Validator whole_number() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        T value{};
        const char* const first = text.data();
        const char* const last = first + text.size();
        const auto [end, ec] = std::from_chars(first, last, value);
        const bool digits = !text.empty() &&
                            std::all_of(text.begin() + (text[0] == '-'), text.end(),
                                        [](char c) { return c >= '0' && c <= '9'; }) &&
                            text != "-";
        if (ec == std::errc() && end == last) return {};
        if (digits && (ec == std::errc::result_out_of_range || text[0] == '-')) {
          return "'" + clip(text) + "' is out of range (" +
                 std::to_string(std::numeric_limits<T>::min()) + " to " +
                 std::to_string(std::numeric_limits<T>::max()) + ")";
        }
        return "'" + clip(text) + "' is not a decimal integer";
      },
      "INT", "whole number");
}

// Decimal reals (1.5, -2, 1e-3; not hex, NaN or infinity) within [lo, hi], or (lo, hi] when
// `open_low`, checked on the text: CLI11's own ranges let NaN through, print 2^1024 in full
// as their bound and quote the whole value back.
CLI::Validator real_number(double lo, double hi, bool open_low, std::string description) {
  return CLI::Validator(
      [lo, hi, open_low](std::string& text) -> std::string {
        const std::size_t sign = !text.empty() && text[0] == '+';
        const char* const first = text.data() + sign;
        const char* const last = text.data() + text.size();
        double value = 0.0;
        const auto [end, ec] = std::from_chars(first, last, value, std::chars_format::general);
        const std::string quoted = "'" + clip(text) + "'";
        if (ec == std::errc::result_out_of_range && end == last) {
          return quoted + " is out of a double's range";
        }
        if (ec != std::errc() || end != last || first == last) return quoted + " is not a number";
        if (!std::isfinite(value)) return quoted + " is not a finite number";
        if ((open_low ? value > lo : value >= lo) && value <= hi) return {};
        if (hi == std::numeric_limits<double>::max()) {
          return quoted + (open_low ? " must be > " : " must be >= ") + format_bound(lo);
        }
        return quoted + " is not in " + (open_low ? "(" : "[") + format_bound(lo) + ", " +
               format_bound(hi) + "]";
      },
      std::move(description));
}
CLI::Validator positive_number() {
  return real_number(0.0, std::numeric_limits<double>::max(), true, "POSITIVE");
}
CLI::Validator non_negative_number() {
  return real_number(0.0, std::numeric_limits<double>::max(), false, "NONNEGATIVE");
}
CLI::Validator finite_number() {
  return real_number(std::numeric_limits<double>::lowest(), std::numeric_limits<double>::max(),
                     false, "FINITE");
}
// Described as CLI::Range describes a double range: "FLOAT in [LO - HI]".
CLI::Validator number_in(double lo, double hi) {
  std::ostringstream description;
  description << "FLOAT in [" << lo << " - " << hi << "]";
  return real_number(lo, hi, false, description.str());
}

// The world of a simulated source (shared by run and convert).
void add_world_options(CLI::App& cmd, RunOptions& o, RunWords& w) {
  cmd.add_option("--landmarks-csv", o.landmarks_csv,
                 "world landmarks (id,x_m,y_m), e.g. ../shared/data/bailey_sim/"
                 "example_webmap_landmarks.csv")
      ->check(CLI::ExistingFile);
  cmd.add_option("--waypoints-csv", o.waypoints_csv, "world route (index,x_m,y_m)")
      ->check(CLI::ExistingFile);
  cmd.add_option("--world", o.world, "procedural world when no CSV is given")
      ->check(CLI::IsMember({"grid", "loop"}))
      ->capture_default_str();
  cmd.add_option("--landmarks", o.landmarks, "landmarks of a grid world")
      ->check(whole_number<std::uint64_t>())
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}))
      ->capture_default_str();
  cmd.add_option("--spacing", w.spacing,
                 "metres per landmark in procedural worlds (default: 2 on a grid, 10 on a loop)")
      ->check(positive_number());
  cmd.add_option("--loop-length", o.loop_length, "length of a loop world, metres")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_option("--scan-period", w.scan_period,
                 "seconds between simulated scans (default: 1 on a grid, else Bailey's 0.2)")
      ->check(number_in(0.001, 3600.0));
  // The simulator's true noises. The filter assumes the same unless --sigma-* says otherwise
  // (a simulated source's header carries these), so one flag scales both.
  cmd.add_option("--sim-sigma-speed", o.sim.sigma_v,
                 "simulated speed noise, m/s (true and, unless --sigma-u0, the filter's)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--sim-sigma-steer", o.sim.sigma_steer,
                 "simulated steering noise, rad (true and, unless --sigma-u1, the filter's)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--sim-sigma-range", o.sim.sigma_range,
                 "simulated range noise, m (true and, unless --sigma-range, the filter's)")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_option("--sim-sigma-bearing", o.sim.sigma_bearing,
                 "simulated bearing noise, rad (true and, unless --sigma-bearing, the filter's)")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_option("--loops", w.loops,
                 "times the route is driven (default: 2 for CSV worlds, 1 else)")
      ->check(whole_number<int>())
      ->check(CLI::Range(1, 1000));
  cmd.add_option("--at-waypoint", o.sim.at_waypoint,
                 "metres within which the simulated car has reached a waypoint")
      ->check(positive_number())
      ->capture_default_str();
}

// The source's recommended filter settings, for each option the user did not give.
template <class Given>
void apply_filter_defaults(const FilterDefaults& d, const Given& given, RunOptions& o) {
  if (d.existence_range_margin && !given("--existence-range-margin")) {
    o.filter.existence.range_margin = *d.existence_range_margin;
  }
  if (d.existence_missed && !given("--existence-missed")) {
    o.filter.existence.missed = *d.existence_missed;
  }
  if (o.filter.algorithm == Algorithm::kFastSlam2) {
    if (d.fastslam2_error_correlation && o.motion == "odometry" && !given("--error-correlation")) {
      o.filter.error_correlation = *d.fastslam2_error_correlation;
    }
    if (d.fastslam2_sigma_range && !given("--sigma-range")) {
      o.model.sigma_range = d.fastslam2_sigma_range;
    }
    if (d.fastslam2_sigma_bearing && !given("--sigma-bearing")) {
      o.model.sigma_bearing = d.fastslam2_sigma_bearing;
    }
  }
}

void add_config_option(CLI::App& cmd, RunWords& w) {
  cmd.add_option("--config", w.config,
                 "JSON file of options (keys = long flag names without dashes); flags win")
      ->check(CLI::ExistingFile);
}

// The UTIAS MRCLAM reader's options (run and convert).
void add_utias_options(CLI::App& cmd, RunOptions& o) {
  cmd.add_option("--robot", o.utias.robot, "utias: the robot whose run is read (1-5)")
      ->check(whole_number<int>())
      ->check(CLI::Range(1, kUtiasRobots))
      ->capture_default_str();
  cmd.add_option("--utias-odometry-lead", o.utias.odometry_lead,
                 "utias: seconds the odometry leads the robot's motion; each control is stamped "
                 "this much later (default: the robot's calibrated lead, 0.14-0.22 s; 0: the "
                 "rows' times)")
      ->check(CLI::Range(0.0, kUtiasMaxOdometryLead));
}

// The Victoria Park reader's options (run and convert): heading fit, control cuts, the gate.
void add_victoria_park_options(CLI::App& cmd, RunOptions& o, RunWords& w) {
  cmd.add_option("--heading-fit-seconds", o.victoria_park.heading_fit_seconds,
                 "victoria-park: seconds of GPS after the first fix the start heading is fitted to")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_flag("--split-controls", o.victoria_park.split_controls_at_scans,
               "victoria-park: cut the odometry interval holding a scan at the scan time");
  VictoriaParkGate& gate = o.victoria_park.gate;
  cmd.add_option("--vp-min-range", gate.min_range,
                 "victoria-park: detections nearer than this are dropped, m")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--vp-max-range", gate.max_range,
                 "victoria-park: detections farther than this are dropped, m (also the range "
                 "within which negative information expects trees)")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_option("--vp-min-bearing-deg", w.vp_min_bearing_deg,
                 "victoria-park: detections right of this bearing are dropped, degrees "
                 "(default -87.1: the detector's scan-edge margin)")
      ->check(finite_number());
  cmd.add_option(
         "--vp-max-bearing-deg", w.vp_max_bearing_deg,
         "victoria-park: detections left of this bearing are dropped, degrees (default 87.1)")
      ->check(finite_number());
  cmd.add_option("--vp-laser-yaw-deg", w.vp_laser_yaw_deg,
                 "victoria-park: the laser's yaw on the car, degrees counter-clockwise (default 0)")
      ->check(finite_number());
  cmd.add_option("--vp-laser-x", o.victoria_park.geometry.a,
                 "victoria-park: the laser's distance ahead of the rear axle, m (the model's a)")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_option("--vp-laser-y", o.victoria_park.geometry.b,
                 "victoria-park: the laser's offset left of the car's centre line, m (the "
                 "model's b)")
      ->check(finite_number())
      ->capture_default_str();
  cmd.add_option("--vp-max-diameter", gate.max_diameter,
                 "victoria-park: detections wider than this are dropped, m (default: no limit)")
      ->check(positive_number());
}

// Option groups of `run`, defined at the end of the file.
void add_association_options(CLI::App& cmd, RunOptions& o, RunWords& w);
void add_execution_options(CLI::App& cmd, RunOptions& o, RunWords& w);
void add_output_options(CLI::App& cmd, RunOptions& o, RunWords& w);

}  // namespace

void add_run_options(CLI::App& cmd, RunOptions& o, RunWords& w) {
  engine::FilterConfig& f = o.filter;
  cmd.add_option("--source", o.source,
                 "where events come from: a simulated world, a native log or a data set")
      ->check(CLI::IsMember(source_names()))
      ->capture_default_str();
  cmd.add_option("--data", o.data,
                 "a recorded source's file or directory: the log file (docs/log-format.md) or "
                 "the data set's directory");
  add_world_options(cmd, o, w);
  cmd.add_option("--algorithm", w.algorithm, "FastSLAM version, or ekf (the EKF-SLAM baseline)")
      ->check(CLI::IsMember(engine::enum_names<Algorithm>()))
      ->capture_default_str();
  cmd.add_option("--motion", o.motion,
                 "odometry: the source's motion model; none: ignore the controls, Brownian "
                 "velocities (eq. 79-81; --sigma-u0/--sigma-u1 are the v and omega increments); "
                 "none-curvature: the same walking v and the path's curvature (1/m), so the "
                 "heading cannot turn while the vehicle stands")
      ->check(CLI::IsMember(motion_choices()))
      ->capture_default_str();
  cmd.add_option("--motion-draw", w.motion_draw,
                 "control moves each particle at every control; composed (FastSLAM with "
                 "odometry) once per run of controls between scans (1.0 draws from the run's "
                 "first-order Gaussian, 2.0's prior is the same up to rounding), faster; auto: "
                 "composed where it applies (docs/engine-config.md, \"The motion draw\")")
      ->check(CLI::IsMember(engine::enum_names<engine::MotionDraw>()))
      ->capture_default_str();
  cmd.add_option("--particles", f.particles, "particles (M)")
      ->check(whole_number<std::uint32_t>())
      ->check(CLI::Range(1U, 100'000'000U))
      ->capture_default_str();
  cmd.add_option("--association", o.association,
                 "data association: known (ids from the source), ml (maximum likelihood, "
                 "eq. 64), das (sampling, eq. 65), mixed (the ids given, detections without "
                 "one discarded) or auto (the source's choice, else known when every detection "
                 "has an id and ml otherwise)")
      ->check(CLI::IsMember(
          std::vector<std::string>(std::begin(kAssociationModes), std::end(kAssociationModes))))
      ->capture_default_str();
  add_association_options(cmd, o, w);
  add_execution_options(cmd, o, w);
  cmd.add_option("--sigma-range", w.sigma_range,
                 "filter range noise, m (default: the source's; the simulator keeps its own)")
      ->check(positive_number());
  cmd.add_option("--sigma-bearing", w.sigma_bearing,
                 "filter bearing noise, rad (default: the source's)")
      ->check(positive_number());
  cmd.add_option("--error-correlation", o.filter.error_correlation,
                 "fastslam2: lag-1 correlation of a landmark's measurement errors from scan to "
                 "scan, in [0, 1); the association and the weights use the sensor noise x (1 + "
                 "rho) / (1 - rho), the proposal and the map the noise itself "
                 "(tools/scripts/innovation_correlation.py estimates it from a --stream file; "
                 "default: the source's, else 0)")
      ->check(number_in(0.0, 0.999));
  cmd.add_option("--sigma-u0", w.sigma_control0,
                 "filter noise of the first control component (speed m/s for the cars, v for the "
                 "unicycle, the v increment without odometry; default: the source's)")
      ->check(non_negative_number());
  cmd.add_option("--sigma-u1", w.sigma_control1,
                 "filter noise of the second control component (steering rad, omega, the omega "
                 "increment; default: the source's)")
      ->check(non_negative_number());
  cmd.add_option("--max-range", w.max_range,
                 "the filter's sensor range, m: beyond it no landmark is expected to be seen "
                 "(default: the source's)")
      ->check(positive_number());
  cmd.add_option("--field-of-view-deg", w.field_of_view_deg,
                 "the filter's sensor field of view, degrees centred ahead (default: the "
                 "source's)")
      ->check(number_in(0.001, 360.0));
  cmd.add_option("--initial-heading-deg", w.initial_heading_deg,
                 "start heading, degrees (default: the source's; victoria-park fits it to GPS)")
      ->check(finite_number());
  add_victoria_park_options(cmd, o, w);
  add_utias_options(cmd, o);
  add_output_options(cmd, o, w);
}

void add_convert_options(CLI::App& cmd, RunOptions& o, RunWords& w) {
  o.source = "sim";
  cmd.add_option("--source", o.source, "what to convert: a simulated world or a data set")
      ->check(CLI::IsMember(source_names()))
      ->capture_default_str();
  cmd.add_option("--data", o.data,
                 "a recorded source's file or directory, e.g. ../shared/data/victoria_park")
      ->check(CLI::ExistingPath);
  add_world_options(cmd, o, w);
  cmd.add_option("--seed", o.filter.seed, "random seed of the simulation")
      ->check(whole_number<std::uint64_t>())
      ->capture_default_str();
  add_victoria_park_options(cmd, o, w);
  add_utias_options(cmd, o);
  cmd.add_option("--out", o.out, "the log file to write (docs/log-format.md); required");
  add_config_option(cmd, w);
}

unsigned max_startable_threads() {
  const std::uint64_t cores = std::max(1U, std::thread::hardware_concurrency());
  std::uint64_t limit = kMaxThreadsPerCore * cores;
  rlimit space{};
  if (::getrlimit(RLIMIT_AS, &space) == 0 && space.rlim_cur != RLIM_INFINITY) {
    // Half the address space for stacks; the map and the heap need the rest.
    limit = std::min<std::uint64_t>(limit, space.rlim_cur / 2 / kThreadStackBytes);
  }
  rlimit processes{};
  if (::getrlimit(RLIMIT_NPROC, &processes) == 0 && processes.rlim_cur != RLIM_INFINITY) {
    limit = std::min<std::uint64_t>(limit, processes.rlim_cur);
  }
  return static_cast<unsigned>(std::max<std::uint64_t>(1, limit));
}

std::string threads_refusal(unsigned threads) {
  return "--threads " + std::to_string(threads) + ": more than this process can usefully start (" +
         std::to_string(max_startable_threads()) + ": " + std::to_string(kMaxThreadsPerCore) +
         " per core of " + std::to_string(std::max(1U, std::thread::hardware_concurrency())) +
         ", within the address-space and process limits); give at most that, or 0 for one per "
         "core";
}

void apply_json_config(CLI::App& cmd, const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open for reading");
  nlohmann::json config;
  // A key given twice would otherwise resolve silently to its last value.
  std::set<std::string> keys;
  const auto refuse_repeats = [&](int depth, nlohmann::json::parse_event_t event,
                                  nlohmann::json& parsed) {
    if (depth == 1 && event == nlohmann::json::parse_event_t::key &&
        !keys.insert(parsed.get<std::string>()).second) {
      throw std::runtime_error(path + ": key '" + clip(parsed.get<std::string>()) +
                               "' is repeated: give each option once");
    }
    return true;
  };
  try {
    config = nlohmann::json::parse(in, refuse_repeats);
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(path + ": not valid JSON: " + e.what());
  }
  // The parser takes a NUL byte for the end of the text and stops there, so anything after
  // one would go unread: the text must end where the object does.
  if (!in.eof()) {
    throw std::runtime_error(path + ": byte " + std::to_string(static_cast<long long>(in.tellg())) +
                             ": a NUL byte after the JSON object: not a JSON text");
  }
  apply_json_config(cmd, config, path);
}

void apply_json_config(CLI::App& cmd, const nlohmann::json& config, const std::string& where) {
  if (!config.is_object()) throw std::runtime_error(where + ": expected one JSON object");
  // The options given on the command line, and those they exclude (--plot and --no-plot):
  // the file's values for them are passed over.
  std::set<const CLI::Option*> given;
  for (const CLI::Option* option : std::as_const(cmd).get_options()) {
    if (option->count() == 0) continue;
    given.insert(option);
    for (const CLI::Option* other : option->get_excludes()) given.insert(other);
  }
  for (const auto& item : config.items()) {
    const std::string& key = item.key();
    const nlohmann::json& value = item.value();
    auto fail = [&](const std::string& what) {
      throw std::runtime_error(where + ": key '" + clip(key) + "': " + what);
    };
    CLI::Option* option = key == "config" ? nullptr : cmd.get_option_no_throw("--" + key);
    if (option == nullptr) fail("unknown option (keys are the long flag names without '--')");
    if (given.contains(option)) continue;  // the command line wins
    if (value.is_null()) continue;         // unset, as metrics.json's "options" writes "none"
    std::string text;
    if (value.is_string()) {
      text = value.get<std::string>();
    } else if (value.is_boolean()) {
      text = value.get<bool>() ? "true" : "false";
    } else if (value.is_number()) {
      text = value.dump();
    } else {
      fail("value must be a number, a string or a boolean");
    }
    try {
      if (option->get_expected_min() == 0) {  // a flag: as CLI11's own config files do
        text = option->get_flag_value(key, text);
      }
      option->add_result(text);
      option->run_callback();
    } catch (const CLI::Error& e) {
      fail(e.what());
    }
  }
}

void finish_run_options(const CLI::App& cmd, const RunWords& w, RunOptions& o) {
  const bool csv = !o.landmarks_csv.empty();
  o.config = w.config;
  const CLI::Option* out = cmd.get_option_no_throw("--out");
  if (out != nullptr && out->count() > 0 && o.out.empty()) {
    throw std::invalid_argument(
        "--out \"\" names no path: give a directory (a file for convert), or leave --out out");
  }
  if (o.filter.threads > max_startable_threads()) {
    throw std::invalid_argument(threads_refusal(o.filter.threads));
  }
  o.sim.loops = w.loops > 0 ? w.loops : (csv ? 2 : 1);
  o.filter.algorithm = engine::parse_enum<Algorithm>(w.algorithm);
  o.filter.resample.when = engine::parse_enum<ResamplePolicy::When>(w.resample);
  o.filter.resample.scheme = engine::parse_enum<ResampleScheme>(w.scheme);
  o.filter.motion_draw = engine::parse_enum<engine::MotionDraw>(w.motion_draw);
  auto given = [&](const char* name) {
    const CLI::Option* option = cmd.get_option_no_throw(name);
    return option != nullptr && option->count() > 0;
  };
  if (given("--spacing")) o.spacing = w.spacing;
  if (given("--scan-period")) o.scan_period = w.scan_period;
  if (given("--sigma-range")) o.model.sigma_range = w.sigma_range;
  if (given("--sigma-bearing")) o.model.sigma_bearing = w.sigma_bearing;
  if (given("--sigma-u0")) o.model.sigma_control0 = w.sigma_control0;
  if (given("--sigma-u1")) o.model.sigma_control1 = w.sigma_control1;
  if (given("--max-range")) o.model.max_range = w.max_range;
  if (given("--filter-clutter-density")) o.model.clutter_density = w.clutter_density;
  if (given("--filter-detection-probability"))
    o.model.detection_probability = w.detection_probability;
  if (given("--field-of-view-deg"))
    o.model.field_of_view = w.field_of_view_deg * std::numbers::pi / 180;
  if (given("--max-steps")) o.max_steps = w.max_steps;
  if (given("--seeds")) {
    o.seeds = parse_seeds(w.seeds);
    if (!o.stream.empty()) {
      throw std::invalid_argument("--stream writes the scans of one run; drop it or --seeds");
    }
    if (o.data == "-") {
      throw std::invalid_argument(
          "--data - (standard input) can be read once; --seeds needs a file it can read again");
    }
  }
  if (!o.seeds.empty() && (!o.checkpoint.empty() || !o.resume.empty())) {
    throw std::invalid_argument(
        "--checkpoint and --resume are for one run; a sweep's seeds are separate runs: rerun "
        "the seeds that did not finish");
  }
  if (o.data == "-" && (!o.checkpoint.empty() || !o.resume.empty())) {
    throw std::invalid_argument(
        "--data - (standard input) can be read once; --checkpoint and --resume need a file "
        "that can be read again");
  }
  if (cmd.get_option_no_throw("--plot") != nullptr) {
    // Both can come from one config file (or the Python module's arguments).
    if (w.no_plot && given("--plot") && w.plot != "none") {
      throw std::invalid_argument("--no-plot and --plot " + w.plot + " contradict: give one");
    }
    o.plot = w.no_plot ? "none" : w.plot;
  }
  if (given("--match-radius")) o.match_radius = w.match_radius;
  if (given("--rpe-delta")) o.rpe_delta = w.rpe_delta;
  if (given("--max-seconds")) o.max_seconds = w.max_seconds;
  for (const SourceEntry& source : sources()) {
    if (source.name == o.source) apply_filter_defaults(source.defaults, given, o);
  }
  if (given("--vp-min-bearing-deg")) {
    o.victoria_park.gate.min_bearing = w.vp_min_bearing_deg * std::numbers::pi / 180;
  }
  if (given("--vp-max-bearing-deg")) {
    o.victoria_park.gate.max_bearing = w.vp_max_bearing_deg * std::numbers::pi / 180;
  }
  if (given("--vp-laser-yaw-deg")) {
    o.victoria_park.laser_yaw = w.vp_laser_yaw_deg * std::numbers::pi / 180;
  }
  if (given("--initial-heading-deg")) {
    o.initial_heading = w.initial_heading_deg * std::numbers::pi / 180;
  }
}

namespace {

// Association, existence and the map's scoring (ml, das, ekf).
void add_association_options(CLI::App& cmd, RunOptions& o, RunWords& w) {
  engine::FilterConfig& f = o.filter;
  cmd.add_option("--log-p0", f.log_new_landmark,
                 "ln p0, the log-likelihood of a new landmark (ml, das)")
      ->check(finite_number())
      ->capture_default_str();
  cmd.add_option("--gate", f.gating.gate,
                 "squared Mahalanobis gate for association candidates (ml, das)")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_flag("!--no-negative-information", f.existence.negative_information,
               "never remove landmarks that were in view and not seen (ml, das)");
  cmd.add_option("--existence-missed", f.existence.missed,
                 "log-odds a landmark loses when in view and not seen (ml, das)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--existence-confirm-at", f.existence.confirm_at,
                 "log-odds from which a landmark is in the reported map; below, it is "
                 "provisional (ml, das)")
      ->check(finite_number())
      ->capture_default_str();
  cmd.add_option("--existence-range-margin", f.existence.range_margin,
                 "metres inside the sensor range where a missed landmark counts (ml, das)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--loop-closure-reach", f.loop_closure.reach,
                 "metres: the largest drift a loop closes over when a particle matches its "
                 "recent landmarks to its old ones; 0: no loop closure (ml, das)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--loop-closure-separation", f.loop_closure.separation,
                 "metres: twins this close must be each other's only confirmed neighbour within "
                 "it, farther ones within the reach (ml, das)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--loop-closure-max-turn", f.loop_closure.max_turn,
                 "radians: the largest heading drift a loop closes over (ml, das)")
      ->check(number_in(1e-9, std::numbers::pi))
      ->capture_default_str();
  cmd.add_option("--loop-closure-merge-gate", f.loop_closure.merge_gate,
                 "squared Mahalanobis distance (their two covariances) within which two confirmed "
                 "landmarks that are candidates of one observation merge; 0: never (ml, das)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--loop-closure-min-age", f.loop_closure.min_age,
                 "steps (controls and scans) without an association that make a landmark old "
                 "for loop closure (ml, das)")
      ->capture_default_str();
  cmd.add_option("--clutter", o.sim.clutter_rate,
                 "simulated false alarms per scan (Poisson mean; ml, das)")
      ->check(number_in(0.0, 1000.0))
      ->capture_default_str();
  cmd.add_option("--detection-probability", o.sim.detection_probability,
                 "probability that the simulated sensor detects a landmark in view")
      ->check(number_in(0.0, 1.0))
      ->capture_default_str();
  cmd.add_option("--filter-clutter-density", w.clutter_density,
                 "false alarms per m² per scan the association expects: 'no landmark' scores "
                 "ln((p0 + density * range) / P_D) (ml, das; default: the simulator's --clutter "
                 "over its footprint's area, else 0, which leaves ln p0 as it is)")
      ->check(non_negative_number());
  cmd.add_option("--filter-detection-probability", w.detection_probability,
                 "P_D, the probability the association expects a landmark in view to be "
                 "detected (ml, das; default: the simulator's --detection-probability, else 1)")
      ->check(number_in(1e-9, 1.0));
  cmd.add_option("--ekf-gate-accept", f.ekf.gate_accept,
                 "ekf with ml: associate when the squared Mahalanobis distance is below this")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_option("--ekf-gate-new", f.ekf.gate_new,
                 "ekf with ml: a new landmark when every squared Mahalanobis distance exceeds it")
      ->check(positive_number())
      ->capture_default_str();
  cmd.add_flag("--ekf-jcbb", f.ekf.joint_compatibility,
               "ekf with ml: joint compatibility branch and bound instead of greedy nearest");
  cmd.add_option("--match-radius", w.match_radius,
                 "metres within which estimated and true landmarks are paired (precision, "
                 "recall, the landmark RMSE of ml and das) and GOSPA's cutoff (default: the "
                 "source's, 5; half the spacing of a procedural world)")
      ->check(positive_number());
  cmd.add_option("--rpe-delta", w.rpe_delta,
                 "metres of true path between the poses of a relative pose error pair (default: "
                 "the source's, 10)")
      ->check(positive_number());
}

// Seed, threads and resampling.
void add_execution_options(CLI::App& cmd, RunOptions& o, RunWords& w) {
  engine::FilterConfig& f = o.filter;
  cmd.add_option("--seed", f.seed, "random seed (the whole run is a function of it)")
      ->check(whole_number<std::uint64_t>())
      ->capture_default_str();
  cmd.add_option("--seeds", w.seeds,
                 "run once per seed (e.g. 1-10 or 1,3,7-9), each into OUT/seed-S, and "
                 "summarise the metrics over them in OUT/sweep.json and sweep.csv");
  cmd.add_option("--threads", f.threads,
                 "worker threads (0: all cores; at most 16 per core, and what the address-space "
                 "limit leaves room for)")
      ->check(whole_number<unsigned>())
      ->check(CLI::Range(0U, 4096U))
      ->capture_default_str();
  cmd.add_option("--grain", f.grain, "particles per parallel task")
      ->check(whole_number<std::size_t>())
      ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 30))
      ->capture_default_str();
  cmd.add_option("--split-seconds", f.split_seconds,
                 "a pass whose previous one took longer is split across the threads whatever "
                 "--grain (0: always)")
      ->check(non_negative_number())
      ->capture_default_str();
  cmd.add_option("--resample", w.resample, "when to resample: every (scan) or neff")
      ->check(CLI::IsMember(engine::enum_names<ResamplePolicy::When>()))
      ->capture_default_str();
  cmd.add_option("--neff-fraction", f.resample.ess_fraction,
                 "with --resample neff: resample when N_eff < fraction x M")
      ->check(number_in(0.0, 1.0))
      ->capture_default_str();
  cmd.add_option("--resample-scheme", w.scheme, "how to draw the ancestors")
      ->check(CLI::IsMember(engine::enum_names<ResampleScheme>()))
      ->capture_default_str();
}

// What a run writes: the output directory, the trace, the progress bar, the picture.
void add_output_options(CLI::App& cmd, RunOptions& o, RunWords& w) {
  cmd.add_option("--out", o.out,
                 "directory for metrics.json, trajectory.csv/.tum, landmarks.csv and the truth");
  cmd.add_option("--trace", o.trace,
                 "CSV file of errors over time, one row per --trace-every scans (t, pose error, "
                 "landmark RMSE of the seen landmarks, landmarks in the map, the particle set's "
                 "N_eff, distinct survivors, spread and the truth's distance in spreads)");
  cmd.add_option("--stream", o.stream,
                 "write a JSON line per scan as it is processed (time, pose, covariance, "
                 "landmark count, the scan's associations, latency) to FILE, or - for standard "
                 "output (the summary then goes to standard error)");
  cmd.add_option("--max-steps", w.max_steps,
                 "stop after this many controls and report what the run has (default: none)")
      ->check(whole_number<std::uint64_t>())
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 62));
  cmd.add_option("--max-seconds", w.max_seconds,
                 "stop after this much wall time and report what the run has (default: none)")
      ->check(positive_number());
  cmd.add_option("--max-memory", o.max_memory,
                 "refuse the run up front when its filter is estimated to need more memory than "
                 "this: bytes, or 512M, 4G, ... (default 0: what the machine has available)")
      ->transform(CLI::Validator([](std::string& text) { return memory_size_check(text); }, "SIZE",
                                 "memory size"));
  cmd.add_option("--trace-every", o.trace_every, "scans between --trace rows")
      ->check(whole_number<std::uint64_t>())
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 40))
      ->capture_default_str();
  cmd.add_option("--checkpoint", o.checkpoint,
                 "write the run's whole state to FILE (atomically) every --checkpoint-every "
                 "scans and when a signal or --max-seconds stops it, for --resume");
  cmd.add_option("--checkpoint-every", o.checkpoint_every, "scans between --checkpoint writes")
      ->check(whole_number<std::uint64_t>())
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 40))
      ->capture_default_str();
  cmd.add_option("--resume", o.resume,
                 "go on from a --checkpoint FILE made with the same options and inputs; the "
                 "outputs are those of an uninterrupted run");
  cmd.add_flag("!--no-progress", o.progress, "no progress bar (it shows only on a terminal)");
  o.plot_script = default_plot_script();
  CLI::Option* plot =
      cmd.add_option("--plot", w.plot,
                     "with --out, the map picture: svg (map.svg, drawn natively), png (map.png, "
                     "by tools/scripts/plot_run.py or $FASTSLAM_PLOT_SCRIPT with matplotlib, "
                     "about a second) or none")
          ->check(CLI::IsMember(
              std::vector<std::string>(std::begin(kPlotFormats), std::end(kPlotFormats))))
          ->capture_default_str();
  cmd.add_flag("--no-plot", w.no_plot, "with --out, no map picture (--plot none)")->excludes(plot);
  add_config_option(cmd, w);
}

}  // namespace

}  // namespace fastslam::tools
