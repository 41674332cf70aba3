// Names for the nodes of landmark trees that move between processes (the particle exchange of a
// set shared by MPI ranks, engine/internal/particle_exchange.h): a node, once named, keeps its
// 64-bit id in every process that holds it, so a message can refer to a subtree the receiver
// holds instead of carrying it (memory/tree_graph.h's linked form). An id is the origin (0 for
// pinned nodes, rank + 1 for nodes a rank first sent) and a serial of that origin.
//
// The registry holds a reference to every node it names, so a named node is never written in
// place (the tree copies shared nodes) and its id always denotes the same contents. `sweep`
// gives back the nodes nothing else holds: they retire (named and resolvable until the next
// sweep, while peers learn of it, and named again if a message brings them back) and are then
// released. Pinned nodes (a prior map every rank
// builds alike) never retire; `unpin` lets them go.
//
// Ownership: borrows the heap the nodes came from, which must outlive the registry.
// Thread safety: thread-compatible; `sweep` reads reference counts, so no thread may change the
// trees while it runs. Costs: find, hold and add O(1) expected; sweep
// O(named nodes) reads of their counts (one cache miss each) plus the retired nodes' children;
// memory about 100 bytes a named node in two hash maps.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "memory/landmark_tree.h"

namespace fastslam::memory {

using NodeId = std::uint64_t;

// The origin of pinned ids (below every rank's).
inline constexpr std::uint64_t kPinnedOrigin = 0;
inline constexpr unsigned kNodeSerialBits = 48;
constexpr NodeId node_id(std::uint64_t origin, std::uint64_t serial) noexcept {
  return origin << kNodeSerialBits | serial;
}
constexpr std::uint64_t node_origin(NodeId id) noexcept { return id >> kNodeSerialBits; }
constexpr bool is_pinned(NodeId id) noexcept { return node_origin(id) == kPinnedOrigin; }

template <class Policy>
class BasicNodeRegistry {
 public:
  using Tree = BasicLandmarkTree<Policy>;

  // New names get origin `origin` (a rank + 1; not kPinnedOrigin).
  BasicNodeRegistry(NodeHeap& heap, std::uint64_t origin) : heap_(&heap), origin_(origin) {}
  BasicNodeRegistry(const BasicNodeRegistry&) = delete;
  BasicNodeRegistry& operator=(const BasicNodeRegistry&) = delete;
  ~BasicNodeRegistry();

  // Names every node of `tree` not named yet with pinned ids, children first, in a fixed walk
  // order: processes that pin equal trees in the same order give them the same ids.
  void pin(const Tree& tree);
  // Drops every pinned node (a new prior replaces the old one on every process at once).
  void unpin() noexcept;

  // Releases the nodes the last sweep retired, then retires the named nodes that only the
  // registry and other retiring nodes hold, and returns their ids (ascending). Pinned nodes
  // never retire.
  std::vector<NodeId> sweep();

  std::size_t named() const noexcept { return by_node_.size(); }
  std::size_t retiring() const noexcept { return retiring_.size(); }

 private:
  template <class>
  friend class BasicTreeGraphWriter;
  template <class>
  friend class BasicTreeGraphReader;
  using Node = typename Tree::Node;
  using Inner = typename Tree::Inner;

  struct Entry {
    NodeId id;
    std::uint64_t base;  // the first slot the node covers
    std::uint32_t count;  // landmarks below
    std::uint32_t height;
  };
  struct Named {
    Node* node;
    Entry entry;
  };

  // The id of a named (not retiring) node, or nullptr.
  const NodeId* find(const Node* node) const noexcept;
  // A node by id, or nullptr; a retiring node is named again (a message put it back in a tree,
  // and its sender lists it).
  const Named* hold(NodeId id);
  // Names `node` `id` and holds a reference to it. REQUIRES: neither is named yet.
  void add(Node* node, std::uint32_t height, std::uint64_t base, std::uint32_t count, NodeId id);
  NodeId fresh() noexcept { return node_id(origin_, next_serial_++); }
  void pin_node(Node* node, std::uint32_t height, std::uint64_t base);

  NodeHeap* heap_;
  std::uint64_t origin_;
  std::uint64_t next_serial_ = 0;
  std::uint64_t next_pinned_ = 0;
  std::unordered_map<NodeId, Named> by_id_;
  std::unordered_map<const Node*, NodeId> by_node_;
  std::unordered_map<NodeId, Named> retiring_;
};

using NodeRegistry = BasicNodeRegistry<DefaultTreePolicy>;

}  // namespace fastslam::memory

#include "memory/internal/node_registry_impl.h"
