// The spatial index of one particle's map: a persistent bucketed region quadtree over (slot,
// x, y, extent) entries, answering "entries within distance d" (also in batches, and pruned by
// each entry's reach), "entries in a sensor footprint" and "k nearest" exactly. Copies share
// nodes and changes copy paths, as the landmark tree (memory/landmark_tree.h); node squares
// are aligned powers of two, so their boundaries are exact doubles. Design: docs/spatial-index.md.
// Coordinates finite, |x|, |y| <= kMaxCoordinate; distances are compared squared, in double as
// written. The index does not check that a slot is entered once (memory/particle_map.h keeps
// one entry per landmark).
// Ownership: borrows its NodeHeap, which must outlive it and every copy; visitors are borrowed
// for the call. Thread safety: thread-compatible; handles sharing nodes may be used from any
// threads at once; a visitor must not change the index it visits.
// Costs (N entries, h = O(log N), B = kLeafCapacity, W = 4^kLevelsPerNode): copy O(1);
// within, within_reach, in_footprint O(h + k + boxes touched), nearest O(h + k log k)
// typically, no allocation; insert O(h + B) plus a split; erase O(h + B) plus a merge
// (O(B W)), never failing once it started changing; move as erase + insert (in place within a
// leaf). Changes allocate path copies and split nodes only.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>

#include "memory/landmark_tree.h"  // Slot
#include "memory/node_heap.h"
#include "memory/refcount.h"

namespace fastslam::memory {

// One entry of the index: a landmark's slot and where the index stores it.
struct SpatialEntry {
  Slot slot = 0;
  // A number the caller keeps with the entry and gets back from queries (it fills the padding
  // after the slot: free). The index reads it only to keep each leaf's widest entry (largest
  // extent; NaN counts as widest) first, for within_reach. The engine keeps the landmark's
  // largest covariance eigenvalue there, so that candidates can be gated without a map lookup.
  float extent = 0.0f;
  double x = 0.0;
  double y = 0.0;
  friend bool operator==(const SpatialEntry&, const SpatialEntry&) = default;
};

// The shape and counting of an index (as TreePolicy for the landmark tree).
template <unsigned LevelsPerNode, unsigned LeafCapacity, class Refcount>
struct SpatialPolicy {
  static constexpr unsigned kLevelsPerNode = LevelsPerNode;
  static constexpr unsigned kLeafCapacity = LeafCapacity;
  using RefcountType = Refcount;
};

// The default: 4-way nodes, leaves of 16 entries (docs/spatial-index.md says why).
using DefaultSpatialPolicy = SpatialPolicy<1, 16, AtomicRefcount>;

template <class Policy>
class BasicSpatialIndex {
 public:
  static constexpr unsigned kLevelsPerNode = Policy::kLevelsPerNode;
  static constexpr unsigned kWidth = 1u << (2 * kLevelsPerNode);  // children per inner node
  static constexpr unsigned kLeafCapacity = Policy::kLeafCapacity;
  static_assert(kLevelsPerNode >= 1 && kLevelsPerNode <= 3);
  static_assert(kLeafCapacity >= 2 && kLeafCapacity <= 256);
  // Finest cell side: 2^kMinLevel metres.
  static constexpr int kMinLevel = -12;
  // Entries one leaf at the finest size may hold (points closer than the finest cell).
  static constexpr std::uint32_t kMaxLeafEntries = 1u << 20;
  static constexpr double kMaxCoordinate = 1e150;
  // Nodes on a root-to-leaf path, at most: root squares stay below 2^505 m (coordinates are
  // below 2^499), leaves at least 2^kMinLevel.
  static constexpr unsigned kMaxDepth = (505 - kMinLevel) / kLevelsPerNode + 2;

