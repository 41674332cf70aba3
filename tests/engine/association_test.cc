// Data association of one scan (engine/association.h) against oracles:
//  - maximum likelihood: on random scans (up to 90 observations), the result is valid (each
//  landmark at most once, every
//    choice a gated candidate at or above ln p0) and is exactly the greedy-stable assignment: no
//    free pair (j, n) above ln p0 beats both j's choice and whoever took n; without conflicts it
//    equals the per-observation argmax (brute force); the order candidates come in is irrelevant,
//    and so are the candidates below ln p0 (the filter drops them before the choice);
//  - sampling: choice frequencies over many keyed streams match p_jn / (p0 + sum p) within 5
//    binomial standard deviations; mutual exclusion holds; the weight is the log normaliser;
//  - the detection model (clutter, P_D): the score of "no landmark" against its closed form; ML
//    with per-observation scores against the brute-force argmax; DAS's frequencies against the
//    model's posterior enumerated over landmark / new / false alarm.
#include "engine/association.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "parallel/random_stream.h"

namespace fastslam::engine {
namespace {

using Candidates = std::vector<AssociationCandidate>;

// A random scan: Z observations, landmarks 0..L-1, each pair present with probability `density`.
Candidates random_scan(std::mt19937_64& rng, std::uint32_t z, std::uint32_t l, double density) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Candidates c;
  for (std::uint32_t j = 0; j < z; ++j) {
    for (memory::Slot n = 0; n < l; ++n) {
      if (u(rng) < density) c.push_back({j, n, -12.0 + 12.0 * u(rng)});
    }
  }
  return c;
}

double likelihood_of(const Candidates& c, std::uint32_t j, std::int64_t slot) {
  for (const AssociationCandidate& a : c) {
    if (a.observation == j && a.slot == slot) return a.log_likelihood;
  }
  ADD_FAILURE() << "observation " << j << " took slot " << slot << ", not a candidate";
  return 0.0;
}

TEST(MaximumLikelihood, IsValidAndGreedyStableOnRandomScans) {
  std::mt19937_64 rng(11);
  const double log_p0 = -6.0;
  for (int trial = 0; trial < 2000; ++trial) {
    // Some large scans: more than 32 observations assigned (the choice's short list of taken
    // slots then gives way to the assignment).
    const bool large = trial % 10 == 0;
    const std::uint32_t z = 1 + static_cast<std::uint32_t>(rng() % (large ? 90 : 8));
    const std::uint32_t l = 1 + static_cast<std::uint32_t>(rng() % (large ? 90 : 8));
    const Candidates original = random_scan(rng, z, l, large ? 0.08 : 0.4);
    Candidates work = original;
    std::vector<std::int64_t> assignment(z, 123);
    const double log_w = associate_maximum_likelihood(work, log_p0, assignment);
    double expected_w = 0.0;
    std::map<std::int64_t, std::uint32_t> owner;
    for (std::uint32_t j = 0; j < z; ++j) {
      if (assignment[j] == kNewLandmark) {
        expected_w += log_p0;
        continue;
      }
      const double ll = likelihood_of(original, j, assignment[j]);
      EXPECT_GE(ll, log_p0);
      expected_w += ll;
      EXPECT_TRUE(owner.emplace(assignment[j], j).second) << "slot taken twice";
    }
    EXPECT_NEAR(log_w, expected_w, 1e-9);
    // Stability: a pair above p0 not chosen loses to j's own choice or to n's owner.
    for (const AssociationCandidate& c : original) {
      if (c.log_likelihood < log_p0 || assignment[c.observation] == c.slot) continue;
      const bool j_better =
          assignment[c.observation] != kNewLandmark &&
          likelihood_of(original, c.observation, assignment[c.observation]) >= c.log_likelihood;
      const auto o = owner.find(c.slot);
      const bool n_better =
          o != owner.end() && likelihood_of(original, o->second, c.slot) >= c.log_likelihood;
      EXPECT_TRUE(j_better || n_better) << "trial " << trial << ": pair (" << c.observation << ", "
                                        << c.slot << ") blocks the assignment";
    }
    // Input order does not matter.
    Candidates shuffled = original;
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    std::vector<std::int64_t> again(z);
    EXPECT_EQ(associate_maximum_likelihood(shuffled, log_p0, again), log_w);
    EXPECT_EQ(again, assignment);
  }
}

TEST(MaximumLikelihood, WithoutConflictsEqualsPerObservationArgmax) {
  std::mt19937_64 rng(12);
  for (int trial = 0; trial < 500; ++trial) {
    // Each observation sees its own disjoint landmarks: no two compete.
    Candidates c;
    const std::uint32_t z = 1 + static_cast<std::uint32_t>(rng() % 6);
    for (std::uint32_t j = 0; j < z; ++j) {
      for (memory::Slot n = 0; n < rng() % 4; ++n) {
        c.push_back({j, j * 10 + n, -14.0 + 14.0 * std::ldexp(double(rng() >> 11), -53)});
      }
    }
    std::vector<std::int64_t> assignment(z);
    Candidates work = c;
    associate_maximum_likelihood(work, -7.0, assignment);
    for (std::uint32_t j = 0; j < z; ++j) {
      std::int64_t best = kNewLandmark;
      double best_ll = -7.0;
      for (const AssociationCandidate& a : c) {
        if (a.observation == j && a.log_likelihood >= best_ll) {
          if (a.log_likelihood > best_ll || best == kNewLandmark || a.slot < best) best = a.slot;
          best_ll = a.log_likelihood;
        }
      }
      EXPECT_EQ(assignment[j], best) << "trial " << trial << " observation " << j;
    }
  }
}

// The filter keeps no candidate below ln p0 under maximum likelihood (engine/filter.cc): the
// choice and the weight must not depend on them, ties at ln p0 included.
TEST(MaximumLikelihood, CandidatesBelowNewLandmarkNeverMatter) {
  std::mt19937_64 rng(5);
  const double log_p0 = -6.0;
  int differ = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const std::uint32_t z = 1 + static_cast<std::uint32_t>(rng() % 8);
    const std::uint32_t l = 1 + static_cast<std::uint32_t>(rng() % 8);
    Candidates all = random_scan(rng, z, l, 0.5);
    for (AssociationCandidate& c : all) {
      if (rng() % 8 == 0) c.log_likelihood = log_p0;  // exactly at ln p0: kept
    }
    Candidates kept;
    for (const AssociationCandidate& c : all) {
      if (!(c.log_likelihood < log_p0)) kept.push_back(c);
    }
    differ += kept.size() != all.size() ? 1 : 0;
    std::vector<std::int64_t> with_all(z);
    std::vector<std::int64_t> with_kept(z);
    const double w_all = associate_maximum_likelihood(all, log_p0, with_all);
    const double w_kept = associate_maximum_likelihood(kept, log_p0, with_kept);
    ASSERT_EQ(with_all, with_kept) << "trial " << trial;
    ASSERT_EQ(w_all, w_kept) << "trial " << trial;
  }
  EXPECT_GT(differ, 1000);  // most scans had candidates below ln p0 to drop
}

