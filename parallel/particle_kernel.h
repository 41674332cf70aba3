// The per-particle kernel: the one way the engine runs "for every particle do X" in parallel.
// It owns a tbb::task_arena of `threads` slots and cuts work into blocks of `grain` particles:
// for_each_block (optionally with per-thread ThreadScratch), for_each_fixed_block, a
// deterministic reduce (fixed blocks of kReduceBlock folded left to right: the same bits for
// any thread count and grain), execute (a TBB algorithm inside the arena) and BackgroundTask.
// Small inputs and one-thread kernels run inline. Under ThreadSanitizer the blocks run on plain
// std::threads (internal/thread_fork_join.h). Design notes: docs/parallel.md.
// Ownership: owns its arena (and may raise TBB's worker limit for its lifetime, never lower
// it); bodies are borrowed for the call.
// Thread safety: thread-safe (const calls from several threads share the arena). A body runs
// concurrently on disjoint ranges through one const reference and must write only its own
// range, per-thread scratch or atomics; when a body throws, the call rethrows one exception
// after the running blocks finished.
// Costs: a parallel call is one arena entry plus one task per grain (O(count / grain)); inline
// calls cost only the body; reduce allocates ceil(count / kReduceBlock) results.
#pragma once

#include <algorithm>
#include <concepts>
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/cache_aligned_allocator.h>
#include <oneapi/tbb/enumerable_thread_specific.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/partitioner.h>
#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/task_group.h>

#include "parallel/internal/thread_fork_join.h"

#if defined(__SANITIZE_THREAD__)
#define FASTSLAM_PARALLEL_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define FASTSLAM_PARALLEL_TSAN 1
#endif
#endif
#ifndef FASTSLAM_PARALLEL_TSAN
#define FASTSLAM_PARALLEL_TSAN 0
#endif

namespace fastslam::parallel {

// The filter's parallel configuration.
struct KernelConfig {
  // Threads the kernel may use, the caller included. 0: the machine's default concurrency
  // (tbb::info::default_concurrency(), which honours the process's CPU affinity mask).
  unsigned threads = 0;
  // Particles per task (>= 1). Smaller grains balance better and cost more scheduling; the
  // default suits phases of nanoseconds per particle such as resampling (docs/parallel.md);
  // phases costing microseconds per particle want smaller grains (pass one per call).
  std::size_t grain = 512;
};

// What the bodies must provide. Each is called through a const reference, concurrently from
// several threads, on disjoint ranges.
// body(begin, end): handles particles [begin, end).
template <class F>
concept BlockBody = std::invocable<const F&, std::size_t, std::size_t>;
// body(begin, end, scratch): the same, with the calling thread's scratch.
template <class F, class Scratch>
concept ScratchBlockBody = std::invocable<const F&, std::size_t, std::size_t, Scratch&>;
// body(block_index, begin, end): handles fixed block `block_index` = particles [begin, end).
template <class F>
concept IndexedBlockBody = std::invocable<const F&, std::size_t, std::size_t, std::size_t>;
// body(particle): handles one particle.
template <class F>
concept ParticleBody = std::invocable<const F&, std::size_t>;
// map_block(begin, end) -> T: the partial result of particles [begin, end).
template <class F, class T>
concept BlockMap = std::invocable<const F&, std::size_t, std::size_t> &&
    std::convertible_to<std::invoke_result_t<const F&, std::size_t, std::size_t>, T>;
// combine(a, b) -> T: joins two partial results, `a` covering particles before `b`'s. Called on
// the calling thread only; need not be associative (the fold order is fixed).
template <class F, class T>
concept Combiner = std::invocable<F&, const T&, const T&> &&
    std::convertible_to<std::invoke_result_t<F&, const T&, const T&>, T>;

// Per-thread scratch that lives across kernel calls: `local()` returns the calling thread's
// element, default-constructed (or copied from the exemplar) on the thread's first use.
// Elements sit on distinct cache lines. Under TSan builds each call's threads are new, so there
// may be one element per call and thread; code must not assume a bound on size(). TSan builds
// take the elements from malloc, which TSan intercepts: memory TBB's allocator hands from one
// filter's threads to another's would read to it as a race.
template <class Scratch>
class ThreadScratch {
 public:
  ThreadScratch() = default;
  explicit ThreadScratch(const Scratch& exemplar) : elements_(exemplar) {}