  // An empty index whose nodes will come from `heap`.
  explicit BasicSpatialIndex(NodeHeap& heap) noexcept : heap_(&heap) {}
  BasicSpatialIndex(const BasicSpatialIndex& other) noexcept;
  BasicSpatialIndex(BasicSpatialIndex&& other) noexcept;
  BasicSpatialIndex& operator=(const BasicSpatialIndex& other) noexcept;
  BasicSpatialIndex& operator=(BasicSpatialIndex&& other) noexcept;
  ~BasicSpatialIndex();

  std::size_t size() const noexcept { return size_; }
  bool empty() const noexcept { return size_ == 0; }
  NodeHeap& heap() const noexcept { return *heap_; }
  // True when both handles hold the very same root (a copy not yet changed).
  bool shares_root_with(const BasicSpatialIndex& other) const noexcept {
    return root_ == other.root_;
  }

  // Adds (slot, x, y) with `extent`. Throws std::invalid_argument when x or y is not finite
  // or exceeds kMaxCoordinate in magnitude, std::length_error when a finest-size leaf is full, or
  // std::bad_alloc; then the index holds the same entries as before.
  void insert(Slot slot, double x, double y, float extent = 0.0f);

  // Removes the entry (slot, x, y): `x, y` is the position it is stored at, compared exactly.
  // Throws std::out_of_range when there is no such entry, or std::bad_alloc; then the index
  // holds the same entries as before.
  void erase(Slot slot, double from_x, double from_y);

  // Moves the entry (slot, from) to `to`, where it holds `extent`. Throws as erase (no such
  // entry) and insert (bad `to`, bad_alloc); then the index holds the same entries as before.
  void move(Slot slot, double from_x, double from_y, double to_x, double to_y, float extent = 0.0f);

  // Moves of entries that lie near each other, in a row (a scan's updated landmarks); declared
  // at the end of the class.
  class MoveFinger;

  // Removes every entry (releases this handle's reference to the root).
  void clear() noexcept;

  // visit(const SpatialEntry&) for every entry within `radius` of (x, y) (see the file comment
  // for "within"), in no particular order. REQUIRES: arguments finite, radius >= 0.
  template <class Visit>
  void within(double x, double y, double radius, Visit&& visit) const;

  // A node of this index with its square, to start disc queries from (see `covering`). It
  // borrows the node: valid until this index is next changed, copied over or destroyed.
  class Subtree {
   public:
    Subtree() = default;
    bool empty() const noexcept { return node_ == nullptr; }
    // Side of the node's square in metres (0 when empty).
    double side() const noexcept { return side_; }

   private:
    friend class BasicSpatialIndex;
    const void* node_ = nullptr;
    double x_ = 0.0;  // the square: corner (x_, y_), side side_ = 2^level_
    double y_ = 0.0;
    double side_ = 0.0;
    int level_ = 0;
  };

  // The deepest node whose square holds the box [min_x, max_x] x [min_y, max_y] (one descent
  // from the root); empty when the index is empty or the box is not inside the root's square.
  // A scan's candidate discs all lie near the sensor, so one descent per scan replaces one per
  // disc query. REQUIRES: arguments finite, min <= max.
  Subtree covering(double min_x, double min_y, double max_x, double max_y) const noexcept;

  // As within(x, y, radius, visit), with the same entries in the same order, but descending
  // from `from` (a result of covering() on this unchanged index) when the disc, with its
  // rounding margin, lies inside its square; otherwise from the root.
  template <class Visit>
  void within(const Subtree& from, double x, double y, double radius, Visit&& visit) const;

  // As within(from, x, y, radius, visit), restricted to the entries whose own reach covers
  // (x, y): visit(e) for every entry with d2 <= radius^2 and !(d2 > reach2(e.extent)), where
  // d2 = (e.x - x)^2 + (e.y - y)^2 as for within, in no particular order. `reach2(float)` is a
  // squared distance, non-decreasing in the extent, and NaN or above every other value for a
  // NaN extent (NaN reaches everywhere, as !(d2 > NaN) says). A leaf whose
  // square lies farther than its widest entry's reach is skipped whole, which is the gain when
  // most extents are far below the one that sized `radius` (the engine's candidate discs: a
  // radius from the map-wide variance bound, a reach from each landmark's own).
  template <class Reach2, class Visit>
  void within_reach(const Subtree& from, double x, double y, double radius, const Reach2& reach2,
                    Visit&& visit) const;

