#include "tools/cli/run_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <numbers>
#include <optional>
#include <span>
#include <stdexcept>
#include <sys/resource.h>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>
#include <oneapi/tbb/info.h>

#include "engine/angles.h"
#include "engine/ekf_slam.h"
#include "engine/enum_names.h"
#include "engine/filter.h"
#include "tools/cli/progress.h"
#include "tools/cli/run_output.h"
#include "tools/eval/map_evaluation.h"
#include "tools/eval/trajectory_errors.h"
#include "tools/io/log_format.h"
#include "tools/io/tum.h"
#include "tools/sim/world.h"

namespace fastslam::tools {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::int64_t peak_rss_bytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<std::int64_t>(usage.ru_maxrss) * 1024;
}

// The true landmarks a run observed (by the ids its detections carry) and a kd-tree over them
// for scoring maps whose ids mean nothing.
class TruthTracker {
 public:
  explicit TruthTracker(std::span<const TruthLandmark> landmarks)
      : landmarks_(landmarks),
        observed_flags_(new bool[landmarks.size()]()),
        points_(positions(landmarks)),
        index_(points_) {
    for (std::size_t i = 0; i < landmarks.size(); ++i) slot_[landmarks[i].id] = i;
  }
  void see(std::span<const engine::Observation> scan) {
    for (const engine::Observation& z : scan) {
      if (z.id < 0) continue;
      const auto found = slot_.find(static_cast<std::uint64_t>(z.id));
      if (found != slot_.end()) observed_flags_[found->second] = true;
    }
  }
  std::span<const bool> observed() const { return {observed_flags_.get(), landmarks_.size()}; }
  std::size_t observed_count() const {
    return static_cast<std::size_t>(std::count(observed().begin(), observed().end(), true));
  }
  // The map paired with the truth within `match_radius` (tools/eval/map_evaluation.h).
  MapScore score(std::span<const engine::MapLandmark> map, double match_radius) const {
    return score_map(map, points_, index_, observed(), match_radius);
  }
  // Known association: each landmark against its own; else as score().
  double rmse(std::span<const engine::MapLandmark> map, bool known, double match_radius) const {
    return known ? landmark_rmse_by_id(map, landmarks_) : score(map, match_radius).rmse_m;
  }

 private:
  static std::vector<Point> positions(std::span<const TruthLandmark> landmarks) {
    std::vector<Point> out(landmarks.size());
    for (std::size_t i = 0; i < landmarks.size(); ++i) out[i] = {landmarks[i].x, landmarks[i].y};
    return out;
  }

  std::span<const TruthLandmark> landmarks_;
  std::unordered_map<std::uint64_t, std::size_t> slot_;
  std::unique_ptr<bool[]> observed_flags_;
  std::vector<Point> points_;
  TruthIndex index_;
};

// What one run recorded, whichever the filter.
struct RunRecord {
  std::vector<double> control_times;
  std::vector<StampedPose> truth;
  std::vector<StampedPose> gps;
  engine::Estimate estimate;
  std::vector<engine::TrajectoryPoint> points;
  engine::FilterStatistics stats;
  double source_seconds = 0.0;
  double filter_seconds = 0.0;  // the trace's estimates excluded
};

// What the loop reads from and reports to besides the filter.
struct RunLoop {
  const RunOptions& options;
  Source& source;
  TruthTracker& truth;
  bool known;
  TraceWriter* trace;  // null: no trace
  ProgressBar& progress;
  ProgressState& state;
};

template <class F>
void observe_state(F& filter, ProgressState& state) {
  const engine::FilterStatistics st = filter.statistics();
  state.done = st.controls;
  if constexpr (requires { filter.particles(); }) {
    state.landmarks = filter.particles().landmark_count(0);
  } else {
    state.landmarks = filter.estimate().map.size();
  }
  state.map_bytes = st.live_bytes;
}

template <class F>
void trace_row(F& filter, const RunLoop& loop, const RunRecord& r, double time) {
  const engine::Estimate now = filter.estimate();
  std::optional<double> pose_error;
  if (!r.truth.empty() && time - r.truth.back().time <= kMaxInterpolationGap) {
    pose_error =
        std::hypot(now.mean_pose[0] - r.truth.back().x, now.mean_pose[1] - r.truth.back().y);
  }
  std::optional<double> map_error;
  if (!loop.source.info().landmarks.empty()) {
    map_error = loop.truth.rmse(now.map, loop.known, loop.options.match_radius);
  }
  loop.trace->row(time, pose_error, map_error, now.map.size(), loop.truth.observed_count());
}

