#pragma once
// The flight plan: roll and pitch angle references made of manoeuvres like the paper's laboratory flight
// (doublets, sinusoid bursts, steps), with seeded random amplitudes, lengths and timing.
#include <utility>
#include <vector>

#include "sim/random.hpp"

namespace imubridge::sim {

// A curve through knots (t, value) that follows a half cosine between consecutive knots: its rate is zero at every
// knot and its acceleration is bounded, so it can be fed forward to the attitude controller. A swing from +A to -A
// over h seconds is exactly half a period of a sinusoid of period 2h.
class CosineCurve {
 public:
  struct Point {
    double value = 0.0, rate = 0.0, acceleration = 0.0;
  };
  // Knot times must increase; a knot not later than the previous one is ignored.
  void add_knot(double t, double value);
  // Before the first knot and after the last one the curve holds that knot's value.
  Point at(double t) const;
  double end_time() const { return knots_.empty() ? 0.0 : knots_.back().first; }

 private:
  std::vector<std::pair<double, double>> knots_;
};

struct ManoeuvreConfig {
  bool enabled = true;
  double first_start_s = 2.0;  // calm lead-in
  double gap_min_s = 0.8, gap_max_s = 2.5;
  double amplitude_min_rad = 0.12, amplitude_max_rad = 0.35;
  double swing_min_s = 0.22, swing_max_s = 0.45;  // time from one level to the next (0 -> A, +A -> -A, ...)
  double hold_min_s = 0.1, hold_max_s = 0.8;      // level held inside doublets and steps
  double roll_share = 0.3;                        // the rest are pitch manoeuvres
};

// What the attitude controller tracks (body roll/pitch angles with their rates and accelerations, yaw rate).
struct AttitudeReference {
  CosineCurve::Point roll, pitch;
  double yaw_rate = 0.0;
};

struct Trajectory {
  CosineCurve roll, pitch;
  AttitudeReference at(double t) const { return {roll.at(t), pitch.at(t), 0.0}; }
};

// Manoeuvres start after the lead-in and all end before `duration_s` - 1 s.
Trajectory plan_manoeuvres(const ManoeuvreConfig& config, double duration_s, Rng& rng);

}  // namespace imubridge::sim
