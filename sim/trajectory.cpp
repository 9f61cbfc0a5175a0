#include "sim/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace imubridge::sim {

void CosineCurve::add_knot(double t, double value) {
  if (knots_.empty() || t > knots_.back().first) knots_.emplace_back(t, value);
}

CosineCurve::Point CosineCurve::at(double t) const {
  if (knots_.empty()) return {};
  const auto next = std::upper_bound(knots_.begin(), knots_.end(), t,
                                     [](double time, const auto& knot) { return time < knot.first; });
  if (next == knots_.begin()) return {knots_.front().second, 0.0, 0.0};
  if (next == knots_.end()) return {knots_.back().second, 0.0, 0.0};
  const auto& [t0, y0] = *std::prev(next);
  const auto& [t1, y1] = *next;
  if (y1 == y0) return {y0, 0.0, 0.0};
  // y = y0 + (y1 - y0) * (1 - cos(w * (t - t0))) / 2 with w = pi / (t1 - t0).
  const double w = std::numbers::pi / (t1 - t0);
  const double half_step = (y1 - y0) / 2;
  const double phase = w * (t - t0);
  return {y0 + half_step * (1 - std::cos(phase)), half_step * w * std::sin(phase), half_step * w * w * std::cos(phase)};
}

void CosineCurve::forget_before(double t) {
  const auto next = std::upper_bound(knots_.begin(), knots_.end(), t,
                                     [](double time, const auto& knot) { return time < knot.first; });
  if (next - knots_.begin() > 1) knots_.erase(knots_.begin(), std::prev(next));
}

namespace {

struct Manoeuvre {
  enum class Kind { doublet, burst, step } kind;
  double amplitude, swing, hold;
  int cycles;

  double length() const {
    if (kind == Kind::doublet) return 3 * swing + 2 * hold;
    if (kind == Kind::burst) return (2 * cycles + 1) * swing;
    return 2 * swing + hold;
  }

  void append_to(CosineCurve& curve, double t) const {
    const double a = amplitude;
    curve.add_knot(t, 0.0);
    curve.add_knot(t += swing, a);
    switch (kind) {
      case Kind::doublet:  // +A held, then -A held: a step and its return
        curve.add_knot(t += hold, a);
        curve.add_knot(t += swing, -a);
        curve.add_knot(t += hold, -a);
        break;
      case Kind::burst:  // `cycles` periods of a sinusoid of period 2 * swing
        for (int i = 1; i < 2 * cycles; ++i) curve.add_knot(t += swing, i % 2 ? -a : a);
        break;
      case Kind::step:  // tilt and hold: the vehicle gains speed; drag and the position hold take it back
        curve.add_knot(t += hold, a);
        break;
    }
    curve.add_knot(t + swing, 0.0);
  }
};

// One step of a plan: manoeuvres follow one another from the lead-in, gaps of [gap_min, gap_max) apart, until one
// would end later than 1 s before the flight's end. Draws the next (`draw(rng)` gives it and the curve it goes on)
// and puts it on its curve, moving `next_start_s` past it, or finds the plan `done`.
template <typename Draw>
void draw_next(double& next_start_s, bool& done, double gap_min_s, double gap_max_s, double duration_s, Rng& rng,
               Draw draw) {
  const auto [curve, m] = draw(rng);
  if (next_start_s + m.length() > duration_s - 1.0) {
    done = true;
    return;
  }
  m.append_to(*curve, next_start_s);
  next_start_s += m.length() + rng.uniform(gap_min_s, gap_max_s);
}

// A manoeuvre of random kind, sign, size in [size_min, size_max), swing, hold and cycle count, drawn in the order
// plans have always been drawn, so that seeds keep their flights.
Manoeuvre draw_manoeuvre(Rng& rng, double size_min, double size_max, double swing_min_s, double swing_max_s,
                         double hold_min_s, double hold_max_s) {
  Manoeuvre m;
  m.kind = static_cast<Manoeuvre::Kind>(std::min(2, static_cast<int>(rng.uniform() * 3)));
  const double sign = rng.uniform() < 0.5 ? -1.0 : 1.0;
  m.amplitude = sign * rng.uniform(size_min, size_max);
  m.swing = rng.uniform(swing_min_s, swing_max_s);
  m.hold = rng.uniform(hold_min_s, hold_max_s);
  m.cycles = 2 + static_cast<int>(rng.uniform() * 2);
  return m;
}

// The next roll or pitch manoeuvre, and the curve of `plan` it goes on.
std::pair<CosineCurve*, Manoeuvre> draw_attitude(const ManoeuvreConfig& c, Trajectory& plan, Rng& rng) {
  CosineCurve* curve = rng.uniform() < c.roll_share ? &plan.roll : &plan.pitch;
  const Manoeuvre m = draw_manoeuvre(rng, c.amplitude_min_rad, c.amplitude_max_rad, c.swing_min_s, c.swing_max_s,
                                     c.hold_min_s, c.hold_max_s);
  return {curve, m};
}

// The next altitude manoeuvre.
std::pair<CosineCurve*, Manoeuvre> draw_vertical(const VerticalManoeuvreConfig& c, CosineCurve& height, Rng& rng) {
  Manoeuvre m =
      draw_manoeuvre(rng, c.height_min_m, c.height_max_m, c.swing_min_s, c.swing_max_s, c.hold_min_s, c.hold_max_s);
  // The largest swing (+A -> -A) peaks at A (pi / swing)^2.
  m.swing = std::max(m.swing, std::numbers::pi * std::sqrt(std::abs(m.amplitude) / c.max_acceleration_mps2));
  return {&height, m};
}

// The next turn: a step of the yaw rate (to the rate, held, back to zero), with a leg after it.
std::pair<CosineCurve*, Manoeuvre> draw_turn(const HeadingTurnConfig& c, CosineCurve& yaw_rate, Rng& rng) {
  Manoeuvre m =
      draw_manoeuvre(rng, c.rate_min_radps, c.rate_max_radps, c.ramp_min_s, c.ramp_max_s, c.hold_min_s, c.hold_max_s);
  m.kind = Manoeuvre::Kind::step;
  return {&yaw_rate, m};
}

}  // namespace

