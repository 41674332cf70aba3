// ParticlePass<Motion, kFs2, kAssociation>: one algorithm's pass (pass.h), its stages fixed at
// compile time. Per block (pass_blocks.h) it runs the motion stage, then the scan's stages; the
// per-thread buffers come from the kernel (parallel::ThreadScratch), one set per thread and
// filter. The factories at the end are defined in one source file per algorithm family, so the
// instantiations compile in parallel. Thread safety and costs: as pass.h.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numeric>
#include <span>
#include <vector>

#include "engine/association.h"
#include "engine/internal/candidate_search.h"
#include "engine/internal/filter_state.h"
#include "engine/internal/fs2_draw.h"
#include "engine/internal/known_update.h"
#include "engine/internal/loop_closure.h"
#include "engine/internal/map_update.h"
#include "engine/internal/motion_normals_ahead.h"
#include "engine/internal/motion_pass.h"
#include "engine/internal/pass.h"
#include "engine/internal/pass_blocks.h"
#include "engine/internal/trajectory_recorder.h"
#include "parallel/particle_kernel.h"
#include "parallel/random_stream.h"

namespace fastslam::engine::internal {

// One thread's buffers for every stage of a pass.
struct PassScratch {
  MotionScratch motion;
  std::vector<double> draws;  // FastSLAM 2.0: N normals per particle of the block
  KnownScratch known;
  CandidateScratch search;
  std::vector<std::int64_t> assignment;     // observation j: a slot or kNewLandmark
  std::vector<std::uint32_t> chosen_terms;  // 1.0: observation j's terms in search.terms
  std::vector<memory::Slot> taken;          // DAS scratch
  // 1.0 ML with twin merging: every candidate of a scan where an observation has two or more,
  // before the lazy choice keeps only the chosen pairs (the map update reads them).
  std::vector<AssociationCandidate> rivals;
  MapUpdateScratch map;
  LoopClosureScratch loop;
};

// The stages' inputs of one pass.
struct PassInputs {
  MotionInput motion;
  KnownInput known;
  SearchInput search;
  MapUpdateInput map;
  LoopClosureInput loop;
  std::uint64_t scan_step = 0;
  bool record = false;
};

template <class Motion, bool kFs2, Association kAssociation>
class ParticlePass final : public Pass {
 public:
  ParticlePass(const Motion& motion, FilterState& state, const parallel::ParticleKernel& kernel,
               TrajectoryRecorder& recorder)
      : motion_(motion),
        s_(state),
        kernel_(kernel),
        recorder_(recorder),
        ahead_(kernel, state.config.seed, state.first_particle) {}
  ~ParticlePass() noexcept override = default;
  ParticlePass(const ParticlePass&) = delete;
  ParticlePass& operator=(const ParticlePass&) = delete;

  void drain() override { run(nullptr, 0); }
  void observe(const std::vector<PlannedObservation>& scan, std::uint64_t scan_step) override {
    run(&scan, scan_step);
  }

 private:
  static constexpr int N = Motion::kStateDim;
  static constexpr bool kKnown = kAssociation == Association::kKnown;
  static constexpr bool kMl = kAssociation == Association::kMaximumLikelihood;
  using Clock = std::chrono::steady_clock;
  using State = typename Motion::State;

  static double seconds_between(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
  }

  // MapUpdateInput::log_missed: ln(1 - P_D) under data association sampling with a detection
  // model of false alarms (clutter density > 0) and P_D < 1, else 0. Without false alarms the
  // map holds few landmarks that are not there, and the factor then only weighs where the
  // footprint's edge falls for each particle (docs/association.md, "Missed detections").
  static double missed_detection_log(const FilterConfig& c) {
    if (kAssociation != Association::kDataAssociationSampling) return 0.0;
    if (!(c.detection.probability < 1.0) || !(c.detection.clutter_density > 0.0)) return 0.0;
    return std::log1p(-c.detection.probability);
  }

