// Benchmarks of the node heaps (docs/memory.md, "Heap policy").
//
//   BM_NodeHeapAllocateFree<Heap>/bytes     allocate one block and free it (a path copy frees
//       one node and allocates one, over and over).
//   BM_NodeHeapPathCopy<Heap>/depth         allocate `depth` inner nodes (136 B) and a leaf
//       (264 B), then free them: the traffic of one shared update of a default-shape tree.
#include <cstdint>
#include <vector>

#include <benchmark/benchmark.h>

#include "memory/node_heap.h"

namespace fastslam::memory {
namespace {

template <class Heap>
void BM_NodeHeapAllocateFree(benchmark::State& state) {
  Heap heap;
  const auto bytes = static_cast<std::size_t>(state.range(0));
  for (auto _ : state) {
    void* block = heap.allocate(bytes);
    benchmark::DoNotOptimize(block);
    heap.deallocate(block, bytes);
  }
}

template <class Heap>
void BM_NodeHeapPathCopy(benchmark::State& state) {
  Heap heap;
  const auto depth = static_cast<std::size_t>(state.range(0));
  std::vector<void*> path(depth + 1);
  for (auto _ : state) {
    for (std::size_t i = 0; i < depth; ++i) path[i] = heap.allocate(136);
    path[depth] = heap.allocate(264);
    benchmark::DoNotOptimize(path.data());
    for (std::size_t i = 0; i < depth; ++i) heap.deallocate(path[i], 136);
    heap.deallocate(path[depth], 264);
  }
}

BENCHMARK_TEMPLATE(BM_NodeHeapAllocateFree, MallocHeap)->Arg(136)->Arg(264)->ArgName("bytes");
BENCHMARK_TEMPLATE(BM_NodeHeapAllocateFree, PoolHeap)->Arg(136)->Arg(264)->ArgName("bytes");
BENCHMARK_TEMPLATE(BM_NodeHeapPathCopy, MallocHeap)->Arg(3)->Arg(5)->ArgName("depth");
BENCHMARK_TEMPLATE(BM_NodeHeapPathCopy, PoolHeap)->Arg(3)->Arg(5)->ArgName("depth");

}  // namespace
}  // namespace fastslam::memory
