// Uses the installed headers and libraries: builds a map, shares it, changes the copy.
#include <cstdio>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"

int main() {
  fastslam::memory::MallocHeap heap;
  {
    fastslam::memory::LandmarkTree map(heap);
    for (int i = 0; i < 100; ++i) map.insert({.x = static_cast<double>(i)});
    fastslam::memory::LandmarkTree copy = map;
    copy.edit(42).x = -1.0;
    if (map.at(42).x != 42.0 || copy.at(42).x != -1.0 || copy.size() != 100) {
      std::puts("consumer: wrong map contents");
      return 1;
    }
  }
  if (heap.stats().live_nodes != 0) {
    std::puts("consumer: leaked nodes");
    return 1;
  }
  std::puts("consumer: ok");
  return 0;
}
