#pragma once
// Residuals of the accelerometer models, templated for Ceres' automatic differentiation and kept apart from the
// solving (identification/least_squares.hpp), as in Ceres' examples. Each functor covers a run of consecutive samples
// rather than one: with one sample per residual block, Ceres' bookkeeping per block costs several times the model's
// arithmetic. With T = double they are also what the GA's 3-D objective evaluates, so both methods minimise the
// same thing.
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <span>

#include "estimator/drag_law.hpp"
#include "estimator/paper_model.hpp"

namespace imubridge::estimator {

// Eq. (14)'s error f - f_bar for each sample. The parameter block is (r, beta, alpha, mu), so its covariance is one
// 4 x 4 matrix. Summed in squares over the samples it is OF^2, eq. (15).
struct PaperResidual {
  static constexpr int kParameters = 4;

  explicit PaperResidual(std::span<const PaperSample> samples) : samples(samples) {}

  template <typename T>
  bool operator()(const T* p, T* residual) const {
    const PaperCoefficients<T> c = paper_coefficients(p[0], p[1], p[2], p[3]);
    for (std::size_t k = 0; k < samples.size(); ++k) residual[k] = samples[k].f - paper_specific_force(c, samples[k]);
    return true;
  }

  std::span<const PaperSample> samples;  // not owned
};

// One sample for the 3-D model: the measurements and the drag's velocity, none depending on the parameters.
struct FullSample {
  double t = 0.0;                                       // s
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();       // rad/s, IMU axes
  Eigen::Vector3d gyro_rate = Eigen::Vector3d::Zero();  // rad/s^2, IMU axes
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();      // measured specific force, m/s^2, IMU axes
  Eigen::Vector2d velocity = Eigen::Vector2d::Zero();   // body-axis horizontal air velocity, m/s
};

// The 3-D model (docs/model.md) solved for the mass centre, as LeverArmCompensator does, but on the parameters:
//   f_cm = R_bs (f_imu - b_a) - w_dot x r - w x (w x r),   w = R_bs w_imu.
// Its x and y rows must be the drag law; the residuals are their differences (m/s^2, body axes), two per sample.
// The z row is -T: the thrust is unknown per sample, so it carries no information about the parameters and is left
// out. That is the model's "T from the compensated body-z reading", which keeps the term eq. (14) drops. The
// parameter blocks are FullModelParams' five: lever arm (3), mounting (3), k (2), mu (2), accel bias (3).
struct FullResidual {
  explicit FullResidual(std::span<const FullSample> samples) : samples(samples) {}

  template <typename T>
  bool operator()(const T* lever_arm, const T* mounting, const T* drag_linear, const T* drag_quadratic,
                  const T* accel_bias, T* residual) const {
    using Vec3 = Eigen::Matrix<T, 3, 1>;
    Eigen::Matrix<T, 3, 3> imu_to_body;  // R_bs, once for every vector of every sample
    ceres::AngleAxisToRotationMatrix(mounting, ceres::ColumnMajorAdapter3x3(imu_to_body.data()));
    const Eigen::Map<const Vec3> r(lever_arm);
    const Eigen::Map<const Vec3> b(accel_bias);
    for (const FullSample& s : samples) {
      const Vec3 w = imu_to_body * s.gyro;
      const Vec3 w_dot = imu_to_body * s.gyro_rate;
      const Vec3 f_cm = imu_to_body * (s.accel - b) - w_dot.cross(r) - w.cross(w.cross(r));
      for (int axis = 0; axis < 2; ++axis)
        *residual++ = f_cm[axis] - drag_specific_force(drag_linear[axis], drag_quadratic[axis], s.velocity[axis]);
    }
    return true;
  }

  std::span<const FullSample> samples;  // not owned
};

}  // namespace imubridge::estimator
