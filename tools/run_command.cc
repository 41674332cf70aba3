#include "tools/run_command.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <numbers>
#include <optional>
#include <span>
#include <spawn.h>
#include <stdexcept>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>
#include <oneapi/tbb/info.h>

#include "engine/angles.h"
#include "engine/ekf_slam.h"
#include "engine/filter.h"
#include "tools/log_format.h"
#include "tools/map_evaluation.h"
#include "tools/progress.h"
#include "tools/tum.h"
#include "tools/victoria_park.h"

namespace fastslam::tools {
namespace {

using Clock = std::chrono::steady_clock;

std::int64_t peak_rss_bytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<std::int64_t>(usage.ru_maxrss) * 1024;
}

bool csv_world(const RunOptions& o) { return !o.landmarks_csv.empty() || !o.waypoints_csv.empty(); }

// The simulator's configuration: the options' with the scan period resolved (RunOptions).
SimConfig sim_config(const RunOptions& o) {
  SimConfig sim = o.sim;
  if (o.scan_period) {
    sim.dt_observe = *o.scan_period;
  } else if (!csv_world(o) && o.world == "grid") {
    sim.dt_observe = kDefaultGridScanPeriod;
  }
  return sim;
}

World make_world(const RunOptions& o) {
  if (csv_world(o)) {
    if (o.landmarks_csv.empty() || o.waypoints_csv.empty()) {
      throw std::invalid_argument("--landmarks-csv and --waypoints-csv go together");
    }
    return read_world_csv(o.landmarks_csv, o.waypoints_csv);
  }
  if (o.world == "grid") {
    return make_grid_world(o.landmarks, o.spacing.value_or(kDefaultGridSpacing),
                           1.5 * o.sim.max_range, o.filter.seed);
  }
  if (o.world == "loop") {
    return make_loop_world(o.loop_length, o.spacing.value_or(kDefaultLoopSpacing), o.sim.max_range,
                           10.0, o.filter.seed);
  }
  throw std::invalid_argument("unknown --world '" + o.world + "' (grid or loop)");
}

// Where events come from. `next` returns the next event in time order (a scan's observations
// in `scan`), false at the end.
class EventSource {
 public:
  virtual ~EventSource() = default;
  virtual bool next(Event& event, std::vector<engine::Observation>& scan) = 0;
};

// Bailey's simulator, step by step: per control step a control, the truth pose after it, and
// the scan taken at its end, all stamped with the time at the end of the step.
class SimSource final : public EventSource {
 public:
  // `clutter`: pass false alarms on (id -1); known association sees true detections only.
  SimSource(const World& world, const SimConfig& config, std::uint64_t seed, bool clutter)
      : sim_(world, config, seed), clutter_(clutter) {}
  bool next(Event& e, std::vector<engine::Observation>& scan) override {
    e = Event{};
    e.time = t_;
    if (stage_ == 1) {
      stage_ = step_.has_scan ? 2 : 0;
      e.kind = EventKind::kTruthPose;
      e.x = step_.truth.x;
      e.y = step_.truth.y;
      e.theta = step_.truth.theta;
      return true;
    }
    if (stage_ == 2) {
      stage_ = 0;
      e.kind = EventKind::kScan;
      scan.clear();
      for (const SimObservation& z : step_.scan) {
        if (z.landmark == kClutter) {
          if (clutter_) scan.push_back({z.range, z.bearing, -1});
          continue;
        }
        scan.push_back({z.range, z.bearing, static_cast<std::int64_t>(z.landmark)});
      }
      e.count = static_cast<std::uint32_t>(scan.size());
      return true;
    }
    if (!sim_.next(step_)) return false;
    t_ += step_.dt;
    e.time = t_;
    e.kind = EventKind::kControl;
    e.dt = step_.dt;
    e.control = {step_.speed, step_.steer};
    stage_ = 1;
    return true;
  }

