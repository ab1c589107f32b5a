#include "body_model.hpp"

#include <Eigen/Dense>
#include <cmath>

#include "pedalwave/model/kinematics.hpp"

namespace pedalwave::observer {

model::Scene BodyModel::make_scene(const model::Params& robot, const model::Ground& ground) {
  model::Scene s;
  s.name = "observer body model";
  s.robot = robot;
  s.ground_on = true;
  s.ground = ground;
  s.ground.patches.clear();  // nominal terrain: one μ everywhere
  if (s.ground.law == model::FrictionLaw::kStickSlip || s.ground.law == model::FrictionLaw::kCoulomb)
    s.ground.law = model::FrictionLaw::kRegularized;  // smooth for the implicit step
  return s;
}

BodyModel::BodyModel(const model::Params& robot, const model::Ground& ground)
    : plant_(make_scene(robot, ground)), m_(plant_.model()) {
  const int n = m_.nq();
  q_ = Eigen::VectorXd::Zero(n);
  v_ = Eigen::VectorXd::Zero(n);
  qdd_ = Eigen::VectorXd::Zero(n);
  terms_.M = Eigen::MatrixXd::Zero(n, n);
  terms_.F = Eigen::VectorXd::Zero(n);
  terms_.dFdq = Eigen::MatrixXd::Zero(n, n);
  terms_.dFdv = Eigen::MatrixXd::Zero(n, n);
  plant_.input().torque_off = true;  // motor rows are imposed, never integrated here
}

bool BodyModel::step(const double* alpha, const double* alpha_dot, const double* alpha_ddot,
                     const double* beta, const double* beta_dot, const double* beta_ddot,
                     const double* deflection, double dt, double* tau_ext) {
  const model::Model& m = m_;
  const int J = m.joints();
  // Impose the measured joint coordinates.
  for (int j = 0; j < J; ++j) {
    q_(m.i_alpha(j)) = alpha[j];
    v_(m.i_alpha(j)) = alpha_dot[j];
    qdd_(m.i_alpha(j)) = alpha_ddot[j];
    q_(m.i_beta(j)) = beta[j];
    v_(m.i_beta(j)) = beta_dot[j];
    qdd_(m.i_beta(j)) = beta_ddot[j];
  }
  if (!started_) {
    // Start at rest with θ_N = 0, p_x = 0 and the lowest body point on the nominal ground.
    model::Data& d = plant_.data();
    q_(m.i_theta_N()) = 0.0;
    q_(m.i_px()) = 0.0;
    q_(m.i_pz()) = 0.0;
    v_(m.i_theta_N()) = v_(m.i_px()) = v_(m.i_pz()) = 0.0;
    model::update_kinematics(m, d, q_, v_);
    double z_low = 1e300;
    for (int k = 0; k < m.points(); ++k)
      z_low = std::min(z_low, model::point_position(m, d, q_, k).y());
    q_(m.i_pz()) = plant_.scene().ground.z - z_low;
    started_ = true;
  }
  if (!plant_.implicit_terms(0.0, q_, v_, terms_)) return false;
  // Body rows b = [θ_N, p_x, p_z] (contiguous in q), implicit-velocity step on them only.
  const int b0 = m.i_theta_N();
  Eigen::Matrix3d A;
  Eigen::Vector3d rhs;
  for (int r = 0; r < 3; ++r) {
    double f = terms_.F(b0 + r);
    for (int j = 0; j < J; ++j)
      f -= terms_.M(b0 + r, m.i_alpha(j)) * qdd_(m.i_alpha(j)) +
           terms_.M(b0 + r, m.i_beta(j)) * qdd_(m.i_beta(j));
    double dq_v = 0.0;
    for (int c = 0; c < 3; ++c) {
      A(r, c) = terms_.M(b0 + r, b0 + c) - dt * terms_.dFdv(b0 + r, b0 + c) -
                dt * dt * terms_.dFdq(b0 + r, b0 + c);
      dq_v += terms_.dFdq(b0 + r, b0 + c) * v_(b0 + c);
    }
    rhs(r) = dt * (f + dt * dq_v);
  }
  const Eigen::Vector3d dv = A.partialPivLu().solve(rhs);
  if (!dv.allFinite()) return false;
  for (int r = 0; r < 3; ++r) qdd_(b0 + r) = dv(r) / dt;
  // α rows at the start of the step (where implicit_terms evaluated the bias): the generalized
  // external force that the measured SEA torques and the motion need.
  const model::Data& d = plant_.data();
  for (int j = 0; j < J; ++j) {
    const int a = m.i_alpha(j);
    const double inertial = terms_.M.row(a).dot(qdd_);
    tau_ext[j] = inertial + d.coriolis(a) + d.gravity(a) - m.K()(j) * deflection[j];
  }
  for (int r = 0; r < 3; ++r) {
    v_(b0 + r) += dv(r);
    q_(b0 + r) += dt * v_(b0 + r);
  }
  return true;
}

}  // namespace pedalwave::observer
