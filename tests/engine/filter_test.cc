#include "engine/filter.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <set>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/motion_model.h"
#include "engine/motion_run.h"
#include "memory/landmark_tree.h"
#include "memory/particle_store.h"
#include "parallel/random_stream.h"
#include "parallel/resample.h"
#include "tests/engine/filter_scenarios.h"
#include "tests/engine/webmap_world.h"
#include "tests/shared_data.h"
#include "tools/eval/map_evaluation.h"
#include "tools/sim/simulator.h"
#include "tools/sim/world.h"

namespace fastslam::engine {
namespace {

using namespace testing;  // tests/engine/filter_scenarios.h


constexpr double kPi = std::numbers::pi;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

double wrap(double a) {
  a = std::remainder(a, 2 * kPi);
  return a <= -kPi ? a + 2 * kPi : a;
}

std::string saved(const Filter& filter) {
  std::ostringstream out;
  filter.save(out);
  return out.str();
}

std::unique_ptr<Filter> loaded(const std::string& bytes) {
  std::istringstream in(bytes);
  return Filter::load(in);
}

// EXPECT that `call` throws E whose message contains `needle`.
template <class E, class F>
void expect_throw_with(F&& call, const std::string& needle) {
  try {
    call();
    ADD_FAILURE() << "no exception; expected one mentioning '" << needle << "'";
  } catch (const E& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos)
        << "message '" << e.what() << "' does not mention '" << needle << "'";
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
  }
}

// ---- 1. Bad input ---------------------------------------------------------------------------

TEST(FilterConfigTest, ValidateNamesTheFirstBadField) {
  struct Case {
    const char* needle;
    std::function<void(FilterConfig&)> spoil;
  };
  const std::vector<Case> cases = {
      {"particles", [](FilterConfig& c) { c.particles = 0; }},
      {"sigma_range", [](FilterConfig& c) { c.sensor.sigma_range = 0; }},
      {"sigma_range", [](FilterConfig& c) { c.sensor.sigma_range = kNaN; }},
      {"sigma_bearing", [](FilterConfig& c) { c.sensor.sigma_bearing = -1; }},
      {"max_range", [](FilterConfig& c) { c.sensor.max_range = kInf; }},
      {"field_of_view", [](FilterConfig& c) { c.sensor.field_of_view = 7.0; }},
      {"offset", [](FilterConfig& c) { c.sensor.offset.x = kNaN; }},
      {"sigma_control[0]", [](FilterConfig& c) { c.motion.sigma_control[0] = -0.1; }},
      {"sigma_control[1]", [](FilterConfig& c) { c.motion.sigma_control[1] = kInf; }},
      {"wheelbase", [](FilterConfig& c) { c.motion.wheelbase = 0; }},
      {"geometry",
       [](FilterConfig& c) {
         c.motion.kind = MotionKind::kAckermann;
         c.motion.geometry.l = -1;
       }},
      {"association", [](FilterConfig& c) { c.association = static_cast<Association>(9); }},
      {"gating.gate", [](FilterConfig& c) { c.gating.gate = 0; }},
      {"gating.search_scale", [](FilterConfig& c) { c.gating.search_scale = 0.5; }},
      {"range_margin", [](FilterConfig& c) { c.existence.range_margin = -1; }},
      {"log_new_landmark", [](FilterConfig& c) { c.log_new_landmark = -kInf; }},
      {"existence", [](FilterConfig& c) { c.existence.missed = kNaN; }},
      {"grain", [](FilterConfig& c) { c.grain = 0; }},
      {"split_seconds", [](FilterConfig& c) { c.split_seconds = kNaN; }},
      {"initial_pose", [](FilterConfig& c) { c.initial_pose[2] = kNaN; }},
      {"fraction", [](FilterConfig& c) { c.resample.ess_fraction = 1.5; }},
      {"motion_draw", [](FilterConfig& c) { c.motion_draw = static_cast<MotionDraw>(7); }},
      {"the EKF predicts",
       [](FilterConfig& c) {
         c.motion_draw = MotionDraw::kComposed;
         c.algorithm = Algorithm::kEkf;
       }},
      {"odometry model",
       [](FilterConfig& c) {
         c.motion_draw = MotionDraw::kComposed;
         c.motion.kind = MotionKind::kBrownian;
       }},
      {"error_correlation must be in [0, 1)",
       [](FilterConfig& c) {
         c.algorithm = Algorithm::kFastSlam2;
         c.error_correlation = 1.0;
       }},
      {"error_correlation must be in [0, 1)",
       [](FilterConfig& c) {
         c.algorithm = Algorithm::kFastSlam2;
         c.error_correlation = kNaN;
       }},
      {"error_correlation is FastSLAM 2.0's", [](FilterConfig& c) { c.error_correlation = 0.5; }},
  };
  for (const Case& k : cases) {
    SCOPED_TRACE(k.needle);
    FilterConfig c;
    EXPECT_NO_THROW(validate(c));
    k.spoil(c);
    expect_throw_with<std::invalid_argument>([&] { validate(c); }, k.needle);
    expect_throw_with<std::invalid_argument>([&] { Filter f(c); }, k.needle);
  }
}

class FilterAlgorithmTest : public ::testing::TestWithParam<Algorithm> {};

std::string algorithm_name(const ::testing::TestParamInfo<Algorithm>& param) {
  return std::string(to_string(param.param));
}

INSTANTIATE_TEST_SUITE_P(Both, FilterAlgorithmTest,
                         ::testing::Values(Algorithm::kFastSlam1, Algorithm::kFastSlam2),
                         algorithm_name);

TEST_P(FilterAlgorithmTest, RefusedInputLeavesTheFilterExactlyAsItWas) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(GetParam(), 32);
  config.record_trajectory = true;
  Filter filter(config);
  Filter twin(config);
  // Stop in the middle, after a control: the queue is not empty when the bad calls come.
  std::size_t cut = s.events.size() / 2;
  while (s.events[cut - 1].is_scan) ++cut;
  feed(filter, s.events, 0, cut);
  feed(twin, s.events, 0, cut);
  std::size_t next_scan = cut;
  while (!s.events[next_scan].is_scan) ++next_scan;
  const std::vector<Observation>& good = s.events[next_scan].scan;
  ASSERT_GE(good.size(), 2u);

  const std::string before = saved(filter);
  auto refused = [&](const std::function<void()>& call, const std::string& needle) {
    SCOPED_TRACE(needle);
    expect_throw_with<std::invalid_argument>(call, needle);
    EXPECT_TRUE(saved(filter) == before) << "a refused call changed the saved state";
  };
  refused([&] { filter.predict({kNaN, 0.0}, 0.025); }, "finite");
  refused([&] { filter.predict({3.0, kInf}, 0.025); }, "finite");
  refused([&] { filter.predict({-kInf, 0.0}, 0.025); }, "finite");
  refused([&] { filter.predict({3.0, 0.0}, -0.025); }, "dt");
  refused([&] { filter.predict({3.0, 0.0}, kNaN); }, "dt");
  refused([&] { filter.predict({3.0, 0.0}, kInf); }, "dt");

  // A bad observation at the end of a scan whose first observations are valid, among them a
  // landmark never seen before (its slot must not be committed).
  auto scan_with_last = [&](Observation last) {
    std::vector<Observation> scan = good;
    scan.push_back({12.0, 0.1, 1000000});  // new
    scan.push_back(last);
    return scan;
  };
  auto observe_refused = [&](Observation last, const std::string& needle) {
    const std::vector<Observation> scan = scan_with_last(last);
    refused([&] { filter.observe(scan); }, needle);
  };
  observe_refused({kNaN, 0.1, 1000001}, "range");
  observe_refused({kInf, 0.1, 1000001}, "range");
  observe_refused({0.0, 0.1, 1000001}, "range");
  observe_refused({-1.0, 0.1, 1000001}, "range");
  observe_refused({5.0, kNaN, 1000001}, "bearing");
  observe_refused({5.0, -kInf, 1000001}, "bearing");
  observe_refused({5.0, 0.1, -1}, "id");
  observe_refused({5.0, 0.1, good[0].id}, "twice");
  observe_refused({5.0, 0.1, 1000000}, "twice");
  // Estimates and trajectories were not touched either: nothing was drained by a refusal.
  EXPECT_TRUE(saved(filter) == before);

  feed(filter, s.events, cut, s.events.size());
  feed(twin, s.events, cut, s.events.size());
  EXPECT_TRUE(identical(snapshot(filter), snapshot(twin)));
  EXPECT_TRUE(identical(filter.estimate(), twin.estimate()));
  EXPECT_TRUE(identical(filter.take_trajectory(), twin.take_trajectory()));
  const FilterStatistics a = filter.statistics();
  const FilterStatistics b = twin.statistics();
  EXPECT_EQ(a.controls, b.controls);
  EXPECT_EQ(a.scans, b.scans);
  EXPECT_EQ(a.observations, b.observations);
  EXPECT_EQ(a.resamples, b.resamples);
  EXPECT_EQ(a.live_nodes, b.live_nodes);
}

// A vehicle driven exactly onto a landmark it then observes: the range-bearing Jacobian divides
// by zero and the weight is NaN. That is a numerical failure after the scan was applied, not a
// refused input, so it must not be reported as std::invalid_argument ("left unchanged").
TEST_P(FilterAlgorithmTest, NumericalFailureIsNotReportedAsRefusedInput) {
  FilterConfig config = base_config(GetParam(), 1);
  config.motion.sigma_control[0] = 0.0;  // deterministic motion
  config.motion.sigma_control[1] = 0.0;
  Filter filter(config);
  filter.observe(std::vector<Observation>{{1.0, 0.0, 0}});  // landmark 0 at (1, 0)
  filter.predict({1.0, 0.0}, 1.0);                          // the vehicle moves onto it
  expect_throw_with<std::runtime_error>(
      [&] {
        filter.observe(std::vector<Observation>{{0.5, 0.0, 0}});
      },
      "numerical");
}

// ---- 2. Determinism ---------------------------------------------------------------------------

struct DeterminismCase {
  Algorithm algorithm;
  parallel::ResampleScheme scheme;
};

class FilterDeterminismTest : public ::testing::TestWithParam<DeterminismCase> {};

struct RunResult {
  Snapshot particles;
  Estimate estimate;
  std::vector<TrajectoryPoint> trajectory;
  std::uint64_t resamples = 0;
};

// The particles, the estimate and the recorded path, bit for bit.
void expect_same_run(const RunResult& r, const RunResult& reference) {
  EXPECT_TRUE(identical(r.particles, reference.particles));
  EXPECT_TRUE(identical(r.estimate, reference.estimate));
  EXPECT_TRUE(identical(r.trajectory, reference.trajectory));
}

// A filter of `config` fed `events`: its trajectory, estimate, particles and resamplings.
RunResult run_events(const FilterConfig& config, const std::vector<Event>& events) {
  Filter filter(config);
  feed(filter, events, 0, events.size());
  RunResult r;
  r.trajectory = filter.take_trajectory();
  r.estimate = filter.estimate();
  r.particles = snapshot(filter);
  r.resamples = filter.statistics().resamples;
  return r;
}

RunResult run_scenario(const FilterConfig& config, const Scenario& s) {
  return run_events(config, s.events);
}

TEST_P(FilterDeterminismTest, BitIdenticalForAnyThreadCountAndGrain) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(GetParam().algorithm, kSanitized ? 40 : 100);
  config.resample = {parallel::ResamplePolicy::When::kEveryStep, 0.5, GetParam().scheme};
  config.record_trajectory = true;
  config.threads = 1;
  config.grain = 16;
  const RunResult reference = run_scenario(config, s);
  EXPECT_GT(reference.resamples, 10u);
  // split_seconds 0: every pass counts as heavy and is split across the threads whatever the
  // grain (as Victoria Park's are); infinity: never.
  const std::tuple<unsigned, std::size_t, double> layouts[] = {
      {1, 1, kInf},    {2, 1, kInf},   {2, 3, kInf},  {2, 16, kInf},
      {2, 1000, kInf}, {2, 1000, 0.0}, {1, 1000, 0.0}};
  for (const auto& [threads, grain, split] : layouts) {
    SCOPED_TRACE("threads " + std::to_string(threads) + ", grain " + std::to_string(grain) +
                 ", split_seconds " + std::to_string(split));
    config.threads = threads;
    config.grain = grain;
    config.split_seconds = split;
    expect_same_run(run_scenario(config, s), reference);
  }
  // Another seed gives another run.
  config.seed += 1;
  const RunResult other = run_scenario(config, s);
  EXPECT_FALSE(identical(other.particles, reference.particles));
  EXPECT_FALSE(same_bits(other.estimate.mean_pose[0], reference.estimate.mean_pose[0]));
}

const DeterminismCase kDeterminismCases[] = {
    {Algorithm::kFastSlam1, parallel::ResampleScheme::kSystematic},
    {Algorithm::kFastSlam1, parallel::ResampleScheme::kStratified},
    {Algorithm::kFastSlam1, parallel::ResampleScheme::kMultinomial},
    {Algorithm::kFastSlam2, parallel::ResampleScheme::kSystematic},
    {Algorithm::kFastSlam2, parallel::ResampleScheme::kStratified},
    {Algorithm::kFastSlam2, parallel::ResampleScheme::kMultinomial},
};

std::string determinism_case_name(const ::testing::TestParamInfo<DeterminismCase>& param) {
  const char* schemes[] = {"systematic", "stratified", "multinomial"};
  return std::string(to_string(param.param.algorithm)) + "_" +
         schemes[static_cast<int>(param.param.scheme)];
}

INSTANTIATE_TEST_SUITE_P(AllSchemes, FilterDeterminismTest, ::testing::ValuesIn(kDeterminismCases),
                         determinism_case_name);

// The loop scenario's first 300 events with 150 of its controls inserted before its 101st event,
// so that one pass queues 150 controls (the motion stage's batches of 64, the composed motion's
// runs of 64).
std::vector<Event> queued_events() {
  const Scenario& s = loop_scenario();
  std::vector<Event> events(s.events.begin(), s.events.begin() + 100);
  for (std::size_t k = 0, added = 0; added < 150; ++k) {
    if (!s.events[k].is_scan) {
      events.push_back(s.events[k]);
      ++added;
    }
  }
  events.insert(events.end(), s.events.begin() + 100, s.events.begin() + 300);
  return events;
}

