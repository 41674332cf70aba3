// Errors of an estimated trajectory against reference positions (truth poses or GPS fixes),
// and of a map whose ids are the true ones. The estimate at a reference time is the sample
// stamped exactly then, else the linear interpolation between the samples around it; a
// reference in a gap of the estimate wider than kMaxInterpolationGap, or outside it, is skipped.
//
// Ownership: borrows its inputs for the call. Thread safety: pure functions.
// Costs: O(R log E) for R references and E estimate samples; landmark_rmse_by_id O(T log T + N).
#pragma once

#include <cstddef>
#include <optional>
#include <span>
#include <vector>

#include "engine/filter.h"
#include "tools/io/log_format.h"
#include "tools/io/tum.h"

namespace fastslam::tools {

// Seconds: estimates farther apart are not interpolated between (40 control steps of Bailey's
// simulator, 40 odometry periods of Victoria Park).
inline constexpr double kMaxInterpolationGap = 1.0;

// The estimate at time t (see the file comment), or nothing. REQUIRES: samples in time order.
std::optional<StampedPose> pose_at(std::span<const StampedPose> samples, double t);

struct PositionErrors {
  double rmse = 0.0;  // m; 0 when no reference was used
  double last = 0.0;  // m, at the last reference used
  std::size_t used = 0, skipped = 0;
};
PositionErrors position_errors(std::span<const StampedPose> estimate,
                               std::span<const StampedPose> reference);

// The position RMSE after the rigid motion (rotation and translation, no scale) that best
// aligns the estimate with the reference (closed-form least squares, Horn/Umeyama in 2-D): the
// error of the path's shape apart from its placement, which for a source without an absolute
// heading comes from the start pose.
struct AlignedErrors {
  double rmse = 0.0;      // m
  double rotation = 0.0;  // rad, applied to the estimate
};
AlignedErrors aligned_position_errors(std::span<const StampedPose> estimate,
                                      std::span<const StampedPose> reference);

// Known association: the RMS distance of each estimated landmark to the true one of its id.
// 0 when either is empty. Throws std::runtime_error for an id that is not a true landmark's.
double landmark_rmse_by_id(std::span<const engine::MapLandmark> map,
                           std::span<const TruthLandmark> truth);

}  // namespace fastslam::tools