TEST(MaximumLikelihood, StrongerObservationWinsAContestedLandmark) {
  // Both observations prefer slot 5; observation 1 fits it better, so observation 0 takes its
  // second choice (slot 2), and an observation with nothing above p0 is new.
  Candidates c = {{0, 5, -1.0}, {0, 2, -3.0}, {1, 5, -0.5}, {1, 2, -9.0}, {2, 5, -8.0}};
  std::vector<std::int64_t> assignment(3);
  const double log_w = associate_maximum_likelihood(c, -6.0, assignment);
  EXPECT_EQ(assignment, (std::vector<std::int64_t>{2, 5, kNewLandmark}));
  EXPECT_DOUBLE_EQ(log_w, -3.0 - 0.5 - 6.0);
}

TEST(Sampling, FrequenciesMatchTheLikelihoods) {
  // One observation, three candidates and "new": p proportional to e^ll and p0.
  const Candidates c = {{0, 7, std::log(0.5)}, {0, 3, std::log(0.2)}, {0, 9, std::log(0.1)}};
  const double log_p0 = std::log(0.2);
  const int draws = 40000;
  std::map<std::int64_t, int> count;
  std::vector<memory::Slot> taken;
  for (int k = 0; k < draws; ++k) {
    parallel::RandomStream stream(
        {5, 17, static_cast<std::uint32_t>(k), parallel::Purpose::kAssociation});
    Candidates work = c;
    std::vector<std::int64_t> assignment(1);
    const double log_w = associate_sampling(work, log_p0, stream, assignment, taken);
    ASSERT_NEAR(log_w, std::log(1.0), 1e-12);  // the normaliser 0.5 + 0.2 + 0.1 + 0.2
    ++count[assignment[0]];
  }
  for (const auto& [slot, p] :
       std::map<std::int64_t, double>{{7, 0.5}, {3, 0.2}, {9, 0.1}, {kNewLandmark, 0.2}}) {
    const double sd = std::sqrt(draws * p * (1 - p));
    EXPECT_NEAR(count[slot], draws * p, 5 * sd) << "slot " << slot;
  }
}