// One loop over the events of any source, the same for the FastSLAM `Filter` and the `EkfSlam`
// baseline (same methods).
template <class F>
void drive(F& filter, RunLoop& loop, RunRecord& r) {
  Event event;
  std::vector<engine::Observation> scan;
  for (;;) {
    const auto t0 = Clock::now();
    if (!loop.source.next(event, scan)) break;
    const auto t1 = Clock::now();
    double trace_seconds = 0.0;
    switch (event.kind) {
      case EventKind::kControl:
        filter.predict(event.control, event.dt);
        r.control_times.push_back(event.time);
        break;
      case EventKind::kScan:
        loop.truth.see(scan);
        filter.observe(scan);
        if (loop.trace != nullptr && loop.trace->due()) {
          const auto t_trace = Clock::now();
          trace_row(filter, loop, r, event.time);
          trace_seconds = seconds_since(t_trace);
        }
        if (loop.progress.due()) {
          observe_state(filter, loop.state);
          loop.progress.draw(loop.state);
        }
        break;
      case EventKind::kTruthPose:
        r.truth.push_back({event.time, event.x, event.y, event.theta});
        break;
      case EventKind::kGps:
        r.gps.push_back({event.time, event.x, event.y, 0.0});
        break;
    }
    r.source_seconds += std::chrono::duration<double>(t1 - t0).count();
    r.filter_seconds += seconds_since(t1);
    r.filter_seconds -= trace_seconds;
  }
  const auto t_end = Clock::now();
  r.estimate = filter.estimate();
  r.points = filter.take_trajectory();
  r.filter_seconds += seconds_since(t_end);
  r.stats = filter.statistics();
  if (loop.trace != nullptr) loop.trace->close();
  if (loop.progress.enabled()) {
    observe_state(filter, loop.state);
    loop.state.total = loop.state.done;  // the expected total was an estimate; the run is done
    loop.progress.finish(loop.state);
  }
}

// The estimated trajectory at the source's reported point: the start, then the pose after
// every control.
std::vector<StampedPose> reported_trajectory(const RunRecord& r, const LogHeader& h,
                                             const engine::SensorOffset& reported) {
  std::vector<StampedPose> trajectory;
  trajectory.reserve(r.points.size() + 1);
  trajectory.push_back({h.start_time, h.start_pose[0], h.start_pose[1], h.start_pose[2]});
  for (const engine::TrajectoryPoint& p : r.points) {
    const double c = std::cos(p.theta), sn = std::sin(p.theta);
    trajectory.push_back({r.control_times.at(p.control), p.x + reported.x * c - reported.y * sn,
                          p.y + reported.x * sn + reported.y * c, p.theta});
  }
  return trajectory;
}

struct RunScores {
  PositionErrors pose, fixes;
  AlignedErrors aligned;
  MapScore map;           // paired by distance (also counts spurious and missing landmarks)
  double map_rmse = 0.0;  // known association: by id; else map.rmse_m
  std::size_t observed = 0;
};

RunScores score_run(const RunRecord& r, std::span<const StampedPose> trajectory,
                    const TruthTracker& truth, const SourceInfo& info, bool known,
                    double match_radius) {
  RunScores s;
  s.pose = position_errors(trajectory, r.truth);
  s.fixes = position_errors(trajectory, r.gps);
  s.aligned = aligned_position_errors(trajectory, r.gps);
  if (!info.landmarks.empty()) s.map = truth.score(r.estimate.map, match_radius);
  s.map_rmse = known ? landmark_rmse_by_id(r.estimate.map, info.landmarks) : s.map.rmse_m;
  s.observed = truth.observed_count();
  return s;
}

constexpr double kDegrees = 180 / std::numbers::pi;

