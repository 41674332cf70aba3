// Bailey's SLAM simulator (fastslam1_sim.m and friends), reproduced step for step: a car
// (engine::BaileyCarModel) steers toward each waypoint in turn (limited steering angle and
// rate), drives the route a given number of loops, and every observation period sees the
// landmarks within range in front of it. Controls and observations get Gaussian noise from the
// keyed random streams, so a run is a pure function of (world, config, seed). Ground truth is
// recorded with each step. A waypoint the car cannot reach (one inside its turning circle is
// orbited forever) stops the run with an error instead of running without end.
//
// Ownership: a `Simulator` borrows the `World`, which must outlive it.
// Thread safety: thread-compatible; distinct simulators are independent.
// Costs: `next` is O(1) per control step plus O(log N + k + clutter) per scan (kd-tree query
// over the true landmarks); construction builds the kd-tree in O(N log N).
#pragma once

#include <cstdint>
#include <numbers>
#include <vector>

#include "engine/motion_model.h"
#include "tools/sim/world.h"

namespace fastslam::tools {

// Defaults: ../shared/data/bailey_sim/README.md (configfile.m).
struct SimConfig {
  double speed = 3.0;                                 // V, m/s
  double max_steer = 30.0 * std::numbers::pi / 180;   // MAXG, rad
  double steer_rate = 20.0 * std::numbers::pi / 180;  // RATEG, rad/s
  double wheelbase = 4.0;                             // m
  double dt = 0.025;                                  // DT_CONTROLS, s
  double sigma_v = 0.3;                               // m/s
  double sigma_steer = 3.0 * std::numbers::pi / 180;  // rad
  double max_range = 30.0;                            // m
  double min_range = 0.5;  // m: nearer landmarks are not seen (inside the vehicle; and a noisy
                           // range there could come out negative)
  double field_of_view = std::numbers::pi;  // rad, centred ahead (Bailey: the front half)
  double dt_observe = 8 * 0.025;            // DT_OBSERVE, s
  double sigma_range = 0.1;                 // m
  double sigma_bearing = 1.0 * std::numbers::pi / 180;  // rad
  double at_waypoint = 1.0;                             // m
  int loops = 2;                                        // NUMBER_LOOPS
  bool control_noise = true;
  bool sensor_noise = true;
  // False alarms: a Poisson number per scan with this mean, uniform over the footprint's area
  // (between min_range and max_range, inside the field of view); their landmark is kClutter.
  double clutter_rate = 0.0;
  // Each landmark in view is detected with this probability, independently (missed
  // detections); 1 draws nothing, so runs without misses are unchanged.
  double detection_probability = 1.0;
};

struct TruePose {
  double x = 0.0;
  double y = 0.0;
  double theta = 0.0;
};

// The false alarms per m² per scan: clutter_rate over the footprint's area (the annular sector
// between min_range and max_range inside the field of view, where they are drawn uniformly).
double clutter_density(const SimConfig& config);

// SimObservation::landmark of a false alarm.
inline constexpr std::uint32_t kClutter = 0xFFFFFFFFu;

struct SimObservation {
  double range = 0.0;
  double bearing = 0.0;        // wrapped to (-pi, pi]
  std::uint32_t landmark = 0;  // index into World::landmarks (the true correspondence), or kClutter
};

// One control step: the (noisy) control the filter sees, the truth after it, and the scan taken
// at the end of it, if any.
struct SimStep {
  std::uint64_t index = 0;  // control step number, from 0
  double dt = 0.0;
  double speed = 0.0;  // measured (noisy) V
  double steer = 0.0;  // measured (noisy) G
  TruePose truth;      // true pose after this step
  bool has_scan = false;
  std::vector<SimObservation> scan;  // valid when has_scan
};

class Simulator {
 public:
  // Throws std::invalid_argument when the world has no waypoints or the config is not usable
  // (non-positive dt, speed, wheelbase, range, observation period; negative noise; loops < 1).
  Simulator(const World& world, const SimConfig& config, std::uint64_t seed);

  // Advances one control step into `step` (its scan vector is reused). Returns false, leaving
  // `step` untouched, once the route has been driven `loops` times. Throws std::runtime_error
  // naming the waypoint when the current one has not been reached within
  // kWaypointPatience x (its distance over the speed, plus a full turning circle and a full
  // swing of the steering): the car is circling it or cannot get there.
  bool next(SimStep& step);

  static constexpr double kWaypointPatience = 3.0;

 private:
  void observe(SimStep& step);
  // Starts the clock for reaching the current waypoint.
  void aim();
  void check_progress(double d2);

  const World* world_;
  SimConfig config_;
  engine::BaileyCarModel car_;  // the true motion, config_.wheelbase
  std::uint64_t seed_;
  TruthIndex index_;
  TruePose pose_;
  double steer_ = 0.0;
  std::size_t waypoint_ = 0;     // current target
  double aimed_at_ = 0.0;        // s, when it became the target
  double patience_ = 0.0;        // s, the time allowed to reach it
  double closest_ = 0.0;         // m, the nearest the car has come to it
  double turning_radius_ = 0.0;  // m, at full steering
  int loops_left_;
  bool done_ = false;
  double since_scan_ = 0.0;
  std::uint64_t step_ = 0;
  std::vector<std::uint32_t> visible_;
};

}  // namespace fastslam::tools
