#include "engine/measurement_model.h"

#include <cmath>
#include <stdexcept>

namespace fastslam::engine {

RangeBearingModel::RangeBearingModel(const SensorOffset& offset)
    : offset_(offset), has_offset_(offset.x != 0.0 || offset.y != 0.0) {
  if (!std::isfinite(offset.x) || !std::isfinite(offset.y) || !std::isfinite(offset.yaw)) {
    throw std::invalid_argument("RangeBearingModel: the sensor offset must be finite");
  }
}

}  // namespace fastslam::engine
