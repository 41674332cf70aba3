// A fork-join over plain std::threads: the scheduler the parallel kernel uses when built with
// ThreadSanitizer. Not API.
//
// Why: Debian's libtbb is not built with TSan, so TSan cannot see the synchronisation inside
// TBB's scheduler (task hand-off and stealing happen in uninstrumented code) and reports every
// access to data handed to a task as a race (google/sanitizers#1004). Thread creation and join
// are intercepted by TSan, so running the same blocks on std::threads keeps every real race in
// our code visible and reports no false ones. Release and ASan builds use TBB.
// Thread safety: `fork_join` may be called from any thread; `run_block` is called concurrently
// from `threads` threads, each block exactly once.
// Costs: creates threads - 1 threads per call (fine for tests, not for production).
#pragma once

#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace fastslam::parallel::internal {

// Calls run_block(b) for every b in [0, blocks) on `threads` threads (the caller is one).
// The first exception thrown by a block is rethrown after every thread has joined.
template <class RunBlock>
void thread_fork_join(unsigned threads, std::size_t blocks, RunBlock&& run_block) {
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&] {
    for (std::size_t b = next.fetch_add(1); b < blocks; b = next.fetch_add(1)) {
      try {
        run_block(b);
      } catch (...) {
        std::lock_guard lock(error_mutex);
        if (!error) {
          error = std::current_exception();
        }
      }
    }
  };
  std::vector<std::thread> pool;
  const std::size_t extra = threads > 1 && blocks > 1 ? threads - 1 : 0;
  pool.reserve(extra);
  for (std::size_t t = 0; t < extra; ++t) {
    pool.emplace_back(worker);
  }
  worker();
  for (std::thread& thread : pool) {
    thread.join();
  }
  if (error) {
    std::rethrow_exception(error);
  }
}

}  // namespace fastslam::parallel::internal
