// Template definitions of memory/node_registry.h; not API, include that header instead.
#pragma once

#include <algorithm>
#include <bit>

namespace fastslam::memory {

template <class P>
BasicNodeRegistry<P>::~BasicNodeRegistry() {
  for (const auto& [id, n] : by_id_) Tree::release(n.node, n.entry.height, *heap_);
  for (const auto& [id, n] : retiring_) Tree::release(n.node, n.entry.height, *heap_);
}

template <class P>
const NodeId* BasicNodeRegistry<P>::find(const Node* node) const noexcept {
  const auto it = by_node_.find(node);
  return it == by_node_.end() ? nullptr : &it->second;
}

template <class P>
auto BasicNodeRegistry<P>::hold(NodeId id) -> const Named* {
  if (const auto it = by_id_.find(id); it != by_id_.end()) return &it->second;
  const auto it = retiring_.find(id);
  if (it == retiring_.end()) return nullptr;
  by_id_.reserve(by_id_.size() + 1);  // nothing throws once the entry has moved
  by_node_.reserve(by_node_.size() + 1);
  const auto named = by_id_.insert(retiring_.extract(it)).position;
  by_node_.emplace(named->second.node, id);
  return &named->second;
}

template <class P>
void BasicNodeRegistry<P>::add(Node* node, std::uint32_t height, std::uint64_t base,
                               std::uint32_t count, NodeId id) {
  const auto named = by_id_.emplace(id, Named{node, Entry{id, base, count, height}}).first;
  try {
    by_node_.emplace(node, id);
  } catch (...) {
    by_id_.erase(named);
    throw;
  }
  node->refs.acquire();
}

template <class P>
void BasicNodeRegistry<P>::pin_node(Node* node, std::uint32_t height, std::uint64_t base) {
  if (find(node) != nullptr) return;
  std::uint32_t count = 0;
  if (height == 0) {
    count = static_cast<std::uint32_t>(std::popcount(node->aux));
  } else {
    auto* inner = static_cast<Inner*>(node);
    for (unsigned i = 0; i < Tree::kInnerWidth; ++i) {
      if (inner->child[i] != nullptr) {
        pin_node(inner->child[i], height - 1, base + i * Tree::capacity_at(height - 1));
      }
    }
    count = node->aux;
  }
  add(node, height, base, count, node_id(kPinnedOrigin, next_pinned_++));
}

template <class P>
void BasicNodeRegistry<P>::pin(const Tree& tree) {
  if (tree.root_ != nullptr) pin_node(tree.root_, tree.height_, 0);
}

template <class P>
void BasicNodeRegistry<P>::unpin() noexcept {
  for (auto it = by_id_.begin(); it != by_id_.end();) {
    if (!is_pinned(it->first)) {
      ++it;
      continue;
    }
    by_node_.erase(it->second.node);
    Tree::release(it->second.node, it->second.entry.height, *heap_);
    it = by_id_.erase(it);
  }
}

template <class P>
std::vector<NodeId> BasicNodeRegistry<P>::sweep() {
  for (const auto& [id, n] : retiring_) Tree::release(n.node, n.entry.height, *heap_);
  retiring_.clear();
  // A node retires when its only references are the registry's and its retiring parents'; a
  // retiring node still holds one reference to each of its children.
  std::vector<NodeId> work;
  for (const auto& [id, n] : by_id_) {
    if (!is_pinned(id) && n.node->refs.use_count() == 1) work.push_back(id);
  }
  std::unordered_map<const Node*, std::uint32_t> held_by_retiring;
  std::vector<NodeId> gone;
  while (!work.empty()) {
    const auto it = by_id_.find(work.back());
    work.pop_back();
    const Named n = it->second;
    by_id_.erase(it);
    by_node_.erase(n.node);
    retiring_.emplace(n.entry.id, n);
    gone.push_back(n.entry.id);
    if (n.entry.height == 0) continue;
    for (Node* child : static_cast<Inner*>(n.node)->child) {
      if (child == nullptr) continue;
      const NodeId* c = find(child);
      if (c == nullptr || is_pinned(*c)) continue;
      const std::uint32_t by_retiring = ++held_by_retiring[child];
      if (child->refs.use_count() == 1 + by_retiring) work.push_back(*c);
    }
  }
  std::sort(gone.begin(), gone.end());
  return gone;
}

}  // namespace fastslam::memory
