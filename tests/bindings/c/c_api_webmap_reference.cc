// The reference for c_api_webmap_driver.c: the same log through engine::Filter directly, its
// configuration built as a struct (not through JSON), printed in the driver's exact format.
//
// usage: c_api_webmap_reference LOG ALGORITHM ASSOCIATION PARTICLES SEED THREADS [RELOADED]
// A seventh argument (any) leaves out the counters a reload restarts, as the driver does.
#include <cinttypes>
#include <cstdio>
#include <exception>
#include <span>
#include <string>

#include "engine/enum_names.h"
#include "engine/filter.h"
#include "engine/filter_config.h"
#include "tools/io/log_format.h"

namespace {

using fastslam::engine::Estimate;
using fastslam::engine::Filter;
using fastslam::engine::FilterConfig;

void print_estimate(Filter& filter, unsigned long scan) {
  const Estimate e = filter.estimate();
  std::printf("scan %lu t=%a mean=%a %a %a cov=", scan, e.time, e.mean_pose[0], e.mean_pose[1],
              e.mean_pose[2]);
  for (int i = 0; i < 9; ++i) std::printf("%a%s", e.pose_covariance[i], i < 8 ? "," : "");
  std::printf(" best=%a %a %a particle=%" PRIu32 " ess=%a landmarks=%lu observations=%lu\n",
              e.best_pose[0], e.best_pose[1], e.best_pose[2], e.best_particle,
              e.effective_sample_size, static_cast<unsigned long>(e.map.size()),
              static_cast<unsigned long>(e.associations.size()));
  for (const auto& a : e.associations) {
    std::printf("  z%" PRIu32 " outcome=%" PRId32 " landmark=%" PRIu64 " d2=%a\n", a.observation,
                static_cast<std::int32_t>(a.outcome), a.landmark_id, a.mahalanobis2);
  }
}

void print_map_and_counters(Filter& filter, bool reloaded) {
  const Estimate e = filter.estimate();
  std::printf("map %lu\n", static_cast<unsigned long>(e.map.size()));
  for (const auto& m : e.map) {
    std::printf("  %" PRIu32 " id=%" PRIu64 " %a %a cov=%a,%a,%a log_odds=%a last_seen=%" PRId64
                "\n",
                m.slot, m.id, m.x, m.y, m.sxx, m.sxy, m.syy, m.log_odds, m.last_seen);
  }
  const fastslam::engine::FilterStatistics s = filter.statistics();
  std::printf("controls=%" PRIu64 " scans=%" PRIu64 " observations=%" PRIu64 " resamples=%" PRIu64
              " weight_resets=%" PRIu64 "\n",
              s.controls, s.scans, s.observations, s.resamples, s.weight_resets);
  if (!reloaded) {
    std::printf("created=%" PRIu64 " removed=%" PRIu64 " log_evidence=%a\n", s.landmarks_created,
                s.landmarks_removed, s.log_evidence);
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 7 && argc != 8) {
    std::fprintf(stderr, "usage: %s LOG ALGORITHM ASSOCIATION PARTICLES SEED THREADS [RELOADED]\n",
                 argv[0]);
    return 2;
  }
  try {
    const fastslam::tools::Log log = fastslam::tools::read_log(argv[1]);
    FilterConfig config;
    config.algorithm = fastslam::engine::parse_enum<fastslam::engine::Algorithm>(argv[2]);
    config.association = fastslam::engine::parse_enum<fastslam::engine::Association>(argv[3]);
    config.particles = static_cast<std::uint32_t>(std::stoul(argv[4]));
    config.seed = std::stoull(argv[5]);
    config.threads = static_cast<unsigned>(std::stoul(argv[6]));
    config.motion = log.header.motion;
    config.sensor = log.header.sensor;
    for (int i = 0; i < 3; ++i) config.initial_pose[i] = log.header.start_pose[i];
    Filter filter(config);
    unsigned long scans = 0;
    for (const fastslam::tools::Event& event : log.events) {
      if (event.kind == fastslam::tools::EventKind::kControl) {
        filter.predict(event.control, event.dt, event.time);
      } else if (event.kind == fastslam::tools::EventKind::kScan) {
        filter.observe(std::span(log.observations).subspan(event.first, event.count), event.time);
        print_estimate(filter, scans++);
      }
    }
    print_map_and_counters(filter, argc == 8);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "c_api_webmap_reference: %s\n", e.what());
    return 1;
  }
  return 0;
}
