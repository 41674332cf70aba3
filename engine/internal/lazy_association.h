// Maximum-likelihood association (association.h, associate_maximum_likelihood) over candidates
// of which some carry only an upper bound on their log-likelihood, evaluated exactly only when
// the choice or the scan report needs them. Most gated candidates cannot win: the greedy choice
// takes pairs in decreasing ln p, so a candidate whose bound lies below what its observation
// takes is never looked at.
//
// The result is that of associate_maximum_likelihood on the exactly evaluated candidate list:
// the same assignment and the same log weight (the same sum in the same order), and the
// candidates left in the vector are, exact, the chosen pair of each associated observation and
// every candidate of the observations that end "new" (their nearest distance goes into the scan
// report). How: the greedy order takes, at each step, the largest (ln p, then observation, then
// slot) pair whose observation and landmark are both free, so it is enough to know each free
// observation's best pair over the free landmarks. Per observation that is found lazily: the
// largest key (exact ln p or bound; at equal keys a bound first, then the smaller slot) among
// its candidates on free landmarks; a bound on top is evaluated (its exact ln p is at most the
// bound) and the search repeats; an exact value on top is the best, since every bound below it,
// hence every exact ln p behind it, is smaller. Each observation's top candidate is needed in
// any case; its exact value cuts the observation's candidates into a front, searched first,
// and the rest, searched only when nothing in the front is left above the cut.
//
// `evaluate(c)`: given a candidate with tag == kBoundOnly, fills its exact log_likelihood, tag
// and mahalanobis2 and returns true, or returns false when the exact candidate is not kept.
// REQUIRES: a bounded candidate's log_likelihood >= its exact one; exact candidates' tags below
// kDropped; observations below both assignment.size() and 2^31. Thread safety: a pure
// function of its arguments and `evaluate`. Costs: O(C + Z log Z) plus, per evaluation and per
// observation whose best landmark another took, a search of that observation's front (its
// candidates with bounds above the cut); Z^2 at worst for the taken-landmark checks; no
// allocation once the scratch has grown.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "engine/association.h"
#include "engine/internal/taken_slots.h"

