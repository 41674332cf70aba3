// What a step needs of the whole particle set when a group of ranks shares it
// (parallel/collective.h): the set's most likely particle and a broadcast from the rank holding
// it. Without a group both are local and free. Collective calls: every rank calls them at the
// same point of the same step. Thread safety: thread-compatible. Costs: best_particle O(M / R)
// plus one all_gather of R values; broadcast moves the root's bytes to every rank.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <type_traits>
#include <vector>

#include "engine/internal/filter_state.h"
#include "engine/internal/weight_range.h"
#include "parallel/collective.h"

namespace fastslam::engine::internal {

// The particle of largest log-weight in the set (lowest set index among ties).
struct BestParticle {
  double log_weight = 0.0;
  std::uint64_t index = 0;  // in the set
  int owner = 0;            // the rank holding it (0 without a group)
  bool here = true;         // held by this rank
  std::size_t local = 0;    // its index in this rank's store (when here)
};

inline BestParticle best_particle(const FilterState& s) {
  const std::span<const double> lw = s.store.log_weight();
  const std::size_t best = first_largest(lw);
  BestParticle b{lw[best], s.first_particle + best, 0, true, best};
  if (s.group == nullptr) return b;
  struct Candidate {
    double log_weight;
    std::uint64_t index;
  };
  const std::vector<Candidate> all =
      parallel::all_gather_value(*s.group, Candidate{b.log_weight, b.index});
  std::size_t owner = 0;
  for (std::size_t r = 1; r < all.size(); ++r) {
    if (all[r].log_weight > all[owner].log_weight) owner = r;
  }
  b.owner = static_cast<int>(owner);
  b.here = b.owner == s.group->rank();
  b.log_weight = all[owner].log_weight;
  b.index = all[owner].index;
  b.local = b.here ? best : 0;
  return b;
}

// `mine` on rank `root`, returned on every rank (the other ranks' `mine` is ignored).
template <class T>
std::vector<T> broadcast(parallel::Collective& group, int root, const std::vector<T>& mine) {
  static_assert(std::is_trivially_copyable_v<T>);
  const std::span<const T> sent = group.rank() == root ? std::span<const T>(mine) : std::span<const T>();
  return parallel::all_gather_values(group, sent);
}

}  // namespace fastslam::engine::internal