nlohmann::json metrics_json(const RunOptions& options, const SourceInfo& info,
                            const engine::FilterConfig& config, std::uint32_t particles,
                            const RunRecord& r, const RunScores& s) {
  const engine::FilterStatistics& st = r.stats;
  nlohmann::json m = {
      {"source", options.source},
      {"world", info.name},
      {"motion", engine::to_string(config.motion.kind)},
      {"algorithm", engine::to_string(config.algorithm)},
      {"particles", particles},
      {"association", engine::to_string(config.association)},
      {"seed", config.seed},
      {"threads", config.threads > 0 ? config.threads : unsigned(tbb::info::default_concurrency())},
      {"steps", st.controls},
      {"scans", st.scans},
      {"observations", st.observations},
      {"true_landmarks", info.landmarks.size()},
      {"landmarks", r.estimate.map.size()},
      {"wall_seconds", r.filter_seconds},
      {"source_seconds", r.source_seconds},
      {"seconds_per_phase",
       {{"predict", st.predict_seconds},
        {"associate", st.associate_seconds},
        {"update", st.update_seconds},
        {"resample", st.resample_seconds}}},
      {"resamples", st.resamples},
      {"log_evidence", st.log_evidence},
      {"live_tree_nodes", st.live_nodes},
      {"live_tree_bytes", st.live_bytes},
      {"peak_rss_bytes", peak_rss_bytes()},
  };
  if (info.simulated) m["simulator_seconds"] = r.source_seconds;
  for (const auto& [key, value] : info.metrics) m[key] = value;
  if (!r.truth.empty()) {
    m["pose_rmse_m"] = s.pose.rmse;
    m["final_position_error_m"] = std::hypot(r.estimate.mean_pose[0] - r.truth.back().x,
                                             r.estimate.mean_pose[1] - r.truth.back().y);
  }
  if (!info.landmarks.empty()) {
    m["landmark_rmse_m"] = s.map_rmse;
    m["observed_landmarks"] = s.observed;
    m["match_radius_m"] = options.match_radius;
    m["matched_landmarks"] = s.map.matched;
    m["spurious_landmarks"] = s.map.spurious;
    m["missing_landmarks"] = s.map.missing;
  }
  if (config.association != engine::Association::kKnown) {
    m["landmarks_created"] = st.landmarks_created;
    m["landmarks_removed"] = st.landmarks_removed;
  }
  if (!r.gps.empty()) {
    m["gps_rmse_m"] = s.fixes.rmse;
    m["final_gps_error_m"] = s.fixes.last;
    m["gps_fixes_used"] = s.fixes.used;
    m["gps_fixes_skipped"] = s.fixes.skipped;
    m["gps_rmse_aligned_m"] = s.aligned.rmse;
    m["gps_alignment_rotation_deg"] = s.aligned.rotation * kDegrees;
    m["initial_heading_deg"] = config.initial_pose[2] * kDegrees;
  }
  return m;
}

void print_summary(const RunOptions& options, const SourceInfo& info,
                   const engine::FilterConfig& config, std::uint32_t particles, const RunRecord& r,
                   const RunScores& s) {
  std::printf("%s, M = %u, %s association, seed %llu: %llu steps, %llu scans, %zu landmarks\n",
              std::string(engine::to_string(config.algorithm)).c_str(), particles,
              std::string(engine::to_string(config.association)).c_str(),
              static_cast<unsigned long long>(config.seed),
              static_cast<unsigned long long>(r.stats.controls),
              static_cast<unsigned long long>(r.stats.scans), r.estimate.map.size());
  std::printf(" ");
  if (!r.truth.empty()) std::printf(" pose RMSE %.3f m,", s.pose.rmse);
  if (!info.landmarks.empty()) std::printf(" landmark RMSE %.3f m,", s.map_rmse);
  if (!r.gps.empty()) {
    std::printf(
        " GPS RMSE %.3f m (%zu fixes, %zu skipped), at the end %.3f m, %.3f m after a "
        "rigid alignment (rotation %.2f deg),",
        s.fixes.rmse, s.fixes.used, s.fixes.skipped, s.fixes.last, s.aligned.rmse,
        s.aligned.rotation * kDegrees);
  }
  std::printf(" filter %.3f s (%s %.3f s)\n", r.filter_seconds,
              info.simulated ? "simulator" : "reading", r.source_seconds);
  if (!info.landmarks.empty()) {
    std::printf("  map: %zu matched within %.1f m, %zu spurious, %zu of %zu observed missing\n",
                s.map.matched, options.match_radius, s.map.spurious, s.map.missing, s.observed);
  }
}

