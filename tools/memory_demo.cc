#include "tools/memory_demo.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/info.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/particle_store.h"
#include "parallel/random_stream.h"

namespace fastslam::tools {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

double mib(std::int64_t bytes) { return static_cast<double>(bytes) / (1024.0 * 1024.0); }

}  // namespace

int run_memory_demo(const MemoryDemoOptions& options) {
  const int threads = options.threads > 0 ? options.threads : tbb::info::default_concurrency();
  tbb::task_arena arena(threads);
  memory::PoolHeap heap;
  const std::uint64_t n = options.landmarks;
  const std::uint32_t m = options.particles;

  std::printf("memory-demo: N = %llu landmarks, M = %u particles, %u steps, K = %u updates per "
              "particle per step, %d threads\n",
              static_cast<unsigned long long>(n), m, options.steps, options.updates_per_step,
              threads);

  nlohmann::json metrics;
  {
    auto start = Clock::now();
    memory::LandmarkTree base(heap);
    for (std::uint64_t i = 0; i < n; ++i) {
      base.insert({.x = static_cast<double>(i % 1000), .y = static_cast<double>(i / 1000),
                   .sxx = 1.0, .syy = 1.0, .log_odds = 1.0, .id = i});
    }
    const memory::HeapStats one_map = heap.stats();
    const double build_seconds = seconds_since(start);
    std::printf("  built one map: %.1f MiB in %lld nodes, %.3f s\n", mib(one_map.live_bytes),
                static_cast<long long>(one_map.live_nodes), build_seconds);

    memory::ParticleStore store(m, heap);
    memory::ParticleMap base_map(std::move(base), memory::Indexing::kNone,
                                 [](const memory::Landmark&) { return 0.0f; });
    for (std::uint32_t i = 0; i < m; ++i) store.map(i) = base_map;
    base_map.clear();

    std::vector<std::uint32_t> index(m);
    std::int64_t peak_bytes = 0;
    double update_seconds = 0.0;
    double resample_seconds = 0.0;
    for (std::uint32_t step = 0; step < options.steps; ++step) {
      auto t0 = Clock::now();
      arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, m, 8),
                          [&](const tbb::blocked_range<std::uint32_t>& r) {
                            for (std::uint32_t p = r.begin(); p != r.end(); ++p) {
                              parallel::RandomStream rng(
                                  {options.seed, step, p, parallel::Purpose::kUser});
                              memory::ParticleMap& map = store.map(p);
                              for (std::uint32_t k = 0; k < options.updates_per_step; ++k) {
                                const auto slot = static_cast<memory::Slot>(rng.next_u64() % n);
                                memory::Landmark& landmark = map.edit_unindexed(slot);
                                landmark.x += 0.01 * rng.normal();
                                landmark.last_seen = step;
                              }
                            }
                          });
      });
      auto t1 = Clock::now();
      parallel::RandomStream pick({options.seed, step, 0, parallel::Purpose::kResample});
      for (std::uint32_t k = 0; k < m; ++k) index[k] = pick.next_u32() % m;
      arena.execute([&] { store.gather(index, 8); });
      update_seconds += std::chrono::duration<double>(t1 - t0).count();
      resample_seconds += seconds_since(t1);
      peak_bytes = std::max(peak_bytes, heap.stats().live_bytes);
    }
    const memory::HeapStats final_stats = heap.stats();
    const double linear_bytes = static_cast<double>(n) * sizeof(memory::Landmark) * m;
    const double updates = static_cast<double>(options.steps) * m * options.updates_per_step;
    std::printf("  live after %u steps: %.1f MiB in %lld nodes (%.2fx one map; the linear "
                "baseline, a whole map per particle, holds %.1f MiB: %.0fx more)\n",
                options.steps, mib(final_stats.live_bytes),
                static_cast<long long>(final_stats.live_nodes),
                static_cast<double>(final_stats.live_bytes) / one_map.live_bytes,
                linear_bytes / (1024.0 * 1024.0), linear_bytes / final_stats.live_bytes);
    std::printf("  %.0f ns per landmark update (path copy), %.3f ms per resampling gather\n",
                updates > 0 ? 1e9 * update_seconds / updates : 0.0,
                1e3 * resample_seconds / options.steps);
    metrics = {{"landmarks", n},
               {"particles", m},
               {"steps", options.steps},
               {"updates_per_step", options.updates_per_step},
               {"seed", options.seed},
               {"threads", threads},
               {"one_map_bytes", one_map.live_bytes},
               {"live_bytes", final_stats.live_bytes},
               {"live_nodes", final_stats.live_nodes},
               {"peak_live_bytes", peak_bytes},
               {"linear_baseline_bytes", linear_bytes},
               {"seconds_per_update", updates > 0 ? update_seconds / updates : 0.0},
               {"seconds_per_gather", resample_seconds / options.steps},
               {"build_seconds", build_seconds}};
  }
  const memory::HeapStats after = heap.stats();
  if (after.live_nodes != 0) {
    throw std::logic_error("memory-demo: " + std::to_string(after.live_nodes) +
                           " nodes still live after every map was released");
  }
  std::printf("  all maps released: 0 live nodes\n");
  if (!options.out.empty()) {
    std::filesystem::create_directories(options.out);
    const std::string path = options.out + "/metrics.json";
    std::ofstream file(path);
    file << metrics.dump(2) << '\n';
    if (!file) throw std::runtime_error("cannot write " + path);
    std::printf("  wrote %s\n", path.c_str());
  }
  return 0;
}

}  // namespace fastslam::tools
