#include "tools/cli/mpi_ranks.h"

#include <algorithm>
#include <cstdlib>

#ifdef FASTSLAM_HAVE_MPI
#include <mpi.h>

#include "parallel/mpi_collective.h"
#endif

namespace fastslam::tools {
namespace {

// A number from the environment, 0 when absent or not a number.
int env_int(const char* name) {
  const char* v = std::getenv(name);
  return v == nullptr ? 0 : std::atoi(v);
}

}  // namespace

Launch launch_environment() {
  Launch l;
  if (std::getenv("OMPI_COMM_WORLD_SIZE") != nullptr) {
    l.launched = true;
    l.size = env_int("OMPI_COMM_WORLD_SIZE");
    l.local_size = std::max(1, env_int("OMPI_COMM_WORLD_LOCAL_SIZE"));
  } else if (std::getenv("PMIX_RANK") != nullptr || std::getenv("PMI_SIZE") != nullptr) {
    l.launched = true;
    l.size = env_int("PMI_SIZE");
    l.local_size = std::max(1, env_int("MPI_LOCALNRANKS"));
  }
  return l;
}

bool have_mpi() noexcept {
#ifdef FASTSLAM_HAVE_MPI
  return true;
#else
  return false;
#endif
}

Ranks::Ranks(bool use_mpi) {
#ifdef FASTSLAM_HAVE_MPI
  if (use_mpi) {
    int provided = 0;
    MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided);
    mpi_ = true;
    serialized_ = provided >= MPI_THREAD_SERIALIZED;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
#else
  (void)use_mpi;
#endif
}

Ranks::~Ranks() {
#ifdef FASTSLAM_HAVE_MPI
  if (mpi_) MPI_Finalize();
#endif
}

std::vector<int> Ranks::all_flags(int flag) const {
  std::vector<int> flags(static_cast<std::size_t>(size_), flag);
#ifdef FASTSLAM_HAVE_MPI
  if (mpi_) MPI_Allgather(&flag, 1, MPI_INT, flags.data(), 1, MPI_INT, MPI_COMM_WORLD);
#endif
  return flags;
}

std::string Ranks::broadcast(std::string text) const {
#ifdef FASTSLAM_HAVE_MPI
  if (mpi_) {
    long long n = static_cast<long long>(text.size());
    MPI_Bcast(&n, 1, MPI_LONG_LONG, 0, MPI_COMM_WORLD);
    text.resize(static_cast<std::size_t>(n));
    MPI_Bcast(text.data(), static_cast<int>(n), MPI_CHAR, 0, MPI_COMM_WORLD);
  }
#endif
  return text;
}

std::vector<std::string> Ranks::gather(const std::string& text, std::size_t width) const {
  std::vector<std::string> out;
  if (!mpi_) return {text};
#ifndef FASTSLAM_HAVE_MPI
  (void)width;
#else
  std::string padded = text;
  padded.resize(width, ' ');
  std::string all(rank_ == 0 ? width * static_cast<std::size_t>(size_) : 0, ' ');
  MPI_Gather(padded.data(), static_cast<int>(width), MPI_CHAR, all.data(), static_cast<int>(width),
             MPI_CHAR, 0, MPI_COMM_WORLD);
  for (std::size_t r = 0; rank_ == 0 && r < static_cast<std::size_t>(size_); ++r) {
    out.push_back(all.substr(r * width, width));
  }
#endif
  return out;
}

std::shared_ptr<parallel::Collective> Ranks::collective() const {
#ifdef FASTSLAM_HAVE_MPI
  if (mpi_) return parallel::mpi_world();
#endif
  throw std::logic_error("Ranks::collective: MPI is not in use");
}

}  // namespace fastslam::tools
