// The landmark map of one particle: a persistent, reference-counted radix tree over slots (dense
// indices), 2^kInnerBits children per inner node, 2^kLeafBits landmarks inline per leaf. A copy
// shares every node; a change copies the root-to-leaf path of its slot (nodes this map holds
// alone are changed in place). Slots are stable for a landmark's life: insert takes the lowest
// free slot, iteration is in slot order. Design and the fanout's choice: docs/memory.md.
// Ownership: borrows its NodeHeap, which must outlive the tree and every copy of it.
// Thread safety: thread-compatible; handles sharing nodes may be used from any threads at once
// (atomic counts, shared nodes never written).
// Costs (N landmarks, h = O(log N)): copy, move, size O(1); find, at O(h); edit, set, insert_at
// O(h) with up to h + 1 allocations (insert_at: h of the slot's tree); insert, erase
// O(h 2^kInnerBits); diff O(nodes not shared); freeing is iterative and frees exactly the nodes
// no other map holds.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <iterator>

#include "memory/node_heap.h"
#include "memory/refcount.h"

namespace fastslam::memory {

// One landmark of one particle: a 2-D Gaussian, its existence log-odds, and the bookkeeping the
// engine tracks it by. 64 bytes, trivially copyable.
struct Landmark {
  double x = 0.0;  // mean
  double y = 0.0;
  double sxx = 0.0;  // covariance (symmetric 2x2: xx, xy, yy)
  double sxy = 0.0;
  double syy = 0.0;
  double log_odds = 0.0;       // existence (ALGORITHM.md, eq. 73-75)
  std::uint64_t id = 0;        // identity set by the engine, stable across copies
  std::int64_t last_seen = 0;  // step of the last association
  friend bool operator==(const Landmark&, const Landmark&) = default;
};
static_assert(sizeof(Landmark) == 64);

using Slot = std::uint32_t;

// A memory policy bundle (as immer's memory_policy): the shape and the counting.
template <unsigned InnerBits, unsigned LeafBits, class Refcount>
struct TreePolicy {
  static constexpr unsigned kInnerBits = InnerBits;
  static constexpr unsigned kLeafBits = LeafBits;
  using RefcountType = Refcount;
};

// The default: 16-way inner nodes, 4 landmarks per leaf (docs/memory.md says why).
using DefaultTreePolicy = TreePolicy<4, 2, AtomicRefcount>;

template <class Policy>
class BasicLandmarkTree {
 public:
  static constexpr unsigned kInnerBits = Policy::kInnerBits;
  static constexpr unsigned kLeafBits = Policy::kLeafBits;
  static constexpr unsigned kInnerWidth = 1u << kInnerBits;
  static constexpr unsigned kLeafWidth = 1u << kLeafBits;
  static_assert(kInnerBits >= 1 && kInnerBits <= 8 && kLeafBits <= 5);
  // Height of a tree whose capacity covers every 32-bit slot.
  static constexpr unsigned kMaxHeight = (32 - kLeafBits + kInnerBits - 1) / kInnerBits;

  // An empty map whose nodes will come from `heap`.
  explicit BasicLandmarkTree(NodeHeap& heap) noexcept : heap_(&heap) {}
  BasicLandmarkTree(const BasicLandmarkTree& other) noexcept;
  BasicLandmarkTree(BasicLandmarkTree&& other) noexcept;
  BasicLandmarkTree& operator=(const BasicLandmarkTree& other) noexcept;
  BasicLandmarkTree& operator=(BasicLandmarkTree&& other) noexcept;
  ~BasicLandmarkTree();

  std::size_t size() const noexcept { return size_; }
  bool empty() const noexcept { return size_ == 0; }
  // Slots [0, capacity()) are addressable without growing the tree.
  std::uint64_t capacity() const noexcept;
  unsigned height() const noexcept { return height_; }
  NodeHeap& heap() const noexcept { return *heap_; }
  // True when both handles hold the very same root (a copy not yet changed).
  bool shares_root_with(const BasicLandmarkTree& other) const noexcept {
    return root_ == other.root_;
  }

  // The landmark in `slot`, or nullptr when the slot is empty or beyond capacity.
  const Landmark* find(Slot slot) const noexcept;
  bool contains(Slot slot) const noexcept { return find(slot) != nullptr; }
  // The landmark in `slot`. Throws std::out_of_range naming the slot when it holds none.
  const Landmark& at(Slot slot) const;

  // A writable reference to the landmark in `slot`, after copying the shared nodes on its path.
  // The reference is valid until the next mutation, copy or destruction of this handle.
  // Throws std::out_of_range when the slot holds no landmark (and changes nothing), or
  // std::bad_alloc (the map then still holds the same landmarks).
  Landmark& edit(Slot slot);
  void set(Slot slot, const Landmark& landmark) { edit(slot) = landmark; }

  // Stores `landmark` in the lowest free slot and returns it. Throws std::bad_alloc or
  // std::length_error (2^32 slots) and then leaves the map's contents unchanged.
  Slot insert(const Landmark& landmark);

  // Stores `landmark` in the empty `slot`, growing the tree to cover it (a loader rebuilding a
  // map with holes, without filling and erasing them). Throws std::invalid_argument naming the
  // slot when it holds a landmark, or std::bad_alloc; either way the contents are unchanged.
  void insert_at(Slot slot, const Landmark& landmark);

  // Removes the landmark in `slot`. Throws std::out_of_range when the slot holds none (for
  // example, erased already) and changes nothing.
  void erase(Slot slot);

