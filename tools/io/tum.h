// Trajectories in the TUM RGB-D format ("timestamp tx ty tz qx qy qz qw" per line), which the
// usual trajectory evaluation tools read (evo, the TUM benchmark scripts): a planar pose is
// written with z = 0 and the rotation by `yaw` about +z as a unit quaternion.
//
// Ownership: borrows its inputs for the call. Thread safety: thread-safe (no shared state).
// Costs: O(poses); every double is printed in its shortest exact form (std::to_chars).
#pragma once

#include <array>
#include <iosfwd>
#include <span>
#include <string>
#include <string_view>

namespace fastslam::tools {

struct StampedPose {
  double time = 0.0;  // s
  double x = 0.0, y = 0.0, theta = 0.0;
};

// (qx, qy, qz, qw) of the rotation by `yaw` radians about +z: (0, 0, sin(yaw/2), cos(yaw/2)).
std::array<double, 4> yaw_quaternion(double yaw);

// The comment line naming the columns, which opens a file.
inline constexpr std::string_view kTumHeader = "# timestamp tx ty tz qx qy qz qw\n";

// Appends one pose's line to `text`. Throws std::invalid_argument on a non-finite value
// (appending nothing).
void append_tum(std::string& text, const StampedPose& pose);

// kTumHeader, then one line per pose. Throws std::invalid_argument on a non-finite value
// (writing nothing).
void write_tum(std::ostream& out, std::span<const StampedPose> poses);

}  // namespace fastslam::tools
