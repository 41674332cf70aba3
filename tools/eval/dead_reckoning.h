// The dead-reckoning baseline: the source's controls integrated through its own motion model
// with no noise and no observations, from its start pose. Reported beside every error of a
// run, it tells drift from failure: a filter that ends worse than it has lost its way.
//
// Ownership: plain values. Thread safety: thread-compatible.
// Costs: one model step per control, O(1) memory.
#pragma once

#include <optional>

#include "engine/filter.h"
#include "engine/filter_config.h"
#include "tools/io/tum.h"

namespace fastslam::tools {

class DeadReckoning {
 public:
  // `motion`: the source's model (the header's, whatever --motion the filter runs). Throws
  // std::invalid_argument for an unusable model.
  DeadReckoning(const engine::MotionConfig& motion, const double start_pose[3], double start_time);

  // Whether the model uses the controls at all (the Brownian models do not: no baseline).
  bool available() const noexcept { return available_; }

  // Moves the pose by one control held for dt, stamped `time`.
  void predict(const engine::Control& control, double dt, double time);
  const StampedPose& pose() const noexcept { return pose_; }

 private:
  engine::MotionConfig motion_;
  bool available_ = false;
  StampedPose pose_;
};

}  // namespace fastslam::tools
