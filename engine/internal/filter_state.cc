#include "engine/internal/filter_state.h"

#include <cmath>

namespace fastslam::engine::internal {

memory::StoreOptions store_options(const FilterConfig& c) {
  memory::StoreOptions o;
  o.indexing =
      c.association == Association::kKnown ? memory::Indexing::kNone : memory::Indexing::kSpatial;
  if (c.algorithm == Algorithm::kFastSlam2) {
    o.pose_covariance = without_odometry(c.motion.kind) ? memory::PoseCovariance::kCarried
                                                        : memory::PoseCovariance::kScratch;
  }
  return o;
}

FilterState::FilterState(const FilterConfig& c)
    : config(c), store(c.particles, heap, store_options(c)), covariances(store),
      sensor(c.sensor.offset) {
  r << c.sensor.sigma_range * c.sensor.sigma_range, 0, 0,
      c.sensor.sigma_bearing * c.sensor.sigma_bearing;
  const double log_m = -std::log(static_cast<double>(c.particles));
  double* columns[5] = {store.x().data(), store.y().data(), store.theta().data(), store.v().data(),
                        store.omega().data()};
  for (std::uint32_t i = 0; i < c.particles; ++i) {
    for (int k = 0; k < 5; ++k) columns[k][i] = c.initial_pose[k];
    store.log_weight()[i] = log_m;
  }
}

}  // namespace fastslam::engine::internal