// Every motion model through the filter's vectorised control loop (engine/motion_batch.h) and,
// for the odometry models, the composed motion (engine/motion_run.h): bit-identical for any
// thread count and grain, and whether the trajectory is recorded (one control per kernel call)
// or not (every queued control in one call, in batches of 64 steps: the events queue 150
// controls before one scan).
TEST(FilterDeterminismMotionTest, EveryModelBitIdenticalForAnyLayoutAndRecording) {
  const std::vector<Event> events = queued_events();
  const auto controls = static_cast<std::size_t>(
      std::count_if(events.begin(), events.end(), [](const Event& e) { return !e.is_scan; }));
  for (const MotionKind kind :
       {MotionKind::kBaileyCar, MotionKind::kUnicycle, MotionKind::kAckermann,
        MotionKind::kBrownian, MotionKind::kBrownianCurvature}) {
    const bool odometry = kind != MotionKind::kBrownian && kind != MotionKind::kBrownianCurvature;
    for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
      for (const MotionDraw draw : {MotionDraw::kEveryControl, MotionDraw::kComposed}) {
        if (draw == MotionDraw::kComposed && !odometry) continue;
        SCOPED_TRACE("motion " + std::string(to_string(kind)) + ", " +
                     std::string(to_string(algorithm)) + ", " + std::string(to_string(draw)));
        FilterConfig config = base_config(algorithm, kSanitized ? 20 : 45);
        config.motion.kind = kind;
        config.motion_draw = draw;
        config.grain = 16;
        const RunResult reference = run_events(config, events);
        std::vector<TrajectoryPoint> recorded;
        const std::tuple<unsigned, std::size_t, bool> layouts[] = {
            {2, 1, false}, {2, 5, false}, {1, 1000, true}, {2, 16, true}};
        for (const auto& [threads, grain, record] : layouts) {
          SCOPED_TRACE("threads " + std::to_string(threads) + ", grain " + std::to_string(grain) +
                       (record ? ", recorded" : ""));
          FilterConfig c = config;
          c.threads = threads;
          c.grain = grain;
          c.record_trajectory = record;
          const RunResult r = run_events(c, events);
          EXPECT_TRUE(identical(r.particles, reference.particles));
          EXPECT_TRUE(identical(r.estimate, reference.estimate));
          EXPECT_EQ(r.trajectory.size(), record ? controls : 0u);
          if (record) {
            if (recorded.empty()) recorded = r.trajectory;
            EXPECT_TRUE(identical(r.trajectory, recorded));
          }
        }
      }
    }
  }
}

// The composed motion (engine/motion_run.h) through the filter, for each odometry model and both
// algorithms (FilterDeterminismMotionTest covers thread counts, grains and recording): a save
// and load between scans continues bit for bit (the queue is saved, not drained). FastSLAM
// 1.0's draws differ from the draw per control's; 2.0's prior is the prediction control by
// control's up to rounding, so its particles stay within 1e-9 of it.
TEST(FilterComposedDrawTest, SaveLoadContinuesAndFastSlam2EqualsTheStepwisePrior) {
  const std::vector<Event> events = queued_events();
  for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
    for (const MotionKind kind :
         {MotionKind::kBaileyCar, MotionKind::kUnicycle, MotionKind::kAckermann}) {
      SCOPED_TRACE(std::string(to_string(algorithm)) + ", motion " + std::string(to_string(kind)));
      FilterConfig config = base_config(algorithm, kSanitized ? 20 : 45);
      config.motion.kind = kind;
      config.motion_draw = MotionDraw::kComposed;
      config.grain = 16;
      const RunResult reference = run_events(config, events);
      // Saved with controls queued (mid-way through the 150), loaded, continued.
      {
        Filter first(config);
        feed(first, events, 0, 175);
        std::stringstream saved;
        first.save(saved);
        const std::unique_ptr<Filter> resumed = Filter::load(saved);
        feed(*resumed, events, 175, events.size());
        EXPECT_TRUE(identical(snapshot(*resumed), reference.particles));
      }
      FilterConfig per_control = config;
      per_control.motion_draw = MotionDraw::kEveryControl;
      const RunResult stepwise = run_events(per_control, events);
      if (algorithm == Algorithm::kFastSlam1) {
        EXPECT_FALSE(identical(stepwise.particles, reference.particles));
        FilterConfig other = config;
        other.seed += 1;
        EXPECT_FALSE(identical(run_events(other, events).particles, reference.particles));
      } else {
        for (int k = 0; k < 3; ++k) {
          const std::vector<double>& a = stepwise.particles.columns[k];
          const std::vector<double>& b = reference.particles.columns[k];
          ASSERT_EQ(a.size(), b.size());
          for (std::size_t i = 0; i < a.size(); ++i) {
            const double d = k == 2 ? wrap(a[i] - b[i]) : a[i] - b[i];
            EXPECT_NEAR(d, 0.0, 1e-9 * (1 + std::abs(a[i]))) << "column " << k << ", " << i;
          }
        }
      }
    }
  }
}

// The default draw, kAuto, is the composed motion bit for bit wherever the motion composes
// (FastSLAM with an odometry model) and the draw per control elsewhere; the EKF and the
// no-odometry walks validate with it, and config() keeps what was given.
TEST(FilterComposedDrawTest, AutoComposesWhereTheMotionComposes) {
  EXPECT_EQ(FilterConfig{}.motion_draw, MotionDraw::kAuto);
  const std::vector<Event> events = queued_events();
  for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
    for (const MotionKind kind : {MotionKind::kBaileyCar, MotionKind::kUnicycle,
                                  MotionKind::kAckermann, MotionKind::kBrownian}) {
      SCOPED_TRACE(std::string(to_string(algorithm)) + ", motion " + std::string(to_string(kind)));
      FilterConfig config = base_config(algorithm, 20);
      config.motion.kind = kind;
      config.motion_draw = MotionDraw::kAuto;
      const MotionDraw want =
          kind == MotionKind::kBrownian ? MotionDraw::kEveryControl : MotionDraw::kComposed;
      EXPECT_EQ(resolved_motion_draw(config), want);
      EXPECT_EQ(Filter(config).config().motion_draw, MotionDraw::kAuto);
      FilterConfig explicit_draw = config;
      explicit_draw.motion_draw = want;
      EXPECT_TRUE(identical(run_events(config, events).particles,
                            run_events(explicit_draw, events).particles));
    }
  }
  FilterConfig ekf;
  ekf.algorithm = Algorithm::kEkf;
  EXPECT_NO_THROW(validate(ekf));
  EXPECT_EQ(resolved_motion_draw(ekf), MotionDraw::kEveryControl);
}

// Between scans the recorded trajectory is the weighted mean of each particle moved from the
// run's start by the run's mean displacement (what TrajectoryRecorder::finish computes
// without reading a lane), against a brute-force sum over the particles saved after each scan.
TEST(FilterComposedDrawTest, TrajectoryInsideARunIsTheMeanDisplacementOfItsStart) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(Algorithm::kFastSlam1, 40);
  config.motion_draw = MotionDraw::kComposed;
  config.record_trajectory = true;
  config.threads = 2;
  config.grain = 8;
  const BaileyCarModel model(config.motion.wheelbase);
  const BaileyCarModel::Control sigmas(config.motion.sigma_control[0],
                                       config.motion.sigma_control[1]);
  Filter filter(config);
  // The particles at each pass's start and the controls of the pass.
  struct Start {
    std::vector<double> x, y, theta, log_weight;
    std::vector<ControlStep> controls;
  };
  std::vector<Start> passes(1);
  auto keep = [&](const memory::ParticleStore& p, Start& start) {
    start.x.assign(p.x().begin(), p.x().end());
    start.y.assign(p.y().begin(), p.y().end());
    start.theta.assign(p.theta().begin(), p.theta().end());
    start.log_weight.assign(p.log_weight().begin(), p.log_weight().end());
  };
  keep(filter.particles(), passes[0]);
  const std::size_t events = std::min<std::size_t>(s.events.size(), 400);
  feed(filter, s.events, 0, events, [&](Filter& f, const Event& e) {
    if (e.is_scan) {
      passes.emplace_back();
      keep(f.particles(), passes.back());  // right after a scan: nothing queued, no drain
    } else {
      passes.back().controls.push_back({e.control.u0, e.control.u1, e.dt});
    }
  });
  const std::vector<TrajectoryPoint> got = filter.take_trajectory();
  std::size_t control = 0;
  std::size_t checked = 0;
  std::vector<MotionRun> runs;
  std::vector<Eigen::Vector3d> partial;
  for (const Start& start : passes) {
    compose_runs(model, start.controls, sigmas, runs, partial);
    // Every control of the pass's first run but its last (which reads the drawn poses).
    for (std::size_t k = 0; !runs.empty() && k + 1 < runs[0].count; ++k) {
      long double w = 0, x = 0, y = 0, c = 0, sn = 0;
      const double best = *std::max_element(start.log_weight.begin(), start.log_weight.end());
      for (std::size_t i = 0; i < start.x.size(); ++i) {
        const long double wi = std::exp(static_cast<long double>(start.log_weight[i] - best));
        const double ct = std::cos(start.theta[i]);
        const double st = std::sin(start.theta[i]);
        w += wi;
        x += wi * (start.x[i] + ct * partial[k][0] - st * partial[k][1]);
        y += wi * (start.y[i] + st * partial[k][0] + ct * partial[k][1]);
        c += wi * std::cos(static_cast<long double>(start.theta[i] + partial[k][2]));
        sn += wi * std::sin(static_cast<long double>(start.theta[i] + partial[k][2]));
      }
      const TrajectoryPoint& p = got.at(control + k);
      const double want_x = static_cast<double>(x / w);
      const double want_y = static_cast<double>(y / w);
      const double tol = 1e-10 * (1 + std::abs(want_x) + std::abs(want_y));
      ASSERT_NEAR(p.x, want_x, tol) << "control " << control + k;
      ASSERT_NEAR(p.y, want_y, tol) << "control " << control + k;
      ASSERT_NEAR(wrap(p.theta - static_cast<double>(std::atan2(sn, c))), 0.0, 1e-10);
      ++checked;
    }
    control += start.controls.size();
  }
  EXPECT_EQ(control, got.size());
  EXPECT_GT(checked, got.size() / 2);
}

// ---- 3. Queue independence ----------------------------------------------------------------------

TEST_P(FilterAlgorithmTest, DrainingTheQueueChangesNothing) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(GetParam(), 50);
  config.threads = 2;
  config.grain = 8;
  config.record_trajectory = true;
  // Draining ends a composed run (FilterComposedDrawTest); control by control it changes nothing.
  config.motion_draw = MotionDraw::kEveryControl;
  Filter plain(config);
  feed(plain, s.events, 0, s.events.size());
  Filter drained(config);
  std::vector<TrajectoryPoint> pieces;
  std::size_t k = 0;
  feed(drained, s.events, 0, s.events.size(), [&](Filter& f, const Event& e) {
    if (e.is_scan) return;
    switch (k++ % 3) {
      case 0:
        (void)f.estimate();
        break;
      case 1:
        (void)f.particles();
        break;
      default: {
        std::vector<TrajectoryPoint> t = f.take_trajectory();
        pieces.insert(pieces.end(), t.begin(), t.end());
      }
    }
  });
  std::vector<TrajectoryPoint> rest = drained.take_trajectory();
  pieces.insert(pieces.end(), rest.begin(), rest.end());
  EXPECT_TRUE(identical(snapshot(drained), snapshot(plain)));
  EXPECT_TRUE(identical(drained.estimate(), plain.estimate()));
  EXPECT_TRUE(identical(pieces, plain.take_trajectory()));
}

// ---- 4. Save and load -------------------------------------------------------------------------

TEST_P(FilterAlgorithmTest, SaveLoadContinuesBitIdentically) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(GetParam(), 64);
  config.threads = 2;
  config.record_trajectory = true;
  // Cut once after a scan (empty queue) and once after controls (queued controls are saved);
  // with known ids and with unknown association (the landmarks created and removed).
  for (const bool after_control : {false, true})
    for (const Association association : {Association::kKnown, Association::kMaximumLikelihood}) {
      SCOPED_TRACE(after_control ? "queue not empty" : "queue empty");
      SCOPED_TRACE(to_string(association));
      config.association = association;
      std::size_t cut = s.events.size() / 3;
      while (s.events[cut - 1].is_scan == after_control) ++cut;
      Filter original(config);
      feed(original, s.events, 0, cut);
      const std::string bytes = saved(original);
      std::unique_ptr<Filter> copy = loaded(bytes);
      EXPECT_EQ(copy->config().particles, config.particles);
      EXPECT_EQ(copy->config().algorithm, config.algorithm);
      EXPECT_EQ(copy->config().seed, config.seed);
      EXPECT_EQ(copy->statistics().controls, original.statistics().controls);
      EXPECT_EQ(copy->statistics().scans, original.statistics().scans);
      EXPECT_EQ(copy->statistics().resamples, original.statistics().resamples);
      // Saving the restored filter writes the same bytes.
      EXPECT_TRUE(saved(*copy) == bytes);
      // Loaded to run on one thread with another grain: the same filter.
      FilterConfig execution = config;
      execution.threads = 1;
      execution.grain = 7;
      std::istringstream in(bytes);
      std::unique_ptr<Filter> serial = Filter::load(in, execution);
      EXPECT_EQ(serial->config().threads, 1u);
      EXPECT_EQ(serial->config().grain, 7u);
      feed(original, s.events, cut, s.events.size());
      feed(*copy, s.events, cut, s.events.size());
      feed(*serial, s.events, cut, s.events.size());
      EXPECT_TRUE(identical(snapshot(*serial), snapshot(original)));
      EXPECT_TRUE(identical(serial->estimate(), original.estimate()));
      EXPECT_TRUE(identical(snapshot(*copy), snapshot(original)));
      EXPECT_TRUE(identical(copy->estimate(), original.estimate()));
      EXPECT_TRUE(identical(copy->take_trajectory(), original.take_trajectory()));
      // The counters and the evidence go on as if the filter had never been saved.
      const FilterStatistics a = copy->statistics(), b = original.statistics();
      EXPECT_EQ(a.observations, b.observations);
      EXPECT_EQ(a.resamples, b.resamples);
      EXPECT_EQ(a.landmarks_created, b.landmarks_created);
      EXPECT_EQ(a.landmarks_removed, b.landmarks_removed);
      if (association != Association::kKnown) {
        EXPECT_GT(b.landmarks_created, 0u);
      }
      EXPECT_TRUE(same_bits(a.log_evidence, b.log_evidence));
    }
}

// Offsets in the saved format (engine/internal/state_io.h): magic, version, sizeof(FilterConfig),
// config, eight counters, the log evidence, the landmark variance bound, the clock (time, flag),
// then length-prefixed vectors (the last scan's report of 24-byte entries, queued controls,
// trajectory, known ids, pose covariances), the six columns and the maps.
constexpr std::size_t kConfigAt = 8 + 4 + 8;
constexpr std::size_t kCountersAt = kConfigAt + sizeof(FilterConfig);
constexpr std::size_t kEvidenceAt = kCountersAt + 8 * 8;
constexpr std::size_t kClockAt = kEvidenceAt + 8 + 8;
constexpr std::size_t kReportAt = kClockAt + 8 + 1;

