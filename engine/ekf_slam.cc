#include "engine/ekf_slam.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "engine/angles.h"
#include "engine/internal/scan_plan.h"
#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/motion_dispatch.h"
#include "engine/motion_model.h"

namespace fastslam::engine {

namespace {
constexpr double kInfinity = std::numeric_limits<double>::infinity();
}  // namespace
namespace {

using Clock = std::chrono::steady_clock;
using Index = Eigen::Index;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

int pose_dim_of(MotionKind kind) { return motion_state_dim(kind); }

constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();

// A candidate pairing of observation `obs` with landmark `landmark` (ML association), with the
// linearisation and innovation it was scored with.
struct Candidate {
  double d2 = 0.0;
  std::size_t obs = 0;
  std::size_t landmark = 0;
  MeasurementLinearization<3> lin;
  Eigen::Vector2d v;
};

// v^T C^-1 v for a small symmetric positive definite C, by a plain Cholesky factorisation
// (C = L L^T, then |L^-1 v|^2); infinity when C is not positive definite. Plain loops: the sizes
// are tiny, and GCC 12 misreports Eigen's AVX-512 kernels for dynamic factorisations.
double quadratic_form_spd(Eigen::MatrixXd& c, const Eigen::VectorXd& v) {
  const Eigen::Index m = c.rows();
  for (Eigen::Index j = 0; j < m; ++j) {
    double diag = c(j, j);
    for (Eigen::Index k = 0; k < j; ++k) diag -= c(j, k) * c(j, k);
    if (!(diag > 0) || !std::isfinite(diag)) return std::numeric_limits<double>::infinity();
    c(j, j) = std::sqrt(diag);
    for (Eigen::Index i = j + 1; i < m; ++i) {
      double sum = c(i, j);
      for (Eigen::Index k = 0; k < j; ++k) sum -= c(i, k) * c(j, k);
      c(i, j) = sum / c(j, j);
    }
  }
  double quad = 0.0;
  std::vector<double> y(static_cast<std::size_t>(m));
  for (Eigen::Index i = 0; i < m; ++i) {
    double sum = v[i];
    for (Eigen::Index k = 0; k < i; ++k) sum -= c(i, k) * y[static_cast<std::size_t>(k)];
    y[static_cast<std::size_t>(i)] = sum / c(i, i);
    quad += y[static_cast<std::size_t>(i)] * y[static_cast<std::size_t>(i)];
  }
  return quad;
}

// The chi-square quantile with 2k degrees of freedom at probability q, by bisection on the
// closed-form CDF of even degrees: 1 - exp(-x/2) sum_{i<k} (x/2)^i / i!.
double chi2_quantile_even(int k, double q) {
  auto cdf = [k](double x) {
    double term = 1.0, sum = 1.0;
    for (int i = 1; i < k; ++i) {
      term *= 0.5 * x / i;
      sum += term;
    }
    return 1.0 - std::exp(-0.5 * x) * sum;
  };
  double lo = 0.0, hi = 1.0;
  while (cdf(hi) < q) hi *= 2;
  for (int it = 0; it < 100; ++it) {
    const double mid = 0.5 * (lo + hi);
    (cdf(mid) < q ? lo : hi) = mid;
  }
  return hi;
}

}  // namespace

struct EkfSlam::Impl {
  explicit Impl(const FilterConfig& c)
      : config(checked(c)), sensor(c.sensor.offset), d(pose_dim_of(c.motion.kind)), n(d) {
    r << c.sensor.sigma_range * c.sensor.sigma_range, 0, 0,
        c.sensor.sigma_bearing * c.sensor.sigma_bearing;
    x = Eigen::VectorXd::Zero(d);
    for (int k = 0; k < d; ++k) x[k] = c.initial_pose[k];
    x[2] = wrap_angle(x[2]);
    p = Eigen::MatrixXd::Zero(d, d);
  }

  static const FilterConfig& checked(const FilterConfig& c) {
    validate(c);
    if (c.algorithm != Algorithm::kEkf) {
      throw std::invalid_argument(std::string("EkfSlam: algorithm '") +
                                  std::string(to_string(c.algorithm)) +
                                  "' is a particle filter; construct engine::Filter "
                                  "(engine/filter.h) instead, or set algorithm = ekf");
    }
    return c;
  }

