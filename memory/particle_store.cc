#include "memory/particle_store.h"

#include <algorithm>
#include <cstddef>
#include <memory>
#include <new>
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
  for (std::size_t k = 0; k < index.size(); ++k) {
    if (index[k] >= from_size) {
      throw std::invalid_argument("ParticleStore::gather: index[" + std::to_string(k) +
                                  "] = " + std::to_string(index[k]) +
                                  " is not below the particle count " + std::to_string(from_size));
    }
  }
  const std::size_t m = index.size();
  Column nx(m), ny(m), ntheta(m), nv(m), nomega(m), nlog_weight(m);
  const bool carried = options_.pose_covariance == PoseCovariance::kCarried;
  if (carried) pose_cov_spare_.resize(m * kPoseCovStride);
  double* const ncov = pose_cov_spare_.data();
  // The survivors' maps, made in the first parallel loop and moved out in the second, in raw
  // blocks: one allocation per gather as large as all the maps would be handed back to the
  // system by the allocator and fault in fresh pages every time; making (or even marking) every
  // slot here, one by one, was a sequential part of each resampling. `made` says which exist,
  // so that an exception from the thread pool leaks none.
  constexpr std::size_t kMapBlock = 8192;
  struct alignas(ParticleMap) MapSlot {
    std::byte bytes[sizeof(ParticleMap)];
  };
  std::vector<std::unique_ptr<MapSlot[]>> survivors((m + kMapBlock - 1) / kMapBlock);
  for (std::unique_ptr<MapSlot[]>& block : survivors) {
    block = std::make_unique_for_overwrite<MapSlot[]>(kMapBlock);
  }
  std::vector<unsigned char> made(m, 0);
  auto slot = [&](std::size_t k) { return survivors[k / kMapBlock][k % kMapBlock].bytes; };
  auto survivor = [&](std::size_t k) {
    return std::launder(reinterpret_cast<ParticleMap*>(slot(k)));
  };
  auto unmake = [&] {
    for (std::size_t k = 0; k < m; ++k) {
      if (made[k] != 0) survivor(k)->~ParticleMap();
    }
  };
  if (grain == 0) grain = 1;
  // What may throw comes before the first survivor is made (so no reallocation below).
  if (options_.pose_covariance == PoseCovariance::kScratch) pose_cov_.reserve(m * kPoseCovStride);
  maps_.reserve(m);
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
        ::new (slot(k)) ParticleMap(maps_[i]);  // bumps the roots' counts
        made[k] = 1;
      }
    });
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
    // The old maps each drop one reference as the survivors replace them (trees no survivor
    // shares are freed there), in parallel; maps beyond the new count are released first.
    if (m < from_size) {
      for_blocks(from_size - m, grain, [&](std::size_t begin, std::size_t end) {
        for (std::size_t k = begin; k != end; ++k) maps_[m + k].clear();
      });
    }
    maps_.resize(m, empty_map());
    for_blocks(m, grain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t k = begin; k != end; ++k) {
        maps_[k] = std::move(*survivor(k));
        survivor(k)->~ParticleMap();
        made[k] = 0;
      }
    });
  } catch (...) {  // only the thread pool's own failures: the loops' bodies do not throw
    unmake();
    throw;
  }
}

}  // namespace fastslam::memory
