// The onboard body model (private to the observer): the plant model driven by the measured joint
// angles. The joint coordinates α, β (and their rates/accelerations) are imposed from the
// measurements; the three body coordinates b = (θ_N, p_x, p_z) follow the body rows of
// model-spec.md §4 with contact against the nominal terrain:
//     M_bb b̈ = F_b(q, q̇) − M_bα α̈ − M_bβ β̈        (F_b: contact − Coriolis − gravity)
// integrated with the implicit-velocity step restricted to those rows (contact stiffness and
// friction implicit, as in the plant's own integrator). θ_N, p_x, p_z are therefore PREDICTED,
// not observed: nothing measured constrains them once the real terrain differs from the nominal.
// The α rows then give the external joint-torque estimate
//     τ_ext = M_α· q̈ + c_α + G_α − K·deflection_measured.
// Sized once; step() allocates nothing.
#pragma once

#include <Eigen/Core>

#include "pedalwave/model/plant.hpp"

namespace pedalwave::observer {

class BodyModel {
 public:
  BodyModel(const model::Params& robot, const model::Ground& ground);

  void reset() { started_ = false; }
  bool started() const { return started_; }

  // One period dt [s]. Inputs (N-1 each): α measured [rad], α̇, α̈ (filtered) [rad/s, rad/s²],
  // β, β̇ measured, β̈ (filtered), deflection measured [rad]. Writes τ_ext (N-1) [N·m].
  // Returns false (state untouched) if the model cannot be evaluated.
  bool step(const double* alpha, const double* alpha_dot, const double* alpha_ddot,
            const double* beta, const double* beta_dot, const double* beta_ddot,
            const double* deflection, double dt, double* tau_ext);

  double theta_N() const { return q_(m_.i_theta_N()); }
  double p_x() const { return q_(m_.i_px()); }
  double p_z() const { return q_(m_.i_pz()); }
  double theta_N_dot() const { return v_(m_.i_theta_N()); }
  double p_x_dot() const { return v_(m_.i_px()); }
  double p_z_dot() const { return v_(m_.i_pz()); }

 private:
  static model::Scene make_scene(const model::Params& robot, const model::Ground& ground);

  model::Plant plant_;
  const model::Model& m_;
  Eigen::VectorXd q_, v_, qdd_;
  model::ImplicitTerms terms_;
  bool started_ = false;
};

}  // namespace pedalwave::observer
