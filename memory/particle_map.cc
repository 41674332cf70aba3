#include "memory/particle_map.h"

#include <stdexcept>

namespace fastslam::memory {

Slot ParticleMap::insert(const Landmark& landmark, float extent) {
  const Slot slot = tree_.insert(landmark);
  if (indexed_) {
    try {
      index_.insert(slot, landmark.x, landmark.y, extent);
    } catch (...) {
      tree_.erase(slot);  // the path to `slot` is owned: allocates nothing
      throw;
    }
  }
  return slot;
}

Landmark& ParticleMap::edit_unindexed(Slot slot) {
  if (indexed_) {
    throw std::logic_error("ParticleMap::edit_unindexed: the map is indexed; use update");
  }
  return tree_.edit(slot);
}

void ParticleMap::erase(Slot slot) {
  // Owning the landmark's path first (may throw, changes nothing) leaves the tree's erase
  // nothing to allocate, so it cannot fail after the index entry is gone.
  if (indexed_) {
    const Landmark& landmark = tree_.edit(slot);
    index_.erase(slot, landmark.x, landmark.y);
  }
  tree_.erase(slot);
}

}  // namespace fastslam::memory
