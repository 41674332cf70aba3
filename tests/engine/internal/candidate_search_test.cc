// The candidate search against brute force: every landmark of the map evaluated against every
// observation with the exact gate (FastSLAM 1.0: the EKF terms at the pose; 2.0: the proposal
// terms with the pose integrated out) and, under maximum likelihood, the ln p0 floor. The disc
// search, the extent bound and the Mahalanobis bound must keep exactly those candidates, with the
// same log-likelihoods, and 1.0's tags must point at their terms (1.0 under maximum likelihood
// once evaluate_all has evaluated the bounded candidates; each bound at or above the exact ln p).
// choose_maximum_likelihood against associate_maximum_likelihood on the brute-force list: the
// same assignment, the bit-identical weight, and the candidates the scan report reads. Half the
// runs place the discs from the scan's bearings (SearchInput::bearings), as the filter does.
#include "engine/internal/candidate_search.h"

#include <algorithm>
#include <cmath>
#include <limits>
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
  // Odd seeds: the discs' centres from the scan's bearings, as the filter's pass gives them.
  std::vector<Eigen::Vector2d> bearings;
  scan_bearings(w.scan, bearings);
  if (seed % 2 == 1) w.in.bearings = bearings;
  CandidateScratch scratch;
  find_candidates<N, kFs2, kMl>(w.in, prior, w.map, w.index, w.scan, scratch);
  if constexpr (!kFs2 && kMl) {
    EXPECT_TRUE(scratch.terms.empty());  // deferred: bounds only
    for (const AssociationCandidate& c : scratch.candidates) ASSERT_EQ(c.tag, kBoundOnly);
    evaluate_all<N>(w.in, prior, w.map, w.scan, scratch);
  }
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

// The bounds find_candidates gives hold: each at or above the exact ln p of its pair.
TEST(CandidateSearchTest, FastSlam1MaximumLikelihoodBoundsHold) {
  for (std::uint64_t seed : {1, 2, 3}) {
    World w(seed);
    PoseGaussian<3> prior;
    prior.mean = w.pose;
    CandidateScratch scratch;
    find_candidates<3, false, true>(w.in, prior, w.map, w.index, w.scan, scratch);
    const std::vector<AssociationCandidate> bounded = scratch.candidates;
    evaluate_all<3>(w.in, prior, w.map, w.scan, scratch);
    for (const AssociationCandidate& c : scratch.candidates) {
      const auto b = std::find_if(bounded.begin(), bounded.end(), [&](const auto& o) {
        return o.observation == c.observation && o.slot == c.slot;
      });
      ASSERT_NE(b, bounded.end());
      EXPECT_GE(b->log_likelihood, c.log_likelihood);
    }
  }
}

// The lazy choice over the search's bounds against the eager choice over the brute-force list.
TEST(CandidateSearchTest, FastSlam1MaximumLikelihoodChoiceIsTheEagerOne) {
  for (std::uint64_t seed : {1, 2, 3, 6, 7}) {
    for (const bool per_observation : {false, true}) {
      World w(seed);
      PoseGaussian<3> prior;
      prior.mean = w.pose;
      // The eager list: brute force, with the exact terms' distances.
      std::vector<AssociationCandidate> eager;
      for (const auto& [j, slot, ll] : brute_force<3, false, true>(w, prior)) {
        const auto t = evaluate_observation(w.sensor, to_gaussian(w.map.at(slot)), w.pose,
                                            w.scan[j].z, w.in.r);
        eager.push_back({j, slot, ll, 0, static_cast<float>(t.mahalanobis2)});
      }
      std::vector<double> scores(w.scan.size(), w.in.log_p0);
      for (std::size_t j = 0; j < scores.size(); ++j) {
        if (per_observation) scores[j] += 3.0 * static_cast<double>(j % 3);
      }
      std::vector<std::int64_t> want(w.scan.size());
      const double want_w = per_observation
                                ? associate_maximum_likelihood(eager, scores, want)
                                : associate_maximum_likelihood(eager, w.in.log_p0, want);
      std::vector<Eigen::Vector2d> bearings;
      scan_bearings(w.scan, bearings);
      if (seed % 2 == 1) w.in.bearings = bearings;
      CandidateScratch scratch;
      find_candidates<3, false, true>(w.in, prior, w.map, w.index, w.scan, scratch);
      std::vector<std::int64_t> got(w.scan.size());
      const double got_w =
          per_observation
              ? choose_maximum_likelihood<3>(w.in, prior, w.map, w.scan, scratch, scores, got)
              : choose_maximum_likelihood<3>(w.in, prior, w.map, w.scan, scratch, w.in.log_p0, got);
      EXPECT_EQ(got, want);
      EXPECT_EQ(got_w, want_w);
      // What the report reads: per observation the chosen pair's distance, or for a new one the
      // nearest candidate's; and the chosen pairs' terms.
      const auto report = [&](const std::vector<AssociationCandidate>& c) {
        std::vector<double> d2(w.scan.size(), std::numeric_limits<double>::infinity());
        for (const AssociationCandidate& a : c) {
          if (got[a.observation] == a.slot) d2[a.observation] = a.mahalanobis2;
          if (got[a.observation] == kNewLandmark) {
            d2[a.observation] = std::min<double>(d2[a.observation], a.mahalanobis2);
          }
        }
        return d2;
      };
      EXPECT_EQ(report(scratch.candidates), report(eager));
      std::size_t chosen_terms = 0;
      for (const AssociationCandidate& c : scratch.candidates) {
        ASSERT_LT(c.tag, scratch.terms.size());
        EXPECT_EQ(scratch.terms[c.tag].log_likelihood, c.log_likelihood);
        chosen_terms += got[c.observation] == c.slot ? 1 : 0;
      }
      EXPECT_EQ(chosen_terms,
                static_cast<std::size_t>(std::count_if(got.begin(), got.end(),
                                                       [](auto a) { return a != kNewLandmark; })));
      EXPECT_LT(scratch.terms.size(), eager.size());  // some were never evaluated
    }
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
