// The candidate search against brute force: every landmark of the map evaluated against every
// observation with the exact gate (FastSLAM 1.0: the EKF terms at the pose; 2.0: the proposal
// terms with the pose integrated out) and, under maximum likelihood, the ln p0 floor. The disc
// search, the extent bound and the Mahalanobis bound must keep exactly those candidates, with the
// same log-likelihoods, and 1.0's tags must point at their terms.
#include "engine/internal/candidate_search.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "engine/internal/map_update.h"
#include "memory/node_heap.h"

namespace fastslam::engine::internal {
namespace {

using Key = std::tuple<std::uint32_t, memory::Slot, double>;

struct World {
  memory::PoolHeap heap;
  memory::LandmarkTree map{heap};
  memory::SpatialIndex index{heap};
  RangeBearingModel sensor{SensorOffset{0.5, -0.2, 0.02}};
  SearchInput in;
  std::vector<PlannedObservation> scan;
  Pose pose{1.0, -2.0, 0.7};

  explicit World(std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    in.sensor = &sensor;
    in.r << 0.04, 0, 0, 0.0009;
    in.gate = 23.025850929940457;
    in.search_scale = 1.5;
    in.log_p0 = -9.0;
    // Clusters of landmarks, so that observations see several candidates each.
    for (int k = 0; k < 400; ++k) {
      const double cx = 25 * u(rng), cy = 25 * u(rng);
      const double s = 0.02 + 0.3 * (1 + u(rng));
      memory::Landmark l{cx,
                         cy,
                         s,
                         0.3 * s * u(rng),
                         s * (0.5 + 0.5 * (1 + u(rng))),
                         1.0,
                         static_cast<std::uint64_t>(k),
                         0};
      const memory::Slot slot = map.insert(l);
      index.insert(slot, l.x, l.y, largest_variance(l));
      in.variance_bound = std::max(in.variance_bound, static_cast<double>(largest_variance(l)));
    }
    for (const auto [slot, l] : map) {
      if (scan.size() >= 25) break;
      if (slot % 16 != 0) continue;
      // An observation of this landmark, perturbed, and one of empty space next to it.
      const Eigen::Vector2d z = sensor.predict({l.x, l.y}, pose);
      for (double shift : {0.0, 1.5}) {
        PlannedObservation o;
        o.z = {z[0] * (1 + 0.01 * u(rng)) + shift, wrap_angle(z[1] + 0.02 * u(rng))};
        scan.push_back(o);
      }
    }
    for (const PlannedObservation& o : scan) {
      in.variance_bound = std::max(in.variance_bound, measurement_variance(in.r, o.z[0]));
    }
  }
};

template <int N, bool kFs2, bool kMl>
std::vector<Key> brute_force(const World& w, const PoseGaussian<N>& prior) {
  std::vector<Key> keys;
  const Pose pose = prior.mean.template head<3>();
  const Eigen::Vector2d from = w.sensor.sensor_position(pose);
  for (std::size_t j = 0; j < w.scan.size(); ++j) {
    for (const auto [slot, l] : w.map) {
      if ((Eigen::Vector2d(l.x, l.y) - from).squaredNorm() < 1e-18) continue;
      const LandmarkGaussian lm = to_gaussian(l);
      double m2, ll;
      if constexpr (kFs2) {
        const auto t = evaluate_proposal<N>(w.sensor, lm, prior, w.scan[j].z, w.in.r);
        m2 = t.mahalanobis2;
        ll = t.log_likelihood;
      } else {
        const auto t = evaluate_observation(w.sensor, lm, pose, w.scan[j].z, w.in.r);
        m2 = t.mahalanobis2;
        ll = t.log_likelihood;
      }
      if (m2 <= w.in.gate && !(kMl && ll < w.in.log_p0)) {
        keys.emplace_back(static_cast<std::uint32_t>(j), slot, ll);
      }
    }
  }
  std::sort(keys.begin(), keys.end());
  return keys;
}

template <int N, bool kFs2, bool kMl>
void expect_search_is_brute_force(std::uint64_t seed) {
  World w(seed);
  PoseGaussian<N> prior;
  prior.mean.template head<3>() = w.pose;
  if constexpr (kFs2) {
    prior.cov.setIdentity();
    prior.cov *= 0.01;
    prior.cov(2, 2) = 0.0004;
  }
  CandidateScratch scratch;
  find_candidates<N, kFs2, kMl>(w.in, prior, w.map, w.index, w.scan, scratch);
  std::vector<Key> got;
  for (const AssociationCandidate& c : scratch.candidates) {
    got.emplace_back(c.observation, c.slot, c.log_likelihood);
    if constexpr (!kFs2) {
      ASSERT_LT(c.tag, scratch.terms.size());
      EXPECT_EQ(scratch.terms[c.tag].log_likelihood, c.log_likelihood);
    }
  }
  std::sort(got.begin(), got.end());
  const std::vector<Key> want = brute_force<N, kFs2, kMl>(w, prior);
  EXPECT_EQ(got, want);
  EXPECT_GT(want.size(), w.scan.size() / 4);  // the test exercises real candidates
}

TEST(CandidateSearchTest, FastSlam1IsBruteForce) {
  for (std::uint64_t seed : {1, 2, 3}) {
    expect_search_is_brute_force<3, false, true>(seed);
    expect_search_is_brute_force<3, false, false>(seed);
  }
}

TEST(CandidateSearchTest, FastSlam2IsBruteForce) {
  for (std::uint64_t seed : {4, 5}) {
    expect_search_is_brute_force<3, true, true>(seed);
    expect_search_is_brute_force<3, true, false>(seed);
    expect_search_is_brute_force<5, true, true>(seed);
  }
}

TEST(CandidateSearchTest, EmptyScanAndEmptyMapFindNothing) {
  World w(9);
  CandidateScratch scratch;
  PoseGaussian<3> prior;
  find_candidates<3, false, true>(w.in, prior, w.map, w.index, {}, scratch);
  EXPECT_TRUE(scratch.candidates.empty());
  memory::LandmarkTree empty_map(w.heap);
  memory::SpatialIndex empty_index(w.heap);
  find_candidates<3, true, false>(w.in, prior, empty_map, empty_index, w.scan, scratch);
  EXPECT_TRUE(scratch.candidates.empty());
}

}  // namespace
}  // namespace fastslam::engine::internal