  std::size_t landmarks() const { return static_cast<std::size_t>((n - d) / 2); }
  Index offset_of(std::size_t landmark) const { return d + 2 * static_cast<Index>(landmark); }
  Pose pose() const { return x.head<3>(); }

  // Room for a state of `size`: grows the storage by 1.25x (at least) and copies the lower
  // triangle. Leaves the state unchanged if the allocation fails.
  void ensure_capacity(Index size) {
    if (size <= p.rows()) return;
    const Index cap = std::max(size, p.rows() + p.rows() / 4 + 8);
    Eigen::MatrixXd q = Eigen::MatrixXd::Zero(cap, cap);
    Eigen::VectorXd y = Eigen::VectorXd::Zero(cap);
    for (Index j = 0; j < n; ++j) q.col(j).segment(j, n - j) = p.col(j).segment(j, n - j);
    y.head(n) = x.head(n);
    p.swap(q);
    x.swap(y);
  }

  // Columns 0..2 (x, y, theta) of the symmetric covariance, n x 3, and the two columns of the
  // landmark at state offset `a`, n x 2, assembled from the lower triangle: O(n).
  void pose_columns(Eigen::Ref<Eigen::MatrixXd> out) const {
    out = p.block(0, 0, n, 3);
    out(0, 1) = p(1, 0);
    out(0, 2) = p(2, 0);
    out(1, 2) = p(2, 1);
  }
  void landmark_columns(Index a, Eigen::Ref<Eigen::MatrixXd> out) const {
    out.col(0).head(a) = p.row(a).head(a).transpose();
    out.col(1).head(a) = p.row(a + 1).head(a).transpose();
    out.col(0).tail(n - a) = p.col(a).segment(a, n - a);
    out(a, 1) = p(a + 1, a);
    out.col(1).tail(n - a - 1) = p.col(a + 1).segment(a + 1, n - a - 1);
  }
  Eigen::Matrix3d pose_block() const {
    return p.topLeftCorner<3, 3>().selfadjointView<Eigen::Lower>();
  }

  template <class Motion>
  void predict_with(const Motion& motion, const Control& control, double dt) {
    constexpr int D = Motion::kStateDim;
    using State = typename Motion::State;
    const State s = x.head<D>();
    typename Motion::Control u(control.u0, control.u1);
    if constexpr (Motion::kNoOdometry) u.setZero();
    const typename Motion::Control sigmas(config.motion.sigma_control[0],
                                          config.motion.sigma_control[1]);
    const auto f = motion.jacobian_pose(s, u, dt);
    const Eigen::Matrix<double, D, D> pss =
        p.topLeftCorner<D, D>().template selfadjointView<Eigen::Lower>();
    Eigen::Matrix<double, D, D> next =
        f * pss * f.transpose() + motion.pose_noise(s, u, dt, Motion::control_covariance(sigmas));
    p.topLeftCorner<D, D>() = 0.5 * (next + next.transpose());
    // The pose-landmark block, stored as its transpose (landmark rows, pose columns): P_mx F^T.
    if (n > D) {
      auto pmx = p.block(D, 0, n - D, D);
      pmx = pmx * f.transpose();  // Eigen evaluates the product into a temporary first
    }
    x.head<D>() = motion.predict(s, u, dt);
  }

  void predict(const Control& control, double dt) {
    visit_motion(config.motion, [&](const auto& motion) { predict_with(motion, control, dt); });
  }

