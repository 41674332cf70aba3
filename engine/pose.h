// The planar pose shared by the models: (x, y, theta) in metres and radians, theta in (-pi, pi].
// Thread safety: a value type. Cost: 24 bytes, no allocation.
#pragma once

#include <Eigen/Core>

namespace fastslam::engine {

using Pose = Eigen::Vector3d;

}  // namespace fastslam::engine
