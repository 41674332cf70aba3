// The direct C++ side of the front-end overhead benchmark (front_end_overhead.py): reads a log
// into memory, then times one pass of it through engine::Filter, scan by scan: predict for
// every control, observe for every scan, then estimate (pose, covariance, associations, map).
// Prints "seconds S" and the final mean pose as hex floats, which the C and Python drivers must
// match. usage: front_end_cpp LOG PARTICLES SEED
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "engine/filter.h"
#include "tools/io/log_format.h"

int main(int argc, char** argv) {
  using namespace fastslam;
  if (argc != 4) {
    std::fprintf(stderr, "usage: front_end_cpp LOG PARTICLES SEED\n");
    return 2;
  }
  const tools::Log log = tools::read_log(argv[1]);
  engine::FilterConfig config;
  config.motion = log.header.motion;
  config.sensor = log.header.sensor;
  config.particles = static_cast<std::uint32_t>(std::atoi(argv[2]));
  config.seed = std::strtoull(argv[3], nullptr, 10);
  config.threads = 1;
  for (int k = 0; k < 3; ++k) config.initial_pose[k] = log.header.start_pose[k];
  engine::Filter filter(config);
  const auto start = std::chrono::steady_clock::now();
  std::size_t landmarks = 0;
  for (const tools::Event& e : log.events) {
    if (e.kind == tools::EventKind::kControl) {
      filter.predict(e.control, e.dt, e.time);
    } else if (e.kind == tools::EventKind::kScan) {
      filter.observe(std::span<const engine::Observation>(log.observations).subspan(e.first, e.count),
                     e.time);
      landmarks += filter.estimate().map.size();
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const engine::Estimate e = filter.estimate();
  std::printf("seconds %.9f\npose %a %a %a\nlandmarks %zu\n", seconds, e.mean_pose[0],
              e.mean_pose[1], e.mean_pose[2], landmarks);
  return 0;
}