template <class T>
void poke(std::string& bytes, std::size_t at, T value) {
  ASSERT_LE(at + sizeof(T), bytes.size());
  std::memcpy(bytes.data() + at, &value, sizeof(T));
}

template <class T>
T peek(const std::string& bytes, std::size_t at) {
  T value{};
  std::memcpy(&value, bytes.data() + at, sizeof(T));
  return value;
}

TEST(FilterSaveTest, LoadRefusesCorruptAndTruncatedStreams) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(Algorithm::kFastSlam2, 8);
  Filter filter(config);
  feed(filter, s.events, 0, 200);
  filter.predict({3.0, 0.1}, 0.025);  // one queued control
  const std::string good = saved(filter);
  ASSERT_NO_THROW(loaded(good));

  auto refused = [](const std::string& bytes, const std::string& needle) {
    expect_throw_with<std::runtime_error>([&] { loaded(bytes); }, needle);
  };
  refused("", "magic");
  refused("not a filter state at all", "magic");
  {
    std::string b = good;
    b[3] ^= 1;
    refused(b, "magic");
  }
  {
    std::string b = good;
    poke<std::uint32_t>(b, 8, 1);  // the format before unknown association
    refused(b, "version");
  }
  {
    std::string b = good;
    poke<double>(b, kEvidenceAt + 8, kNaN);
    refused(b, "variance bound");
  }
  for (const double evidence : {kNaN, kInf}) {
    std::string b = good;
    poke<double>(b, kEvidenceAt, evidence);
    refused(b, "log evidence");
  }
  {  // -inf is what a scan every particle found impossible leaves.
    std::string b = good;
    poke<double>(b, kEvidenceAt, -kInf);
    EXPECT_TRUE(std::isinf(loaded(b)->statistics().log_evidence));
  }
  {  // Counters 6 and 7: landmarks created and removed.
    std::string b = good;
    poke<std::uint64_t>(b, kCountersAt + 7 * 8, 1);
    refused(b, "removed than created");
  }
  {
    std::string b = good;
    poke<std::uint8_t>(b,
                       kConfigAt + offsetof(FilterConfig, existence) +
                           offsetof(ExistenceConfig, negative_information),
                       2);
    refused(b, "config flag");
  }
  {
    std::string b = good;
    poke<std::uint64_t>(b, 12, sizeof(FilterConfig) + 8);
    refused(b, "incompatible");
  }
  {  // An unusable configuration is a corrupt stream, not a bad argument.
    std::string b = good;
    poke<std::uint32_t>(b, kConfigAt + offsetof(FilterConfig, particles), 0);
    refused(b, "Filter::load");
  }
  {  // A huge particle count must not allocate before the stream shows that many particles.
    std::string b = good;
    poke<std::uint32_t>(b, kConfigAt + offsetof(FilterConfig, particles), 2000000000u);
    refused(b, "Filter::load");
  }
  {
    std::string b = good;
    poke<double>(b, kClockAt, kNaN);
    refused(b, "clock");
  }
  const auto reported = peek<std::uint64_t>(good, kReportAt);
  ASSERT_GT(reported, 0u);
  {  // The first entry's outcome: no such value.
    std::string b = good;
    poke<std::uint8_t>(b, kReportAt + 8 + 4, 7);
    refused(b, "scan report");
  }
  // Vectors whose length prefix is huge: refused without allocating gigabytes.
  const std::size_t kPendingAt = kReportAt + 8 + 24 * reported;
  ASSERT_EQ(peek<std::uint64_t>(good, kPendingAt), 1u);
  for (const std::uint64_t length : {std::uint64_t{1} << 28, std::uint64_t{1} << 33,
                                     std::uint64_t{1} << 40, ~std::uint64_t{0}}) {
    std::string b = good;
    poke<std::uint64_t>(b, kPendingAt, length);
    refused(b, "Filter::load");
  }
  // Every truncation is refused (stride over the long tail to keep the test fast).
  for (std::size_t n = 0; n < good.size(); n += (n < 2048 ? 1 : 61)) {
    SCOPED_TRACE("truncated to " + std::to_string(n) + " of " + std::to_string(good.size()));
    refused(good.substr(0, n), "Filter::load");
    if (::testing::Test::HasFailure()) break;
  }
  // Flipping bytes anywhere never crashes or hangs: the load either succeeds or throws
  // std::runtime_error.
  for (std::size_t at = 0; at < good.size(); at += 7) {
    std::string b = good;
    b[at] = static_cast<char>(b[at] ^ 0x5a);
    try {
      (void)loaded(b);
    } catch (const std::runtime_error&) {
    } catch (const std::exception& e) {
      ADD_FAILURE() << "byte " << at << ": " << e.what();
      break;
    }
  }
}

// ---- 5. Weights and landmark posteriors against independent computations -------------------

// Range-bearing model and Jacobians written out from ALGORITHM.md (sensor at the pose).
struct Linearisation {
  Eigen::Vector2d z_hat;
  Eigen::Matrix2d g_mu;
  Eigen::Matrix<double, 2, 3> g_s;
};

Linearisation linearise(const Eigen::Vector2d& mu, const Eigen::Vector3d& s) {
  const double dx = mu[0] - s[0];
  const double dy = mu[1] - s[1];
  const double q = dx * dx + dy * dy;
  const double sq = std::sqrt(q);
  Linearisation l;
  l.z_hat << sq, wrap(std::atan2(dy, dx) - s[2]);
  l.g_mu << dx / sq, dy / sq, -dy / q, dx / q;
  l.g_s << -dx / sq, -dy / sq, 0, dy / q, -dx / q, -1;
  return l;
}

// ln N(v; 0, S), in long double with an explicit 2x2 inverse.
double log_normal2(const Eigen::Vector2d& v, const Eigen::Matrix2d& s) {
  const long double a = s(0, 0), b = 0.5L * (s(0, 1) + s(1, 0)), d = s(1, 1);
  const long double det = a * d - b * b;
  const long double x = v[0], y = v[1];
  const long double quad = (d * x * x - 2 * b * x * y + a * y * y) / det;
  return static_cast<double>(-std::log(2 * std::numbers::pi_v<long double>) - 0.5L * std::log(det) -
                             0.5L * quad);
}

struct Gaussian2 {
  Eigen::Vector2d mean;
  Eigen::Matrix2d cov;
};

Gaussian2 gaussian_of(const memory::Landmark& lm) {
  Gaussian2 g;
  g.mean << lm.x, lm.y;
  g.cov << lm.sxx, lm.sxy, lm.sxy, lm.syy;
  return g;
}

// The textbook EKF update (eq. 25, non-Joseph form) at pose s; returns ln N(v; 0, Q) (eq. 31).
double dense_ekf_update(Gaussian2& lm, const Eigen::Vector3d& s, const Eigen::Vector2d& z,
                        const Eigen::Matrix2d& r) {
  const Linearisation l = linearise(lm.mean, s);
  Eigen::Vector2d v = z - l.z_hat;
  v[1] = wrap(v[1]);
  const Eigen::Matrix2d q = l.g_mu * lm.cov * l.g_mu.transpose() + r;
  const Eigen::Matrix2d k = lm.cov * l.g_mu.transpose() * q.inverse();
  lm.mean += k * v;
  lm.cov = (Eigen::Matrix2d::Identity() - k * l.g_mu) * lm.cov;
  return log_normal2(v, q);
}

Gaussian2 new_landmark(const Eigen::Vector3d& s, const Eigen::Vector2d& z,
                       const Eigen::Matrix2d& r) {
  const double c = std::cos(s[2] + z[1]);
  const double sn = std::sin(s[2] + z[1]);
  Gaussian2 g;
  g.mean << s[0] + z[0] * c, s[1] + z[0] * sn;
  Eigen::Matrix2d j;
  j << c, -z[0] * sn, sn, z[0] * c;
  g.cov = j * r * j.transpose();
  return g;
}

double log_sum_exp(const std::vector<double>& v) {
  const double m = *std::max_element(v.begin(), v.end());
  long double s = 0;
  for (double x : v) s += std::exp(static_cast<long double>(x - m));
  return m + static_cast<double>(std::log(s));
}

void expect_landmark_near(const memory::Landmark& got, const Gaussian2& want, double tol) {
  EXPECT_NEAR(got.x, want.mean[0], tol);
  EXPECT_NEAR(got.y, want.mean[1], tol);
  const double scale = want.cov.cwiseAbs().maxCoeff();
  EXPECT_NEAR(got.sxx, want.cov(0, 0), tol * scale);
  EXPECT_NEAR(got.sxy, 0.5 * (want.cov(0, 1) + want.cov(1, 0)), tol * scale);
  EXPECT_NEAR(got.syy, want.cov(1, 1), tol * scale);
}

Eigen::Vector3d pose_of(const memory::ParticleStore& store, std::size_t i) {
  return {store.x()[i], store.y()[i], store.theta()[i]};
}

// Observations of `landmarks` (id, position) from `pose`, slightly off the prediction.
std::vector<Observation> observe_from(const Eigen::Vector3d& pose,
                                      const std::vector<std::pair<int, Eigen::Vector2d>>& lms) {
  std::vector<Observation> scan;
  double jitter = 0.05;
  for (const auto& [id, p] : lms) {
    const Eigen::Vector2d d = p - pose.head<2>();
    scan.push_back({d.norm() + jitter, wrap(std::atan2(d[1], d[0]) - pose[2] - 0.2 * jitter), id});
    jitter = -0.7 * jitter;
  }
  return scan;
}

FilterConfig weight_test_config(Algorithm algorithm) {
  FilterConfig c = base_config(algorithm, 5);
  c.seed = 11;
  c.initial_pose[0] = 1.0;
  c.initial_pose[1] = 2.0;
  c.initial_pose[2] = 0.3;
  // Resampling off: the log-weights are only normalised after each scan.
  c.resample = {parallel::ResamplePolicy::When::kEssBelowFraction, 0.0,
                parallel::ResampleScheme::kSystematic};
  c.motion_draw = MotionDraw::kEveryControl;  // the oracles move each particle control by control
  return c;
}

const std::vector<std::pair<int, Eigen::Vector2d>> kTestLandmarks = {
    {0, {12.0, 9.0}}, {1, {15.0, -3.0}}, {2, {6.0, 14.0}}, {7, {20.0, 6.0}}};

// FastSLAM 2.0 without odometry: the velocities' covariance a scan's draw leaves (draw_state)
// follows its particle through resampling. Two particles, resampled whenever N_eff < M: after a
// scan that tells them apart, both are copies of the better one; copies with the same state,
// map and covariance weigh the same at the next scan, so N_eff = M and nothing is resampled.
// A copy that kept its own covariance would weigh otherwise and be resampled again.
// Both no-odometry models (omega and curvature walks).
class FilterNoOdometryTest : public ::testing::TestWithParam<MotionKind> {};

TEST_P(FilterNoOdometryTest, FastSlam2VelocityCovarianceFollowsItsParticle) {
  const std::vector<std::pair<int, Eigen::Vector2d>> landmarks = {{0, {12.0, 9.0}},
                                                                  {1, {15.0, -3.0}}};
  bool checked = false;
  for (std::uint64_t seed = 1; seed <= 20 && !checked; ++seed) {
    FilterConfig c = base_config(Algorithm::kFastSlam2, 2);
    c.seed = seed;
    c.motion.kind = GetParam();
    c.motion.sigma_control[0] = 0.3;
    c.motion.sigma_control[1] = 0.1;  // rad/s or 1/m per step
    c.sensor.sigma_range = 0.01;
    c.sensor.sigma_bearing = 0.001;
    c.initial_pose[3] = 2.0;  // v = 2 m/s along x
    c.resample = {parallel::ResamplePolicy::When::kEssBelowFraction, 1.0,
                  parallel::ResampleScheme::kSystematic};
    Filter filter(c);
    auto scan_at = [&](double x) {
      for (int k = 0; k < 5; ++k) filter.predict({0.0, 0.0}, 0.1);
      filter.observe(observe_from({x, 0.0, 0.0}, landmarks));
    };
    scan_at(1.0);  // new landmarks: equal weights, different draws
    scan_at(2.0);  // tells the particles apart
    const memory::ParticleStore& store = filter.particles();
    const std::uint64_t resamples = filter.statistics().resamples;
    bool copies = resamples == 1;
    for (const auto column : {store.x(), store.y(), store.theta(), store.v(), store.omega()}) {
      copies = copies && column[0] == column[1];
    }
    if (!copies) continue;  // this seed kept both: try the next
    scan_at(3.0);
    EXPECT_EQ(filter.statistics().resamples, resamples) << "seed " << seed;
    checked = true;
  }
  EXPECT_TRUE(checked) << "no seed made both particles copies of one";
}

// Without motion noise every particle follows the scalar model exactly, and the logged controls
// are ignored (they are far from zero here): FastSLAM 1.0's sampling and 2.0's mean
// propagation, on the vectorised lanes, against repeated BrownianModel::predict.
TEST_P(FilterNoOdometryTest, NoiselessRunIsTheScalarModel) {
  for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
    SCOPED_TRACE(std::string(to_string(algorithm)));
    FilterConfig c = base_config(algorithm, 9);
    c.motion.kind = GetParam();
    c.motion.sigma_control[0] = c.motion.sigma_control[1] = 0.0;
    const double start[5] = {1.0, -2.0, 3.0, -1.5, 0.2};  // reversing, turning
    std::copy(start, start + 5, c.initial_pose);
    Filter filter(c);
    Eigen::Matrix<double, 5, 1> want = Eigen::Map<const Eigen::Matrix<double, 5, 1>>(start);
    for (int k = 0; k < 70; ++k) {
      const double dt = 0.05 + 0.001 * k;
      filter.predict({3.0, 0.4}, dt);
      want = GetParam() == MotionKind::kBrownian
                 ? BrownianVelocityModel().predict(want, Eigen::Vector2d::Zero(), dt)
                 : BrownianCurvatureModel().predict(want, Eigen::Vector2d::Zero(), dt);
    }
    const Estimate e = filter.estimate();
    const memory::ParticleStore& store = filter.particles();
    for (std::size_t i = 0; i < store.size(); ++i) {
      const double got[5] = {store.x()[i], store.y()[i], store.theta()[i], store.v()[i],
                             store.omega()[i]};
      for (int k = 0; k < 5; ++k) {
        const double diff = k == 2 ? angle_diff(got[k], want[k]) : got[k] - want[k];
        EXPECT_NEAR(diff, 0.0, 1e-12) << "particle " << i << " component " << k;
      }
    }
    EXPECT_NEAR(e.mean_pose[4], want[4], 1e-12);
  }
}

