// Stair-climb events of a run over a scene with a box (the first of its obstacles): when the head
// gets on top, when the COM and when the whole body are past the box. One implementation for every
// tool that reports them (pedalwave_paper, pedalwave_sim).
#pragma once

#include <limits>
#include <string>

#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::simloop {

// NaN = never happened within the run.
struct StairEvents {
  double x_near = std::numeric_limits<double>::quiet_NaN();  // box extent along X [m]
  double x_far = std::numeric_limits<double>::quiet_NaN();
  double top = std::numeric_limits<double>::quiet_NaN();     // box top height [m]
  double t_head_on_top = std::numeric_limits<double>::quiet_NaN();  // head on the top face [s]:
      // the head tip x_near ≤ x ≤ x_far, its module's underside (the tip's z less the link's half
      // thickness, model::Params::half_thickness) within top − kOnTopBelow … top + kOnTopAbove
  double t_com_past = std::numeric_limits<double>::quiet_NaN();   // whole-robot COM x > x_far [s]
  double t_body_past = std::numeric_limits<double>::quiet_NaN();  // every body point x > x_far [s]
  double max_head_z = std::numeric_limits<double>::quiet_NaN();   // highest head-tip z [m]
};
inline constexpr double kOnTopBelow = 0.01;   // [m] contact penetration plus margin
inline constexpr double kOnTopAbove = 0.005;  // [m] touching, not swinging over it

class StairWatch {
 public:
  // `resolved`: the scene as the plant placed it (model::Plant::scene(): boxes at absolute x).
  // Watches nothing when the scene has no box.
  explicit StairWatch(const model::Scene& resolved);
  bool active() const { return active_; }
  // At time t [s] with the kinematics of q in d (model::update_kinematics).
  void observe(double t, const model::Model& m, const model::Data& d, const Eigen::VectorXd& q);
  // The events so far (max_head_z NaN until observed).
  StairEvents events() const;

 private:
  bool active_ = false;
  double half_ = 0.0;  // link half thickness [m]
  StairEvents e_;
};

// "head on top 0.2 s, COM past 45.4 s, whole body past — (box x = 0.212 … 0.322 m, top 0.06 m)"
std::string describe(const StairEvents& e);

}  // namespace pedalwave::simloop
