// Uses the installed headers and libraries: a persistent map shared and changed, and a FastSLAM
// 2.0 filter driven through the Filter API around one landmark.
#include <cmath>
#include <cstdio>
#include <vector>

#include "engine/filter.h"
#include "memory/landmark_tree.h"
#include "memory/node_heap.h"

int main() {
  fastslam::memory::MallocHeap heap;
  {
    fastslam::memory::LandmarkTree map(heap);
    for (int i = 0; i < 100; ++i) map.insert({.x = static_cast<double>(i)});
    fastslam::memory::LandmarkTree copy = map;
    copy.edit(42).x = -1.0;
    if (map.at(42).x != 42.0 || copy.at(42).x != -1.0 || copy.size() != 100) {
      std::puts("consumer: wrong map contents");
      return 1;
    }
  }
  if (heap.stats().live_nodes != 0) {
    std::puts("consumer: leaked nodes");
    return 1;
  }

  fastslam::engine::FilterConfig config;
  config.algorithm = fastslam::engine::Algorithm::kFastSlam2;
  config.particles = 20;
  config.threads = 2;
  fastslam::engine::Filter filter(config);
  // Drive straight at 1 m/s past a landmark at (10, 5), observing it exactly each second.
  for (int t = 1; t <= 8; ++t) {
    filter.predict({1.0, 0.0}, 1.0);
    const double dx = 10.0 - t;
    const double dy = 5.0;
    const std::vector<fastslam::engine::Observation> scan = {
        {std::hypot(dx, dy), std::atan2(dy, dx), 0}};
    filter.observe(scan);
  }
  const fastslam::engine::Estimate e = filter.estimate();
  if (e.map.size() != 1 || std::hypot(e.map[0].x - 10.0, e.map[0].y - 5.0) > 3.0) {
    std::puts("consumer: the filter did not map the landmark");
    return 1;
  }
  std::printf("consumer: ok (landmark at %.2f, %.2f)\n", e.map[0].x, e.map[0].y);
  return 0;
}