// Driving a circle (v = 2 m/s, radius 10 m: kappa = 0.1 1/m, constant) among landmarks, known
// association, the speed known at the start, the curvature not: both algorithms recover v and
// kappa for the second half of the lap (a model that took the fifth component for the turn
// rate would settle at 0.2, as the omega walk does on this run).
TEST(FilterNoOdometryCurvatureTest, TracksACircleAndItsCurvature) {
  std::vector<std::pair<int, Eigen::Vector2d>> landmarks;
  for (int k = 0; k < 12; ++k) {
    const double a = 2 * std::numbers::pi * k / 12;
    const double r = k % 2 == 0 ? 16.0 : 5.0;
    landmarks.push_back({k, {r * std::cos(a), 10.0 + r * std::sin(a)}});
  }
  const double v = 2.0, kappa = 0.1, dt = 0.1;
  for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
    SCOPED_TRACE(std::string(to_string(algorithm)));
    FilterConfig c = base_config(algorithm, 30);
    c.motion.kind = MotionKind::kBrownianCurvature;
    c.motion.sigma_control[0] = 0.05;
    c.motion.sigma_control[1] = 0.005;
    c.initial_pose[3] = 2.0;  // the curvature is learnt
    c.initial_pose[4] = 0.0;
    c.sensor.max_range = 1e3;
    c.sensor.field_of_view = 2 * std::numbers::pi;
    Filter filter(c);
    double worst = 0.0;
    const int steps = static_cast<int>(2 * std::numbers::pi / (v * kappa) / dt);  // one lap
    filter.observe(observe_from({0.0, 0.0, 0.0}, landmarks));  // the map anchored at the start
    for (int k = 1; k <= steps; ++k) {
      filter.predict({0.0, 0.0}, dt);
      if (k % 2 != 0) continue;
      const double a = v * kappa * dt * k;  // heading; the centre is (0, 10)
      const Eigen::Vector3d truth(std::sin(a) / kappa, 10.0 - std::cos(a) / kappa, wrap(a));
      filter.observe(observe_from(truth, landmarks));
      const Estimate e = filter.estimate();
      worst = std::max(worst, std::hypot(e.mean_pose[0] - truth[0], e.mean_pose[1] - truth[1]));
      if (k > steps / 2) {
        EXPECT_NEAR(e.mean_pose[3], v, 0.3) << "step " << k;
        EXPECT_NEAR(e.mean_pose[4], kappa, 0.03) << "step " << k;
      }
    }
    // The absolute pose is a gauge (the early scans, before kappa is learnt, leave the map
    // rotated about the start by up to about 0.1 rad, for the omega walk too): bounded loosely.
    EXPECT_LT(worst, 3.0);
  }
}

INSTANTIATE_TEST_SUITE_P(BothWalks, FilterNoOdometryTest,
                         ::testing::Values(MotionKind::kBrownian, MotionKind::kBrownianCurvature),
                         [](const ::testing::TestParamInfo<MotionKind>& p) {
                           return p.param == MotionKind::kBrownian ? "Omega" : "Curvature";
                         });

TEST(FilterWeightTest, FastSlam1MatchesEq31AndDenseEkf) {
  const FilterConfig config = weight_test_config(Algorithm::kFastSlam1);
  Filter filter(config);
  const BaileyCarModel car(config.motion.wheelbase);
  const Eigen::Matrix2d r =
      Eigen::Vector2d(config.sensor.sigma_range * config.sensor.sigma_range,
                      config.sensor.sigma_bearing * config.sensor.sigma_bearing)
          .asDiagonal();
  // Step 0: one control. Each particle's pose is the motion under the control perturbed by the
  // keyed normals of (seed, step 0, particle, kMotion).
  const Control u0{3.0, 0.1};
  filter.predict(u0, 0.1);
  {
    const memory::ParticleStore& store = filter.particles();
    for (std::uint32_t i = 0; i < config.particles; ++i) {
      parallel::RandomStream stream({config.seed, 0, i, parallel::Purpose::kMotion});
      const double n[2] = {stream.normal(), stream.normal()};
      const Eigen::Vector3d want =
          car.sample(Eigen::Vector3d(1.0, 2.0, 0.3), {u0.u0, u0.u1}, 0.1,
                     {config.motion.sigma_control[0], config.motion.sigma_control[1]}, n);
      EXPECT_NEAR((pose_of(store, i) - want).norm(), 0.0, 1e-12) << "particle " << i;
    }
  }
  filter.predict({3.0, 0.05}, 0.1);
  // Step 2: landmarks 0, 1, 2 are new.
  filter.observe(
      observe_from({1.5, 2.1, 0.31}, {kTestLandmarks[0], kTestLandmarks[1], kTestLandmarks[2]}));
  filter.predict({3.0, -0.1}, 0.1);
  filter.predict({3.0, -0.05}, 0.1);
  const Snapshot before = snapshot(filter);
  const double evidence_before = filter.statistics().log_evidence;
  // Step 5: landmarks 2 and 0 again (in that order) and 7 for the first time.
  const std::vector<Observation> scan =
      observe_from({2.6, 2.2, 0.3}, {kTestLandmarks[2], kTestLandmarks[0], kTestLandmarks[3]});
  filter.observe(scan);
  const Snapshot after = snapshot(filter);
  const memory::ParticleStore& store = filter.particles();

  std::vector<double> increments(config.particles);
  std::vector<double> unnormalised(config.particles);
  for (std::size_t i = 0; i < config.particles; ++i) {
    SCOPED_TRACE("particle " + std::to_string(i));
    // FastSLAM 1.0 does not move the pose at a scan.
    for (int k = 0; k < 3; ++k) EXPECT_TRUE(same_bits(after.columns[k][i], before.columns[k][i]));
    const Eigen::Vector3d s = pose_of(store, i);
    // Slots follow first appearance: ids 0, 1, 2 -> slots 0, 1, 2; id 7 -> slot 3.
    Gaussian2 lm2 = gaussian_of(before.maps[i][2].second);
    Gaussian2 lm0 = gaussian_of(before.maps[i][0].second);
    double l = dense_ekf_update(lm2, s, {scan[0].range, scan[0].bearing}, r);
    l += dense_ekf_update(lm0, s, {scan[1].range, scan[1].bearing}, r);
    increments[i] = l;
    unnormalised[i] = before.columns[5][i] + l;
    ASSERT_EQ(after.maps[i].size(), 4u);
    expect_landmark_near(after.maps[i][2].second, lm2, 1e-10);
    expect_landmark_near(after.maps[i][0].second, lm0, 1e-10);
    // Unobserved: copied bit for bit (eq. 22).
    EXPECT_EQ(
        std::memcmp(&after.maps[i][1].second, &before.maps[i][1].second, sizeof(memory::Landmark)),
        0);
    // New: eq. 69-70 at the particle's pose.
    const memory::Landmark& added = after.maps[i][3].second;
    expect_landmark_near(added, new_landmark(s, {scan[2].range, scan[2].bearing}, r), 1e-10);
    EXPECT_EQ(added.id, 7u);
    EXPECT_EQ(added.last_seen, 5);
    EXPECT_EQ(added.log_odds, config.existence.initial);
    EXPECT_EQ(after.maps[i][0].second.log_odds,
              before.maps[i][0].second.log_odds + config.existence.seen);
    EXPECT_EQ(after.maps[i][2].second.last_seen, 5);
    EXPECT_EQ(after.maps[i][1].second.last_seen, 2);
  }
  // The weights differ between particles (the test has teeth) and each changed by its eq. 31
  // sum, up to the common normalisation.
  EXPECT_GT(*std::max_element(increments.begin(), increments.end()) -
                *std::min_element(increments.begin(), increments.end()),
            0.1);
  const double log_sum = log_sum_exp(unnormalised);
  // The evidence grew by this scan's factor: ln sum_i w_i exp(increment_i), w normalised.
  EXPECT_NEAR(filter.statistics().log_evidence - evidence_before,
              log_sum - log_sum_exp(before.columns[5]), 1e-9);
  EXPECT_TRUE(std::isfinite(evidence_before));
  for (std::size_t i = 0; i < config.particles; ++i) {
    EXPECT_NEAR(after.columns[5][i], unnormalised[i] - log_sum, 1e-9) << "particle " << i;
  }
}

TEST(FilterWeightTest, FastSlam2MatchesFoldedEq61ProposalDrawAndDenseEkf) {
  const FilterConfig config = weight_test_config(Algorithm::kFastSlam2);
  Filter filter(config);
  const BaileyCarModel car(config.motion.wheelbase);
  const Eigen::Matrix2d r =
      Eigen::Vector2d(config.sensor.sigma_range * config.sensor.sigma_range,
                      config.sensor.sigma_bearing * config.sensor.sigma_bearing)
          .asDiagonal();
  Eigen::Matrix2d m =
      Eigen::Vector2d(config.motion.sigma_control[0] * config.motion.sigma_control[0],
                      config.motion.sigma_control[1] * config.motion.sigma_control[1])
          .asDiagonal();
  // Steps 0-2: controls; step 3: new landmarks 0 and 1; steps 4-6: controls; step 7: new
  // landmark 2. Both scans draw the pose from the motion prior (no known landmark), so after
  // step 7 the particles' maps differ beyond a rigid motion and their weights will differ.
  for (int k = 0; k < 3; ++k) filter.predict({3.0, 0.1 + 0.05 * k}, 0.1);
  filter.observe(observe_from({1.8, 2.3, 0.33}, {kTestLandmarks[0], kTestLandmarks[1]}));
  for (int k = 0; k < 3; ++k) filter.predict({3.0, -0.1 * k}, 0.1);
  filter.observe(observe_from({2.7, 2.6, 0.35}, {kTestLandmarks[2]}));
  const Snapshot drawn = snapshot(filter);
  // Steps 8-11: controls, whose mean and covariance the test propagates itself.
  const Control controls[4] = {{3.0, -0.2}, {2.5, -0.1}, {3.2, 0.3}, {3.0, 0.4}};
  for (const Control& c : controls) filter.predict(c, 0.1);
  const Snapshot predicted = snapshot(filter);
  std::vector<Eigen::Vector3d> mean(config.particles);
  std::vector<Eigen::Matrix3d> cov(config.particles, Eigen::Matrix3d::Zero());
  for (std::size_t i = 0; i < config.particles; ++i) {
    Eigen::Vector3d s(drawn.columns[0][i], drawn.columns[1][i], drawn.columns[2][i]);
    for (const Control& c : controls) {
      const Eigen::Vector2d u(c.u0, c.u1);
      const Eigen::Matrix3d j = car.jacobian_pose(s, u, 0.1);
      const Eigen::Matrix<double, 3, 2> v = car.jacobian_control(s, u, 0.1);
      cov[i] = j * cov[i] * j.transpose() + v * m * v.transpose();
      s = car.predict(s, u, 0.1);
    }
    mean[i] = s;
    EXPECT_NEAR((pose_of(filter.particles(), i) - s).norm(), 0.0, 1e-12) << "particle " << i;
  }
  // Step 12: landmarks 2 and 0 (in that order) and 7, new.
  const std::vector<Observation> scan =
      observe_from({5.5, 2.7, 0.4}, {kTestLandmarks[2], kTestLandmarks[0], kTestLandmarks[3]});
  filter.observe(scan);
  const Snapshot after = snapshot(filter);

  std::vector<double> increments(config.particles);
  std::vector<double> unnormalised(config.particles);
  for (std::uint32_t i = 0; i < config.particles; ++i) {
    SCOPED_TRACE("particle " + std::to_string(i));
    // The proposal, folded over the known observations; each fold linearises at the current
    // proposal mean; its weight term is ln N(v; 0, G_s Sigma_s G_s^T + G_mu Sigma G_mu^T + R),
    // which for the first fold (Sigma_s = P, mean = s_hat) is exactly eq. 60-61.
    Eigen::Vector3d mu = mean[i];
    Eigen::Matrix3d sigma = cov[i];
    double l = 0;
    for (int k = 0; k < 2; ++k) {
      const int slot = k == 0 ? 2 : 0;
      const Gaussian2 lm = gaussian_of(predicted.maps[i][slot].second);
      const Linearisation lin = linearise(lm.mean, mu);
      Eigen::Vector2d v = Eigen::Vector2d(scan[k].range, scan[k].bearing) - lin.z_hat;
      v[1] = wrap(v[1]);
      const Eigen::Matrix2d q = lin.g_mu * lm.cov * lin.g_mu.transpose() + r;   // eq. 42
      const Eigen::Matrix2d big_l = lin.g_s * sigma * lin.g_s.transpose() + q;  // eq. 60
      l += log_normal2(v, big_l);                                               // eq. 61
      const Eigen::Matrix<double, 3, 2> gain = sigma * lin.g_s.transpose() * big_l.inverse();
      mu += gain * v;  // eq. 49 (Kalman form)
      mu[2] = wrap(mu[2]);
      sigma = sigma - gain * big_l * gain.transpose();  // eq. 48 (Kalman form)
      sigma = 0.5 * (sigma + sigma.transpose()).eval();
    }
    increments[i] = l;
    unnormalised[i] = predicted.columns[5][i] + l;
    // The draw: mean + chol(Sigma_s) n with n from the keyed stream (seed, step 12, i, proposal).
    parallel::RandomStream stream({config.seed, 12, i, parallel::Purpose::kProposal});
    Eigen::Vector3d n;
    for (int k = 0; k < 3; ++k) n[k] = stream.normal();
    const Eigen::LLT<Eigen::Matrix3d> llt(sigma);
    ASSERT_EQ(llt.info(), Eigen::Success);
    Eigen::Vector3d s = mu + llt.matrixL() * n;
    s[2] = wrap(s[2]);
    const Eigen::Vector3d got(after.columns[0][i], after.columns[1][i], after.columns[2][i]);
    EXPECT_NEAR((got - s).norm(), 0.0, 1e-9);
    // The proposal really moved the pose (the measurement pulled on it).
    EXPECT_GT((mu - mean[i]).norm(), 1e-3);
    // Landmarks: the 1.0 update at the drawn pose; the new one initialised there.
    Gaussian2 lm2 = gaussian_of(predicted.maps[i][2].second);
    Gaussian2 lm0 = gaussian_of(predicted.maps[i][0].second);
    dense_ekf_update(lm2, got, {scan[0].range, scan[0].bearing}, r);
    dense_ekf_update(lm0, got, {scan[1].range, scan[1].bearing}, r);
    expect_landmark_near(after.maps[i][2].second, lm2, 1e-10);
    expect_landmark_near(after.maps[i][0].second, lm0, 1e-10);
    expect_landmark_near(after.maps[i][3].second,
                         new_landmark(got, {scan[2].range, scan[2].bearing}, r), 1e-10);
    EXPECT_EQ(std::memcmp(&after.maps[i][1].second, &predicted.maps[i][1].second,
                          sizeof(memory::Landmark)),
              0);
  }
  EXPECT_GT(*std::max_element(increments.begin(), increments.end()) -
                *std::min_element(increments.begin(), increments.end()),
            0.1);
  const double log_sum = log_sum_exp(unnormalised);
  for (std::size_t i = 0; i < config.particles; ++i) {
    EXPECT_NEAR(after.columns[5][i], unnormalised[i] - log_sum, 1e-9) << "particle " << i;
  }
}