TEST(Sampling, NeverGivesOneLandmarkToTwoObservations) {
  std::mt19937_64 rng(13);
  std::vector<memory::Slot> taken;
  for (int trial = 0; trial < 3000; ++trial) {
    const std::uint32_t z = 1 + static_cast<std::uint32_t>(rng() % 6);
    Candidates c = random_scan(rng, z, 3, 0.8);
    for (AssociationCandidate& a : c) a.log_likelihood += 10.0;  // "new" rarely wins
    const Candidates original = c;
    parallel::RandomStream stream(
        {6, 1, static_cast<std::uint32_t>(trial), parallel::Purpose::kAssociation});
    std::vector<std::int64_t> assignment(z);
    associate_sampling(c, -6.0, stream, assignment, taken);
    std::map<std::int64_t, int> uses;
    for (std::uint32_t j = 0; j < z; ++j) {
      if (assignment[j] == kNewLandmark) continue;
      likelihood_of(original, j, assignment[j]);  // a candidate of j
      EXPECT_EQ(++uses[assignment[j]], 1) << "trial " << trial;
    }
  }
}

TEST(Sampling, IsDeterministicPerStreamAndIgnoresInputOrder) {
  std::mt19937_64 rng(14);
  std::vector<memory::Slot> taken;
  for (int trial = 0; trial < 200; ++trial) {
    Candidates c = random_scan(rng, 5, 6, 0.5);
    Candidates shuffled = c;
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    std::vector<std::int64_t> a(5), b(5);
    parallel::RandomStream s1({1, 2, 3, parallel::Purpose::kAssociation});
    parallel::RandomStream s2({1, 2, 3, parallel::Purpose::kAssociation});
    const double wa = associate_sampling(c, -8.0, s1, a, taken);
    const double wb = associate_sampling(shuffled, -8.0, s2, b, taken);
    EXPECT_EQ(a, b);
    EXPECT_EQ(wa, wb);
  }
}

// The detection model's score of "no landmark": ln((p0 + kappa r) / P_D), by the closed form,
// also where p0 is far below a double's range; the defaults give ln p0 itself, bit for bit.
TEST(DetectionModel, UnassociatedScoreIsTheClosedForm) {
  EXPECT_EQ(log_unassociated(-6.0, DetectionConfig{}, 12.0), -6.0);
  const DetectionConfig d{0.8, 2.0 / 1413.0};
  for (const double log_p0 : {-9.0, -6.0, -3.0, 0.0}) {
    for (const double r : {0.5, 5.0, 15.0, 30.0}) {
      const double expected = std::log((std::exp(log_p0) + d.clutter_density * r) / 0.8);
      EXPECT_NEAR(log_unassociated(log_p0, d, r), expected, 1e-12) << log_p0 << " " << r;
    }
  }
  EXPECT_NEAR(log_unassociated(-900.0, d, 10.0), std::log(d.clutter_density * 10.0 / 0.8), 1e-12);
  EXPECT_NEAR(log_unassociated(-6.0, DetectionConfig{0.5, 0.0}, 10.0), -6.0 - std::log(0.5), 1e-12);
}