  PassInputs inputs(std::uint64_t scan_step) const {
    const FilterConfig& c = s_.config;
    PassInputs in;
    in.motion.pending = s_.pending;
    in.motion.seed = c.seed;
    in.motion.first_particle = s_.first_particle;
    in.motion.sigma_control[0] = c.motion.sigma_control[0];
    in.motion.sigma_control[1] = c.motion.sigma_control[1];
    in.motion.ahead = &ahead_.ready();
    in.motion.runs = runs_;
    in.motion.partial = partial_;
    in.known = {&s_.sensor, s_.r, c.existence, scan_step, weight_scale(c.error_correlation)};
    in.search.sensor = &s_.sensor;
    in.search.r = s_.r;
    in.search.gate = c.gating.gate;
    in.search.search_scale = c.gating.search_scale;
    in.search.log_p0 = c.log_new_landmark;
    in.search.variance_bound = s_.landmark_variance_bound;
    in.search.bearings = bearings_;
    in.search.weight_scale = weight_scale(c.error_correlation);
    in.map = {&s_.sensor,
              s_.r,
              c.existence,
              c.sensor.max_range,
              c.sensor.field_of_view,
              scan_step,
              c.loop_closure.merge_gate,
              missed_detection_log(c)};
    in.loop = {c.loop_closure, c.existence.confirm_at, c.sensor.max_range, scan_step};
    in.scan_step = scan_step;
    in.record = c.record_trajectory && !s_.pending.empty();
    return in;
  }

  void run(const std::vector<PlannedObservation>* scan, std::uint64_t scan_step) {
    const std::size_t m = s_.store.size();
    const std::size_t queued = s_.pending.size();
    const PassBlocks blocks(m, kernel_.threads(), s_.config.grain, heavy_);
    const bool composed = compose();
    if constexpr (!kFs2) {
      if (!composed && blocks.tasks == 1 && kernel_.threads() > 1 &&
          m <= MotionNormalsAhead::kMaxParticles && scan != nullptr) {
        ahead_.start_next(scan_step, queued, m);
      }
    }
    if constexpr (!kKnown) {
      if (scan != nullptr) {
        score_unassociated(*scan);
        scan_bearings(*scan, bearings_);
      }
    }
    const PassInputs in = inputs(scan_step);
    if (in.record) recorder_.begin(s_.store.log_weight(), queued);
    block_seconds_.assign(blocks.tasks, 0.0);
    kernel_.for_each_block(
        blocks.tasks, scratch_,
        [&](std::size_t t, std::size_t, PassScratch& scratch) {
          run_block(in, scan, t, blocks.begin(t), blocks.begin(t + 1), scratch);
        },
        1);
    heavy_ = std::accumulate(block_seconds_.begin(), block_seconds_.end(), 0.0) >
             s_.config.split_seconds;
    if (in.record) recorder_.finish(queued, s_.counters.controls - queued, runs_, partial_);
    s_.pending.clear();
  }

  // Under the composed motion, the runs of the queued controls (runs_ stays empty otherwise).
  // Returns whether the motion is composed.
  bool compose() {
    runs_.clear();
    if constexpr (kComposable<Motion>) {
      if (resolved_motion_draw(s_.config) != MotionDraw::kComposed) return false;
      steps_.clear();
      for (const PendingControl& c : s_.pending) steps_.push_back({c.u0, c.u1, c.dt});
      const typename Motion::Control sigmas(s_.config.motion.sigma_control[0],
                                            s_.config.motion.sigma_control[1]);
      compose_runs(motion_, steps_, sigmas, runs_, partial_);
      return true;
    }
    return false;
  }

  void run_block(const PassInputs& in, const std::vector<PlannedObservation>* scan, std::size_t t,
                 std::size_t begin, std::size_t end, PassScratch& scratch) {
    const Clock::time_point t0 = Clock::now();
    if (!in.motion.pending.empty()) {
      advance_block<Motion, kFs2>(motion_, in.motion, s_.store, s_.covariances, begin, end - begin,
                                  in.record ? &recorder_.sums() : nullptr, scratch.motion);
    }
    const Clock::time_point t1 = Clock::now();
    double associate_seconds = 0.0;
    MapUpdateCounts counts;
    if (scan != nullptr) {
      if constexpr (kFs2) {
        // The N normals of each particle's pose draw, stream (seed, scan step, particle,
        // kProposal), for the whole block in one vectorised batch.
        scratch.draws.resize(static_cast<std::size_t>(N) * (end - begin));
        parallel::normals_for_particles(s_.config.seed, in.scan_step, parallel::Purpose::kProposal,
                                        s_.first_particle + static_cast<std::uint32_t>(begin),
                                        end - begin, N,
                                        scratch.draws);
      }
      if constexpr (kKnown) {
        if constexpr (kFs2) {
          propose_block_known<N>(in.known, *scan, s_.store, s_.covariances, begin, end,
                                 scratch.draws.data(), scratch.known);
        }
        update_block_known<!kFs2>(in.known, *scan, s_.store, begin, end, s_.records,
                                  scratch.known);
      } else {
        associate_seconds = update_block_unknown(in, *scan, t1, begin, end, scratch, counts);
      }
    }
    const Clock::time_point t2 = Clock::now();
    PhaseTimes& times = s_.phase_times.local();
    times.predict += seconds_between(t0, t1);
    times.associate += associate_seconds;
    times.update += seconds_between(t1, t2) - associate_seconds;
    times.created += counts.created;
    times.removed += counts.removed;
    block_seconds_[t] = seconds_between(t0, t2);
  }