  // The innovation covariance S of z against landmark `landmark` at the current state, its
  // inverse and the innovation: O(1), from the blocks (pose, pose), (landmark, pose) and
  // (landmark, landmark). Returns false when S is not usable (a landmark at the sensor).
  struct Scored {
    MeasurementLinearization<3> lin;
    Eigen::Vector2d v;
    Eigen::Matrix2d s_inv;
    double d2 = 0.0;
  };
  bool score(std::size_t landmark, const Eigen::Matrix3d& pss, const Eigen::Vector2d& z,
             Scored& out) const {
    const Index a = offset_of(landmark);
    out.lin = sensor.linearize(x.segment<2>(a), pose());
    const Eigen::Matrix<double, 2, 3> pms = p.block<2, 3>(a, 0);
    const Eigen::Matrix2d pmm = p.block<2, 2>(a, a).selfadjointView<Eigen::Lower>();
    const Eigen::Matrix2d cross = out.lin.g_pose * pms.transpose() * out.lin.g_landmark.transpose();
    Eigen::Matrix2d s = out.lin.g_pose * pss * out.lin.g_pose.transpose() + cross +
                        cross.transpose() +
                        out.lin.g_landmark * pmm * out.lin.g_landmark.transpose() + r;
    s(0, 1) = s(1, 0) = 0.5 * (s(0, 1) + s(1, 0));
    const double det = s(0, 0) * s(1, 1) - s(0, 1) * s(0, 1);
    if (!std::isfinite(det) || !(det > 0) || !(s(0, 0) > 0)) return false;
    out.s_inv << s(1, 1) / det, -s(0, 1) / det, -s(0, 1) / det, s(0, 0) / det;
    out.v = RangeBearingModel::innovation(z, out.lin.z_hat);
    out.d2 = out.v.dot(out.s_inv * out.v);
    return std::isfinite(out.d2);
  }

  // One EKF update of landmark `landmark` with measurement z: O(n^2). Returns the squared
  // Mahalanobis distance of the innovation.
  double update(std::size_t landmark, const Eigen::Vector2d& z, std::size_t obs_index) {
    const Index a = offset_of(landmark);
    const auto lin = sensor.linearize(x.segment<2>(a), pose());
    // P H^T from the five columns H touches.
    columns.resize(n, 5);
    pose_columns(columns.leftCols<3>());
    landmark_columns(a, columns.rightCols<2>());
    Eigen::Matrix<double, 2, 5> h;
    h << lin.g_pose, lin.g_landmark;
    pht.noalias() = columns * h.transpose();
    Eigen::Matrix2d s =
        h.leftCols<3>() * pht.topRows<3>() + h.rightCols<2>() * pht.middleRows<2>(a) + r;
    s(0, 1) = s(1, 0) = 0.5 * (s(0, 1) + s(1, 0));
    const double det = s(0, 0) * s(1, 1) - s(0, 1) * s(0, 1);
    if (!std::isfinite(det) || !(det > 0) || !(s(0, 0) > 0)) {
      throw std::runtime_error("EkfSlam::observe: observation " + std::to_string(obs_index) +
                               ": the innovation covariance is not positive definite (det " +
                               std::to_string(det) + ")");
    }
    Eigen::Matrix2d s_inv;
    s_inv << s(1, 1) / det, -s(0, 1) / det, -s(0, 1) / det, s(0, 0) / det;
    gain.noalias() = pht * s_inv;
    const Eigen::Vector2d v = RangeBearingModel::innovation(z, lin.z_hat);
    x.head(n).noalias() += gain * v;
    x[2] = wrap_angle(x[2]);
    // P -= K (P H^T)^T on the lower triangle: column j, rows j..n-1.
    for (Index j = 0; j < n; ++j) {
      const double c0 = pht(j, 0);
      const double c1 = pht(j, 1);
      p.col(j).segment(j, n - j) -=
          gain.col(0).segment(j, n - j) * c0 + gain.col(1).segment(j, n - j) * c1;
    }
    return v.dot(s_inv * v);
  }

  // A new landmark from z at the current pose, with its cross-covariances. REQUIRES capacity.
  void augment(const Eigen::Vector2d& z, std::int64_t id, std::int64_t seen_at) {
    const Pose s = pose();
    const Eigen::Vector2d m = sensor.landmark_from(z, s);
    const Eigen::Matrix<double, 2, 3> js = sensor.inverse_jacobian_pose(z, s);
    const Eigen::Matrix2d jz = sensor.inverse_jacobian_measurement(z, s);
    columns.resize(n, 3);
    pose_columns(columns.leftCols<3>());
    const Index a = n;
    // cov(m, everything) = J_s P_{s,.}: rows a and a+1, columns 0..n-1 (lower triangle).
    // (A plain loop: GCC 12's -Warray-bounds misfires on Eigen's product kernel with js here.)
    for (Index i = 0; i < n; ++i) {
      const double c0 = columns(i, 0), c1 = columns(i, 1), c2 = columns(i, 2);
      p(a, i) = js(0, 0) * c0 + js(0, 1) * c1 + js(0, 2) * c2;
      p(a + 1, i) = js(1, 0) * c0 + js(1, 1) * c1 + js(1, 2) * c2;
    }
    Eigen::Matrix2d pmm =
        js * columns.topLeftCorner<3, 3>() * js.transpose() + jz * r * jz.transpose();
    pmm(0, 1) = pmm(1, 0) = 0.5 * (pmm(0, 1) + pmm(1, 0));
    p.block<2, 2>(a, a) = pmm;
    x.segment<2>(a) = m;
    n += 2;
    ids.push_back(id);
    last_seen.push_back(seen_at);
  }

