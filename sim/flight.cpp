#include "sim/flight.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace imubridge::sim {

namespace {

// Manoeuvres and sensor noise draw from separate streams of the one seed.
constexpr std::uint64_t kPlanStream = 1;
// The altitude plan has its own (the sensor noise is stream 2): switching it on leaves roll and pitch as they were.
constexpr std::uint64_t kVerticalPlanStream = 3;
// And the heading turns theirs: a flight with turns keeps the roll, pitch and altitude plan it has without them.
constexpr std::uint64_t kHeadingPlanStream = 4;

}  // namespace

Flight::Flight(const FlightConfig& config, double duration_s, std::uint64_t seed)
    : vehicle_(config.vehicle, config.air),
      controller_(vehicle_, config.gains, Eigen::Vector3d(0.0, 0.0, -config.start_altitude_m)),
      plan_(config.manoeuvres, config.vertical, duration_s, Rng::stream(seed, kPlanStream),
            Rng::stream(seed, kVerticalPlanStream), config.turns, Rng::stream(seed, kHeadingPlanStream)),
      dt_(1.0 / config.physics_rate_hz) {
  const RigidState start = vehicle_.hover_at({0.0, 0.0, -config.start_altitude_m});
  nodes_.push_back({start, controller_.rotor_command(start, plan_.at(0.0))});
}

const Flight::Node& Flight::node(std::int64_t index) {
  if (index < first_index_) throw std::logic_error("Flight: state requested before the forgotten history");
  while (first_index_ + static_cast<std::int64_t>(nodes_.size()) <= index) {
    const Node& last = nodes_.back();
    const double t_next = static_cast<double>(first_index_ + nodes_.size()) * dt_;
    RigidState next = vehicle_.step(last.state, last.command, dt_);
    const Eigen::Vector4d command = controller_.rotor_command(next, plan_.at(t_next));
    nodes_.push_back({std::move(next), command});
  }
  return nodes_[static_cast<std::size_t>(index - first_index_)];
}

TrueState Flight::at(double t) {
  const double t_flight = std::max(t, 0.0);
  // The epsilon keeps a sample time that is a grid time (n / 200 Hz on a 2 kHz grid) on its grid point.
  const auto index = static_cast<std::int64_t>(std::floor(t_flight / dt_ + 1e-9));
  const Node& n = node(index);
  const double partial = t_flight - static_cast<double>(index) * dt_;
  const RigidState s = partial > 0.0 ? vehicle_.step(n.state, n.command, partial) : n.state;

  TrueState truth;
  truth.time_s = t;
  truth.position_ned = s.position;
  truth.velocity_ned = s.velocity;
  truth.velocity_body = s.attitude.conjugate() * s.velocity;
  truth.air_velocity_body = vehicle_.air_velocity_body(s);
  truth.attitude = s.attitude;
  truth.euler = euler_zyx(s.attitude);
  truth.omega = s.omega;
  truth.omega_dot = vehicle_.angular_acceleration(s);
  truth.specific_force = vehicle_.specific_force(s);
  truth.rotor_speed = s.rotor_speed;
  return truth;
}

void Flight::forget_before(double t) {
  const auto keep_from = static_cast<std::int64_t>(std::floor(t / dt_)) - 1;
  while (first_index_ < keep_from && nodes_.size() > 1) {
    nodes_.pop_front();
    ++first_index_;
  }
  plan_.forget_before(static_cast<double>(first_index_) * dt_);  // the plan is only read ahead of the kept nodes
}

}  // namespace imubridge::sim
