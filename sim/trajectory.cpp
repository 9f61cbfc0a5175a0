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
  // y = y0 + (y1 - y0) * (1 - cos(w * (t - t0))) / 2 with w = pi / (t1 - t0).
  const double w = std::numbers::pi / (t1 - t0);
  const double half_step = (y1 - y0) / 2;
  const double phase = w * (t - t0);
  return {y0 + half_step * (1 - std::cos(phase)), half_step * w * std::sin(phase), half_step * w * w * std::cos(phase)};
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

// Manoeuvres one after another from `first_start_s`, gaps of [gap_min, gap_max) between them, until one would end
// later than 1 s before the flight's end. `draw(rng)` gives the next manoeuvre and the curve it goes on.
template <typename Draw>
void plan_sequence(double first_start_s, double gap_min_s, double gap_max_s, double duration_s, Rng& rng, Draw draw) {
  for (double t = first_start_s;;) {
    const auto [curve, m] = draw(rng);
    if (t + m.length() > duration_s - 1.0) break;
    m.append_to(*curve, t);
    t += m.length() + rng.uniform(gap_min_s, gap_max_s);
  }
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

}  // namespace

Trajectory plan_manoeuvres(const ManoeuvreConfig& c, double duration_s, Rng& rng) {
  Trajectory plan;
  if (!c.enabled) return plan;
  plan_sequence(c.first_start_s, c.gap_min_s, c.gap_max_s, duration_s, rng, [&](Rng& r) {
    CosineCurve* curve = r.uniform() < c.roll_share ? &plan.roll : &plan.pitch;
    const Manoeuvre m = draw_manoeuvre(r, c.amplitude_min_rad, c.amplitude_max_rad, c.swing_min_s, c.swing_max_s,
                                       c.hold_min_s, c.hold_max_s);
    return std::pair{curve, m};
  });
  return plan;
}

CosineCurve plan_vertical_manoeuvres(const VerticalManoeuvreConfig& c, double duration_s, Rng& rng) {
  CosineCurve height;
  if (!c.enabled) return height;
  plan_sequence(c.first_start_s, c.gap_min_s, c.gap_max_s, duration_s, rng, [&](Rng& r) {
    Manoeuvre m =
        draw_manoeuvre(r, c.height_min_m, c.height_max_m, c.swing_min_s, c.swing_max_s, c.hold_min_s, c.hold_max_s);
    // The largest swing (+A -> -A) peaks at A (pi / swing)^2.
    m.swing = std::max(m.swing, std::numbers::pi * std::sqrt(std::abs(m.amplitude) / c.max_acceleration_mps2));
    return std::pair{&height, m};
  });
  return height;
}

}  // namespace imubridge::sim
