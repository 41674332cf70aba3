#include "memory/particle_store.h"

#include <stdexcept>
#include <string>
#include <utility>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

namespace fastslam::memory {

ParticleStore::ParticleStore(std::size_t particles, NodeHeap& heap)
    : heap_(&heap),
      x_(particles, 0.0),
      y_(particles, 0.0),
      theta_(particles, 0.0),
      v_(particles, 0.0),
      omega_(particles, 0.0),
      log_weight_(particles, 0.0),
      maps_(particles, LandmarkTree(heap)) {}

void ParticleStore::gather(std::span<const std::uint32_t> index, std::size_t grain) {
  const std::size_t from_size = size();
  for (std::size_t k = 0; k < index.size(); ++k) {
    if (index[k] >= from_size) {
      throw std::invalid_argument("ParticleStore::gather: index[" + std::to_string(k) + "] = " +
                                  std::to_string(index[k]) + " is not below the particle count " +
                                  std::to_string(from_size));
    }
  }
  const std::size_t m = index.size();
  Column nx(m), ny(m), ntheta(m), nv(m), nomega(m), nlog_weight(m);
  std::vector<LandmarkTree> nmaps(m, LandmarkTree(*heap_));
  if (grain == 0) grain = 1;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m, grain),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t k = r.begin(); k != r.end(); ++k) {
                        const std::uint32_t i = index[k];
                        nx[k] = x_[i];
                        ny[k] = y_[i];
                        ntheta[k] = theta_[i];
                        nv[k] = v_[i];
                        nomega[k] = omega_[i];
                        nlog_weight[k] = log_weight_[i];
                        nmaps[k] = maps_[i];  // bumps the root's count
                      }
                    });
  x_.swap(nx);
  y_.swap(ny);
  theta_.swap(ntheta);
  v_.swap(nv);
  omega_.swap(nomega);
  log_weight_.swap(nlog_weight);
  maps_.swap(nmaps);
  // The old maps: each drops one reference; maps no survivor shares are freed, in parallel.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nmaps.size(), grain),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t k = r.begin(); k != r.end(); ++k) nmaps[k].clear();
                    });
}

}  // namespace fastslam::memory
