#include "engine/internal/particle_exchange.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_set>
#include <vector>

#include "engine/internal/map_update.h"
#include "memory/tree_graph.h"

namespace fastslam::engine::internal {
namespace {

// A particle's copies bound for one rank.
struct Run {
  std::uint32_t particle;  // local index
  std::uint32_t copies;
};

struct SentParticle {
  std::uint64_t copies;
  double pose[5];
};
static_assert(sizeof(SentParticle) == 48 && std::is_trivially_copyable_v<SentParticle>);

void put(std::ostream& out, const void* data, std::size_t bytes) {
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
}

void get(std::istream& in, void* data, std::size_t bytes, int from) {
  if (!in.read(static_cast<char*>(data), static_cast<std::streamsize>(bytes))) {
    throw std::logic_error("resampling exchange: the message from rank " + std::to_string(from) +
                             " is truncated (are all ranks running the same fastslam?)");
  }
}

}  // namespace

ExchangeCounts exchange_particles(FilterState& s, const parallel::ParticleKernel& kernel,
                                  std::uint64_t start, std::span<const std::uint64_t> ends,
                                  std::size_t grain) {
  parallel::Collective& group = *s.group;
  const int ranks = group.size();
  const int me = group.rank();
  const std::size_t total = s.config.particles;
  memory::ParticleStore& store = s.store;
  const bool carried = store.options().pose_covariance == memory::PoseCovariance::kCarried;
  constexpr std::size_t kCov = memory::ParticleStore::kPoseCovStride;

  // Each local particle's outputs, split by the rank holding them.
  std::vector<parallel::ParticleShare> shares(static_cast<std::size_t>(ranks));
  for (int r = 0; r < ranks; ++r) shares[r] = parallel::particle_share(total, ranks, r);
  std::vector<std::vector<Run>> runs(static_cast<std::size_t>(ranks));
  for (std::size_t i = 0; i < ends.size(); ++i) {
    std::uint64_t a = i == 0 ? start : ends[i - 1];
    const std::uint64_t b = ends[i];
    while (a < b) {
      const int d = parallel::particle_owner(a, total, ranks);
      const std::uint64_t d_end = shares[d].first + shares[d].count;
      const std::uint64_t n = std::min(b, d_end) - a;
      runs[d].push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(n)});
      a += n;
    }
  }

  ExchangeCounts counts;
  NodeLinks& links = *s.links;
  std::vector<parallel::Bytes> to(static_cast<std::size_t>(ranks));
  for (int d = 0; d < ranks; ++d) {
    std::vector<memory::NodeId>& retired = links.retired_for[d];
    if (d == me || (runs[d].empty() && retired.empty())) continue;
    std::ostringstream out;
    const std::uint64_t released = retired.size();
    put(out, &released, sizeof released);
    put(out, retired.data(), retired.size() * sizeof(memory::NodeId));
    const std::uint64_t sent = runs[d].size();
    put(out, &sent, sizeof sent);
    for (const Run& run : runs[d]) {
      const std::size_t i = run.particle;
      SentParticle p{run.copies,
                     {store.x()[i], store.y()[i], store.theta()[i], store.v()[i],
                      store.omega()[i]}};
      put(out, &p, sizeof p);
      if (carried) put(out, &store.pose_cov()[i * kCov], kCov * sizeof(double));
      counts.copies_sent += run.copies;
      counts.naive_bytes +=
          run.copies * (sizeof p + (carried ? kCov * sizeof(double) : 0) +
                        store.map(i).size() * sizeof(memory::Landmark));
    }
    if (sent > 0) {
      std::unordered_set<memory::NodeId>& held = links.held_by[d];
      memory::TreeGraphWriter graph(out, links.registry, held);
      for (const Run& run : runs[d]) graph.write(store.map(run.particle).tree());
      held.insert(graph.named().begin(), graph.named().end());
    }
    retired.clear();
    const std::string bytes = std::move(out).str();
    to[d].resize(bytes.size());
    std::memcpy(to[d].data(), bytes.data(), bytes.size());
    counts.particles_sent += sent;
    counts.bytes_sent += bytes.size();
  }
  const std::vector<parallel::Bytes> from = group.exchange(to);

  // Arrivals after the local particles; then one gather in output order: the outputs of lower
  // ranks' particles first, then this rank's, then higher ranks'.
  std::vector<std::uint32_t> index;
  index.reserve(shares[me].count);
  for (int r = 0; r < ranks; ++r) {
    if (r == me) {
      for (const Run& run : runs[me]) index.insert(index.end(), run.copies, run.particle);
      continue;
    }
    if (from[r].empty()) continue;
    std::istringstream in(std::string(reinterpret_cast<const char*>(from[r].data()),
                                      from[r].size()));
    std::uint64_t released = 0;
    get(in, &released, sizeof released, r);
    if (released > from[r].size() / sizeof(memory::NodeId)) {
      throw std::logic_error("resampling exchange: rank " + std::to_string(r) + " retired " +
                               std::to_string(released) + " nodes in a shorter message");
    }
    for (std::uint64_t k = 0; k < released; ++k) {
      memory::NodeId name = 0;
      get(in, &name, sizeof name, r);
      links.held_by[r].erase(name);
    }
    std::uint64_t arriving = 0;
    get(in, &arriving, sizeof arriving, r);
    if (arriving == 0) continue;
    if (arriving > shares[me].count) {
      throw std::logic_error("resampling exchange: rank " + std::to_string(r) + " sent " +
                               std::to_string(arriving) + " particles for " +
                               std::to_string(shares[me].count) + " slots");
    }
    const std::size_t at = store.size();
    store.append(arriving);
    for (std::size_t j = 0; j < arriving; ++j) {
      SentParticle p;
      get(in, &p, sizeof p, r);
      const std::size_t k = at + j;
      store.x()[k] = p.pose[0];
      store.y()[k] = p.pose[1];
      store.theta()[k] = p.pose[2];
      store.v()[k] = p.pose[3];
      store.omega()[k] = p.pose[4];
      if (carried) get(in, &store.pose_cov()[k * kCov], kCov * sizeof(double), r);
      if (p.copies == 0 || p.copies > shares[me].count) {
        throw std::logic_error("resampling exchange: a bad copy count from rank " +
                                 std::to_string(r));
      }
      index.insert(index.end(), p.copies, static_cast<std::uint32_t>(k));
    }
    memory::TreeGraphReader graph(in, s.heap, links.registry);
    try {
      for (std::size_t j = 0; j < arriving; ++j) {
        memory::LandmarkTree tree = graph.read([](memory::Slot, const memory::Landmark&) {});
        const std::size_t k = at + j;
        if (k == 0 || store.options().indexing == memory::Indexing::kNone) {
          store.map(k) =
              memory::ParticleMap(std::move(tree), store.options().indexing, largest_variance);
        } else {
          // Beside the previous arrival's map, or a local one's: they share most nodes.
          std::uint64_t steps = std::numeric_limits<std::uint64_t>::max();
          store.map(k) = memory::ParticleMap(std::move(tree), store.map(k - 1),
                                             largest_variance, steps);
        }
      }
      graph.finish();
      links.held_by[r].insert(graph.named().begin(), graph.named().end());
    } catch (const memory::TreeGraphError& e) {
      throw std::logic_error("resampling exchange: the maps from rank " + std::to_string(r) +
                               ": " + e.what());
    }
  }
  if (index.size() != shares[me].count) {
    throw std::logic_error("resampling exchange: rank " + std::to_string(me) + " received " +
                             std::to_string(index.size()) + " particles for " +
                             std::to_string(shares[me].count) + " slots");
  }
  kernel.execute([&] { store.gather(index, grain); });
  // The nodes no particle holds now retire here; the ranks that hold their names hear of it at
  // the next exchange, and until then may still send them as held.
  for (const memory::NodeId name : links.registry.sweep()) {
    for (int r = 0; r < ranks; ++r) {
      if (r != me && links.held_by[r].erase(name) > 0) links.retired_for[r].push_back(name);
    }
  }
  return counts;
}

}  // namespace fastslam::engine::internal