// ---- 6. Estimate, 7. trajectory ---------------------------------------------------------------

struct BruteMean {
  double x = 0, y = 0, theta = 0, ess = 0;
  std::size_t best = 0;
  double cov[9] = {};  // (x, y, theta) about the mean, heading differences wrapped
};

BruteMean brute_force_mean(const memory::ParticleStore& store) {
  const std::span<const double> lw = store.log_weight();
  BruteMean out;
  for (std::size_t i = 1; i < lw.size(); ++i) {
    if (lw[i] > lw[out.best]) out.best = i;
  }
  long double w = 0, w2 = 0, x = 0, y = 0, c = 0, s = 0;
  for (std::size_t i = 0; i < lw.size(); ++i) {
    const long double wi = std::exp(static_cast<long double>(lw[i] - lw[out.best]));
    w += wi;
    w2 += wi * wi;
    x += wi * store.x()[i];
    y += wi * store.y()[i];
    c += wi * std::cos(static_cast<long double>(store.theta()[i]));
    s += wi * std::sin(static_cast<long double>(store.theta()[i]));
  }
  out.x = static_cast<double>(x / w);
  out.y = static_cast<double>(y / w);
  out.theta = static_cast<double>(std::atan2(s, c));
  out.ess = static_cast<double>(w * w / w2);
  long double cov[3][3] = {};
  for (std::size_t i = 0; i < lw.size(); ++i) {
    const long double wi = std::exp(static_cast<long double>(lw[i] - lw[out.best]));
    const long double d[3] = {store.x()[i] - static_cast<long double>(out.x),
                              store.y()[i] - static_cast<long double>(out.y),
                              wrap(store.theta()[i] - out.theta)};
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) cov[r][k] += wi * d[r] * d[k];
    }
  }
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) out.cov[3 * r + k] = static_cast<double>(cov[r][k] / w);
  }
  return out;
}

// A straight drive along -x: headings straddle +-pi, where an arithmetic mean would say 0.
Scenario seam_scenario() {
  tools::World world;
  world.start_theta = kPi;
  world.waypoints = {{-60.0, 0.0}, {-120.0, 0.0}};
  for (int k = 0; k < 24; ++k) {
    world.landmarks.push_back({-5.0 * k, (k % 2 == 0 ? 8.0 : -9.0) + 0.3 * k});
  }
  tools::SimConfig sim;
  sim.loops = 1;
  return simulate(std::move(world), sim, 9, 1200);
}

TEST_P(FilterAlgorithmTest, EstimateIsTheBruteForceWeightedMeanAndBestParticle) {
  const Scenario s = seam_scenario();
  FilterConfig config = base_config(GetParam(), 60);
  config.initial_pose[2] = kPi;
  config.threads = 2;
  config.grain = 7;
  config.resample.ess_fraction = 0.3;  // weights stay uneven between resamplings
  Filter filter(config);
  int checked = 0, straddling = 0;
  feed(filter, s.events, 0, s.events.size(), [&](Filter& f, const Event& e) {
    if (!e.is_scan) return;
    const Estimate est = f.estimate();
    const memory::ParticleStore& store = f.particles();
    const BruteMean want = brute_force_mean(store);
    const double scale = 1e-12 * (1 + std::abs(want.x) + std::abs(want.y));
    ASSERT_NEAR(est.mean_pose[0], want.x, scale);
    ASSERT_NEAR(est.mean_pose[1], want.y, scale);
    ASSERT_NEAR(wrap(est.mean_pose[2] - want.theta), 0.0, 1e-12);
    ASSERT_NEAR(est.effective_sample_size, want.ess, 1e-9 * want.ess);
    ASSERT_EQ(est.best_particle, want.best);
    for (int k = 0; k < 9; ++k) {
      ASSERT_NEAR(est.pose_covariance[k], want.cov[k], 1e-9 * (1e-6 + std::abs(want.cov[k])))
          << "entry " << k;
    }
    ASSERT_EQ(est.pose_covariance[1], est.pose_covariance[3]);
    for (int k = 0; k < 3; ++k) {
      const double column = k == 0   ? store.x()[want.best]
                            : k == 1 ? store.y()[want.best]
                                     : store.theta()[want.best];
      ASSERT_TRUE(same_bits(est.best_pose[k], column));
    }
    const memory::LandmarkTree& map = store.map(want.best).tree();
    ASSERT_EQ(est.map.size(), map.size());
    std::size_t j = 0;
    for (const auto [slot, lm] : map) {
      const MapLandmark& got = est.map[j++];
      ASSERT_EQ(got.slot, slot);
      ASSERT_EQ(got.id, lm.id);
      ASSERT_TRUE(same_bits(got.x, lm.x) && same_bits(got.y, lm.y) && same_bits(got.sxx, lm.sxx) &&
                  same_bits(got.sxy, lm.sxy) && same_bits(got.syy, lm.syy));
    }
    ++checked;
    const auto [lo, hi] = std::minmax_element(store.theta().begin(), store.theta().end());
    if (*lo < -3.0 && *hi > 3.0) ++straddling;
    EXPECT_GT(std::abs(est.mean_pose[2]), 3.0);
  });
  EXPECT_GT(checked, 50);
  EXPECT_GT(straddling, 10) << "the headings never straddled the seam: the test lost its teeth";
}

TEST_P(FilterAlgorithmTest, TrajectoryIsTheWeightedMeanAfterEveryControl) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(GetParam(), 40);
  config.threads = 2;
  config.grain = 8;
  config.resample.ess_fraction = 0.3;
  config.record_trajectory = true;
  config.motion_draw = MotionDraw::kEveryControl;  // composed: FilterComposedDrawTest's oracle
  Filter drained(config);
  std::vector<BruteMean> want;
  feed(drained, s.events, 0, s.events.size(), [&](Filter& f, const Event& e) {
    if (!e.is_scan) want.push_back(brute_force_mean(f.particles()));
  });
  const std::vector<TrajectoryPoint> got = drained.take_trajectory();
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t k = 0; k < got.size(); ++k) {
    ASSERT_EQ(got[k].control, k);
    const double tol = 1e-12 * (1 + std::abs(want[k].x) + std::abs(want[k].y));
    ASSERT_NEAR(got[k].x, want[k].x, tol) << "control " << k;
    ASSERT_NEAR(got[k].y, want[k].y, tol) << "control " << k;
    ASSERT_NEAR(wrap(got[k].theta - want[k].theta), 0.0, 1e-12) << "control " << k;
  }
  EXPECT_TRUE(drained.take_trajectory().empty());
  // Without draining: the same points, bit for bit; without recording: none.
  Filter plain(config);
  feed(plain, s.events, 0, s.events.size());
  EXPECT_TRUE(identical(plain.take_trajectory(), got));
  config.record_trajectory = false;
  Filter silent(config);
  feed(silent, s.events, 0, 50);
  EXPECT_TRUE(silent.take_trajectory().empty());
}

TEST(FilterClockTest, TimesSetTheClockAndMayNotGoBackwards) {
  const Scenario& s = loop_scenario();
  Filter filter(base_config(Algorithm::kFastSlam1, 10));
  EXPECT_EQ(filter.estimate().time, 0.0);
  filter.predict(s.events[0].control, 0.25);  // untimed: the clock advances by dt
  EXPECT_EQ(filter.estimate().time, 0.25);
  filter.predict(s.events[0].control, 0.25, -100.0);  // the first time given may be any
  EXPECT_EQ(filter.estimate().time, -100.0);
  filter.predict(s.events[0].control, 0.5);
  EXPECT_EQ(filter.estimate().time, -99.5);
  filter.observe({}, -99.5);  // equal times are fine
  filter.observe({});         // untimed scans leave the clock
  EXPECT_EQ(filter.estimate().time, -99.5);
  const std::string before = saved(filter);
  expect_throw_with<std::invalid_argument>([&] { filter.predict(s.events[0].control, 0.1, -99.6); },
                                           "time goes backwards");
  expect_throw_with<std::invalid_argument>([&] { filter.observe({}, -200.0); },
                                           "time goes backwards");
  expect_throw_with<std::invalid_argument>([&] { filter.observe({}, kNaN); }, "finite");
  expect_throw_with<std::invalid_argument>([&] { filter.predict({}, 0.1, kInf); }, "finite");
  // A bad control with a good time: refused, and the clock is not moved.
  expect_throw_with<std::invalid_argument>(
      [&] {
        filter.predict({kNaN, 0.0}, 0.1, 5.0);
      },
      "finite");
  EXPECT_TRUE(saved(filter) == before) << "a refused call changed the state";
  filter.observe({}, 7.0);
  EXPECT_EQ(filter.estimate().time, 7.0);
  EXPECT_EQ(loaded(saved(filter))->estimate().time, 7.0);  // the clock is saved
  const std::unique_ptr<Filter> copy = loaded(saved(filter));
  EXPECT_THROW(copy->observe({}, 6.0), std::invalid_argument);  // and so is "timed"
}

// The batch form queues exactly what one call per control queues (the saved states are
// equal, bytes for bytes), timed or not, and refuses all or nothing, naming the index.
TEST(FilterBatchPredictTest, EqualsOneCallPerControlAndRefusesAllOrNothing) {
  const Scenario& s = loop_scenario();
  for (const bool timed : {false, true}) {
    Filter one(base_config(Algorithm::kFastSlam1, 10));
    Filter batch(base_config(Algorithm::kFastSlam1, 10));
    std::vector<Control> controls;
    std::vector<double> dts, times;
    double t = 3.0;
    for (const Event& e : s.events) {
      if (!e.is_scan) {
        t += e.dt;
        if (timed) {
          one.predict(e.control, e.dt, t);
        } else {
          one.predict(e.control, e.dt);
        }
        controls.push_back(e.control);
        dts.push_back(e.dt);
        times.push_back(t);
        continue;
      }
      batch.predict(controls, dts,
                    timed ? std::span<const double>(times) : std::span<const double>());
      controls.clear();
      dts.clear();
      times.clear();
      one.observe(e.scan);
      batch.observe(e.scan);
    }
    batch.predict(controls, dts,
                  timed ? std::span<const double>(times) : std::span<const double>());
    ASSERT_TRUE(saved(one) == saved(batch)) << (timed ? "timed" : "untimed");
    // A bad control in the middle, a time going backwards, unequal lengths: nothing queued.
    const std::string before = saved(batch);
    const std::vector<Control> three = {{1.0, 0.0}, {kNaN, 0.0}, {1.0, 0.0}};
    const std::vector<double> dt3 = {0.1, 0.1, 0.1};
    expect_throw_with<std::invalid_argument>([&] { batch.predict(three, dt3); }, "control 1: ");
    const std::vector<Control> good = {{1.0, 0.0}, {1.0, 0.0}, {1.0, 0.0}};
    const std::vector<double> backwards = {1e6, 1e6 + 1, 1e6};
    expect_throw_with<std::invalid_argument>([&] { batch.predict(good, dt3, backwards); },
                                             "control 2: Filter: time goes backwards");
    expect_throw_with<std::invalid_argument>(
        [&] { batch.predict(good, std::span<const double>(dt3).first(2)); }, "durations");
    EXPECT_TRUE(saved(batch) == before) << "a refused batch changed the state";
  }
}

// The landmarks of particle i's map by id.
std::map<std::uint64_t, memory::Landmark> landmarks_by_id(const memory::ParticleStore& store,
                                                          std::size_t i) {
  std::map<std::uint64_t, memory::Landmark> out;
  for (const auto [slot, lm] : store.map(i).tree()) out.emplace(lm.id, lm);
  return out;
}

std::size_t most_likely(const memory::ParticleStore& store) {
  const std::span<const double> lw = store.log_weight();
  return static_cast<std::size_t>(std::max_element(lw.begin(), lw.end()) - lw.begin());
}

Eigen::Matrix2d noise_of(const FilterConfig& c) {
  return Eigen::Vector2d(c.sensor.sigma_range * c.sensor.sigma_range,
                         c.sensor.sigma_bearing * c.sensor.sigma_bearing)
      .asDiagonal();
}

// Known ids, resampling off (so the most likely particle after the scan is the one the report
// was made for): each observation names its id, "new" exactly on first sight, and its distance
// is the scalar EKF's at that particle's pose (FastSLAM 2.0: the drawn one) against the landmark
// as it was before the scan.
TEST_P(FilterAlgorithmTest, AssociationsAreTheMostLikelyParticlesKnownIdsAndDistances) {
  const Scenario& s = loop_scenario();
  FilterConfig config = base_config(GetParam(), 20);
  config.resample.ess_fraction = 0.0;
  Filter filter(config);
  const RangeBearingModel sensor(config.sensor.offset);
  const Eigen::Matrix2d r = noise_of(config);
  EXPECT_TRUE(filter.estimate().associations.empty());
  int scans = 0, associated = 0, fresh = 0;
  for (const Event& e : s.events) {
    if (!e.is_scan || scans++ % 7 != 0 || e.scan.empty()) {
      apply(filter, e);
      continue;
    }
    const std::unique_ptr<Filter> before = loaded(saved(filter));
    filter.observe(e.scan);
    const std::size_t best = most_likely(filter.particles());
    const std::map<std::uint64_t, memory::Landmark> prior =
        landmarks_by_id(before->particles(), best);
    const Eigen::Vector3d pose = pose_of(filter.particles(), best);
    const std::vector<ObservationAssociation> got = filter.estimate().associations;
    ASSERT_EQ(got.size(), e.scan.size());
    for (std::size_t j = 0; j < got.size(); ++j) {
      ASSERT_EQ(got[j].observation, j);
      ASSERT_EQ(got[j].landmark_id, static_cast<std::uint64_t>(e.scan[j].id));
      const auto it = prior.find(got[j].landmark_id);
      if (it == prior.end()) {
        ASSERT_EQ(got[j].outcome, AssociationOutcome::kNew);
        ASSERT_EQ(got[j].mahalanobis2, kInf);
        ++fresh;
        continue;
      }
      ASSERT_EQ(got[j].outcome, AssociationOutcome::kAssociated);
      const LandmarkGaussian lm = to_gaussian(it->second);
      const double want = evaluate_observation(sensor, lm, Pose(pose[0], pose[1], pose[2]),
                                               {e.scan[j].range, wrap(e.scan[j].bearing)}, r)
                              .mahalanobis2;
      ASSERT_NEAR(got[j].mahalanobis2, want, 1e-9 * (1.0 + want)) << "observation " << j;
      ++associated;
    }
  }
  EXPECT_GT(associated, kSanitized ? 50 : 100);
  EXPECT_GT(fresh, 10);
}

