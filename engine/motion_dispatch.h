// The one place a run-time motion choice becomes a model type: `MotionKind` names the models of
// engine/motion_model.h, `MotionConfig` holds a kind with its parameters and control noise, and
// `MotionTraits<kind>` gives each kind's model type, parameters (by name, as log headers write
// them) and construction. `visit_motion(config, f)` calls f(model); the filter, the EKF
// baseline, FilterConfig's validation and the log format all dispatch here. Adding a model
// touches engine/motion_model.h (the model), engine/motion_batch.h (its vector lane) and this
// file (an enumerator, its name, its traits and a case of visit_motion_kind): nothing else.
// Thread safety: constexpr tables and pure functions. Costs: O(1), no allocation; f is
// instantiated once per model.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include "engine/enum_names.h"
#include "engine/motion_model.h"

namespace fastslam::engine {

enum class MotionKind : std::uint8_t {
  kBaileyCar,          // BaileyCarModel: control (speed, steering from the heading)
  kUnicycle,           // UnicycleModel: control (v, omega)
  kAckermann,          // AckermannModel: control (encoder speed, steering); state = sensor pose
  kBrownian,           // BrownianVelocityModel: no odometry, (v, omega) walked (eq. 79-81)
  kBrownianCurvature,  // BrownianCurvatureModel: no odometry, (v, kappa) walked
};

template <>
struct EnumNames<MotionKind> {
  static constexpr std::string_view kWhat = "motion kind";
  static constexpr std::array<EnumName<MotionKind>, 6> kNames = {{
      {MotionKind::kBaileyCar, "bailey-car"},
      {MotionKind::kUnicycle, "unicycle"},
      {MotionKind::kAckermann, "ackermann"},
      {MotionKind::kBrownian, "none"},
      {MotionKind::kBrownianCurvature, "none-curvature"},
      {MotionKind::kAckermann, "victoria-park", true},  // logs written before the rename
  }};
};

struct MotionConfig {
  MotionKind kind = MotionKind::kBaileyCar;
  double wheelbase = 4.0;  // kBaileyCar (Bailey's WHEELBASE)
  // kAckermann: by default a car of the same wheelbase with its sensor and encoder on the rear
  // axle's centre, so that every kind's default configuration is usable.
  AckermannGeometry geometry{0.0, 0.0, 4.0, 0.0};
  // Standard deviations of the control noise per component: speed (m/s) and steering (rad) for
  // the cars, v and omega for the unicycle; the per-step increments of v and omega (kBrownian,
  // eq. 80) or of v and kappa (kBrownianCurvature).
  double sigma_control[2] = {0.3, 3.0 * std::numbers::pi / 180};
};

// One parameter of a model kind in MotionConfig, as a log header names it.
struct MotionParameter {
  std::string_view name;
  double (*get)(const MotionConfig&);
  void (*set)(MotionConfig&, double);
};

// Per kind: `Model`, `kParameters` (in log-header order) and `make(config)`, which throws
// std::invalid_argument (from the model's constructor) for unusable parameters.
template <MotionKind K>
struct MotionTraits;

template <>
struct MotionTraits<MotionKind::kBaileyCar> {
  using Model = BaileyCarModel;
  static constexpr std::array<MotionParameter, 1> kParameters = {{
      {"wheelbase", [](const MotionConfig& c) { return c.wheelbase; },
       [](MotionConfig& c, double v) { c.wheelbase = v; }},
  }};
  static Model make(const MotionConfig& c) { return Model(c.wheelbase); }
};

template <>
struct MotionTraits<MotionKind::kUnicycle> {
  using Model = UnicycleModel;
  static constexpr std::array<MotionParameter, 0> kParameters = {};
  static Model make(const MotionConfig& /*c*/) { return Model(); }
};

template <>
struct MotionTraits<MotionKind::kAckermann> {
  using Model = AckermannModel;
  static constexpr std::array<MotionParameter, 4> kParameters = {{
      {"a", [](const MotionConfig& c) { return c.geometry.a; },
       [](MotionConfig& c, double v) { c.geometry.a = v; }},
      {"b", [](const MotionConfig& c) { return c.geometry.b; },
       [](MotionConfig& c, double v) { c.geometry.b = v; }},
      {"l", [](const MotionConfig& c) { return c.geometry.l; },
       [](MotionConfig& c, double v) { c.geometry.l = v; }},
      {"h", [](const MotionConfig& c) { return c.geometry.h; },
       [](MotionConfig& c, double v) { c.geometry.h = v; }},
  }};
  static Model make(const MotionConfig& c) { return Model(c.geometry); }
};

template <>
struct MotionTraits<MotionKind::kBrownian> {
  using Model = BrownianVelocityModel;
  static constexpr std::array<MotionParameter, 0> kParameters = {};
  static Model make(const MotionConfig& /*c*/) { return Model(); }
};

template <>
struct MotionTraits<MotionKind::kBrownianCurvature> {
  using Model = BrownianCurvatureModel;
  static constexpr std::array<MotionParameter, 0> kParameters = {};
  static Model make(const MotionConfig& /*c*/) { return Model(); }
};

// Calls f(MotionTraits<kind>{}); every call must return the same type. Throws
// std::invalid_argument for a kind outside the enumeration.
template <class F>
decltype(auto) visit_motion_kind(MotionKind kind, F&& f) {
  switch (kind) {
    case MotionKind::kBaileyCar:
      return std::forward<F>(f)(MotionTraits<MotionKind::kBaileyCar>{});
    case MotionKind::kUnicycle:
      return std::forward<F>(f)(MotionTraits<MotionKind::kUnicycle>{});
    case MotionKind::kAckermann:
      return std::forward<F>(f)(MotionTraits<MotionKind::kAckermann>{});
    case MotionKind::kBrownian:
      return std::forward<F>(f)(MotionTraits<MotionKind::kBrownian>{});
    case MotionKind::kBrownianCurvature:
      return std::forward<F>(f)(MotionTraits<MotionKind::kBrownianCurvature>{});
  }
  throw std::invalid_argument("unknown motion kind");
}

// Calls f(model) with the model `config` names; every call must return the same type. Throws
// std::invalid_argument for an unknown kind or parameters the model refuses.
template <class F>
decltype(auto) visit_motion(const MotionConfig& config, F&& f) {
  return visit_motion_kind(config.kind, [&](auto traits) -> decltype(auto) {
    return std::forward<F>(f)(decltype(traits)::make(config));
  });
}

// Whether the model ignores the controls and carries its velocities in the state.
// REQUIRES: a known kind (else std::invalid_argument).
inline bool without_odometry(MotionKind kind) {
  return visit_motion_kind(kind, [](auto traits) { return decltype(traits)::Model::kNoOdometry; });
}

// The model's state dimension (3, or 5 with the velocities). REQUIRES: a known kind.
inline int motion_state_dim(MotionKind kind) {
  return visit_motion_kind(kind, [](auto traits) { return decltype(traits)::Model::kStateDim; });
}

// The parameters of `kind` in log-header order; empty for an unknown kind.
inline std::span<const MotionParameter> motion_parameters(MotionKind kind) noexcept {
  if (!enum_known(kind)) return {};
  return visit_motion_kind(kind, [](auto traits) -> std::span<const MotionParameter> {
    return decltype(traits)::kParameters;
  });
}

// Throws std::invalid_argument naming the first unusable field: an unknown kind, a parameter
// the model refuses, a control noise that is negative or not finite.
inline void validate(const MotionConfig& config) {
  if (!enum_known(config.kind)) {
    throw std::invalid_argument("motion.kind is not a known motion kind (" +
                                enum_name_list<MotionKind>() + ")");
  }
  visit_motion(config, [](const auto& /*model*/) {});  // the model's constructor checks
  for (int k = 0; k < 2; ++k) {
    if (!std::isfinite(config.sigma_control[k]) || config.sigma_control[k] < 0) {
      throw std::invalid_argument("motion.sigma_control[" + std::to_string(k) +
                                  "] must be finite and >= 0");
    }
  }
}

}  // namespace fastslam::engine
