#include "parallel/particle_kernel.h"

#include <stdexcept>
#include <string>

#include <oneapi/tbb/info.h>

namespace fastslam::parallel {

ParticleKernel::ParticleKernel(KernelConfig config)
    : threads_(config.threads), grain_(config.grain) {
  if (grain_ == 0) {
    throw std::invalid_argument("ParticleKernel: grain must be at least 1");
  }
  if (threads_ > kMaxThreads) {
    throw std::invalid_argument("ParticleKernel: threads = " + std::to_string(threads_) +
                                " exceeds the limit of " + std::to_string(kMaxThreads));
  }
  const auto machine = static_cast<unsigned>(tbb::info::default_concurrency());
  if (threads_ == 0) {
    threads_ = machine > 0 ? machine : 1;
  }
#if FASTSLAM_PARALLEL_TSAN
  // Blocks run on std::threads; TBB algorithms inside execute() stay on the calling thread.
  arena_ = std::make_unique<tbb::task_arena>(1);
#else
  if (threads_ > machine) {
    // Without this the arena would get no more than machine - 1 workers. global_control only
    // raises the limit here (the process-wide value is the smallest of the active ones).
    raise_limit_ = std::make_unique<tbb::global_control>(
        tbb::global_control::max_allowed_parallelism, threads_);
  }
  arena_ = std::make_unique<tbb::task_arena>(static_cast<int>(threads_));
#endif
  arena_->initialize();
}

ParticleKernel::~ParticleKernel() {
  // The arena goes before the limit it relies on.
  arena_.reset();
  raise_limit_.reset();
}

}  // namespace fastslam::parallel
