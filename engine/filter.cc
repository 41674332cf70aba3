#include "engine/filter.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <istream>
#include <limits>
#include <numeric>
#include <ostream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <Eigen/Core>
#include <oneapi/tbb/combinable.h>

#include "engine/association.h"
#include "engine/landmark_batch.h"
#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/motion_batch.h"
#include "engine/motion_dispatch.h"
#include "engine/motion_model.h"
#include "engine/proposal.h"
#include "memory/node_heap.h"
#include "parallel/internal/vmath.h"
#include "parallel/particle_kernel.h"
#include "parallel/random_stream.h"
#include "parallel/resample.h"

namespace fastslam::engine {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// A queued odometry sample, with the step number that keys its random draws.
struct PendingControl {
  double u0 = 0.0;
  double u1 = 0.0;
  double dt = 0.0;
  std::uint64_t step = 0;
};

// One observation of a scan as every particle will process it (known association): the
// measurement, the map slot of its landmark, and whether the scan creates that landmark.
struct PlannedObservation {
  Eigen::Vector2d z;
  memory::Slot slot = 0;
  std::uint64_t id = 0;
  bool is_new = false;
};

struct PhaseTimes {
  double predict = 0.0;
  double associate = 0.0;
  double update = 0.0;
  std::uint64_t created = 0;  // landmarks started, summed over particles
  std::uint64_t removed = 0;  // landmarks removed by negative information
};

// Unknown association: ids of new landmarks are (scan step) * 2^20 + (observation index), unique
// and stable across copies; a scan may hold fewer than 2^20 observations.
constexpr std::uint64_t kObservationsPerScanLimit = std::uint64_t{1} << 20;

// The largest eigenvalue of a stored landmark's covariance, rounded up to a float: its spatial
// index entry's extent, which gates candidates before the map is read (associate_particle).
float largest_variance(const memory::Landmark& l) {
  const double half_gap = 0.5 * (l.sxx - l.syy);
  const double v = 0.5 * (l.sxx + l.syy) + std::sqrt(half_gap * half_gap + l.sxy * l.sxy);
  const auto f = static_cast<float>(v);
  return static_cast<double>(f) >= v ? f
                                     : std::nextafter(f, std::numeric_limits<float>::infinity());
}

// Per-thread scratch of the unknown-association step of one particle.
struct AssociationScratch {
  std::vector<AssociationCandidate> candidates;  // tag: index into `terms` (FastSLAM 1.0)
  std::vector<LandmarkObservation> terms;        // 1.0: each candidate's EKF terms, reused
  std::vector<std::int64_t> assignment;          // observation j: a slot or kNewLandmark
  std::vector<std::uint32_t> chosen_terms;       // 1.0: observation j's terms in `terms`
  std::vector<memory::Slot> taken;
  std::vector<memory::Slot> touched;
  std::vector<memory::SpatialEntry> in_view;
  // Observation j's candidate disc: x, y, radius (from the variance bound), and the part of the
  // spread that is not the landmark's own (measurement, and for 2.0 the pose).
  std::vector<std::array<double, 4>> discs;
  std::vector<memory::SpatialIndex::Disc> queries;  // the discs as the index takes them
  std::vector<Eigen::Vector2d> directions;          // observation j's bearing in the world
};

// The particle blocks of a pass over m particles: whole groups of kMotionLanes particles (the
// vector width of the control loop, and one 64-byte cache line of a column, so no two tasks
// write the same line), dealt to `tasks` blocks that differ by at most one group. There are
// about m / grain tasks; when there is more than one, their number is rounded up to a multiple
// of the thread count so that at the end of a pass no thread waits long for another (M = 1000,
// grain 128, 2 threads: 8 blocks of 120 or 128 particles, 496/504 per thread when split evenly,
// where blocks of exactly 128 would give 7 and a block of 104). m <= grain runs as one block
// on the calling thread unless the pass is heavy (below): webmap FS1 with M = 100 and 2
// threads took 50 ms split in two tasks against 34 ms inline (a pass is ~17 us of work; the
// second thread adds its dispatch and the cross-core traffic of the particles' maps, which the
// sequential resampling touches).
// A heavy pass (`heavy`: the previous pass's work exceeded FilterConfig::split_seconds, e.g.
// Victoria Park's association, ~5 us per particle and scan) gets at least four blocks per
// thread whatever the grain: its work dwarfs the dispatch, and a thread slowed by another
// process hands its blocks over instead of holding up the pass.
// Results never depend on the blocks: each particle's work reads only its own state and
// streams.
struct PassBlocks {
  std::size_t m = 0;
  std::size_t groups = 0;
  std::size_t tasks = 0;

  PassBlocks(std::size_t particles, unsigned threads, std::size_t grain, bool heavy)
      : m(particles), groups((particles + kMotionLanes - 1) / kMotionLanes) {
    tasks = (particles + grain - 1) / grain;
    if (heavy && threads > 1) tasks = std::max<std::size_t>(tasks, 4 * std::size_t{threads});
    if (threads > 1 && tasks > 1) tasks = (tasks + threads - 1) / threads * threads;
    tasks = std::clamp<std::size_t>(tasks, 1, std::max<std::size_t>(groups, 1));
  }
  // First particle of block t (t <= tasks; block t is [begin(t), begin(t + 1))).
  std::size_t begin(std::size_t t) const { return std::min(m, t * groups / tasks * kMotionLanes); }
};

}  // namespace

struct Filter::Impl {
  explicit Impl(const FilterConfig& c)
      : config(checked(c)),
        kernel({c.threads, c.grain}),
        // Resampling costs nanoseconds per particle: its own grain (the kernel's default, 512,
        // measured best for it), so that small filters resample inline instead of paying a
        // parallel dispatch per scan. The result does not depend on it.
        resampler(c.resample, kernel, parallel::KernelConfig{}.grain),
        store(c.particles, heap, store_options(c)),
        sensor(c.sensor.offset) {
    r << c.sensor.sigma_range * c.sensor.sigma_range, 0, 0,
        c.sensor.sigma_bearing * c.sensor.sigma_bearing;
    const double log_m = -std::log(static_cast<double>(c.particles));
    double* columns[5] = {store.x().data(), store.y().data(), store.theta().data(),
                          store.v().data(), store.omega().data()};
    for (std::uint32_t i = 0; i < c.particles; ++i) {
      for (int k = 0; k < 5; ++k) columns[k][i] = c.initial_pose[k];
      store.log_weight()[i] = log_m;
    }
  }

  // Known ids find landmarks by slot: no spatial index. FastSLAM 2.0 keeps the state's
  // covariance, N x N in slots of 25: the motion's since the last scan plus, without odometry,
  // the velocities' left by the scan's draw (draw_state), which follows its particle through
  // resampling.
  static memory::StoreOptions store_options(const FilterConfig& c) {
    memory::StoreOptions o;
    o.indexing =
        c.association == Association::kKnown ? memory::Indexing::kNone : memory::Indexing::kSpatial;
    if (c.algorithm == Algorithm::kFastSlam2) {
      o.pose_covariance = without_odometry(c.motion.kind) ? memory::PoseCovariance::kCarried
                                                          : memory::PoseCovariance::kScratch;
    }
    return o;
  }

  static const FilterConfig& checked(const FilterConfig& c) {
    validate(c);
    if (c.algorithm == Algorithm::kEkf) {
      throw std::invalid_argument(
          "Filter: algorithm 'ekf' is the EKF-SLAM baseline; construct engine::EkfSlam "
          "(engine/ekf_slam.h) instead");
    }
    return c;
  }

  // Runs the queued controls and, if given, the planned scan through every particle.
  void run_pass(const std::vector<PlannedObservation>* scan, std::uint64_t scan_step) {
    visit_motion(config.motion,
                 [&](const auto& motion) { run_pass_with(motion, scan, scan_step); });
    pending.clear();
  }