  void observe_known(std::span<const Observation> scan) {
    std::unordered_set<std::int64_t> in_scan;
    std::size_t fresh = 0;
    for (std::size_t j = 0; j < scan.size(); ++j) {
      const Observation& o = scan[j];
      if (o.id < 0) {
        throw std::invalid_argument("EkfSlam::observe: observation " + std::to_string(j) +
                                    ": known association needs a landmark id >= 0 (got " +
                                    std::to_string(o.id) + ")");
      }
      if (!in_scan.insert(o.id).second) {
        throw std::invalid_argument("EkfSlam::observe: observation " + std::to_string(j) +
                                    ": landmark id " + std::to_string(o.id) +
                                    " appears twice in one scan");
      }
      if (!index_of_id.contains(o.id)) ++fresh;
    }
    // Everything that can fail on allocation, before any change.
    ensure_capacity(n + 2 * static_cast<Index>(fresh));
    ids.reserve(ids.size() + fresh);
    last_seen.reserve(last_seen.size() + fresh);
    index_of_id.reserve(index_of_id.size() + fresh);
    const auto step_now = static_cast<std::int64_t>(step);
    report.assign(scan.size(), {});
    for (std::size_t j = 0; j < scan.size(); ++j) {
      report[j] = {static_cast<std::uint32_t>(j), AssociationOutcome::kAssociated,
                   static_cast<std::uint64_t>(scan[j].id), kInfinity};
      const auto found = index_of_id.find(scan[j].id);
      if (found == index_of_id.end()) continue;
      report[j].mahalanobis2 = update(found->second, measurement(scan[j]), j);
      last_seen[found->second] = step_now;
      ++counts.updated;
    }
    for (std::size_t j = 0; j < scan.size(); ++j) {
      if (index_of_id.contains(scan[j].id)) continue;
      index_of_id.emplace(scan[j].id, landmarks());
      augment(measurement(scan[j]), scan[j].id, step_now);
      report[j].outcome = AssociationOutcome::kNew;
      ++counts.created;
    }
  }

  // Joint compatibility branch and bound (Neira and Tardos 2001) over the individually
  // compatible candidates: the hypothesis with the most pairings whose joint squared Mahalanobis
  // distance (all pairs' innovations together, with their correlations) is below the chi-square
  // quantile of 2k degrees of freedom at the confidence of gate_accept; ties go to the smaller
  // distance. The search stops after kJcbbNodeBudget hypotheses and keeps the best so far.
  static constexpr std::size_t kJcbbNodeBudget = 100'000;

