#include "tools/cli/mpi_ranks.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <dlfcn.h>
#include <filesystem>
#include <stdexcept>

namespace fastslam::tools {
namespace {

// A number from the environment, 0 when absent or not a number.
int env_int(const char* name) {
  const char* v = std::getenv(name);
  return v == nullptr ? 0 : std::atoi(v);
}

#ifdef FASTSLAM_HAVE_MPI
// The module beside the executable: <bin>/../lib/fastslam/fastslam_mpi.so, in the build tree
// (build/<preset>/tools/fastslam) as installed (<prefix>/bin/fastslam).
std::unique_ptr<MpiTransport> open_transport() {
  std::error_code error;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", error);
  const std::filesystem::path module =
      (exe.parent_path() / FASTSLAM_MPI_MODULE_RELATIVE).lexically_normal();
  // RTLD_GLOBAL: Open MPI's own components, loaded later, resolve libmpi's symbols from it.
  void* handle = dlopen(module.c_str(), RTLD_NOW | RTLD_GLOBAL);
  if (handle == nullptr) {
    const char* why = dlerror();
    throw std::runtime_error("cannot load the MPI module " + module.string() + ": " +
                             (why != nullptr ? why : "unknown error") +
                             " (the module is installed with fastslam; the Open MPI it needs "
                             "comes with Debian's libopenmpi3). Without mpirun, fastslam needs "
                             "no MPI");
  }
  // Never closed: MPI cannot be initialised twice in a process.
  const auto open = reinterpret_cast<MpiTransportOpen>(dlsym(handle, kMpiTransportOpen));
  if (open == nullptr) {
    throw std::runtime_error("the MPI module " + module.string() + " has no " + kMpiTransportOpen +
                             ": it is not this fastslam's");
  }
  return std::unique_ptr<MpiTransport>(open());
}
#endif

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
  if (use_mpi) mpi_ = open_transport();
#else
  (void)use_mpi;
#endif
}

Ranks::~Ranks() = default;

const MpiTransport& Ranks::transport() const {
  if (!mpi_) throw std::logic_error("Ranks: MPI is not in use");
  return *mpi_;
}

std::vector<int> Ranks::all_flags(int flag) const {
  std::vector<int> flags(static_cast<std::size_t>(size()), flag);
  if (mpi_) mpi_->all_gather(&flag, sizeof(flag), flags.data());
  return flags;
}

std::string Ranks::broadcast(std::string text) const {
  if (mpi_) mpi_->broadcast(text);
  return text;
}

std::vector<std::string> Ranks::gather(const std::string& text, std::size_t width) const {
  if (!mpi_) return {text};
  std::string padded = text;
  padded.resize(width, ' ');
  std::string all(rank() == 0 ? width * static_cast<std::size_t>(size()) : 0, ' ');
  mpi_->gather(padded.data(), width, all.data());
  std::vector<std::string> out;
  for (std::size_t r = 0; rank() == 0 && r < static_cast<std::size_t>(size()); ++r) {
    out.push_back(all.substr(r * width, width));
  }
  return out;
}

std::shared_ptr<parallel::Collective> Ranks::collective() const { return transport().collective(); }

void Ranks::send(int destination, int tag, std::string_view bytes) const {
  transport().send(destination, tag, bytes);
}

std::optional<RankMessage> Ranks::poll() const { return transport().poll(); }

std::optional<std::string> Ranks::poll(int source, int tag) const {
  return transport().poll(source, tag);
}

std::string Ranks::receive(int source, int tag) const { return transport().receive(source, tag); }

void Ranks::abort(int code) const {
  transport().abort(code);
  std::abort();  // not reached: the transport's abort ends the process
}

}  // namespace fastslam::tools