  template <class Motion>
  void run_pass_with(const Motion& motion, const std::vector<PlannedObservation>* scan,
                     std::uint64_t scan_step) {
    constexpr int N = Motion::kStateDim;
    using State = typename Motion::State;
    using Cov = Eigen::Matrix<double, N, N>;
    const bool fs2 = config.algorithm == Algorithm::kFastSlam2;
    const std::uint64_t seed = config.seed;
    double* col[5] = {store.x().data(), store.y().data(), store.theta().data(), store.v().data(),
                      store.omega().data()};
    double* log_weight = store.log_weight().data();

    auto load = [&](std::size_t i) {
      State s;
      for (int k = 0; k < N; ++k) s[k] = col[k][i];
      return s;
    };
    auto save = [&](std::size_t i, const State& s) {
      for (int k = 0; k < N; ++k) col[k][i] = s[k];
    };
    double* const pose_cov = store.pose_cov().data();
    auto cov_of = [&](std::size_t i) { return Eigen::Map<Cov>(&pose_cov[i * 25]); };
    const std::size_t m = store.size();
    const bool record = config.record_trajectory && !pending.empty();
    if (record) {
      recorded.assign(pending.size() * m * 4, 0.0);
      snapshot_weights();
    }
    const PassBlocks blocks(m, kernel.threads(), config.grain, heavy_pass);
    if (!fs2 && blocks.tasks == 1 && kernel.threads() > 1 && m <= kAheadMaxParticles &&
        scan != nullptr) {
      draw_ahead(scan_step, pending.size(), m);
    }
    block_seconds.assign(blocks.tasks, 0.0);
    auto run_block = [&](std::size_t t, std::size_t begin, std::size_t end) {
      const Clock::time_point t0 = Clock::now();
      const std::size_t count = end - begin;
      if (!pending.empty()) {
        advance_block(motion, begin, count, record ? recorded.data() : nullptr);
      }
      const Clock::time_point t1 = Clock::now();
      double associate_seconds = 0.0;
      if (scan != nullptr) {
        // FastSLAM 2.0: the N normals of each particle's pose draw, stream (seed, scan step,
        // particle, kProposal), for the whole block in one vectorised batch (the same values
        // as per-particle streams, at a fraction of the cost).
        thread_local std::vector<double> draws;
        if (fs2) {
          draws.resize(static_cast<std::size_t>(N) * count);
          parallel::normals_for_particles(seed, scan_step, parallel::Purpose::kProposal,
                                          static_cast<std::uint32_t>(begin), count, N, draws);
        }
        if (config.association == Association::kKnown) {
          if (fs2) propose_block_known<N>(begin, end, *scan, draws.data());
          update_block_known(begin, end, *scan, scan_step, fs2 ? nullptr : log_weight);
        } else {
          // Unknown association, per particle: choose (and, for 2.0, draw the pose), then
          // change the map; one clock read between the phases times both.
          thread_local AssociationScratch scratch;
          Clock::time_point mark = t1;
          for (std::size_t i = begin; i < end; ++i) {
            associate_particle<Motion>(
                i, load(i), *scan, scan_step,
                fs2 ? &draws[static_cast<std::size_t>(N) * (i - begin)] : nullptr, log_weight, save,
                cov_of, scratch);
            const Clock::time_point chosen = Clock::now();
            associate_seconds += seconds_between(mark, chosen);
            update_particle_unknown(i, *scan, scan_step, fs2, scratch);
            mark = Clock::now();
          }
        }
      }
      const Clock::time_point t2 = Clock::now();
      PhaseTimes& times = phase_times.local();
      times.predict += seconds_between(t0, t1);
      times.associate += associate_seconds;
      times.update += seconds_between(t1, t2) - associate_seconds;
      block_seconds[t] = seconds_between(t0, t2);
    };
    kernel.for_each_particle(
        blocks.tasks, [&](std::size_t t) { run_block(t, blocks.begin(t), blocks.begin(t + 1)); },
        1);
    heavy_pass =
        std::accumulate(block_seconds.begin(), block_seconds.end(), 0.0) > config.split_seconds;
    if (record) reduce_recorded(m);
  }

  // The queued controls applied to particles [begin, begin + count) (one task's block): the
  // block's states (and, for FastSLAM 2.0, the upper triangles of its pose covariances) are
  // copied into this thread's lane columns, padded to whole groups of kMotionLanes, carried
  // through every control by the vectorised kernels of engine/motion_batch.h, and copied back.
  // `recorded` (null unless record_trajectory) receives x, y, cos, sin per control and particle.
  template <class Motion>
  void advance_block(const Motion& motion, std::size_t begin, std::size_t count,
                     double* recorded_out) {
    constexpr int N = Motion::kStateDim;
    constexpr int E = kCovEntries<N>;
    const bool fs2 = config.algorithm == Algorithm::kFastSlam2;
    const typename Motion::Control sigmas(config.motion.sigma_control[0],
                                          config.motion.sigma_control[1]);
    const std::size_t lanes = padded_lanes(count);
    const std::size_t k_steps = pending.size();
    // Columns: N states, then (FastSLAM 2.0) E covariance entries or (FastSLAM 1.0) two normals
    // per control step of a batch of at most kStepBatch steps (bounds the scratch when many
    // controls are queued).
    constexpr std::size_t kStepBatch = 64;
    thread_local std::vector<double> scratch;
    thread_local std::vector<ControlStep> steps;
    thread_local std::vector<std::uint64_t> keys;
    const std::size_t columns = N + (fs2 ? E : 2 * std::min(k_steps, kStepBatch));
    scratch.resize(columns * lanes);
    auto column = [&](std::size_t c) { return scratch.data() + c * lanes; };
    steps.resize(k_steps);
    keys.resize(k_steps);
    for (std::size_t k = 0; k < k_steps; ++k) {
      const PendingControl& c = pending[k];
      steps[k] = {c.u0, c.u1, c.dt};
      if constexpr (Motion::kNoOdometry) steps[k].u0 = steps[k].u1 = 0;
      keys[k] = c.step;
    }
    double* const store_col[5] = {store.x().data(), store.y().data(), store.theta().data(),
                                  store.v().data(), store.omega().data()};
    double* const pose_cov = store.pose_cov().data();
    StateBlock<N> block;
    block.lanes = lanes;
    for (int k = 0; k < N; ++k) {
      block.col[k] = column(k);
      std::copy_n(store_col[k] + begin, count, block.col[k]);
      std::fill(block.col[k] + count, block.col[k] + lanes, 0.0);  // padding lanes: any finite
    }
    CovBlock<N> cov{};
    if (fs2) {
      for (int row = 0, e = 0; row < N; ++row) {
        for (int c = row; c < N; ++c, ++e) {
          cov[e] = column(N + e);
          for (std::size_t l = 0; l < count; ++l) {
            cov[e][l] = pose_cov[(begin + l) * 25 + c * N + row];
          }
          std::fill(cov[e] + count, cov[e] + lanes, 0.0);
        }
      }
    }
    const std::size_t m = store.size();
    // Recording the trajectory needs the poses after every step; otherwise one call runs a batch.
    const std::size_t per_call = recorded_out != nullptr ? 1 : kStepBatch;
    for (std::size_t first = 0; first < k_steps; first += kStepBatch) {
      const std::size_t batch = std::min(kStepBatch, k_steps - first);
      if (!fs2) {
        // The two motion normals of every particle and step: stream (seed, step, particle,
        // kMotion), step first + j's pair in columns N + 2j and N + 2j + 1. Drawn for the
        // padding lanes too (the streams of the particles after the block; their values go
        // nowhere): whole vectors, no scalar remainder.
        const std::span<double> normals(column(N), 2 * batch * lanes);
        const std::span<const std::uint64_t> batch_keys = std::span(keys).subspan(first, batch);
        const std::size_t drawn = ahead[ahead_ready].copy(batch_keys, begin, lanes, normals);
        if (drawn < batch) {
          const std::span<double> rest = normals.subspan(2 * drawn * lanes);
          parallel::normal_pairs_for_particles(
              config.seed, batch_keys.subspan(drawn), parallel::Purpose::kMotion,
              static_cast<std::uint32_t>(begin), lanes, rest, rest.subspan(lanes), 2 * lanes);
        }
      }
      for (std::size_t j = 0; j < batch; j += per_call) {
        const std::size_t k = first + j;
        const std::span<const ControlStep> run(steps.data() + k, std::min(per_call, batch - j));
        if (fs2) {
          predict_block(motion, block, run, sigmas, cov);
        } else {
          sample_block(motion, block, run, sigmas, column(N + 2 * j));
        }
        if (recorded_out != nullptr) {
          for (std::size_t l = 0; l < count; ++l) {
            double* out = &recorded_out[(k * m + begin + l) * 4];
            out[0] = block.col[0][l];
            out[1] = block.col[1][l];
            parallel::internal::sincos(block.col[2][l], out[2], out[3]);
          }
        }
      }
    }
    for (int k = 0; k < N; ++k) std::copy_n(block.col[k], count, store_col[k] + begin);
    if (fs2) {
      for (int row = 0, e = 0; row < N; ++row) {
        for (int c = row; c < N; ++c, ++e) {
          for (std::size_t l = 0; l < count; ++l) {
            double* p = &pose_cov[(begin + l) * 25];
            p[c * N + row] = p[row * N + c] = cov[e][l];
          }
        }
      }
    }
  }

