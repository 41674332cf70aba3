// Template definitions of memory/spatial_index.h, part 3: queries (disc, batch of discs, sensor
// footprint, nearest, traversal, introspection). Not API: include memory/spatial_index.h
// instead.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <numbers>
#include <type_traits>
#include <utility>

#include "memory/internal/spatial_index_nodes.h"

namespace fastslam::memory {

template <class P>
template <class Visit>
void BasicSpatialIndex<P>::for_each_node(const Node* node, Visit& visit) {
  if (node->leaf()) {
    const SpatialEntry* e = entries(node);
    for (std::uint32_t i = 0; i < node->count; ++i) {
      visit(e[i]);
    }
    return;
  }
  for (const Node* child : static_cast<const Inner*>(node)->child) {
    if (child != nullptr) {
      for_each_node(child, visit);
    }
  }
}

template <class P>
template <class Visit>
void BasicSpatialIndex<P>::for_each(Visit&& visit) const {
  if (root_ != nullptr) {
    for_each_node(root_, visit);
  }
}

template <class P>
template <class Reach2, class Visit>
void BasicSpatialIndex<P>::within_node(const Node* node, const Cell& cell, double x, double y,
                                       double r2, double prune2, double reach, const Reach2& reach2,
                                       Visit& visit) {
  if (node->leaf()) {
    const SpatialEntry* e = entries(node);
    if constexpr (std::is_same_v<Reach2, AnyReach>) {
      for (std::uint32_t i = 0; i < node->count; ++i) {
        const double dx = e[i].x - x;
        const double dy = e[i].y - y;
        if (dx * dx + dy * dy <= r2) {
          visit(e[i]);
        }
      }
    } else {
      for (std::uint32_t i = 0; i < node->count; ++i) {
        const double dx = e[i].x - x;
        const double dy = e[i].y - y;
        const double d2 = dx * dx + dy * dy;
        if (d2 <= r2 && !(d2 > reach2(e[i].extent))) {
          visit(e[i]);
        }
      }
    }
    return;
  }
  const auto* inner = static_cast<const Inner*>(node);
  // Only the rows and columns of children that the square [x - reach, x + reach] x [y - reach,
  // y + reach] overlaps (a small disc deep in the tree: one child of four, not four box tests).
  // The margin is far above the rounding of these few operations; the exact tests below decide.
  constexpr unsigned kSide = 1u << kLevelsPerNode;
  const double inv_side = static_cast<double>(kSide) / cell.side;
  const double margin = 0x1p-30 * (std::fabs(x - cell.x) + std::fabs(y - cell.y) + cell.side);
  unsigned lo[2];
  unsigned hi[2];
  const double q[2] = {x - cell.x, y - cell.y};
  for (int axis = 0; axis < 2; ++axis) {
    const double a = (q[axis] - reach - margin) * inv_side;
    const double b = (q[axis] + reach + margin) * inv_side;
    if (!(b >= 0.0) || !(a < static_cast<double>(kSide))) {
      return;  // the square misses this cell on this axis
    }
    lo[axis] = a <= 0.0 ? 0u : static_cast<unsigned>(a);
    hi[axis] = b >= static_cast<double>(kSide - 1) ? kSide - 1 : static_cast<unsigned>(b);
  }
  for (unsigned iy = lo[1]; iy <= hi[1]; ++iy) {
    for (unsigned ix = lo[0]; ix <= hi[0]; ++ix) {
      const unsigned i = (iy << kLevelsPerNode) | ix;
      const Node* child = inner->child[i];
      if (child == nullptr) {
        continue;
      }
      const Cell sub = child_cell(cell, i);
      const double box2 = box_distance2(sub, x, y);
      if (box2 > prune2) {
        continue;
      }
      if constexpr (std::is_same_v<Reach2, AnyReach>) {
        // A square wholly inside the disc (with a margin for rounding) needs no per-entry test.
        const double fx = std::max(std::fabs(sub.x - x), std::fabs(sub.x + sub.side - x));
        const double fy = std::max(std::fabs(sub.y - y), std::fabs(sub.y + sub.side - y));
        if (fx * fx + fy * fy <= r2 * (1.0 - 0x1p-40)) {
          for_each_node(child, visit);
          continue;
        }
      } else if (child->leaf() && child->count != 0) {
        if (beyond_reach(box2, reach2(entries(child)[0].extent))) {
          continue;
        }
      }
      within_node(child, sub, x, y, r2, prune2, reach, reach2, visit);
    }
  }
}

template <class P>
template <class Visit>
void BasicSpatialIndex<P>::within(double x, double y, double radius, Visit&& visit) const {
  if (root_ == nullptr) {
    return;
  }
  // From the deepest node whose square holds the disc's (as within(from, ...), which checks
  // the containment exactly): the same entries in the same order as from the root, and the
  // levels above cost a cheap descent instead of within_node's per-level work.
  const double prune2 = radius * radius * (1.0 + 0x1p-40);
  const double reach = std::sqrt(prune2) * (1.0 + 0x1p-30) * (1.0 + 0x1p-30);
  const double margin = 0x1p-29 * (std::fabs(x) + std::fabs(y) + reach);
  const Subtree from =
      covering(x - reach - margin, y - reach - margin, x + reach + margin, y + reach + margin);
  within_reach(from, x, y, radius, AnyReach{}, visit);
}

template <class P>
auto BasicSpatialIndex<P>::covering(double min_x, double min_y, double max_x,
                                    double max_y) const noexcept -> Subtree {
  Subtree out;
  if (root_ == nullptr || !contains(root_cell_, min_x, min_y) ||
      !contains(root_cell_, max_x, max_y)) {
    return out;
  }
  const Node* node = root_;
  Cell cell = root_cell_;
  while (!node->leaf()) {
    Cell low;
    Cell high;
    const unsigned i = child_of(cell, min_x, min_y, low);
    if (i != child_of(cell, max_x, max_y, high)) {
      break;  // the box straddles this node's children
    }
    const Node* child = static_cast<const Inner*>(node)->child[i];
    if (child == nullptr) {
      break;
    }
    node = child;
    cell = low;
  }
  out.node_ = node;
  out.x_ = cell.x;
  out.y_ = cell.y;
  out.side_ = cell.side;
  out.level_ = cell.level;
  return out;
}

template <class P>
template <class Visit>
void BasicSpatialIndex<P>::within(const Subtree& from, double x, double y, double radius,
                                  Visit&& visit) const {
  within_reach(from, x, y, radius, AnyReach{}, visit);
}

template <class P>
template <class Reach2, class Visit>
void BasicSpatialIndex<P>::within_reach(const Subtree& from, double x, double y, double radius,
                                        const Reach2& reach2, Visit&& visit) const {
  if (root_ == nullptr) {
    return;
  }
  if (from.node_ != nullptr) {
    const double r2 = radius * radius;
    const double prune2 = r2 + r2 * 0x1p-40;
    const double reach = std::sqrt(prune2) * (1.0 + 0x1p-30);
    // Every entry the disc holds lies within `reach` of (x, y) on each axis; the margin covers
    // the rounding of these sums. Then no entry outside the square can be a hit, and the
    // descent below the node visits the same children in the same order as one from the root
    // (no ancestor's square lies wholly inside the disc: each holds the square of half-side
    // reach around (x, y)).
    const double margin = 0x1p-30 * (std::fabs(x) + std::fabs(y) + reach);
    if (x - reach - margin >= from.x_ && x + reach + margin < from.x_ + from.side_ &&
        y - reach - margin >= from.y_ && y + reach + margin < from.y_ + from.side_) {
      const Cell cell{from.x_, from.y_, from.side_, from.level_};
      within_node(static_cast<const Node*>(from.node_), cell, x, y, r2, prune2, reach, reach2,
                  visit);
      return;
    }
  }
  const double r2 = radius * radius;
  const double prune2 = r2 + r2 * 0x1p-40;
  if (box_distance2(root_cell_, x, y) > prune2) {
    return;
  }
  const double reach = std::sqrt(prune2) * (1.0 + 0x1p-30);
  within_node(root_, root_cell_, x, y, r2, prune2, reach, reach2, visit);
}

template <class P>
template <class Reach2, class Visit>
void BasicSpatialIndex<P>::within_many_node(const Node* node, const Cell& cell,
                                            const DiscBounds* discs, std::size_t first,
                                            std::uint64_t active, const Reach2& reach2,
                                            Visit& visit) {
  if (node->leaf()) {
    if (node->count == 0) {
      return;
    }
    const SpatialEntry* e = entries(node);
    // The exact box test, and the leaf's widest entry's reach, per disc.
    std::uint64_t reached = 0;
    for (std::uint64_t bits = active; bits != 0; bits &= bits - 1) {
      const auto k = static_cast<unsigned>(std::countr_zero(bits));
      const double box2 = box_distance2(cell, discs[k].x, discs[k].y);
      if (box2 <= discs[k].prune2 && !beyond_reach(box2, reach2(first + k, e[0].extent))) {
        reached |= std::uint64_t{1} << k;
      }
    }
    if (reached == 0) {
      return;
    }
    // Disc by disc: the entry loop is then a plain distance test.
    const std::uint32_t count = node->count;
    for (std::uint64_t bits = reached; bits != 0; bits &= bits - 1) {
      const auto k = static_cast<unsigned>(std::countr_zero(bits));
      const double x = discs[k].x;
      const double y = discs[k].y;
      const double r2 = discs[k].r2;
      for (std::uint32_t i = 0; i < count; ++i) {
        const double dx = e[i].x - x;
        const double dy = e[i].y - y;
        const double d2 = dx * dx + dy * dy;
        if (d2 <= r2 && !(d2 > reach2(first + k, e[i].extent))) {
          visit(first + k, e[i]);
        }
      }
    }
    return;
  }
  // Per axis, the discs whose square reaches column (row) c: its low side lies below the
  // column's upper boundary and its high side at or above the lower one. The boundaries are
  // exact (child_of's), and every disc here overlaps this node's square, so only the inner
  // boundaries need comparing.
  constexpr unsigned kSide = 1u << kLevelsPerNode;
  const double child_side = cell.side * (1.0 / static_cast<double>(kSide));
  std::uint64_t column[kSide];
  std::uint64_t row[kSide];
  if constexpr (kLevelsPerNode == 1) {
    const double mid_x = cell.x + child_side;
    const double mid_y = cell.y + child_side;
    std::uint64_t low_x = 0;
    std::uint64_t high_x = 0;
    std::uint64_t low_y = 0;
    std::uint64_t high_y = 0;
    for (std::uint64_t bits = active; bits != 0; bits &= bits - 1) {
      const auto k = static_cast<unsigned>(std::countr_zero(bits));
      const std::uint64_t bit = std::uint64_t{1} << k;
      const DiscBounds& d = discs[k];
      low_x |= d.lo_x < mid_x ? bit : 0;
      high_x |= d.hi_x >= mid_x ? bit : 0;
      low_y |= d.lo_y < mid_y ? bit : 0;
      high_y |= d.hi_y >= mid_y ? bit : 0;
    }
    column[0] = low_x;
    column[1] = high_x;
    row[0] = low_y;
    row[1] = high_y;
  } else {
    for (unsigned c = 0; c < kSide; ++c) {
      column[c] = row[c] = active;
    }
    for (std::uint64_t bits = active; bits != 0; bits &= bits - 1) {
      const auto k = static_cast<unsigned>(std::countr_zero(bits));
      const std::uint64_t bit = std::uint64_t{1} << k;
      const DiscBounds& d = discs[k];
      for (unsigned c = 1; c < kSide; ++c) {
        const double bx = cell.x + static_cast<double>(c) * child_side;
        const double by = cell.y + static_cast<double>(c) * child_side;
        // Below the boundary: not in columns c.. ; at or above it: not in columns ..c-1.
        if (!(d.hi_x >= bx)) {
          for (unsigned u = c; u < kSide; ++u) column[u] &= ~bit;
        }
        if (!(d.lo_x < bx)) {
          for (unsigned u = 0; u < c; ++u) column[u] &= ~bit;
        }
        if (!(d.hi_y >= by)) {
          for (unsigned u = c; u < kSide; ++u) row[u] &= ~bit;
        }
        if (!(d.lo_y < by)) {
          for (unsigned u = 0; u < c; ++u) row[u] &= ~bit;
        }
      }
    }
  }
  const auto* inner = static_cast<const Inner*>(node);
  for (unsigned i = 0; i < kWidth; ++i) {
    const std::uint64_t reached = column[i & (kSide - 1)] & row[i >> kLevelsPerNode];
    const Node* child = inner->child[i];
    if (reached == 0 || child == nullptr) {
      continue;
    }
    within_many_node(child, child_cell(cell, i), discs, first, reached, reach2, visit);
  }
}

template <class P>
template <class Reach2, class Visit>
void BasicSpatialIndex<P>::within_reach(const Subtree& from, std::span<const Disc> discs,
                                        const Reach2& reach2, Visit&& visit) const {
  if (root_ == nullptr) {
    return;
  }
  // In groups of 64 (one bit each); per group, the discs inside `from`'s square (as
  // within(from, ...) decides it) descend from there, the others from the root.
  for (std::size_t first = 0; first < discs.size(); first += 64) {
    const std::size_t n = std::min<std::size_t>(64, discs.size() - first);
    std::array<DiscBounds, 64> bounds;
    std::uint64_t inside = 0;
    std::uint64_t outside = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const Disc& d = discs[first + k];
      const double r2 = d.radius * d.radius;
      const double prune2 = r2 + r2 * 0x1p-40;
      // Every entry the disc holds lies within `reach` of its centre on each axis; the margin
      // covers the rounding of these sums (as within(from, ...)'s containment test).
      const double reach = std::sqrt(prune2) * (1.0 + 0x1p-30);
      const double margin = 0x1p-30 * (std::fabs(d.x) + std::fabs(d.y) + reach);
      const double lo_x = d.x - reach - margin;
      const double hi_x = d.x + reach + margin;
      const double lo_y = d.y - reach - margin;
      const double hi_y = d.y + reach + margin;
      bounds[k] = {d.x, d.y, r2, prune2, lo_x, hi_x, lo_y, hi_y};
      if (from.node_ != nullptr && lo_x >= from.x_ && hi_x < from.x_ + from.side_ &&
          lo_y >= from.y_ && hi_y < from.y_ + from.side_) {
        inside |= std::uint64_t{1} << k;
      } else if (box_distance2(root_cell_, d.x, d.y) <= prune2 && hi_x >= root_cell_.x &&
                 lo_x < root_cell_.x + root_cell_.side && hi_y >= root_cell_.y &&
                 lo_y < root_cell_.y + root_cell_.side) {
        outside |= std::uint64_t{1} << k;
      }
    }
    if (inside != 0) {
      const Cell cell{from.x_, from.y_, from.side_, from.level_};
      within_many_node(static_cast<const Node*>(from.node_), cell, bounds.data(), first, inside,
                       reach2, visit);
    }
    if (outside != 0) {
      within_many_node(root_, root_cell_, bounds.data(), first, outside, reach2, visit);
    }
  }
}

