// Tree-graph streams written by hand, record by record (memory/tree_graph.h's format), for the
// tests that feed its readers malformed or linked input: leaf, inner, tree and held records, a
// node's name after its record, and raw bytes.
// Thread safety: a value type. Costs: appends to a string.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory::testing {

class GraphRecords {
 public:
  // A leaf of the default tree shape (4 slots) at `base`; its landmarks are tagged_landmark's.
  GraphRecords& leaf(std::uint32_t base, std::uint32_t mask) {
    put<std::uint8_t>(0);
    put(base);
    put(mask);
    for (int i = 0; i < 4; ++i) {
      if (mask >> i & 1u) put(tagged_landmark(1, base + i));
    }
    return *this;
  }
  GraphRecords& inner(std::uint8_t height, std::uint32_t base, std::uint32_t mask,
                      const std::vector<std::uint32_t>& children) {
    put<std::uint8_t>(1);
    put(height);
    put(base);
    put(mask);
    for (std::uint32_t c : children) put(c);
    return *this;
  }
  GraphRecords& tree(std::uint8_t height, std::uint32_t root) {
    put<std::uint8_t>(2);
    put(height);
    put(root);
    return *this;
  }
  // The linked form's record of a node the receiver holds, and the name after a new record.
  GraphRecords& held(std::uint8_t height, std::uint32_t base, std::uint64_t name) {
    put<std::uint8_t>(3);
    put(height);
    put(base);
    put(name);
    return *this;
  }
  GraphRecords& name(std::uint64_t name) {
    put(name);
    return *this;
  }
  GraphRecords& raw(std::uint8_t byte) {
    put(byte);
    return *this;
  }
  const std::string& bytes() const { return bytes_; }

 private:
  template <class T>
  void put(const T& v) {
    bytes_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  std::string bytes_;
};

}  // namespace fastslam::memory::testing