 private:
  Simulator sim_;
  bool clutter_;
  SimStep step_;
  double t_ = 0.0;
  int stage_ = 0;  // 0: next is a control; 1: the truth pose; 2: the scan
};

class LogSource final : public EventSource {
 public:
  explicit LogSource(const Log& log) : log_(log) {}
  bool next(Event& e, std::vector<engine::Observation>& scan) override {
    if (i_ == log_.events.size()) return false;
    e = log_.events[i_++];
    if (e.kind == EventKind::kScan) {
      const auto first = log_.observations.begin() + static_cast<std::ptrdiff_t>(e.first);
      scan.assign(first, first + e.count);
    }
    return true;
  }

 private:
  const Log& log_;
  std::size_t i_ = 0;
};

// The log header of a simulated world: Bailey's car and sensor with the simulator's noises.
LogHeader sim_header(const RunOptions& o, const World& world) {
  LogHeader h;
  h.motion.kind = engine::MotionKind::kBaileyCar;
  h.motion.wheelbase = o.sim.wheelbase;
  h.motion.sigma_control[0] = o.sim.sigma_v;
  h.motion.sigma_control[1] = o.sim.sigma_steer;
  h.sensor.sigma_range = o.sim.sigma_range;
  h.sensor.sigma_bearing = o.sim.sigma_bearing;
  h.sensor.max_range = o.sim.max_range;
  h.sensor.field_of_view = o.sim.field_of_view;
  h.start_time = 0.0;
  h.start_pose[0] = world.start_x;
  h.start_pose[1] = world.start_y;
  h.start_pose[2] = world.start_theta;
  return h;
}

std::vector<TruthLandmark> truth_landmarks(const World& world) {
  std::vector<TruthLandmark> out(world.landmarks.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    out[i] = {i, world.landmarks[i].x, world.landmarks[i].y};
  }
  return out;
}

// The estimate at time t: the last sample stamped exactly t, else the interpolation between
// the samples around t when they are at most kMaxInterpolationGap apart. REQUIRES: samples in
// time order.
std::optional<StampedPose> pose_at(const std::vector<StampedPose>& samples, double t) {
  auto it = std::upper_bound(samples.begin(), samples.end(), t,
                             [](double v, const StampedPose& p) { return v < p.time; });
  if (it != samples.begin() && std::prev(it)->time == t) return *std::prev(it);
  if (it == samples.begin() || it == samples.end()) return std::nullopt;
  const StampedPose& a = *std::prev(it);
  const StampedPose& b = *it;
  if (b.time - a.time > kMaxInterpolationGap) return std::nullopt;
  const double f = (t - a.time) / (b.time - a.time);
  return StampedPose{t, a.x + f * (b.x - a.x), a.y + f * (b.y - a.y),
                     engine::wrap_angle(a.theta + f * engine::wrap_angle(b.theta - a.theta))};
}

struct Errors {
  double rmse = 0.0;
  double last = 0.0;  // at the last reference used
  std::size_t used = 0, skipped = 0;
};

Errors position_errors(const std::vector<StampedPose>& estimate,
                       const std::vector<StampedPose>& reference) {
  Errors e;
  double se = 0.0;
  for (const StampedPose& r : reference) {
    const std::optional<StampedPose> p = pose_at(estimate, r.time);
    if (!p) {
      ++e.skipped;
      continue;
    }
    const double d2 = (p->x - r.x) * (p->x - r.x) + (p->y - r.y) * (p->y - r.y);
    se += d2;
    e.last = std::sqrt(d2);
    ++e.used;
  }
  e.rmse = e.used == 0 ? 0.0 : std::sqrt(se / e.used);
  return e;
}

// The position RMSE after the rigid motion (rotation and translation, no scale) that best
// aligns the estimate with the reference (closed-form least squares, as Horn/Umeyama in 2-D).
// It separates the error of the shape of the path from that of its placement, which for a
// source without absolute heading comes from the start pose (Victoria Park: the heading fitted
// to early GPS; 1 deg there moves the far end of the park by about 5 m).
struct AlignedErrors {
  double rmse = 0.0;
  double rotation = 0.0;  // rad, applied to the estimate
};

AlignedErrors aligned_position_errors(const std::vector<StampedPose>& estimate,
                                      const std::vector<StampedPose>& reference) {
  std::vector<std::array<double, 4>> pairs;  // estimate x, y; reference x, y
  for (const StampedPose& r : reference) {
    if (const std::optional<StampedPose> p = pose_at(estimate, r.time)) {
      pairs.push_back({p->x, p->y, r.x, r.y});
    }
  }
  AlignedErrors out;
  if (pairs.empty()) return out;
  double me[2] = {0, 0}, mr[2] = {0, 0};
  for (const auto& [ex, ey, rx, ry] : pairs) {
    me[0] += ex, me[1] += ey, mr[0] += rx, mr[1] += ry;
  }
  const auto n = static_cast<double>(pairs.size());
  for (double* m : {me, mr}) m[0] /= n, m[1] /= n;
  double cross = 0.0, dot = 0.0;
  for (const auto& [ex, ey, rx, ry] : pairs) {
    const double ax = ex - me[0], ay = ey - me[1], bx = rx - mr[0], by = ry - mr[1];
    cross += ax * by - ay * bx;
    dot += ax * bx + ay * by;
  }
  out.rotation = std::atan2(cross, dot);
  const double c = std::cos(out.rotation), sn = std::sin(out.rotation);
  double se = 0.0;
  for (const auto& [ex, ey, rx, ry] : pairs) {
    const double ax = ex - me[0], ay = ey - me[1];
    se +=
        std::pow(c * ax - sn * ay - (rx - mr[0]), 2) + std::pow(sn * ax + c * ay - (ry - mr[1]), 2);
  }
  out.rmse = std::sqrt(se / n);
  return out;
}

// Landmark RMSE of the estimated map under known association: each against its true landmark.
double landmark_rmse_by_id(const std::vector<engine::MapLandmark>& map,
                           const std::vector<TruthLandmark>& truth) {
  if (map.empty() || truth.empty()) return 0.0;
  double se = 0.0;
  std::vector<TruthLandmark> sorted = truth;
  std::sort(sorted.begin(), sorted.end(),
            [](const TruthLandmark& a, const TruthLandmark& b) { return a.id < b.id; });
  for (const engine::MapLandmark& l : map) {
    auto it = std::lower_bound(sorted.begin(), sorted.end(), l.id,
                               [](const TruthLandmark& a, std::uint64_t id) { return a.id < id; });
    if (it == sorted.end() || it->id != l.id) {
      throw std::runtime_error("estimated landmark id " + std::to_string(l.id) +
                               " is not a true landmark");
    }
    se += (l.x - it->x) * (l.x - it->x) + (l.y - it->y) * (l.y - it->y);
  }
  return std::sqrt(se / map.size());
}

// A run's source: its events, header, truth landmarks and how many controls to expect.
struct Source {
  LogHeader header;
  std::vector<TruthLandmark> landmarks;
  std::unique_ptr<EventSource> events;
  double expected_controls = 0.0;  // for the progress bar; 0: unknown
  std::string name;                // "world" in metrics.json
  // Owned data the events borrow.
  std::unique_ptr<World> world;
  std::unique_ptr<Log> log;
};

Source open_source(const RunOptions& o) {
  Source s;
  if (o.source == "sim") {
    s.world = std::make_unique<World>(make_world(o));
    const World& world = *s.world;
    s.header = sim_header(o, world);
    s.landmarks = truth_landmarks(world);
    s.events = std::make_unique<SimSource>(world, sim_config(o), o.filter.seed,
                                           o.filter.association != engine::Association::kKnown);
    // The length of the drive, for the progress bar: from the start to the first waypoint,
    // the route `loops` times, and back from the last waypoint to the first between loops.
    const std::vector<Point>& w = world.waypoints;
    double open_route = 0.0;
    for (std::size_t i = 0; i + 1 < w.size(); ++i) {
      open_route += std::hypot(w[i + 1].x - w[i].x, w[i + 1].y - w[i].y);
    }
    const double drive = std::hypot(w[0].x - world.start_x, w[0].y - world.start_y) +
                         open_route * o.sim.loops +
                         std::hypot(w[0].x - w.back().x, w[0].y - w.back().y) * (o.sim.loops - 1);
    s.expected_controls = std::max(1.0, drive / (o.sim.speed * o.sim.dt));
    s.name = o.landmarks_csv.empty() ? o.world : o.landmarks_csv;
    return s;
  }
  if (o.source == "log") {
    if (o.data.empty()) throw std::invalid_argument("--source log needs --data FILE.log");
    s.log = std::make_unique<Log>(read_log(o.data));
    s.header = s.log->header;
    s.landmarks = s.log->landmarks;
    s.events = std::make_unique<LogSource>(*s.log);
    for (const Event& e : s.log->events) s.expected_controls += e.kind == EventKind::kControl;
    s.name = o.data;
    return s;
  }
  if (o.source == "victoria-park") {
    if (o.data.empty()) {
      throw std::invalid_argument(
          "--source victoria-park needs --data DIR (../shared/data/victoria_park)");
    }
    s.log = std::make_unique<Log>(read_victoria_park(o.data, o.victoria_park).log);
    s.header = s.log->header;
    s.events = std::make_unique<LogSource>(*s.log);
    for (const Event& e : s.log->events) s.expected_controls += e.kind == EventKind::kControl;
    s.name = o.data;
    return s;
  }
  throw std::invalid_argument("--source '" + o.source +
                              "' is not supported (sim, log or victoria-park)");
}

void write_poses_csv(std::ofstream& file, const std::vector<StampedPose>& poses) {
  file << "t,x,y,theta\n";
  char line[160];
  for (const StampedPose& p : poses) {
    std::snprintf(line, sizeof(line), "%.3f,%.6f,%.6f,%.6f\n", p.time, p.x, p.y, p.theta);
    file << line;
  }
}

// `--trace`: the errors-over-time CSV (RunOptions::trace), written as the run goes.
class TraceWriter {
 public:
  TraceWriter(const std::string& path, std::uint64_t every)
      : path_(path), every_(every == 0 ? 1 : every), file_(path) {
    if (!file_) throw std::runtime_error("--trace " + path + ": cannot open for writing");
    file_ << "t,scan,pose_error_m,landmark_rmse_m,landmarks,observed_landmarks\n";
  }
  // Counts a scan; true when this one gets a row.
  bool due() { return scans_++ % every_ == 0; }
  void row(double t, std::optional<double> pose_error, std::optional<double> map_error,
           std::size_t landmarks, std::size_t observed) {
    char line[200];
    int n = std::snprintf(line, sizeof(line), "%.3f,%llu,", t,
                          static_cast<unsigned long long>(scans_ - 1));
    n += pose_error ? std::snprintf(line + n, sizeof(line) - n, "%.6f,", *pose_error)
                    : std::snprintf(line + n, sizeof(line) - n, ",");
    n += map_error ? std::snprintf(line + n, sizeof(line) - n, "%.6f,", *map_error)
                   : std::snprintf(line + n, sizeof(line) - n, ",");
    std::snprintf(line + n, sizeof(line) - n, "%zu,%zu\n", landmarks, observed);
    file_ << line;
  }
  void close() {
    file_.close();
    if (!file_) throw std::runtime_error("--trace " + path_ + ": write failed");
  }