template <class P>
template <class Visit>
void BasicSpatialIndex<P>::in_footprint(double x, double y, double heading, double max_range,
                                        double field_of_view, Visit&& visit) const {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  if (field_of_view >= kTwoPi) {
    within(x, y, max_range, visit);
    return;
  }
  const double half = 0.5 * field_of_view;
  // Most entries are clearly inside or outside: the cosine of their angle off the heading,
  // (d . u) / |d|, against cos(half), decides them without trigonometry when the two differ by
  // more than 1e-9, far above the rounding of either way (a few ulps). Entries in the band
  // between (on the edge, or too close to the sensor for |d| to be exact) take the exact test.
  const double ux = std::cos(heading);
  const double uy = std::sin(heading);
  const double cos_half = std::cos(half);
  within(x, y, max_range, [&](const SpatialEntry& e) {
    const double dx = e.x - x;
    const double dy = e.y - y;
    const double norm = std::sqrt(dx * dx + dy * dy);
    if (norm > 0x1p-500) {
      const double gap = dx * ux + dy * uy - cos_half * norm;
      if (gap > 1e-9 * norm) {
        visit(e);
        return;
      }
      if (gap < -1e-9 * norm) {
        return;
      }
    }
    if ((dx == 0.0 && dy == 0.0) ||
        std::fabs(std::remainder(std::atan2(dy, dx) - heading, kTwoPi)) <= half) {
      visit(e);
    }
  });
}

