// Helpers for the numerical hard-case tests: a passive energy that must not grow, a PD hold, and a
// runner that settles a plant, perturbs it and steps it with one integrator.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>

#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"

namespace pedalwave::model::hard {

// Module PD holding the motors at their current angles: u = K_p (β_ref − β) − K_D β̇, β_ref = β(q).
inline void hold_pd(Plant& p, const VectorXd& q, double K_p, double K_D) {
  const Model& m = p.model();
  for (int j = 0; j < m.joints(); ++j) {
    p.input().kp(j) = K_p;
    p.input().kd(j) = K_D;
    p.input().beta_dot_ref(j) = 0.0;
    p.input().beta_ref(j) = q(m.flexible() ? m.i_beta(j) : m.i_alpha(j));
  }
}

// Ground contact potential Σ ½ k δ² over the body points [J] (the plant's energy() leaves it out).
inline double contact_energy(Plant& p, const VectorXd& q) {
  const Scene& s = p.scene();
  if (!s.ground_on) return 0.0;
  const Model& m = p.model();
  double e = 0.0;
  for (int k = 0; k < m.points(); ++k) {
    const double depth = s.ground.z - point_position(m, p.data(), q, k).y();
    if (depth > 0) e += 0.5 * s.ground.k * depth * depth;
  }
  return e;
}

// Everything the passive system stores [J]: kinetic + gravity + springs + PD springs + contact.
// With a constant PD set-point and no feed-forward nothing puts energy in: it may only decrease
// (contact and PD damping, friction). Box contacts are not included.
inline double passive_energy(Plant& p, const VectorXd& q, const VectorXd& v) {
  double e = p.energy(q, v);  // also updates the kinematics contact_energy needs
  const Model& m = p.model();
  const ActuatorInput& in = p.input();
  if (!in.torque_off)
    for (int j = 0; j < m.joints(); ++j) {
      const double d = in.beta_ref(j) - q(m.flexible() ? m.i_beta(j) : m.i_alpha(j));
      e += 0.5 * in.kp(j) * d * d;
    }
  return e + contact_energy(p, q);
}

// Maximum penetration of any body point into the ground [m].
inline double ground_penetration(Plant& p, const VectorXd& q) {
  const Model& m = p.model();
  update_kinematics(m, p.data(), q, VectorXd());
  double d = 0.0;
  for (int k = 0; k < m.points(); ++k)
    d = std::max(d, p.scene().ground.z - point_position(m, p.data(), q, k).y());
  return d;
}

}  // namespace pedalwave::model::hard

// ---- Closed loop without the tools layer ---------------------------------------------------------
// The gait controller (control layer, module-side PD) stepping a Simulation in lockstep, one control
// period at a time: measure → update → the module's PD law set in the plant → advance one period.
// The same composition as tools/simloop's ClosedLoop, kept here so the model tests do not depend on
// the tools build.
#include <span>

#include "pedalwave/control/gait_controller.hpp"

namespace pedalwave::model::hard {

class GaitLoop {
 public:
  GaitLoop(const Scene& s, const IntegratorOptions& integ, double rate_hz = 1000.0)
      : sim_(s, integ), ctl_(params(s, rate_hz)), state_(ctl_.make_state()), period_(1.0 / rate_hz) {
    const int J = s.robot.N - 1;
    meas_.beta = VectorXd::Zero(J);
    meas_.beta_dot = VectorXd::Zero(J);
    meas_.deflection = VectorXd::Zero(J);
    ctl_.reset(state_, 0.0);
  }

  static control::GaitControllerParams params(const Scene& s, double rate_hz) {
    control::GaitControllerParams c;
    c.joints = s.robot.N - 1;
    c.period = 1.0 / rate_hz;
    c.gait.A_p = s.gait.A_p;
    c.gait.omega = s.gait.omega;
    c.admittance.eta_n = {s.gait.eta};
    c.actuator.K = {s.robot.joints == JointModel::kFlexible ? s.robot.stiffness(0) : 1e6};
    c.actuator.reflected_inertia = {std::max(s.robot.n * s.robot.n * s.robot.I_r, 1e-12)};
    return c;
  }

  StepStatus step() {
    Plant& p = sim_.plant();
    const double t = period_ * static_cast<double>(cycle_);
    p.measure(sim_.q(), sim_.v(), meas_);
    const auto J = static_cast<std::size_t>(meas_.beta.size());
    const control::Measurement m{std::span<const double>(meas_.beta.data(), J),
                                 std::span<const double>(meas_.beta_dot.data(), J),
                                 std::span<const double>(meas_.deflection.data(), J)};
    ctl_.update(t, period_, m, state_, out_);
    ctl_.fill_command(out_, cmd_);
    ActuatorInput& in = p.input();
    for (std::size_t j = 0; j < J; ++j) {
      const auto i = static_cast<Eigen::Index>(j);
      in.tau(i) = cmd_.tau[j];
      in.beta_ref(i) = cmd_.beta_ref[j];
      in.beta_dot_ref(i) = cmd_.beta_dot_ref[j];
      in.kp(i) = cmd_.kp[j];
      in.kd(i) = cmd_.kd[j];
    }
    ++cycle_;
    return sim_.advance_to(period_ * static_cast<double>(cycle_));
  }

  Simulation& sim() { return sim_; }
  const control::ControlOutput& control() const { return out_; }
  double t() const { return period_ * static_cast<double>(cycle_); }

 private:
  Simulation sim_;
  control::GaitController ctl_;
  control::GaitControllerState state_;
  control::ControlOutput out_{};
  drivers::Command cmd_{};
  Measurement meas_;
  double period_;
  std::uint64_t cycle_ = 0;
};

// Whole-robot centre of mass [m].
inline Vec2 com(Simulation& s) {
  const Model& m = s.plant().model();
  update_kinematics(m, s.plant().data(), s.q(), VectorXd());
  return center_of_mass(m, s.plant().data(), s.q());
}

}  // namespace pedalwave::model::hard