// ---- 8, 9. Accuracy on Bailey's webmap --------------------------------------------------------

struct Accuracy {
  double pose_rmse = 0;      // m, weighted-mean position vs truth over every control
  double max_error = 0;      // m, the largest of those errors
  double landmark_rmse = 0;  // m, the best particle's map vs the true landmarks (by id)
  double landmark_sd = 0;    // m, median of sqrt((sxx + syy) / 2) over the best map
  std::size_t landmarks = 0;  // in the best particle's reported map
};

Accuracy webmap_accuracy(const tools::World& world, const tools::SimConfig& sim,
                         Algorithm algorithm, std::uint32_t particles, std::uint64_t seed,
                         Association association = Association::kKnown,
                         double loop_closure_reach = LoopClosureConfig{}.reach) {
  FilterConfig config;
  config.loop_closure.reach = loop_closure_reach;
  config.algorithm = algorithm;
  config.association = association;
  config.particles = particles;
  config.seed = seed;
  config.threads = 2;
  config.record_trajectory = true;
  config.sensor.sigma_range = sim.sigma_range;
  config.sensor.sigma_bearing = sim.sigma_bearing;
  config.motion.sigma_control[0] = sim.sigma_v;
  config.motion.sigma_control[1] = sim.sigma_steer;
  config.motion.wheelbase = sim.wheelbase;
  Filter filter(config);
  tools::Simulator simulator(world, sim, seed);
  tools::SimStep step;
  std::vector<tools::TruePose> truth;
  std::vector<Observation> scan;
  while (simulator.next(step)) {
    filter.predict({step.speed, step.steer}, step.dt);
    truth.push_back(step.truth);
    if (step.has_scan) {
      scan.clear();
      for (const tools::SimObservation& z : step.scan) {
        scan.push_back({z.range, z.bearing, static_cast<std::int64_t>(z.landmark)});
      }
      filter.observe(scan);
    }
  }
  const std::vector<TrajectoryPoint> trajectory = filter.take_trajectory();
  EXPECT_EQ(trajectory.size(), truth.size());
  Accuracy a;
  double sum = 0;
  for (std::size_t k = 0; k < trajectory.size(); ++k) {
    const double e2 =
        std::pow(trajectory[k].x - truth[k].x, 2) + std::pow(trajectory[k].y - truth[k].y, 2);
    sum += e2;
    a.max_error = std::max(a.max_error, std::sqrt(e2));
  }
  a.pose_rmse = std::sqrt(sum / static_cast<double>(trajectory.size()));
  const Estimate e = filter.estimate();
  if (association == Association::kKnown) {
    double lm = 0;
    for (const MapLandmark& l : e.map) {
      const tools::Point& p = world.landmarks.at(l.id);
      lm += std::pow(l.x - p.x, 2) + std::pow(l.y - p.y, 2);
    }
    a.landmark_rmse = std::sqrt(lm / static_cast<double>(e.map.size()));
  } else {
    const tools::TruthIndex index(world.landmarks);
    a.landmark_rmse = tools::score_map(e.map, world.landmarks, index, {}, 5.0).rmse_m;
  }
  a.landmarks = e.map.size();
  std::vector<double> sd;
  for (const MapLandmark& l : e.map) sd.push_back(std::sqrt(0.5 * (l.sxx + l.syy)));
  std::nth_element(sd.begin(), sd.begin() + sd.size() / 2, sd.end());
  a.landmark_sd = sd[sd.size() / 2];
  EXPECT_GE(e.map.size(), 30u);
  return a;
}

struct Summary {
  double mean = 0, sd = 0, max = 0;
};

Summary summarise(const std::vector<double>& v) {
  Summary s;
  for (double x : v) s.mean += x / static_cast<double>(v.size());
  for (double x : v) s.sd += (x - s.mean) * (x - s.mean);
  s.sd = v.size() > 1 ? std::sqrt(s.sd / static_cast<double>(v.size() - 1)) : 0.0;
  s.max = *std::max_element(v.begin(), v.end());
  return s;
}

using testing::webmap;

// Measured (seeds 1..10, M = 100, threads 2, Release; the default composed motion): FS1 pose
// RMSE 5.1 +- 1.9 m (max 7.5), landmark RMSE 5.1 m; FS2 6.4 +- 2.9 m (max 12.3), landmark
// 6.3 m. Moved control by control FS1 gives 6.7 +- 2.5 m. Over seeds 1..30 (per control): FS1 6.9,
// FS2 6.3 m, and an EKF-SLAM on the same data 4.5 m. Most of the error is a rigid drift of the
// whole map (after a best rigid alignment the landmark RMSE is about 2 m): FastSLAM's particles
// descend from one ancestor well before the loop closes, so the first loop's drift is never
// corrected. Mutations of engine/filter.cc measured on these seeds: FS2 fold innovation negated
// -> 4e8 m; G_mu transposed -> NaN weights; bearing sign flipped -> 125 / 324 m; FS2 covariance
// never reset -> 114 m; FS1 weights dropped -> 11.1 m; landmarks never updated -> 9.2 / 8.1 m
// (below the RMSE bound; caught by the landmark spread, 0.37 m instead of 0.024 m, and by the
// dense-EKF oracle above). A broken proposal that degenerates to the motion prior is caught by
// the M = 1 test below, not here (7.2 m at M = 100: the proposal barely narrows the prior at
// Bailey's noise levels).
TEST(FilterAccuracyTest, BaileyWebmapKnownAssociation) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const tools::World world = webmap(shared);
  const tools::SimConfig sim;
  const int seeds = kSanitized ? 2 : 10;
  for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
    std::vector<double> pose, landmarks;
    for (int seed = 1; seed <= seeds; ++seed) {
      const Accuracy a = webmap_accuracy(world, sim, algorithm, 100, seed);
      pose.push_back(a.pose_rmse);
      landmarks.push_back(a.landmark_rmse);
      // Per seed: the worst of 30 seeds measured was 14.7 m.
      EXPECT_LT(a.pose_rmse, 20.0) << to_string(algorithm) << " seed " << seed;
      EXPECT_LT(a.landmark_rmse, 20.0) << to_string(algorithm) << " seed " << seed;
      // Each landmark is seen many times: its posterior is far tighter than one sighting's.
      EXPECT_LT(a.landmark_sd, 0.1) << to_string(algorithm) << " seed " << seed;
    }
    const Summary p = summarise(pose);
    const Summary l = summarise(landmarks);
    std::cout << "webmap " << to_string(algorithm) << " M=100 over " << seeds
              << " seeds: pose RMSE " << p.mean << " +- " << p.sd << " m (max " << p.max
              << "), landmark RMSE " << l.mean << " +- " << l.sd << " m\n";
    if (!kSanitized) {
      // The mean over 10 seeds has a standard error of about 0.9 m.
      EXPECT_LT(p.mean, 10.0) << to_string(algorithm);
      EXPECT_LT(l.mean, 10.0) << to_string(algorithm);
      EXPECT_GT(p.mean, 1.0) << to_string(algorithm) << ": too good to be true (truth leaking?)";
    }
  }
}

// Paper fig. 22: with one particle, FastSLAM 1.0 never corrects its pose (it is dead reckoning
// with a map), while 2.0 draws the pose from a proposal that includes the measurements. With
// the measurement noise ten times lower (0.01 m, 0.1 deg), measured over seeds 1..10: FS2 M=1
// pose RMSE 5.4 +- 1.9 m, FS1 M=1 16.0 +- 6.6 m (13.5 +- 4.7 m moved control by control). Without
// the fold (proposal = motion prior) FS2 M=1 gives 14.2 m.
TEST(FilterAccuracyTest, FastSlam2WithOneParticleStaysBoundedWhereFastSlam1Drifts) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const tools::World world = webmap(shared);
  tools::SimConfig sim;
  sim.sigma_range *= 0.1;
  sim.sigma_bearing *= 0.1;
  const int seeds = kSanitized ? 2 : 10;
  std::vector<double> fs1, fs2, fs2_max;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Accuracy a1 = webmap_accuracy(world, sim, Algorithm::kFastSlam1, 1, seed);
    const Accuracy a2 = webmap_accuracy(world, sim, Algorithm::kFastSlam2, 1, seed);
    fs1.push_back(a1.pose_rmse);
    fs2.push_back(a2.pose_rmse);
    fs2_max.push_back(a2.max_error);
    EXPECT_LT(a2.pose_rmse, 12.0) << "seed " << seed;
  }
  const Summary s1 = summarise(fs1);
  const Summary s2 = summarise(fs2);
  std::cout << "webmap M=1, measurement noise x0.1, " << seeds << " seeds: FS1 pose RMSE "
            << s1.mean << " +- " << s1.sd << " m, FS2 " << s2.mean << " +- " << s2.sd
            << " m (largest error " << summarise(fs2_max).max << " m)\n";
  if (!kSanitized) {
    EXPECT_LT(s2.mean, 8.0);
    EXPECT_GT(s1.mean, 1.6 * s2.mean);
  }
}

// ---- 10^4 particles ---------------------------------------------------------------------------

// Nodes of one map of `k` landmarks in slots 0..k-1 (an upper bound for the default tree).
std::int64_t nodes_of_dense_map(std::size_t k) {
  using Tree = memory::LandmarkTree;
  std::int64_t level = static_cast<std::int64_t>((k + Tree::kLeafWidth - 1) / Tree::kLeafWidth);
  std::int64_t total = level;
  while (level > 1) {
    level = (level + Tree::kInnerWidth - 1) / Tree::kInnerWidth;
    total += level;
  }
  return total + 1;
}

TEST(FilterScaleTest, TenThousandParticles) {
  const Scenario& s = loop_scenario();
  for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
    SCOPED_TRACE(std::string(to_string(algorithm)));
    FilterConfig config = base_config(algorithm, kSanitized ? 2000 : 10000);
    config.threads = 2;
    config.grain = 64;
    config.resample.when = parallel::ResamplePolicy::When::kEveryStep;
    Filter filter(config);
    std::size_t landmarks = 0;
    std::int64_t peak = 0;
    const std::size_t end = kSanitized ? s.events.size() / 3 : s.events.size();
    feed(filter, s.events, 0, end, [&](Filter& f, const Event& e) {
      if (!e.is_scan) return;
      for (const Observation& o : e.scan) {
        landmarks = std::max(landmarks, static_cast<std::size_t>(o.id) + 1);
      }
      const FilterStatistics st = f.statistics();
      peak = std::max(peak, st.live_nodes);
      // Every map is at most a full tree (so, with M maps, no node leaks: the maps a scan
      // replaces, about M x (1 + observations) nodes per scan, must be freed for this to hold
      // over 100 scans); at least one map's leaves are alive.
      const std::size_t known = f.particles().map(0).size();
      ASSERT_LE(st.live_nodes,
                static_cast<std::int64_t>(config.particles) * nodes_of_dense_map(known));
      ASSERT_GE(st.live_nodes,
                static_cast<std::int64_t>((known + memory::LandmarkTree::kLeafWidth - 1) /
                                          memory::LandmarkTree::kLeafWidth));
      ASSERT_GT(st.live_bytes, 0);
    });
    const Estimate e = filter.estimate();
    const tools::TruePose& truth = s.truth.at(filter.statistics().controls - 1);
    EXPECT_LT(std::hypot(e.mean_pose[0] - truth.x, e.mean_pose[1] - truth.y), 3.0);
    const FilterStatistics st = filter.statistics();
    EXPECT_EQ(st.resamples, st.scans);
    std::cout << to_string(algorithm) << " M=" << config.particles << ": " << st.scans
              << " scans, peak live nodes " << peak << ", final " << st.live_nodes << " ("
              << st.live_bytes << " bytes)\n";
  }
}

// ---- 11. Unknown data association (ML, DAS), negative information, the spatial index ----------

// The loop world with every landmark doubled: a twin 1.5 m away in a random direction, so two
// landmarks are as close as a few standard deviations of a far observation (0.5 m at 30 m).
const Scenario& ambiguous_scenario() {
  static const Scenario scenario = [] {
    tools::World world = tools::make_loop_world(240.0, 12.0, 12.0, 10.0, 4);
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<double> angle(-kPi, kPi);
    const std::size_t n = world.landmarks.size();
    for (std::size_t i = 0; i < n; ++i) {
      const double a = angle(rng);
      world.landmarks.push_back(
          {world.landmarks[i].x + 1.5 * std::cos(a), world.landmarks[i].y + 1.5 * std::sin(a)});
    }
    return simulate(std::move(world), tools::SimConfig{}, 6, kSanitized ? 600 : 2500);
  }();
  return scenario;
}

struct MapRun {
  double pose_rmse = 0;
  tools::MapScore map;
  std::size_t observed = 0;  // true landmarks observed at least once
};

// Runs the whole scenario and scores the weighted-mean path and the best map (paired with the
// truth within 2 m).
MapRun run_and_score(const FilterConfig& config, const Scenario& s) {
  FilterConfig c = config;
  c.record_trajectory = true;
  Filter filter(c);
  std::unique_ptr<bool[]> flags(new bool[s.world.landmarks.size()]());
  const std::span<bool> observed(flags.get(), s.world.landmarks.size());
  feed(filter, s.events, 0, s.events.size(), [&](Filter&, const Event& e) {
    for (const Observation& o : e.scan) {
      if (o.id >= 0 && static_cast<std::size_t>(o.id) < observed.size()) observed[o.id] = true;
    }
  });
  MapRun r;
  const std::vector<TrajectoryPoint> path = filter.take_trajectory();
  double se = 0;
  for (const TrajectoryPoint& p : path) {
    const tools::TruePose& t = s.truth.at(p.control);
    se += (p.x - t.x) * (p.x - t.x) + (p.y - t.y) * (p.y - t.y);
  }
  r.pose_rmse = std::sqrt(se / static_cast<double>(path.size()));
  const tools::TruthIndex index(s.world.landmarks);
  r.map = tools::score_map(filter.estimate().map, s.world.landmarks, index, observed, 2.0);
  r.observed = static_cast<std::size_t>(std::count(observed.begin(), observed.end(), true));
  return r;
}

