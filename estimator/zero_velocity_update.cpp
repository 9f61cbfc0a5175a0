// The zero-velocity update: while the autopilot's land detector says the vehicle is landed (set_landed), its velocity
// is measured, not inferred: rest, within landed_speed_std. Gate: the land detector alone, never the IMU's stillness
// (docs/estimator.md, "On the ground": idling motors shake a standing airframe more than some flights do, and a
// vibration-free stream looks still in the air). Fuse: v = 0 on each axis, in place of the drag law, which on the
// ground would read the stance's tilt and the accelerometer's offset as a speed. Status: counters().landed, and the
// estimate's variance, which is the filter's own (no accelerometer offset or wind stands between rest and the output).
#include "estimator/drag_velocity.hpp"

namespace imubridge::estimator {

void DragVelocityEstimator::fuse_zero_velocity(int axis, DragVelocityEstimate& out) {
  const double r = config_.landed_speed_std * config_.landed_speed_std;
  update_velocity(axis, 0.0, r);
  // What was measured is rest; the output is the filter's velocity after it (the tilt the prediction levelled on the
  // accelerometer keeps it there).
  out.v_raw[axis] = 0.0;
  out.v_raw_var[axis] = r;
  out.v[axis] = x_[axis];
  out.v_var[axis] = p_(axis, axis);
}

}  // namespace imubridge::estimator