  // w_i = exp(l_i - max l): the weights the recorded poses are averaged with.
  void snapshot_weights() {
    std::span<const double> lw = store.log_weight();
    const double max_lw = *std::max_element(lw.begin(), lw.end());
    weights.resize(lw.size());
    for (std::size_t i = 0; i < lw.size(); ++i) weights[i] = std::exp(lw[i] - max_lw);
  }

  // The weighted mean of the recorded poses, per control, in fixed blocks folded in order.
  void reduce_recorded(std::size_t m) {
    using Sums = std::array<double, 5>;
    for (std::size_t k = 0; k < pending.size(); ++k) {
      const double* rec = &recorded[k * m * 4];
      const Sums sums = kernel.reduce(
          m, Sums{},
          [&](std::size_t begin, std::size_t end) {
            Sums part{};
            for (std::size_t i = begin; i < end; ++i) {
              const double w = weights[i];
              part[0] += w;
              for (int c = 0; c < 4; ++c) part[c + 1] += w * rec[i * 4 + c];
            }
            return part;
          },
          [](const Sums& a, const Sums& b) {
            return Sums{a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3], a[4] + b[4]};
          });
      trajectory.push_back({controls - pending.size() + k, sums[1] / sums[0], sums[2] / sums[0],
                            std::atan2(sums[4], sums[3])});
    }
  }

  // FastSLAM 2.0, known association, particles [begin, end): the scan's observations of known
  // landmarks folded into each particle's proposal in scan order (eq. 61), in lanes across the
  // particles (engine/landmark_batch.h), their log-likelihoods added to the weights; then each
  // pose drawn from its proposal (`draws`: N standard normals per particle) and the motion
  // covariance restarted (to the velocities' conditional one without odometry, draw_state).
  template <int N>
  void propose_block_known(std::size_t begin, std::size_t end,
                           const std::vector<PlannedObservation>& scan, const double* draws) {
    constexpr int E = N * (N + 1) / 2;
    const std::size_t count = end - begin;
    // Columns: N means, E covariance entries, landmark x, y, sxx, sxy, syy, the log-likelihood.
    thread_local std::vector<double> buffer;
    buffer.assign((N + E + 6) * count, 0.0);
    auto column = [&](int c) { return buffer.data() + static_cast<std::size_t>(c) * count; };
    double* const state[5] = {store.x().data() + begin, store.y().data() + begin,
                              store.theta().data() + begin, store.v().data() + begin,
                              store.omega().data() + begin};
    double* const pose_cov = store.pose_cov().data();
    ProposalLanes<N> proposal;
    for (int k = 0; k < N; ++k) {
      proposal.mean[k] = column(k);
      std::copy_n(state[k], count, proposal.mean[k]);
    }
    for (int row = 0, e = 0; row < N; ++row) {
      for (int c = row; c < N; ++c, ++e) {
        proposal.cov[e] = column(N + e);
        for (std::size_t l = 0; l < count; ++l) {
          proposal.cov[e][l] = pose_cov[(begin + l) * 25 + c * N + row];
        }
      }
    }
    double* lm[5];
    for (int k = 0; k < 5; ++k) lm[k] = column(N + E + k);
    double* const log_w = column(N + E + 5);
    for (const PlannedObservation& o : scan) {
      if (o.is_new) continue;
      for (std::size_t l = 0; l < count; ++l) {
        const memory::Landmark& stored = store.map(begin + l).at(o.slot);
        lm[0][l] = stored.x;
        lm[1][l] = stored.y;
        lm[2][l] = stored.sxx;
        lm[3][l] = stored.sxy;
        lm[4][l] = stored.syy;
      }
      fold_proposal_lanes<N>(sensor, r, o.z, proposal, {lm[0], lm[1], lm[2], lm[3], lm[4]}, log_w,
                             count);
    }
    std::fill_n(&pose_cov[begin * 25], count * 25, 0.0);
    if constexpr (N > 3) {
      // As draw_state (engine/proposal.h): only the pose is drawn; the velocities keep their
      // Gaussian conditioned on it (normals from 3 on zeroed; covariance F22 F22^T).
      thread_local std::vector<double> pose_only;
      pose_only.assign(draws, draws + N * count);
      for (std::size_t l = 0; l < count; ++l) std::fill_n(&pose_only[l * N + 3], N - 3, 0.0);
      sample_pose_lanes<N>(proposal, pose_only.data(), state, count);
      for (std::size_t l = 0; l < count; ++l) {
        Eigen::Matrix<double, N, N> cov;
        for (int row = 0, e = 0; row < N; ++row) {
          for (int c = row; c < N; ++c, ++e) cov(row, c) = cov(c, row) = proposal.cov[e][l];
        }
        Eigen::Map<Eigen::Matrix<double, N, N>> slot(&pose_cov[(begin + l) * 25]);
        slot = rest_given_pose<N>(psd_factor<N>(cov));
      }
    } else {
      sample_pose_lanes<N>(proposal, draws, state, count);
    }
    double* const log_weight = store.log_weight().data();
    for (std::size_t l = 0; l < count; ++l) log_weight[begin + l] += log_w[l];
  }

  // Known association, the scan of particles [begin, end) at their (for 2.0: drawn) poses, one
  // observation at a time in scan order: a new landmark is initialised in every particle's map
  // (eq. 69-70); a known one is gathered from every particle's map into lanes, updated by the
  // vectorised EKF (engine/landmark_batch.h) and scattered back. Each particle sees its
  // observations in scan order, as a per-particle loop would. `log_weight` (FastSLAM 1.0; null
  // for 2.0, whose weight came from the proposal) gains each particle's sum of eq. 31 terms.
  // The landmark references stay valid across the particles: an edit makes the particle's
  // path its own, and later edits of other maps only copy shared nodes, never write them.
  void update_block_known(std::size_t begin, std::size_t end,
                          const std::vector<PlannedObservation>& scan, std::uint64_t scan_step,
                          double* log_weight) {
    const std::size_t count = end - begin;
    const std::size_t lanes = padded_lanes(count);
    // Columns: pose x, y, theta; landmark x, y, sxx, sxy, syy; the scan's log-likelihood sum.
    thread_local std::vector<double> buffer;
    thread_local std::vector<memory::Landmark*> edited;
    buffer.resize(9 * lanes);
    edited.resize(count);
    double* col[9];
    for (int c = 0; c < 9; ++c) col[c] = buffer.data() + c * lanes;
    const double* const pose_col[3] = {store.x().data(), store.y().data(), store.theta().data()};
    for (int c = 0; c < 3; ++c) {
      std::copy_n(pose_col[c] + begin, count, col[c]);
      std::fill(col[c] + count, col[c] + lanes, 0.0);
    }
    // Padding lanes: a landmark 1 m ahead with a unit covariance (any valid input; unused).
    constexpr double kPadding[5] = {1.0, 0.0, 1.0, 0.0, 1.0};
    for (int c = 0; c < 5; ++c) std::fill(col[3 + c] + count, col[3 + c] + lanes, kPadding[c]);
    std::fill_n(col[8], lanes, 0.0);
    const PoseLanes poses{col[0], col[1], col[2]};
    const LandmarkLanes lm{col[3], col[4], col[5], col[6], col[7]};
    const auto step_now = static_cast<std::int64_t>(scan_step);
    for (const PlannedObservation& o : scan) {
      if (o.is_new) {
        for (std::size_t l = 0; l < count; ++l) {
          const Pose pose(col[0][l], col[1][l], col[2][l]);
          memory::Landmark stored;
          store_gaussian(initialize_landmark(sensor, pose, o.z, r), stored);
          stored.log_odds = config.existence.initial;
          stored.id = o.id;
          stored.last_seen = step_now;
          store.map(begin + l).insert(stored, 0.0f);  // unindexed: no extent
        }
        continue;
      }
      for (std::size_t l = 0; l < count; ++l) {
        memory::Landmark& stored = store.map(begin + l).edit_unindexed(o.slot);
        edited[l] = &stored;
        lm.x[l] = stored.x;
        lm.y[l] = stored.y;
        lm.sxx[l] = stored.sxx;
        lm.sxy[l] = stored.sxy;
        lm.syy[l] = stored.syy;
      }
      update_landmark_lanes(sensor, r, o.z, poses, lm, log_weight != nullptr ? col[8] : nullptr,
                            lanes);
      for (std::size_t l = 0; l < count; ++l) {
        memory::Landmark& stored = *edited[l];
        stored.x = lm.x[l];
        stored.y = lm.y[l];
        stored.sxx = lm.sxx[l];
        stored.sxy = lm.sxy[l];
        stored.syy = lm.syy[l];
        stored.log_odds += config.existence.seen;
        stored.last_seen = step_now;
      }
    }
    if (log_weight != nullptr) {
      for (std::size_t l = 0; l < count; ++l) log_weight[begin + l] += col[8][l];
    }
  }

  // Unknown association, first sweep: the candidates of every observation from the spatial
  // index, gated; the scan's joint choice (ML or DAS, mutual exclusion); the log-weight; for
  // FastSLAM 2.0 the proposal folded over the chosen landmarks and the pose drawn from it.
  // Writes the choice of observation j to scratch.assignment[j] (a slot, or kNewLandmark) and,
  // for 1.0, where its EKF terms are (scratch.chosen_terms[j]), so the update reuses them: the
  // pose and the landmark are the same then, since no other observation takes that landmark.
  template <class Motion, class Save, class CovOf>
  void associate_particle(std::size_t i, typename Motion::State s,
                          const std::vector<PlannedObservation>& scan, std::uint64_t scan_step,
                          const double* draw, double* log_weight, const Save& save,
                          const CovOf& cov_of, AssociationScratch& scratch) {
    constexpr int N = Motion::kStateDim;
    const bool fs2 = draw != nullptr;
    const memory::LandmarkTree& map = store.map(i).tree();
    const memory::SpatialIndex& index = store.map(i).index();
    PoseGaussian<N> prior;
    prior.mean = s;
    if (fs2) prior.cov = cov_of(i);
    const Pose pose = s.template head<3>();  // 1.0: the sampled pose; 2.0: the predicted mean
    // The gate as a Euclidean radius around the landmark position an observation implies:
    // Mahalanobis^2 >= |d|^2 / lambda_max(Sigma + R_xy + pose term) under linearisation, and a
    // landmark's covariance never exceeds its initial one (EKF updates only shrink it), whose
    // largest eigenvalue is bounded by landmark_variance_bound.
    const double offset = std::hypot(sensor.offset().x, sensor.offset().y);
    const double gate = config.gating.gate;
    const double scale2 = config.gating.search_scale * config.gating.search_scale;
    const Eigen::Vector2d from = sensor.sensor_position(pose);
    scratch.candidates.clear();
    scratch.terms.clear();
    // The scan's discs first, then one descent to the node whose square holds all of them; each
    // disc query starts there (the same entries in the same order as from the root).
    scratch.discs.resize(scan.size());
    double box[4] = {
        std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
    for (std::size_t j = 0; j < scan.size(); ++j) {
      const Eigen::Vector2d& z = scan[j].z;
      const Eigen::Vector2d at = sensor.landmark_from(z, pose);
      double spread = measurement_variance(z[0]);
      if (fs2) {
        const double lever = z[0] + offset;
        spread += 2.0 * (prior.cov(0, 0) + prior.cov(1, 1)) + 2.0 * lever * lever * prior.cov(2, 2);
      }
      const double radius = std::sqrt(scale2 * gate * (landmark_variance_bound + spread));
      scratch.discs[j] = {at[0], at[1], radius, spread};
      box[0] = std::min(box[0], at[0] - radius);
      box[1] = std::min(box[1], at[1] - radius);
      box[2] = std::max(box[2], at[0] + radius);
      box[3] = std::max(box[3], at[1] + radius);
    }
    // A margin of 1/64 of the box's extent, so that rounding near the edges rarely sends a
    // query back to the root (within() checks the containment exactly either way).
    const double pad = 0.015625 * (box[2] - box[0] + box[3] - box[1]);
    const memory::SpatialIndex::Subtree near =
        scan.empty() || !std::isfinite(pad)
            ? memory::SpatialIndex::Subtree()
            : index.covering(box[0] - pad, box[1] - pad, box[2] + pad, box[3] + pad);
    // Maximum likelihood never takes a candidate below ln p0 (association.h), so those are not
    // kept; and since det Q >= det R, ln N(v; 0, Q) <= -ln 2 pi - ln det R / 2 - m^2 / 2, so
    // neither is one whose m^2 exceeds 2 (-ln 2 pi - ln det R / 2 - ln p0) (Victoria Park:
    // 14.3 against the gate's 23).
    const bool ml = config.association == Association::kMaximumLikelihood;
    const double log_p0 = config.log_new_landmark;
    double limit = gate;
    if (ml) {
      const double log_det_r = std::log(r(0, 0) * r(1, 1) - r(0, 1) * r(1, 0));
      limit = std::min(limit, 2.0 * (-kLogTwoPi - 0.5 * log_det_r - log_p0));
    }
    // FastSLAM 1.0: candidates whose Mahalanobis distance provably exceeds that limit, from the
    // index entry alone (range_bearing_mahalanobis2_bound; the margin far above its rounding and
    // that of ln det), skip the map lookup and the exact gate, which would drop them too: the
    // chosen landmarks and the weight are the same. Victoria Park: 17.5 M entries reach the
    // bound, 6.3 M pass it (7.8 M against the gate alone), 6.0 M are kept.
    const double bound_limit = limit + 1e-6 * (std::fabs(limit) + 1.0);
    // The observed directions (unit, to rounding): at = sensor position + z_r (cos, sin).
    scratch.queries.resize(scan.size());
    scratch.directions.resize(scan.size());
    for (std::size_t j = 0; j < scan.size(); ++j) {
      const auto [at_x, at_y, radius, spread] = scratch.discs[j];
      scratch.queries[j] = {at_x, at_y, radius};
      scratch.directions[j] = {(at_x - from[0]) / scan[j].z[0], (at_y - from[1]) / scan[j].z[0]};
    }
    // The same bound with each landmark's own largest eigenvalue (the entry's extent) in place
    // of the map-wide one: most landmarks are far tighter than a new one at full range, so most
    // entries of a disc stop in the index, before the map lookup and the trigonometry of the
    // exact gate (Victoria Park: 17 entries a disc, 3.4 pass), and so do whole leaves whose
    // widest landmark cannot reach (half of those a disc touches). All the scan's discs go down
    // the index together; the candidates' order does not matter (association.h sorts them).
    const auto reach2 = [&](std::size_t j, float extent) {
      return scale2 * gate * (static_cast<double>(extent) + scratch.discs[j][3]);
    };
    index.within_reach(
        near, scratch.queries, reach2, [&](std::size_t j, const memory::SpatialEntry& e) {
          const Eigen::Vector2d& z = scan[j].z;
          if ((Eigen::Vector2d(e.x, e.y) - from).squaredNorm() < 1e-18) return;  // g undefined
          if (!fs2 &&
              range_bearing_mahalanobis2_bound(from, scratch.directions[j], z[0], e.x, e.y,
                                               static_cast<double>(e.extent), r) > bound_limit) {
            return;
          }
          const LandmarkGaussian lm = to_gaussian(map.at(e.slot));
          const auto obs = static_cast<std::uint32_t>(j);
          if (fs2) {
            const ProposalObservation<N> t = evaluate_proposal<N>(sensor, lm, prior, z, r);
            if (t.mahalanobis2 <= gate && !(ml && t.log_likelihood < log_p0)) {
              scratch.candidates.push_back({obs, e.slot, t.log_likelihood});
            }
          } else {
            const LandmarkObservation t = evaluate_observation(sensor, lm, pose, z, r);
            if (t.mahalanobis2 <= gate && !(ml && t.log_likelihood < log_p0)) {
              const auto tag = static_cast<std::uint32_t>(scratch.terms.size());
              scratch.terms.push_back(t);
              scratch.candidates.push_back({obs, e.slot, t.log_likelihood, tag});
            }
          }
        });
    scratch.assignment.resize(scan.size());
    const std::span<std::int64_t> chosen(scratch.assignment);
    double log_w;
    if (config.association == Association::kMaximumLikelihood) {
      log_w = associate_maximum_likelihood(scratch.candidates, config.log_new_landmark, chosen);
    } else {
      parallel::RandomStream stream(
          {config.seed, scan_step, static_cast<std::uint32_t>(i), parallel::Purpose::kAssociation});
      log_w = associate_sampling(scratch.candidates, config.log_new_landmark, stream, chosen,
                                 scratch.taken);
    }
    if (!fs2) {
      scratch.chosen_terms.resize(scan.size());
      for (const AssociationCandidate& c : scratch.candidates) {
        if (chosen[c.observation] == c.slot) scratch.chosen_terms[c.observation] = c.tag;
      }
    }
    if (fs2) {
      // Fold the chosen landmarks into the proposal in scan order, then draw the pose once; with
      // none chosen the draw is from the motion prior (as eq. 68 for new landmarks). Under ML
      // the weight is the chain of the folds' terms (as with known ids) times p0 per new
      // landmark; under DAS it stays the product of the normalisers.
      PoseGaussian<N> proposal = prior;
      double folded = 0.0;
      for (std::size_t j = 0; j < scan.size(); ++j) {
        if (chosen[j] == kNewLandmark) {
          folded += config.log_new_landmark;
          continue;
        }
        const LandmarkGaussian lm = to_gaussian(map.at(static_cast<memory::Slot>(chosen[j])));
        const ProposalObservation<N> terms =
            evaluate_proposal<N>(sensor, lm, proposal, scan[j].z, r);
        folded += terms.log_likelihood;
        proposal = fold<N>(proposal, terms);
      }
      if (config.association == Association::kMaximumLikelihood) log_w = folded;
      Eigen::Matrix<double, N, N> rest;
      save(i, draw_state<N>(proposal, draw, rest));
      cov_of(i) = rest;
    }
    log_weight[i] += log_w;
  }

  // Unknown association, second sweep: EKF updates of the chosen landmarks at the particle's
  // (drawn) pose, their index entries moved; negative information for the landmarks in view and
  // not chosen (eq. 73-75; removal below the bound); then the new landmarks.
  void update_particle_unknown(std::size_t i, const std::vector<PlannedObservation>& scan,
                               std::uint64_t scan_step, bool fs2, AssociationScratch& scratch) {
    const std::vector<std::int64_t>& assignment = scratch.assignment;
    memory::ParticleMap& map = store.map(i);
    const memory::SpatialIndex& index = map.index();
    const Pose pose(store.x()[i], store.y()[i], store.theta()[i]);
    const auto step_now = static_cast<std::int64_t>(scan_step);
    PhaseTimes& counts = phase_times.local();
    scratch.touched.clear();
    for (std::size_t j = 0; j < scan.size(); ++j) {
      if (assignment[j] == kNewLandmark) continue;
      const auto slot = static_cast<memory::Slot>(assignment[j]);
      map.update(
          slot,
          [&](memory::Landmark& stored) {
            LandmarkGaussian lm = to_gaussian(stored);
            // 1.0: the terms from the association (same pose, same landmark); 2.0: at the drawn
            // pose.
            if (fs2) {
              apply_update(lm, evaluate_observation(sensor, lm, pose, scan[j].z, r), r);
            } else {
              apply_update(lm, scratch.terms[scratch.chosen_terms[j]], r);
            }
            store_gaussian(lm, stored);
            stored.log_odds += config.existence.seen;
            stored.last_seen = step_now;
          },
          largest_variance);
      scratch.touched.push_back(slot);
    }
    const ExistenceConfig& ex = config.existence;
    if (ex.negative_information && config.sensor.max_range > ex.range_margin) {
      const Eigen::Vector2d at = sensor.sensor_position(pose);
      scratch.in_view.clear();
      index.in_footprint(at[0], at[1], pose[2] + sensor.offset().yaw,
                         config.sensor.max_range - ex.range_margin, config.sensor.field_of_view,
                         [&](const memory::SpatialEntry& e) {
                           if (std::find(scratch.touched.begin(), scratch.touched.end(), e.slot) ==
                               scratch.touched.end()) {
                             scratch.in_view.push_back(e);
                           }
                         });
      // Slot order, so the result does not depend on how the index visits its leaves.
      std::sort(scratch.in_view.begin(), scratch.in_view.end(),
                [](const memory::SpatialEntry& a, const memory::SpatialEntry& b) {
                  return a.slot < b.slot;
                });
      for (const memory::SpatialEntry& e : scratch.in_view) {
        const double log_odds = map.at(e.slot).log_odds - ex.missed;
        if (log_odds < ex.remove_below) {
          map.erase(e.slot);
          ++counts.removed;
        } else {
          map.update(
              e.slot, [&](memory::Landmark& stored) { stored.log_odds = log_odds; },
              largest_variance);
        }
      }
    }
    for (std::size_t j = 0; j < scan.size(); ++j) {
      if (assignment[j] != kNewLandmark) continue;
      memory::Landmark stored;
      store_gaussian(initialize_landmark(sensor, pose, scan[j].z, r), stored);
      stored.log_odds = ex.initial;
      stored.id = scan_step * kObservationsPerScanLimit + j;
      stored.last_seen = step_now;
      map.insert(stored, largest_variance(stored));
      ++counts.created;
    }
  }

  // The largest eigenvalue of the measurement noise mapped to the plane at range `range`: the
  // landmark covariance of eq. 70 has eigenvalues sigma_r^2 and (range sigma_phi)^2.
  double measurement_variance(double range) const {
    return std::max(r(0, 0), range * range * r(1, 1));
  }

  void resample(std::uint64_t scan_step) {
    const Clock::time_point t0 = Clock::now();
    try {
      // After a heavy pass the gather releases many path copies (about 0.2 us a particle at
      // M = 100 with ML on a 10^4 map): split it as finely as the pass (N = 10^4, M = 100,
      // 2 threads: ~333 -> ~316 us per update); after a light one it stays at the resampler's
      // grain, inline for small filters.
      const std::size_t threads = kernel.threads();
      const std::size_t grain =
          heavy_pass && threads > 1 ? std::max<std::size_t>(1, store.size() / (4 * threads)) : 0;
      const parallel::ResampleOutcome outcome =
          resampler.resample(store, config.seed, scan_step, grain);
      resamples += outcome.resampled ? 1 : 0;
      // The weights summed to one after the last scan, so their sum now is this scan's factor.
      log_evidence += outcome.before.log_sum;
    } catch (const std::invalid_argument& e) {
      // A NaN or +inf log-weight: a numerical failure inside the filter, not refused input (the
      // scan has been applied), so not std::invalid_argument, whose contract is "unchanged".
      throw std::runtime_error(std::string("Filter::observe: numerical failure after scan ") +
                               std::to_string(scan_step) + ": " + e.what());
    } catch (const std::domain_error&) {
      // Every weight is zero: the scan was impossible under every particle. The maps already
      // hold it; start the weights afresh rather than stop (counted in the statistics).
      parallel::reset_log_weights(store.log_weight(), kernel);
      ++weight_resets;
      log_evidence = -std::numeric_limits<double>::infinity();
    }
    resample_seconds += seconds_between(t0, Clock::now());
  }

  FilterConfig config;
  memory::PoolHeap heap;  // before the store: outlives every map
  parallel::ParticleKernel kernel;
  parallel::Resampler resampler;
  memory::ParticleStore store;
  RangeBearingModel sensor;
  Eigen::Matrix2d r;
  std::vector<PendingControl> pending;
  std::vector<double> recorded;  // x, y, cos, sin per control per particle (record_trajectory)
  std::vector<double> weights;
  std::vector<TrajectoryPoint> trajectory;
  std::unordered_map<std::int64_t, memory::Slot> known_slots;
  // Unknown association: a bound on every landmark covariance's largest eigenvalue (the
  // largest of eq. 70 over the observations seen so far), for the candidate search radius.
  double landmark_variance_bound = 0.0;
  // The work of the last pass, per block, and whether it was heavy (see PassBlocks); they
  // decide only how the next pass is split, never a result.
  std::vector<double> block_seconds;
  bool heavy_pass = false;

  // FastSLAM 1.0 with a pass too light to split (webmap, M = 100: ~10 us a pass) and a second
  // thread: that thread draws the next pass's motion normals while this one runs the pass. They
  // are keyed by (seed, step, particle), so who draws them, and when, changes no bit. The next
  // pass's controls follow this pass's scan step; their count is guessed as this pass's plus
  // one (the window costs the other thread about as long as the pass it overlaps); steps past
  // the window are drawn in the pass as before. Webmap FS1, M = 100: 20.9 ms on one thread,
  // 16.7 ms on two.
  static constexpr std::size_t kAheadMaxParticles = 4096;  // bounds the window's memory
  struct MotionNormalsAhead {
    std::vector<std::uint64_t> keys;  // steps first, first + 1, ...
    std::size_t lanes = 0;            // the particle count, padded to whole lane groups
    // Step j's first normals at [2 j lanes, 2 j lanes + lanes), its second after them.
    std::vector<double> values;

    // Copies the normals of the leading steps of `steps` that the window holds, for lanes
    // [begin, begin + count), into `out` in the pass's layout (step j's first normals at
    // 2 j count, second at (2 j + 1) count); returns how many steps it copied.
    std::size_t copy(std::span<const std::uint64_t> steps, std::size_t begin, std::size_t count,
                     std::span<double> out) const {
      if (keys.empty() || begin + count > lanes) return 0;
      std::size_t j = 0;
      for (; j < steps.size(); ++j) {
        if (steps[j] < keys.front() || steps[j] - keys.front() >= keys.size()) break;
        const double* from = values.data() + 2 * (steps[j] - keys.front()) * lanes + begin;
        std::copy_n(from, count, out.data() + 2 * j * count);
        std::copy_n(from + lanes, count, out.data() + (2 * j + 1) * count);
      }
      return j;
    }
  };
  // ahead[ahead_ready] is drawn; the other one may be being drawn by ahead_task (declared after
  // them: destroyed, and so waited for, first).
  MotionNormalsAhead ahead[2];
  int ahead_ready = 0;
  parallel::BackgroundTask ahead_task{kernel};

  // Waits for the window being drawn, makes it the ready one, and starts drawing the next:
  // queued + 1 steps from scan_step + 1, for every particle.
  void draw_ahead(std::uint64_t scan_step, std::size_t queued, std::size_t m) {
    ahead_task.wait();
    ahead_ready = 1 - ahead_ready;
    MotionNormalsAhead& next = ahead[1 - ahead_ready];
    next.keys.resize(queued + 1);
    std::iota(next.keys.begin(), next.keys.end(), scan_step + 1);
    next.lanes = padded_lanes(m);
    next.values.resize(2 * next.keys.size() * next.lanes);
    ahead_task.start([&next, seed = config.seed] {
      const std::span<double> out(next.values);
      parallel::normal_pairs_for_particles(seed, next.keys, parallel::Purpose::kMotion, 0,
                                           next.lanes, out, out.subspan(next.lanes),
                                           2 * next.lanes);
    });
  }
  std::uint64_t step = 0;  // events so far (controls and scans): keys the random streams
  std::uint64_t controls = 0, scans = 0, observations = 0, resamples = 0, weight_resets = 0;
  double resample_seconds = 0.0;
  double log_evidence = 0.0;
  double observe_wall_seconds = 0.0;
  mutable tbb::combinable<PhaseTimes> phase_times;  // combine_each is not const
};

