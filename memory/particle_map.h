// The map of one particle: its landmark tree and, when indexed, the spatial index over the
// landmarks' means, changed together so that the index holds exactly one entry per landmark, at
// the landmark's (x, y) (the invariant this type owns).
// The indexing is chosen once, at construction: `Indexing::kSpatial` for data association by
// search, `Indexing::kNone` (known ids: only the tree, no index cost) otherwise. Copies share
// nodes as the tree and index do (O(1)); a copy keeps the mode.
// Ownership: borrows its `NodeHeap`, which must outlive it and every copy. Callables passed to
// a call are borrowed for that call.
// Thread safety: thread-compatible, as LandmarkTree and SpatialIndex: maps that share nodes
// may be used from different threads at once.
// Costs (N landmarks, h = O(log N)): copy O(1); queries as the tree's and index's; insert,
// update, erase O(h) in the tree plus, when indexed, the index's insert / move / erase (moved
// only when the mean changed); they allocate only path copies and index nodes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <utility>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/spatial_index.h"

namespace fastslam::memory {

enum class Indexing { kNone, kSpatial };

class ParticleMap {
 public:
  // An empty map whose nodes come from `heap`.
  ParticleMap(NodeHeap& heap, Indexing indexing) noexcept
      : tree_(heap), index_(heap), indexed_(indexing == Indexing::kSpatial) {}
  // The map of `tree`'s landmarks; when indexed, each gets the extent extent_of(landmark),
  // entered in slot order. Throws as SpatialIndex::insert.
  template <class ExtentOf>
  ParticleMap(LandmarkTree tree, Indexing indexing, const ExtentOf& extent_of);
  // The map of `tree`'s landmarks, in `near`'s indexing, its index `near`'s (shared) changed by
  // the landmarks where the two trees differ (LandmarkTree::diff): a map read back beside
  // others it shares most of its landmarks with shares most of its index too, in O(differing
  // paths). The entries are those the constructor above makes: same slots, positions and
  // extents. Each node pair compared and each entry changed takes a step of `steps`; throws
  // std::length_error when they run out (a loader bounding its work by its input). REQUIRES:
  // both on the same heap. Throws as SpatialIndex::insert.
  template <class ExtentOf>
  ParticleMap(LandmarkTree tree, const ParticleMap& near, const ExtentOf& extent_of,
              std::uint64_t& steps);

  Indexing indexing() const noexcept { return indexed_ ? Indexing::kSpatial : Indexing::kNone; }
  bool indexed() const noexcept { return indexed_; }
  NodeHeap& heap() const noexcept { return tree_.heap(); }

  // Read access. The index is empty when the map is not indexed.
  const LandmarkTree& tree() const noexcept { return tree_; }
  const SpatialIndex& index() const noexcept { return index_; }
  std::size_t size() const noexcept { return tree_.size(); }
  bool empty() const noexcept { return tree_.empty(); }
  const Landmark* find(Slot slot) const noexcept { return tree_.find(slot); }
  const Landmark& at(Slot slot) const { return tree_.at(slot); }
  LandmarkTree::Iterator begin() const noexcept { return tree_.begin(); }
  LandmarkTree::Iterator end() const noexcept { return tree_.end(); }
  // True when both maps hold the very same tree and index (a copy not yet changed).
  bool shares_root_with(const ParticleMap& other) const noexcept {
    return tree_.shares_root_with(other.tree_) && index_.shares_root_with(other.index_);
  }

  // Stores `landmark` in the lowest free slot (LandmarkTree::insert) and, when indexed, enters
  // it in the index at (x, y) with `extent`. Throws as those two; then the map is unchanged.
  Slot insert(const Landmark& landmark, float extent);

  // change(Landmark&) on a copy of the landmark in `slot`, which is then stored; when indexed
  // and its x or y changed, the index entry moves there with extent extent_of(landmark) (not
  // called otherwise, so an entry keeps its extent while its mean stays). Throws
  // std::out_of_range (no landmark in `slot`), what `change` throws, or as SpatialIndex::move;
  // then the map is unchanged.
  template <class Change, class ExtentOf>
  void update(Slot slot, Change&& change, const ExtentOf& extent_of);

