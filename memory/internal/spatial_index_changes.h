// Template definitions of memory/spatial_index.h, part 2: changes (insert, erase, move) with
// the root's growth and shrinking and the merging of sparse subtrees. Not API: include
// memory/spatial_index.h instead.
#pragma once

#include <algorithm>
#include <array>
#include <cstring>
#include <vector>

#include "memory/internal/spatial_index_nodes.h"

namespace fastslam::memory {

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
  MoveFinger finger(*this);
  finger.move(slot, from_x, from_y, to_x, to_y, extent);
}

template <class P>
void BasicSpatialIndex<P>::MoveFinger::move(Slot slot, double from_x, double from_y, double to_x,
                                            double to_y, float extent) {
  BasicSpatialIndex& index = *index_;
  check_point(to_x, to_y, "move");
  if (index.root_ == nullptr || !contains(index.root_cell_, from_x, from_y)) {
    internal::throw_no_entry("move", slot, from_x, from_y);
  }
  // Where to start: the deepest recorded node whose square holds `from`, when the recorded
  // path down to it is still owned (a copy of the index made meanwhile shares it); else the
  // root. One descent from there owns the path to the leaf that holds `from` (the path any
  // change of this entry owns: an in-place move, or the erase after an insert). Owning
  // replaces a node by an equal copy, so on bad_alloc or when there is no such entry the
  // entries are unchanged (and the path recorded so far is owned).
  unsigned level = 0;
  if (depth_ != 0 && path_[0] == index.root_) {
    level = depth_ - 1;
    while (level > 0 && !contains(cells_[level], from_x, from_y)) {
      --level;
    }
    for (unsigned k = 0; k <= level; ++k) {
      if (!path_[k]->refs.unique()) {
        level = 0;
        depth_ = 0;
        break;
      }
    }
  } else {
    depth_ = 0;
  }
  Node* node;
  Cell cell;
  if (depth_ == 0) {
    node = index.root_ = index.own(index.root_);
    cell = index.root_cell_;
    path_[0] = node;
    cells_[0] = cell;
  } else {
    node = path_[level];
    cell = cells_[level];
  }
  depth_ = level + 1;
  while (!node->leaf()) {
    Cell child;
    Node** link = &static_cast<Inner*>(node)->child[child_of(cell, from_x, from_y, child)];
    if (*link == nullptr) {
      internal::throw_no_entry("move", slot, from_x, from_y);
    }
    node = *link = index.own(*link);
    cell = child;
    if (depth_ < kDepth) {
      path_[depth_] = node;
      cells_[depth_] = cell;
      ++depth_;
    }
  }
  SpatialEntry* e = entries(node);
  const std::uint32_t count = node->count;
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
      widest_first(node);
    } else if (wider(extent, e[0].extent)) {
      std::swap(e[0], e[i]);
    }
    return;
  }
  depth_ = 0;  // the shape changes
  index.insert(slot, to_x, to_y, extent);
  try {
    index.erase_existing(slot, from_x, from_y);
  } catch (...) {
    // The path to the new entry is owned (insert made it so): removing it allocates nothing.
    index.erase_existing(slot, to_x, to_y);
    throw;
  }
}

}  // namespace fastslam::memory