Filter::Filter(const FilterConfig& config) : impl_(std::make_unique<Impl>(config)) {}
Filter::Filter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Filter::~Filter() = default;

const FilterConfig& Filter::config() const noexcept { return impl_->config; }

void Filter::predict(const Control& control, double dt) {
  if (!std::isfinite(dt) || dt < 0) {
    throw std::invalid_argument("Filter::predict: dt must be finite and >= 0 (got " +
                                std::to_string(dt) + ")");
  }
  if (!std::isfinite(control.u0) || !std::isfinite(control.u1)) {
    throw std::invalid_argument("Filter::predict: control values must be finite (got " +
                                std::to_string(control.u0) + ", " + std::to_string(control.u1) +
                                ")");
  }
  impl_->pending.push_back({control.u0, control.u1, dt, impl_->step});
  ++impl_->step;
  ++impl_->controls;
}

void Filter::observe(std::span<const Observation> scan) {
  Impl& s = *impl_;
  // Validate and plan everything before changing anything.
  std::vector<PlannedObservation> plan;
  plan.reserve(scan.size());
  std::unordered_map<std::int64_t, memory::Slot> new_slots;
  std::unordered_set<std::int64_t> ids_in_scan;
  memory::Slot next_slot = static_cast<memory::Slot>(s.known_slots.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const Observation& o = scan[j];
    auto where = [j] { return "Filter::observe: observation " + std::to_string(j) + ": "; };
    if (!std::isfinite(o.range) || !(o.range > 0)) {
      throw std::invalid_argument(where() + "range must be finite and > 0 (got " +
                                  std::to_string(o.range) + ")");
    }
    if (!std::isfinite(o.bearing)) {
      throw std::invalid_argument(where() + "bearing must be finite (got " +
                                  std::to_string(o.bearing) + ")");
    }
    PlannedObservation p;
    p.z = {o.range, wrap_angle(o.bearing)};
    if (s.config.association != Association::kKnown) {
      plan.push_back(p);
      continue;
    }
    if (o.id < 0) {
      throw std::invalid_argument(where() + "known association needs a landmark id >= 0 (got " +
                                  std::to_string(o.id) + ")");
    }
    if (!ids_in_scan.insert(o.id).second) {
      throw std::invalid_argument(where() + "landmark id " + std::to_string(o.id) +
                                  " appears twice in one scan");
    }
    p.id = static_cast<std::uint64_t>(o.id);
    if (auto found = s.known_slots.find(o.id); found != s.known_slots.end()) {
      p.slot = found->second;
    } else {
      p.slot = next_slot++;
      p.is_new = true;
      new_slots.emplace(o.id, p.slot);
    }
    plan.push_back(p);
  }
  if (s.config.association != Association::kKnown) {
    if (scan.size() >= kObservationsPerScanLimit) {
      throw std::invalid_argument("Filter::observe: a scan holds at most " +
                                  std::to_string(kObservationsPerScanLimit - 1) +
                                  " observations (got " + std::to_string(scan.size()) + ")");
    }
    for (const PlannedObservation& p : plan) {
      s.landmark_variance_bound =
          std::max(s.landmark_variance_bound, s.measurement_variance(p.z[0]));
    }
  }
  const Clock::time_point t0 = Clock::now();
  const std::uint64_t scan_step = s.step;
  s.run_pass(&plan, scan_step);
  s.known_slots.merge(new_slots);
  ++s.step;
  ++s.scans;
  s.observations += scan.size();
  s.resample(scan_step);
  s.observe_wall_seconds += seconds_between(t0, Clock::now());
}

