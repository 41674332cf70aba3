// Angle wrapping: every heading and bearing the engine stores or compares lives in (-pi, pi].
// `wrap_angle` is exact (a - 2 pi k without rounding) and returns after two compares for an
// angle in range, one exact subtraction just outside it. Pure functions; O(1), no allocation.
#pragma once

#include <cmath>
#include <numbers>

namespace fastslam::engine {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kTwoPi = 2.0 * std::numbers::pi;

// `angle` wrapped to (-pi, pi]: -pi maps to pi. NaN and infinities give NaN.
inline double wrap_angle(double angle) noexcept {
  if (angle > -kPi && angle <= kPi) [[likely]] {
    return angle;
  }
  // For |angle| in [pi, 4 pi] the shift by 2 pi is exact (Sterbenz), so an angle just outside
  // the interval lands inside it with no rounding; farther ones fail the check and fall through.
  if (angle > kPi) {
    const double r = angle - kTwoPi;  // > -pi, exactly
    if (r <= kPi) {
      return r;
    }
  } else if (angle <= -kPi) {
    const double r = angle + kTwoPi;  // <= pi, exactly
    if (r > -kPi) {
      return r;
    }
  }
  // remainder gives [-pi, pi] exactly; fold the one endpoint outside the half-open interval.
  const double r = std::remainder(angle, kTwoPi);
  return r <= -kPi ? r + kTwoPi : r;
}

// The signed difference a - b, wrapped to (-pi, pi]. REQUIRES: both finite.
inline double angle_diff(double a, double b) noexcept { return wrap_angle(a - b); }

}  // namespace fastslam::engine
