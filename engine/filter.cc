// The Filter facade: it owns the state and the stages and runs a step through them. `predict`
// checks and queues (scan_plan.h); `observe` plans the scan, runs the pass (pass.h: motion, then
// the scan's stages, per block of particles), commits the plan and resamples
// (resample_stage.h); `save` / `load` are state_io.h's. docs/engine.md describes the stages and
// the data flow of a step.
#include "engine/filter.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "engine/angles.h"
#include "engine/internal/filter_state.h"
#include "engine/internal/map_update.h"
#include "engine/internal/pass.h"
#include "engine/internal/resample_stage.h"
#include "engine/internal/scan_plan.h"
#include "engine/internal/shared_set.h"
#include "engine/internal/state_io.h"
#include "engine/internal/trajectory_recorder.h"
#include "memory/node_heap.h"
#include "parallel/particle_kernel.h"

namespace fastslam::engine {

struct Filter::Impl {
  explicit Impl(const FilterConfig& c, std::shared_ptr<parallel::Collective> g = nullptr)
      : group(std::move(g)),
        kernel({checked(c).threads, c.grain}),
        state(c, group.get()),
        resample(c, kernel),
        recorder(group.get()),
        pass(internal::make_pass(state, kernel, recorder)) {}

  static const FilterConfig& checked(const FilterConfig& c) {
    validate(c);
    if (c.algorithm == Algorithm::kEkf) {
      throw std::invalid_argument(
          "Filter: algorithm 'ekf' is the EKF-SLAM baseline; construct engine::EkfSlam "
          "(engine/ekf_slam.h) instead");
    }
    return c;
  }

  void drain() {
    if (!state.pending.empty()) pass->drain();
  }

