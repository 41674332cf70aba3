#include "parallel/collective.h"

#include <algorithm>
#include <barrier>
#include <chrono>
#include <cstdlib>
#include <string>

namespace fastslam::parallel {

ParticleShare particle_share(std::size_t total, int ranks, int rank) {
  constexpr std::size_t kBlock = ParticleKernel::kReduceBlock;
  const std::size_t blocks = (total + kBlock - 1) / kBlock;
  const auto r = static_cast<std::size_t>(ranks);
  if (ranks < 1 || rank < 0 || rank >= ranks) {
    throw std::invalid_argument("particle_share: rank " + std::to_string(rank) + " of " +
                                std::to_string(ranks));
  }
  if (blocks < r) {
    throw std::invalid_argument(
        std::to_string(total) + " particles are " + std::to_string(blocks) + " block(s) of " +
        std::to_string(kBlock) + ", too few for " + std::to_string(ranks) +
        " ranks: every rank holds whole blocks; use at least " +
        std::to_string((r - 1) * kBlock + 1) + " particles or at most " + std::to_string(blocks) +
        " rank(s)");
  }
  const auto k = static_cast<std::size_t>(rank);
  const std::size_t b0 = blocks * k / r, b1 = blocks * (k + 1) / r;
  const std::size_t first = b0 * kBlock;
  return {first, std::min(total, b1 * kBlock) - first};
}

int particle_owner(std::size_t particle, std::size_t total, int ranks) noexcept {
  constexpr std::size_t kBlock = ParticleKernel::kReduceBlock;
  const std::size_t blocks = (total + kBlock - 1) / kBlock;
  const std::size_t b = particle / kBlock;
  const auto r = static_cast<std::size_t>(ranks);
  // The first rank k with b < blocks * (k + 1) / r; the guess b * r / blocks is at most one low.
  std::size_t k = b * r / blocks;
  while (b >= blocks * (k + 1) / r) ++k;
  return static_cast<int>(k);
}

struct LocalGroup::Shared {
  explicit Shared(int n)
      : size(n), sync(n), slots(static_cast<std::size_t>(n)),
        mail(static_cast<std::size_t>(n) * static_cast<std::size_t>(n)) {}
  int size;
  std::barrier<> sync;
  std::vector<std::span<const std::byte>> slots;  // each rank's contribution to all_gather
  std::vector<const Bytes*> mail;                 // mail[s * size + d]: rank s's message to d
};

namespace {

class LocalMember final : public Collective {
 public:
  LocalMember(std::shared_ptr<LocalGroup::Shared> shared, int rank)
      : shared_(std::move(shared)), rank_(rank) {}
  int rank() const noexcept override { return rank_; }
  int size() const noexcept override { return group().size; }

  Bytes all_gather(std::span<const std::byte> mine, std::vector<std::size_t>* sizes) override {
    auto& g = group();
    g.slots[static_cast<std::size_t>(rank_)] = mine;
    g.sync.arrive_and_wait();  // every contribution posted
    Bytes all;
    if (sizes != nullptr) sizes->clear();
    for (const std::span<const std::byte> s : g.slots) {
      all.insert(all.end(), s.begin(), s.end());
      if (sizes != nullptr) sizes->push_back(s.size());
    }
    g.sync.arrive_and_wait();  // every rank has read: the contributions may go
    return all;
  }

  std::vector<Bytes> exchange(const std::vector<Bytes>& to) override {
    auto& g = group();
    const auto n = static_cast<std::size_t>(g.size);
    if (to.size() != n) {
      throw std::invalid_argument("Collective::exchange: " + std::to_string(to.size()) +
                                  " messages for " + std::to_string(n) + " ranks");
    }
    const auto me = static_cast<std::size_t>(rank_);
    for (std::size_t d = 0; d < n; ++d) g.mail[me * n + d] = &to[d];
    g.sync.arrive_and_wait();
    std::vector<Bytes> from(n);
    for (std::size_t s = 0; s < n; ++s) {
      if (s != me) from[s] = *g.mail[s * n + me];
    }
    g.sync.arrive_and_wait();
    return from;
  }

  // The ranks are threads of this process: ending it ends them all.
  [[noreturn]] void abort(int code) override { std::_Exit(code); }

 private:
  LocalGroup::Shared& group() const { return *shared_; }
  std::shared_ptr<LocalGroup::Shared> shared_;
  int rank_;
};

}  // namespace

Bytes TimedCollective::all_gather(std::span<const std::byte> mine,
                                  std::vector<std::size_t>* sizes) {
  const auto t0 = std::chrono::steady_clock::now();
  Bytes all = inner_->all_gather(mine, sizes);
  gather_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ++gathers;
  gather_bytes += mine.size();
  return all;
}

std::vector<Bytes> TimedCollective::exchange(const std::vector<Bytes>& to) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<Bytes> from = inner_->exchange(to);
  exchange_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ++exchanges;
  for (std::size_t d = 0; d < to.size(); ++d) {
    if (static_cast<int>(d) != rank()) exchange_bytes += to[d].size();
  }
  return from;
}

LocalGroup::LocalGroup(int size) {
  if (size < 1) throw std::invalid_argument("LocalGroup: size must be >= 1");
  shared_ = std::make_shared<Shared>(size);
}

LocalGroup::~LocalGroup() = default;

std::shared_ptr<Collective> LocalGroup::member(int rank) {
  if (rank < 0 || rank >= shared_->size) {
    throw std::invalid_argument("LocalGroup::member: rank " + std::to_string(rank) + " of " +
                                std::to_string(shared_->size));
  }
  return std::make_shared<LocalMember>(shared_, rank);
}

}  // namespace fastslam::parallel