  std::vector<std::size_t> jcbb(const std::vector<Candidate>& accepted, std::size_t z,
                                const Eigen::Matrix3d& pss) const {
    std::vector<std::vector<const Candidate*>> options(z);
    for (const Candidate& c : accepted) options[c.obs].push_back(&c);
    // 2-dof confidence of the individual gate, then the quantile per hypothesis size.
    const double confidence = 1.0 - std::exp(-0.5 * config.ekf.gate_accept);
    std::vector<double> gate(z + 1, 0.0);
    for (std::size_t k = 1; k <= z; ++k) {
      gate[k] = chi2_quantile_even(static_cast<int>(k), confidence);
    }
    std::vector<const Candidate*> pairs;
    std::vector<std::size_t> best(z, kNone), current(z, kNone);
    std::size_t best_pairs = 0;
    double best_d2 = 0.0;
    std::size_t nodes = 0;
    std::vector<bool> taken(landmarks(), false);
    // The joint distance of `pairs`: C_ab = H_a P H_b^T (+ R on the diagonal), from the blocks.
    auto joint_d2 = [&]() {
      const auto k = static_cast<Index>(pairs.size());
      Eigen::MatrixXd c(2 * k, 2 * k);
      Eigen::VectorXd v(2 * k);
      for (Index a = 0; a < k; ++a) {
        const Candidate& ca = *pairs[a];
        const Index la = offset_of(ca.landmark);
        v.segment<2>(2 * a) = ca.v;
        for (Index b = 0; b <= a; ++b) {
          const Candidate& cb = *pairs[b];
          const Index lb = offset_of(cb.landmark);
          // P_{ma,mb} from the lower triangle (la > lb: a below b; equal: the diagonal block).
          const Eigen::Matrix2d pmm =
              la == lb  ? Eigen::Matrix2d(p.block<2, 2>(la, la).selfadjointView<Eigen::Lower>())
              : la > lb ? Eigen::Matrix2d(p.block<2, 2>(la, lb))
                        : Eigen::Matrix2d(p.block<2, 2>(lb, la).transpose());
          const Eigen::Matrix<double, 2, 3> pas = p.block<2, 3>(la, 0);
          const Eigen::Matrix<double, 2, 3> pbs = p.block<2, 3>(lb, 0);
          Eigen::Matrix2d block = ca.lin.g_pose * pss * cb.lin.g_pose.transpose() +
                                  ca.lin.g_pose * pbs.transpose() * cb.lin.g_landmark.transpose() +
                                  ca.lin.g_landmark * pas * cb.lin.g_pose.transpose() +
                                  ca.lin.g_landmark * pmm * cb.lin.g_landmark.transpose();
          if (a == b) block += r;
          c.block<2, 2>(2 * a, 2 * b) = block;
          c.block<2, 2>(2 * b, 2 * a) = block.transpose();
        }
      }
      return quadratic_form_spd(c, v);
    };
    auto search = [&](auto&& self, std::size_t j, double d2) -> void {
      if (++nodes > kJcbbNodeBudget) return;
      if (j == z) {
        if (pairs.size() > best_pairs || (pairs.size() == best_pairs && d2 < best_d2)) {
          best = current;
          best_pairs = pairs.size();
          best_d2 = d2;
        }
        return;
      }
      for (const Candidate* c : options[j]) {
        if (taken[c->landmark]) continue;
        pairs.push_back(c);
        const double joint = joint_d2();
        if (joint < gate[pairs.size()]) {
          taken[c->landmark] = true;
          current[j] = c->landmark;
          self(self, j + 1, joint);
          current[j] = kNone;
          taken[c->landmark] = false;
        }
        pairs.pop_back();
      }
      // Leave j unpaired only if that can still beat the best.
      if (pairs.size() + (z - j - 1) >= best_pairs) self(self, j + 1, d2);
    };
    search(search, 0, 0.0);
    return best;
  }

  void observe_ml(std::span<const Observation> scan) {
    // Score every (observation, landmark) pair at the state before the scan.
    const std::size_t count = landmarks();
    const Eigen::Matrix3d pss = pose_block();
    std::vector<Candidate> accepted;
    std::vector<double> nearest(scan.size(), std::numeric_limits<double>::infinity());
    Scored scored;
    for (std::size_t j = 0; j < scan.size(); ++j) {
      const Eigen::Vector2d z = measurement(scan[j]);
      for (std::size_t i = 0; i < count; ++i) {
        if (!score(i, pss, z, scored)) continue;
        nearest[j] = std::min(nearest[j], scored.d2);
        if (scored.d2 < config.ekf.gate_accept) {
          accepted.push_back({scored.d2, j, i, scored.lin, scored.v});
        }
      }
    }
    // The closest pairs first (greedy order; JCBB tries each observation's candidates in it).
    std::sort(accepted.begin(), accepted.end(), [](const Candidate& a, const Candidate& b) {
      if (a.d2 != b.d2) return a.d2 < b.d2;
      return a.obs != b.obs ? a.obs < b.obs : a.landmark < b.landmark;
    });
    std::vector<std::size_t> match(scan.size(), kNone);
    if (config.ekf.joint_compatibility) {
      match = jcbb(accepted, scan.size(), pss);
    } else {
      // Greedy mutual exclusion: each observation and landmark once.
      std::vector<bool> taken(count, false);
      for (const Candidate& c : accepted) {
        if (match[c.obs] != kNone || taken[c.landmark]) continue;
        match[c.obs] = c.landmark;
        taken[c.landmark] = true;
      }
    }
    std::size_t fresh = 0;
    for (std::size_t j = 0; j < scan.size(); ++j) {
      if (match[j] == kNone && nearest[j] > config.ekf.gate_new) ++fresh;
    }
    ensure_capacity(n + 2 * static_cast<Index>(fresh));
    ids.reserve(ids.size() + fresh);
    last_seen.reserve(last_seen.size() + fresh);
    const auto step_now = static_cast<std::int64_t>(step);
    // The report: a pair's distance as the choice scored it, before the scan's updates.
    report.assign(scan.size(), {});
    for (const Candidate& c : accepted) {
      if (match[c.obs] == c.landmark) {
        report[c.obs] = {static_cast<std::uint32_t>(c.obs), AssociationOutcome::kAssociated,
                         static_cast<std::uint64_t>(ids[c.landmark]), c.d2};
      }
    }
    for (std::size_t j = 0; j < scan.size(); ++j) {
      if (match[j] == kNone) continue;
      update(match[j], measurement(scan[j]), j);
      last_seen[match[j]] = step_now;
      ++counts.updated;
    }
    for (std::size_t j = 0; j < scan.size(); ++j) {
      if (match[j] != kNone) continue;
      report[j] = {static_cast<std::uint32_t>(j), AssociationOutcome::kDiscarded, 0, nearest[j]};
      if (nearest[j] > config.ekf.gate_new) {
        report[j].outcome = AssociationOutcome::kNew;
        report[j].landmark_id = landmarks();
        augment(measurement(scan[j]), static_cast<std::int64_t>(landmarks()), step_now);
        ++counts.created;
      } else {
        ++counts.dropped;
      }
    }
  }

