#include "tools/io/tum.h"

#include <charconv>
#include <cmath>
#include <ostream>
#include <stdexcept>
#include <string>

namespace fastslam::tools {
namespace {

void put(std::string& line, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  line.append(buf, static_cast<std::size_t>(r.ptr - buf));
}

void check_finite(const StampedPose& p) {
  if (!std::isfinite(p.time) || !std::isfinite(p.x) || !std::isfinite(p.y) ||
      !std::isfinite(p.theta)) {
    throw std::invalid_argument("write_tum: a pose at time " + std::to_string(p.time) +
                                " is not finite");
  }
}

}  // namespace

std::array<double, 4> yaw_quaternion(double yaw) {
  return {0.0, 0.0, std::sin(0.5 * yaw), std::cos(0.5 * yaw)};
}

void append_tum(std::string& text, const StampedPose& p) {
  check_finite(p);
  const std::array<double, 4> q = yaw_quaternion(p.theta);
  put(text, p.time);
  for (double v : {p.x, p.y, 0.0, q[0], q[1], q[2], q[3]}) {
    text += ' ';
    put(text, v);
  }
  text += '\n';
}

void write_tum(std::ostream& out, std::span<const StampedPose> poses) {
  for (const StampedPose& p : poses) check_finite(p);
  std::string text(kTumHeader);
  for (const StampedPose& p : poses) {
    append_tum(text, p);
    if (text.size() > (1 << 16)) {  // stream in chunks: a trajectory can have millions of poses
      out << text;
      text.clear();
    }
  }
  out << text;
}

}  // namespace fastslam::tools
