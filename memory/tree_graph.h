// Many landmark trees written and read back as one graph of nodes, each node once, so a set of
// maps that share subtrees (a particle set after resampling) costs its distinct nodes, not
// particles x landmarks, and reads back with exactly the sharing it had: the same nodes, the
// same live-node count. Used by the filter's saved state (engine/internal/state_io.cc).
//
// Format, native byte order; a record per node, children before parents, then a record per tree:
//   leaf   u8 0, u32 base slot, u32 occupancy mask, then one Landmark per set bit, lowest first
//   inner  u8 1, u8 height, u32 base slot, u32 child mask, then a u32 node id per set bit
//   tree   u8 2, u8 height, u32 root id (kNoNode: the empty tree)
// Node ids number the node records from 0 in the order written, over the whole graph.
//
// The linked form (the particle exchange between processes) names nodes through a
// NodeRegistry (memory/node_registry.h) on both sides: every node record is followed by its
// u64 name, and a node the receiver holds already is one record instead of its subtree:
//   held   u8 3, u8 height, u32 base slot, u64 name
// The writer sends as held the pinned nodes and those named in the receiver's set it is given;
// it names the nodes it writes that have no name yet. The reader resolves held names in its
// registry and names the nodes it reads (a name it holds already keeps its node).
//
// The reader trusts nothing: a record must be well formed (a known tag, no bits beyond the
// node's width, no empty node), a child must be an earlier node one level lower whose base slot
// is its place under the parent, a root must have base 0 and the tree's height, every landmark
// passes the caller's check (given its slot), and finish() refuses nodes no tree holds. Errors
// throw TreeGraphError naming the record. A node is allocated only after its record was read,
// so memory grows at most ~10x as fast as the input (a leaf record, never empty, is >= 73 bytes
// for a 264-byte node; an inner record >= 14 bytes for a 136-byte node).
//
// Ownership: the writer keeps the addresses of the nodes it wrote, so the trees must stay
// alive and unchanged while it is used; the reader holds a reference to every node it made
// until it is destroyed. Thread safety: thread-compatible. Costs: O(distinct nodes) time and
// memory for either side (a hash map of node addresses in the writer).
#pragma once

#include <algorithm>
#include <cstdint>
#include <istream>
#include <ostream>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "memory/landmark_tree.h"
#include "memory/node_registry.h"

namespace fastslam::memory {

class TreeGraphError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

inline constexpr std::uint32_t kNoNode = 0xffffffffu;

template <class Policy>
class BasicTreeGraphWriter {
 public:
  using Tree = BasicLandmarkTree<Policy>;

  using Registry = BasicNodeRegistry<Policy>;

  explicit BasicTreeGraphWriter(std::ostream& out) : out_(&out) {}
  // The linked form, for a receiver holding the pinned nodes and those named in
  // `receiver_holds`; both must outlive the writer.
  BasicTreeGraphWriter(std::ostream& out, Registry& registry,
                       const std::unordered_set<NodeId>& receiver_holds)
      : out_(&out), registry_(&registry), receiver_holds_(&receiver_holds) {}

  // Writes the nodes of `tree` not written yet, then its tree record. Stream errors are the
  // stream's state, for the caller to check.
  void write(const Tree& tree);

  // Node records and held records written.
  std::uint64_t nodes_written() const noexcept { return ids_.size(); }
  // The linked form: the names of the node records written (the nodes the receiver will hold).
  const std::vector<NodeId>& named() const noexcept { return named_; }

 private:
  using Node = typename Tree::Node;
  std::uint32_t write_node(const Node* node, unsigned height, std::uint64_t base);

  std::ostream* out_;
  std::unordered_map<const Node*, std::uint32_t> ids_;
  Registry* registry_ = nullptr;
  const std::unordered_set<NodeId>* receiver_holds_ = nullptr;
  std::vector<NodeId> named_;
};

template <class Policy>
class BasicTreeGraphReader {
 public:
  using Tree = BasicLandmarkTree<Policy>;

  using Registry = BasicNodeRegistry<Policy>;

  // Nodes come from `heap`, which must outlive the trees read.
  BasicTreeGraphReader(std::istream& in, NodeHeap& heap) : in_(&in), heap_(&heap) {}
  // The linked form: held records resolve in `registry`, which names the nodes read.
  BasicTreeGraphReader(std::istream& in, NodeHeap& heap, Registry& registry)
      : in_(&in), heap_(&heap), registry_(&registry) {}
  BasicTreeGraphReader(const BasicTreeGraphReader&) = delete;
  BasicTreeGraphReader& operator=(const BasicTreeGraphReader&) = delete;
  ~BasicTreeGraphReader();

  // Reads node records up to the next tree record and returns that tree. check(slot, landmark)
  // is called once per landmark read and may throw to refuse it. Throws TreeGraphError on a
  // malformed or truncated graph (`truncated()` then says which), and what `check` or the heap
  // throws.
  template <class Check>
  Tree read(Check&& check);

  // Throws TreeGraphError when a node read is held by no tree read (an orphan record).
  void finish() const;

  // True when the last error was the stream running out.
  bool truncated() const noexcept { return truncated_; }
  // Node records and landmarks read so far: the input's size, for a caller's work bounds.
  std::uint64_t nodes_read() const noexcept { return made_.size(); }
  std::uint64_t landmarks_read() const noexcept { return landmarks_read_; }
  // The linked form: the names of the node records read.
  const std::vector<NodeId>& named() const noexcept { return named_; }

 private:
  using Node = typename Tree::Node;
  using Inner = typename Tree::Inner;
  using Leaf = typename Tree::Leaf;
  struct Made {
    Node* node;
    std::uint64_t base;
    std::uint32_t height;
    std::uint32_t count;  // landmarks below
  };

  template <class T>
  T get();
  [[noreturn]] void fail(const std::string& what) const;
  template <class Check>
  void read_leaf(Check& check);
  void read_inner();
  void read_held();
  // The linked form: reads the name of the node just read; a name held already replaces the
  // new node by the held one.
  void name_last();
  // Capacity for one more node record, grown geometrically (reserving size() + 1 each time
  // would copy the whole table at every node: quadratic in the nodes read).
  void room_for_one() {
    if (made_.size() == made_.capacity()) made_.reserve(std::max<std::size_t>(64, 2 * made_.size()));
  }

  std::istream* in_;
  NodeHeap* heap_;
  std::vector<Made> made_;  // every node read, in id order, one reference each
  std::uint64_t landmarks_read_ = 0;
  bool truncated_ = false;
  Registry* registry_ = nullptr;
  std::vector<NodeId> named_;
};

using TreeGraphWriter = BasicTreeGraphWriter<DefaultTreePolicy>;
using TreeGraphReader = BasicTreeGraphReader<DefaultTreePolicy>;

}  // namespace fastslam::memory

#include "memory/internal/tree_graph_impl.h"