template <class P>
struct BasicSpatialIndex<P>::Best {
  SpatialEntry* out;
  std::size_t k;
  std::size_t n;
  double x;
  double y;
  double d2(const SpatialEntry& e) const noexcept {
    const double dx = e.x - x;
    const double dy = e.y - y;
    return dx * dx + dy * dy;
  }
  bool less(const SpatialEntry& a, const SpatialEntry& b) const noexcept { return d2(a) < d2(b); }
};

template <class P>
void BasicSpatialIndex<P>::nearest_node(const Node* node, const Cell& cell, Best& best) noexcept {
  auto less = [&best](const SpatialEntry& a, const SpatialEntry& b) { return best.less(a, b); };
  if (node->leaf()) {
    const SpatialEntry* e = entries(node);
    for (std::uint32_t i = 0; i < node->count; ++i) {
      if (best.n < best.k) {
        best.out[best.n++] = e[i];
        std::push_heap(best.out, best.out + best.n, less);
      } else if (best.d2(e[i]) < best.d2(best.out[0])) {
        std::pop_heap(best.out, best.out + best.n, less);
        best.out[best.n - 1] = e[i];
        std::push_heap(best.out, best.out + best.n, less);
      }
    }
    return;
  }
  // Children nearest first, so the bound tightens early.
  std::array<std::pair<double, unsigned>, kWidth> order;
  unsigned count = 0;
  const auto* inner = static_cast<const Inner*>(node);
  for (unsigned i = 0; i < kWidth; ++i) {
    if (inner->child[i] != nullptr) {
      order[count++] = {box_distance2(child_cell(cell, i), best.x, best.y), i};
    }
  }
  std::sort(order.begin(), order.begin() + count);
  for (unsigned j = 0; j < count; ++j) {
    if (best.n == best.k) {
      const double worst = best.d2(best.out[0]);
      if (order[j].first > worst + worst * 0x1p-40) {
        break;
      }
    }
    const unsigned i = order[j].second;
    nearest_node(inner->child[i], child_cell(cell, i), best);
  }
}

