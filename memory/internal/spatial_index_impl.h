// Template definitions of memory/spatial_index.h; not API, include that header instead.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <new>
#include <numbers>
#include <type_traits>
#include <utility>
#include <vector>

namespace fastslam::memory {

namespace internal {
[[noreturn]] void throw_bad_position(const char* operation, double x, double y);
[[noreturn]] void throw_no_entry(const char* operation, Slot slot, double x, double y);
[[noreturn]] void throw_leaf_full(Slot slot, double x, double y);
}  // namespace internal

template <class P>
BasicSpatialIndex<P>::BasicSpatialIndex(const BasicSpatialIndex& other) noexcept
    : root_(other.root_), heap_(other.heap_), root_cell_(other.root_cell_), size_(other.size_) {
  if (root_ != nullptr) {
    root_->refs.acquire();
  }
}

template <class P>
BasicSpatialIndex<P>::BasicSpatialIndex(BasicSpatialIndex&& other) noexcept
    : root_(std::exchange(other.root_, nullptr)),
      heap_(other.heap_),
      root_cell_(other.root_cell_),
      size_(std::exchange(other.size_, 0)) {}

template <class P>
BasicSpatialIndex<P>& BasicSpatialIndex<P>::operator=(const BasicSpatialIndex& other) noexcept {
  if (this != &other) {
    if (other.root_ != nullptr) {
      other.root_->refs.acquire();
    }
    release(root_, *heap_);
    root_ = other.root_;
    heap_ = other.heap_;
    root_cell_ = other.root_cell_;
    size_ = other.size_;
  }
  return *this;
}

template <class P>
BasicSpatialIndex<P>& BasicSpatialIndex<P>::operator=(BasicSpatialIndex&& other) noexcept {
  if (this != &other) {
    release(root_, *heap_);
    root_ = std::exchange(other.root_, nullptr);
    heap_ = other.heap_;
    root_cell_ = other.root_cell_;
    size_ = std::exchange(other.size_, 0);
  }
  return *this;
}

template <class P>
BasicSpatialIndex<P>::~BasicSpatialIndex() {
  release(root_, *heap_);
}

template <class P>
void BasicSpatialIndex<P>::clear() noexcept {
  release(std::exchange(root_, nullptr), *heap_);
  size_ = 0;
}

// ---------------------------------------------------------------------------------------------
// Geometry. Every cell is a square whose boundaries are exact doubles (the corner is a multiple
// of the children's side, and |corner| / side stays far below 2^53), so "which child holds this
// point" is decided by exact comparisons and is the same on every path that asks it.

template <class P>
inline unsigned BasicSpatialIndex<P>::child_of(const Cell& cell, double x, double y,
                                               Cell& child) noexcept {
  double cx = cell.x;
  double cy = cell.y;
  double side = cell.side;
  unsigned ix = 0;
  unsigned iy = 0;
  for (unsigned l = 0; l < kLevelsPerNode; ++l) {
    side *= 0.5;
    ix <<= 1;
    iy <<= 1;
    if (x >= cx + side) {
      cx += side;
      ix |= 1;
    }
    if (y >= cy + side) {
      cy += side;
      iy |= 1;
    }
  }
  child = {cx, cy, side, cell.level - static_cast<int>(kLevelsPerNode)};
  return iy << kLevelsPerNode | ix;
}

template <class P>
inline auto BasicSpatialIndex<P>::child_cell(const Cell& cell, unsigned index) noexcept -> Cell {
  const double side = cell.side * (1.0 / static_cast<double>(1u << kLevelsPerNode));
  const unsigned ix = index & ((1u << kLevelsPerNode) - 1);
  const unsigned iy = index >> kLevelsPerNode;
  return {cell.x + ix * side, cell.y + iy * side, side,
          cell.level - static_cast<int>(kLevelsPerNode)};
}

template <class P>
bool BasicSpatialIndex<P>::can_split(const Cell& cell) noexcept {
  if (cell.level - static_cast<int>(kLevelsPerNode) < kMinLevel) {
    return false;
  }
  const double limit = cell.side * (1.0 / static_cast<double>(1u << kLevelsPerNode)) * 0x1p50;
  return std::fabs(cell.x) + cell.side <= limit && std::fabs(cell.y) + cell.side <= limit;
}

template <class P>
inline double BasicSpatialIndex<P>::box_distance2(const Cell& cell, double x, double y) noexcept {
  // Rounding is monotone, so each term is at most the same term for any point in the square.
  double dx = 0.0;
  double dy = 0.0;
  if (x < cell.x) {
    dx = cell.x - x;
  } else if (x > cell.x + cell.side) {
    dx = x - (cell.x + cell.side);
  }
  if (y < cell.y) {
    dy = cell.y - y;
  } else if (y > cell.y + cell.side) {
    dy = y - (cell.y + cell.side);
  }
  return dx * dx + dy * dy;
}

template <class P>
void BasicSpatialIndex<P>::check_point(double x, double y, const char* operation) {
  if (!(std::fabs(x) <= kMaxCoordinate) || !(std::fabs(y) <= kMaxCoordinate)) {
    internal::throw_bad_position(operation, x, y);
  }
}

// ---------------------------------------------------------------------------------------------
// Nodes

template <class P>
auto BasicSpatialIndex<P>::make_leaf(std::uint32_t capacity) -> Node* {
  void* block = heap_->allocate(leaf_bytes(capacity));
  return ::new (block) Node(capacity);
}

template <class P>
auto BasicSpatialIndex<P>::make_inner() -> Inner* {
  void* block = heap_->allocate(sizeof(Inner));
  return ::new (block) Inner();
}

template <class P>
auto BasicSpatialIndex<P>::own(Node* node) -> Node* {
  if (node->refs.unique()) {
    return node;
  }
  Node* copy;
  if (node->leaf()) {
    copy = make_leaf(node->capacity);
    std::memcpy(static_cast<void*>(entries(copy)), entries(node),
                std::size_t{node->count} * sizeof(SpatialEntry));
  } else {
    Inner* inner = make_inner();
    const auto* source = static_cast<const Inner*>(node);
    for (unsigned i = 0; i < kWidth; ++i) {
      Node* child = source->child[i];
      if (child != nullptr) {
        child->refs.acquire();
      }
      inner->child[i] = child;
    }
    copy = inner;
  }
  copy->count = node->count;
  release(node, *heap_);
  return copy;
}

template <class P>
void BasicSpatialIndex<P>::free_node(Node* node, NodeHeap& heap) noexcept {
  if (node->leaf()) {
    heap.deallocate(node, leaf_bytes(node->capacity));
  } else {
    heap.deallocate(node, sizeof(Inner));
  }
}

template <class P>
void BasicSpatialIndex<P>::release(Node* node, NodeHeap& heap) noexcept {
  if (node == nullptr || !node->refs.release()) {
    return;
  }
  // The nodes to free form a stack chained through their (dead) counts: no recursion, no
  // allocation, whatever the depth.
  node->next_dead = nullptr;
  Node* head = node;
  while (head != nullptr) {
    Node* next = head;
    head = next->next_dead;
    if (!next->leaf()) {
      for (Node* child : static_cast<Inner*>(next)->child) {
        if (child != nullptr && child->refs.release()) {
          child->next_dead = head;
          head = child;
        }
      }
    }
    free_node(next, heap);
  }
}

template <class P>
auto BasicSpatialIndex<P>::build(SpatialEntry* first, SpatialEntry* last, const Cell& cell)
    -> Node* {
  const auto n = static_cast<std::size_t>(last - first);
  if (n == 0) {
    return nullptr;
  }
  if (n <= kLeafCapacity || !can_split(cell)) {
    const auto capacity = static_cast<std::uint32_t>(std::max<std::size_t>(
        kLeafCapacity, n <= kLeafCapacity ? kLeafCapacity : std::bit_ceil(n)));
    Node* leaf = make_leaf(capacity);
    std::memcpy(static_cast<void*>(entries(leaf)), first, n * sizeof(SpatialEntry));
    leaf->count = static_cast<std::uint32_t>(n);
    widest_first(leaf);
    return leaf;
  }
  Inner* inner = make_inner();
  inner->count = static_cast<std::uint32_t>(n);
  auto index_of = [&cell](const SpatialEntry& e) {
    Cell unused;
    return child_of(cell, e.x, e.y, unused);
  };
  std::sort(first, last, [&](const SpatialEntry& a, const SpatialEntry& b) {
    return index_of(a) < index_of(b);
  });
  try {
    for (SpatialEntry* begin = first; begin != last;) {
      const unsigned i = index_of(*begin);
      SpatialEntry* end = begin + 1;
      while (end != last && index_of(*end) == i) {
        ++end;
      }
      inner->child[i] = build(begin, end, child_cell(cell, i));
      begin = end;
    }
  } catch (...) {
    release(inner, *heap_);  // the children built so far go with it
    throw;
  }
  return inner;
}

template <class P>
void BasicSpatialIndex<P>::widest_first(Node* leaf) noexcept {
  SpatialEntry* e = entries(leaf);
  std::uint32_t widest = 0;
  for (std::uint32_t i = 1; i < leaf->count; ++i) {
    if (wider(e[i].extent, e[widest].extent)) {
      widest = i;
    }
  }
  if (widest != 0) {
    std::swap(e[0], e[widest]);
  }
}

template <class P>
void BasicSpatialIndex<P>::appended(Node* leaf) noexcept {
  SpatialEntry* e = entries(leaf);
  const std::uint32_t last = leaf->count - 1;
  if (last != 0 && wider(e[last].extent, e[0].extent)) {
    std::swap(e[0], e[last]);
  }
}

// ---------------------------------------------------------------------------------------------
// Changes

template <class P>
void BasicSpatialIndex<P>::grow_to(double x, double y) {
  // The root square is [-h, h)^2; its children are aligned squares. Growing by kLevelsPerNode
  // levels gives [-h', h')^2, h' = h * 2^L; the old root's children keep their squares and go
  // one level down, under four new nodes (one per quadrant around the origin), which sit at
  // the centre of the new root.
  constexpr unsigned kSide = 1u << kLevelsPerNode;
  constexpr unsigned kHalf = kSide / 2;
  while (!contains(root_cell_, x, y)) {
    Cell up = root_cell_;
    up.level += static_cast<int>(kLevelsPerNode);
    up.side *= static_cast<double>(kSide);
    up.x = up.y = -0.5 * up.side;
    if (!root_->leaf()) {
      auto* old = static_cast<Inner*>(root_);
      Inner* top = make_inner();  // may throw: nothing changed yet
      std::array<Inner*, 4> quadrant{};
      try {
        for (unsigned i = 0; i < kWidth; ++i) {
          if (old->child[i] == nullptr) {
            continue;
          }
          const unsigned q =
              ((i >> kLevelsPerNode) >= kHalf ? 2u : 0u) | ((i & (kSide - 1)) >= kHalf ? 1u : 0u);
          if (quadrant[q] == nullptr) {
            quadrant[q] = make_inner();
          }
        }
      } catch (...) {
        for (Inner* node : quadrant) {
          release(node, *heap_);
        }
        release(top, *heap_);
        throw;
      }
      for (unsigned i = 0; i < kWidth; ++i) {
        Node* child = old->child[i];
        if (child == nullptr) {
          continue;
        }
        const unsigned ix = i & (kSide - 1);
        const unsigned iy = i >> kLevelsPerNode;
        const unsigned q = (iy >= kHalf ? 2u : 0u) | (ix >= kHalf ? 1u : 0u);
        const unsigned gx = ix >= kHalf ? ix - kHalf : ix + kHalf;
        const unsigned gy = iy >= kHalf ? iy - kHalf : iy + kHalf;
        child->refs.acquire();
        quadrant[q]->child[gy << kLevelsPerNode | gx] = child;
        quadrant[q]->count += child->count;
      }
      for (unsigned q = 0; q < 4; ++q) {
        if (quadrant[q] != nullptr) {
          const unsigned jx = (q & 1u) != 0 ? kHalf : kHalf - 1;
          const unsigned jy = (q & 2u) != 0 ? kHalf : kHalf - 1;
          top->child[jy << kLevelsPerNode | jx] = quadrant[q];
        }
      }
      top->count = old->count;
      release(old, *heap_);
      root_ = top;
    }
    root_cell_ = up;  // a leaf root's entries lie in the larger square too
  }
}

template <class P>
void BasicSpatialIndex<P>::insert(Slot slot, double x, double y, float extent) {
  check_point(x, y, "insert");
  const SpatialEntry entry{slot, extent, x, y};
  if (root_ == nullptr) {
    // The first square: [-16, 16)^2, or larger (by the growth step) until it holds the point.
    Cell cell{-16.0, -16.0, 32.0, 5};
    while (!contains(cell, x, y)) {
      cell.level += static_cast<int>(kLevelsPerNode);
      cell.side *= static_cast<double>(1u << kLevelsPerNode);
      cell.x = cell.y = -0.5 * cell.side;
    }
    Node* leaf = make_leaf(kLeafCapacity);
    entries(leaf)[0] = entry;
    leaf->count = 1;
    root_ = leaf;
    root_cell_ = cell;
    size_ = 1;
    return;
  }
  grow_to(x, y);
  std::array<Node*, kMaxDepth> path;
  unsigned depth = 0;
  Node** link = &root_;
  Cell cell = root_cell_;
  while (!(*link)->leaf()) {
    *link = own(*link);
    auto* inner = static_cast<Inner*>(*link);
    path[depth++] = inner;
    Cell child;
    link = &inner->child[child_of(cell, x, y, child)];
    cell = child;
    if (*link == nullptr) {
      *link = make_leaf(kLeafCapacity);  // linked empty: harmless if what follows throws
    }
  }
  Node* leaf = *link;
  if (leaf->count < leaf->capacity) {
    leaf = own(leaf);
    *link = leaf;
    entries(leaf)[leaf->count++] = entry;
    appended(leaf);
  } else if (can_split(cell)) {
    // A full leaf becomes a subtree. It holds kLeafCapacity entries, unless it grew at the
    // finest size and became the root whose square then grew (rare: then a vector).
    std::array<SpatialEntry, kLeafCapacity + 1> small;
    std::vector<SpatialEntry> large;
    SpatialEntry* all = small.data();
    const std::size_t n = std::size_t{leaf->count} + 1;
    if (n > small.size()) {
      large.resize(n);
      all = large.data();
    }
    std::copy_n(entries(leaf), leaf->count, all);
    all[n - 1] = entry;
    Node* subtree = build(all, all + n, cell);
    release(leaf, *heap_);
    *link = subtree;
  } else {
    if (leaf->count >= kMaxLeafEntries) {
      internal::throw_leaf_full(slot, x, y);
    }
    Node* bigger = make_leaf(leaf->capacity * 2);
    std::memcpy(static_cast<void*>(entries(bigger)), entries(leaf),
                std::size_t{leaf->count} * sizeof(SpatialEntry));
    bigger->count = leaf->count;
    entries(bigger)[bigger->count++] = entry;
    appended(bigger);
    release(leaf, *heap_);
    *link = bigger;
  }
  for (unsigned k = 0; k < depth; ++k) {
    ++path[k]->count;
  }
  ++size_;
}

template <class P>
bool BasicSpatialIndex<P>::locate(Slot slot, double x, double y, Cell* leaf_cell) const noexcept {
  if (root_ == nullptr || !contains(root_cell_, x, y)) {
    return false;
  }
  const Node* node = root_;
  Cell cell = root_cell_;
  while (!node->leaf()) {
    Cell child;
    node = static_cast<const Inner*>(node)->child[child_of(cell, x, y, child)];
    if (node == nullptr) {
      return false;
    }
    cell = child;
  }
  const SpatialEntry* e = entries(node);
  for (std::uint32_t i = 0; i < node->count; ++i) {
    if (e[i].slot == slot && e[i].x == x && e[i].y == y) {
      if (leaf_cell != nullptr) {
        *leaf_cell = cell;
      }
      return true;
    }
  }
  return false;
}

template <class P>
void BasicSpatialIndex<P>::erase_existing(Slot slot, double x, double y) {
  std::array<Node*, kMaxDepth> path;
  unsigned depth = 0;
  Node** link = &root_;
  Cell cell = root_cell_;
  for (;;) {
    *link = own(*link);  // on bad_alloc: same contents, nothing to undo
    if ((*link)->leaf()) {
      break;
    }
    auto* inner = static_cast<Inner*>(*link);
    path[depth++] = inner;
    Cell child;
    link = &inner->child[child_of(cell, x, y, child)];
    cell = child;
  }
  Node* leaf = *link;
  SpatialEntry* e = entries(leaf);
  std::uint32_t i = 0;
  while (!(e[i].slot == slot && e[i].x == x && e[i].y == y)) {
    ++i;
  }
  e[i] = e[--leaf->count];
  if (i == 0) {
    widest_first(leaf);
  }
  for (unsigned k = 0; k < depth; ++k) {
    --path[k]->count;
  }
  --size_;
  shrink(x, y);
}

template <class P>
void BasicSpatialIndex<P>::shrink(double x, double y) noexcept {
  // The highest node on the (owned) path that is an inner node with few entries, or an empty
  // leaf: it becomes one leaf (or nothing).
  Node** link = &root_;
  Cell cell = root_cell_;
  while (*link != nullptr) {
    Node* node = *link;
    if (node->leaf() ? node->count == 0 : node->count <= kLeafCapacity / 2) {
      Node* replacement = nullptr;
      if (node->count > 0 && !node->leaf()) {
        std::array<SpatialEntry, kLeafCapacity / 2> all;
        std::size_t n = 0;
        auto collect = [&](const SpatialEntry& e) { all[n++] = e; };
        for_each_node(node, collect);
        try {
          replacement = build(all.data(), all.data() + n, cell);
        } catch (...) {
          break;  // best effort: the inner node stays, the index is correct as it is
        }
      }
      release(node, *heap_);
      *link = replacement;
      break;
    }
    if (node->leaf()) {
      break;
    }
    Cell child;
    link = &static_cast<Inner*>(node)->child[child_of(cell, x, y, child)];
    cell = child;
  }
  shrink_root();
}

template <class P>
void BasicSpatialIndex<P>::shrink_root() noexcept {
  // The inverse of grow_to, while every entry lies in the central square of 2^-L the side: a
  // leaf root just takes the smaller square; an inner root whose entries all sit in
  // the grandchildren next to the origin is replaced by a root holding those (best effort).
  constexpr unsigned kSide = 1u << kLevelsPerNode;
  constexpr unsigned kHalf = kSide / 2;
  while (root_ != nullptr && root_cell_.level - static_cast<int>(kLevelsPerNode) >= 5) {
    Cell down = root_cell_;
    down.level -= static_cast<int>(kLevelsPerNode);
    down.side /= static_cast<double>(kSide);
    down.x = down.y = -0.5 * down.side;
    if (root_->leaf()) {
      const SpatialEntry* e = entries(root_);
      bool inside = true;
      for (std::uint32_t i = 0; i < root_->count && inside; ++i) {
        inside = contains(down, e[i].x, e[i].y);
      }
      if (!inside) {
        return;
      }
      root_cell_ = down;
      continue;
    }
    auto* top = static_cast<Inner*>(root_);
    for (unsigned i = 0; i < kWidth; ++i) {
      const Node* child = top->child[i];
      if (child == nullptr) {
        continue;
      }
      const unsigned ix = i & (kSide - 1);
      const unsigned iy = i >> kLevelsPerNode;
      const bool central = (ix == kHalf || ix == kHalf - 1) && (iy == kHalf || iy == kHalf - 1);
      if (!central || child->leaf()) {
        return;
      }
      const auto* quadrant = static_cast<const Inner*>(child);
      for (unsigned g = 0; g < kWidth; ++g) {
        const unsigned gx = g & (kSide - 1);
        const unsigned gy = g >> kLevelsPerNode;
        const bool next_to_origin = (ix == kHalf) == (gx < kHalf) && (iy == kHalf) == (gy < kHalf);
        if (quadrant->child[g] != nullptr && !next_to_origin) {
          return;
        }
      }
    }
    Inner* smaller;
    try {
      smaller = make_inner();
    } catch (...) {
      return;  // best effort: the larger root is as correct
    }
    for (unsigned i = 0; i < kWidth; ++i) {
      const auto* quadrant = static_cast<const Inner*>(top->child[i]);
      if (quadrant == nullptr) {
        continue;
      }
      for (unsigned g = 0; g < kWidth; ++g) {
        Node* grandchild = quadrant->child[g];
        if (grandchild == nullptr) {
          continue;
        }
        const unsigned gx = g & (kSide - 1);
        const unsigned gy = g >> kLevelsPerNode;
        const unsigned ox = gx < kHalf ? gx + kHalf : gx - kHalf;
        const unsigned oy = gy < kHalf ? gy + kHalf : gy - kHalf;
        grandchild->refs.acquire();
        smaller->child[oy << kLevelsPerNode | ox] = grandchild;
      }
    }
    smaller->count = top->count;
    release(top, *heap_);
    root_ = smaller;
    root_cell_ = down;
  }
}

template <class P>
void BasicSpatialIndex<P>::erase(Slot slot, double x, double y) {
  if (!locate(slot, x, y, nullptr)) {
    internal::throw_no_entry("erase", slot, x, y);
  }
  erase_existing(slot, x, y);
}

template <class P>
void BasicSpatialIndex<P>::move(Slot slot, double from_x, double from_y, double to_x, double to_y,
                                float extent) {
  check_point(to_x, to_y, "move");
  if (root_ == nullptr || !contains(root_cell_, from_x, from_y)) {
    internal::throw_no_entry("move", slot, from_x, from_y);
  }
  // One descent, owning the path to the leaf that holds `from` (the path any change of this
  // entry owns: an in-place move, or the erase after an insert). Owning replaces a node by an
  // equal copy, so on bad_alloc or when there is no such entry the entries are unchanged.
  Node** link = &root_;
  Cell cell = root_cell_;
  for (;;) {
    *link = own(*link);
    if ((*link)->leaf()) {
      break;
    }
    Cell child;
    Node** next = &static_cast<Inner*>(*link)->child[child_of(cell, from_x, from_y, child)];
    if (*next == nullptr) {
      internal::throw_no_entry("move", slot, from_x, from_y);
    }
    link = next;
    cell = child;
  }
  SpatialEntry* e = entries(*link);
  const std::uint32_t count = (*link)->count;
  std::uint32_t i = 0;
  while (i < count && !(e[i].slot == slot && e[i].x == from_x && e[i].y == from_y)) {
    ++i;
  }
  if (i == count) {
    internal::throw_no_entry("move", slot, from_x, from_y);
  }
  if (contains(cell, to_x, to_y)) {
    e[i].x = to_x;  // same leaf: in place
    e[i].y = to_y;
    e[i].extent = extent;
    if (i == 0) {
      widest_first(*link);
    } else if (wider(extent, e[0].extent)) {
      std::swap(e[0], e[i]);
    }
    return;
  }
  insert(slot, to_x, to_y, extent);
  try {
    erase_existing(slot, from_x, from_y);
  } catch (...) {
    // The path to the new entry is owned (insert made it so): removing it allocates nothing.
    erase_existing(slot, to_x, to_y);
    throw;
  }
}

// ---------------------------------------------------------------------------------------------
// Queries

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
  const double r2 = radius * radius;
  const double prune2 = r2 + r2 * 0x1p-40;  // rounding margin: never prunes an entry within
  if (box_distance2(root_cell_, x, y) > prune2) {
    return;
  }
  // sqrt(prune2) rounds to within an ulp of the pruning radius; the relative 2^-30 covers it.
  const double reach = std::sqrt(prune2) * (1.0 + 0x1p-30);
  within_node(root_, root_cell_, x, y, r2, prune2, reach, AnyReach{}, visit);
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
    const SpatialEntry* e = entries(node);
    for (std::uint32_t i = 0; i < node->count; ++i) {
      for (std::uint64_t bits = active; bits != 0; bits &= bits - 1) {
        const auto k = static_cast<unsigned>(std::countr_zero(bits));
        const double dx = e[i].x - discs[k].x;
        const double dy = e[i].y - discs[k].y;
        const double d2 = dx * dx + dy * dy;
        if (d2 <= discs[k].r2 && !(d2 > reach2(first + k, e[i].extent))) {
          visit(first + k, e[i]);
        }
      }
    }
    return;
  }
  const auto* inner = static_cast<const Inner*>(node);
  for (unsigned i = 0; i < kWidth; ++i) {
    const Node* child = inner->child[i];
    if (child == nullptr) {
      continue;
    }
    const Cell sub = child_cell(cell, i);
    const bool leaf = child->leaf() && child->count != 0;
    std::uint64_t reached = 0;
    for (std::uint64_t bits = active; bits != 0; bits &= bits - 1) {
      const auto k = static_cast<unsigned>(std::countr_zero(bits));
      const double box2 = box_distance2(sub, discs[k].x, discs[k].y);
      if (box2 > discs[k].prune2) {
        continue;
      }
      if (leaf) {
        if (beyond_reach(box2, reach2(first + k, entries(child)[0].extent))) {
          continue;
        }
      }
      reached |= std::uint64_t{1} << k;
    }
    if (reached != 0) {
      within_many_node(child, sub, discs, first, reached, reach2, visit);
    }
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
      bounds[k] = {d.x, d.y, r2, prune2};
      bool in_from = false;
      if (from.node_ != nullptr) {
        const double reach = std::sqrt(prune2) * (1.0 + 0x1p-30);
        const double margin = 0x1p-30 * (std::fabs(d.x) + std::fabs(d.y) + reach);
        in_from = d.x - reach - margin >= from.x_ && d.x + reach + margin < from.x_ + from.side_ &&
                  d.y - reach - margin >= from.y_ && d.y + reach + margin < from.y_ + from.side_;
      }
      if (in_from) {
        inside |= std::uint64_t{1} << k;
      } else if (box_distance2(root_cell_, d.x, d.y) <= prune2) {
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