  // The calling thread's element. Thread-safe; the element is this thread's alone.
  Scratch& local() { return elements_.local(); }
  // Visits every element created so far. REQUIRES: no kernel call using this scratch runs.
  template <class F>
  void for_each(F&& f) {
    for (Scratch& element : elements_) {
      f(element);
    }
  }
  std::size_t size() const { return elements_.size(); }
  // Drops every element. REQUIRES: no kernel call using this scratch runs.
  void clear() { elements_.clear(); }

 private:
  using Allocator = std::conditional_t<FASTSLAM_PARALLEL_TSAN != 0, std::allocator<Scratch>,
                                       tbb::cache_aligned_allocator<Scratch>>;
  tbb::enumerable_thread_specific<Scratch, Allocator, tbb::ets_key_per_instance> elements_;
};

class ParticleKernel {
 public:
  // Fixed block size of `reduce` (and of the weight scans in resample.h): part of the result's
  // definition, so it never depends on the configuration.
  static constexpr std::size_t kReduceBlock = 256;

  // Throws std::invalid_argument when grain is 0 or threads exceeds kMaxThreads.
  explicit ParticleKernel(KernelConfig config = {});
  ParticleKernel(const ParticleKernel&) = delete;
  ParticleKernel& operator=(const ParticleKernel&) = delete;
  ~ParticleKernel();

  static constexpr unsigned kMaxThreads = 4096;

  unsigned threads() const noexcept { return threads_; }
  std::size_t grain() const noexcept { return grain_; }

  // Runs f() inside the kernel's arena and returns its result: TBB algorithms inside use at
  // most threads() threads. Under TSan builds the arena has one slot (see the file comment).
  template <class F>
  decltype(auto) execute(F&& f) const {
    return arena_->execute(std::forward<F>(f));
  }

  // Every loop below takes an optional `grain` (particles per task) for this call only; 0 means
  // the kernel's grain(). Cheap bodies (a few ns per particle) want grains of thousands, heavy
  // ones (microseconds per particle) grains of a few particles.

  // body(begin, end) on the chunks [j * g, min((j + 1) * g, count)), g = the grain, in parallel.
  template <BlockBody Body>
  void for_each_block(std::size_t count, const Body& body, std::size_t grain = 0) const {
    const std::size_t g = grain_or_default(grain);
    run_tasks(chunks(count, g), 1, [&](std::size_t first, std::size_t last) {
      for (std::size_t j = first; j < last; ++j) {
        body(j * g, std::min(count, (j + 1) * g));
      }
    });
  }

  // As above, with the running thread's element of `scratch` as third argument.
  template <class Scratch, ScratchBlockBody<Scratch> Body>
  void for_each_block(std::size_t count, ThreadScratch<Scratch>& scratch, const Body& body,
                      std::size_t grain = 0) const {
    const std::size_t g = grain_or_default(grain);
    run_tasks(chunks(count, g), 1, [&](std::size_t first, std::size_t last) {
      Scratch& local = scratch.local();
      for (std::size_t j = first; j < last; ++j) {
        body(j * g, std::min(count, (j + 1) * g), local);
      }
    });
  }

  // body(i) for every particle i in [0, count), chunked as for_each_block.
  template <ParticleBody Body>
  void for_each_particle(std::size_t count, const Body& body, std::size_t grain = 0) const {
    for_each_block(
        count,
        [&](std::size_t begin, std::size_t end) {
          for (std::size_t i = begin; i < end; ++i) body(i);
        },
        grain);
  }

  // body(b, b * block, min((b + 1) * block, count)) for every block b in
  // [0, ceil(count / block)), in parallel; one task runs max(1, grain / block) blocks.
  // REQUIRES: block >= 1.
  template <IndexedBlockBody Body>
  void for_each_fixed_block(std::size_t count, std::size_t block, const Body& body,
                            std::size_t grain = 0) const {
    run_tasks(chunks(count, block), std::max<std::size_t>(1, grain_or_default(grain) / block),
              [&](std::size_t first, std::size_t last) {
                for (std::size_t b = first; b < last; ++b) {
                  body(b, b * block, std::min(count, (b + 1) * block));
                }
              });
  }