// Writes one event of a source to a log.
void write_event(LogWriter& writer, const Event& e, std::span<const engine::Observation> scan) {
  switch (e.kind) {
    case EventKind::kControl:
      writer.control(e.time, e.dt, e.control);
      break;
    case EventKind::kScan:
      writer.scan(e.time, scan);
      break;
    case EventKind::kTruthPose:
      writer.truth_pose(e.time, e.x, e.y, e.theta);
      break;
    case EventKind::kGps:
      writer.gps(e.time, e.x, e.y);
      break;
  }
}

}  // namespace

SourceOptions source_options(const RunOptions& o) {
  SourceOptions s;
  s.data = o.data;
  s.seed = o.filter.seed;
  s.clutter = o.filter.association != engine::Association::kKnown;
  s.sim.landmarks_csv = o.landmarks_csv;
  s.sim.waypoints_csv = o.waypoints_csv;
  s.sim.world = o.world;
  s.sim.landmarks = o.landmarks;
  s.sim.spacing = o.spacing;
  s.sim.scan_period = o.scan_period;
  s.sim.loop_length = o.loop_length;
  s.sim.config = o.sim;
  s.victoria_park = o.victoria_park;
  s.utias = o.utias;
  return s;
}

// Where the source's pose (the point its log and its GPS refer to) is relative to the point the
// filter tracks: zero, except without odometry on an Ackermann car (Victoria Park). There the
// log's state is the sensor's pose, (a, b) from the rear axle, and the sensor does not move
// along its heading when the car turns (its sideslip reaches ~40 deg in tight turns), which the
// Brownian model (eq. 81: x += v cos(theta) dt) assumes; the rear axle's centre does. So the
// filter tracks the axle, the sensor sits at (a, b) from it, and the trajectory is reported at
// the laser again.
std::vector<std::string> motion_choices() {
  std::vector<std::string> out = {"odometry"};
  for (const std::string& name : engine::enum_names<engine::MotionKind>()) {
    if (engine::without_odometry(engine::parse_enum<engine::MotionKind>(name))) out.push_back(name);
  }
  return out;
}

engine::MotionKind no_odometry_kind(const std::string& motion) {
  for (const engine::EnumName<engine::MotionKind>& n :
       engine::EnumNames<engine::MotionKind>::kNames) {
    if (n.name == motion && engine::without_odometry(n.value)) return n.value;
  }
  std::string choices;
  for (const std::string& c : motion_choices()) choices += (choices.empty() ? "" : ", ") + c;
  throw std::invalid_argument("--motion '" + motion + "' is not supported (" + choices + ")");
}

engine::SensorOffset tracked_point_offset(const RunOptions& o, const LogHeader& h) {
  if (o.motion == "odometry" || h.motion.kind != engine::MotionKind::kAckermann) return {};
  return {h.motion.geometry.a, h.motion.geometry.b, 0.0};
}

// The filter's configuration: the options' algorithm, particles, ...; the models of the
// source's header; the noise overrides.
engine::FilterConfig filter_config(const RunOptions& o, const LogHeader& h) {
  engine::FilterConfig config = o.filter;
  config.record_trajectory = true;
  config.motion = h.motion;
  if (o.motion != "odometry") {
    const engine::MotionKind kind = no_odometry_kind(o.motion);
    config.motion.kind = kind;
    config.motion.sigma_control[0] = o.no_odometry_sigma[0];
    config.motion.sigma_control[1] = kind == engine::MotionKind::kBrownianCurvature
                                         ? o.no_odometry_sigma_kappa
                                         : o.no_odometry_sigma[1];
  }
  config.sensor = h.sensor;
  if (o.noise.sigma_range) config.sensor.sigma_range = *o.noise.sigma_range;
  if (o.noise.sigma_bearing) config.sensor.sigma_bearing = *o.noise.sigma_bearing;
  if (o.noise.sigma_control0) config.motion.sigma_control[0] = *o.noise.sigma_control0;
  if (o.noise.sigma_control1) config.motion.sigma_control[1] = *o.noise.sigma_control1;
  for (int k = 0; k < 5; ++k) config.initial_pose[k] = k < 3 ? h.start_pose[k] : 0.0;
  if (o.initial_heading) config.initial_pose[2] = engine::wrap_angle(*o.initial_heading);
  const engine::SensorOffset axle = tracked_point_offset(o, h);
  if (axle.x != 0.0 || axle.y != 0.0) {
    // The filter tracks the rear axle; the source's pose sits at `axle` from it (same heading),
    // and the sensor at the header's offset from that.
    const engine::SensorOffset& header = h.sensor.offset;
    config.sensor.offset = {axle.x + header.x, axle.y + header.y, header.yaw};
    const double th = config.initial_pose[2];
    config.initial_pose[0] -= axle.x * std::cos(th) - axle.y * std::sin(th);
    config.initial_pose[1] -= axle.x * std::sin(th) + axle.y * std::cos(th);
  }
  return config;
}