namespace fastslam::engine::internal {

// The tag of a candidate whose log_likelihood is an upper bound, not yet evaluated.
inline constexpr std::uint32_t kBoundOnly = std::numeric_limits<std::uint32_t>::max();
// The tag of a candidate evaluate() rejected.
inline constexpr std::uint32_t kDropped = kBoundOnly - 1;

// lazy_maximum_likelihood's buffers.
struct LazyScratch {
  std::vector<AssociationCandidate> grouped;  // the candidates, by observation
  std::vector<std::uint32_t> start;           // observation j's: [start[j], start[j + 1])
  std::vector<std::uint32_t> front;           // [start[j], front[j]): keys >= threshold[j]
  std::vector<std::uint32_t> back;
  std::vector<double> threshold;
  std::vector<std::int64_t> best;    // index into grouped of j's best free pair, or below 0
  std::vector<std::uint32_t> order;  // the observations in the greedy order
};

namespace lazy_association_detail {

// A candidate whose landmark another observation took (in the observation field).
inline constexpr std::uint32_t kBlocked = 0x80000000u;

// Whether a comes before b within one observation: higher key; at equal keys a bound first
// (its exact value may tie), then the smaller slot (the eager order).
inline bool before(const AssociationCandidate& a, const AssociationCandidate& b) {
  if (a.log_likelihood != b.log_likelihood) return a.log_likelihood > b.log_likelihood;
  const bool a_bound = a.tag == kBoundOnly;
  const bool b_bound = b.tag == kBoundOnly;
  if (a_bound != b_bound) return a_bound;
  return a.slot < b.slot;
}

// The weight's tail, as associate_maximum_likelihood adds it: the "no landmark" scores of the
// observations left new, after the `taken` pairs' values in `log_weight`.
template <class Unassociated>
double plus_unassociated(double log_weight, const Unassociated& log_unassociated, bool same_for_all,
                         std::span<const std::int64_t> assignment, std::size_t taken) {
  const std::size_t z = assignment.size();
  if (same_for_all) return log_weight + static_cast<double>(z - taken) * log_unassociated(0);
  for (std::size_t j = 0; j < z; ++j) {
    if (assignment[j] == kNewLandmark) log_weight += log_unassociated(j);
  }
  return log_weight;
}

}  // namespace lazy_association_detail

// `log_unassociated(j)`: observation j's score of "no landmark"; `same_for_all`: it is one
// value (the scalar overload of associate_maximum_likelihood). Reorders and shrinks
// `candidates` (see above); writes assignment[j] for every j. Returns the log weight factor.
template <class Unassociated, class Evaluate>
double lazy_maximum_likelihood(std::vector<AssociationCandidate>& candidates,
                               const Unassociated& log_unassociated, bool same_for_all,
                               std::span<std::int64_t> assignment, LazyScratch& scratch,
                               Evaluate&& evaluate) {
  using lazy_association_detail::before;
  using lazy_association_detail::kBlocked;
  using lazy_association_detail::plus_unassociated;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const std::size_t z = assignment.size();
  std::fill(assignment.begin(), assignment.end(), kNewLandmark);
  // Per observation, the count and the top candidate (largest key). Every observation's best
  // pair is looked for before any is taken, so its top is evaluated whatever happens; its exact
  // value cuts the observation's candidates into a front (keys at or above it) and a back,
  // which is looked at only if nothing in the front is left above the cut.
  std::vector<std::uint32_t>& start = scratch.start;
  std::vector<std::int64_t>& best = scratch.best;  // first the top's index into `candidates`
  start.assign(z + 1, 0);
  best.assign(z, -1);
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    const AssociationCandidate& c = candidates[k];
    ++start[c.observation + 1];
    std::int64_t& top = best[c.observation];
    if (top < 0 || before(c, candidates[static_cast<std::size_t>(top)])) {
      top = static_cast<std::int64_t>(k);
    }
  }
  for (std::size_t j = 0; j < z; ++j) start[j + 1] += start[j];
  std::vector<double>& threshold = scratch.threshold;
  threshold.assign(z, -kInf);
  for (std::size_t j = 0; j < z; ++j) {
    if (best[j] < 0) continue;
    AssociationCandidate& c = candidates[static_cast<std::size_t>(best[j])];
    if (c.tag != kBoundOnly || evaluate(c)) {
      threshold[j] = c.log_likelihood;
    } else {
      c.tag = kDropped;
    }
  }
  // Grouped by observation, the front filled from the start, the back from the end.
  std::vector<std::uint32_t>& front = scratch.front;
  std::vector<std::uint32_t>& back = scratch.back;
  front.assign(start.begin(), start.end() - 1);
  back.assign(start.begin() + 1, start.end());
  std::vector<AssociationCandidate>& grouped = scratch.grouped;
  grouped.resize(candidates.size());
  for (const AssociationCandidate& c : candidates) {
    const std::uint32_t j = c.observation;
    if (c.log_likelihood >= threshold[j]) {
      grouped[front[j]++] = c;
    } else {
      grouped[--back[j]] = c;
    }
  }
  std::fill(best.begin(), best.end(), -1);
  double log_weight = 0.0;
  TakenSlots taken(assignment);
  // Observation j's best pair on a free landmark (exact), as an index into `grouped`, or -1.
  const auto resolve = [&](std::size_t j) -> std::int64_t {
    const std::uint32_t last = start[j + 1];
    for (;;) {
      std::int64_t top = -1;
      for (std::uint32_t k = start[j]; k < front[j]; ++k) {
        const AssociationCandidate& c = grouped[k];
        if ((c.observation & kBlocked) != 0 || c.tag == kDropped) continue;
        if (top < 0 || before(c, grouped[static_cast<std::size_t>(top)])) top = k;
      }
      if (front[j] != last &&
          (top < 0 || grouped[static_cast<std::size_t>(top)].log_likelihood < threshold[j])) {
        front[j] = last;  // nothing in the front above the threshold: all of j's candidates
        threshold[j] = -kInf;
        continue;
      }
      if (top < 0) return -1;
      AssociationCandidate& c = grouped[static_cast<std::size_t>(top)];
      if (taken.contains(c.slot)) {
        c.observation |= kBlocked;
        continue;
      }
      if (c.tag != kBoundOnly) return top;
      if (!evaluate(c)) c.tag = kDropped;
    }
  };
  // The greedy order: the observations by their best pair (larger first; ties: the smaller
  // observation). The first one's pair is the next the eager choice takes, unless another
  // observation took its landmark since: then it looks again, and goes back in its place (its
  // new best is no larger, and a stale best elsewhere in the order is no smaller than the
  // truth, so the first one, once valid, is the largest of all). A pair below its
  // observation's "no landmark" score leaves the observation new.
  std::vector<std::uint32_t>& order = scratch.order;
  order.clear();
  for (std::size_t j = 0; j < z; ++j) {
    best[j] = resolve(j);
    if (best[j] >= 0) order.push_back(static_cast<std::uint32_t>(j));
  }
  const auto precedes = [&](std::uint32_t a, std::uint32_t b) {
    const double la = grouped[static_cast<std::size_t>(best[a])].log_likelihood;
    const double lb = grouped[static_cast<std::size_t>(best[b])].log_likelihood;
    return la > lb || (la == lb && a < b);
  };
  std::sort(order.begin(), order.end(), precedes);
  for (std::size_t p = 0; p < order.size();) {
    const std::uint32_t j = order[p];
    AssociationCandidate& cand = grouped[static_cast<std::size_t>(best[j])];
    if (taken.size() > 0 && taken.contains(cand.slot)) {
      cand.observation |= kBlocked;
      best[j] = resolve(j);
      if (best[j] < 0) {
        ++p;
        continue;
      }
      std::size_t q = p;
      while (q + 1 < order.size() && precedes(order[q + 1], j)) {
        order[q] = order[q + 1];
        ++q;
      }
      order[q] = j;
      continue;
    }
    ++p;
    if (cand.log_likelihood < log_unassociated(j)) continue;  // j stays new
    assignment[j] = cand.slot;
    log_weight += cand.log_likelihood;
    taken.take(cand.slot);
  }
  // What the scan report and the map update read: the chosen pairs, and every candidate of the
  // observations left new, exact.
  candidates.clear();
  for (std::size_t j = 0; j < z; ++j) {
    if (assignment[j] != kNewLandmark) {
      AssociationCandidate c = grouped[static_cast<std::size_t>(best[j])];
      c.observation &= ~kBlocked;
      candidates.push_back(c);
      continue;
    }
    for (std::uint32_t k = start[j]; k < start[j + 1]; ++k) {
      AssociationCandidate& c = grouped[k];
      c.observation &= ~kBlocked;
      if (c.tag == kBoundOnly && !evaluate(c)) c.tag = kDropped;
      if (c.tag < kDropped) candidates.push_back(c);
    }
  }
  return plus_unassociated(log_weight, log_unassociated, same_for_all, assignment, taken.size());
}