void Filter::set_map(std::span<const MapLandmark> landmarks) {
  Impl& s = *impl_;
  const bool known_ids = s.config.association == Association::kKnown;
  std::unordered_map<std::int64_t, memory::Slot> known;
  double variance_bound = s.landmark_variance_bound;
  for (std::size_t k = 0; k < landmarks.size(); ++k) {
    const MapLandmark& l = landmarks[k];
    auto where = [k] { return "Filter::set_map: landmark " + std::to_string(k) + ": "; };
    if (!std::isfinite(l.x) || !std::isfinite(l.y) || std::abs(l.x) > 1e150 ||
        std::abs(l.y) > 1e150) {
      throw std::invalid_argument(where() + "position must be finite and within 1e150");
    }
    const double det = l.sxx * l.syy - l.sxy * l.sxy;
    if (!std::isfinite(l.sxx) || !std::isfinite(l.sxy) || !std::isfinite(l.syy) || !(l.sxx > 0) ||
        !(det > 0)) {
      throw std::invalid_argument(where() + "covariance must be symmetric positive definite");
    }
    if (!std::isfinite(l.log_odds)) throw std::invalid_argument(where() + "log_odds not finite");
    if (known_ids) {
      if (l.id >= (std::uint64_t{1} << 63) ||
          !known.emplace(static_cast<std::int64_t>(l.id), static_cast<memory::Slot>(k)).second) {
        throw std::invalid_argument(where() + "id " + std::to_string(l.id) +
                                    " is repeated or too large");
      }
    }
    // The largest eigenvalue of the covariance bounds the candidate search (see observe).
    const double half_trace = 0.5 * (l.sxx + l.syy);
    variance_bound = std::max(variance_bound,
                              half_trace + std::sqrt(std::max(0.0, half_trace * half_trace - det)));
  }
  if (!s.pending.empty()) s.run_pass(nullptr, 0);
  memory::ParticleMap map = s.store.empty_map();
  for (const MapLandmark& l : landmarks) {
    memory::Landmark stored{l.x, l.y, l.sxx, l.sxy, l.syy, l.log_odds, l.id, 0};
    map.insert(stored, largest_variance(stored));
  }
  for (std::size_t i = 0; i < s.store.size(); ++i) {
    s.store.map(i) = map;
  }
  if (known_ids) s.known_slots = std::move(known);
  s.landmark_variance_bound = variance_bound;
}