// Known-association scenarios carry clutter ids; these tests use the unknown modes only.
struct UnknownCase {
  Algorithm algorithm;
  Association association;
};

class FilterUnknownAssociationTest : public ::testing::TestWithParam<UnknownCase> {
 protected:
  FilterConfig config(std::uint32_t particles) const {
    FilterConfig c = base_config(GetParam().algorithm, particles);
    c.association = GetParam().association;
    return c;
  }
};

std::string unknown_case_name(const ::testing::TestParamInfo<UnknownCase>& param) {
  return std::string(to_string(param.param.algorithm)) + "_" +
         std::string(to_string(param.param.association));
}

INSTANTIATE_TEST_SUITE_P(
    AllModes, FilterUnknownAssociationTest,
    ::testing::Values(UnknownCase{Algorithm::kFastSlam1, Association::kMaximumLikelihood},
                      UnknownCase{Algorithm::kFastSlam1, Association::kDataAssociationSampling},
                      UnknownCase{Algorithm::kFastSlam2, Association::kMaximumLikelihood},
                      UnknownCase{Algorithm::kFastSlam2, Association::kDataAssociationSampling}),
    unknown_case_name);

// Every particle's spatial index holds exactly its map's (slot, mean) pairs, and its disc and
// footprint queries return exactly what brute force over the map returns: checked along a run
// with clutter, where landmarks are created, moved by updates, removed by negative information,
// and shared and path-copied by resampling.
// Unknown association on the cluttered loop, resampling off: every observation of the most
// likely particle either updated a landmark its map held before the scan (at the distance the
// scalar terms give, FastSLAM 1.0; within the gate, 2.0) or started the landmark the map now
// holds under the id (scan step) 2^20 + j; a new one reports the nearest candidate it left,
// which for FastSLAM 1.0 is the brute-force minimum over the map of the pairs the association
// may consider (within the gate; ML: no less likely than a new landmark).
TEST_P(FilterUnknownAssociationTest, AssociationsAreTheMostLikelyParticlesChoices) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(20);
  c.resample.ess_fraction = 0.0;
  Filter filter(c);
  const RangeBearingModel sensor(c.sensor.offset);
  const Eigen::Matrix2d r = noise_of(c);
  const bool fs1 = c.algorithm == Algorithm::kFastSlam1;
  const bool ml = c.association == Association::kMaximumLikelihood;
  int scans = 0, associated = 0, fresh = 0, fresh_near = 0;
  for (const Event& e : s.events) {
    if (!e.is_scan || scans++ % 5 != 0 || e.scan.empty()) {
      apply(filter, e);
      continue;
    }
    const FilterStatistics stats = filter.statistics();
    const std::uint64_t scan_step = stats.controls + stats.scans;
    const std::unique_ptr<Filter> before = loaded(saved(filter));
    filter.observe(e.scan);
    const std::size_t best = most_likely(filter.particles());
    const memory::ParticleStore& was = before->particles();
    const std::map<std::uint64_t, memory::Landmark> prior = landmarks_by_id(was, best);
    const std::map<std::uint64_t, memory::Landmark> now = landmarks_by_id(filter.particles(), best);
    const Pose pose(was.x()[best], was.y()[best], was.theta()[best]);
    const std::vector<ObservationAssociation> got = filter.estimate().associations;
    ASSERT_EQ(got.size(), e.scan.size());
    std::set<std::uint64_t> taken;
    for (std::size_t j = 0; j < got.size(); ++j) {
      const Eigen::Vector2d z(e.scan[j].range, wrap(e.scan[j].bearing));
      ASSERT_EQ(got[j].observation, j);
      if (got[j].outcome == AssociationOutcome::kAssociated) {
        const auto it = prior.find(got[j].landmark_id);
        ASSERT_NE(it, prior.end()) << "observation " << j << " names no landmark of the map";
        ASSERT_TRUE(taken.insert(got[j].landmark_id).second) << "a landmark taken twice";
        ASSERT_LE(got[j].mahalanobis2, c.gating.gate * (1 + 1e-6));
        if (fs1) {
          const double want =
              evaluate_observation(sensor, to_gaussian(it->second), pose, z, r).mahalanobis2;
          ASSERT_NEAR(got[j].mahalanobis2, want, 1e-6 * (1.0 + want)) << "observation " << j;
        }
        ++associated;
        continue;
      }
      ASSERT_EQ(got[j].outcome, AssociationOutcome::kNew);
      ASSERT_EQ(got[j].landmark_id, scan_step * (std::uint64_t{1} << 20) + j);
      ASSERT_TRUE(now.contains(got[j].landmark_id)) << "the new landmark is not in the map";
      ++fresh;
      if (got[j].mahalanobis2 != kInf) ++fresh_near;
      if (!fs1) continue;
      double nearest = kInf;
      for (const auto& [id, lm] : prior) {
        const LandmarkObservation t = evaluate_observation(sensor, to_gaussian(lm), pose, z, r);
        if (t.mahalanobis2 > c.gating.gate || (ml && t.log_likelihood < c.log_new_landmark)) {
          continue;
        }
        nearest = std::min(nearest, t.mahalanobis2);
      }
      if (nearest == kInf) {
        ASSERT_EQ(got[j].mahalanobis2, kInf) << "observation " << j;
      } else {
        ASSERT_NEAR(got[j].mahalanobis2, nearest, 1e-6 * (1.0 + nearest)) << "observation " << j;
      }
    }
  }
  EXPECT_GT(associated, kSanitized ? 50 : 100);
  EXPECT_GT(fresh, 20);
  if (!ml && !kSanitized) {  // the sanitizers' shorter run may hold no such draw
    EXPECT_GT(fresh_near, 0) << "sampling never chose new beside a candidate";
  }
}

TEST_P(FilterUnknownAssociationTest, SpatialIndexStaysExactAgainstBruteForce) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(24);
  c.threads = 2;
  c.grain = 5;
  c.resample.when = parallel::ResamplePolicy::When::kEveryStep;
  Filter filter(c);
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> coordinate(-60.0, 60.0);
  std::size_t scans = 0, checked = 0;
  feed(filter, s.events, 0, s.events.size(), [&](Filter& f, const Event& event) {
    if (!event.is_scan || ++scans % 25 != 0) return;
    const memory::ParticleStore& store = f.particles();
    for (std::size_t i = 0; i < store.size(); ++i) {
      const memory::LandmarkTree& map = store.map(i).tree();
      const memory::SpatialIndex& index = store.map(i).index();
      std::vector<memory::SpatialEntry> truth, got;
      for (const auto [slot, lm] : map) {
        // The extent: the covariance's largest eigenvalue, rounded up to a float (the gate
        // relies on it never being below; the EKF updates move the mean with the covariance).
        const double half_gap = 0.5 * (lm.sxx - lm.syy);
        const double largest =
            0.5 * (lm.sxx + lm.syy) + std::sqrt(half_gap * half_gap + lm.sxy * lm.sxy);
        const memory::SpatialEntry* stored = nullptr;
        index.within(lm.x, lm.y, 0.0, [&](const memory::SpatialEntry& e) {
          if (e.slot == slot) stored = &e;
        });
        ASSERT_NE(stored, nullptr) << "slot " << slot << " of particle " << i;
        EXPECT_GE(static_cast<double>(stored->extent), largest) << "slot " << slot;
        EXPECT_LE(static_cast<double>(stored->extent), largest * (1.0 + 1e-6)) << "slot " << slot;
        truth.push_back({slot, stored->extent, lm.x, lm.y});
      }
      index.for_each([&](const memory::SpatialEntry& e) { got.push_back(e); });
      auto by_slot = [](const memory::SpatialEntry& a, const memory::SpatialEntry& b) {
        return a.slot < b.slot;
      };
      std::sort(got.begin(), got.end(), by_slot);
      ASSERT_EQ(got, truth) << "particle " << i << " after scan " << scans;
      for (int q = 0; q < 4; ++q) {
        const double x = coordinate(rng), y = coordinate(rng), radius = 4.0 + 10.0 * q;
        const double heading = coordinate(rng) / 10.0;
        std::vector<memory::Slot> in_disc, in_view, brute_disc, brute_view;
        index.within(x, y, radius,
                     [&](const memory::SpatialEntry& e) { in_disc.push_back(e.slot); });
        index.in_footprint(x, y, heading, radius, 2.0,
                           [&](const memory::SpatialEntry& e) { in_view.push_back(e.slot); });
        for (const memory::SpatialEntry& e : truth) {
          const double dx = e.x - x, dy = e.y - y;
          if (dx * dx + dy * dy > radius * radius) continue;
          brute_disc.push_back(e.slot);
          if ((dx == 0 && dy == 0) ||
              std::abs(std::remainder(std::atan2(dy, dx) - heading, 2 * kPi)) <= 1.0) {
            brute_view.push_back(e.slot);
          }
        }
        std::sort(in_disc.begin(), in_disc.end());
        std::sort(in_view.begin(), in_view.end());
        ASSERT_EQ(in_disc, brute_disc);
        ASSERT_EQ(in_view, brute_view);
        ++checked;
      }
    }
  });
  EXPECT_GT(checked, 100u);
  EXPECT_GT(filter.statistics().landmarks_removed, 100u) << "removal untested";
  std::cout << "landmarks created " << filter.statistics().landmarks_created << ", removed "
            << filter.statistics().landmarks_removed << "\n";
}

TEST_P(FilterUnknownAssociationTest, BitIdenticalForAnyThreadCountAndGrain) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(kSanitized ? 24 : 64);
  c.record_trajectory = true;
  // Twin merging off and on; a detection model with false alarms (sampling's missed detections).
  for (const auto& [merge_gate, detection] :
       {std::pair{0.0, DetectionConfig{}}, std::pair{9.21, DetectionConfig{}},
        std::pair{0.0, DetectionConfig{0.8, 1e-3}}}) {
    c.loop_closure.merge_gate = merge_gate;
    c.detection = detection;
    c.threads = 1;
    c.grain = FilterConfig{}.grain;
    const RunResult reference = run_scenario(c, s);
    for (const auto& [threads, grain] :
         {std::pair<unsigned, std::size_t>{2, 1}, {2, 7}, {2, 64}}) {
      SCOPED_TRACE("merge gate " + std::to_string(merge_gate) + ", P_D " +
                   std::to_string(detection.probability) + ", threads " + std::to_string(threads) +
                   ", grain " + std::to_string(grain));
      c.threads = threads;
      c.grain = grain;
      expect_same_run(run_scenario(c, s), reference);
    }
  }
}

// Twin merging (LoopClosureConfig::merge_gate) in every mode's pass, FastSLAM 1.0 ML's lazy
// choice included: it changes the run, and a loaded state continues it bit for bit (its thread
// counts: BitIdenticalForAnyThreadCountAndGrain).
TEST_P(FilterUnknownAssociationTest, TwinMergingChangesTheRunAndSurvivesALoad) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(kSanitized ? 24 : 64);
  c.threads = 2;
  c.existence.confirm_at = 2.0;  // twins confirmed at their second sighting: this loop has some
  const RunResult unmerged = run_scenario(c, s);
  c.loop_closure.merge_gate = 9.21;
  const RunResult merged = run_scenario(c, s);
  EXPECT_FALSE(identical(merged.particles, unmerged.particles)) << "no twin was merged";
  std::size_t cut = s.events.size() / 2;
  while (!s.events[cut - 1].is_scan) ++cut;
  Filter original(c);
  feed(original, s.events, 0, cut);
  std::unique_ptr<Filter> copy = loaded(saved(original));
  feed(original, s.events, cut, s.events.size());
  feed(*copy, s.events, cut, s.events.size());
  EXPECT_TRUE(identical(snapshot(*copy), snapshot(original)));
  EXPECT_TRUE(identical(copy->estimate(), original.estimate()));
}

TEST_P(FilterUnknownAssociationTest, SaveLoadContinuesBitIdentically) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(32);
  c.threads = 2;
  c.record_trajectory = true;
  std::size_t cut = s.events.size() / 2;
  while (!s.events[cut - 1].is_scan) ++cut;
  Filter original(c);
  feed(original, s.events, 0, cut);
  const std::string bytes = saved(original);
  std::unique_ptr<Filter> copy = loaded(bytes);
  EXPECT_TRUE(saved(*copy) == bytes);
  // Corrupt maps (slots, positions, counts) load or are refused; nothing else happens.
  for (std::size_t at = 0; at < bytes.size(); at += kSanitized ? 1999 : 97) {
    std::string b = bytes;
    b[at] = static_cast<char>(b[at] ^ 0x5a);
    try {
      (void)loaded(b);
    } catch (const std::runtime_error&) {
    }
  }
  feed(original, s.events, cut, s.events.size());
  feed(*copy, s.events, cut, s.events.size());
  EXPECT_TRUE(identical(snapshot(*copy), snapshot(original)));
  EXPECT_TRUE(identical(copy->estimate(), original.estimate()));
  EXPECT_TRUE(identical(copy->take_trajectory(), original.take_trajectory()));
}

TEST_P(FilterUnknownAssociationTest, RefusedInputLeavesTheFilterExactlyAsItWas) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(16);
  Filter filter(c);
  Filter twin(c);
  const std::size_t cut = s.events.size() / 2;
  feed(filter, s.events, 0, cut);
  feed(twin, s.events, 0, cut);
  // An empty scan is a valid scan (every landmark in view is missed).
  filter.observe({});
  twin.observe({});
  std::vector<Observation> bad = {{10.0, 0.1, -1}, {kNaN, 0.2, -1}};
  expect_throw_with<std::invalid_argument>([&] { filter.observe(bad); }, "observation 1");
  bad[1] = {-2.0, 0.0, -1};
  expect_throw_with<std::invalid_argument>([&] { filter.observe(bad); }, "range");
  bad[1] = {2.0, kInf, -1};
  expect_throw_with<std::invalid_argument>([&] { filter.observe(bad); }, "bearing");
  EXPECT_TRUE(identical(snapshot(filter), snapshot(twin)));
  feed(filter, s.events, cut, s.events.size());
  feed(twin, s.events, cut, s.events.size());
  EXPECT_TRUE(identical(snapshot(filter), snapshot(twin)));
}

