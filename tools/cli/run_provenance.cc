#include "tools/cli/run_provenance.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>
#include <oneapi/tbb/info.h>

#include "engine/enum_names.h"
#include "tools/datasets/sim_source.h"
#include "tools/datasets/utias.h"
#include "tools/io/sha256.h"

namespace fastslam::tools {
namespace {

constexpr double kDegrees = 180 / std::numbers::pi;

template <class T>
nlohmann::json or_null(const std::optional<T>& value) {
  return value ? nlohmann::json(*value) : nlohmann::json(nullptr);
}

// An unset path (empty) as null: "" is no file, and --config refuses it.
nlohmann::json path_or_null(const std::string& path) {
  return path.empty() ? nlohmann::json(nullptr) : nlohmann::json(path);
}

// One input: hashed when it is a regular file; a pipe or a device would be consumed (or never
// end: /dev/zero), so it is named and left to the run.
nlohmann::json input_file(const std::string& option, const std::string& path) {
  nlohmann::json entry = {{"option", option}, {"path", path}};
  if (path == "-") {
    entry["sha256"] = nullptr;
    entry["not_hashed"] = "standard input is read once, by the run";
    return entry;
  }
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    entry["sha256"] = nullptr;
    entry["not_hashed"] = "not a regular file (a pipe or a device is read once, by the run)";
    return entry;
  }
  entry["bytes"] = std::filesystem::file_size(path);
  entry["sha256"] = sha256_file(path);
  return entry;
}

}  // namespace

