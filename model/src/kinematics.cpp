#include "pedalwave/model/kinematics.hpp"

#include <cmath>

namespace pedalwave::model {

void absolute_angles(const Model& m, const Eigen::Ref<const VectorXd>& q,
                     Eigen::Ref<VectorXd> theta) {
  const int N = m.N();
  theta(N - 1) = q(m.i_theta_N());
  for (int i = N - 2; i >= 0; --i) theta(i) = theta(i + 1) + q(m.i_alpha(i));
}

void update_kinematics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                       const Eigen::Ref<const VectorXd>& qd) {
  const int N = m.N();
  absolute_angles(m, q, d.theta);
  // glibc's sincos: one argument reduction for both, bit-identical to sin() and cos().
  for (int i = 0; i < N; ++i) ::sincos(d.theta(i), &d.sin_t(i), &d.cos_t(i));
  if (qd.size() > 0) {
    d.theta_dot(N - 1) = qd(m.i_theta_N());
    for (int i = N - 2; i >= 0; --i) d.theta_dot(i) = d.theta_dot(i + 1) + qd(m.i_alpha(i));
  }
  d.mass_valid = false;
}

Vec2 point_position(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& q, int k) {
  const auto c = m.point_coeff().row(k);
  return {q(m.i_px()) + c.dot(d.cos_t), q(m.i_pz()) + c.dot(d.sin_t)};
}

Vec2 point_velocity(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& qd, int k) {
  const auto c = m.point_coeff().row(k);
  double vx = qd(m.i_px()), vz = qd(m.i_pz());
  for (int i = 0; i < m.N(); ++i) {
    const double w = c(i) * d.theta_dot(i);
    vx -= w * d.sin_t(i);
    vz += w * d.cos_t(i);
  }
  return {vx, vz};
}

void point_jacobian(const Model& m, const Data& d, int k, Eigen::Ref<MatrixXd> J) {
  const int N = m.N();
  const auto c = m.point_coeff().row(k);
  J.setZero();
  // ∂/∂θ_i, then the running sum maps the θ columns to [α, θ_N] (z = T q_1).
  double sx = 0.0, sz = 0.0;
  for (int i = 0; i < N; ++i) {
    sx += -c(i) * d.sin_t(i);
    sz += c(i) * d.cos_t(i);
    J(0, i) = sx;
    J(1, i) = sz;
  }
  J(0, m.i_px()) = 1.0;
  J(1, m.i_pz()) = 1.0;
}

void add_point_force(const Model& m, Data& d, int k, const Vec2& f, Eigen::Ref<VectorXd> Q) {
  (void)d;
  const int N = m.N();
  const auto c = m.point_coeff().row(k);
  double run = 0.0;
  for (int i = 0; i < N; ++i) {
    run += c(i) * (-f.x() * d.sin_t(i) + f.y() * d.cos_t(i));
    Q(i) += run;  // i < N-1: α_i; i = N-1: θ_N
  }
  Q(m.i_px()) += f.x();
  Q(m.i_pz()) += f.y();
}

void add_link_torque(const Model& m, int i, double tau, Eigen::Ref<VectorXd> Q) {
  for (int k = i; k < m.N() - 1; ++k) Q(m.i_alpha(k)) += tau;
  Q(m.i_theta_N()) += tau;
}

Vec2 center_of_mass(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& q) {
  return Vec2{q(m.i_px()) + m.s().dot(d.cos_t) / m.total_mass(),
              q(m.i_pz()) + m.s().dot(d.sin_t) / m.total_mass()};
}

Vec2 linear_momentum(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& qd) {
  double px = m.total_mass() * qd(m.i_px()), pz = m.total_mass() * qd(m.i_pz());
  for (int i = 0; i < m.N(); ++i) {
    const double w = m.s()(i) * d.theta_dot(i);
    px -= w * d.sin_t(i);
    pz += w * d.cos_t(i);
  }
  return {px, pz};
}

void apply_T_right(int N, Eigen::Ref<MatrixXd> A) {
  for (int i = 1; i < N; ++i) A.col(i) += A.col(i - 1);
}

void apply_Tt_left(int N, Eigen::Ref<MatrixXd> A) {
  for (int i = 1; i < N; ++i) A.row(i) += A.row(i - 1);
}

void apply_Tt_left_vec(int N, Eigen::Ref<VectorXd> v) {
  for (int i = 1; i < N; ++i) v(i) += v(i - 1);
}

}  // namespace pedalwave::model