// Clutter (one false alarm per scan on average): negative information removes most of the
// landmarks it starts. Measured (seed 42, M = 50, release): see the printed counts.
TEST_P(FilterUnknownAssociationTest, NegativeInformationRemovesMostClutter) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(kSanitized ? 16 : 50);
  c.threads = 2;
  c.existence.confirm_at = -1e300;  // every landmark reported: removal alone is measured
  const MapRun with = run_and_score(c, s);
  c.existence.negative_information = false;
  const MapRun without = run_and_score(c, s);
  std::cout << unknown_case_name({GetParam(), 0}) << ": clutter 1/scan, spurious landmarks "
            << with.map.spurious << " with negative information, " << without.map.spurious
            << " without; missing " << with.map.missing << " / " << without.map.missing << " of "
            << with.observed << "; pose RMSE " << with.pose_rmse << " / " << without.pose_rmse
            << " m\n";
  EXPECT_GT(without.map.spurious, 20u);  // the clutter did start landmarks
  EXPECT_LT(with.map.spurious * 5, without.map.spurious);
  EXPECT_LE(with.map.missing * 10, with.observed);  // true landmarks survive
}

// Provisional landmarks (log-odds below confirm_at) are left out of the reported map, and the
// rule changes nothing else but what reads it by design (loop closure, which this loop does not
// close, and twin merging, off here): the run is bit for bit the one that reports every landmark,
// whose map filtered by the rule is the reported one. On the cluttered loop, the rule keeps most
// false alarms out of the map and no true landmark.
TEST_P(FilterUnknownAssociationTest, ProvisionalLandmarksStayOutOfTheReportedMap) {
  const Scenario& s = clutter_scenario();
  FilterConfig c = config(kSanitized ? 16 : 50);
  c.threads = 2;
  c.loop_closure.merge_gate = 0.0;
  ASSERT_EQ(c.existence.confirm_at, 3.0);
  Filter filter(c);
  feed(filter, s.events, 0, s.events.size());
  FilterConfig all = c;
  all.existence.confirm_at = -1e300;
  Filter every(all);
  feed(every, s.events, 0, s.events.size());

  const Estimate reported = filter.estimate();
  const Estimate full = every.estimate();
  EXPECT_EQ(reported.best_particle, full.best_particle);
  EXPECT_EQ(std::memcmp(reported.mean_pose, full.mean_pose, sizeof(full.mean_pose)), 0);
  EXPECT_EQ(full.map.size(), full.map_size);
  EXPECT_EQ(reported.map_size, full.map_size);
  std::vector<MapLandmark> confirmed;
  for (const MapLandmark& l : full.map) {
    if (l.log_odds >= 3.0) confirmed.push_back(l);
  }
  ASSERT_EQ(reported.map.size(), confirmed.size());
  for (std::size_t i = 0; i < confirmed.size(); ++i) {
    EXPECT_EQ(reported.map[i].slot, confirmed[i].slot);
    EXPECT_EQ(reported.map[i].id, confirmed[i].id);
    EXPECT_EQ(reported.map[i].x, confirmed[i].x);
    EXPECT_EQ(reported.map[i].log_odds, confirmed[i].log_odds);
  }
  EXPECT_LT(reported.map.size(), full.map.size());  // the test can fail: some were provisional
  EXPECT_EQ(filter.estimate(EstimateMap::kSizeOnly).map_size, full.map_size);

  const MapRun with = run_and_score(c, s);
  const MapRun without = run_and_score(all, s);
  std::cout << unknown_case_name({GetParam(), 0}) << ": clutter 1/scan, spurious landmarks "
            << with.map.spurious << " reported with the rule, " << without.map.spurious
            << " without; missing " << with.map.missing << " / " << without.map.missing << " of "
            << with.observed << "\n";
  EXPECT_LT(with.map.spurious * 2, without.map.spurious);
  EXPECT_LE(with.map.missing, without.map.missing + with.observed / 20);
}

// Landmarks in pairs 1.5 m apart: the unknown modes recover the map about as well as known ids.
TEST_P(FilterUnknownAssociationTest, RecoversAnAmbiguousMap) {
  const Scenario& s = ambiguous_scenario();
  FilterConfig c = config(kSanitized ? 16 : 50);
  c.threads = 2;
  const MapRun unknown = run_and_score(c, s);
  c.association = Association::kKnown;
  const MapRun known = run_and_score(c, s);
  std::cout << unknown_case_name({GetParam(), 0}) << ", ambiguous pairs: pose RMSE "
            << unknown.pose_rmse << " m (known ids " << known.pose_rmse << "), landmark RMSE "
            << unknown.map.rmse_m << " m (" << known.map.rmse_m << "), spurious "
            << unknown.map.spurious << ", missing " << unknown.map.missing << " of "
            << unknown.observed << "\n";
  EXPECT_LT(unknown.pose_rmse, 1.5 * known.pose_rmse + 0.5);
  EXPECT_LT(unknown.map.rmse_m, 1.5 * known.map.rmse_m + 0.2);
  // Sampling draws the wrong twin now and then (FS2 DAS, M = 50: 12 spurious, 9 missing of 70);
  // ML keeps to a few. Missing also counts the landmarks seen fewer than three times, which stay
  // provisional (FS1 ML: 7 missing of 70 confirmed at the second sighting, 9 at the third).
  const bool ml = GetParam().association == Association::kMaximumLikelihood;
  EXPECT_LE(unknown.map.spurious * (ml ? 10 : 4), unknown.observed);
  EXPECT_LE(unknown.map.missing * (ml ? 7 : 4), unknown.observed);
}

// The issue's bar: on webmap, FS2 with ML association over 10 seeds, mean pose RMSE within 1.5x
// of the known-association run.
TEST(FilterAccuracyTest, BaileyWebmapMaximumLikelihoodWithinOneAndAHalfOfKnown) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const tools::World world = webmap(shared);
  const tools::SimConfig sim;
  const int seeds = kSanitized ? 1 : 10;
  std::vector<double> known, ml, ml_landmarks;
  for (int seed = 1; seed <= seeds; ++seed) {
    known.push_back(webmap_accuracy(world, sim, Algorithm::kFastSlam2, 100, seed).pose_rmse);
    const Accuracy a = webmap_accuracy(world, sim, Algorithm::kFastSlam2, 100, seed,
                                       Association::kMaximumLikelihood);
    ml.push_back(a.pose_rmse);
    ml_landmarks.push_back(a.landmark_rmse);
    EXPECT_LT(a.pose_rmse, 25.0) << "seed " << seed;
  }
  const Summary k = summarise(known), m = summarise(ml), l = summarise(ml_landmarks);
  std::cout << "webmap fastslam2 M=100 over " << seeds << " seeds: ML pose RMSE " << m.mean
            << " +- " << m.sd << " m (landmarks, paired within 5 m: " << l.mean << " m); known ids "
            << k.mean << " +- " << k.sd << " m\n";
  if (!kSanitized) {
    EXPECT_LT(m.mean, 1.5 * k.mean);
  }
}

// Loop closure by matching (engine/internal/loop_closure.h): without it every particle maps the
// webmap's landmarks a second time on the second loop (44 in the map for 30 observed, seeds
// 1-10) and the first loop's drift stays; with it the twins merge and the error falls. Measured
// (FastSLAM 1.0, ML, M = 100, seeds 1-10): landmarks 43.5 -> 34.1, pose RMSE 8.1 -> 4.9 m.
TEST(FilterAccuracyTest, BaileyWebmapLoopClosureMergesTheSecondLoopsTwins) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const tools::World world = webmap(shared);
  const tools::SimConfig sim;
  const int seeds = kSanitized ? 1 : 10;
  std::vector<double> open_rmse, closed_rmse, open_map, closed_map;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Accuracy open = webmap_accuracy(world, sim, Algorithm::kFastSlam1, 100, seed,
                                          Association::kMaximumLikelihood, 0.0);
    const Accuracy closed = webmap_accuracy(world, sim, Algorithm::kFastSlam1, 100, seed,
                                            Association::kMaximumLikelihood);
    open_rmse.push_back(open.pose_rmse);
    closed_rmse.push_back(closed.pose_rmse);
    open_map.push_back(static_cast<double>(open.landmarks));
    closed_map.push_back(static_cast<double>(closed.landmarks));
  }
  const Summary o = summarise(open_rmse), c = summarise(closed_rmse);
  const Summary om = summarise(open_map), cm = summarise(closed_map);
  std::cout << "webmap fastslam1 ML M=100 over " << seeds << " seeds: pose RMSE " << o.mean
            << " m without loop closure, " << c.mean << " m with; landmarks " << om.mean << " -> "
            << cm.mean << "\n";
  if (!kSanitized) {
    EXPECT_LT(cm.mean, 37.0);
    EXPECT_GT(om.mean, 40.0);
    EXPECT_LT(c.mean, 0.8 * o.mean);
  }
}

// set_map: every particle gets the given map (one shared root); with known ids the ids address
// it; unknown association finds its landmarks through the index; bad maps change nothing.
TEST(FilterSetMapTest, SharedPriorMapIsUsedAndBadMapsAreRefused) {
  for (const Association association : {Association::kKnown, Association::kMaximumLikelihood,
                                        Association::kDataAssociationSampling}) {
    SCOPED_TRACE(std::string(to_string(association)));
    FilterConfig c = base_config(Algorithm::kFastSlam1, 8);
    c.association = association;
    c.motion.sigma_control[0] = c.motion.sigma_control[1] = 1e-9;
    Filter filter(c);
    const std::vector<MapLandmark> prior = {
        {0, 7, 10.0, 0.0, 0.04, 0.0, 0.04, 5.0, 0},
        {0, 3, 0.0, 10.0, 0.04, 0.01, 0.04, 5.0, 0},
        {0, 9, -5.0, -5.0, 0.04, 0.0, 0.09, 5.0, 0},
    };
    filter.set_map(prior);
    const memory::ParticleStore& store = filter.particles();
    for (std::size_t i = 1; i < store.size(); ++i) {
      EXPECT_TRUE(store.map(i).shares_root_with(store.map(0)));
    }
    EXPECT_EQ(filter.estimate().map.size(), 3u);
    const Snapshot before = snapshot(filter);
    std::vector<MapLandmark> bad = prior;
    bad[2].syy = -1;
    expect_throw_with<std::invalid_argument>([&] { filter.set_map(bad); }, "landmark 2");
    bad = prior;
    bad[1].x = kNaN;
    expect_throw_with<std::invalid_argument>([&] { filter.set_map(bad); }, "landmark 1");
    if (association == Association::kKnown) {
      bad = prior;
      bad[2].id = 7;
      expect_throw_with<std::invalid_argument>([&] { filter.set_map(bad); }, "repeated");
    }
    EXPECT_TRUE(identical(snapshot(filter), before));
    // The vehicle at the origin facing +x sees the first landmark 10 m ahead.
    filter.observe(std::vector<Observation>{{10.0, 0.0, 7}});
    const Estimate e = filter.estimate();
    ASSERT_EQ(e.map.size(), 3u) << "the observation was not associated with the prior landmark";
    EXPECT_LT(e.map[0].sxx, 0.04);  // updated
    EXPECT_EQ(e.map[1].sxx, 0.04);  // untouched
  }
}

// Data association sampling with P_D < 1 and false alarms: a particle's weight gains ln(1 - P_D)
// for each confirmed landmark in view that its draw left undetected. FastSLAM 1.0 with every
// particle at one pose, so that the scan's normalisers are the same in all: a scan of two
// observations, each of which some draws take and others start anew, one of confirmed A and one
// of provisional C. The log-weights then differ by exactly ln(1 - P_D) where A's draws differ
// and not at all where only C's do (a provisional landmark is not counted; map_update_test
// checks which landmarks count against brute-force geometry). Without false alarms, under
// maximum likelihood, and for FastSLAM 2.0 the same run leaves A's draw out of the weight.
TEST(FilterDetectionTest, SamplingWeighsTheConfirmedLandmarksItMissed) {
  const double p_d = 0.7;
  const std::vector<MapLandmark> map = {
      {0, 1, 10.0, 0.0, 0.04, 0.0, 0.04, 5.0, 0},   // A, confirmed
      {0, 2, 5.0, 12.0, 0.04, 0.0, 0.04, 5.0, 0},   // B, confirmed, in view, never observed
      {0, 3, 15.0, -8.0, 0.04, 0.0, 0.04, 1.0, 0},  // C, provisional
      {0, 4, -10.0, 0.0, 0.04, 0.0, 0.04, 5.0, 0},  // behind
  };
  // Each observation 0.9 m long of its landmark: m^2 about 16, so that some draws take "new".
  const double c_range = std::hypot(15.0, -8.0);
  const std::vector<Observation> scan = {{10.9, 0.0, -1},
                                         {c_range + 0.9, std::atan2(-8.0, 15.0), -1}};
  for (const Algorithm algorithm : {Algorithm::kFastSlam1, Algorithm::kFastSlam2}) {
    for (const Association association :
         {Association::kDataAssociationSampling, Association::kMaximumLikelihood}) {
      for (const double clutter : {1e-4, 0.0}) {
        SCOPED_TRACE(std::string(to_string(algorithm)) + " " + std::string(to_string(association)) +
                     (clutter > 0.0 ? "" : " no clutter"));
        FilterConfig config = base_config(algorithm, 200);
        config.association = association;
        config.detection.probability = p_d;
        config.detection.clutter_density = clutter;
        config.resample = {parallel::ResamplePolicy::When::kEssBelowFraction, 0.0};
        Filter filter(config);
        filter.set_map(map);
        filter.observe(scan);
        const memory::ParticleStore& store = filter.particles();
        // Weight by (A taken, C taken): A's log-odds rose from 5 by `seen`, C's from 1.
        std::map<std::pair<bool, bool>, std::vector<double>> groups;
        for (std::size_t i = 0; i < store.size(); ++i) {
          const bool took_a = store.map(i).at(0).log_odds > 5.0;
          const bool took_c = store.map(i).at(2).log_odds > 1.0;
          groups[{took_a, took_c}].push_back(store.log_weight()[i]);
        }
        if (algorithm == Algorithm::kFastSlam2) {
          // The drawn poses differ; what is left to check is that both of A's outcomes ran.
          if (association == Association::kDataAssociationSampling) {
            EXPECT_GE(groups.size(), 2u);
          }
          continue;
        }
        if (association == Association::kMaximumLikelihood) {
          ASSERT_EQ(groups.size(), 1u);
          continue;
        }
        ASSERT_EQ(groups.size(), 4u);  // the test can fail: every outcome was drawn
        const double step = clutter > 0.0 ? std::log1p(-p_d) : 0.0;
        const double took = groups.at({true, true}).front();
        for (const auto& [outcome, weights] : groups) {
          for (const double w : weights) {
            if (outcome.first) {
              EXPECT_EQ(w, took);
            } else {
              EXPECT_NEAR(w, took + step, 1e-12);
              if (clutter > 0.0) {
                EXPECT_NE(w, took);
              }
            }
          }
        }
      }
    }
  }
}

}  // namespace
}  // namespace fastslam::engine