  static Eigen::Vector2d measurement(const Observation& o) {
    return {o.range, wrap_angle(o.bearing)};
  }

  FilterConfig config;
  RangeBearingModel sensor;
  Eigen::Matrix2d r;
  int d;                                // pose dimension
  Index n;                              // state dimension, d + 2 N
  Eigen::VectorXd x;                    // mean; capacity entries, the first n in use
  Eigen::MatrixXd p;                    // covariance; lower triangle of the top-left n x n in use
  std::vector<std::int64_t> ids;        // per landmark: its id (known) or index (ML)
  std::vector<std::int64_t> last_seen;  // per landmark: the step of its last update
  std::unordered_map<std::int64_t, std::size_t> index_of_id;  // known association
  std::vector<TrajectoryPoint> trajectory;
  EkfAssociationCounts counts;
  std::uint64_t step = 0;  // events so far (controls and scans), as Filter counts them
  double time = 0.0;       // the clock, as Filter keeps it
  bool timed = false;
  std::vector<ObservationAssociation> report;  // the last scan's
  std::uint64_t controls = 0, scans = 0, observations = 0;
  double predict_seconds = 0.0, update_seconds = 0.0;
  Eigen::MatrixXd columns;  // scratch: the columns of P that H touches
  Eigen::Matrix<double, Eigen::Dynamic, 2> pht;
  Eigen::Matrix<double, Eigen::Dynamic, 2> gain;
};

EkfSlam::EkfSlam(const FilterConfig& config) : impl_(std::make_unique<Impl>(config)) {}
EkfSlam::~EkfSlam() = default;
EkfSlam::EkfSlam(EkfSlam&&) noexcept = default;
EkfSlam& EkfSlam::operator=(EkfSlam&&) noexcept = default;

const FilterConfig& EkfSlam::config() const noexcept { return impl_->config; }

void EkfSlam::predict(const Control& control, double dt) {
  if (!std::isfinite(dt) || dt < 0) {
    throw std::invalid_argument("EkfSlam::predict: dt must be finite and >= 0 (got " +
                                std::to_string(dt) + ")");
  }
  if (!std::isfinite(control.u0) || !std::isfinite(control.u1)) {
    throw std::invalid_argument("EkfSlam::predict: control values must be finite (got " +
                                std::to_string(control.u0) + ", " + std::to_string(control.u1) +
                                ")");
  }
  Impl& s = *impl_;
  const Clock::time_point t0 = Clock::now();
  if (s.config.record_trajectory && s.trajectory.size() == s.trajectory.capacity()) {
    s.trajectory.reserve(std::max<std::size_t>(64, 2 * s.trajectory.capacity()));
  }
  s.predict(control, dt);
  if (s.config.record_trajectory) s.trajectory.push_back({s.controls, s.x[0], s.x[1], s.x[2]});
  ++s.step;
  ++s.controls;
  s.predict_seconds += seconds_between(t0, Clock::now());
  s.time += dt;
}

void EkfSlam::predict(const Control& control, double dt, double time) {
  Impl& s = *impl_;
  internal::check_time(time, s.time, s.timed);
  predict(control, dt);
  s.time = time;
  s.timed = true;
}

void EkfSlam::observe(std::span<const Observation> scan, double time) {
  Impl& s = *impl_;
  internal::check_time(time, s.time, s.timed);
  observe(scan);
  s.time = time;
  s.timed = true;
}

void EkfSlam::observe(std::span<const Observation> scan) {
  Impl& s = *impl_;
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const Observation& o = scan[j];
    if (!std::isfinite(o.range) || !(o.range > 0)) {
      throw std::invalid_argument("EkfSlam::observe: observation " + std::to_string(j) +
                                  ": range must be finite and > 0 (got " + std::to_string(o.range) +
                                  ")");
    }
    if (!std::isfinite(o.bearing)) {
      throw std::invalid_argument("EkfSlam::observe: observation " + std::to_string(j) +
                                  ": bearing must be finite (got " + std::to_string(o.bearing) +
                                  ")");
    }
  }
  const Clock::time_point t0 = Clock::now();
  if (s.config.association == Association::kKnown) {
    s.observe_known(scan);
  } else {
    s.observe_ml(scan);
  }
  ++s.step;
  ++s.scans;
  s.observations += scan.size();
  s.update_seconds += seconds_between(t0, Clock::now());
}