Estimate Filter::estimate() {
  Impl& s = *impl_;
  if (!s.pending.empty()) s.run_pass(nullptr, 0);
  const memory::ParticleStore& store = s.store;
  const std::size_t m = store.size();
  Estimate e;
  std::span<const double> lw = store.log_weight();
  std::size_t best = 0;
  for (std::size_t i = 1; i < m; ++i) {
    if (lw[i] > lw[best]) best = i;
  }
  const double max_lw = lw[best];
  // Weighted sums over fixed blocks, folded in order: deterministic for any thread count.
  struct Sums {
    double w = 0, w2 = 0, x = 0, y = 0, c = 0, sn = 0, v = 0, omega = 0;
  };
  const Sums sums = s.kernel.reduce(
      m, Sums{},
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
  e.best_particle = static_cast<std::uint32_t>(best);
  const double best_pose[5] = {store.x()[best], store.y()[best], store.theta()[best],
                               store.v()[best], store.omega()[best]};
  std::copy(std::begin(best_pose), std::end(best_pose), e.best_pose);
  const memory::LandmarkTree& map = store.map(best).tree();
  e.map.reserve(map.size());
  for (const auto [slot, lm] : map) {
    e.map.push_back({slot, lm.id, lm.x, lm.y, lm.sxx, lm.sxy, lm.syy, lm.log_odds, lm.last_seen});
  }
  return e;
}

FilterStatistics Filter::statistics() const {
  const Impl& s = *impl_;
  FilterStatistics st;
  st.controls = s.controls;
  st.scans = s.scans;
  st.observations = s.observations;
  st.resamples = s.resamples;
  st.weight_resets = s.weight_resets;
  s.phase_times.combine_each([&](const PhaseTimes& t) {
    st.predict_seconds += t.predict;
    st.associate_seconds += t.associate;
    st.update_seconds += t.update;
    st.landmarks_created += t.created;
    st.landmarks_removed += t.removed;
  });
  st.resample_seconds = s.resample_seconds;
  st.log_evidence = s.log_evidence;
  st.observe_wall_seconds = s.observe_wall_seconds;
  const memory::HeapStats heap = s.heap.stats();
  st.live_nodes = heap.live_nodes;
  st.live_bytes = heap.live_bytes;
  return st;
}

std::vector<TrajectoryPoint> Filter::take_trajectory() {
  if (!impl_->pending.empty()) impl_->run_pass(nullptr, 0);
  std::vector<TrajectoryPoint> out;
  out.swap(impl_->trajectory);
  return out;
}

const memory::ParticleStore& Filter::particles() {
  if (!impl_->pending.empty()) impl_->run_pass(nullptr, 0);
  return impl_->store;
}

// ---- save / load ----------------------------------------------------------------------------
// Format (native byte order, for the same build): magic, version, sizeof(FilterConfig), the
// config bytes (padding zeroed), counters, the landmark variance bound, queued controls,
// known-id table, FastSLAM 2.0 covariances, particle columns, then per particle either "same map
// as particle i-1" or its landmarks (slot, value). Spatial indices are not written: they are
// rebuilt from the maps (an index's entries are its map's slots and means, and queries are
// exact, so the rebuilt index answers the same). Equal states save equal bytes.
//
// Loading trusts nothing: every length is checked against what the configuration implies, and
// vectors are read in bounded chunks, so a corrupt length or particle count fails with
// std::runtime_error once the stream runs out instead of allocating what it claims. The
// particle store is allocated only after the FastSLAM 2.0 covariances (25 doubles per particle)
// were read, i.e. once the stream has shown that it holds that many particles.

namespace {

constexpr char kMagic[8] = {'F', 'S', 'L', 'A', 'M', 'S', 'T', '1'};
constexpr std::uint32_t kVersion = 2;  // 2: unknown association (variance bound, free slots)

[[noreturn]] void corrupt(const std::string& what) {
  throw std::runtime_error("Filter::load: corrupt state (" + what + ")");
}

template <class T>
void put(std::ostream& out, const T& value) {
  static_assert(std::is_trivially_copyable_v<T>);
  out.write(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <class T>
void put_vector(std::ostream& out, const std::vector<T>& values) {
  put<std::uint64_t>(out, values.size());
  out.write(reinterpret_cast<const char*>(values.data()),
            static_cast<std::streamsize>(values.size() * sizeof(T)));
}

void read_bytes(std::istream& in, void* to, std::size_t bytes) {
  in.read(static_cast<char*>(to), static_cast<std::streamsize>(bytes));
  if (!in) throw std::runtime_error("Filter::load: truncated or unreadable state");
}

template <class T>
T get(std::istream& in) {
  static_assert(std::is_trivially_copyable_v<T>);
  T value;
  read_bytes(in, &value, sizeof(T));
  return value;
}

// A length-prefixed vector of at most `limit` elements, read in chunks of at most 1 MiB so that
// memory grows only as fast as the stream delivers data.
template <class T>
std::vector<T> get_vector(std::istream& in, std::uint64_t limit) {
  const auto n = get<std::uint64_t>(in);
  if (n > limit) corrupt("a length is too large");
  constexpr std::size_t kChunk = std::max<std::size_t>(1, (std::size_t{1} << 20) / sizeof(T));
  std::vector<T> values;
  for (std::size_t done = 0; done < n;) {
    const std::size_t count = std::min<std::size_t>(kChunk, n - done);
    values.resize(done + count);
    read_bytes(in, values.data() + done, count * sizeof(T));
    done += count;
  }
  return values;
}

// One entry of the known-id table, with its padding spelled out (and zero).
struct KnownSlot {
  std::int64_t id = 0;
  memory::Slot slot = 0;
  std::uint32_t zero = 0;
};
static_assert(sizeof(KnownSlot) == 16 && std::is_trivially_copyable_v<KnownSlot>);
static_assert(sizeof(PendingControl) == 32 && sizeof(TrajectoryPoint) == 32,
              "saved structs must have no padding");

}  // namespace

void Filter::save(std::ostream& out) const {
  const Impl& s = *impl_;
  static_assert(std::is_trivially_copyable_v<FilterConfig>);
  out.write(kMagic, sizeof(kMagic));
  put<std::uint32_t>(out, kVersion);
  put<std::uint64_t>(out, sizeof(FilterConfig));
  FilterConfig config = s.config;
#if defined(__has_builtin)
#if __has_builtin(__builtin_clear_padding)
  __builtin_clear_padding(&config);  // equal configs, equal bytes
#endif
#endif
  put(out, config);
  for (std::uint64_t v :
       {s.step, s.controls, s.scans, s.observations, s.resamples, s.weight_resets}) {
    put(out, v);
  }
  put(out, s.landmark_variance_bound);
  put_vector(out, s.pending);
  put_vector(out, s.trajectory);
  std::vector<KnownSlot> known;
  known.reserve(s.known_slots.size());
  for (const auto& [id, slot] : s.known_slots) known.push_back({id, slot, 0});
  std::sort(known.begin(), known.end(),
            [](const KnownSlot& a, const KnownSlot& b) { return a.id < b.id; });
  put_vector(out, known);
  // M x 25 doubles, zero when the store keeps no covariance (FastSLAM 1.0).
  const std::span<const double> kept_cov = s.store.pose_cov();
  std::vector<double> pose_cov(kept_cov.begin(), kept_cov.end());
  pose_cov.resize(s.store.size() * memory::ParticleStore::kPoseCovStride, 0.0);
  put_vector(out, pose_cov);
  const memory::ParticleStore& store = s.store;
  for (std::span<const double> column :
       {store.x(), store.y(), store.theta(), store.v(), store.omega(), store.log_weight()}) {
    out.write(reinterpret_cast<const char*>(column.data()),
              static_cast<std::streamsize>(column.size() * sizeof(double)));
  }
  for (std::size_t i = 0; i < store.size(); ++i) {
    const bool same = i > 0 && store.map(i).shares_root_with(store.map(i - 1));
    put<std::uint8_t>(out, same ? 1 : 0);
    if (same) continue;
    put<std::uint64_t>(out, store.map(i).size());
    for (const auto [slot, lm] : store.map(i)) {
      put(out, slot);
      put(out, lm);
    }
  }
  if (!out) throw std::runtime_error("Filter::save: write failed");
}

std::unique_ptr<Filter> Filter::load(std::istream& in) {
  char magic[sizeof(kMagic)];
  in.read(magic, sizeof(magic));
  if (!in || std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
    throw std::runtime_error("Filter::load: not a fastslam filter state (bad magic)");
  }
  if (get<std::uint32_t>(in) != kVersion) {
    throw std::runtime_error("Filter::load: unknown version");
  }
  if (get<std::uint64_t>(in) != sizeof(FilterConfig)) {
    throw std::runtime_error("Filter::load: state written by an incompatible build");
  }
  // The config, checked before any of its values is used: a bool must be 0 or 1, and the
  // values must pass validate (enums in range, particles >= 1, ...).
  alignas(FilterConfig) unsigned char config_bytes[sizeof(FilterConfig)];
  read_bytes(in, config_bytes, sizeof(config_bytes));
  if (config_bytes[offsetof(FilterConfig, record_trajectory)] > 1 ||
      config_bytes[offsetof(FilterConfig, existence) +
                   offsetof(ExistenceConfig, negative_information)] > 1) {
    corrupt("config flag");
  }
  FilterConfig config;
  std::memcpy(&config, config_bytes, sizeof(config));
  try {
    validate(config);
  } catch (const std::invalid_argument& e) {
    corrupt(std::string("config: ") + e.what());
  }
  std::uint64_t counters[6];
  for (std::uint64_t& v : counters) v = get<std::uint64_t>(in);
  const std::uint64_t step = counters[0];
  const auto variance_bound = get<double>(in);
  if (!std::isfinite(variance_bound) || variance_bound < 0) corrupt("variance bound");
  constexpr std::uint64_t kLimit = std::uint64_t{1} << 34;
  std::vector<PendingControl> pending = get_vector<PendingControl>(in, kLimit);
  for (const PendingControl& c : pending) {
    if (!std::isfinite(c.u0) || !std::isfinite(c.u1) || !std::isfinite(c.dt) || c.dt < 0 ||
        c.step >= step) {
      corrupt("queued control");
    }
  }
  std::vector<TrajectoryPoint> trajectory = get_vector<TrajectoryPoint>(in, kLimit);
  const std::vector<KnownSlot> known = get_vector<KnownSlot>(in, kLimit);
  // Known association: the table maps distinct ids >= 0 onto the slots 0..K-1.
  std::vector<bool> slot_used(known.size(), false);
  for (const KnownSlot& k : known) {
    if (k.id < 0 || k.slot >= known.size() || slot_used[k.slot] || k.zero != 0) {
      corrupt("known-id table");
    }
    slot_used[k.slot] = true;
  }
  const std::uint64_t cov_size = std::uint64_t{config.particles} * 25;
  std::vector<double> pose_cov = get_vector<double>(in, cov_size);
  if (pose_cov.size() != cov_size) corrupt("covariance block size");

  std::unique_ptr<Impl> impl;
  try {
    impl = std::make_unique<Impl>(config);
  } catch (const std::invalid_argument& e) {
    corrupt(std::string("config: ") + e.what());
  }
  Impl& s = *impl;
  s.step = step;
  s.controls = counters[1];
  s.scans = counters[2];
  s.observations = counters[3];
  s.resamples = counters[4];
  s.weight_resets = counters[5];
  s.pending = std::move(pending);
  s.trajectory = std::move(trajectory);
  for (const KnownSlot& k : known) s.known_slots.emplace(k.id, k.slot);
  std::copy_n(pose_cov.begin(), s.store.pose_cov().size(), s.store.pose_cov().begin());
  s.landmark_variance_bound = variance_bound;
  memory::ParticleStore& store = s.store;
  for (std::span<double> column :
       {store.x(), store.y(), store.theta(), store.v(), store.omega(), store.log_weight()}) {
    read_bytes(in, column.data(), column.size() * sizeof(double));
  }
  for (std::size_t i = 0; i < store.size(); ++i) {
    if (!std::isfinite(store.x()[i]) || !std::isfinite(store.y()[i]) ||
        !std::isfinite(store.theta()[i]) || !std::isfinite(store.v()[i]) ||
        !std::isfinite(store.omega()[i]) || std::isnan(store.log_weight()[i]) ||
        store.log_weight()[i] == std::numeric_limits<double>::infinity()) {
      corrupt("particle " + std::to_string(i));
    }
  }
  for (std::size_t i = 0; i < store.size(); ++i) {
    const auto flag = get<std::uint8_t>(in);
    if (flag > 1 || (flag == 1 && i == 0)) corrupt("map sharing");
    if (flag == 1) {
      store.map(i) = store.map(i - 1);
      continue;
    }
    // Rebuild with the same slots: inserting in slot order takes the lowest free slot, so
    // placeholders fill the holes and are erased afterwards. Known association: every map
    // holds exactly the K known slots. Unknown: any count, and holes (removed landmarks) of at
    // most kMaxHoles in all, so a corrupt slot cannot make the load allocate without bound.
    memory::LandmarkTree map(s.heap);
    const bool known_ids = config.association == Association::kKnown;
    const auto count = get<std::uint64_t>(in);
    if (known_ids ? count != known.size() : count > kLimit) corrupt("map size");
    constexpr std::uint64_t kMaxHoles = std::uint64_t{1} << 24;
    std::vector<memory::Slot> holes;
    for (std::uint64_t k = 0; k < count; ++k) {
      const auto slot = get<memory::Slot>(in);
      const auto lm = get<memory::Landmark>(in);
      if ((known_ids && slot >= known.size()) || slot < map.size() ||
          slot - map.size() > kMaxHoles - holes.size()) {
        corrupt("slots out of order");
      }
      if (!std::isfinite(lm.x) || !std::isfinite(lm.y) || std::abs(lm.x) > 1e150 ||
          std::abs(lm.y) > 1e150) {
        corrupt("landmark position");
      }
      while (map.size() < slot) holes.push_back(map.insert({}));
      map.insert(lm);
    }
    for (memory::Slot hole : holes) map.erase(hole);
    store.map(i) = memory::ParticleMap(std::move(map), store.options().indexing, largest_variance);
  }
  return std::unique_ptr<Filter>(new Filter(std::move(impl)));
}

}  // namespace fastslam::engine