  // A disc of a batch query: centre and radius (finite, radius >= 0).
  struct Disc {
    double x = 0.0;
    double y = 0.0;
    double radius = 0.0;
  };
  // Many within_reach queries in one descent: visit(k, e) for every k < discs.size() and every
  // entry e that within_reach(from, discs[k].x, discs[k].y, discs[k].radius,
  // [&](float extent) { return reach2(k, extent); }, ...) visits, in no particular order (the
  // queries' hits interleave). A scan's discs share most of their nodes and leaves, so this
  // loads each once instead of once per disc. REQUIRES: reach2(k, extent) as within_reach's.
  template <class Reach2, class Visit>
  void within_reach(const Subtree& from, std::span<const Disc> discs, const Reach2& reach2,
                    Visit&& visit) const;

  // visit(const SpatialEntry&) for every entry inside the sensor footprint of a sensor at
  // (x, y) facing `heading` (radians): within `max_range`, and with a bearing off the heading
  // by at most field_of_view / 2: |remainder(atan2(ey - y, ex - x) - heading, 2 pi)| <=
  // field_of_view / 2. An entry at the sensor's own position is inside. field_of_view >= 2 pi
  // is the whole disc. REQUIRES: arguments finite, max_range >= 0, field_of_view >= 0.
  template <class Visit>
  void in_footprint(double x, double y, double heading, double max_range, double field_of_view,
                    Visit&& visit) const;

  // The min(k, out.size(), size()) entries nearest to (x, y), written to `out` in increasing
  // distance (ties in any order); returns how many. REQUIRES: x, y finite.
  std::size_t nearest(double x, double y, std::size_t k, std::span<SpatialEntry> out) const;

  // visit(const SpatialEntry&) for every entry, in no particular order.
  template <class Visit>
  void for_each(Visit&& visit) const;

  // Introspection for tests and diagnostics: visit(const void* node) for each node on the path
  // from the root to the node whose square holds (x, y) (a leaf, or an inner node with no child
  // there). Nothing when the index is empty or (x, y) lies outside the root's square.
  template <class Visit>
  void for_each_path_node(double x, double y, Visit&& visit) const;
  // Levels of nodes from the root to the deepest leaf (0 when empty).
  unsigned depth() const noexcept;

 private:
  using Refcount = typename Policy::RefcountType;
  // The 16-byte header of every node. Once the count dropped to zero the node belongs to the
  // thread that freed it, which reuses the count's bytes to chain the nodes still to be freed.
  struct Node {
    explicit Node(std::uint32_t leaf_capacity) noexcept : refs(), capacity(leaf_capacity) {}
    union {
      Refcount refs;
      Node* next_dead;
    };
    std::uint32_t count = 0;  // entries in the subtree (a leaf: entries stored)
    std::uint32_t capacity;   // 0: inner node; else entries the leaf has room for
    bool leaf() const noexcept { return capacity != 0; }
  };
  static_assert(sizeof(Node) == 16);
  static_assert(sizeof(SpatialEntry) == 24, "extent must stay in the slot's padding");
  struct Inner : Node {
    Inner() noexcept : Node(0) {}
    Node* child[kWidth] = {};
  };
  // A square: corner (x, y), side 2^level.
  struct Cell {
    double x;
    double y;
    double side;
    int level;
  };