  // Unknown association, per particle: choose (and, for 2.0, draw the pose), then change the
  // map; one clock read between the phases times both. Returns the choosing time.
  double update_block_unknown(const PassInputs& in, const std::vector<PlannedObservation>& scan,
                              Clock::time_point mark, std::size_t begin, std::size_t end,
                              PassScratch& scratch, MapUpdateCounts& counts) {
    double associate_seconds = 0.0;
    for (std::size_t i = begin; i < end; ++i) {
      const double* draw = nullptr;
      if constexpr (kFs2) draw = &scratch.draws[static_cast<std::size_t>(N) * (i - begin)];
      associate_particle(in, scan, i, draw, scratch);
      const Clock::time_point chosen = Clock::now();
      associate_seconds += seconds_between(mark, chosen);
      const Pose pose(s_.store.x()[i], s_.store.y()[i], s_.store.theta()[i]);
      const double missed = update_particle_map<kFs2>(
          in.map, pose, scan, scratch.assignment, scratch.search.terms, scratch.chosen_terms,
          s_.store.map(i), scratch.map, counts,
          kMl && !kFs2 ? std::span<const AssociationCandidate>(scratch.rivals)
                       : std::span<const AssociationCandidate>(scratch.search.candidates));
      if (missed != 0.0) s_.store.log_weight()[i] += missed;
      if (in.loop.config.reach > 0.0 && !scratch.map.confirmed.empty()) {
        Pose moved = pose;
        if (close_loop(in.loop, scratch.map.confirmed, s_.store.map(i), moved, scratch.loop)) {
          s_.store.x()[i] = moved[0];
          s_.store.y()[i] = moved[1];
          s_.store.theta()[i] = moved[2];
        }
      }
      mark = Clock::now();
    }
    return associate_seconds;
  }

  // Particle i's candidates, the scan's joint choice (ML or DAS, mutual exclusion) into
  // scratch.assignment, the log-weight, and for FastSLAM 2.0 the pose drawn from the proposal
  // folded over the chosen landmarks (`draw`: its N normals). FastSLAM 1.0 records where each
  // chosen pair's EKF terms are (scratch.chosen_terms), so the map update reuses them.
  void associate_particle(const PassInputs& in, const std::vector<PlannedObservation>& scan,
                          std::size_t i, const double* draw, PassScratch& scratch) {
    double* const col[5] = {s_.store.x().data(), s_.store.y().data(), s_.store.theta().data(),
                            s_.store.v().data(), s_.store.omega().data()};
    PoseGaussian<N> prior;
    for (int k = 0; k < N; ++k) prior.mean[k] = col[k][i];
    if constexpr (kFs2) prior.cov = s_.covariances.template at<N>(i);
    const memory::LandmarkTree& map = s_.store.map(i).tree();
    find_candidates<N, kFs2, kMl>(in.search, prior, map, s_.store.map(i).index(), scan,
                                  scratch.search);
    scratch.assignment.resize(scan.size());
    const std::span<std::int64_t> chosen(scratch.assignment);
    // Without a detection model every observation's "no landmark" score is ln p0, and the
    // scalar overloads keep the sums in their original order (bit-identical results).
    const double log_p0 = s_.config.log_new_landmark;
    const std::span<const double> unassociated(log_unassociated_);
    double log_w;
    if constexpr (kMl && !kFs2) {  // the candidates carry bounds, evaluated as needed
      scratch.rivals.clear();
      if (in.map.merge_gate > 0.0 &&
          std::any_of(scratch.search.counts.begin(), scratch.search.counts.end(),
                      [](std::uint32_t n) { return n > 1; })) {
        scratch.rivals = scratch.search.candidates;
      }
      log_w = detection_model_ ? choose_maximum_likelihood<N>(in.search, prior, map, scan,
                                                              scratch.search, unassociated, chosen)
                               : choose_maximum_likelihood<N>(in.search, prior, map, scan,
                                                              scratch.search, log_p0, chosen);
    } else if constexpr (kMl) {
      log_w = detection_model_
                  ? associate_maximum_likelihood(scratch.search.candidates, unassociated, chosen)
                  : associate_maximum_likelihood(scratch.search.candidates, log_p0, chosen);
    } else {
      parallel::RandomStream stream({s_.config.seed, in.scan_step,
                                     s_.first_particle + static_cast<std::uint32_t>(i),
                                     parallel::Purpose::kAssociation});
      log_w = detection_model_ ? associate_sampling(scratch.search.candidates, unassociated, stream,
                                                    chosen, scratch.taken)
                               : associate_sampling(scratch.search.candidates, log_p0, stream,
                                                    chosen, scratch.taken);
    }
    if constexpr (kFs2) {
      const Fs2Draw<N> d = fold_and_draw<N>(s_.sensor, s_.r, unassociated, prior, map, scan, chosen,
                                            draw, in.search.weight_scale);
      // Under ML the weight is the chain of the folds' terms; under DAS it stays the product
      // of the normalisers.
      if constexpr (kMl) log_w = d.folded;
      for (int k = 0; k < N; ++k) col[k][i] = d.state[k];
      s_.covariances.template at<N>(i) = d.rest;
    } else {
      scratch.chosen_terms.resize(scan.size());
      for (const AssociationCandidate& c : scratch.search.candidates) {
        if (chosen[c.observation] == c.slot) scratch.chosen_terms[c.observation] = c.tag;
      }
    }
    s_.store.log_weight()[i] += log_w;
    record(scratch.search.candidates, chosen, i);
  }

