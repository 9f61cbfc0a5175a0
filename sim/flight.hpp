#pragma once
// The flight: vehicle + controller + flight plan, integrated on a fixed grid (physics_rate_hz) whatever the IMU
// rate, with the controller's command held over each step. The true state between grid points comes from a partial
// RK4 step, so a flight looks the same at every IMU rate.
#include <Eigen/Geometry>
#include <cstdint>
#include <deque>

#include "sim/controller.hpp"
#include "sim/quadrotor.hpp"
#include "sim/trajectory.hpp"

namespace imubridge::sim {

struct FlightConfig {
  QuadrotorParams vehicle;
  Aerodynamics air;
  ControllerGains gains;
  ManoeuvreConfig manoeuvres;
  VerticalManoeuvreConfig vertical;
  HeadingTurnConfig turns;
  double physics_rate_hz = 2000.0;
  double start_altitude_m = 1.5;  // starts hovering here, above the NED origin
};

// Everything true about the vehicle at one instant. Vectors in body axes unless named _ned.
struct TrueState {
  double time_s = 0.0;
  Eigen::Vector3d position_ned = Eigen::Vector3d::Zero();  // mass centre, m
  Eigen::Vector3d velocity_ned = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_body = Eigen::Vector3d::Zero();       // ground velocity
  Eigen::Vector3d air_velocity_body = Eigen::Vector3d::Zero();   // what drag acts on: ground velocity - wind
  Eigen::Quaterniond attitude = Eigen::Quaterniond::Identity();  // body -> NED
  Eigen::Vector3d euler = Eigen::Vector3d::Zero();               // ZYX roll, pitch, yaw, rad
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();
  Eigen::Vector3d omega_dot = Eigen::Vector3d::Zero();
  Eigen::Vector3d specific_force = Eigen::Vector3d::Zero();  // at the mass centre
  Eigen::Vector4d rotor_speed = Eigen::Vector4d::Zero();
};

class Flight {
 public:
  Flight(const FlightConfig& config, double duration_s, std::uint64_t seed);

  // The true state at time t (s). Before t = 0 the vehicle is taken to be in its initial state. Times may go
  // back, but not before the last forget_before().
  TrueState at(double t);
  // Releases the history (and the flight plan) before t; a streaming caller keeps memory bounded with it.
  void forget_before(double t);

  FlightPlan& plan() { return plan_; }

 private:
  struct Node {
    RigidState state;
    Eigen::Vector4d command;  // held from this grid point to the next
  };
  const Node& node(std::int64_t index);  // integrates forward as far as needed

  Quadrotor vehicle_;
  Controller controller_;
  FlightPlan plan_;
  double dt_;
  std::deque<Node> nodes_;
  std::int64_t first_index_ = 0;  // grid index of nodes_.front()
};

}  // namespace imubridge::sim
