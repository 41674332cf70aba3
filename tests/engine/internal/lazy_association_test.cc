// The lazy maximum-likelihood choice (engine/internal/lazy_association.h) against the eager one
// (associate_maximum_likelihood on the exactly evaluated list) as the oracle, on random scans
// whose candidates carry bounds at, just above or far above their exact ln p, some rejected on
// evaluation, with ties in ln p and in the bounds, with one ln p0 and with per-observation
// scores: the same assignment and bit-identical weight; every candidate left is exact and one
// the eager list holds; an observation left new keeps all of its candidates and an associated
// one its chosen pair (what the scan report and the map update read); a candidate whose bound
// is below what its observation takes is never evaluated. The per-observation choice
// (independent_maximum_likelihood) against the same oracle on scans where no landmark is a
// candidate of two observations, and slots_disjoint against a brute-force count.
#include "engine/internal/lazy_association.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <span>
#include <tuple>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::engine::internal {
namespace {

using Candidates = std::vector<AssociationCandidate>;
using Key = std::tuple<std::uint32_t, memory::Slot, double, std::uint32_t, float>;

// A candidate's exact terms and whether evaluation keeps it.
struct Truth {
  double log_likelihood = 0.0;
  float mahalanobis2 = 0.0f;
  bool kept = true;
};

struct Scan {
  std::uint32_t observations = 0;
  std::vector<Truth> truth;  // by the pair's index, the tag its evaluation gives
  std::map<std::pair<std::uint32_t, memory::Slot>, std::uint32_t> index;  // pair -> index
  Candidates lazy;   // what the lazy choice starts from: some exact, most bounded
  Candidates eager;  // the oracle's input: every kept candidate, exact
};

Key key_of(const AssociationCandidate& c) {
  return {c.observation, c.slot, c.log_likelihood, c.tag, c.mahalanobis2};
}

// `kind` 0: small scans; 1: large ones (more than 32 observations assigned: the taken slots'
// short list gives way to the assignment); 2: a few observations with many candidates each,
// competing for the same landmarks; 3: as 0, but each observation's landmarks its own.
Scan random_scan(std::mt19937_64& rng, int kind) {
  const bool disjoint = kind == 3;
  if (disjoint) kind = 0;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Scan s;
  const std::uint32_t max_observations[] = {9, 80, 5};
  const std::uint32_t max_landmarks[] = {9, 80, 60};
  s.observations = 1 + static_cast<std::uint32_t>(rng() % max_observations[kind]);
  const std::uint32_t landmarks = 1 + static_cast<std::uint32_t>(rng() % max_landmarks[kind]);
  const double density = kind == 1 ? 0.1 : kind == 0 ? 0.45 : 0.8;
  const bool coarse = rng() % 3 == 0;  // ln p on a grid: many ties
  for (std::uint32_t j = 0; j < s.observations; ++j) {
    for (memory::Slot n = 0; n < landmarks; ++n) {
      if (u(rng) >= density) continue;
      Truth t;
      t.log_likelihood = -6.0 + 10.0 * u(rng);
      if (coarse) t.log_likelihood = std::floor(t.log_likelihood * 2.0) / 2.0;
      t.mahalanobis2 = static_cast<float>(20.0 * u(rng));
      t.kept = u(rng) < 0.85;
      const auto index = static_cast<std::uint32_t>(s.truth.size());
      s.truth.push_back(t);
      const memory::Slot slot = disjoint ? j * 100 + n : n;
      s.index[{j, slot}] = index;
      AssociationCandidate c{j, slot, 0.0, index, t.mahalanobis2};
      if (t.kept) {
        c.log_likelihood = t.log_likelihood;
        s.eager.push_back(c);
      }
      const double pick = u(rng);
      if (pick < 0.15 && t.kept) {
        s.lazy.push_back(c);  // exact from the start
        continue;
      }
      c.tag = kBoundOnly;
      c.mahalanobis2 = 0.0f;
      if (pick < 0.35) {
        c.log_likelihood = t.log_likelihood;  // a tight bound
      } else if (pick < 0.7) {
        c.log_likelihood = t.log_likelihood + (coarse ? 0.5 : 0.3 * u(rng));
      } else {
        c.log_likelihood = t.log_likelihood + 5.0 * u(rng);
      }
      s.lazy.push_back(c);
    }
  }
  std::shuffle(s.lazy.begin(), s.lazy.end(), rng);
  std::shuffle(s.eager.begin(), s.eager.end(), rng);
  return s;
}

// Runs both choices and checks the lazy one against the eager one. Returns the evaluations.
std::size_t expect_lazy_is_eager(const Scan& s, std::span<const double> scores, bool one_score,
                                 bool independent = false) {
  Candidates eager = s.eager;
  std::vector<std::int64_t> want(s.observations, 7);
  const double want_w = one_score ? associate_maximum_likelihood(eager, scores[0], want)
                                  : associate_maximum_likelihood(eager, scores, want);
  Candidates lazy = s.lazy;
  std::vector<std::int64_t> got(s.observations, 7);
  std::vector<int> evaluated(s.truth.size(), 0);
  const auto evaluate = [&](AssociationCandidate& c) {
    EXPECT_EQ(c.tag, kBoundOnly);
    const auto it = s.index.find({c.observation, c.slot});
    EXPECT_NE(it, s.index.end());
    const std::uint32_t index = it->second;
    ++evaluated[index];
    const Truth& t = s.truth[index];
    if (!t.kept) return false;
    c.log_likelihood = t.log_likelihood;
    c.tag = index;
    c.mahalanobis2 = t.mahalanobis2;
    return true;
  };
  const auto unassociated = [&](std::size_t j) { return one_score ? scores[0] : scores[j]; };
  LazyScratch scratch;
  const double got_w =
      independent
          ? independent_maximum_likelihood(lazy, unassociated, one_score, got, scratch, evaluate)
          : lazy_maximum_likelihood(lazy, unassociated, one_score, got, scratch, evaluate);
  EXPECT_EQ(got, want);
  EXPECT_EQ(got_w, want_w);  // bit for bit: the same sum in the same order
  for (int e : evaluated) EXPECT_LE(e, 1);
  std::vector<Key> eager_keys;
  for (const AssociationCandidate& c : s.eager) eager_keys.push_back(key_of(c));
  std::sort(eager_keys.begin(), eager_keys.end());
  std::vector<Key> left;
  for (const AssociationCandidate& c : lazy) {
    EXPECT_NE(c.tag, kBoundOnly);
    left.push_back(key_of(c));
    EXPECT_TRUE(std::binary_search(eager_keys.begin(), eager_keys.end(), key_of(c)));
  }
  std::sort(left.begin(), left.end());
  for (const AssociationCandidate& c : s.eager) {
    const std::int64_t chosen = got[c.observation];
    if (chosen == kNewLandmark || chosen == c.slot) {
      EXPECT_TRUE(std::binary_search(left.begin(), left.end(), key_of(c)))
          << "observation " << c.observation << " slot " << c.slot << " missing";
    }
  }
  std::size_t total = 0;
  for (int e : evaluated) total += static_cast<std::size_t>(e);
  return total;
}

TEST(LazyMaximumLikelihood, EqualsTheEagerChoiceWithOneScore) {
  std::mt19937_64 rng(21);
  std::size_t evaluations = 0, bounded = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const Scan s = random_scan(rng, trial % 10 == 0 ? 1 : trial % 10 == 1 ? 2 : 0);
    for (const AssociationCandidate& c : s.lazy) bounded += c.tag == kBoundOnly ? 1 : 0;
    const double log_p0 = -6.0 + static_cast<double>(trial % 4);
    const std::vector<double> scores{log_p0};
    evaluations += expect_lazy_is_eager(s, scores, true);
  }
  EXPECT_LT(evaluations, bounded);  // the point of it
}

