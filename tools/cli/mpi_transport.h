// The MPI calls of the command line, behind an interface that the module fastslam_mpi
// (tools/cli/mpi_module.cc, built when the build finds MPI) implements. The `fastslam`
// executable does not link Open MPI: Ranks (tools/cli/mpi_ranks.h) loads the module, and with it
// libmpi, only when a launcher started the process. Linked in, Open MPI's libraries cost every
// command about 2 ms of start-up (their loading, relocations and constructors), a tenth of a
// short run's.
//
// Ownership: the module's object owns MPI's lifetime: made by the module's entry point after
// MPI_Init_thread, it calls MPI_Finalize when deleted. Thread safety: one thread at a time
// (MPI_THREAD_SERIALIZED). Costs: one MPI call per method (two for the variable-length ones).
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "parallel/collective.h"

namespace fastslam::tools {

// A point-to-point message of bytes.
struct RankMessage {
  int source = 0;
  int tag = 0;
  std::string bytes;
};

class MpiTransport {
 public:
  virtual ~MpiTransport() = default;

  virtual int rank() const = 0;
  virtual int size() const = 0;
  // Whether MPI granted MPI_THREAD_SERIALIZED (several threads may call, one at a time).
  virtual bool serialized() const = 0;

  // Every rank's `bytes` bytes at `mine`, in rank order, into `all` (size() * bytes).
  virtual void all_gather(const void* mine, std::size_t bytes, void* all) const = 0;
  // Rank 0's text, on every rank.
  virtual void broadcast(std::string& text) const = 0;
  // Every rank's `bytes` bytes into `all` on rank 0 (size() * bytes there; unused elsewhere).
  virtual void gather(const void* mine, std::size_t bytes, void* all) const = 0;
  // MPI_COMM_WORLD as a particle set's group (parallel/mpi_collective.h).
  virtual std::shared_ptr<parallel::Collective> collective() const = 0;

  virtual void send(int destination, int tag, std::string_view bytes) const = 0;
  // A message that has arrived from any rank with any tag, or none: does not wait.
  virtual std::optional<RankMessage> poll() const = 0;
  // A message that has arrived from `source` with `tag`, or none: does not wait.
  virtual std::optional<std::string> poll(int source, int tag) const = 0;
  // The next message from `source` with `tag`: waits for it.
  virtual std::string receive(int source, int tag) const = 0;
  // Ends every rank of the job.
  [[noreturn]] virtual void abort(int code) const = 0;
};

// The module's entry point: initialises MPI and returns the world's transport (the caller owns
// it); throws std::runtime_error when MPI cannot be initialised.
using MpiTransportOpen = MpiTransport* (*)();
inline constexpr const char* kMpiTransportOpen = "fastslam_mpi_transport_open";

}  // namespace fastslam::tools