  // Removes every landmark (releases this handle's reference to the root).
  void clear() noexcept;

  // visit(slot, mine, theirs) for every slot where this tree and `other` differ: a landmark in
  // one only (the other's pointer null) or unequal landmarks, in increasing slot order. Shared
  // subtrees are skipped unvisited, so two maps that differ by a scan's updates cost those
  // paths, not their size. Each pair of nodes compared takes one step of `steps`; when none is
  // left the walk stops and diff returns false (a caller bounding its work by its input's
  // size). `visit` must not change either tree.
  template <class Visit>
  bool diff(const BasicLandmarkTree& other, Visit&& visit,
            std::uint64_t& steps) const;
  template <class Visit>
  void diff(const BasicLandmarkTree& other, Visit&& visit) const {
    std::uint64_t unbounded = ~std::uint64_t{0};
    diff(other, visit, unbounded);
  }

  // Ordered iteration over (slot, landmark), in increasing slot order.
  struct Entry {
    Slot slot;
    const Landmark& landmark;
  };
  class Iterator;
  Iterator begin() const noexcept;
  Iterator end() const noexcept;

 private:
  // Writes and rebuilds trees node by node, sharing included (memory/tree_graph.h).
  template <class>
  friend class BasicTreeGraphWriter;
  template <class>
  friend class BasicTreeGraphReader;
  template <class>
  friend class BasicNodeRegistry;

  using Refcount = typename Policy::RefcountType;
  struct Node {
    Node() = default;
    // A copy starts with one reference (the copier's) and the same contents.
    Node(const Node& other) noexcept : aux(other.aux) {}
    Node& operator=(const Node&) = delete;
    mutable Refcount refs;
    // Inner: landmarks in the subtree. Leaf: occupancy bit mask of `landmarks`.
    std::uint32_t aux = 0;
  };
  struct Inner : Node {
    Node* child[kInnerWidth] = {};
  };
  struct Leaf : Node {
    Landmark landmarks[kLeafWidth];
  };

  static std::uint64_t capacity_at(unsigned height) noexcept {
    return std::uint64_t{kLeafWidth} << (kInnerBits * height);
  }
  static unsigned child_index(Slot slot, unsigned height) noexcept {
    return (slot >> (kLeafBits + kInnerBits * (height - 1))) & (kInnerWidth - 1);
  }
  static std::uint32_t live_of(const Node* node, unsigned height) noexcept;

  // A node from the heap, constructed from `args` (nothing, or the node to copy).
  template <class T, class... Args>
  T* make(Args&&... args);
  // Path copying, the one primitive every mutation goes through: returns a node equal to
  // `node` (of the given height) that this map owns alone. A null node becomes an empty one; a
  // uniquely held node is returned as is; a shared node is copied (its children gain a
  // reference) and the map's reference to the original is dropped.
  Node* own(Node* node, unsigned height);
  // Drops one reference to `node`; frees it and, iteratively, every descendant that no other
  // map holds.
  static void release(Node* node, unsigned height, NodeHeap& heap) noexcept;
  static void free_node(Node* node, unsigned height, NodeHeap& heap) noexcept;

  // Owns the path to `slot` (creating empty nodes where there are none) and fills `path` with
  // the inner nodes from the root down; returns the leaf.
  Leaf* own_path(Slot slot, std::array<Inner*, kMaxHeight>& path);
  // Frees the empty nodes on the (owned) path to `slot` and removes needless top levels.
  void prune(Slot slot) noexcept;
  // The lowest free slot below capacity(), or capacity() when the tree is full.
  std::uint64_t lowest_free_slot() const noexcept;
  // diff's walk over two subtrees covering slots from `base` (null: no landmarks there).
  template <class Visit>
  static bool diff_nodes(const Node* a, unsigned height_a, const Node* b, unsigned height_b,
                         std::uint64_t base, Visit& visit, std::uint64_t& steps);

  Node* root_ = nullptr;
  NodeHeap* heap_;
  std::uint32_t height_ = 0;  // inner levels above the leaves
  std::uint32_t size_ = 0;
};

template <class Policy>
class BasicLandmarkTree<Policy>::Iterator {
 public:
  using iterator_category = std::forward_iterator_tag;
  using value_type = Entry;
  using difference_type = std::ptrdiff_t;
  using reference = Entry;

  Iterator() = default;
  Entry operator*() const noexcept { return {slot_, leaf_->landmarks[slot_ & (kLeafWidth - 1)]}; }
  Iterator& operator++() noexcept;
  Iterator operator++(int) noexcept {
    Iterator before = *this;
    ++*this;
    return before;
  }
  friend bool operator==(const Iterator& a, const Iterator& b) noexcept {
    return a.leaf_ == b.leaf_ && (a.leaf_ == nullptr || a.slot_ == b.slot_);
  }

 private:
  friend class BasicLandmarkTree;
  // Moves to the first landmark at or after `from` (slot) or to end().
  void seek(std::uint64_t from) noexcept;

  const Node* root_ = nullptr;
  unsigned height_ = 0;
  const Leaf* leaf_ = nullptr;  // null at end()
  Slot slot_ = 0;
};

using LandmarkTree = BasicLandmarkTree<DefaultTreePolicy>;

extern template class BasicLandmarkTree<DefaultTreePolicy>;
extern template class BasicLandmarkTree<TreePolicy<4, 2, LocalRefcount>>;

}  // namespace fastslam::memory

#include "memory/internal/landmark_tree_impl.h"
