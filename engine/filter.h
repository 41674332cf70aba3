// The FastSLAM 1.0 / 2.0 filter that embedders call (paper sections 4-5): M particles, each with
// its own persistent map. Feed it `predict(control, dt, time)` for every odometry sample and
// `observe(scan, time)` for every scan, in time order (the time is optional); read `estimate()`
// (poses, covariance, the last scan's associations, the map) and `statistics()` whenever you
// like; `save` and `load` the whole state (a restored filter continues bit-identically).
// Results are bit-identical for any thread count and grain. Bad input (non-finite values, a
// range <= 0, dt < 0, a missing or repeated id with known ids) throws std::invalid_argument and
// leaves the filter as it was. Owns its particles, maps, node heap and threads (a TBB arena of
// `config.threads`); `observe` borrows the scan for the call. Thread-compatible: one call at a
// time (a background task of its own may still run after `observe` returns; it touches only the
// filter's internals and the destructor waits for it). Costs (M particles, K queued controls, Z
// observations, N landmarks a map, k candidates and landmarks in view a particle): `predict`
// O(1) amortised; `observe` O(M (K + Z log N)) with known ids, O(M (K + (Z + k) log N + Z k))
// unknown, plus O(M) resampling; `estimate` O(M + N); `save` O(M N) worst case.
// docs/engine.md describes the algorithm and the stages a step runs through.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include "engine/enum_names.h"
#include "engine/filter_config.h"
#include "memory/landmark_tree.h"
#include "memory/particle_store.h"
#include "parallel/collective.h"

