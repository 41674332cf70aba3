// Template definitions of memory/spatial_index.h, part 1: handles (copy, move, destruction),
// cell geometry and node lifetime (allocation, path copying, release, bulk build). Not API:
// include memory/spatial_index.h instead.
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <new>
#include <utility>

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
auto BasicSpatialIndex<P>::copy_shared(Node* node) -> Node* {
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

}  // namespace fastslam::memory
