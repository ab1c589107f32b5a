// Shared helpers for the model tests: random states, an ODE wrapper around forward dynamics.
#pragma once

#include <random>

#include "pedalwave/model/dynamics.hpp"
#include "pedalwave/model/integrators.hpp"

namespace pedalwave::model::testing {

// Random configuration: joint angles within ±1 rad, θ_N anywhere, p within ±1 m, β near α.
inline VectorXd random_q(const Model& m, std::mt19937& rng, double deflection = 0.2) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  VectorXd q(m.nq());
  for (int i = 0; i < m.nq(); ++i) q(i) = u(rng);
  q(m.i_theta_N()) = 3.0 * u(rng);
  if (m.flexible())
    for (int j = 0; j < m.joints(); ++j) q(m.i_beta(j)) = q(m.i_alpha(j)) + deflection * u(rng);
  return q;
}

inline VectorXd random_v(const Model& m, std::mt19937& rng, double scale = 1.0) {
  std::uniform_real_distribution<double> u(-scale, scale);
  VectorXd v(m.nq());
  for (int i = 0; i < m.nq(); ++i) v(i) = u(rng);
  return v;
}

// The bare robot as an ODE: constant motor torques u, no contact.
class FreeRobot : public System {
 public:
  explicit FreeRobot(const Model& m) : m_(m), d_(m), u_(VectorXd::Zero(m.joints())), Q_(VectorXd::Zero(0)) {}
  int nq() const override { return m_.nq(); }
  bool acceleration(double, const VectorXd& q, const VectorXd& v, VectorXd& a) override {
    return forward_dynamics(m_, d_, q, v, u_, Q_, a);
  }
  VectorXd& u() { return u_; }
  double energy(const VectorXd& q, const VectorXd& v) {
    update_kinematics(m_, d_, q, v);
    compute_mass_matrix(m_, d_);
    return kinetic_energy(d_, v) + gravity_energy(m_, d_, q) + spring_energy(m_, q);
  }
  Data& data() { return d_; }

 private:
  const Model& m_;
  Data d_;
  VectorXd u_, Q_;
};

}  // namespace pedalwave::model::testing
