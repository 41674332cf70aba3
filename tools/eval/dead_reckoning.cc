#include "tools/eval/dead_reckoning.h"

#include <type_traits>

#include "engine/angles.h"
#include "engine/motion_dispatch.h"

namespace fastslam::tools {

DeadReckoning::DeadReckoning(const engine::MotionConfig& motion, const double start_pose[3],
                             double start_time)
    : motion_(motion),
      available_(!engine::without_odometry(motion.kind)),
      pose_{start_time, start_pose[0], start_pose[1], start_pose[2]} {
  engine::validate(motion);
}

void DeadReckoning::predict(const engine::Control& control, double dt, double time) {
  pose_.time = time;
  if (!available_) return;
  engine::visit_motion(motion_, [&](const auto& model) {
    using Model = std::decay_t<decltype(model)>;
    typename Model::State s = Model::State::Zero();
    s[0] = pose_.x;
    s[1] = pose_.y;
    s[2] = pose_.theta;
    const typename Model::State next =
        model.predict(s, typename Model::Control(control.u0, control.u1), dt);
    pose_.x = next[0];
    pose_.y = next[1];
    pose_.theta = engine::wrap_angle(next[2]);
  });
}

}  // namespace fastslam::tools
