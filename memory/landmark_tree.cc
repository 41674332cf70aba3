#include "memory/landmark_tree.h"

#include <stdexcept>
#include <string>

namespace fastslam::memory {
namespace internal {

void throw_empty_slot(Slot slot, std::size_t capacity, const char* operation) {
  std::string what = "LandmarkTree::" + std::string(operation) + ": slot " + std::to_string(slot);
  what += slot >= capacity ? " is out of range (capacity " + std::to_string(capacity) + ")"
                           : " holds no landmark (never inserted, or erased)";
  throw std::out_of_range(what);
}

void throw_held_slot(Slot slot, const char* operation) {
  throw std::invalid_argument("LandmarkTree::" + std::string(operation) + ": slot " +
                              std::to_string(slot) + " holds a landmark already");
}

}  // namespace internal

template class BasicLandmarkTree<DefaultTreePolicy>;
template class BasicLandmarkTree<TreePolicy<4, 2, LocalRefcount>>;

}  // namespace fastslam::memory
