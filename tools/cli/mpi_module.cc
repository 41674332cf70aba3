// The module fastslam_mpi: MpiTransport (tools/cli/mpi_transport.h) over MPI_COMM_WORLD, loaded
// by Ranks (tools/cli/mpi_ranks.cc) when a launcher started the process.
#include <cstdlib>
#include <mpi.h>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

#include "parallel/mpi_collective.h"
#include "tools/cli/mpi_transport.h"

namespace fastslam::tools {
namespace {

class WorldTransport final : public MpiTransport {
 public:
  WorldTransport() {
    int provided = 0;
    if (MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided) != MPI_SUCCESS) {
      throw std::runtime_error("MPI_Init_thread failed");
    }
    serialized_ = provided >= MPI_THREAD_SERIALIZED;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  ~WorldTransport() override { MPI_Finalize(); }

  int rank() const override { return rank_; }
  int size() const override { return size_; }
  bool serialized() const override { return serialized_; }

  void all_gather(const void* mine, std::size_t bytes, void* all) const override {
    const int n = parallel::mpi_count(bytes);
    MPI_Allgather(mine, n, MPI_BYTE, all, n, MPI_BYTE, MPI_COMM_WORLD);
  }
  void broadcast(std::string& text) const override {
    long long n = static_cast<long long>(text.size());
    MPI_Bcast(&n, 1, MPI_LONG_LONG, 0, MPI_COMM_WORLD);
    text.resize(static_cast<std::size_t>(n));
    MPI_Bcast(text.data(), parallel::mpi_count(text.size()), MPI_BYTE, 0, MPI_COMM_WORLD);
  }
  void gather(const void* mine, std::size_t bytes, void* all) const override {
    const int n = parallel::mpi_count(bytes);
    MPI_Gather(mine, n, MPI_BYTE, all, n, MPI_BYTE, 0, MPI_COMM_WORLD);
  }
  std::shared_ptr<parallel::Collective> collective() const override {
    return parallel::mpi_world();
  }

  void send(int destination, int tag, std::string_view bytes) const override {
    MPI_Send(bytes.data(), parallel::mpi_count(bytes.size()), MPI_BYTE, destination, tag,
             MPI_COMM_WORLD);
  }
  std::optional<RankMessage> poll() const override { return arrived(MPI_ANY_SOURCE, MPI_ANY_TAG); }
  std::optional<std::string> poll(int source, int tag) const override {
    std::optional<RankMessage> m = arrived(source, tag);
    if (!m) return std::nullopt;
    return std::move(m->bytes);
  }
  std::string receive(int source, int tag) const override {
    MPI_Status status;
    MPI_Probe(source, tag, MPI_COMM_WORLD, &status);
    return take(status).bytes;
  }
  [[noreturn]] void abort(int code) const override {
    MPI_Abort(MPI_COMM_WORLD, code);
    std::abort();  // MPI_Abort does not return; this says so to the compiler
  }

 private:
  std::optional<RankMessage> arrived(int source, int tag) const {
    int flag = 0;
    MPI_Status status;
    MPI_Iprobe(source, tag, MPI_COMM_WORLD, &flag, &status);
    if (!flag) return std::nullopt;
    return take(status);
  }
  // Receives the message `status` describes.
  RankMessage take(const MPI_Status& status) const {
    int bytes = 0;
    MPI_Get_count(&status, MPI_BYTE, &bytes);
    RankMessage m{status.MPI_SOURCE, status.MPI_TAG,
                  std::string(static_cast<std::size_t>(bytes), '\0')};
    MPI_Recv(m.bytes.data(), bytes, MPI_BYTE, status.MPI_SOURCE, status.MPI_TAG, MPI_COMM_WORLD,
             MPI_STATUS_IGNORE);
    return m;
  }

  bool serialized_ = false;
  int rank_ = 0;
  int size_ = 1;
};

}  // namespace
}  // namespace fastslam::tools

extern "C" __attribute__((visibility("default"))) fastslam::tools::MpiTransport*
fastslam_mpi_transport_open() {
  return new fastslam::tools::WorldTransport();
}
