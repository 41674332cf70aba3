// Uses the installed headers and libraries: a persistent map shared and changed, keyed random
// streams and a FastSLAM 2.0 filter driven through the Filter API around one landmark. Prints
// the random-stream kernels in use ("isa: ...") and a digest of the streams' and the filter's
// bits ("digest: ..."), which tests/install/run_install_test.cmake compares across runs on
// every kernel copy and emulated CPU: they must all be equal.
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <fastslam/engine/filter.h>
#include <fastslam/memory/landmark_tree.h>
#include <fastslam/memory/node_heap.h>
#include <fastslam/parallel/random_stream.h>

namespace {

// FNV-1a over the bits of the values.
class Digest {
 public:
  void add(double v) {
    const auto bits = std::bit_cast<std::uint64_t>(v);
    for (int i = 0; i < 8; ++i) {
      hash_ = (hash_ ^ ((bits >> (8 * i)) & 0xFFu)) * 0x100000001b3u;
    }
  }
  void add(const std::vector<double>& values) {
    for (const double v : values) add(v);
  }
  std::uint64_t value() const { return hash_; }

 private:
  std::uint64_t hash_ = 0xcbf29ce484222325u;
};

}  // namespace

int main() {
  namespace parallel = fastslam::parallel;
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

  // Every batch entry point, at sizes that use the kernels' wide chunks and their tails.
  Digest digest;
  std::vector<double> normals(53 * 5);
  parallel::normals_for_particles(7, 3, parallel::Purpose::kProposal, 11, 53, 5, normals);
  digest.add(normals);
  std::vector<double> uniforms(41 * 4);
  parallel::uniforms_for_particles(7, 3, parallel::Purpose::kResample, 0, 41, 4, uniforms);
  digest.add(uniforms);
  const std::vector<std::uint64_t> steps = {1, 2, 0xFFFFFFFFu};
  std::vector<double> first(3 * 77);
  std::vector<double> second(3 * 77);
  parallel::normal_pairs_for_particles(9, steps, parallel::Purpose::kMotion, 5, 77, first, second,
                                       77);
  digest.add(first);
  digest.add(second);
  parallel::RandomStream stream({.seed = 1, .step = 2, .particle = 3});
  std::vector<double> filled(99);
  stream.fill_normal(filled);
  digest.add(filled);
  stream.fill_uniform(filled);
  digest.add(filled);

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
  for (const double v : e.mean_pose) digest.add(v);
  digest.add(e.effective_sample_size);
  digest.add(e.map[0].x);
  digest.add(e.map[0].y);
  std::printf("isa: %s\n", std::string(parallel::random_stream_isa()).c_str());
  std::printf("digest: %016llx\n", static_cast<unsigned long long>(digest.value()));
  std::printf("consumer: ok (landmark at %.2f, %.2f)\n", e.map[0].x, e.map[0].y);
  return 0;
}