 private:
  std::string path_;
  std::uint64_t every_;
  std::ofstream file_;
  std::uint64_t scans_ = 0;
};

// Runs the plot script on the output directory; the run's results stand whatever it does, so a
// failure is a warning naming the command and its exit status.
void draw_map(const std::string& script, const std::string& out) {
  std::fflush(stdout);
  const std::string python = "/usr/bin/python3";
  std::vector<std::string> args = {python, script, out};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  int status = 0;
  const int spawned = posix_spawn(&pid, python.c_str(), nullptr, nullptr, argv.data(), environ);
  if (spawned != 0) {
    std::fprintf(stderr, "warning: map.png not drawn: cannot start %s: %s\n", python.c_str(),
                 std::strerror(spawned));
    return;
  }
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::fprintf(stderr, "warning: map.png not drawn: '%s %s %s' failed (status %d)\n",
                 python.c_str(), script.c_str(), out.c_str(), status);
  }
}

}  // namespace

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
  Source source = open_source(options);
  const engine::FilterConfig config = filter_config(options, source.header);
  const bool ekf = config.algorithm == engine::Algorithm::kEkf;
  const std::uint32_t particles = ekf ? 1 : config.particles;
  ProgressBar progress(options.progress);
  ProgressState state;
  state.total = static_cast<std::uint64_t>(source.expected_controls);
  state.particles = particles;
  auto observe_state = [&](auto& filter) {
    const engine::FilterStatistics st = filter.statistics();
    state.done = st.controls;
    if constexpr (requires { filter.particles(); }) {
      state.landmarks = filter.particles().landmark_count(0);
    } else {
      state.landmarks = filter.estimate().map.size();
    }
    state.map_bytes = st.live_bytes;
  };

  // One loop over the events of any source.
  std::vector<double> control_times;
  std::vector<StampedPose> truth;
  std::vector<StampedPose> gps;
  std::vector<engine::Observation> scan;
  // Which true landmarks the run observed (by the ids the source gives its detections).
  std::unordered_map<std::uint64_t, std::size_t> truth_slot;
  for (std::size_t i = 0; i < source.landmarks.size(); ++i) truth_slot[source.landmarks[i].id] = i;
  std::unique_ptr<bool[]> observed_flags(new bool[source.landmarks.size()]());
  const std::span<bool> observed(observed_flags.get(), source.landmarks.size());
  std::vector<Point> truth_points(source.landmarks.size());
  for (std::size_t i = 0; i < source.landmarks.size(); ++i) {
    truth_points[i] = {source.landmarks[i].x, source.landmarks[i].y};
  }
  const TruthIndex truth_index(truth_points);
  const bool known = config.association == engine::Association::kKnown;
  std::unique_ptr<TraceWriter> trace;
  if (!options.trace.empty()) {
    trace = std::make_unique<TraceWriter>(options.trace, options.trace_every);
  }
  Event event;
  double source_seconds = 0.0;
  double filter_seconds = 0.0;
  double trace_seconds = 0.0;
  engine::Estimate estimate;
  std::vector<engine::TrajectoryPoint> points;
  engine::FilterStatistics stats;
  // The loop, the same for the FastSLAM `Filter` and the `EkfSlam` baseline (same methods).
  auto drive = [&](auto& filter) {
    for (;;) {
      const auto t0 = Clock::now();
      if (!source.events->next(event, scan)) break;
      const auto t1 = Clock::now();
      switch (event.kind) {
        case EventKind::kControl:
          filter.predict(event.control, event.dt);
          control_times.push_back(event.time);
          break;
        case EventKind::kScan:
          for (const engine::Observation& z : scan) {
            if (z.id < 0) continue;
            const auto found = truth_slot.find(static_cast<std::uint64_t>(z.id));
            if (found != truth_slot.end()) observed[found->second] = true;
          }
          filter.observe(scan);
          if (trace && trace->due()) {
            const auto t_trace = Clock::now();
            const engine::Estimate now = filter.estimate();
            std::optional<double> pose_error;
            if (!truth.empty() && event.time - truth.back().time <= kMaxInterpolationGap) {
              pose_error =
                  std::hypot(now.mean_pose[0] - truth.back().x, now.mean_pose[1] - truth.back().y);
            }
            std::optional<double> map_error;
            if (!source.landmarks.empty()) {
              map_error = known ? landmark_rmse_by_id(now.map, source.landmarks)
                                : score_map(now.map, truth_points, truth_index, observed,
                                            options.match_radius)
                                      .rmse_m;
            }
            trace->row(
                event.time, pose_error, map_error, now.map.size(),
                static_cast<std::size_t>(std::count(observed.begin(), observed.end(), true)));
            trace_seconds += std::chrono::duration<double>(Clock::now() - t_trace).count();
          }
          if (progress.due()) {
            observe_state(filter);
            progress.draw(state);
          }
          break;
        case EventKind::kTruthPose:
          truth.push_back({event.time, event.x, event.y, event.theta});
          break;
        case EventKind::kGps:
          gps.push_back({event.time, event.x, event.y, 0.0});
          break;
      }
      source_seconds += std::chrono::duration<double>(t1 - t0).count();
      filter_seconds += std::chrono::duration<double>(Clock::now() - t1).count();
      filter_seconds -= trace_seconds;  // the trace's estimates are not the filter's time
      trace_seconds = 0.0;
    }
    const auto t_end = Clock::now();
    estimate = filter.estimate();
    points = filter.take_trajectory();
    filter_seconds += std::chrono::duration<double>(Clock::now() - t_end).count();
    stats = filter.statistics();
    if (trace) trace->close();
    if (progress.enabled()) {
      observe_state(filter);
      state.total = state.done;  // the expected total was an estimate; the run is complete
      progress.finish(state);
    }
  };
  if (ekf) {
    engine::EkfSlam filter(config);
    drive(filter);
  } else {
    engine::Filter filter(config);
    drive(filter);
  }

  // The estimated trajectory: the start, then the pose after every control.
  std::vector<StampedPose> trajectory;
  trajectory.reserve(points.size() + 1);
  trajectory.push_back({source.header.start_time, source.header.start_pose[0],
                        source.header.start_pose[1], source.header.start_pose[2]});
  const engine::SensorOffset reported = tracked_point_offset(options, source.header);
  for (const engine::TrajectoryPoint& p : points) {
    const double c = std::cos(p.theta), sn = std::sin(p.theta);
    trajectory.push_back({control_times.at(p.control), p.x + reported.x * c - reported.y * sn,
                          p.y + reported.x * sn + reported.y * c, p.theta});
  }
  const Errors pose = position_errors(trajectory, truth);
  const Errors fixes = position_errors(trajectory, gps);
  const AlignedErrors aligned = aligned_position_errors(trajectory, gps);
  // Known ids: each landmark against its own. Unknown: paired with the truth by distance
  // (tools/map_evaluation.h), which also counts spurious and missing landmarks.
  const MapScore score =
      source.landmarks.empty()
          ? MapScore{}
          : score_map(estimate.map, truth_points, truth_index, observed, options.match_radius);
  const double map_rmse = config.association == engine::Association::kKnown
                              ? landmark_rmse_by_id(estimate.map, source.landmarks)
                              : score.rmse_m;
  const auto observed_count =
      static_cast<std::size_t>(std::count(observed.begin(), observed.end(), true));

  nlohmann::json metrics = {
      {"source", options.source},
      {"world", source.name},
      {"motion", engine::to_string(config.motion.kind)},
      {"algorithm", engine::to_string(config.algorithm)},
      {"particles", particles},
      {"association", engine::to_string(config.association)},
      {"seed", config.seed},
      {"threads", config.threads > 0 ? config.threads : unsigned(tbb::info::default_concurrency())},
      {"steps", stats.controls},
      {"scans", stats.scans},
      {"observations", stats.observations},
      {"true_landmarks", source.landmarks.size()},
      {"landmarks", estimate.map.size()},
      {"wall_seconds", filter_seconds},
      {"source_seconds", source_seconds},
      {"seconds_per_phase",
       {{"predict", stats.predict_seconds},
        {"associate", stats.associate_seconds},
        {"update", stats.update_seconds},
        {"resample", stats.resample_seconds}}},
      {"resamples", stats.resamples},
      {"log_evidence", stats.log_evidence},
      {"live_tree_nodes", stats.live_nodes},
      {"live_tree_bytes", stats.live_bytes},
      {"peak_rss_bytes", peak_rss_bytes()},
  };
  if (options.source == "sim") metrics["simulator_seconds"] = source_seconds;
  if (!truth.empty()) {
    metrics["pose_rmse_m"] = pose.rmse;
    const StampedPose& last = truth.back();
    metrics["final_position_error_m"] =
        std::hypot(estimate.mean_pose[0] - last.x, estimate.mean_pose[1] - last.y);
  }
  if (!source.landmarks.empty()) {
    metrics["landmark_rmse_m"] = map_rmse;
    metrics["observed_landmarks"] = observed_count;
    metrics["match_radius_m"] = options.match_radius;
    metrics["matched_landmarks"] = score.matched;
    metrics["spurious_landmarks"] = score.spurious;
    metrics["missing_landmarks"] = score.missing;
  }
  if (options.source == "sim") {
    metrics["clutter_rate"] = options.sim.clutter_rate;
    metrics["scan_period_s"] = sim_config(options).dt_observe;
  }
  if (config.association != engine::Association::kKnown) {
    metrics["landmarks_created"] = stats.landmarks_created;
    metrics["landmarks_removed"] = stats.landmarks_removed;
  }
  if (!gps.empty()) {
    metrics["gps_rmse_m"] = fixes.rmse;
    metrics["final_gps_error_m"] = fixes.last;
    metrics["gps_fixes_used"] = fixes.used;
    metrics["gps_fixes_skipped"] = fixes.skipped;
    metrics["gps_rmse_aligned_m"] = aligned.rmse;
    metrics["gps_alignment_rotation_deg"] = aligned.rotation * 180 / std::numbers::pi;
    metrics["initial_heading_deg"] = config.initial_pose[2] * 180 / std::numbers::pi;
  }
  std::printf("%s, M = %u, %s association, seed %llu: %llu steps, %llu scans, %zu landmarks\n",
              std::string(engine::to_string(config.algorithm)).c_str(), particles,
              std::string(engine::to_string(config.association)).c_str(),
              static_cast<unsigned long long>(config.seed),
              static_cast<unsigned long long>(stats.controls),
              static_cast<unsigned long long>(stats.scans), estimate.map.size());
  std::printf(" ");
  if (!truth.empty()) std::printf(" pose RMSE %.3f m,", pose.rmse);
  if (!source.landmarks.empty()) std::printf(" landmark RMSE %.3f m,", map_rmse);
  if (!gps.empty()) {
    std::printf(
        " GPS RMSE %.3f m (%zu fixes, %zu skipped), at the end %.3f m, %.3f m after a "
        "rigid alignment (rotation %.2f deg),",
        fixes.rmse, fixes.used, fixes.skipped, fixes.last, aligned.rmse,
        aligned.rotation * 180 / std::numbers::pi);
  }
  std::printf(" filter %.3f s (%s %.3f s)\n", filter_seconds,
              options.source == "sim" ? "simulator" : "reading", source_seconds);
  if (!source.landmarks.empty()) {
    std::printf("  map: %zu matched within %.1f m, %zu spurious, %zu of %zu observed missing\n",
                score.matched, options.match_radius, score.spurious, score.missing, observed_count);
  }
  if (options.out.empty()) return 0;

  std::filesystem::create_directories(options.out);
  auto open = [&](const std::string& name) {
    std::ofstream file(options.out + "/" + name);
    if (!file) throw std::runtime_error("cannot write " + options.out + "/" + name);
    return file;
  };
  open("metrics.json") << metrics.dump(2) << '\n';
  // The poses after the controls (the start is not a control's).
  const std::span<const StampedPose> after_controls(trajectory.data() + 1, trajectory.size() - 1);
  {
    std::ofstream file = open("trajectory.csv");
    write_poses_csv(file, std::vector<StampedPose>(after_controls.begin(), after_controls.end()));
  }
  {
    std::ofstream file = open("trajectory.tum");
    write_tum(file, after_controls);
  }
  {
    std::ofstream file = open("landmarks.csv");
    file << "id,x,y,sxx,sxy,syy\n";
    char line[200];
    for (const engine::MapLandmark& l : estimate.map) {
      std::snprintf(line, sizeof(line), "%llu,%.6f,%.6f,%.9g,%.9g,%.9g\n",
                    static_cast<unsigned long long>(l.id), l.x, l.y, l.sxx, l.sxy, l.syy);
      file << line;
    }
  }
  std::string written = "metrics.json,trajectory.csv,trajectory.tum,landmarks.csv";
  if (!truth.empty()) {
    std::ofstream file = open("truth.csv");
    write_poses_csv(file, truth);
    written += ",truth.csv";
  }
  if (!gps.empty()) {
    std::ofstream file = open("gps.csv");
    file << "t,x,y\n";
    char line[120];
    for (const StampedPose& g : gps) {
      std::snprintf(line, sizeof(line), "%.3f,%.6f,%.6f\n", g.time, g.x, g.y);
      file << line;
    }
    written += ",gps.csv";
  }
  if (!source.landmarks.empty()) {
    std::ofstream file = open("true_landmarks.csv");
    file << "id,x,y\n";
    char line[120];
    for (const TruthLandmark& l : source.landmarks) {
      std::snprintf(line, sizeof(line), "%llu,%.6f,%.6f\n", static_cast<unsigned long long>(l.id),
                    l.x, l.y);
      file << line;
    }
    written += ",true_landmarks.csv";
  }
  std::printf("  wrote %s/{%s}\n", options.out.c_str(), written.c_str());
  if (!options.plot_script.empty()) draw_map(options.plot_script, options.out);
  return 0;
}