TEST(LazyMaximumLikelihood, EqualsTheEagerChoiceWithPerObservationScores) {
  std::mt19937_64 rng(22);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 3000; ++trial) {
    const Scan s = random_scan(rng, trial % 10 == 0 ? 1 : trial % 10 == 1 ? 2 : 0);
    std::vector<double> scores(s.observations);
    for (double& v : scores) v = -6.0 + 6.0 * u(rng);
    expect_lazy_is_eager(s, scores, false);
  }
}

TEST(IndependentMaximumLikelihood, EqualsTheEagerChoice) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::size_t evaluations = 0, bounded = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const Scan s = random_scan(rng, 3);
    ASSERT_TRUE(slots_disjoint(s.lazy));
    for (const AssociationCandidate& c : s.lazy) bounded += c.tag == kBoundOnly ? 1 : 0;
    const bool one_score = trial % 2 == 0;
    std::vector<double> scores(one_score ? 1 : s.observations);
    for (double& v : scores) v = -6.0 + 6.0 * u(rng);
    evaluations += expect_lazy_is_eager(s, scores, one_score, true);
  }
  EXPECT_LT(evaluations, bounded);
}

TEST(IndependentMaximumLikelihood, SlotsDisjointIsBruteForce) {
  std::mt19937_64 rng(24);
  for (int trial = 0; trial < 2000; ++trial) {
    const Scan s = random_scan(rng, trial % 4 == 3 ? 3 : trial % 4 == 1 ? 2 : 0);
    bool shared = false;
    for (const AssociationCandidate& a : s.lazy) {
      for (const AssociationCandidate& b : s.lazy) {
        shared = shared || (a.slot == b.slot && a.observation != b.observation);
      }
    }
    EXPECT_EQ(slots_disjoint(s.lazy), !shared);
  }
}

TEST(LazyMaximumLikelihood, ABoundBelowTheWinnerIsNeverEvaluated) {
  // Observation 0: an exact candidate at -1 and a bound of -2 (slot 1); observation 1: a bound
  // of 3 whose exact value is 2 (slot 2). Only the latter is evaluated.
  Candidates c = {
      {0, 0, -1.0, 0, 1.0f}, {0, 1, -2.0, kBoundOnly, 0.0f}, {1, 2, 3.0, kBoundOnly, 0.0f}};
  std::vector<std::int64_t> assignment(2);
  int evaluations = 0;
  LazyScratch scratch;
  const double w = lazy_maximum_likelihood(
      c, [](std::size_t) { return -6.0; }, true, assignment, scratch,
      [&](AssociationCandidate& a) {
        ++evaluations;
        EXPECT_EQ(a.slot, 2u);
        a.log_likelihood = 2.0;
        a.tag = 1;
        a.mahalanobis2 = 2.0f;
        return true;
      });
  EXPECT_EQ(evaluations, 1);
  EXPECT_EQ(assignment, (std::vector<std::int64_t>{0, 2}));
  EXPECT_EQ(w, 2.0 + -1.0);
  EXPECT_EQ(c.size(), 2u);
}

TEST(LazyMaximumLikelihood, EmptyScan) {
  Candidates c;
  std::vector<std::int64_t> assignment(3, 5);
  LazyScratch scratch;
  const double w = lazy_maximum_likelihood(
      c, [](std::size_t) { return -6.0; }, true, assignment, scratch,
      [](AssociationCandidate&) { return true; });
  EXPECT_EQ(assignment, (std::vector<std::int64_t>(3, kNewLandmark)));
  EXPECT_EQ(w, -18.0);
}

}  // namespace
}  // namespace fastslam::engine::internal