  // The deterministic reduction:
  //   combine(...combine(combine(identity, map_block(B_0)), map_block(B_1))..., map_block(B_n))
  // over the blocks B_b = [b * kReduceBlock, min((b + 1) * kReduceBlock, count)), the block
  // results computed in parallel. Returns identity when count is 0. Allocates one T per block.
  // `grain` only groups blocks into tasks; it never changes the result.
  template <class T, BlockMap<T> Map, Combiner<T> Combine>
  T reduce(std::size_t count, T identity, const Map& map_block, Combine&& combine,
           std::size_t grain = 0) const {
    const std::size_t blocks = chunks(count, kReduceBlock);
    if (blocks == 1) {
      return combine(identity, static_cast<T>(map_block(0, count)));
    }
    std::vector<std::optional<T>> partial(blocks);
    for_each_fixed_block(
        count, kReduceBlock,
        [&](std::size_t b, std::size_t begin, std::size_t end) {
          partial[b].emplace(map_block(begin, end));
        },
        grain);
    T result = std::move(identity);
    for (std::optional<T>& p : partial) {
      result = combine(result, *p);
    }
    return result;
  }

 private:
  std::size_t grain_or_default(std::size_t grain) const noexcept {
    return grain != 0 ? grain : grain_;
  }
  static std::size_t chunks(std::size_t count, std::size_t size) noexcept {
    return count / size + (count % size != 0 ? 1 : 0);
  }

  // run(first, last) over the task ranges of `units` units, `per_task` units per task.
  template <class Run>
  void run_tasks(std::size_t units, std::size_t per_task, const Run& run) const {
    if (units == 0) {
      return;
    }
    if (threads_ == 1 || units <= per_task) {
      run(0, units);
      return;
    }
#if FASTSLAM_PARALLEL_TSAN
    const std::size_t tasks = chunks(units, per_task);
    internal::thread_fork_join(threads_, tasks, [&](std::size_t t) {
      run(t * per_task, std::min(units, (t + 1) * per_task));
    });
#else
    arena_->execute([&] {
      tbb::parallel_for(
          tbb::blocked_range<std::size_t>(0, units, per_task),
          [&](const tbb::blocked_range<std::size_t>& r) { run(r.begin(), r.end()); },
          tbb::auto_partitioner());
    });
#endif
  }

  unsigned threads_;
  std::size_t grain_;
  std::unique_ptr<tbb::global_control> raise_limit_;  // only when threads_ > default
  // task_arena::execute is not const; the arena is internally synchronised.
  std::unique_ptr<tbb::task_arena> arena_;
};

// One task at a time in the background: start(f) hands f to the kernel's threads and returns,
// wait() returns once f has finished (the caller helps run it if no worker has taken it yet, so
// it never waits on an idle pool). With a one-thread kernel start() runs f inline. Under TSan
// builds f runs on a std::thread (see the file comment). What f writes may be read after
// wait(); nothing it touches may be used by the caller in between.
// Thread safety: one owner thread calls start and wait. Costs: start is an arena entry and a
// spawn (a sleeping worker may take longer to pick f up; the owner's wait then runs it); no
// allocation beyond f's copy.
class BackgroundTask {
 public:
  explicit BackgroundTask(const ParticleKernel& kernel) : kernel_(&kernel) {}
  BackgroundTask(const BackgroundTask&) = delete;
  BackgroundTask& operator=(const BackgroundTask&) = delete;
  // Waits for the running task.
  ~BackgroundTask() { wait(); }

  // Waits for the previous task, then starts f. f must not throw.
  template <class F>
  void start(F&& f) {
    wait();
    if (kernel_->threads() == 1) {
      f();
      return;
    }
#if FASTSLAM_PARALLEL_TSAN
    thread_ = std::thread(std::forward<F>(f));
#else
    kernel_->execute([&] { group_.run(std::forward<F>(f)); });
    running_ = true;
#endif
  }

  // Returns when the last task started has finished.
  void wait() {
#if FASTSLAM_PARALLEL_TSAN
    if (thread_.joinable()) thread_.join();
#else
    if (running_) {
      kernel_->execute([&] { group_.wait(); });
      running_ = false;
    }
#endif
  }

 private:
  const ParticleKernel* kernel_;
#if FASTSLAM_PARALLEL_TSAN
  std::thread thread_;
#else
  tbb::task_group group_;
  bool running_ = false;
#endif
};

}  // namespace fastslam::parallel
