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

Manoeuvre::Kind draw_kind(Rng& rng) {
  return static_cast<Manoeuvre::Kind>(std::min(2, static_cast<int>(rng.uniform() * 3)));
}

double draw_sign(Rng& rng) { return rng.uniform() < 0.5 ? -1.0 : 1.0; }

}  // namespace

Trajectory plan_manoeuvres(const ManoeuvreConfig& c, double duration_s, Rng& rng) {
  Trajectory plan;
  if (!c.enabled) return plan;
  plan_sequence(c.first_start_s, c.gap_min_s, c.gap_max_s, duration_s, rng, [&](Rng& r) {
    CosineCurve* curve = r.uniform() < c.roll_share ? &plan.roll : &plan.pitch;
    Manoeuvre m;
    m.kind = draw_kind(r);
    const double sign = draw_sign(r);  // before the size, as plans have always been drawn: seeds keep their flights
    m.amplitude = sign * r.uniform(c.amplitude_min_rad, c.amplitude_max_rad);
    m.swing = r.uniform(c.swing_min_s, c.swing_max_s);
    m.hold = r.uniform(c.hold_min_s, c.hold_max_s);
    m.cycles = 2 + static_cast<int>(r.uniform() * 2);
    return std::pair{curve, m};
  });
  return plan;
}

CosineCurve plan_vertical_manoeuvres(const VerticalManoeuvreConfig& c, double duration_s, Rng& rng) {
  CosineCurve height;
  if (!c.enabled) return height;
  plan_sequence(c.first_start_s, c.gap_min_s, c.gap_max_s, duration_s, rng, [&](Rng& r) {
    Manoeuvre m;
    m.kind = draw_kind(r);
    const double sign = draw_sign(r);
    m.amplitude = sign * r.uniform(c.height_min_m, c.height_max_m);
    m.swing = r.uniform(c.swing_min_s, c.swing_max_s);
    m.hold = r.uniform(c.hold_min_s, c.hold_max_s);
    m.cycles = 2 + static_cast<int>(r.uniform() * 2);
    // The largest swing (+A -> -A) peaks at A (pi / swing)^2.
    m.swing = std::max(m.swing, std::numbers::pi * std::sqrt(std::abs(m.amplitude) / c.max_acceleration_mps2));
    return std::pair{&height, m};
  });
  return height;
}

}  // namespace imubridge::sim
