// Bailey's webmap (../shared/data/bailey_sim), the classic accuracy test of the engine tests.
// Header-only; the including test links fastslam::tools.
#pragma once

#include <string>

#include "tools/sim/world.h"

namespace fastslam::engine::testing {

// Throws as tools::read_world_csv when the files are missing or malformed.
inline tools::World webmap(const std::string& shared) {
  const std::string dir = shared + "/data/bailey_sim/";
  return tools::read_world_csv(dir + "example_webmap_landmarks.csv",
                               dir + "example_webmap_waypoints.csv");
}

}  // namespace fastslam::engine::testing
