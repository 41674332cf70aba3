#include "memory/spatial_index.h"

#include <sstream>
#include <stdexcept>
#include <string>

namespace fastslam::memory {
namespace internal {

namespace {
std::string position(double x, double y) {
  std::ostringstream text;
  text.precision(17);
  text << "(" << x << ", " << y << ")";
  return text.str();
}
}  // namespace

void throw_bad_position(const char* operation, double x, double y) {
  throw std::invalid_argument("SpatialIndex::" + std::string(operation) + ": position " +
                              position(x, y) +
                              " is not finite or exceeds 1e150 in magnitude");
}

void throw_no_entry(const char* operation, Slot slot, double x, double y) {
  throw std::out_of_range("SpatialIndex::" + std::string(operation) + ": no entry for slot " +
                          std::to_string(slot) + " at " + position(x, y));
}

void throw_leaf_full(Slot slot, double x, double y) {
  throw std::length_error("SpatialIndex::insert: slot " + std::to_string(slot) + " at " +
                          position(x, y) +
                          ": more than 2^20 entries within the finest cell (0.24 mm)");
}

}  // namespace internal

template class BasicSpatialIndex<SpatialPolicy<1, 8, AtomicRefcount>>;
template class BasicSpatialIndex<SpatialPolicy<1, 16, AtomicRefcount>>;
template class BasicSpatialIndex<SpatialPolicy<2, 8, AtomicRefcount>>;
template class BasicSpatialIndex<SpatialPolicy<2, 16, AtomicRefcount>>;
template class BasicSpatialIndex<SpatialPolicy<1, 8, LocalRefcount>>;

}  // namespace fastslam::memory
