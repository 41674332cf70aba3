// A particle set shared by a group of ranks (processes, or threads standing in for them): the
// group's two primitives, how particles are dealt to ranks, and the deterministic reduction over
// the whole set. A rank holds whole blocks of ParticleKernel::kReduceBlock particles, so each
// block's result is computed by one rank exactly as one process would compute it; gathering the
// block results and folding them left to right on every rank gives the bits of
// ParticleKernel::reduce over all particles, for any number of ranks. The MPI group is
// parallel/mpi_collective.h; LocalGroup runs ranks as threads of one process (tests, and a
// process that wants the distributed code path without MPI). Design: docs/distributed.md.
// Ownership: a Collective is owned by its rank's user (shared_ptr); LocalGroup members share
// the group's mailboxes. Thread safety: a member is used by one thread, its rank's; every rank
// makes the same calls in the same order (collective calls), or the group hangs.
// Costs: all_gather moves sum of all contributions to every rank; exchange moves each message
// once; shared_reduce gathers one T per block (ceil(M / 256) Ts).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <span>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "parallel/particle_kernel.h"

namespace fastslam::parallel {

using Bytes = std::vector<std::byte>;

class Collective {
 public:
  virtual ~Collective() = default;
  virtual int rank() const noexcept = 0;
  virtual int size() const noexcept = 0;
  // Every rank's `mine` (any length, including 0) concatenated in rank order, on every rank;
  // `sizes`, when given, receives each rank's length.
  virtual Bytes all_gather(std::span<const std::byte> mine,
                           std::vector<std::size_t>* sizes = nullptr) = 0;
  // to[d] goes to rank d (to.size() == size(); to[rank()] is not sent). Returns from[s], what
  // rank s sent to this one (from[rank()] empty).
  virtual std::vector<Bytes> exchange(const std::vector<Bytes>& to) = 0;
  // Ends every rank of the group now with exit code `code`: for an error on one rank while the
  // others wait in a collective call, which would otherwise hang them (MPI_Abort).
  [[noreturn]] virtual void abort(int code) = 0;
};

// The particles [first, first + count) of `total` that rank `rank` of `ranks` holds: whole
// blocks of kReduceBlock, dealt as evenly as blocks allow (ranks differ by at most one block;
// the last block may be short). Throws std::invalid_argument when there are fewer blocks than
// ranks (every rank must hold particles), naming the smallest particle count that works.
struct ParticleShare {
  std::size_t first = 0;
  std::size_t count = 0;
};
ParticleShare particle_share(std::size_t total, int ranks, int rank);

// The rank holding particle `particle` of `total` dealt to `ranks`. O(1).
int particle_owner(std::size_t particle, std::size_t total, int ranks) noexcept;

// A group of `size` ranks inside one process, each used from its own thread: member(r) is rank
// r's Collective. The calls synchronise the threads (a barrier per call).
class LocalGroup {
 public:
  explicit LocalGroup(int size);
  ~LocalGroup();
  LocalGroup(const LocalGroup&) = delete;
  LocalGroup& operator=(const LocalGroup&) = delete;
  std::shared_ptr<Collective> member(int rank);

  struct Shared;  // the mailboxes and the barrier (collective.cc)

 private:
  std::shared_ptr<Shared> shared_;
};

// A Collective that forwards to another and counts its calls: wall seconds in each primitive
// (waiting for the slowest rank included) and bytes this rank contributed or sent. For
// benchmarks; the counters are plain members, read between calls.
class TimedCollective final : public Collective {
 public:
  explicit TimedCollective(std::shared_ptr<Collective> inner) : inner_(std::move(inner)) {}
  int rank() const noexcept override { return inner_->rank(); }
  int size() const noexcept override { return inner_->size(); }
  Bytes all_gather(std::span<const std::byte> mine, std::vector<std::size_t>* sizes) override;
  std::vector<Bytes> exchange(const std::vector<Bytes>& to) override;
  [[noreturn]] void abort(int code) override {
    inner_->abort(code);
    std::_Exit(code);  // not reached: the inner abort does not return
  }

  void reset() noexcept {
    gathers = gather_bytes = exchanges = exchange_bytes = 0;
    gather_seconds = exchange_seconds = 0.0;
  }

  std::uint64_t gathers = 0, gather_bytes = 0, exchanges = 0, exchange_bytes = 0;
  double gather_seconds = 0.0, exchange_seconds = 0.0;

 private:
  std::shared_ptr<Collective> inner_;
};

// Typed forms of all_gather for trivially copyable values.
template <class T>
std::vector<T> all_gather_values(Collective& group, std::span<const T> mine) {
  static_assert(std::is_trivially_copyable_v<T>);
  const Bytes all = group.all_gather(std::as_bytes(mine));
  std::vector<T> out(all.size() / sizeof(T));
  if (!out.empty()) std::memcpy(out.data(), all.data(), out.size() * sizeof(T));
  return out;
}
template <class T>
std::vector<T> all_gather_value(Collective& group, const T& mine) {
  return all_gather_values(group, std::span<const T>(&mine, 1));
}

// ParticleKernel::reduce over the particle set of which this rank holds `count` particles (a
// share from particle_share): without a group, kernel.reduce itself; with one, each rank maps
// its blocks, the block results are gathered and folded in block order on every rank, so every
// rank returns the bits one process would. T must be trivially copyable.
template <class T, BlockMap<T> Map, Combiner<T> Combine>
T shared_reduce(const ParticleKernel& kernel, Collective* group, std::size_t count, T identity,
                const Map& map_block, Combine&& combine) {
  if (group == nullptr) return kernel.reduce(count, identity, map_block, combine);
  static_assert(std::is_trivially_copyable_v<T>);
  constexpr std::size_t kBlock = ParticleKernel::kReduceBlock;
  std::vector<T> mine((count + kBlock - 1) / kBlock, identity);
  kernel.for_each_fixed_block(count, kBlock,
                              [&](std::size_t b, std::size_t begin, std::size_t end) {
                                mine[b] = map_block(begin, end);
                              });
  T result = identity;
  for (const T& block : all_gather_values(*group, std::span<const T>(mine))) {
    result = combine(result, block);
  }
  return result;
}

}  // namespace fastslam::parallel
