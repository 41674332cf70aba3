#include "parallel/mpi_collective.h"

#include <mpi.h>

#include <climits>
#include <cstdlib>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace fastslam::parallel {
namespace {

void check(int code, const char* what) {
  if (code != MPI_SUCCESS) {
    char text[MPI_MAX_ERROR_STRING];
    int length = 0;
    MPI_Error_string(code, text, &length);
    throw std::runtime_error(std::string("MPI collective: ") + what + ": " +
                             std::string(text, static_cast<std::size_t>(length)));
  }
}

// Displacements of `counts`, and their total.
std::size_t displacements(const std::vector<int>& counts, std::vector<int>& at) {
  at.resize(counts.size());
  std::size_t total = 0;
  for (std::size_t r = 0; r < counts.size(); ++r) {
    at[r] = mpi_count(total);
    total += static_cast<std::size_t>(counts[r]);
  }
  mpi_count(total);
  return total;
}

class MpiCollective final : public Collective {
 public:
  MpiCollective() {
    check(MPI_Comm_dup(MPI_COMM_WORLD, &comm_), "MPI_Comm_dup");
    // Errors come back as codes, which `check` turns into exceptions.
    MPI_Comm_set_errhandler(comm_, MPI_ERRORS_RETURN);
    MPI_Comm_rank(comm_, &rank_);
    MPI_Comm_size(comm_, &size_);
  }
  ~MpiCollective() override {
    int finalized = 0;
    MPI_Finalized(&finalized);
    if (!finalized) MPI_Comm_free(&comm_);
  }
  MpiCollective(const MpiCollective&) = delete;
  MpiCollective& operator=(const MpiCollective&) = delete;

  int rank() const noexcept override { return rank_; }
  int size() const noexcept override { return size_; }

  Bytes all_gather(std::span<const std::byte> mine, std::vector<std::size_t>* sizes) override {
    const int count = mpi_count(mine.size());
    std::vector<int> counts(static_cast<std::size_t>(size_));
    check(MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_), "MPI_Allgather");
    std::vector<int> at;
    Bytes all(displacements(counts, at));
    check(MPI_Allgatherv(mine.data(), count, MPI_BYTE, all.data(), counts.data(), at.data(),
                         MPI_BYTE, comm_),
          "MPI_Allgatherv");
    if (sizes != nullptr) sizes->assign(counts.begin(), counts.end());
    return all;
  }

  std::vector<Bytes> exchange(const std::vector<Bytes>& to) override {
    const auto n = static_cast<std::size_t>(size_);
    if (to.size() != n) {
      throw std::invalid_argument("Collective::exchange: " + std::to_string(to.size()) +
                                  " messages for " + std::to_string(n) + " ranks");
    }
    std::vector<int> send_counts(n), recv_counts(n);
    for (std::size_t d = 0; d < n; ++d) {
      send_counts[d] = d == static_cast<std::size_t>(rank_) ? 0 : mpi_count(to[d].size());
    }
    check(MPI_Alltoall(send_counts.data(), 1, MPI_INT, recv_counts.data(), 1, MPI_INT, comm_),
          "MPI_Alltoall");
    std::vector<int> send_at, recv_at;
    Bytes sent(displacements(send_counts, send_at));
    for (std::size_t d = 0; d < n; ++d) {
      if (send_counts[d] > 0) std::copy(to[d].begin(), to[d].end(), sent.begin() + send_at[d]);
    }
    Bytes received(displacements(recv_counts, recv_at));
    check(MPI_Alltoallv(sent.data(), send_counts.data(), send_at.data(), MPI_BYTE,
                        received.data(), recv_counts.data(), recv_at.data(), MPI_BYTE, comm_),
          "MPI_Alltoallv");
    std::vector<Bytes> from(n);
    for (std::size_t s = 0; s < n; ++s) {
      from[s].assign(received.begin() + recv_at[s],
                     received.begin() + recv_at[s] + recv_counts[s]);
    }
    return from;
  }

  [[noreturn]] void abort(int code) override {
    MPI_Abort(MPI_COMM_WORLD, code);
    std::_Exit(code);  // MPI_Abort returns only if MPI could not end the job
  }

 private:
  MPI_Comm comm_ = MPI_COMM_NULL;
  int rank_ = 0;
  int size_ = 1;
};

}  // namespace

int mpi_count(std::size_t bytes) {
  if (bytes > static_cast<std::size_t>(INT_MAX)) {
    throw std::length_error("MPI: " + std::to_string(bytes) +
                            " bytes exceed MPI's int count limit");
  }
  return static_cast<int>(bytes);
}

std::shared_ptr<Collective> mpi_world() {
  int initialized = 0;
  MPI_Initialized(&initialized);
  if (!initialized) {
    throw std::runtime_error("parallel::mpi_world: MPI is not initialised (call MPI_Init first)");
  }
  return std::make_shared<MpiCollective>();
}

}  // namespace fastslam::parallel