namespace fastslam::engine {

// One odometry sample; the meaning of the two numbers is the motion model's (MotionKind).
struct Control {
  double u0 = 0.0;
  double u1 = 0.0;
};

// Unknown association names a new landmark (scan step) * kLandmarkIdsPerScan + (observation
// index) (MapLandmark::id): unique and stable across copies, so a scan holds fewer observations.
inline constexpr std::uint64_t kLandmarkIdsPerScan = std::uint64_t{1} << 20;

// One detection of a scan. `id` is the landmark's identity in known-association mode (>= 0);
// ignored otherwise.
struct Observation {
  double range = 0.0;    // m, > 0
  double bearing = 0.0;  // rad, from the sensor's heading, counter-clockwise
  std::int64_t id = -1;
};

// A landmark of one particle's map, in that particle's world frame: its mean and covariance are
// conditioned on that particle's path, so they agree with its pose (Estimate::best_pose), not
// exactly with the weighted mean pose. `log_odds` is its existence (eq. 73-75; unknown
// association: below ExistenceConfig::remove_below it is removed, below confirm_at it is
// provisional and left out of Estimate::map). `id`: with known ids the observations'; under
// unknown association (scan step) * kLandmarkIdsPerScan + (index in that scan) of the
// observation that started it, the step counting every predict and observe call before it.
struct MapLandmark {
  memory::Slot slot = 0;
  std::uint64_t id = 0;
  double x = 0.0, y = 0.0;
  double sxx = 0.0, sxy = 0.0, syy = 0.0;
  double log_odds = 0.0;
  std::int64_t last_seen = 0;
};

// What became of one observation of a scan in one particle (ObservationAssociation).
enum class AssociationOutcome : std::uint8_t {
  kAssociated,  // updated an existing landmark
  kNew,         // started a landmark
  // Left out of the map: EkfSlam's observations between its two gates (EkfConfig). FastSLAM
  // never discards one: an observation no landmark explains better than p0 starts a landmark.
  kDiscarded,
};

template <>
struct EnumNames<AssociationOutcome> {
  static constexpr std::string_view kWhat = "association outcome";
  static constexpr std::array<EnumName<AssociationOutcome>, 3> kNames = {{
      {AssociationOutcome::kAssociated, "associated"},
      {AssociationOutcome::kNew, "new"},
      {AssociationOutcome::kDiscarded, "discarded"},
  }};
};

// One observation of the last scan, as the most likely particle took it.
struct ObservationAssociation {
  std::uint32_t observation = 0;  // index in the scan
  AssociationOutcome outcome = AssociationOutcome::kAssociated;
  // The landmark it updated or started (its MapLandmark::id); 0 when discarded.
  std::uint64_t landmark_id = 0;
  // Squared Mahalanobis distance v^T Q^-1 v to that landmark, as the association weighed it
  // (FastSLAM 2.0, unknown association: with the pose integrated out, eq. 60; known ids: at the
  // particle's drawn pose). For a new or discarded observation: to the nearest gated candidate
  // it did not take (mutual exclusion gave that one to another observation), +inf when none.
  double mahalanobis2 = 0.0;
};

struct Estimate {
  // The time of the latest data (predict / observe), in the caller's seconds: the last time
  // given, advanced by the dt of every untimed predict since; 0 until a time is given.
  double time = 0.0;
  // Weighted mean of the particles' poses (heading by circular mean); v, omega for kBrownian,
  // v, kappa for kBrownianCurvature.
  double mean_pose[5] = {0, 0, 0, 0, 0};
  // Weighted covariance of the particles' (x, y, theta) about mean_pose, row-major; heading
  // differences are wrapped to (-pi, pi]. Zero for a filter whose particles all coincide.
  double pose_covariance[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  // The pose of the particle of highest weight (lowest index on ties).
  double best_pose[5] = {0, 0, 0, 0, 0};
  std::uint32_t best_particle = 0;
  double effective_sample_size = 0.0;
  // The last scan's observations in scan order, for the particle of highest weight after that
  // scan's weighting and before resampling (lowest index on ties), which after resampling need
  // not be `best_particle`; empty before the first scan. Ids of the unknown-association
  // landmarks are shared by the copies a map was resampled into, so they name the same
  // landmarks in `map` wherever that particle's lineage and the best particle's agree.
  std::vector<ObservationAssociation> associations;
  // The best particle's confirmed landmarks, in slot order (EstimateMap::kCopy). With unknown
  // association, its provisional ones (log-odds below ExistenceConfig::confirm_at) are left out.
  std::vector<MapLandmark> map;
  // The best particle's landmarks, provisional ones included, copied or not (O(1)):
  // map.size() <= map_size.
  std::size_t map_size = 0;
};

// Whether `estimate` copies the best particle's map (O(N)) or only counts it (O(1)).
enum class EstimateMap : std::uint8_t { kCopy, kSizeOnly };

// The weighted-mean pose after one control (FilterConfig::record_trajectory).
struct TrajectoryPoint {
  std::uint64_t control = 0;  // index of the predict call, from 0
  double x = 0.0, y = 0.0, theta = 0.0;
};

struct FilterStatistics {
  std::uint64_t controls = 0;       // predict calls
  std::uint64_t scans = 0;          // observe calls
  std::uint64_t observations = 0;   // detections in all scans
  std::uint64_t resamples = 0;      // scans after which the particles were resampled
  std::uint64_t weight_resets = 0;  // scans whose every weight was zero (reset to uniform)
  // Time in each phase, summed over threads (thread-seconds), and the wall time of observe.
  double predict_seconds = 0.0;
  double associate_seconds = 0.0;  // unknown association: candidates, choice, 2.0's pose draw
  double update_seconds = 0.0;     // landmark updates, negative information, new landmarks
  double resample_seconds = 0.0;
  double observe_wall_seconds = 0.0;
  // Unknown association, summed over particles since construction (a loaded filter continues the
  // saved counts): landmarks started by observations, and removed by negative information.
  std::uint64_t landmarks_created = 0;
  std::uint64_t landmarks_removed = 0;
  // ln p(z_1..t | u_1..t), the filter's estimate of the data's likelihood under its models: the
  // sum over scans of ln sum_i w_i l_i (w the normalised weights before the scan, l_i particle
  // i's weight factor; new landmarks count ln p0). Compares settings (noises, a sensor offset)
  // on the same data without ground truth. -inf after a scan every particle found impossible.
  // Since construction, across save and load.
  double log_evidence = 0.0;
  // A rank of a particle set shared by a group (the Filter's group constructor), this rank's
  // part: distinct particles and copies its resamplings sent to other ranks, the bytes of
  // those messages, what sending each copy with its whole map would have cost, and the wall
  // time of the exchanges. Zero without a group.
  std::uint64_t exchange_particles = 0;
  std::uint64_t exchange_copies = 0;
  std::uint64_t exchange_bytes = 0;
  std::uint64_t exchange_naive_bytes = 0;
  double exchange_seconds = 0.0;
  // The node heap: live tree nodes and bytes of all maps together.
  std::int64_t live_nodes = 0;
  std::int64_t live_bytes = 0;
};

class Filter {
 public:
  // Throws std::invalid_argument as validate(config), and for Algorithm::kEkf (use EkfSlam).
  explicit Filter(const FilterConfig& config);
  // One rank's part of a filter whose particle set is spread over `group`
  // (parallel/collective.h; docs/distributed.md): config.particles is the whole set's M, of which
  // this rank holds the share parallel::particle_share deals it (throws std::invalid_argument
  // when the set has fewer blocks of 256 than the group has ranks). Every rank constructs it with
  // the same config and then makes the same calls with the same data: predict, observe,
  // set_map, estimate and take_trajectory are collective. Each returns on every rank the bits a
  // one-process Filter returns (Estimate::best_particle is the set's index); `particles()` is
  // this rank's share, and the statistics' times, landmark counts, live nodes and exchange
  // figures are this rank's. `save` throws std::logic_error: a shared set has no saved form.
  Filter(const FilterConfig& config, std::shared_ptr<parallel::Collective> group);
  ~Filter();
  Filter(const Filter&) = delete;
  Filter& operator=(const Filter&) = delete;

