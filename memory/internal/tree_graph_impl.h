// Template definitions of memory/tree_graph.h; not API, include that header instead.
#pragma once

#include <bit>
#include <cstring>
#include <new>
#include <string>
#include <type_traits>
#include <utility>

namespace fastslam::memory {

namespace internal {
enum class GraphTag : std::uint8_t { kLeaf = 0, kInner = 1, kTree = 2, kHeld = 3 };

template <class T>
void put_raw(std::ostream& out, const T& value) {
  static_assert(std::is_trivially_copyable_v<T>);
  out.write(reinterpret_cast<const char*>(&value), sizeof(T));
}
}  // namespace internal

template <class P>
void BasicTreeGraphWriter<P>::write(const Tree& tree) {
  const std::uint32_t root =
      tree.root_ == nullptr ? kNoNode : write_node(tree.root_, tree.height_, 0);
  internal::put_raw(*out_, internal::GraphTag::kTree);
  internal::put_raw(*out_, static_cast<std::uint8_t>(tree.height_));
  internal::put_raw(*out_, root);
}

template <class P>
std::uint32_t BasicTreeGraphWriter<P>::write_node(const Node* node, unsigned height,
                                                  std::uint64_t base) {
  if (const auto found = ids_.find(node); found != ids_.end()) {
    return found->second;
  }
  const NodeId* name = registry_ == nullptr ? nullptr : registry_->find(node);
  if (name != nullptr && (is_pinned(*name) || receiver_holds_->contains(*name))) {
    internal::put_raw(*out_, internal::GraphTag::kHeld);
    internal::put_raw(*out_, static_cast<std::uint8_t>(height));
    internal::put_raw(*out_, static_cast<std::uint32_t>(base));
    internal::put_raw(*out_, *name);
    const auto id = static_cast<std::uint32_t>(ids_.size());
    ids_.emplace(node, id);
    return id;
  }
  if (height == 0) {
    const auto* leaf = static_cast<const typename Tree::Leaf*>(node);
    internal::put_raw(*out_, internal::GraphTag::kLeaf);
    internal::put_raw(*out_, static_cast<std::uint32_t>(base));
    internal::put_raw(*out_, node->aux);
    for (unsigned i = 0; i < Tree::kLeafWidth; ++i) {
      if (node->aux >> i & 1u) internal::put_raw(*out_, leaf->landmarks[i]);
    }
  } else {
    const auto* inner = static_cast<const typename Tree::Inner*>(node);
    std::uint32_t children[Tree::kInnerWidth];
    std::uint32_t mask = 0;
    for (unsigned i = 0; i < Tree::kInnerWidth; ++i) {
      if (inner->child[i] != nullptr) {
        children[i] = write_node(inner->child[i], height - 1,
                                 base + i * Tree::capacity_at(height - 1));
        mask |= 1u << i;
      }
    }
    internal::put_raw(*out_, internal::GraphTag::kInner);
    internal::put_raw(*out_, static_cast<std::uint8_t>(height));
    internal::put_raw(*out_, static_cast<std::uint32_t>(base));
    internal::put_raw(*out_, mask);
    for (unsigned i = 0; i < Tree::kInnerWidth; ++i) {
      if (mask >> i & 1u) internal::put_raw(*out_, children[i]);
    }
  }
  if (registry_ != nullptr) {
    NodeId named = 0;
    if (name != nullptr) {
      named = *name;
    } else {
      named = registry_->fresh();
      const std::uint32_t count =
          height == 0 ? static_cast<std::uint32_t>(std::popcount(node->aux)) : node->aux;
      registry_->add(const_cast<Node*>(node), height, base, count, named);
    }
    internal::put_raw(*out_, named);
    named_.push_back(named);
  }
  const auto id = static_cast<std::uint32_t>(ids_.size());
  ids_.emplace(node, id);
  return id;
}

template <class P>
BasicTreeGraphReader<P>::~BasicTreeGraphReader() {
  for (const Made& m : made_) Tree::release(m.node, m.height, *heap_);
}

template <class P>
void BasicTreeGraphReader<P>::fail(const std::string& what) const {
  throw TreeGraphError("map graph, node record " + std::to_string(made_.size()) + ": " + what);
}

template <class P>
template <class T>
T BasicTreeGraphReader<P>::get() {
  static_assert(std::is_trivially_copyable_v<T>);
  T value;
  in_->read(reinterpret_cast<char*>(&value), sizeof(T));
  if (!*in_) {
    truncated_ = true;
    fail("the input ends inside a record");
  }
  return value;
}

template <class P>
template <class Check>
auto BasicTreeGraphReader<P>::read(Check&& check) -> Tree {
  for (;;) {
    const auto tag = get<std::uint8_t>();
    if (tag == static_cast<std::uint8_t>(internal::GraphTag::kLeaf)) {
      read_leaf(check);
    } else if (tag == static_cast<std::uint8_t>(internal::GraphTag::kInner)) {
      read_inner();
    } else if (tag == static_cast<std::uint8_t>(internal::GraphTag::kHeld) &&
               registry_ != nullptr) {
      read_held();
      continue;
    } else if (tag == static_cast<std::uint8_t>(internal::GraphTag::kTree)) {
      break;
    } else {
      fail("unknown record tag " + std::to_string(tag));
    }
    if (registry_ != nullptr) name_last();
  }
  const auto height = get<std::uint8_t>();
  const auto root = get<std::uint32_t>();
  Tree tree(*heap_);
  if (root == kNoNode) {
    if (height != 0) fail("an empty tree of height " + std::to_string(height));
    return tree;
  }
  if (root >= made_.size()) fail("a tree's root is not an earlier node");
  const Made& m = made_[root];
  if (m.height != height || m.base != 0) {
    fail("a tree's root has height " + std::to_string(m.height) + " and base " +
         std::to_string(m.base) + ", not height " + std::to_string(height) + " and base 0");
  }
  m.node->refs.acquire();
  tree.root_ = m.node;
  tree.height_ = height;
  tree.size_ = m.count;
  return tree;
}

template <class P>
template <class Check>
void BasicTreeGraphReader<P>::read_leaf(Check& check) {
  const auto base = get<std::uint32_t>();
  const auto mask = get<std::uint32_t>();
  if (base % Tree::kLeafWidth != 0) fail("a leaf's base slot is not a multiple of its width");
  if (mask == 0 || (Tree::kLeafWidth < 32 && mask >> Tree::kLeafWidth != 0)) {
    fail("a leaf's occupancy is empty or beyond its width");
  }
  Landmark landmarks[Tree::kLeafWidth];
  for (unsigned i = 0; i < Tree::kLeafWidth; ++i) {
    if (mask >> i & 1u) {
      landmarks[i] = get<Landmark>();
      check(static_cast<Slot>(base + i), landmarks[i]);
    }
  }
  if (made_.size() >= kNoNode) fail("too many nodes");
  room_for_one();  // nothrow push_back below: the node is never lost
  auto* leaf = ::new (heap_->allocate(sizeof(Leaf))) Leaf();
  std::memcpy(static_cast<void*>(leaf->landmarks), landmarks, sizeof(landmarks));
  leaf->aux = mask;
  made_.push_back({leaf, base, 0, static_cast<std::uint32_t>(std::popcount(mask))});
  landmarks_read_ += static_cast<std::uint64_t>(std::popcount(mask));
}

template <class P>
void BasicTreeGraphReader<P>::read_inner() {
  const auto height = get<std::uint8_t>();
  const auto base = get<std::uint32_t>();
  const auto mask = get<std::uint32_t>();
  if (height == 0 || height > Tree::kMaxHeight) {
    fail("an inner node of height " + std::to_string(height));
  }
  const std::uint64_t child_capacity = Tree::capacity_at(height - 1u);
  if (base % Tree::capacity_at(height) != 0) {
    fail("an inner node's base slot is not a multiple of its capacity");
  }
  if (mask == 0 || (Tree::kInnerWidth < 32 && mask >> Tree::kInnerWidth != 0)) {
    fail("an inner node's children are none or beyond its width");
  }
  std::uint32_t children[Tree::kInnerWidth] = {};
  std::uint64_t count = 0;
  for (unsigned i = 0; i < Tree::kInnerWidth; ++i) {
    if ((mask >> i & 1u) == 0) continue;
    children[i] = get<std::uint32_t>();
    if (children[i] >= made_.size()) fail("a child is not an earlier node");
    const Made& c = made_[children[i]];
    if (c.height + 1u != height || c.base != base + i * child_capacity) {
      fail("child " + std::to_string(i) + " has height " + std::to_string(c.height) +
           " and base " + std::to_string(c.base) + ", not its place under the node");
    }
    count += c.count;
  }
  if (count > 0xffffffffu || made_.size() >= kNoNode) fail("too many landmarks or nodes");
  room_for_one();
  auto* inner = ::new (heap_->allocate(sizeof(Inner))) Inner();
  for (unsigned i = 0; i < Tree::kInnerWidth; ++i) {
    if (mask >> i & 1u) {
      inner->child[i] = made_[children[i]].node;
      inner->child[i]->refs.acquire();
    }
  }
  inner->aux = static_cast<std::uint32_t>(count);
  made_.push_back({inner, base, height, static_cast<std::uint32_t>(count)});
}

template <class P>
void BasicTreeGraphReader<P>::read_held() {
  const auto height = get<std::uint8_t>();
  const auto base = get<std::uint32_t>();
  const auto name = get<NodeId>();
  const auto* held = registry_->hold(name);
  if (held == nullptr) fail("node " + std::to_string(name) + " is not held here");
  if (held->entry.height != height || held->entry.base != base) {
    fail("held node " + std::to_string(name) + " has height " +
         std::to_string(held->entry.height) + " and base " + std::to_string(held->entry.base) +
         ", not " + std::to_string(height) + " and " + std::to_string(base));
  }
  if (made_.size() >= kNoNode) fail("too many nodes");
  room_for_one();
  held->node->refs.acquire();
  made_.push_back({held->node, base, height, held->entry.count});
}

template <class P>
void BasicTreeGraphReader<P>::name_last() {
  const auto name = get<NodeId>();
  Made& last = made_.back();
  if (is_pinned(name)) fail("a node record named as pinned (" + std::to_string(name) + ")");
  named_.push_back(name);
  const auto* held = registry_->hold(name);
  if (held == nullptr) {
    registry_->add(last.node, last.height, last.base, last.count, name);
    return;
  }
  if (held->entry.height != last.height || held->entry.base != last.base ||
      held->entry.count != last.count) {
    fail("node " + std::to_string(name) + " differs from the node of that name held here");
  }
  held->node->refs.acquire();
  Tree::release(std::exchange(last.node, held->node), last.height, *heap_);
}

template <class P>
void BasicTreeGraphReader<P>::finish() const {
  for (std::size_t id = 0; id < made_.size(); ++id) {
    if (made_[id].node->refs.unique()) {
      throw TreeGraphError("map graph: node record " + std::to_string(id) +
                           " is held by no tree");
    }
  }
}

}  // namespace fastslam::memory
