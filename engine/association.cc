#include "engine/association.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "engine/internal/taken_slots.h"

namespace fastslam::engine {
namespace {

bool contains(const std::vector<memory::Slot>& slots, memory::Slot slot) {
  return std::find(slots.begin(), slots.end(), slot) != slots.end();
}

// `log_unassociated(j)`: observation j's score of "no landmark" (ln p0, or per observation).
template <class Unassociated>
double maximum_likelihood(std::span<AssociationCandidate> candidates,
                          const Unassociated& log_unassociated, bool same_for_all,
                          std::span<std::int64_t> assignment) {
  std::fill(assignment.begin(), assignment.end(), kNewLandmark);
  std::sort(candidates.begin(), candidates.end(),
            [](const AssociationCandidate& a, const AssociationCandidate& b) {
              if (a.log_likelihood != b.log_likelihood) return a.log_likelihood > b.log_likelihood;
              if (a.observation != b.observation) return a.observation < b.observation;
              return a.slot < b.slot;
            });
  double log_weight = 0.0;
  internal::TakenSlots taken(assignment);
  for (std::size_t c = 0; c < candidates.size() && taken.size() < assignment.size(); ++c) {
    const AssociationCandidate& cand = candidates[c];
    if (cand.log_likelihood < log_unassociated(cand.observation)) {
      if (same_for_all) break;  // sorted: every later one is below too
      continue;
    }
    if (assignment[cand.observation] != kNewLandmark || taken.contains(cand.slot)) continue;
    assignment[cand.observation] = cand.slot;
    log_weight += cand.log_likelihood;
    taken.take(cand.slot);
  }
  if (same_for_all) {
    log_weight += static_cast<double>(assignment.size() - taken.size()) * log_unassociated(0);
  } else {
    for (std::size_t j = 0; j < assignment.size(); ++j) {
      if (assignment[j] == kNewLandmark) log_weight += log_unassociated(j);
    }
  }
  return log_weight;
}

template <class Unassociated>
double sampling(std::span<AssociationCandidate> candidates, const Unassociated& log_unassociated,
                parallel::RandomStream& stream, std::span<std::int64_t> assignment,
                std::vector<memory::Slot>& taken) {
  // Candidates grouped by observation, in slot order: the draw does not depend on the order the
  // spatial query visited them in.
  std::sort(candidates.begin(), candidates.end(),
            [](const AssociationCandidate& a, const AssociationCandidate& b) {
              if (a.observation != b.observation) return a.observation < b.observation;
              return a.slot < b.slot;
            });
  taken.clear();
  double log_weight = 0.0;
  std::size_t c = 0;
  for (std::size_t j = 0; j < assignment.size(); ++j) {
    const std::size_t first = c;
    while (c < candidates.size() && candidates[c].observation == j) ++c;
    const double log_new_landmark = log_unassociated(j);
    // ln of the normaliser p0 + sum p_jn over free candidates, by log-sum-exp.
    double top = log_new_landmark;
    for (std::size_t k = first; k < c; ++k) {
      if (!contains(taken, candidates[k].slot)) top = std::max(top, candidates[k].log_likelihood);
    }
    double total = std::exp(log_new_landmark - top);
    for (std::size_t k = first; k < c; ++k) {
      if (!contains(taken, candidates[k].slot))
        total += std::exp(candidates[k].log_likelihood - top);
    }
    log_weight += top + std::log(total);
    // Walk the cumulative sum to the uniform's point; "new" is the last bucket, so rounding at
    // the end of the sum falls to it.
    double point = stream.uniform() * total;
    std::int64_t choice = kNewLandmark;
    for (std::size_t k = first; k < c; ++k) {
      if (contains(taken, candidates[k].slot)) continue;
      point -= std::exp(candidates[k].log_likelihood - top);
      if (point < 0) {
        choice = candidates[k].slot;
        break;
      }
    }
    assignment[j] = choice;
    if (choice != kNewLandmark) taken.push_back(static_cast<memory::Slot>(choice));
  }
  return log_weight;
}

}  // namespace

double associate_maximum_likelihood(std::span<AssociationCandidate> candidates,
                                    double log_new_landmark, std::span<std::int64_t> assignment) {
  return maximum_likelihood(
      candidates, [log_new_landmark](std::size_t) { return log_new_landmark; }, true, assignment);
}

double associate_maximum_likelihood(std::span<AssociationCandidate> candidates,
                                    std::span<const double> log_unassociated,
                                    std::span<std::int64_t> assignment) {
  return maximum_likelihood(
      candidates, [log_unassociated](std::size_t j) { return log_unassociated[j]; }, false,
      assignment);
}

double associate_sampling(std::span<AssociationCandidate> candidates, double log_new_landmark,
                          parallel::RandomStream& stream, std::span<std::int64_t> assignment,
                          std::vector<memory::Slot>& taken) {
  return sampling(
      candidates, [log_new_landmark](std::size_t) { return log_new_landmark; }, stream, assignment,
      taken);
}

double associate_sampling(std::span<AssociationCandidate> candidates,
                          std::span<const double> log_unassociated, parallel::RandomStream& stream,
                          std::span<std::int64_t> assignment, std::vector<memory::Slot>& taken) {
  return sampling(
      candidates, [log_unassociated](std::size_t j) { return log_unassociated[j]; }, stream,
      assignment, taken);
}

double log_unassociated(double log_new_landmark, const DetectionConfig& detection, double range) {
  double log_sum = log_new_landmark;
  const double kappa = detection.clutter_density * range;
  if (kappa > 0) {  // ln(p0 + kappa) by log-sum-exp: p0 may be far below a double's range
    const double log_kappa = std::log(kappa);
    const double top = std::max(log_sum, log_kappa);
    log_sum = top + std::log1p(std::exp(std::min(log_sum, log_kappa) - top));
  }
  return log_sum - std::log(detection.probability);
}

}  // namespace fastslam::engine