  const FilterConfig& config() const noexcept;

  // Queues one odometry sample of duration dt. Throws std::invalid_argument (and queues
  // nothing) unless dt >= 0 and every value is finite. The timed form also sets the filter's
  // clock (Estimate::time) to `time`, which must be finite and not before the clock (unless no
  // time was given yet); the untimed form advances the clock by dt.
  void predict(const Control& control, double dt);
  void predict(const Control& control, double dt, double time);
  // Queues controls[k] held for dt[k] (and, unless `times` is empty, at time times[k]) for every
  // k, as predict would one at a time, for front ends that hand over the odometry between two
  // scans in one call. All or nothing: throws std::invalid_argument naming the first bad index
  // (or unequal lengths) and queues none. Costs O(K).
  void predict(std::span<const Control> controls, std::span<const double> dt,
               std::span<const double> times = {});

  // Runs the queued controls and this scan through every particle, then resamples by policy.
  // Throws std::invalid_argument (and changes nothing) for a bad observation or time (as
  // predict's). The untimed form leaves the clock as it is.
  void observe(std::span<const Observation> scan);
  void observe(std::span<const Observation> scan, double time);

  // Replaces every particle's map by `landmarks` (one map, shared by all particles): a prior
  // map, a relocalisation, or a pre-grown map for benchmarks. Slots are assigned in order;
  // `slot` and `last_seen` of the input are ignored. With known ids each landmark's `id` is its
  // identity (distinct, < 2^63); otherwise ids are kept as given. Drains the queue first.
  // Throws std::invalid_argument (and changes nothing) for a non-finite or too large position
  // (|x|, |y| > 1e150), a covariance that is not symmetric positive definite, non-finite
  // log-odds, or a repeated id with known ids.
  // Costs: O(N log N) to build, O(M) to share; the old maps are released.
  void set_map(std::span<const MapLandmark> landmarks);

  // Drains the queue (as observe would, without a scan) and summarises the particles.
  // Costs O(M + Z), plus O(N) to copy the map.
  Estimate estimate(EstimateMap map = EstimateMap::kCopy);

  FilterStatistics statistics() const;

  // The last scan's report, as Estimate::associations, without summarising the particles: O(1).
  const std::vector<ObservationAssociation>& last_associations() const noexcept;

  // The weighted-mean pose after every control since the last call (drains the queue first).
  // Empty unless config.record_trajectory.
  std::vector<TrajectoryPoint> take_trajectory();

  // The particles, after draining the queue: for tests, tools and diagnostics.
  const memory::ParticleStore& particles();

  // The whole state (config, counters, queued controls, particles and maps) in a versioned
  // binary format; `load` throws std::runtime_error on a stream that is not one.
  void save(std::ostream& out) const;
  static std::unique_ptr<Filter> load(std::istream& in);
  // As load, running with `execution`'s threads, grain and split_seconds instead of the saved
  // ones (they change no result: the filter is bit-identical for any of them).
  static std::unique_ptr<Filter> load(std::istream& in, const FilterConfig& execution);

 private:
  struct Impl;
  explicit Filter(std::unique_ptr<Impl> impl);
  static std::unique_ptr<Filter> load(std::istream& in, const FilterConfig* execution);
  std::unique_ptr<Impl> impl_;
};

}  // namespace fastslam::engine
