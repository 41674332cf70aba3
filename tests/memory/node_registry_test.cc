// Node names and the linked node graph (memory/node_registry.h, memory/tree_graph.h's linked
// form) between two heaps standing for two ranks, against oracles: every tree read equals a
// std::map copy of the tree sent; a message carries exactly the nodes the receiver lacks (the
// distinct-node counts of the unlinked writer); a sweep retires exactly the named nodes no tree
// holds (the heap's live nodes afterwards equal the distinct nodes of the trees kept); retired
// names resolve until the next sweep; pinned names agree between heaps and never retire; bad
// linked records are refused by name and leak nothing.
#include "memory/node_registry.h"

#include <cstdint>
#include <random>
#include <sstream>
#include <string>
#include <unordered_set>
#include <vector>

#include <gtest/gtest.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/tree_graph.h"
#include "tests/memory/graph_records.h"
#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

using testing::Oracle;
using testing::same_contents;
using testing::sized;
using Names = std::unordered_set<NodeId>;

Oracle oracle_of(const LandmarkTree& tree) {
  Oracle oracle;
  for (const auto [slot, landmark] : tree) oracle[slot] = landmark;
  return oracle;
}

// A particle set's maps: copies of `from` (or of one fresh map) changed by a few edits, inserts
// and erases each, as a scan and a resampling leave them.
std::vector<LandmarkTree> next_set(NodeHeap& heap, std::mt19937_64& rng,
                                   const std::vector<LandmarkTree>& from, int count,
                                   int landmarks) {
  std::vector<LandmarkTree> trees;
  if (from.empty()) {
    LandmarkTree first(heap);
    for (int k = 0; k < landmarks; ++k) first.insert(testing::random_landmark(rng, k));
    trees.push_back(first);
  }
  while (static_cast<int>(trees.size()) < count) {
    LandmarkTree tree = from.empty() ? trees[rng() % trees.size()] : from[rng() % from.size()];
    for (int c = static_cast<int>(rng() % 4); c > 0; --c) {
      testing::random_scan_change(tree, rng, 7000 + c);
    }
    trees.push_back(tree);
  }
  return trees;
}

// The distinct nodes of a set of trees (the unlinked writer writes each once).
std::uint64_t distinct_nodes(const std::vector<LandmarkTree>& a,
                             const std::vector<LandmarkTree>& b = {}) {
  std::ostringstream sink;
  TreeGraphWriter writer(sink);
  for (const LandmarkTree& t : a) writer.write(t);
  for (const LandmarkTree& t : b) writer.write(t);
  return writer.nodes_written();
}

// One rank's message: the trees in the linked form for a receiver holding `held`, which then
// also lists what the message named.
std::string send(NodeRegistry& registry, Names& held, const std::vector<LandmarkTree>& trees,
                 std::uint64_t* records = nullptr) {
  std::ostringstream out;
  TreeGraphWriter writer(out, registry, held);
  for (const LandmarkTree& t : trees) writer.write(t);
  held.insert(writer.named().begin(), writer.named().end());
  if (records != nullptr) *records = writer.named().size();
  return out.str();
}

std::vector<LandmarkTree> receive(const std::string& bytes, NodeHeap& heap, NodeRegistry& registry,
                                  std::size_t count, Names* from_sender = nullptr) {
  std::istringstream in(bytes);
  TreeGraphReader reader(in, heap, registry);
  std::vector<LandmarkTree> trees;
  for (std::size_t i = 0; i < count; ++i) trees.push_back(reader.read([](Slot, const Landmark&) {}));
  reader.finish();
  if (from_sender != nullptr) from_sender->insert(reader.named().begin(), reader.named().end());
  return trees;
}

void expect_same(const std::vector<LandmarkTree>& back, const std::vector<LandmarkTree>& sent) {
  ASSERT_EQ(back.size(), sent.size());
  for (std::size_t i = 0; i < sent.size(); ++i) {
    EXPECT_TRUE(same_contents(back[i], oracle_of(sent[i]))) << "tree " << i;
    for (std::size_t j = 0; j < i; ++j) {
      EXPECT_EQ(back[i].shares_root_with(back[j]), sent[i].shares_root_with(sent[j]));
    }
  }
}

class NodeRegistryTest
    : public testing::HeapLeakCheck<testing::Config<DefaultTreePolicy, PoolHeap>> {
 protected:
  PoolHeap other_heap_;  // the receiving rank's
  void TearDown() override {
    HeapLeakCheck::TearDown();
    EXPECT_EQ(other_heap_.stats().live_nodes, 0) << "nodes leaked on the receiving side";
  }
};

