#include "engine/landmark_ekf.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace fastslam::engine {

void check_covariance2(const Eigen::Matrix2d& m, const char* what) {
  const auto fail = [&](const char* why) {
    std::ostringstream msg;
    msg << what << ": " << why << " (got [[" << m(0, 0) << ", " << m(0, 1) << "], [" << m(1, 0)
        << ", " << m(1, 1) << "]])";
    throw std::invalid_argument(msg.str());
  };
  if (!m.allFinite()) {
    fail("covariance must be finite");
  }
  const double scale = std::max(std::abs(m(0, 0)), std::abs(m(1, 1)));
  if (std::abs(m(0, 1) - m(1, 0)) > 1e-9 * scale) {
    fail("covariance must be symmetric");
  }
  const double b = 0.5 * (m(0, 1) + m(1, 0));
  if (!(m(0, 0) > 0.0) || !(m(0, 0) * m(1, 1) - b * b > 0.0)) {
    fail("covariance must be positive definite");
  }
}

}  // namespace fastslam::engine
