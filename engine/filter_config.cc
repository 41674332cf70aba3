#include "engine/filter_config.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "parallel/particle_kernel.h"

namespace fastslam::engine {
namespace {

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("FilterConfig: " + what);
}

bool positive(double v) { return std::isfinite(v) && v > 0; }

// The EKF-SLAM baseline: known or ML association (DAS samples an association per particle, which
// a single Gaussian cannot), and usable gates.
void validate_ekf(const FilterConfig& c) {
  require(c.association == Association::kKnown || c.association == Association::kMaximumLikelihood,
          std::string("association '") + std::string(to_string(c.association)) +
              "' is not meaningful for the EKF (data association sampling needs particles); "
              "use 'known' or 'ml'");
  require(positive(c.ekf.gate_accept), "ekf.gate_accept must be finite and > 0");
  require(std::isfinite(c.ekf.gate_new) && c.ekf.gate_new >= c.ekf.gate_accept,
          "ekf.gate_new must be finite and >= ekf.gate_accept");
}

}  // namespace

MotionDraw resolved_motion_draw(const FilterConfig& c) {
  if (c.motion_draw != MotionDraw::kAuto) return c.motion_draw;
  return c.algorithm != Algorithm::kEkf && !without_odometry(c.motion.kind)
             ? MotionDraw::kComposed
             : MotionDraw::kEveryControl;
}

void validate(const FilterConfig& c) {
  require(c.particles >= 1, "particles must be at least 1 (got 0)");
  require(enum_known(c.algorithm), "unknown algorithm");
  require(enum_known(c.association), "unknown association");
  if (c.algorithm == Algorithm::kEkf) validate_ekf(c);
  try {
    validate(c.motion);
  } catch (const std::invalid_argument& e) {
    require(false, e.what());
  }
  const SensorConfig& s = c.sensor;
  require(positive(s.sigma_range), "sensor.sigma_range must be finite and > 0");
  require(positive(s.sigma_bearing), "sensor.sigma_bearing must be finite and > 0");
  require(positive(s.max_range), "sensor.max_range must be finite and > 0");
  require(positive(s.field_of_view) && s.field_of_view <= 2 * std::numbers::pi + 1e-12,
          "sensor.field_of_view must be in (0, 2 pi]");
  require(std::isfinite(s.offset.x) && std::isfinite(s.offset.y) && std::isfinite(s.offset.yaw),
          "sensor.offset must be finite");
  require(std::isfinite(c.log_new_landmark), "log_new_landmark must be finite");
  const ExistenceConfig& e = c.existence;
  require(std::isfinite(e.initial) && std::isfinite(e.seen) && std::isfinite(e.missed) &&
              std::isfinite(e.remove_below) && std::isfinite(e.confirm_at),
          "existence parameters must be finite");
  require(std::isfinite(e.range_margin) && e.range_margin >= 0,
          "existence.range_margin must be finite and >= 0");
  require(c.gating.gate > 0 && std::isfinite(c.gating.gate), "gating.gate must be finite and > 0");
  require(std::isfinite(c.gating.search_scale) && c.gating.search_scale >= 1,
          "gating.search_scale must be finite and >= 1");
  parallel::validate(c.resample);
  require(enum_known(c.resample.when), "resample.when is not a known policy");
  require(enum_known(c.resample.scheme), "resample.scheme is not a known scheme");
  require(enum_known(c.motion_draw), "motion_draw is not a known draw");
  if (c.motion_draw == MotionDraw::kComposed) {
    require(c.algorithm != Algorithm::kEkf,
            "motion_draw 'composed' is FastSLAM's (the EKF predicts its state control by "
            "control); use 'control'");
    require(!without_odometry(c.motion.kind),
            std::string("motion_draw 'composed' needs an odometry model, not '") +
                std::string(to_string(c.motion.kind)) + "' (its velocities differ per particle)");
  }
  require(c.grain >= 1, "grain must be at least 1");
  require(c.split_seconds >= 0, "split_seconds must be >= 0 (infinity: never split)");
  require(c.threads <= parallel::ParticleKernel::kMaxThreads,
          "threads must be at most " + std::to_string(parallel::ParticleKernel::kMaxThreads));
  for (double v : c.initial_pose) require(std::isfinite(v), "initial_pose must be finite");
  require(c.detection.probability > 0 && c.detection.probability <= 1,
          "detection.probability must be in (0, 1]");
  require(std::isfinite(c.detection.clutter_density) && c.detection.clutter_density >= 0,
          "detection.clutter_density must be finite and >= 0");
  require(std::isfinite(c.loop_closure.reach) && c.loop_closure.reach >= 0,
          "loop_closure.reach must be finite and >= 0");
  require(std::isfinite(c.loop_closure.separation) && c.loop_closure.separation >= 0,
          "loop_closure.separation must be finite and >= 0");
  require(c.loop_closure.max_turn > 0 && c.loop_closure.max_turn <= std::numbers::pi,
          "loop_closure.max_turn must be in (0, pi] radians");
  require(std::isfinite(c.loop_closure.merge_gate) && c.loop_closure.merge_gate >= 0,
          "loop_closure.merge_gate must be finite and >= 0");
  require(c.error_correlation >= 0 && c.error_correlation < 1,
          "error_correlation must be in [0, 1)");
  require(c.error_correlation == 0 || c.algorithm == Algorithm::kFastSlam2,
          "error_correlation is FastSLAM 2.0's (its weights are scored apart from its proposal); "
          "use 0 with " +
              std::string(to_string(c.algorithm)));
}

}  // namespace fastslam::engine