TEST_F(NodeRegistryTest, MessagesCarryExactlyTheNodesTheReceiverLacks) {
  for (int trial = 0; trial < sized(10, 3); ++trial) {
    std::mt19937_64 rng(trial);
    NodeRegistry a(heap_, 1), b(other_heap_, 2);
    Names held_by_b;  // a's list
    std::vector<LandmarkTree> sent = next_set(heap_, rng, {}, 20, 1000);
    std::uint64_t records = 0;
    std::vector<LandmarkTree> back =
        receive(send(a, held_by_b, sent, &records), other_heap_, b, sent.size());
    expect_same(back, sent);
    EXPECT_EQ(records, distinct_nodes(sent)) << "a first message carries every node";
    EXPECT_EQ(b.named(), records);
    for (int round = 0; round < 4; ++round) {
      std::vector<LandmarkTree> later = next_set(heap_, rng, sent, 20, 0);
      const std::string bytes = send(a, held_by_b, later, &records);
      EXPECT_EQ(records, distinct_nodes(sent, later) - distinct_nodes(sent))
          << "trial " << trial << ", round " << round << ": only the nodes new since";
      std::ostringstream whole;
      TreeGraphWriter unlinked(whole);
      for (const LandmarkTree& t : later) unlinked.write(t);
      EXPECT_LT(bytes.size() * 4, whole.str().size());
      std::vector<LandmarkTree> got = receive(bytes, other_heap_, b, later.size());
      expect_same(got, later);
      // The receiver holds what it was sent, each node once, all named.
      EXPECT_EQ(other_heap_.stats().live_nodes, static_cast<std::int64_t>(b.named()));
      sent = std::move(later);
      back = std::move(got);
    }
  }
}

TEST_F(NodeRegistryTest, SweepRetiresExactlyTheNamedNodesNoTreeHolds) {
  std::mt19937_64 rng(11);
  NodeRegistry a(heap_, 1);
  Names held;
  std::vector<LandmarkTree> trees = next_set(heap_, rng, {}, 40, 400);
  send(a, held, trees);  // names every node
  const std::uint64_t all = distinct_nodes(trees);
  ASSERT_EQ(a.named(), all);
  EXPECT_TRUE(a.sweep().empty()) << "every named node is in a tree";
  trees.erase(trees.begin() + 15, trees.end());
  const std::uint64_t kept = distinct_nodes(trees);
  const std::vector<NodeId> gone = a.sweep();
  EXPECT_EQ(gone.size(), all - kept);
  EXPECT_EQ(a.named(), kept);
  EXPECT_EQ(a.retiring(), all - kept);
  EXPECT_EQ(heap_.stats().live_nodes, static_cast<std::int64_t>(all)) << "retiring, not freed";
  EXPECT_TRUE(a.sweep().empty());
  EXPECT_EQ(a.retiring(), 0u);
  EXPECT_EQ(heap_.stats().live_nodes, static_cast<std::int64_t>(kept));
  for (const NodeId id : gone) EXPECT_EQ(node_origin(id), 1u);
  trees.clear();
  EXPECT_EQ(a.sweep().size(), kept);
  a.sweep();
  EXPECT_EQ(heap_.stats().live_nodes, 0);
}

TEST_F(NodeRegistryTest, RetiredNamesResolveUntilTheNextSweep) {
  std::mt19937_64 rng(12);
  NodeRegistry a(heap_, 1), b(other_heap_, 2);
  Names held_by_b;
  std::vector<LandmarkTree> sent = next_set(heap_, rng, {}, 10, 200);
  std::vector<LandmarkTree> back = receive(send(a, held_by_b, sent), other_heap_, b, sent.size());
  back.clear();
  EXPECT_EQ(b.sweep().size(), distinct_nodes(sent));
  // a has not heard yet: every tree goes as one held record, and still resolves; the roots
  // are in trees again, so b names them again.
  std::uint64_t records = 1;
  back = receive(send(a, held_by_b, sent, &records), other_heap_, b, sent.size());
  EXPECT_EQ(records, 0u);
  expect_same(back, sent);
  std::uint64_t roots = 0;
  for (std::size_t i = 0; i < sent.size(); ++i) {
    bool repeated = false;
    for (std::size_t j = 0; j < i; ++j) repeated = repeated || sent[i].shares_root_with(sent[j]);
    roots += repeated ? 0 : 1;
  }
  EXPECT_EQ(b.named(), roots);
  EXPECT_TRUE(b.sweep().empty()) << "the named roots are in trees";
  expect_same(back, sent);  // the retirees went; the trees keep their nodes
  EXPECT_EQ(b.named(), roots);
  // Too late now for the nodes below the roots: a changed map refers to them and is refused by
  // name, leaking nothing.
  sent[0].edit((*sent[0].begin()).slot).x += 1.0;
  try {
    receive(send(a, held_by_b, {sent[0]}), other_heap_, b, 1);
    ADD_FAILURE() << "a name retired two sweeps ago resolved";
  } catch (const TreeGraphError& e) {
    EXPECT_NE(std::string(e.what()).find("is not held here"), std::string::npos) << e.what();
  }
}