template <class P>
std::size_t BasicSpatialIndex<P>::nearest(double x, double y, std::size_t k,
                                          std::span<SpatialEntry> out) const {
  k = std::min(k, out.size());
  if (root_ == nullptr || k == 0) {
    return 0;
  }
  Best best{out.data(), k, 0, x, y};
  nearest_node(root_, root_cell_, best);
  std::sort_heap(out.data(), out.data() + best.n,
                 [&best](const SpatialEntry& a, const SpatialEntry& b) { return best.less(a, b); });
  return best.n;
}

template <class P>
template <class Visit>
void BasicSpatialIndex<P>::for_each_path_node(double x, double y, Visit&& visit) const {
  if (root_ == nullptr || !contains(root_cell_, x, y)) {
    return;
  }
  const Node* node = root_;
  Cell cell = root_cell_;
  while (node != nullptr) {
    visit(static_cast<const void*>(node));
    if (node->leaf()) {
      return;
    }
    Cell child;
    node = static_cast<const Inner*>(node)->child[child_of(cell, x, y, child)];
    cell = child;
  }
}

template <class P>
unsigned BasicSpatialIndex<P>::depth() const noexcept {
  struct Walk {
    static unsigned of(const Node* node) noexcept {
      if (node->leaf()) {
        return 1;
      }
      unsigned deepest = 0;
      for (const Node* child : static_cast<const Inner*>(node)->child) {
        if (child != nullptr) {
          deepest = std::max(deepest, of(child));
        }
      }
      return deepest + 1;
    }
  };
  return root_ == nullptr ? 0 : Walk::of(root_);
}

}  // namespace fastslam::memory