  static SpatialEntry* entries(Node* leaf) noexcept {
    return reinterpret_cast<SpatialEntry*>(reinterpret_cast<std::byte*>(leaf) + sizeof(Node));
  }
  static const SpatialEntry* entries(const Node* leaf) noexcept {
    return reinterpret_cast<const SpatialEntry*>(reinterpret_cast<const std::byte*>(leaf) +
                                                 sizeof(Node));
  }
  static std::size_t leaf_bytes(std::uint32_t capacity) noexcept {
    return sizeof(Node) + std::size_t{capacity} * sizeof(SpatialEntry);
  }
  [[gnu::always_inline]] static bool contains(const Cell& cell, double x, double y) noexcept {
    return x >= cell.x && x < cell.x + cell.side && y >= cell.y && y < cell.y + cell.side;
  }
  // The child of `cell` holding (x, y), and its index; exact comparisons against boundaries.
  // Always inlined: it runs once per level of every descent.
  [[gnu::always_inline]] static inline unsigned child_of(const Cell& cell, double x, double y,
                                                         Cell& child) noexcept;
  [[gnu::always_inline]] static inline Cell child_cell(const Cell& cell, unsigned index) noexcept;
  // Whether a leaf of `cell` may split (children at least kMinLevel, boundaries exact).
  static bool can_split(const Cell& cell) noexcept;
  // Squared distance from (x, y) to the square, never more than to any point inside it.
  [[gnu::always_inline]] static inline double box_distance2(const Cell& cell, double x,
                                                            double y) noexcept;
  static void check_point(double x, double y, const char* operation);

  Node* make_leaf(std::uint32_t capacity);
  Inner* make_inner();
  // A node equal to `node` that this index holds alone (see the landmark tree's `own`): the node
  // itself when unique (inlined: every level of every change asks), else copy_shared's copy.
  [[gnu::always_inline]] Node* own(Node* node) {
    return node->refs.unique() ? node : copy_shared(node);
  }
  Node* copy_shared(Node* node);
  static void release(Node* node, NodeHeap& heap) noexcept;
  static void free_node(Node* node, NodeHeap& heap) noexcept;
  // A subtree for `cell` holding entries [first, last) (which it reorders); splits as needed.
  Node* build(SpatialEntry* first, SpatialEntry* last, const Cell& cell);
  // Grows the root square until it holds (x, y); may allocate (a new root and four quadrant
  // nodes per step); on bad_alloc the index is as before the failed step.
  void grow_to(double x, double y);
  // Index of (slot, x, y) in the leaf whose square holds (x, y), with that leaf's square, or
  // false. Read-only.
  bool locate(Slot slot, double x, double y, Cell* leaf_cell) const noexcept;
  // Removes the located entry (slot, x, y), which must exist; owns the path first (may throw
  // bad_alloc before any change), then changes nothing that can fail.
  void erase_existing(Slot slot, double x, double y);
  // Merges the highest inner node on the path to (x, y) that holds kLeafCapacity / 2 entries or
  // fewer into one leaf (best effort: skipped when the leaf cannot be allocated), then
  // shrink_root. The path must be owned.
  void shrink(double x, double y) noexcept;
  // Halves the root square (by 2^kLevelsPerNode) while every entry lies in the smaller one.
  void shrink_root() noexcept;

