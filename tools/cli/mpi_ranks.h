// The command line's process group: whether a launcher (mpirun, srun) started this process, and
// MPI_COMM_WORLD when it did and the build has MPI (FASTSLAM_HAVE_MPI; this process alone
// otherwise). `fastslam sweep` spreads runs over the ranks; `fastslam run` spreads one run's
// particles over them (collective(): parallel/mpi_collective.h).
// Ownership: a Ranks initialises MPI for its lifetime (MPI_THREAD_SERIALIZED) and finalises it.
// Thread safety: one Ranks per process; collective calls from one thread at a time.
// Costs: a collective call each.
#pragma once

#include <cstddef>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "parallel/collective.h"

namespace fastslam::tools {

// Whether a launcher started this process, and how many it started.
struct Launch {
  bool launched = false;
  int size = 1;        // 0 when the launcher does not say
  int local_size = 1;  // processes of the job on this node
};
Launch launch_environment();

// Whether this build can run over MPI ranks.
bool have_mpi() noexcept;

class Ranks {
 public:
  // MPI initialised when `use_mpi` and the build has MPI.
  explicit Ranks(bool use_mpi);
  ~Ranks();
  Ranks(const Ranks&) = delete;
  Ranks& operator=(const Ranks&) = delete;

  int rank() const { return rank_; }
  int size() const { return size_; }
  bool mpi() const { return mpi_; }
  // Several threads of a rank may exchange with rank 0 (one at a time).
  bool serialized() const { return serialized_; }

  // Every rank's flag, on every rank.
  std::vector<int> all_flags(int flag) const;
  // Rank 0's text, on every rank.
  std::string broadcast(std::string text) const;
  // Every rank's text of `width` bytes, on rank 0 (empty elsewhere).
  std::vector<std::string> gather(const std::string& text, std::size_t width) const;
  // The ranks as a particle set's group (REQUIRES: mpi()).
  std::shared_ptr<parallel::Collective> collective() const;

  std::mutex exchange_mutex;

 private:
  bool mpi_ = false;
  bool serialized_ = true;
  int rank_ = 0;
  int size_ = 1;
};

}  // namespace fastslam::tools
