// The command line's process group: whether a launcher (mpirun, srun) started this process, and
// MPI_COMM_WORLD when it did and the build has MPI (FASTSLAM_HAVE_MPI; this process alone
// otherwise). `fastslam sweep` spreads runs over the ranks; `fastslam run` spreads one run's
// particles over them (collective(): parallel/mpi_collective.h). MPI itself is in a module
// loaded only then (tools/cli/mpi_transport.h), so a command that uses no ranks never loads it.
// Ownership: a Ranks over MPI owns the module's transport, which initialised MPI
// (MPI_THREAD_SERIALIZED) and finalises it with the Ranks. Thread safety: one Ranks per process;
// calls from one thread at a time. Costs: an MPI call each; loading the module, once, the
// dynamic loading of Open MPI (a few ms).
#pragma once

#include <cstddef>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "parallel/collective.h"
#include "tools/cli/mpi_transport.h"

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
  // MPI initialised when `use_mpi` and the build has MPI. Throws std::runtime_error naming the
  // module when it cannot be loaded (Open MPI's libraries missing on this machine).
  explicit Ranks(bool use_mpi);
  ~Ranks();
  Ranks(const Ranks&) = delete;
  Ranks& operator=(const Ranks&) = delete;

  int rank() const { return mpi_ ? mpi_->rank() : 0; }
  int size() const { return mpi_ ? mpi_->size() : 1; }
  bool mpi() const { return mpi_ != nullptr; }
  // Several threads of a rank may exchange with rank 0 (one at a time).
  bool serialized() const { return mpi_ ? mpi_->serialized() : true; }

  // Every rank's flag, on every rank.
  std::vector<int> all_flags(int flag) const;
  // Rank 0's text, on every rank.
  std::string broadcast(std::string text) const;
  // Every rank's text of `width` bytes, on rank 0 (empty elsewhere).
  std::vector<std::string> gather(const std::string& text, std::size_t width) const;
  // The ranks as a particle set's group (REQUIRES: mpi()).
  std::shared_ptr<parallel::Collective> collective() const;

  // Point-to-point messages of bytes (REQUIRES: mpi()); see MpiTransport.
  void send(int destination, int tag, std::string_view bytes) const;
  std::optional<RankMessage> poll() const;
  std::optional<std::string> poll(int source, int tag) const;
  std::string receive(int source, int tag) const;
  // Ends every rank of the job (REQUIRES: mpi()).
  [[noreturn]] void abort(int code) const;

  std::mutex exchange_mutex;

 private:
  const MpiTransport& transport() const;

  std::unique_ptr<MpiTransport> mpi_;
};

}  // namespace fastslam::tools