  // `reach`: a radius at least the query's plus every rounding margin; only the children the
  // square of half-side `reach` around (x, y) overlaps are tested. `reach2`: AnyReach for
  // within(), else within_reach()'s per-entry bound.
  struct AnyReach {};
  template <class Reach2, class Visit>
  static void within_node(const Node* node, const Cell& cell, double x, double y, double r2,
                          double prune2, double reach, const Reach2& reach2, Visit& visit);
  // The batch query's discs below `node` whose bit is set in `active` (at most 64 at a time):
  // each disc's centre, squared radius and pruning bound, and the square [lo_x, hi_x] x
  // [lo_y, hi_y] that holds every entry the disc can hit (half-side `reach` plus the rounding
  // margin). An inner node passes each child the discs whose square overlaps the child's: two
  // comparisons per disc and axis against the exact boundaries between the children, no
  // distance per child; the exact box test runs at the leaves.
  struct DiscBounds {
    double x;
    double y;
    double r2;
    double prune2;
    double lo_x;
    double hi_x;
    double lo_y;
    double hi_y;
  };
  template <class Reach2, class Visit>
  static void within_many_node(const Node* node, const Cell& cell, const DiscBounds* discs,
                               std::size_t first, std::uint64_t active, const Reach2& reach2,
                               Visit& visit);
  // Whether a leaf at squared distance box2 is out of reach of all its entries, given its widest
  // (first) entry's reach2: with the pruning's rounding margin, as within_node's box test.
  static bool beyond_reach(double box2, double widest2) noexcept {
    return box2 > widest2 + std::fabs(widest2) * 0x1p-40;
  }
  // Whether extent a ranks before b in a leaf (larger; NaN before any number).
  static bool wider(float a, float b) noexcept { return a > b || (a != a && b == b); }
  // Puts the leaf's widest entry first (O(count)), after any change but an append.
  static void widest_first(Node* leaf) noexcept;
  // The same after appending one entry to a leaf whose widest entry was first (O(1)).
  static void appended(Node* leaf) noexcept;
  template <class Visit>
  static void for_each_node(const Node* node, Visit& visit);
  struct Best;  // nearest(): the running k best, a max-heap on distance
  static void nearest_node(const Node* node, const Cell& cell, Best& best) noexcept;

  Node* root_ = nullptr;
  NodeHeap* heap_;
  Cell root_cell_{0.0, 0.0, 1.0, 0};
  std::size_t size_ = 0;

 public:
  // A run of moves in one index: each move(...) is the index's move(...) (same entries, same
  // exceptions and guarantee), but descends from the deepest node of the previous move's path
  // whose square holds the entry, when every node above it is still this index's alone,
  // instead of from the root: for a scan's landmarks, which lie near each other, a move then
  // owns and tests a few levels, not the whole path. A move that changes the index's shape (the
  // entry leaves its leaf) forgets the path.
  // It borrows the index: while it is used, the index changes only through it (it may be
  // copied meanwhile: a shared path is owned again). Not thread-safe; no allocation of its own
  // (the path is kept inline, 2 KB).
  class MoveFinger {
   public:
    explicit MoveFinger(BasicSpatialIndex& index) noexcept : index_(&index) {}
    MoveFinger(const MoveFinger&) = delete;
    MoveFinger& operator=(const MoveFinger&) = delete;

    void move(Slot slot, double from_x, double from_y, double to_x, double to_y,
              float extent = 0.0f);

   private:
    // Levels kept: deeper ones are not recorded (a later move starts from the deepest kept).
    static constexpr unsigned kDepth = 48;
    BasicSpatialIndex* index_;
    unsigned depth_ = 0;  // path_[0 .. depth_) from the root, each node owned when recorded
    std::array<Node*, kDepth> path_;
    std::array<Cell, kDepth> cells_;
  };
};

using SpatialIndex = BasicSpatialIndex<DefaultSpatialPolicy>;

extern template class BasicSpatialIndex<SpatialPolicy<1, 8, AtomicRefcount>>;
extern template class BasicSpatialIndex<SpatialPolicy<1, 16, AtomicRefcount>>;
extern template class BasicSpatialIndex<SpatialPolicy<2, 8, AtomicRefcount>>;
extern template class BasicSpatialIndex<SpatialPolicy<2, 16, AtomicRefcount>>;
extern template class BasicSpatialIndex<SpatialPolicy<1, 8, LocalRefcount>>;

}  // namespace fastslam::memory

#include "memory/internal/spatial_index_changes.h"
#include "memory/internal/spatial_index_nodes.h"
#include "memory/internal/spatial_index_queries.h"