// Whether no landmark is a candidate of two observations (then the choice is made per
// observation). O(C^2) for C candidates: callers ask only for short lists.
inline bool slots_disjoint(std::span<const AssociationCandidate> candidates) {
  for (std::size_t a = 0; a < candidates.size(); ++a) {
    for (std::size_t b = a + 1; b < candidates.size(); ++b) {
      if (candidates[a].slot == candidates[b].slot &&
          candidates[a].observation != candidates[b].observation) {
        return false;
      }
    }
  }
  return true;
}

// lazy_maximum_likelihood when no landmark is a candidate of two observations
// (slots_disjoint): mutual exclusion then never binds, so each observation takes its own best
// pair, found lazily as there (a bound on top is evaluated; an exact value on top is the best),
// if it is at or above its "no landmark" score. The same result, weight (the chosen values
// summed in the greedy order: larger first, ties by observation) and candidates left in the
// vector; no grouping, no order to keep. REQUIRES: as lazy_maximum_likelihood's, and
// slots_disjoint(candidates). Costs: O(C) per evaluation within one observation's candidates.
template <class Unassociated, class Evaluate>
double independent_maximum_likelihood(std::vector<AssociationCandidate>& candidates,
                                      const Unassociated& log_unassociated, bool same_for_all,
                                      std::span<std::int64_t> assignment, LazyScratch& scratch,
                                      Evaluate&& evaluate) {
  using lazy_association_detail::before;
  using lazy_association_detail::plus_unassociated;
  const std::size_t z = assignment.size();
  std::fill(assignment.begin(), assignment.end(), kNewLandmark);
  // By observation (stable), so that each one's candidates are a range.
  std::vector<std::uint32_t>& start = scratch.start;
  start.assign(z + 1, 0);
  for (const AssociationCandidate& c : candidates) ++start[c.observation + 1];
  for (std::size_t j = 0; j < z; ++j) start[j + 1] += start[j];
  std::vector<AssociationCandidate>& grouped = scratch.grouped;
  grouped.resize(candidates.size());
  std::vector<std::uint32_t>& fill = scratch.front;
  fill.assign(start.begin(), start.end() - 1);
  for (const AssociationCandidate& c : candidates) grouped[fill[c.observation]++] = c;
  std::vector<std::int64_t>& best = scratch.best;
  best.assign(z, -1);
  std::vector<std::uint32_t>& order = scratch.order;  // the associated observations
  order.clear();
  candidates.clear();
  for (std::size_t j = 0; j < z; ++j) {
    for (;;) {
      std::int64_t top = -1;
      for (std::uint32_t k = start[j]; k < start[j + 1]; ++k) {
        if (grouped[k].tag == kDropped) continue;
        if (top < 0 || before(grouped[k], grouped[static_cast<std::size_t>(top)])) top = k;
      }
      if (top < 0) break;
      AssociationCandidate& c = grouped[static_cast<std::size_t>(top)];
      if (c.tag != kBoundOnly) {
        best[j] = top;
        break;
      }
      if (!evaluate(c)) c.tag = kDropped;
    }
    if (best[j] >= 0 &&
        !(grouped[static_cast<std::size_t>(best[j])].log_likelihood < log_unassociated(j))) {
      const AssociationCandidate& c = grouped[static_cast<std::size_t>(best[j])];
      assignment[j] = c.slot;
      order.push_back(static_cast<std::uint32_t>(j));
      candidates.push_back(c);
      continue;
    }
    // New: every candidate, exact, for the scan report.
    for (std::uint32_t k = start[j]; k < start[j + 1]; ++k) {
      AssociationCandidate& c = grouped[k];
      if (c.tag == kBoundOnly && !evaluate(c)) c.tag = kDropped;
      if (c.tag < kDropped) candidates.push_back(c);
    }
  }
  // The greedy order of the taken pairs: larger ln p first, ties by observation.
  const auto value = [&](std::uint32_t j) {
    return grouped[static_cast<std::size_t>(best[j])].log_likelihood;
  };
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return value(a) > value(b) || (value(a) == value(b) && a < b);
  });
  double log_weight = 0.0;
  for (const std::uint32_t j : order) log_weight += value(j);
  return plus_unassociated(log_weight, log_unassociated, same_for_all, assignment, order.size());
}

}  // namespace fastslam::engine::internal
