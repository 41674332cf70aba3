// Simulated scenarios for the Filter's tests (a loop world, with and without false alarms), a
// runner that feeds one to a filter, and bit-for-bit comparisons of particles, estimates and
// trajectories. Header-only; the including test links fastslam::engine and fastslam::sim.
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <cstring>
#include <functional>
#include <span>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "engine/filter.h"
#include "memory/landmark_tree.h"
#include "memory/particle_store.h"
#include "tools/sim/simulator.h"
#include "tools/sim/world.h"

namespace fastslam::engine::testing {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

inline bool same_bits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

// ---- Scenarios: simulated controls and scans, fed to filters ----------------------------------

struct Event {
  bool is_scan = false;
  Control control;
  double dt = 0.0;
  std::vector<Observation> scan;
};

struct Scenario {
  tools::World world;
  std::vector<Event> events;
  std::vector<tools::TruePose> truth;  // after each control
};

inline Scenario simulate(tools::World world, const tools::SimConfig& sim_config, std::uint64_t seed,
                  std::size_t max_controls) {
  Scenario out;
  out.world = std::move(world);
  tools::Simulator sim(out.world, sim_config, seed);
  tools::SimStep step;
  while (out.truth.size() < max_controls && sim.next(step)) {
    out.events.push_back({false, {step.speed, step.steer}, step.dt, {}});
    out.truth.push_back(step.truth);
    if (step.has_scan) {
      Event e;
      e.is_scan = true;
      for (const tools::SimObservation& z : step.scan) {
        e.scan.push_back({z.range, z.bearing, static_cast<std::int64_t>(z.landmark)});
      }
      out.events.push_back(std::move(e));
    }
  }
  return out;
}

// A loop of 240 m with 90 landmarks around it (no shared data needed).
inline const Scenario& loop_scenario() {
  static const Scenario scenario = simulate(tools::make_loop_world(240.0, 8.0, 12.0, 10.0, 3),
                                            tools::SimConfig{}, 5, kSanitized ? 500 : 900);
  return scenario;
}

inline void apply(Filter& filter, const Event& e) {
  if (e.is_scan) {
    filter.observe(e.scan);
  } else {
    filter.predict(e.control, e.dt);
  }
}

inline void feed(Filter& filter, const std::vector<Event>& events, std::size_t begin, std::size_t end,
          const std::function<void(Filter&, const Event&)>& after = {}) {
  for (std::size_t k = begin; k < end; ++k) {
    apply(filter, events[k]);
    if (after) after(filter, events[k]);
  }
}

inline FilterConfig base_config(Algorithm algorithm, std::uint32_t particles = 100) {
  FilterConfig c;
  c.algorithm = algorithm;
  c.particles = particles;
  c.seed = 42;
  c.threads = 1;
  return c;
}

// ---- Snapshots: every column and every map, compared bit for bit ------------------------------

struct Snapshot {
  std::array<std::vector<double>, 6> columns;
  std::vector<std::vector<std::pair<memory::Slot, memory::Landmark>>> maps;
};

inline Snapshot snapshot_columns(Filter& filter) {
  const memory::ParticleStore& store = filter.particles();
  Snapshot s;
  const std::span<const double> cols[6] = {store.x(), store.y(),     store.theta(),
                                           store.v(), store.omega(), store.log_weight()};
  for (int k = 0; k < 6; ++k) s.columns[k].assign(cols[k].begin(), cols[k].end());
  return s;
}

inline Snapshot snapshot(Filter& filter) {
  const memory::ParticleStore& store = filter.particles();
  Snapshot s = snapshot_columns(filter);
  s.maps.resize(store.size());
  for (std::size_t i = 0; i < store.size(); ++i) {
    for (const auto [slot, lm] : store.map(i)) s.maps[i].emplace_back(slot, lm);
  }
  return s;
}

inline ::testing::AssertionResult identical(const Snapshot& a, const Snapshot& b) {
  static const char* kNames[6] = {"x", "y", "theta", "v", "omega", "log_weight"};
  for (int k = 0; k < 6; ++k) {
    if (a.columns[k].size() != b.columns[k].size()) {
      return ::testing::AssertionFailure() << "particle counts differ";
    }
    for (std::size_t i = 0; i < a.columns[k].size(); ++i) {
      if (!same_bits(a.columns[k][i], b.columns[k][i])) {
        return ::testing::AssertionFailure() << "column " << kNames[k] << ", particle " << i << ": "
                                             << a.columns[k][i] << " vs " << b.columns[k][i];
      }
    }
  }
  for (std::size_t i = 0; i < a.maps.size(); ++i) {
    if (a.maps[i].size() != b.maps[i].size()) {
      return ::testing::AssertionFailure() << "particle " << i << ": map sizes " << a.maps[i].size()
                                           << " vs " << b.maps[i].size();
    }
    for (std::size_t j = 0; j < a.maps[i].size(); ++j) {
      const auto& [sa, la] = a.maps[i][j];
      const auto& [sb, lb] = b.maps[i][j];
      if (sa != sb || std::memcmp(&la, &lb, sizeof(memory::Landmark)) != 0) {
        return ::testing::AssertionFailure()
               << "particle " << i << ", landmark #" << j << " (slots " << sa << ", " << sb
               << "): (" << la.x << ", " << la.y << ") vs (" << lb.x << ", " << lb.y << ")";
      }
    }
  }
  return ::testing::AssertionSuccess();
}

inline ::testing::AssertionResult identical(const Estimate& a, const Estimate& b) {
  for (int k = 0; k < 5; ++k) {
    if (!same_bits(a.mean_pose[k], b.mean_pose[k]) || !same_bits(a.best_pose[k], b.best_pose[k])) {
      return ::testing::AssertionFailure() << "pose component " << k << " differs";
    }
  }
  if (a.best_particle != b.best_particle ||
      !same_bits(a.effective_sample_size, b.effective_sample_size) ||
      a.map.size() != b.map.size()) {
    return ::testing::AssertionFailure() << "best particle, ESS or map size differs";
  }
  for (std::size_t j = 0; j < a.map.size(); ++j) {
    const MapLandmark& p = a.map[j];
    const MapLandmark& q = b.map[j];
    if (p.slot != q.slot || p.id != q.id || !same_bits(p.x, q.x) || !same_bits(p.y, q.y) ||
        !same_bits(p.sxx, q.sxx) || !same_bits(p.sxy, q.sxy) || !same_bits(p.syy, q.syy) ||
        !same_bits(p.log_odds, q.log_odds) || p.last_seen != q.last_seen) {
      return ::testing::AssertionFailure() << "map landmark #" << j << " differs";
    }
  }
  return ::testing::AssertionSuccess();
}

inline ::testing::AssertionResult identical(const std::vector<TrajectoryPoint>& a,
                                     const std::vector<TrajectoryPoint>& b) {
  if (a.size() != b.size()) {
    return ::testing::AssertionFailure() << "trajectory lengths " << a.size() << " vs " << b.size();
  }
  for (std::size_t k = 0; k < a.size(); ++k) {
    if (a[k].control != b[k].control || !same_bits(a[k].x, b[k].x) || !same_bits(a[k].y, b[k].y) ||
        !same_bits(a[k].theta, b[k].theta)) {
      return ::testing::AssertionFailure() << "trajectory point " << k << " differs";
    }
  }
  return ::testing::AssertionSuccess();
}

// The loop world with false alarms: a Poisson number per scan (mean `clutter`) anywhere in the
// footprint. Their Observation::id is kClutter (ignored under unknown association).
inline const Scenario& clutter_scenario() {
  static const Scenario scenario = [] {
    tools::SimConfig sim;
    sim.clutter_rate = 1.0;
    return simulate(tools::make_loop_world(240.0, 8.0, 12.0, 10.0, 3), sim, 5,
                    kSanitized ? 500 : 900);
  }();
  return scenario;
}

}  // namespace fastslam::engine::testing
