#include "engine/motion_model.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace fastslam::engine {

BaileyCarModel::BaileyCarModel(double wheelbase) : wheelbase_(wheelbase) {
  if (!std::isfinite(wheelbase) || wheelbase <= 0.0) {
    throw std::invalid_argument("BaileyCarModel: wheelbase must be finite and > 0, got " +
                                std::to_string(wheelbase));
  }
}

AckermannModel::AckermannModel(const AckermannGeometry& geometry) : g_(geometry) {
  if (!std::isfinite(g_.a) || !std::isfinite(g_.b) || !std::isfinite(g_.l) ||
      !std::isfinite(g_.h) || g_.l <= 0.0 || g_.h < 0.0) {
    throw std::invalid_argument(
        "AckermannModel: geometry must be finite with wheelbase l > 0 and encoder offset "
        "h >= 0, got a = " +
        std::to_string(g_.a) + ", b = " + std::to_string(g_.b) + ", l = " + std::to_string(g_.l) +
        ", h = " + std::to_string(g_.h));
  }
}

}  // namespace fastslam::engine
