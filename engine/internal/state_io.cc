#include "engine/internal/state_io.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <istream>
#include <limits>
#include <ostream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <Eigen/Eigenvalues>

#include "engine/internal/map_update.h"
#include "memory/tree_graph.h"

namespace fastslam::engine::internal {
namespace {

constexpr char kMagic[8] = {'F', 'S', 'L', 'A', 'M', 'S', 'T', '1'};
constexpr std::uint32_t kVersion = 5;  // 5: the maps as one graph of shared nodes
constexpr std::uint64_t kLimit = std::uint64_t{1} << 34;

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

// One entry of the last scan's report, with its padding spelled out (and zero).
struct SavedAssociation {
  std::uint32_t observation = 0;
  std::uint8_t outcome = 0;
  std::uint8_t zero[3] = {0, 0, 0};
  std::uint64_t landmark_id = 0;
  double mahalanobis2 = 0.0;
};
static_assert(sizeof(SavedAssociation) == 24 && std::is_trivially_copyable_v<SavedAssociation>);

std::vector<SavedAssociation> saved(const std::vector<ObservationAssociation>& report) {
  std::vector<SavedAssociation> out;
  out.reserve(report.size());
  for (const ObservationAssociation& a : report) {
    SavedAssociation e;
    e.observation = a.observation;
    e.outcome = static_cast<std::uint8_t>(a.outcome);
    e.landmark_id = a.landmark_id;
    e.mahalanobis2 = a.mahalanobis2;
    out.push_back(e);
  }
  return out;
}

std::vector<ObservationAssociation> get_report(std::istream& in) {
  const std::vector<SavedAssociation> entries = get_vector<SavedAssociation>(in, kLimit);
  std::vector<ObservationAssociation> report;
  report.reserve(entries.size());
  for (std::size_t j = 0; j < entries.size(); ++j) {
    const SavedAssociation& e = entries[j];
    if (e.observation != j ||
        e.outcome > static_cast<std::uint8_t>(AssociationOutcome::kDiscarded) || e.zero[0] != 0 ||
        e.zero[1] != 0 || e.zero[2] != 0 || std::isnan(e.mahalanobis2) || e.mahalanobis2 < 0) {
      corrupt("scan report");
    }
    report.push_back(
        {e.observation, static_cast<AssociationOutcome>(e.outcome), e.landmark_id, e.mahalanobis2});
  }
  return report;
}
static_assert(sizeof(PendingControl) == 32 && sizeof(TrajectoryPoint) == 32,
              "saved structs must have no padding");

void put_maps(const memory::ParticleStore& store, std::ostream& out) {
  memory::TreeGraphWriter graph(out);
  for (std::size_t i = 0; i < store.size(); ++i) graph.write(store.map(i).tree());
}

// The config, checked before any of its values is used: a bool must be 0 or 1, and the values
// must pass validate (enums in range, particles >= 1, ...).
// motion_draw sits in record_trajectory's padding: a state saved before it existed reads as the
// draw per control (its padding was cleared), and no later field moved.
static_assert(offsetof(FilterConfig, motion_draw) == offsetof(FilterConfig, record_trajectory) + 1);
static_assert(offsetof(FilterConfig, ekf) == offsetof(FilterConfig, record_trajectory) + 8);

FilterConfig get_config(std::istream& in) {
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
  return config;
}

// Known association: the table maps distinct ids >= 0 (saved in increasing order) onto the
// slots 0..K-1; `ids` gets each slot's id. Unknown association: the table is empty.
KnownSlots get_known(std::istream& in, bool known_ids, std::vector<std::int64_t>& ids) {
  const std::vector<KnownSlot> known = get_vector<KnownSlot>(in, kLimit);
  if (!known_ids && !known.empty()) corrupt("known-id table without known association");
  ids.assign(known.size(), -1);
  for (std::size_t j = 0; j < known.size(); ++j) {
    const KnownSlot& k = known[j];
    if (k.id < 0 || (j > 0 && k.id <= known[j - 1].id)) {
      corrupt("known-id table: ids negative, repeated or out of order");
    }
    if (k.slot >= known.size() || ids[k.slot] != -1 || k.zero != 0) {
      corrupt("known-id table: slot " + std::to_string(k.slot) + " out of range or repeated");
    }
    ids[k.slot] = k.id;
  }
  KnownSlots table;
  for (const KnownSlot& k : known) table.emplace(k.id, k.slot);
  return table;
}

// Finite poses; log-weights at most 0 (every scan normalises them, l_i -= log sum exp l), at
// least one above -inf (the estimate and resampling normalise by the largest).
void get_columns(std::istream& in, memory::ParticleStore& store) {
  for (std::span<double> column :
       {store.x(), store.y(), store.theta(), store.v(), store.omega(), store.log_weight()}) {
    read_bytes(in, column.data(), column.size() * sizeof(double));
  }
  bool possible = false;
  for (std::size_t i = 0; i < store.size(); ++i) {
    if (!std::isfinite(store.x()[i]) || !std::isfinite(store.y()[i]) ||
        !std::isfinite(store.theta()[i]) || !std::isfinite(store.v()[i]) ||
        !std::isfinite(store.omega()[i]) || std::isnan(store.log_weight()[i]) ||
        store.log_weight()[i] > 0.0) {
      corrupt("particle " + std::to_string(i));
    }
    possible = possible || std::isfinite(store.log_weight()[i]);
  }
  if (!possible) corrupt("every particle's weight is zero");
}

// A landmark as the engine keeps one: set_map's rules (a finite position within 1e150, a
// symmetric positive definite covariance, which the updates invert; finite log-odds), last seen
// at a step already taken, and with known ids the id the table gives its slot.
void check_landmark(const memory::Landmark& lm, memory::Slot slot, std::size_t particle,
                    std::uint64_t step, const std::vector<std::int64_t>& known_ids) {
  auto where = [&] {
    return "landmark in slot " + std::to_string(slot) + " of particle " + std::to_string(particle) +
           ": ";
  };
  if (!std::isfinite(lm.x) || !std::isfinite(lm.y) || std::abs(lm.x) > 1e150 ||
      std::abs(lm.y) > 1e150) {
    corrupt(where() + "position");
  }
  const double det = lm.sxx * lm.syy - lm.sxy * lm.sxy;
  if (!std::isfinite(lm.sxx) || !std::isfinite(lm.sxy) || !std::isfinite(lm.syy) || !(lm.sxx > 0) ||
      !(det > 0) || !std::isfinite(det)) {
    corrupt(where() + "covariance not positive definite");
  }
  if (!std::isfinite(lm.log_odds)) corrupt(where() + "log-odds");
  if (lm.last_seen < 0 || static_cast<std::uint64_t>(lm.last_seen) > step) {
    corrupt(where() + "last seen after the current step");
  }
  if (!known_ids.empty() && lm.id != static_cast<std::uint64_t>(known_ids[slot])) {
    corrupt(where() + "id differs from the known-id table's");
  }
}

// FastSLAM 2.0's proposal factors each particle's pose covariance: its N x N block (N the
// motion state's dimension) must be symmetric and positive semi-definite, the rest of the slot
// zero. The eigenvalues may fall below zero by rounding only (relative to the largest).
void check_pose_covariances(const MotionConfig& motion, const std::vector<double>& values) {
  const int n = visit_motion(
      motion, [](const auto& model) { return std::remove_cvref_t<decltype(model)>::kStateDim; });
  constexpr std::size_t kSlot = PoseCovariances::kSlot;
  for (std::size_t i = 0; i * kSlot < values.size(); ++i) {
    const double* p = &values[i * kSlot];
    const std::string what = "pose covariance of particle " + std::to_string(i);
    for (std::size_t k = static_cast<std::size_t>(n * n); k < kSlot; ++k) {
      if (p[k] != 0.0) corrupt(what + ": entry " + std::to_string(k) + " outside the block");
    }
    const Eigen::Map<const Eigen::MatrixXd> c(p, n, n);
    if (c != c.transpose()) corrupt(what + ": not symmetric");
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(c, Eigen::EigenvaluesOnly);
    const Eigen::VectorXd& values_i = eigen.eigenvalues();
    if (eigen.info() != Eigen::Success ||
        values_i.minCoeff() < -1e-9 * std::max(1.0, values_i.maxCoeff())) {
      corrupt(what + ": not positive semi-definite");
    }
  }
}

}  // namespace

void save_state(const FilterState& s, const std::vector<TrajectoryPoint>& trajectory,
                std::ostream& out) {
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
  const FilterCounters& c = s.counters;
  std::uint64_t created = c.landmarks_created, removed = c.landmarks_removed;
  s.phase_times.combine_each([&](const PhaseTimes& t) {
    created += t.created;
    removed += t.removed;
  });
  for (std::uint64_t v : {c.step, c.controls, c.scans, c.observations, c.resamples, c.weight_resets,
                          created, removed}) {
    put(out, v);
  }
  put(out, c.log_evidence);
  put(out, s.landmark_variance_bound);
  put(out, s.time);
  put<std::uint8_t>(out, s.timed ? 1 : 0);
  put_vector(out, saved(s.associations));
  put_vector(out, s.pending);
  put_vector(out, trajectory);
  std::vector<KnownSlot> known;
  known.reserve(s.known_slots.size());
  for (const auto& [id, slot] : s.known_slots) known.push_back({id, slot, 0});
  std::sort(known.begin(), known.end(),
            [](const KnownSlot& a, const KnownSlot& b) { return a.id < b.id; });
  put_vector(out, known);
  // M x 25 doubles, zeros when the store keeps none (FastSLAM 1.0).
  const std::span<const double> kept = s.covariances.values();
  std::vector<double> covariances(kept.begin(), kept.end());
  covariances.resize(s.store.size() * PoseCovariances::kSlot, 0.0);
  put_vector(out, covariances);
  const memory::ParticleStore& store = s.store;
  for (std::span<const double> column :
       {store.x(), store.y(), store.theta(), store.v(), store.omega(), store.log_weight()}) {
    out.write(reinterpret_cast<const char*>(column.data()),
              static_cast<std::streamsize>(column.size() * sizeof(double)));
  }
  put_maps(store, out);
  if (!out) throw std::runtime_error("Filter::save: write failed");
}

StateHeader read_header(std::istream& in) {
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
  StateHeader h;
  h.config = get_config(in);
  FilterCounters& c = h.counters;
  for (std::uint64_t* v : {&c.step, &c.controls, &c.scans, &c.observations, &c.resamples,
                           &c.weight_resets, &c.landmarks_created, &c.landmarks_removed}) {
    *v = get<std::uint64_t>(in);
  }
  c.log_evidence = get<double>(in);
  // The random streams are keyed by step < 2^56 (parallel/random_stream.h); every step is a
  // control or a scan, and a scan resamples or resets the weights at most once.
  if (c.step >= std::uint64_t{1} << 56) corrupt("step counter");
  if (c.controls > c.step || c.scans != c.step - c.controls) {
    corrupt("counters: controls and scans do not add up to the steps");
  }
  if (c.resamples > c.scans || c.weight_resets > c.scans) {
    corrupt("counters: more resamples or weight resets than scans");
  }
  // Every observation starts at most one landmark per particle, and only a started one can be
  // removed.
  std::uint64_t most = 0;
  if (__builtin_mul_overflow(c.observations, std::uint64_t{h.config.particles}, &most)) {
    most = std::numeric_limits<std::uint64_t>::max();
  }
  if (c.landmarks_created > most || c.landmarks_removed > c.landmarks_created) {
    corrupt("counters: more landmarks created than observations, or removed than created");
  }
  // A sum of logs of probabilities' sums: finite, or -inf once a scan was impossible.
  if (std::isnan(c.log_evidence) || c.log_evidence == std::numeric_limits<double>::infinity()) {
    corrupt("log evidence");
  }
  h.variance_bound = get<double>(in);
  if (!std::isfinite(h.variance_bound) || h.variance_bound < 0) corrupt("variance bound");
  h.time = get<double>(in);
  const auto timed = get<std::uint8_t>(in);
  if (!std::isfinite(h.time) || timed > 1) corrupt("clock");
  h.timed = timed == 1;
  h.associations = get_report(in);
  if (h.associations.size() > c.observations || (c.scans == 0 && !h.associations.empty())) {
    corrupt("scan report longer than the observations seen");
  }
  h.pending = get_vector<PendingControl>(in, kLimit);
  if (h.pending.size() > c.controls) corrupt("more queued controls than controls");
  for (std::size_t k = 0; k < h.pending.size(); ++k) {
    const PendingControl& p = h.pending[k];
    if (!std::isfinite(p.u0) || !std::isfinite(p.u1) || !std::isfinite(p.dt) || p.dt < 0 ||
        p.step >= c.step || (k > 0 && p.step <= h.pending[k - 1].step)) {
      corrupt("queued control " + std::to_string(k));
    }
  }
  h.trajectory = get_vector<TrajectoryPoint>(in, kLimit);
  if (!h.config.record_trajectory && !h.trajectory.empty()) {
    corrupt("trajectory recorded without record_trajectory");
  }
  for (std::size_t k = 0; k < h.trajectory.size(); ++k) {
    const TrajectoryPoint& p = h.trajectory[k];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.theta) ||
        p.control >= c.controls || (k > 0 && p.control <= h.trajectory[k - 1].control)) {
      corrupt("trajectory point " + std::to_string(k));
    }
  }
  h.known = get_known(in, h.config.association == Association::kKnown, h.known_ids);
  const std::uint64_t cov_size = std::uint64_t{h.config.particles} * PoseCovariances::kSlot;
  h.covariances = get_vector<double>(in, cov_size);
  if (h.covariances.size() != cov_size) corrupt("covariance block size");
  // FastSLAM 1.0 keeps none and saves zeros.
  const bool kept = h.config.algorithm == Algorithm::kFastSlam2;
  for (double v : h.covariances) {
    if (!std::isfinite(v) || (!kept && v != 0.0)) corrupt("pose covariance");
  }
  if (kept) check_pose_covariances(h.config.motion, h.covariances);
  return h;
}

