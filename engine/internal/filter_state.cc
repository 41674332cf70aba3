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

namespace {

parallel::ParticleShare share_of(const FilterConfig& c, parallel::Collective* group) {
  if (group == nullptr) return {0, c.particles};
  return parallel::particle_share(c.particles, group->size(), group->rank());
}

}  // namespace

FilterState::FilterState(const FilterConfig& c, parallel::Collective* g)
    : FilterState(c, g, share_of(c, g)) {}

FilterState::FilterState(const FilterConfig& c, parallel::Collective* g,
                         parallel::ParticleShare share)
    : config(c), group(g), first_particle(static_cast<std::uint32_t>(share.first)),
      links(g == nullptr ? nullptr : std::make_unique<NodeLinks>(heap, g->rank(), g->size())),
      store(share.count, heap, store_options(c)), covariances(store), sensor(c.sensor.offset) {
  r << c.sensor.sigma_range * c.sensor.sigma_range, 0, 0,
      c.sensor.sigma_bearing * c.sensor.sigma_bearing;
  const double log_m = -std::log(static_cast<double>(c.particles));
  double* columns[5] = {store.x().data(), store.y().data(), store.theta().data(), store.v().data(),
                        store.omega().data()};
  for (std::size_t i = 0; i < store.size(); ++i) {
    for (int k = 0; k < 5; ++k) columns[k][i] = c.initial_pose[k];
    store.log_weight()[i] = log_m;
  }
}

}  // namespace fastslam::engine::internal