int convert_to_log(const RunOptions& options) {
  if (options.out.empty()) throw std::invalid_argument("convert needs --out FILE.log");
  const std::string partial = options.out + ".partial";
  std::size_t events = 0;
  if (options.source == "sim") {
    const World world = make_world(options);
    std::ofstream file(partial);
    if (!file) throw std::runtime_error(partial + ": cannot open for writing");
    LogWriter writer(file, sim_header(options, world));
    for (const TruthLandmark& l : truth_landmarks(world)) writer.landmark(l);
    SimSource sim(world, sim_config(options), options.filter.seed, /*clutter=*/true);
    Event e;
    std::vector<engine::Observation> scan;
    while (sim.next(e, scan)) {
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
      ++events;
    }
    file.close();
    if (!file) throw std::runtime_error(partial + ": write failed");
  } else if (options.source == "victoria-park") {
    if (options.data.empty()) {
      throw std::invalid_argument("--source victoria-park needs --data DIR");
    }
    const VictoriaPark vp = read_victoria_park(options.data, options.victoria_park);
    write_log(partial, vp.log);
    events = vp.log.events.size();
    std::printf(
        "Victoria Park: %zu controls, %zu scans, %zu detections (%zu gated out), %zu GPS "
        "fixes, initial heading %.2f deg (GPS fit RMS %.2f m)\n",
        vp.odometry_samples, vp.scans, vp.detections, vp.gated_out, vp.gps_fixes,
        vp.initial_heading * 180 / std::numbers::pi, vp.heading_fit_rms_m);
  } else {
    throw std::invalid_argument("convert --source '" + options.source +
                                "' is not supported (sim or victoria-park)");
  }
  std::filesystem::rename(partial, options.out);
  std::printf("wrote %zu events to %s\n", events, options.out.c_str());
  return 0;
}

}  // namespace fastslam::tools
