#include "memory/particle_store.h"

#include <algorithm>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <utility>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#if defined(__SANITIZE_THREAD__)
#define FASTSLAM_MEMORY_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define FASTSLAM_MEMORY_TSAN 1
#endif
#endif
#if defined(FASTSLAM_MEMORY_TSAN)
#include <atomic>
#include <thread>
#include <vector>

#include <oneapi/tbb/task_arena.h>
#endif

namespace fastslam::memory {
namespace {

// Calls body(begin, end) over [0, m) in blocks of `grain`, in parallel: TBB in the caller's
// arena; under ThreadSanitizer on plain std::threads (as many as the caller's arena has),
// because Debian's libtbb is not instrumented and TSan would report TBB's own task hand-offs
// as races in our code (google/sanitizers#1004; parallel/internal/thread_fork_join.h).
// `body` must not throw. A single block runs inline: a resampling of a small filter then costs
// no parallel_for setup (twice per resampling).
template <class Body>
void for_blocks(std::size_t m, std::size_t grain, const Body& body) {
  if (m <= grain) {
    if (m > 0) body(0, m);
    return;
  }
#if defined(FASTSLAM_MEMORY_TSAN)
  const std::size_t blocks = (m + grain - 1) / grain;
  const std::size_t threads =
      std::min<std::size_t>(blocks, std::max(1, tbb::this_task_arena::max_concurrency()));
  std::atomic<std::size_t> next{0};
  auto worker = [&] {
    for (std::size_t b = next.fetch_add(1); b < blocks; b = next.fetch_add(1)) {
      body(b * grain, std::min(m, (b + 1) * grain));
    }
  };
  std::vector<std::thread> pool;
  for (std::size_t t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (std::thread& thread : pool) thread.join();
#else
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m, grain),
                    [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
#endif
}

}  // namespace

ParticleStore::ParticleStore(std::size_t particles, NodeHeap& heap, StoreOptions options)
    : heap_(&heap),
      options_(options),
      x_(particles, 0.0),
      y_(particles, 0.0),
      theta_(particles, 0.0),
      v_(particles, 0.0),
      omega_(particles, 0.0),
      log_weight_(particles, 0.0),
      pose_cov_(options.pose_covariance == PoseCovariance::kNone ? 0 : particles * kPoseCovStride,
                0.0),
      maps_(particles, ParticleMap(heap, options.indexing)) {}

void ParticleStore::append(std::size_t count) {
  const std::size_t m = size() + count;
  for (Column* c : {&x_, &y_, &theta_, &v_, &omega_, &log_weight_}) c->resize(m, 0.0);
  if (options_.pose_covariance != PoseCovariance::kNone) pose_cov_.resize(m * kPoseCovStride, 0.0);
  maps_.resize(m, ParticleMap(*heap_, options_.indexing));
}

void ParticleStore::gather(std::span<const std::uint32_t> index, std::size_t grain) {
  const std::size_t from_size = size();
  const std::size_t m = index.size();
  if (m > kNoChild) {
    throw std::length_error("ParticleStore::gather: " + std::to_string(m) +
                            " outputs exceed the 32-bit index limit");
  }
  // Each input's first output takes its map by a move; the others copy it (bumping the roots'
  // counts), and an input with no output releases its map. A family of one, the common case,
  // then costs no count change at all. One serial pass finds the first outputs (and checks the
  // indices: what may throw comes before anything changes).
  first_child_.assign(from_size, kNoChild);
  for (std::size_t k = 0; k < m; ++k) {
    const std::uint32_t i = index[k];
    if (i >= from_size) {
      throw std::invalid_argument("ParticleStore::gather: index[" + std::to_string(k) +
                                  "] = " + std::to_string(i) + " is not below the particle count " +
                                  std::to_string(from_size));
    }
    if (first_child_[i] == kNoChild) first_child_[i] = static_cast<std::uint32_t>(k);
  }
  Column nx(m), ny(m), ntheta(m), nv(m), nomega(m), nlog_weight(m);
  const bool carried = options_.pose_covariance == PoseCovariance::kCarried;
  if (carried) pose_cov_spare_.resize(m * kPoseCovStride);
  double* const ncov = pose_cov_spare_.data();
  if (options_.pose_covariance == PoseCovariance::kScratch) pose_cov_.reserve(m * kPoseCovStride);
  // Every entry of the spare is an empty map (the previous gather emptied the maps it held).
  maps_spare_.resize(m, empty_map());
  if (grain == 0) grain = 1;
  const std::uint32_t* const first = first_child_.data();
  try {
    for_blocks(m, grain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t k = begin; k != end; ++k) {
        const std::uint32_t i = index[k];
        nx[k] = x_[i];
        ny[k] = y_[i];
        ntheta[k] = theta_[i];
        nv[k] = v_[i];
        nomega[k] = omega_[i];
        nlog_weight[k] = log_weight_[i];
        if (carried) {
          std::copy_n(&pose_cov_[std::size_t{i} * kPoseCovStride], kPoseCovStride,
                      &ncov[k * kPoseCovStride]);
        }
        if (first[i] != k) maps_spare_[k] = maps_[i];
      }
    });
  } catch (...) {  // only the thread pool's own failures: the loop's body does not throw
    for (ParticleMap& map : maps_spare_) map.clear();
    throw;
  }
  x_.swap(nx);
  y_.swap(ny);
  theta_.swap(ntheta);
  v_.swap(nv);
  omega_.swap(nomega);
  log_weight_.swap(nlog_weight);
  if (carried) {
    pose_cov_.swap(pose_cov_spare_);
  } else if (options_.pose_covariance == PoseCovariance::kScratch) {
    pose_cov_.resize(m * kPoseCovStride, 0.0);
  }
  // Input j's map is touched by its first output's move or, when it has none, by its release:
  // by one task either way. Trees no output holds are freed here, in parallel.
  for_blocks(std::max(m, from_size), grain, [&](std::size_t begin, std::size_t end) {
    for (std::size_t j = begin; j != end; ++j) {
      if (j < from_size && first[j] == kNoChild) maps_[j].clear();
      if (j < m && first[index[j]] == j) maps_spare_[j] = std::move(maps_[index[j]]);
    }
  });
  maps_.swap(maps_spare_);
}

}  // namespace fastslam::memory