std::string default_plot_script() {
  if (const char* env = std::getenv("FASTSLAM_PLOT_SCRIPT"); env != nullptr) return env;
  return FASTSLAM_PLOT_RUN_SCRIPT;
}

int run_simulation(const RunOptions& options) {
  const std::unique_ptr<Source> source = find_source(options.source).open(source_options(options));
  const SourceInfo& info = source->info();
  const engine::FilterConfig config = filter_config(options, info.header);
  const bool ekf = config.algorithm == engine::Algorithm::kEkf;
  const std::uint32_t particles = ekf ? 1 : config.particles;
  ProgressBar progress(options.progress);
  ProgressState state;
  state.total = static_cast<std::uint64_t>(info.expected_controls);
  state.particles = particles;
  TruthTracker truth(info.landmarks);
  std::unique_ptr<TraceWriter> trace;
  if (!options.trace.empty()) {
    trace = std::make_unique<TraceWriter>(options.trace, options.trace_every);
  }
  const bool known = config.association == engine::Association::kKnown;
  RunLoop loop{options, *source, truth, known, trace.get(), progress, state};
  RunRecord r;
  if (ekf) {
    engine::EkfSlam filter(config);
    drive(filter, loop, r);
  } else {
    engine::Filter filter(config);
    drive(filter, loop, r);
  }

  const std::vector<StampedPose> trajectory =
      reported_trajectory(r, info.header, tracked_point_offset(options, info.header));
  const RunScores scores = score_run(r, trajectory, truth, info, known, options.match_radius);
  const nlohmann::json metrics = metrics_json(options, info, config, particles, r, scores);
  print_summary(options, info, config, particles, r, scores);
  if (options.out.empty()) return 0;
  // The poses after the controls (the start is not a control's).
  write_run_files(options.out, {.metrics = &metrics,
                                .trajectory = std::span(trajectory).subspan(1),
                                .truth = r.truth,
                                .gps = r.gps,
                                .map = r.estimate.map,
                                .true_landmarks = info.landmarks});
  if (!options.plot_script.empty()) draw_map(options.plot_script, options.out);
  return 0;
}

int convert_to_log(const RunOptions& options) {
  if (options.out.empty()) throw std::invalid_argument("convert needs --out FILE.log");
  SourceOptions so = source_options(options);
  so.clutter = true;
  const std::unique_ptr<Source> source = find_source(options.source).open(so);
  const SourceInfo& info = source->info();
  if (!info.summary.empty()) std::printf("%s\n", info.summary.c_str());
  const std::string partial = options.out + ".partial";
  std::size_t events = 0;
  try {
    std::ofstream file(partial);
    if (!file) throw std::runtime_error(partial + ": cannot open for writing");
    LogWriter writer(file, info.header);
    for (const TruthLandmark& l : info.landmarks) writer.landmark(l);
    Event e;
    std::vector<engine::Observation> scan;
    while (source->next(e, scan)) {
      write_event(writer, e, scan);
      ++events;
    }
    file.close();
    if (!file) throw std::runtime_error(partial + ": write failed");
  } catch (...) {
    std::filesystem::remove(partial);
    throw;
  }
  std::filesystem::rename(partial, options.out);
  std::printf("wrote %zu events to %s\n", events, options.out.c_str());
  return 0;
}

}  // namespace fastslam::tools