const std::vector<ObservationAssociation>& EkfSlam::last_associations() const noexcept {
  return impl_->report;
}

Estimate EkfSlam::estimate(EstimateMap map_part) const {
  const Impl& s = *impl_;
  Estimate e;
  for (int k = 0; k < s.d; ++k) e.mean_pose[k] = e.best_pose[k] = s.x[k];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) e.pose_covariance[3 * r + c] = s.p(std::max(r, c), std::min(r, c));
  }
  e.best_particle = 0;
  e.effective_sample_size = 1.0;
  e.time = s.time;
  e.associations = s.report;
  e.map_size = s.landmarks();
  if (map_part == EstimateMap::kSizeOnly) return e;
  e.map.reserve(s.landmarks());
  for (std::size_t i = 0; i < s.landmarks(); ++i) {
    const Index a = s.offset_of(i);
    e.map.push_back({static_cast<memory::Slot>(i), static_cast<std::uint64_t>(s.ids[i]), s.x[a],
                     s.x[a + 1], s.p(a, a), s.p(a + 1, a), s.p(a + 1, a + 1), 0.0, s.last_seen[i]});
  }
  return e;
}

FilterStatistics EkfSlam::statistics() const {
  const Impl& s = *impl_;
  FilterStatistics st;
  st.controls = s.controls;
  st.scans = s.scans;
  st.observations = s.observations;
  st.predict_seconds = s.predict_seconds;
  st.update_seconds = s.update_seconds;
  st.observe_wall_seconds = s.update_seconds;
  st.live_bytes = static_cast<std::int64_t>((s.p.size() + s.x.size()) * sizeof(double));
  return st;
}

EkfAssociationCounts EkfSlam::association_counts() const noexcept { return impl_->counts; }

std::vector<TrajectoryPoint> EkfSlam::take_trajectory() {
  std::vector<TrajectoryPoint> out;
  out.swap(impl_->trajectory);
  return out;
}

int EkfSlam::pose_dim() const noexcept { return impl_->d; }
std::size_t EkfSlam::landmark_count() const noexcept { return impl_->landmarks(); }

Eigen::VectorXd EkfSlam::mean() const { return impl_->x.head(impl_->n); }

Eigen::MatrixXd EkfSlam::covariance() const {
  const Impl& s = *impl_;
  return s.p.topLeftCorner(s.n, s.n).selfadjointView<Eigen::Lower>();
}

void EkfSlam::reserve(std::size_t landmarks) {
  impl_->ensure_capacity(impl_->d + 2 * static_cast<Index>(landmarks));
}

}  // namespace fastslam::engine