void read_particles(std::istream& in, StateHeader&& h, FilterState& s) {
  s.counters = h.counters;
  s.pending = std::move(h.pending);
  s.known_slots = std::move(h.known);
  const std::span<double> kept = s.covariances.values();
  std::copy_n(h.covariances.begin(), kept.size(), kept.begin());
  s.landmark_variance_bound = h.variance_bound;
  s.time = h.time;
  s.timed = h.timed;
  s.associations = std::move(h.associations);
  memory::ParticleStore& store = s.store;
  get_columns(in, store);
  // The maps, as the graph of nodes they shared when saved (memory/tree_graph.h). Each index is
  // the previous particle's changed where the maps differ, so indices share as the maps do: the
  // engine keeps particles in ancestry order (resampling's ancestors come out sorted), so the
  // previous particle is the nearest relative, and the changes add up to a few times the nodes
  // read. That bound is enforced: a graph whose neighbouring maps differ by far more than the
  // input holds (shared trees in an order no filter makes) is refused, not rebuilt at length.
  // With known ids every map holds exactly the K known slots: K landmarks, all below K.
  const bool known_ids = s.config.association == Association::kKnown;
  const std::size_t known_count = h.known_ids.size();
  memory::TreeGraphReader graph(in, s.heap);
  std::uint64_t steps = 0;  // index work allowed and not yet used
  std::uint64_t nodes_counted = 0, landmarks_counted = 0;
  try {
    for (std::size_t i = 0; i < store.size(); ++i) {
      memory::LandmarkTree map = graph.read([&](memory::Slot slot, const memory::Landmark& lm) {
        if (known_ids && slot >= known_count) {
          corrupt("slot " + std::to_string(slot) + " of particle " + std::to_string(i) +
                  " beyond the known ids");
        }
        check_landmark(lm, slot, i, s.counters.step, h.known_ids);
      });
      if (known_ids && map.size() != known_count) {
        corrupt("map size of particle " + std::to_string(i));
      }
      steps += 64 + 64 * (graph.nodes_read() - nodes_counted) +
               16 * (graph.landmarks_read() - landmarks_counted);
      nodes_counted = graph.nodes_read();
      landmarks_counted = graph.landmarks_read();
      if (i == 0) {
        store.map(i) = memory::ParticleMap(std::move(map), store.options().indexing,
                                           largest_variance);
      } else {
        try {
          store.map(i) =
              memory::ParticleMap(std::move(map), store.map(i - 1), largest_variance, steps);
        } catch (const std::length_error&) {
          corrupt("the map of particle " + std::to_string(i) +
                  " differs from its neighbour's by far more than the state's nodes hold");
        }
      }
    }
    graph.finish();
  } catch (const memory::TreeGraphError& e) {
    if (graph.truncated()) throw std::runtime_error("Filter::load: truncated or unreadable state");
    corrupt(e.what());
  }
}

}  // namespace fastslam::engine::internal