nlohmann::json resolved_options_json(const RunOptions& o, const engine::FilterConfig& config,
                                     const std::string& association) {
  const engine::FilterConfig& f = o.filter;
  const SimWorldOptions world = source_options(o).sim;
  const VictoriaParkGate& gate = o.victoria_park.gate;
  nlohmann::json j = {
      // Source and world.
      {"source", o.source},
      {"data", path_or_null(o.data)},
      {"landmarks-csv", path_or_null(o.landmarks_csv)},
      {"waypoints-csv", path_or_null(o.waypoints_csv)},
      {"world", o.world},
      {"landmarks", o.landmarks},
      {"spacing",
       o.spacing.value_or(o.world == "grid" ? kDefaultGridSpacing : kDefaultLoopSpacing)},
      {"loop-length", o.loop_length},
      {"scan-period", resolved_sim_config(world).dt_observe},
      {"sim-sigma-speed", o.sim.sigma_v},
      {"sim-sigma-steer", o.sim.sigma_steer},
      {"sim-sigma-range", o.sim.sigma_range},
      {"sim-sigma-bearing", o.sim.sigma_bearing},
      {"loops", o.sim.loops},
      {"at-waypoint", o.sim.at_waypoint},
      {"clutter", o.sim.clutter_rate},
      {"detection-probability", o.sim.detection_probability},
      // Filter.
      {"algorithm", engine::enum_name(config.algorithm)},
      {"motion", o.motion},
      {"motion-draw", engine::enum_name(engine::resolved_motion_draw(config))},
      {"particles", config.particles},
      {"association", association},
      {"log-p0", config.log_new_landmark},
      {"gate", config.gating.gate},
      {"no-negative-information", !config.existence.negative_information},
      {"existence-missed", config.existence.missed},
      {"existence-confirm-at", config.existence.confirm_at},
      {"existence-range-margin", config.existence.range_margin},
      {"loop-closure-reach", config.loop_closure.reach},
      {"loop-closure-min-age", config.loop_closure.min_age},
      {"loop-closure-separation", config.loop_closure.separation},
      {"loop-closure-max-turn", config.loop_closure.max_turn},
      {"loop-closure-merge-gate", config.loop_closure.merge_gate},
      {"ekf-gate-accept", config.ekf.gate_accept},
      {"ekf-gate-new", config.ekf.gate_new},
      {"ekf-jcbb", config.ekf.joint_compatibility},
      {"match-radius", or_null(o.match_radius)},
      {"rpe-delta", or_null(o.rpe_delta)},
      // The models, the source's unless overridden.
      {"sigma-range", config.sensor.sigma_range},
      {"sigma-bearing", config.sensor.sigma_bearing},
      {"error-correlation", config.error_correlation},
      {"sigma-u0", config.motion.sigma_control[0]},
      {"sigma-u1", config.motion.sigma_control[1]},
      {"max-range", config.sensor.max_range},
      {"field-of-view-deg", config.sensor.field_of_view * kDegrees},
      {"filter-clutter-density", config.detection.clutter_density},
      {"filter-detection-probability", config.detection.probability},
      {"initial-heading-deg", config.initial_pose[2] * kDegrees},
      // Execution.
      {"seed", config.seed},
      {"seeds", nullptr},
      {"threads", f.threads > 0 ? f.threads : unsigned(tbb::info::default_concurrency())},
      {"grain", config.grain},
      {"split-seconds", config.split_seconds},
      {"resample", engine::enum_name(config.resample.when)},
      {"neff-fraction", config.resample.ess_fraction},
      {"resample-scheme", engine::enum_name(config.resample.scheme)},
      // Victoria Park and UTIAS readers.
      {"heading-fit-seconds", o.victoria_park.heading_fit_seconds},
      {"split-controls", o.victoria_park.split_controls_at_scans},
      {"vp-min-range", gate.min_range},
      {"vp-max-range", gate.max_range},
      {"vp-min-bearing-deg", gate.min_bearing * kDegrees},
      {"vp-max-bearing-deg", gate.max_bearing * kDegrees},
      {"vp-laser-yaw-deg", o.victoria_park.laser_yaw * kDegrees},
      {"vp-laser-x", o.victoria_park.geometry.a},
      {"vp-laser-y", o.victoria_park.geometry.b},
      {"vp-max-diameter",
       std::isfinite(gate.max_diameter) ? nlohmann::json(gate.max_diameter) : nullptr},
      {"robot", o.utias.robot},
      {"utias-odometry-lead", o.source == "utias" ? nlohmann::json(utias_odometry_lead(o.utias))
                                                  : nlohmann::json(or_null(o.utias.odometry_lead))},
      // Outputs and budgets.
      {"out", path_or_null(o.out)},
      {"trace", path_or_null(o.trace)},
      {"trace-every", o.trace_every},
      {"stream", path_or_null(o.stream)},
      {"max-steps", or_null(o.max_steps)},
      {"max-seconds", or_null(o.max_seconds)},
      {"checkpoint", path_or_null(o.checkpoint)},
      {"checkpoint-every", o.checkpoint_every},
      {"max-memory", o.max_memory},
      {"no-progress", !o.progress},
      {"plot", o.plot},
      {"no-plot", o.plot == "none"},
  };
  if (!o.seeds.empty()) j["seeds"] = o.seeds;
  return j;
}

nlohmann::json input_files_json(const RunOptions& o) {
  nlohmann::json files = nlohmann::json::array();
  if (!o.config.empty()) files.push_back(input_file("--config", o.config));
  if (o.source == "sim") {
    if (!o.landmarks_csv.empty()) files.push_back(input_file("--landmarks-csv", o.landmarks_csv));
    if (!o.waypoints_csv.empty()) files.push_back(input_file("--waypoints-csv", o.waypoints_csv));
  } else if (!o.data.empty()) {
    std::error_code error;
    if (std::filesystem::is_directory(o.data, error)) {
      std::vector<std::string> paths;
      for (const auto& entry : std::filesystem::recursive_directory_iterator(o.data)) {
        if (entry.is_regular_file()) paths.push_back(entry.path().string());
      }
      std::sort(paths.begin(), paths.end());
      for (const std::string& path : paths) files.push_back(input_file("--data", path));
    } else {
      files.push_back(input_file("--data", o.data));
    }
  }
  return files;
}

}  // namespace fastslam::tools
