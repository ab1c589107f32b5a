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
