#include "tools/datasets/sim_source.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "tools/datasets/source.h"

namespace fastslam::tools {
namespace {

bool csv_world(const SimWorldOptions& o) {
  return !o.landmarks_csv.empty() || !o.waypoints_csv.empty();
}

// Bailey's car and sensor with the simulator's noises, starting where the world says.
LogHeader sim_header(const SimConfig& sim, const World& world) {
  LogHeader h;
  h.motion.kind = engine::MotionKind::kBaileyCar;
  h.motion.wheelbase = sim.wheelbase;
  h.motion.sigma_control[0] = sim.sigma_v;
  h.motion.sigma_control[1] = sim.sigma_steer;
  h.sensor.sigma_range = sim.sigma_range;
  h.sensor.sigma_bearing = sim.sigma_bearing;
  h.sensor.max_range = sim.max_range;
  h.sensor.field_of_view = sim.field_of_view;
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

// The controls of the whole drive, for the progress bar: from the start to the first
// waypoint, the route `loops` times, and back from the last waypoint to the first between loops.
double expected_controls(const World& world, const SimConfig& sim) {
  const std::vector<Point>& w = world.waypoints;
  double open_route = 0.0;
  for (std::size_t i = 0; i + 1 < w.size(); ++i) {
    open_route += std::hypot(w[i + 1].x - w[i].x, w[i + 1].y - w[i].y);
  }
  const double drive = std::hypot(w[0].x - world.start_x, w[0].y - world.start_y) +
                       open_route * sim.loops +
                       std::hypot(w[0].x - w.back().x, w[0].y - w.back().y) * (sim.loops - 1);
  return std::max(1.0, drive / (sim.speed * sim.dt));
}

// The detections a scan holds, expected: the true landmarks within the sensor's range of the
// busiest of up to 16 points along the route (the middles of its legs), the share of them in its
// field of view, detected with the simulator's probability, plus the clutter. O(16 N), fewer
// points for worlds of over 10^7 landmarks.
std::uint64_t expected_detections(const World& world, const SimConfig& sim, bool clutter) {
  const std::vector<Point>& w = world.waypoints;
  std::vector<Point> points = {{world.start_x, world.start_y}};
  const std::size_t legs = w.size();
  const std::size_t budget = std::clamp<std::size_t>(
      200'000'000 / std::max<std::size_t>(1, world.landmarks.size()), 1, 16);
  for (std::size_t k = 0; k < std::min(legs, budget - 1); ++k) {
    const std::size_t i = k * legs / std::min(legs, budget - 1);
    const Point& a = w[i];
    const Point& b = w[(i + 1) % legs];
    points.push_back({(a.x + b.x) / 2, (a.y + b.y) / 2});
  }
  const double r2 = sim.max_range * sim.max_range;
  std::uint64_t most = 0;
  for (const Point& p : points) {
    std::uint64_t in_range = 0;
    for (const Point& l : world.landmarks) {
      in_range += (l.x - p.x) * (l.x - p.x) + (l.y - p.y) * (l.y - p.y) <= r2;
    }
    most = std::max(most, in_range);
  }
  const double seen = static_cast<double>(most) *
                      std::min(1.0, sim.field_of_view / (2 * std::numbers::pi)) *
                      sim.detection_probability;
  return static_cast<std::uint64_t>(std::ceil(seen + (clutter ? sim.clutter_rate : 0.0)));
}

class SimSource final : public Source {
 public:
  // `clutter`: pass false alarms on (id -1); known association sees true detections only.
  SimSource(std::unique_ptr<World> world, const SimWorldOptions& o, std::uint64_t seed,
            bool clutter)
      : world_(std::move(world)), sim_(*world_, resolved_sim_config(o), seed), clutter_(clutter) {
    const SimConfig config = resolved_sim_config(o);
    info_.header = sim_header(o.config, *world_);
    info_.landmarks = truth_landmarks(*world_);
    info_.expected_controls = tools::expected_controls(*world_, o.config);
    info_.scans = {.controls = static_cast<std::uint64_t>(std::ceil(config.dt_observe / config.dt)),
                   .detections = expected_detections(*world_, config, clutter),
                   .known = true};
    info_.name = o.landmarks_csv.empty() ? o.world : o.landmarks_csv;
    info_.simulated = true;
    info_.labels = clutter && o.config.clutter_rate > 0 ? Labels::kSome : Labels::kAll;
    // A procedural world's maps are paired within half its landmark spacing.
    if (!csv_world(o)) {
      info_.match_radius =
          0.5 * o.spacing.value_or(o.world == "grid" ? kDefaultGridSpacing : kDefaultLoopSpacing);
    }
    // The true noises, beside the dead-reckoning baseline they explain.
    info_.metrics = {{"clutter_rate", o.config.clutter_rate},
                     {"scan_period_s", config.dt_observe},
                     {"sim_sigma_speed", o.config.control_noise ? o.config.sigma_v : 0.0},
                     {"sim_sigma_steer", o.config.control_noise ? o.config.sigma_steer : 0.0},
                     {"sim_sigma_range", o.config.sensor_noise ? o.config.sigma_range : 0.0},
                     {"sim_sigma_bearing", o.config.sensor_noise ? o.config.sigma_bearing : 0.0},
                     {"detection_probability", o.config.detection_probability}};
  }

  bool next(Event& e, std::vector<engine::Observation>& scan) override {
    e = Event{};
    e.time = t_;
    if (stage_ == Stage::kTruth) {
      stage_ = step_.has_scan ? Stage::kScan : Stage::kControl;
      e.kind = EventKind::kTruthPose;
      e.x = step_.truth.x;
      e.y = step_.truth.y;
      e.theta = step_.truth.theta;
      return true;
    }
    if (stage_ == Stage::kScan) {
      stage_ = Stage::kControl;
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
    stage_ = Stage::kTruth;
    return true;
  }

 private:
  enum class Stage { kControl, kTruth, kScan };  // what `next` gives next
  std::unique_ptr<World> world_;                 // the simulator borrows it
  Simulator sim_;
  bool clutter_;
  SimStep step_;
  double t_ = 0.0;
  Stage stage_ = Stage::kControl;
};

}  // namespace

SimConfig resolved_sim_config(const SimWorldOptions& o) {
  SimConfig sim = o.config;
  if (o.scan_period) {
    sim.dt_observe = *o.scan_period;
  } else if (!csv_world(o) && o.world == "grid") {
    sim.dt_observe = kDefaultGridScanPeriod;
  }
  return sim;
}

World make_world(const SimWorldOptions& o, std::uint64_t seed) {
  if (csv_world(o)) {
    if (o.landmarks_csv.empty() || o.waypoints_csv.empty()) {
      throw std::invalid_argument("--landmarks-csv and --waypoints-csv go together");
    }
    return read_world_csv(o.landmarks_csv, o.waypoints_csv);
  }
  if (o.world == "grid") {
    return make_grid_world(o.landmarks, o.spacing.value_or(kDefaultGridSpacing),
                           1.5 * o.config.max_range, seed);
  }
  if (o.world == "loop") {
    return make_loop_world(o.loop_length, o.spacing.value_or(kDefaultLoopSpacing),
                           o.config.max_range, 10.0, seed);
  }
  throw std::invalid_argument("unknown --world '" + o.world + "' (grid or loop)");
}

std::unique_ptr<Source> open_sim_source(const SourceOptions& o) {
  return std::make_unique<SimSource>(std::make_unique<World>(make_world(o.sim, o.seed)), o.sim,
                                     o.seed, o.clutter);
}

}  // namespace fastslam::tools