  // Each observation's score of "no landmark" for this scan, the same in every particle: ln p0,
  // or with a detection model ln((p0 + kappa(z)) / P_D) (association.h). O(Z), once per scan,
  // before the blocks run.
  void score_unassociated(const std::vector<PlannedObservation>& scan) {
    const FilterConfig& c = s_.config;
    detection_model_ = c.detection.probability != 1.0 || c.detection.clutter_density != 0.0;
    log_unassociated_.resize(scan.size());
    for (std::size_t j = 0; j < scan.size(); ++j) {
      log_unassociated_[j] = detection_model_
                                 ? log_unassociated(c.log_new_landmark, c.detection, scan[j].z[0])
                                 : c.log_new_landmark;
    }
  }

  // Particle i's row of the scan report (scan_report.h): its choices, and per observation the
  // distance of the chosen pair, or for a new landmark the nearest candidate's.
  void record(std::span<const AssociationCandidate> candidates, std::span<const std::int64_t> chosen,
              std::size_t i) {
    ScanRecords& records = s_.records;
    for (std::size_t j = 0; j < chosen.size(); ++j) {
      records.assignment(j, i) = chosen[j];
      records.mahalanobis2(j, i) = std::numeric_limits<double>::infinity();
    }
    for (const AssociationCandidate& c : candidates) {
      const std::int64_t taken = chosen[c.observation];
      const double m2 = c.mahalanobis2;
      double& d2 = records.mahalanobis2(c.observation, i);
      if (taken == c.slot) {
        d2 = m2;
      } else if (taken == kNewLandmark) {
        d2 = std::min(d2, m2);
      }
    }
  }

  Motion motion_;
  FilterState& s_;
  const parallel::ParticleKernel& kernel_;
  TrajectoryRecorder& recorder_;
  parallel::ThreadScratch<PassScratch> scratch_;
  // The work of the last pass, per block (decides heavy_).
  std::vector<double> block_seconds_;
  // This scan's "no landmark" scores (score_unassociated); every block reads them.
  std::vector<double> log_unassociated_;
  std::vector<Eigen::Vector2d> bearings_;  // the scan's, for the candidate search
  // The composed motion's runs of the pass's controls (engine/motion_run.h).
  std::vector<ControlStep> steps_;
  std::vector<MotionRun> runs_;
  std::vector<Eigen::Vector3d> partial_;
  bool detection_model_ = false;
  MotionNormalsAhead ahead_;  // FastSLAM 1.0 only; last: destroyed, so waited for, first
};

// The factories of the algorithm families (pass_known.cc, pass_fastslam1.cc, pass_fastslam2.cc).
std::unique_ptr<Pass> make_known_pass(FilterState& state, const parallel::ParticleKernel& kernel,
                                      TrajectoryRecorder& recorder);
std::unique_ptr<Pass> make_fastslam1_pass(FilterState& state,
                                          const parallel::ParticleKernel& kernel,
                                          TrajectoryRecorder& recorder);
std::unique_ptr<Pass> make_fastslam2_pass(FilterState& state,
                                          const parallel::ParticleKernel& kernel,
                                          TrajectoryRecorder& recorder);

}  // namespace fastslam::engine::internal