  // update(slots[k], change_k, extent_of) for k = 0, 1, ... in turn, where change_k(landmark)
  // is change(k, landmark): the index moves share their descents (SpatialIndex::MoveFinger),
  // which is the gain when the landmarks lie near each other (a scan's). `change` must not use
  // the map (nor copy it: the run's path is this map's alone until it returns). Throws as update;
  // then the landmarks before the failing one are updated, it and those after unchanged.
  template <class Change, class ExtentOf>
  void update_each(std::span<const Slot> slots, Change&& change, const ExtentOf& extent_of);

  // The landmark in `slot`, writable in place (LandmarkTree::edit), for maps without an index,
  // where nothing else depends on it. Throws std::logic_error when the map is indexed.
  Landmark& edit_unindexed(Slot slot);

  // Removes the landmark in `slot` and its index entry. Throws std::out_of_range when the slot
  // holds none, or std::bad_alloc; then the map is unchanged.
  void erase(Slot slot);

  // Removes every landmark (drops this map's references).
  void clear() noexcept {
    tree_.clear();
    index_.clear();
  }

 private:
  LandmarkTree tree_;
  SpatialIndex index_;
  bool indexed_;
};

template <class ExtentOf>
ParticleMap::ParticleMap(LandmarkTree tree, Indexing indexing, const ExtentOf& extent_of)
    : tree_(std::move(tree)), index_(tree_.heap()), indexed_(indexing == Indexing::kSpatial) {
  if (indexed_) {
    for (const auto [slot, landmark] : tree_) {
      index_.insert(slot, landmark.x, landmark.y, extent_of(landmark));
    }
  }
}

template <class ExtentOf>
ParticleMap::ParticleMap(LandmarkTree tree, const ParticleMap& near, const ExtentOf& extent_of,
                         std::uint64_t& steps)
    : tree_(std::move(tree)), index_(near.index_), indexed_(near.indexed_) {
  if (!indexed_) return;
  const auto change = [&](Slot slot, const Landmark* mine, const Landmark* theirs) {
    if (steps == 0) throw std::length_error("ParticleMap: the maps differ by more than allowed");
    --steps;
    if (theirs == nullptr) {
      index_.insert(slot, mine->x, mine->y, extent_of(*mine));
    } else if (mine == nullptr) {
      index_.erase(slot, theirs->x, theirs->y);
    } else if (mine->x != theirs->x || mine->y != theirs->y ||
               extent_of(*mine) != extent_of(*theirs)) {
      index_.move(slot, theirs->x, theirs->y, mine->x, mine->y, extent_of(*mine));
    }
  };
  if (!tree_.diff(near.tree_, change, steps)) {
    throw std::length_error("ParticleMap: the maps differ by more than allowed");
  }
}

template <class Change, class ExtentOf>
void ParticleMap::update(Slot slot, Change&& change, const ExtentOf& extent_of) {
  // Owning the path first (an equal copy) and changing a copy keeps the map as it was when
  // the change or the index move throws.
  Landmark& stored = tree_.edit(slot);
  Landmark next = stored;
  change(next);
  if (indexed_ && (next.x != stored.x || next.y != stored.y)) {
    index_.move(slot, stored.x, stored.y, next.x, next.y, extent_of(next));
  }
  stored = next;
}

template <class Change, class ExtentOf>
void ParticleMap::update_each(std::span<const Slot> slots, Change&& change,
                              const ExtentOf& extent_of) {
  SpatialIndex::MoveFinger finger(index_);
  for (std::size_t k = 0; k < slots.size(); ++k) {
    Landmark& stored = tree_.edit(slots[k]);
    Landmark next = stored;
    change(k, next);
    if (indexed_ && (next.x != stored.x || next.y != stored.y)) {
      finger.move(slots[k], stored.x, stored.y, next.x, next.y, extent_of(next));
    }
    stored = next;
  }
}

}  // namespace fastslam::memory