  // Members in order of construction; the pass (and its background task) is destroyed first,
  // the kernel last.
  std::shared_ptr<parallel::Collective> group;  // nullptr: this process holds the whole set
  parallel::ParticleKernel kernel;
  internal::FilterState state;
  internal::ResampleStage resample;
  internal::TrajectoryRecorder recorder;
  std::unique_ptr<internal::Pass> pass;
};

Filter::Filter(const FilterConfig& config) : impl_(std::make_unique<Impl>(config)) {}
Filter::Filter(const FilterConfig& config, std::shared_ptr<parallel::Collective> group)
    : impl_(std::make_unique<Impl>(config, [&] {
        if (group == nullptr) throw std::invalid_argument("Filter: the group is null");
        if (config.resample.scheme == parallel::ResampleScheme::kMultinomial) {
          throw std::invalid_argument(
              "Filter: multinomial resampling is not available over ranks (its pointers are a "
              "scan over every rank's spacings); use systematic or stratified");
        }
        return std::move(group);
      }())) {}
Filter::Filter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Filter::~Filter() = default;

const FilterConfig& Filter::config() const noexcept { return impl_->state.config; }

void Filter::predict(const Control& control, double dt) {
  internal::check_control(control, dt);
  internal::FilterState& s = impl_->state;
  s.pending.push_back({control.u0, control.u1, dt, s.counters.step});
  ++s.counters.step;
  ++s.counters.controls;
  s.time += dt;
}

void Filter::predict(const Control& control, double dt, double time) {
  internal::FilterState& s = impl_->state;
  internal::check_time(time, s.time, s.timed);
  predict(control, dt);
  s.time = time;
  s.timed = true;
}

void Filter::predict(std::span<const Control> controls, std::span<const double> dt,
                     std::span<const double> times) {
  internal::FilterState& s = impl_->state;
  if (dt.size() != controls.size() || (!times.empty() && times.size() != controls.size())) {
    throw std::invalid_argument("Filter::predict: " + std::to_string(controls.size()) +
                                " controls, " + std::to_string(dt.size()) + " durations and " +
                                std::to_string(times.size()) +
                                " times (durations and times must match the controls)");
  }
  // Every check first, on a copy of the clock, so that a refusal queues nothing.
  double clock = s.time;
  bool timed = s.timed;
  for (std::size_t k = 0; k < controls.size(); ++k) {
    try {
      internal::check_control(controls[k], dt[k]);
      if (times.empty()) {
        clock += dt[k];
      } else {
        internal::check_time(times[k], clock, timed);
        clock = times[k];
        timed = true;
      }
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("control " + std::to_string(k) + ": " + e.what());
    }
  }
  s.pending.reserve(s.pending.size() + controls.size());
  for (std::size_t k = 0; k < controls.size(); ++k) {
    s.pending.push_back({controls[k].u0, controls[k].u1, dt[k], s.counters.step});
    ++s.counters.step;
    ++s.counters.controls;
  }
  s.time = clock;
  s.timed = timed;
}

void Filter::observe(std::span<const Observation> scan, double time) {
  internal::FilterState& s = impl_->state;
  internal::check_time(time, s.time, s.timed);
  observe(scan);
  s.time = time;
  s.timed = true;
}

void Filter::observe(std::span<const Observation> scan) {
  Impl& impl = *impl_;
  internal::FilterState& s = impl.state;
  // Validate and plan everything before changing anything.
  internal::ScanPlan plan = internal::plan_scan(scan, s.config.association, s.known_slots);
  if (s.config.association != Association::kKnown) {
    for (const internal::PlannedObservation& p : plan.observations) {
      s.landmark_variance_bound =
          std::max(s.landmark_variance_bound, internal::measurement_variance(s.r, p.z[0]));
    }
  }
  using Clock = std::chrono::steady_clock;
  const Clock::time_point t0 = Clock::now();
  const std::uint64_t scan_step = s.counters.step;
  s.records.reset(s.store.size(), plan.observations.size());
  impl.pass->observe(plan.observations, scan_step);
  const internal::BestParticle best = internal::best_particle(s);
  std::vector<ObservationAssociation> report;
  if (best.here) {
    report = internal::report_scan(s.store, best.local, s.records, plan.observations,
                                   s.config.association == Association::kKnown, scan_step);
  }
  s.associations =
      s.group == nullptr ? std::move(report) : internal::broadcast(*s.group, best.owner, report);
  s.known_slots.merge(plan.new_slots);
  ++s.counters.step;
  ++s.counters.scans;
  s.counters.observations += scan.size();
  impl.resample.run(s, scan_step, impl.pass->heavy());
  s.counters.observe_wall_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
}

void Filter::set_map(std::span<const MapLandmark> landmarks) {
  Impl& impl = *impl_;
  internal::FilterState& s = impl.state;
  const bool known_ids = s.config.association == Association::kKnown;
  internal::MapCheck checked = internal::check_map(landmarks, known_ids, s.landmark_variance_bound);
  impl.drain();
  memory::LandmarkTree tree(s.heap);
  for (const MapLandmark& l : landmarks) {
    const memory::Landmark stored{l.x, l.y, l.sxx, l.sxy, l.syy, l.log_odds, l.id, 0};
    tree.insert(stored);
  }
  if (s.links != nullptr) {  // every rank builds this tree alike: its nodes never travel
    s.links->registry.unpin();
    s.links->registry.pin(tree);
  }
  const memory::ParticleMap map(std::move(tree), s.store.options().indexing,
                                internal::largest_variance);
  for (std::size_t i = 0; i < s.store.size(); ++i) s.store.map(i) = map;
  if (known_ids) s.known_slots = std::move(checked.known);
  s.landmark_variance_bound = checked.variance_bound;
}

const std::vector<ObservationAssociation>& Filter::last_associations() const noexcept {
  return impl_->state.associations;
}

Estimate Filter::estimate(EstimateMap map_part) {
  impl_->drain();
  const internal::FilterState& s = impl_->state;
  parallel::Collective* const group = s.group;
  const memory::ParticleStore& store = s.store;
  const std::size_t m = store.size();
  Estimate e;
  std::span<const double> lw = store.log_weight();
  const internal::BestParticle best = internal::best_particle(s);
  const double max_lw = best.log_weight;
  // Weighted sums over fixed blocks, folded in order: deterministic for any thread count.
  struct Sums {
    double w = 0, w2 = 0, x = 0, y = 0, c = 0, sn = 0, v = 0, omega = 0;
  };
  const Sums sums = parallel::shared_reduce(
      impl_->kernel, group, m, Sums{},
      [&](std::size_t begin, std::size_t end) {
        Sums part;
        for (std::size_t i = begin; i < end; ++i) {
          const double w = std::exp(lw[i] - max_lw);
          part.w += w;
          part.w2 += w * w;
          part.x += w * store.x()[i];
          part.y += w * store.y()[i];
          part.c += w * std::cos(store.theta()[i]);
          part.sn += w * std::sin(store.theta()[i]);
          part.v += w * store.v()[i];
          part.omega += w * store.omega()[i];
        }
        return part;
      },
      [](const Sums& a, const Sums& b) {
        return Sums{a.w + b.w, a.w2 + b.w2, a.x + b.x, a.y + b.y,
                    a.c + b.c, a.sn + b.sn, a.v + b.v, a.omega + b.omega};
      });
  e.mean_pose[0] = sums.x / sums.w;
  e.mean_pose[1] = sums.y / sums.w;
  e.mean_pose[2] = std::atan2(sums.sn, sums.c);
  e.mean_pose[3] = sums.v / sums.w;
  e.mean_pose[4] = sums.omega / sums.w;
  e.effective_sample_size = sums.w * sums.w / sums.w2;
  // The covariance about the mean, a second pass (no cancellation of large sums).
  using Moments = std::array<double, 6>;  // xx, xy, xt, yy, yt, tt
  const Moments mo = parallel::shared_reduce(
      impl_->kernel, group, m, Moments{},
      [&](std::size_t begin, std::size_t end) {
        Moments part{};
        for (std::size_t i = begin; i < end; ++i) {
          const double w = std::exp(lw[i] - max_lw);
          const double d[3] = {store.x()[i] - e.mean_pose[0], store.y()[i] - e.mean_pose[1],
                               wrap_angle(store.theta()[i] - e.mean_pose[2])};
          for (int r = 0, k = 0; r < 3; ++r) {
            for (int c = r; c < 3; ++c, ++k) part[k] += w * d[r] * d[c];
          }
        }
        return part;
      },
      [](const Moments& a, const Moments& b) {
        Moments sum;
        for (std::size_t k = 0; k < sum.size(); ++k) sum[k] = a[k] + b[k];
        return sum;
      });
  for (int r = 0, k = 0; r < 3; ++r) {
    for (int c = r; c < 3; ++c, ++k) {
      e.pose_covariance[3 * r + c] = e.pose_covariance[3 * c + r] = mo[k] / sums.w;
    }
  }
  e.time = impl_->state.time;
  e.associations = impl_->state.associations;
  e.best_particle = static_cast<std::uint32_t>(best.index);
  // The best particle's pose, map size and map, from the rank holding it.
  struct BestOf {
    double pose[5];
    std::uint64_t map_size;
  };
  std::vector<BestOf> best_of(1);  // the holder's; the others' are overwritten by the broadcast
  std::vector<MapLandmark> landmarks;
  if (best.here) {
    const std::size_t b = best.local;
    const memory::LandmarkTree& map = store.map(b).tree();
    best_of[0] = {{store.x()[b], store.y()[b], store.theta()[b], store.v()[b], store.omega()[b]},
                  map.size()};
    if (map_part == EstimateMap::kCopy) {
      landmarks.reserve(map.size());
      const bool known_ids = s.config.association == Association::kKnown;
      const double confirm_at = s.config.existence.confirm_at;
      for (const auto [slot, lm] : map) {
        if (!known_ids && !(lm.log_odds >= confirm_at)) continue;
        landmarks.push_back(
            {slot, lm.id, lm.x, lm.y, lm.sxx, lm.sxy, lm.syy, lm.log_odds, lm.last_seen});
      }
    }
  }
  if (group != nullptr) {
    best_of = internal::broadcast(*group, best.owner, best_of);
    if (map_part == EstimateMap::kCopy) landmarks = internal::broadcast(*group, best.owner, landmarks);
  }
  std::copy_n(best_of[0].pose, 5, e.best_pose);
  e.map_size = best_of[0].map_size;
  e.map = std::move(landmarks);
  return e;
}

FilterStatistics Filter::statistics() const {
  const internal::FilterState& s = impl_->state;
  const internal::FilterCounters& c = s.counters;
  FilterStatistics st;
  st.controls = c.controls;
  st.scans = c.scans;
  st.observations = c.observations;
  st.resamples = c.resamples;
  st.weight_resets = c.weight_resets;
  st.landmarks_created = c.landmarks_created;
  st.landmarks_removed = c.landmarks_removed;
  s.phase_times.combine_each([&](const internal::PhaseTimes& t) {
    st.predict_seconds += t.predict;
    st.associate_seconds += t.associate;
    st.update_seconds += t.update;
    st.landmarks_created += t.created;
    st.landmarks_removed += t.removed;
  });
  st.resample_seconds = c.resample_seconds;
  st.log_evidence = c.log_evidence;
  st.observe_wall_seconds = c.observe_wall_seconds;
  const memory::HeapStats heap = s.heap.stats();
  st.live_nodes = heap.live_nodes;
  st.live_bytes = heap.live_bytes;
  st.exchange_particles = s.exchange.particles;
  st.exchange_copies = s.exchange.copies;
  st.exchange_bytes = s.exchange.bytes;
  st.exchange_naive_bytes = s.exchange.naive_bytes;
  st.exchange_seconds = s.exchange.seconds;
  return st;
}

std::vector<TrajectoryPoint> Filter::take_trajectory() {
  impl_->drain();
  std::vector<TrajectoryPoint> out;
  out.swap(impl_->recorder.points());
  return out;
}

const memory::ParticleStore& Filter::particles() {
  impl_->drain();
  return impl_->state.store;
}

void Filter::save(std::ostream& out) const {
  if (impl_->state.group != nullptr) {
    throw std::logic_error(
        "Filter::save: this filter's particle set is spread over ranks, and a shared set has no "
        "saved form; run on one process to save or checkpoint");
  }
  internal::save_state(impl_->state, impl_->recorder.points(), out);
}

std::unique_ptr<Filter> Filter::load(std::istream& in) { return load(in, nullptr); }

std::unique_ptr<Filter> Filter::load(std::istream& in, const FilterConfig& execution) {
  return load(in, &execution);
}

std::unique_ptr<Filter> Filter::load(std::istream& in, const FilterConfig* execution) {
  internal::StateHeader header = internal::read_header(in);
  if (execution != nullptr) {
    header.config.threads = execution->threads;
    header.config.grain = execution->grain;
    header.config.split_seconds = execution->split_seconds;
  }
  std::unique_ptr<Impl> impl;
  try {
    impl = std::make_unique<Impl>(header.config);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(std::string("Filter::load: corrupt state (config: ") + e.what() + ")");
  }
  impl->recorder.points() = std::move(header.trajectory);
  internal::read_particles(in, std::move(header), impl->state);
  return std::unique_ptr<Filter>(new Filter(std::move(impl)));
}

}  // namespace fastslam::engine
