#pragma once
// The flight plan: roll and pitch angle references made of manoeuvres like the paper's laboratory flight
// (doublets, sinusoid bursts, steps), with seeded random amplitudes, lengths and timing; optionally, the same kinds
// of manoeuvre on the altitude (climbs and descents), which make the thrust vary, and turns of the heading.
#include <cstddef>
#include <utility>
#include <vector>

#include "sim/quadrotor.hpp"
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
  // Before the first knot and after the last one the curve holds that knot's value, as it does between two knots
  // of the same value: so a curve whose next knot is not known yet (FlightPlan) reads the same as the whole one.
  Point at(double t) const;
  double end_time() const { return knots_.empty() ? 0.0 : knots_.back().first; }
  // Releases the knots that no time from t on needs: all before the last one at or before t.
  void forget_before(double t);
  std::size_t knot_count() const { return knots_.size(); }

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

// Altitude manoeuvres: the altitude reference steps up or down and back (step), up then down past the hold and back
// (doublet) or bobs (burst). An identification flight excites the vertical axis so that the thrust varies; holding
// altitude, it varies only through the tilt, g / (cos phi cos theta). Off by default.
struct VerticalManoeuvreConfig {
  bool enabled = false;
  double first_start_s = 2.0;
  double gap_min_s = 0.5, gap_max_s = 2.0;
  double height_min_m = 0.3, height_max_m = 1.0;  // away from the hold altitude, up or down
  double swing_min_s = 0.5, swing_max_s = 1.2;
  double hold_min_s = 0.2, hold_max_s = 1.0;
  // A swing is slowed down, if need be, to keep the vertical acceleration under this: the thrust then stays within
  // (1 +- this / g) times the weight, well inside what the rotors give (thrust / weight about 4).
  double max_acceleration_mps2 = 0.5 * kGravity;
};

// Turns of the heading, as a survey flight makes them between its legs: the yaw-rate reference ramps up to a rate,
// holds it and ramps back to zero (a turn of some 30 to 180 degrees), then the heading is held for a leg of several
// seconds. Without turns a constant wind is, from the IMU alone, a constant force in body axes like a sensor tilt;
// turning rotates it through the body axes, where no tilt follows. Off by default.
struct HeadingTurnConfig {
  bool enabled = false;
  double first_start_s = 2.0;
  double leg_min_s = 3.0, leg_max_s = 7.0;             // heading held between turns
  double rate_min_radps = 0.25, rate_max_radps = 0.5;  // held yaw rate of a turn, either way
  double ramp_min_s = 0.5, ramp_max_s = 1.0;           // from no yaw rate to the turn's, and back
  double hold_min_s = 1.0, hold_max_s = 4.0;           // the turn's rate held
};

// What the controller tracks: body roll/pitch angles with their rates and accelerations, yaw rate, and the height
// above the hold altitude (m, up) with its rate and acceleration.
struct FlightReference {
  CosineCurve::Point roll, pitch;
  double yaw_rate = 0.0;
  CosineCurve::Point height;
};

struct Trajectory {
  CosineCurve roll, pitch, height;
  CosineCurve yaw_rate;  // its value is the rate reference (rad/s); empty without heading turns
  FlightReference at(double t) const { return {roll.at(t), pitch.at(t), yaw_rate.at(t).value, height.at(t)}; }
};

// Manoeuvres start after the lead-in and all end before `duration_s` - 1 s. Fills roll and pitch.
Trajectory plan_manoeuvres(const ManoeuvreConfig& config, double duration_s, Rng& rng);
// The same for the altitude: the height curve, empty when disabled.
CosineCurve plan_vertical_manoeuvres(const VerticalManoeuvreConfig& config, double duration_s, Rng& rng);
// The same for the heading: the yaw-rate curve, empty when disabled.
CosineCurve plan_heading_turns(const HeadingTurnConfig& config, double duration_s, Rng& rng);

// The plan of plan_manoeuvres(), plan_vertical_manoeuvres() and plan_heading_turns() (from the same generators, it
// reads the same at every time), drawn as the flight reaches it and released behind it: a flight of any length holds
// only the manoeuvres around the present.
class FlightPlan {
 public:
  FlightPlan(const ManoeuvreConfig& manoeuvres, const VerticalManoeuvreConfig& vertical, double duration_s,
             Rng attitude_rng, Rng vertical_rng, const HeadingTurnConfig& heading = {}, Rng heading_rng = Rng(0));

  // The reference at t; t must not go back before the last forget_before().
  FlightReference at(double t);
  void forget_before(double t);
  // The curves as far as drawn (and not yet released).
  const Trajectory& drawn() const { return drawn_; }

 private:
  // One generator's manoeuvres, drawn in order: every manoeuvre starting before next_start_s is on the curves.
  struct Sequence {
    Rng rng;
    double next_start_s;
    bool done;
  };
  void draw_until(double t);

  ManoeuvreConfig manoeuvres_;
  VerticalManoeuvreConfig vertical_;
  HeadingTurnConfig heading_;
  double duration_s_;
  Sequence attitude_, altitude_, turns_;
  Trajectory drawn_;
};

}  // namespace imubridge::sim
