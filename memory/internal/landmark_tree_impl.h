// Template definitions of memory/landmark_tree.h; not API, include that header instead.
#pragma once

#include <algorithm>
#include <bit>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>

namespace fastslam::memory {

namespace internal {
[[noreturn]] void throw_empty_slot(Slot slot, std::size_t capacity, const char* operation);
[[noreturn]] void throw_held_slot(Slot slot, const char* operation);
}  // namespace internal

template <class P>
BasicLandmarkTree<P>::BasicLandmarkTree(const BasicLandmarkTree& other) noexcept
    : root_(other.root_), heap_(other.heap_), height_(other.height_), size_(other.size_) {
  if (root_ != nullptr) {
    root_->refs.acquire();
  }
}

template <class P>
BasicLandmarkTree<P>::BasicLandmarkTree(BasicLandmarkTree&& other) noexcept
    : root_(std::exchange(other.root_, nullptr)),
      heap_(other.heap_),
      height_(std::exchange(other.height_, 0)),
      size_(std::exchange(other.size_, 0)) {}

template <class P>
BasicLandmarkTree<P>& BasicLandmarkTree<P>::operator=(const BasicLandmarkTree& other) noexcept {
  if (this != &other) {
    if (other.root_ != nullptr) {
      other.root_->refs.acquire();
    }
    release(root_, height_, *heap_);
    root_ = other.root_;
    heap_ = other.heap_;
    height_ = other.height_;
    size_ = other.size_;
  }
  return *this;
}

template <class P>
BasicLandmarkTree<P>& BasicLandmarkTree<P>::operator=(BasicLandmarkTree&& other) noexcept {
  if (this != &other) {
    release(root_, height_, *heap_);
    root_ = std::exchange(other.root_, nullptr);
    heap_ = other.heap_;
    height_ = std::exchange(other.height_, 0);
    size_ = std::exchange(other.size_, 0);
  }
  return *this;
}

template <class P>
BasicLandmarkTree<P>::~BasicLandmarkTree() {
  release(root_, height_, *heap_);
}

template <class P>
void BasicLandmarkTree<P>::clear() noexcept {
  release(std::exchange(root_, nullptr), height_, *heap_);
  height_ = 0;
  size_ = 0;
}

template <class P>
std::uint64_t BasicLandmarkTree<P>::capacity() const noexcept {
  return root_ == nullptr ? 0 : capacity_at(height_);
}

template <class P>
std::uint32_t BasicLandmarkTree<P>::live_of(const Node* node, unsigned height) noexcept {
  if (node == nullptr) {
    return 0;
  }
  return height == 0 ? static_cast<std::uint32_t>(std::popcount(node->aux)) : node->aux;
}

template <class P>
const Landmark* BasicLandmarkTree<P>::find(Slot slot) const noexcept {
  if (root_ == nullptr || slot >= capacity_at(height_)) {
    return nullptr;
  }
  const Node* node = root_;
  for (unsigned h = height_; h > 0; --h) {
    node = static_cast<const Inner*>(node)->child[child_index(slot, h)];
    if (node == nullptr) {
      return nullptr;
    }
  }
  const unsigned i = slot & (kLeafWidth - 1);
  if ((node->aux >> i & 1u) == 0) {
    return nullptr;
  }
  return &static_cast<const Leaf*>(node)->landmarks[i];
}

template <class P>
const Landmark& BasicLandmarkTree<P>::at(Slot slot) const {
  const Landmark* landmark = find(slot);
  if (landmark == nullptr) {
    internal::throw_empty_slot(slot, capacity(), "at");
  }
  return *landmark;
}

template <class P>
template <class T, class... Args>
T* BasicLandmarkTree<P>::make(Args&&... args) {
  void* block = heap_->allocate(sizeof(T));
  return ::new (block) T(std::forward<Args>(args)...);
}

template <class P>
auto BasicLandmarkTree<P>::own(Node* node, unsigned height) -> Node* {
  if (node == nullptr) {
    return height == 0 ? static_cast<Node*>(make<Leaf>()) : make<Inner>();
  }
  if (node->refs.unique()) {
    return node;
  }
  Node* copy;
  if (height == 0) {
    copy = make<Leaf>(*static_cast<const Leaf*>(node));
  } else {
    auto* inner = make<Inner>(*static_cast<const Inner*>(node));
    for (Node* child : inner->child) {
      if (child != nullptr) {
        child->refs.acquire();
      }
    }
    copy = inner;
  }
  release(node, height, *heap_);
  return copy;
}

template <class P>
void BasicLandmarkTree<P>::free_node(Node* node, unsigned height, NodeHeap& heap) noexcept {
  if (height == 0) {
    static_cast<Leaf*>(node)->~Leaf();
    heap.deallocate(node, sizeof(Leaf));
  } else {
    static_cast<Inner*>(node)->~Inner();
    heap.deallocate(node, sizeof(Inner));
  }
}

template <class P>
void BasicLandmarkTree<P>::release(Node* node, unsigned height, NodeHeap& heap) noexcept {
  if (node == nullptr || !node->refs.release()) {
    return;
  }
  // Depth-first with an explicit stack: at most kInnerWidth - 1 pending siblings per level.
  struct Pending {
    Node* node;
    unsigned height;
  };
  std::array<Pending, kInnerWidth * kMaxHeight + 1> stack;
  std::size_t top = 0;
  stack[top++] = {node, height};
  while (top > 0) {
    const Pending next = stack[--top];
    if (next.height > 0) {
      auto* inner = static_cast<Inner*>(next.node);
      for (Node* child : inner->child) {
        if (child != nullptr && child->refs.release()) {
          stack[top++] = {child, next.height - 1};
        }
      }
    }
    free_node(next.node, next.height, heap);
  }
}

template <class P>
auto BasicLandmarkTree<P>::own_path(Slot slot, std::array<Inner*, kMaxHeight>& path) -> Leaf* {
  // A unique node is taken as is without a call: every level of every update asks.
  if (root_ == nullptr || !root_->refs.unique()) {
    root_ = own(root_, height_);
  }
  Node* node = root_;
  for (unsigned h = height_; h > 0; --h) {
    auto* inner = static_cast<Inner*>(node);
    path[height_ - h] = inner;
    Node*& link = inner->child[child_index(slot, h)];
    if (link == nullptr || !link->refs.unique()) {
      link = own(link, h - 1);
    }
    node = link;
  }
  return static_cast<Leaf*>(node);
}

template <class P>
Landmark& BasicLandmarkTree<P>::edit(Slot slot) {
  if (find(slot) == nullptr) {
    internal::throw_empty_slot(slot, capacity(), "edit");
  }
  std::array<Inner*, kMaxHeight> path;
  Leaf* leaf = own_path(slot, path);
  return leaf->landmarks[slot & (kLeafWidth - 1)];
}

template <class P>
std::uint64_t BasicLandmarkTree<P>::lowest_free_slot() const noexcept {
  if (root_ == nullptr) {
    return 0;
  }
  const std::uint64_t cap = capacity_at(height_);
  if (live_of(root_, height_) == cap) {
    return cap;
  }
  const Node* node = root_;
  std::uint64_t base = 0;
  for (unsigned h = height_; h > 0; --h) {
    const auto* inner = static_cast<const Inner*>(node);
    const std::uint64_t child_cap = capacity_at(h - 1);
    unsigned i = 0;
    while (inner->child[i] != nullptr && live_of(inner->child[i], h - 1) == child_cap) {
      ++i;
    }
    base += i * child_cap;
    node = inner->child[i];
    if (node == nullptr) {
      return base;
    }
  }
  return base + static_cast<unsigned>(std::countr_one(node->aux));
}

template <class P>
Slot BasicLandmarkTree<P>::insert(const Landmark& landmark) {
  std::uint64_t slot = lowest_free_slot();
  if (root_ != nullptr && slot == capacity_at(height_)) {
    // Full: a new root above the old one; the old root becomes its first child.
    if (height_ + 1 > kMaxHeight) {
      throw std::length_error("LandmarkTree::insert: 2^32 slots used");
    }
    Inner* top = make<Inner>();
    top->child[0] = root_;
    top->aux = size_;
    root_ = top;
    ++height_;
  }
  std::array<Inner*, kMaxHeight> path;
  Leaf* leaf;
  try {
    leaf = own_path(static_cast<Slot>(slot), path);
  } catch (...) {
    prune(static_cast<Slot>(slot));
    throw;
  }
  const unsigned i = static_cast<unsigned>(slot) & (kLeafWidth - 1);
  leaf->landmarks[i] = landmark;
  leaf->aux |= 1u << i;
  for (unsigned k = 0; k < height_; ++k) {
    ++path[k]->aux;
  }
  ++size_;
  return static_cast<Slot>(slot);
}

template <class P>
void BasicLandmarkTree<P>::insert_at(Slot slot, const Landmark& landmark) {
  if (find(slot) != nullptr) {
    internal::throw_held_slot(slot, "insert_at");
  }
  if (root_ == nullptr) {
    height_ = 0;  // own_path creates the nodes of the path only
    while (capacity_at(height_) <= slot) ++height_;
  }
  std::array<Inner*, kMaxHeight> path;
  Leaf* leaf;
  try {
    // New roots above the old one, whose first child it becomes, until `slot` is covered.
    while (capacity_at(height_) <= slot) {
      Inner* top = make<Inner>();
      top->child[0] = root_;
      top->aux = size_;
      root_ = top;
      ++height_;
    }
    leaf = own_path(slot, path);
  } catch (...) {
    prune(slot);  // frees the empty path and collapses the new roots
    throw;
  }
  const unsigned i = slot & (kLeafWidth - 1);
  leaf->landmarks[i] = landmark;
  leaf->aux |= 1u << i;
  for (unsigned k = 0; k < height_; ++k) {
    ++path[k]->aux;
  }
  ++size_;
}

template <class P>
void BasicLandmarkTree<P>::erase(Slot slot) {
  if (find(slot) == nullptr) {
    internal::throw_empty_slot(slot, capacity(), "erase");
  }
  std::array<Inner*, kMaxHeight> path;
  Leaf* leaf = own_path(slot, path);  // on bad_alloc: same contents, nothing to undo
  leaf->aux &= ~(1u << (slot & (kLeafWidth - 1)));
  for (unsigned k = 0; k < height_; ++k) {
    --path[k]->aux;
  }
  --size_;
  prune(slot);
}

template <class P>
void BasicLandmarkTree<P>::prune(Slot slot) noexcept {
  // Bottom-up over the path to `slot`: an owned node that holds nothing is unlinked and freed.
  // Only the nodes of this path can be empty, and they are owned (own_path made them so).
  // After a failed insert the path may stop early (own_path threw creating a missing node), so
  // only the links actually reached are visited.
  std::array<Node**, kMaxHeight + 1> links;
  Node** link = &root_;
  links[0] = link;
  unsigned reached = 1;  // links[0, reached) are set
  for (unsigned h = height_; h > 0 && *link != nullptr; --h) {
    link = &static_cast<Inner*>(*link)->child[child_index(slot, h)];
    links[reached++] = link;
  }
  for (unsigned depth = reached; depth-- > 0;) {
    Node** at = links[depth];
    const unsigned h = height_ - depth;
    if (*at != nullptr && live_of(*at, h) == 0) {
      release(*at, h, *heap_);
      *at = nullptr;
    }
  }
  // Collapse top levels whose only child is the first one: slots keep their meaning.
  while (root_ != nullptr && height_ > 0) {
    auto* top = static_cast<Inner*>(root_);
    bool only_first = true;
    for (unsigned i = 1; i < kInnerWidth; ++i) {
      only_first = only_first && top->child[i] == nullptr;
    }
    if (!only_first || !top->refs.unique()) {
      break;
    }
    Node* first = top->child[0];
    top->child[0] = nullptr;
    free_node(top, height_, *heap_);
    root_ = first;
    --height_;
  }
  if (root_ == nullptr) {
    height_ = 0;
  }
}

template <class P>
template <class Visit>
bool BasicLandmarkTree<P>::diff(const BasicLandmarkTree& other, Visit&& visit,
                                std::uint64_t& steps) const {
  return diff_nodes(root_, height_, other.root_, other.height_, 0, visit, steps);
}

template <class P>
template <class Visit>
bool BasicLandmarkTree<P>::diff_nodes(const Node* a, unsigned height_a, const Node* b,
                                      unsigned height_b, std::uint64_t base, Visit& visit,
                                      std::uint64_t& steps) {
  if ((a == b && height_a == height_b) || (a == nullptr && b == nullptr)) {
    return true;  // shared, or both empty
  }
  if (steps == 0) {
    return false;
  }
  --steps;
  if (height_a != height_b) {
    // The shorter tree's slots are the taller one's first child's (roots grow above child 0).
    const bool a_taller = height_a > height_b;
    const Node* tall = a_taller ? a : b;
    const unsigned h = a_taller ? height_a : height_b;
    for (unsigned i = 0; i < kInnerWidth; ++i) {
      const Node* child = tall == nullptr ? nullptr : static_cast<const Inner*>(tall)->child[i];
      const Node* other = i == 0 ? (a_taller ? b : a) : nullptr;
      const unsigned other_height = i == 0 ? (a_taller ? height_b : height_a) : h - 1;
      const std::uint64_t at = base + i * capacity_at(h - 1);
      const bool done = a_taller ? diff_nodes(child, h - 1, other, other_height, at, visit, steps)
                                 : diff_nodes(other, other_height, child, h - 1, at, visit, steps);
      if (!done) return false;
    }
    return true;
  }
  if (height_a == 0) {
    const std::uint32_t in_a = a == nullptr ? 0 : a->aux;
    const std::uint32_t in_b = b == nullptr ? 0 : b->aux;
    for (unsigned i = 0; i < kLeafWidth; ++i) {
      const Landmark* la = (in_a >> i & 1u) ? &static_cast<const Leaf*>(a)->landmarks[i] : nullptr;
      const Landmark* lb = (in_b >> i & 1u) ? &static_cast<const Leaf*>(b)->landmarks[i] : nullptr;
      if ((la != nullptr || lb != nullptr) && !(la != nullptr && lb != nullptr && *la == *lb)) {
        visit(static_cast<Slot>(base + i), la, lb);
      }
    }
    return true;
  }
  for (unsigned i = 0; i < kInnerWidth; ++i) {
    const Node* ca = a == nullptr ? nullptr : static_cast<const Inner*>(a)->child[i];
    const Node* cb = b == nullptr ? nullptr : static_cast<const Inner*>(b)->child[i];
    if (!diff_nodes(ca, height_a - 1, cb, height_b - 1, base + i * capacity_at(height_a - 1),
                    visit, steps)) {
      return false;
    }
  }
  return true;
}

template <class P>
auto BasicLandmarkTree<P>::begin() const noexcept -> Iterator {
  Iterator it;
  it.root_ = root_;
  it.height_ = height_;
  it.seek(0);
  return it;
}

template <class P>
auto BasicLandmarkTree<P>::end() const noexcept -> Iterator {
  Iterator it;
  it.root_ = root_;
  it.height_ = height_;
  return it;
}

template <class P>
void BasicLandmarkTree<P>::Iterator::seek(std::uint64_t from) noexcept {
  leaf_ = nullptr;
  if (root_ == nullptr) {
    return;
  }
  const std::uint64_t cap = capacity_at(height_);
  while (from < cap) {
    const Node* node = root_;
    bool restart = false;
    for (unsigned h = height_; h > 0 && !restart; --h) {
      const auto* inner = static_cast<const Inner*>(node);
      const unsigned shift = kLeafBits + kInnerBits * (h - 1);
      unsigned i = static_cast<unsigned>(from >> shift) & (kInnerWidth - 1);
      const unsigned first = i;
      while (i < kInnerWidth && inner->child[i] == nullptr) {
        ++i;
      }
      if (i == kInnerWidth) {
        // Nothing left under this node: continue after its whole range.
        from = ((from >> (shift + kInnerBits)) + 1) << (shift + kInnerBits);
        restart = true;
      } else {
        if (i != first) {
          from = ((from >> (shift + kInnerBits)) << (shift + kInnerBits)) |
                 (std::uint64_t{i} << shift);
        }
        node = inner->child[i];
      }
    }
    if (restart) {
      continue;
    }
    const unsigned offset = static_cast<unsigned>(from) & (kLeafWidth - 1);
    const std::uint32_t bits = node->aux >> offset;
    if (bits != 0) {
      leaf_ = static_cast<const Leaf*>(node);
      slot_ = static_cast<Slot>(from + static_cast<unsigned>(std::countr_zero(bits)));
      return;
    }
    from = ((from >> kLeafBits) + 1) << kLeafBits;
  }
}

template <class P>
auto BasicLandmarkTree<P>::Iterator::operator++() noexcept -> Iterator& {
  // Next landmark in the same leaf, else a seek from the next leaf's first slot.
  const unsigned offset = (slot_ & (kLeafWidth - 1)) + 1;
  const std::uint32_t bits = offset < kLeafWidth ? leaf_->aux >> offset : 0;
  if (bits != 0) {
    slot_ += 1 + static_cast<unsigned>(std::countr_zero(bits));
  } else {
    seek(((std::uint64_t{slot_} >> kLeafBits) + 1) << kLeafBits);
  }
  return *this;
}

}  // namespace fastslam::memory