TEST_F(NodeRegistryTest, PinnedNamesAgreeEverywhereAndNeverRetire) {
  std::mt19937_64 rng(13);
  LandmarkTree prior_a(heap_), prior_b(other_heap_);
  for (int k = 0; k < 500; ++k) {
    const Landmark l = testing::random_landmark(rng, k);
    prior_a.insert(l);
    prior_b.insert(l);
  }
  NodeRegistry a(heap_, 1), b(other_heap_, 2);
  a.pin(prior_a);
  b.pin(prior_b);
  const std::uint64_t prior_nodes = distinct_nodes({prior_a});
  EXPECT_EQ(a.named(), prior_nodes);
  Names held_by_b;  // empty: the pinned nodes need no list
  std::vector<LandmarkTree> sent = next_set(heap_, rng, {prior_a}, 8, 0);
  std::uint64_t records = 0;
  const std::vector<LandmarkTree> back =
      receive(send(a, held_by_b, sent, &records), other_heap_, b, sent.size());
  expect_same(back, sent);
  EXPECT_EQ(records, distinct_nodes({prior_a}, sent) - prior_nodes);
  sent.clear();
  prior_a = LandmarkTree(heap_);
  EXPECT_EQ(a.sweep().size(), records) << "only the sent paths retire";
  a.sweep();
  EXPECT_EQ(heap_.stats().live_nodes, static_cast<std::int64_t>(prior_nodes));
  a.unpin();
  EXPECT_EQ(heap_.stats().live_nodes, 0);
}

TEST_F(NodeRegistryTest, ANameHeldAlreadyKeepsItsNode) {
  std::mt19937_64 rng(14);
  NodeRegistry a(heap_, 1), b(other_heap_, 2);
  Names held_by_b, told_nothing;
  const std::vector<LandmarkTree> sent = next_set(heap_, rng, {}, 12, 200);
  const std::vector<LandmarkTree> first = receive(send(a, held_by_b, sent), other_heap_, b, sent.size());
  const std::int64_t live = other_heap_.stats().live_nodes;
  // As from a third rank that does not know b holds them: whole records, names b holds.
  const std::vector<LandmarkTree> second =
      receive(send(a, told_nothing, sent), other_heap_, b, sent.size());
  expect_same(second, sent);
  EXPECT_EQ(other_heap_.stats().live_nodes, live) << "the copies read were let go";
  for (std::size_t i = 0; i < sent.size(); ++i) EXPECT_TRUE(second[i].shares_root_with(first[i]));
}

using Linked = testing::GraphRecords;

TEST_F(NodeRegistryTest, BadLinkedRecordsAreRefusedByNameAndLeakNothing) {
  NodeRegistry b(other_heap_, 2);
  const NodeId known = node_id(1, 7);
  {
    std::istringstream in(Linked().leaf(8, 3).name(known).tree(0, kNoNode).bytes());
    TreeGraphReader reader(in, other_heap_, b);
    EXPECT_TRUE(reader.read([](Slot, const Landmark&) {}).empty());
  }
  ASSERT_EQ(b.named(), 1u);
  const std::vector<std::pair<Linked, std::string>> cases = {
      {Linked().held(0, 0, node_id(1, 8)), "node " + std::to_string(node_id(1, 8)) +
                                               " is not held here"},
      {Linked().held(1, 8, known), "has height 0 and base 8, not 1 and 8"},
      {Linked().held(0, 12, known), "has height 0 and base 8, not 0 and 12"},
      {Linked().leaf(0, 1).name(node_id(kPinnedOrigin, 3)), "named as pinned"},
      {Linked().leaf(8, 1).name(known), "differs from the node of that name"},
      {Linked().held(0, 8, known).tree(0, 1), "root is not an earlier node"},
  };
  for (const auto& [graph, message] : cases) {
    std::istringstream in(graph.bytes());
    TreeGraphReader reader(in, other_heap_, b);
    try {
      reader.read([](Slot, const Landmark&) {});
      ADD_FAILURE() << message << ": accepted";
    } catch (const TreeGraphError& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  }
  // Every truncation of a real message.
  NodeRegistry a(heap_, 1);
  Names held;
  std::mt19937_64 rng(15);
  const std::vector<LandmarkTree> trees = next_set(heap_, rng, {}, 4, 30);
  const std::string bytes = send(a, held, trees);
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    NodeRegistry fresh(other_heap_, 3);
    std::istringstream in(bytes.substr(0, n));
    TreeGraphReader reader(in, other_heap_, fresh);
    try {
      for (std::size_t i = 0; i < trees.size(); ++i) reader.read([](Slot, const Landmark&) {});
      FAIL() << "a message cut at byte " << n << " of " << bytes.size() << " was read";
    } catch (const TreeGraphError&) {
      EXPECT_TRUE(reader.truncated()) << "cut at " << n;
    }
  }
  EXPECT_EQ(other_heap_.stats().live_nodes, 1) << "only b's named leaf";
}

}  // namespace
}  // namespace fastslam::memory
