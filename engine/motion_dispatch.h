// The one place a run-time motion choice (MotionConfig::kind) becomes a compile-time model type:
// `visit_motion(config, f)` builds the model the configuration names and calls f(model). The
// filter, the EKF baseline and the simulator all dispatch here, so a new model is added here and
// in engine/motion_model.h, nowhere else.
//
// Thread safety: a pure function. Costs: O(1); f is instantiated once per model.
#pragma once

#include <stdexcept>
#include <utility>

#include "engine/filter_config.h"
#include "engine/motion_model.h"

namespace fastslam::engine {

// Calls f(model) with the model `config` names; every call must return the same type.
// Throws std::invalid_argument for a kind outside the enumeration.
template <class F>
decltype(auto) visit_motion(const MotionConfig& config, F&& f) {
  switch (config.kind) {
    case MotionKind::kBaileyCar:
      return std::forward<F>(f)(BaileyCarModel(config.wheelbase));
    case MotionKind::kUnicycle:
      return std::forward<F>(f)(UnicycleModel());
    case MotionKind::kVictoriaPark:
      return std::forward<F>(f)(VictoriaParkModel(config.geometry));
    case MotionKind::kBrownian:
      return std::forward<F>(f)(BrownianVelocityModel());
    case MotionKind::kBrownianCurvature:
      return std::forward<F>(f)(BrownianCurvatureModel());
  }
  throw std::invalid_argument("unknown motion kind");
}

}  // namespace fastslam::engine