// Per-observation scores against brute force: on scans where no two observations share a
// candidate, ML is the per-observation argmax against that observation's own score, and the
// weight the sum of the choices' scores; with one score for all, the span overload agrees with
// the scalar one.
TEST(DetectionModel, MaximumLikelihoodWithPerObservationScoresMatchesBruteForce) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const std::uint32_t z = 1 + static_cast<std::uint32_t>(rng() % 8);
    Candidates c;
    std::vector<double> scores(z);
    memory::Slot next = 0;
    for (std::uint32_t j = 0; j < z; ++j) {
      scores[j] = -9.0 + 8.0 * u(rng);
      const int k = static_cast<int>(rng() % 4);
      for (int n = 0; n < k; ++n) c.push_back({j, next++, -12.0 + 12.0 * u(rng)});
    }
    std::vector<std::int64_t> expected(z, kNewLandmark);
    double expected_w = 0.0;
    for (std::uint32_t j = 0; j < z; ++j) {
      double best = scores[j];
      for (const AssociationCandidate& a : c) {
        if (a.observation == j && a.log_likelihood >= best) {
          best = a.log_likelihood;
          expected[j] = a.slot;
        }
      }
      expected_w += best;
    }
    Candidates work = c;
    std::vector<std::int64_t> assignment(z, 123);
    const double log_w = associate_maximum_likelihood(work, scores, assignment);
    EXPECT_EQ(assignment, expected) << "trial " << trial;
    EXPECT_NEAR(log_w, expected_w, 1e-9) << "trial " << trial;

    const std::vector<double> same(z, -6.0);
    Candidates a = c, b = c;
    std::vector<std::int64_t> with_span(z), with_scalar(z);
    const double wa = associate_maximum_likelihood(a, same, with_span);
    const double wb = associate_maximum_likelihood(b, -6.0, with_scalar);
    EXPECT_EQ(with_span, with_scalar);
    EXPECT_NEAR(wa, wb, 1e-9);
  }
}

// The draw against the model's posterior by enumeration: an observation is landmark n
// (detected, P_D p_n), a new landmark (p0) or a false alarm (kappa r), so P(n) = P_D p_n / S and
// P(no landmark) = (p0 + kappa r) / S, S = P_D sum p + p0 + kappa r. DAS with the scores of
// log_unassociated draws with these frequencies, per observation with its own range, and its
// weight is the sum of ln(S / P_D).
TEST(DetectionModel, SamplingFrequenciesMatchTheModelPosterior) {
  const DetectionConfig d{0.8, 0.002};
  const double log_p0 = std::log(0.01);
  const double ranges[2] = {4.0, 25.0};
  const Candidates c = {{0, 7, std::log(0.05)}, {0, 3, std::log(0.02)}, {1, 9, std::log(0.03)}};
  const std::vector<double> scores = {log_unassociated(log_p0, d, ranges[0]),
                                      log_unassociated(log_p0, d, ranges[1])};
  // The model's posterior, by enumeration over each observation's hypotheses.
  std::map<std::int64_t, double> posterior[2];
  double expected_w = 0.0;
  for (std::uint32_t j = 0; j < 2; ++j) {
    double total = std::exp(log_p0) + d.clutter_density * ranges[j];
    posterior[j][kNewLandmark] = total;
    for (const AssociationCandidate& a : c) {
      if (a.observation != j) continue;
      posterior[j][a.slot] = d.probability * std::exp(a.log_likelihood);
      total += posterior[j][a.slot];
    }
    for (auto& [slot, p] : posterior[j]) p /= total;
    expected_w += std::log(total / d.probability);
  }
  const int draws = 40000;
  std::map<std::int64_t, int> count[2];
  std::vector<memory::Slot> taken;
  for (int k = 0; k < draws; ++k) {
    parallel::RandomStream stream(
        {8, 3, static_cast<std::uint32_t>(k), parallel::Purpose::kAssociation});
    Candidates work = c;
    std::vector<std::int64_t> assignment(2);
    const double log_w = associate_sampling(work, scores, stream, assignment, taken);
    ASSERT_NEAR(log_w, expected_w, 1e-12);
    ++count[0][assignment[0]];
    ++count[1][assignment[1]];
  }
  for (int j = 0; j < 2; ++j) {
    for (const auto& [slot, p] : posterior[j]) {
      const double sd = std::sqrt(draws * p * (1 - p));
      EXPECT_NEAR(count[j][slot], draws * p, 5 * sd) << "observation " << j << " slot " << slot;
    }
  }
}

}  // namespace
}  // namespace fastslam::engine