Trajectory plan_manoeuvres(const ManoeuvreConfig& c, double duration_s, Rng& rng) {
  Trajectory plan;
  double next_start_s = c.first_start_s;
  for (bool done = !c.enabled; !done;) {
    draw_next(next_start_s, done, c.gap_min_s, c.gap_max_s, duration_s, rng,
              [&](Rng& r) { return draw_attitude(c, plan, r); });
  }
  return plan;
}

CosineCurve plan_vertical_manoeuvres(const VerticalManoeuvreConfig& c, double duration_s, Rng& rng) {
  CosineCurve height;
  double next_start_s = c.first_start_s;
  for (bool done = !c.enabled; !done;) {
    draw_next(next_start_s, done, c.gap_min_s, c.gap_max_s, duration_s, rng,
              [&](Rng& r) { return draw_vertical(c, height, r); });
  }
  return height;
}

CosineCurve plan_heading_turns(const HeadingTurnConfig& c, double duration_s, Rng& rng) {
  CosineCurve yaw_rate;
  double next_start_s = c.first_start_s;
  for (bool done = !c.enabled; !done;) {
    draw_next(next_start_s, done, c.leg_min_s, c.leg_max_s, duration_s, rng,
              [&](Rng& r) { return draw_turn(c, yaw_rate, r); });
  }
  return yaw_rate;
}

FlightPlan::FlightPlan(const ManoeuvreConfig& manoeuvres, const VerticalManoeuvreConfig& vertical, double duration_s,
                       Rng attitude_rng, Rng vertical_rng, const HeadingTurnConfig& heading, Rng heading_rng)
    : manoeuvres_(manoeuvres),
      vertical_(vertical),
      heading_(heading),
      duration_s_(duration_s),
      attitude_{std::move(attitude_rng), manoeuvres.first_start_s, !manoeuvres.enabled},
      altitude_{std::move(vertical_rng), vertical.first_start_s, !vertical.enabled},
      turns_{std::move(heading_rng), heading.first_start_s, !heading.enabled} {}

// Every manoeuvre starting at or before t is drawn, so the curves' knots around t are the whole plan's; a curve whose
// next manoeuvre is still to come holds 0 until it, as the whole plan's does between its manoeuvres.
void FlightPlan::draw_until(double t) {
  while (!attitude_.done && attitude_.next_start_s <= t) {
    draw_next(attitude_.next_start_s, attitude_.done, manoeuvres_.gap_min_s, manoeuvres_.gap_max_s, duration_s_,
              attitude_.rng, [&](Rng& r) { return draw_attitude(manoeuvres_, drawn_, r); });
  }
  while (!altitude_.done && altitude_.next_start_s <= t) {
    draw_next(altitude_.next_start_s, altitude_.done, vertical_.gap_min_s, vertical_.gap_max_s, duration_s_,
              altitude_.rng, [&](Rng& r) { return draw_vertical(vertical_, drawn_.height, r); });
  }
  while (!turns_.done && turns_.next_start_s <= t) {
    draw_next(turns_.next_start_s, turns_.done, heading_.leg_min_s, heading_.leg_max_s, duration_s_, turns_.rng,
              [&](Rng& r) { return draw_turn(heading_, drawn_.yaw_rate, r); });
  }
}

FlightReference FlightPlan::at(double t) {
  draw_until(t);
  return drawn_.at(t);
}

void FlightPlan::forget_before(double t) {
  drawn_.roll.forget_before(t);
  drawn_.pitch.forget_before(t);
  drawn_.height.forget_before(t);
  drawn_.yaw_rate.forget_before(t);
}

}  // namespace imubridge::sim
