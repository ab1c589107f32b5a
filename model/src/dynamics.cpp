#include "pedalwave/model/dynamics.hpp"

namespace pedalwave::model {

void compute_mass_matrix(const Model& m, Data& d) {
  const int N = m.N();
  const double I_l = m.params().I_l;
  auto& Mz = d.Mz;
  // Absolute coordinates: links' and rotors' translation W_kl cos(θ_k − θ_l), link rotation I_l,
  // coupling to the mean position p, total mass on p.
  for (int k = 0; k < N; ++k) {
    for (int l = 0; l <= k; ++l) {
      const double v = m.W()(k, l) * (d.cos_t(k) * d.cos_t(l) + d.sin_t(k) * d.sin_t(l));
      Mz(k, l) = v;
      Mz(l, k) = v;
    }
    Mz(k, k) += I_l;
    Mz(k, N) = Mz(N, k) = -m.s()(k) * d.sin_t(k);
    Mz(k, N + 1) = Mz(N + 1, k) = m.s()(k) * d.cos_t(k);
  }
  Mz(N, N) = Mz(N + 1, N + 1) = m.total_mass();
  Mz(N, N + 1) = Mz(N + 1, N) = 0.0;
  // q_1 coordinates: Tᵀ Mz T, then the rotors' spin inertia I_r Lᵀ L on all of q.
  apply_T_right(N, Mz);
  apply_Tt_left(N, Mz);
  d.M = m.M_spin();
  d.M.topLeftCorner(m.nq1(), m.nq1()) += Mz;
  d.llt.compute(d.M);
  d.mass_valid = d.llt.info() == Eigen::Success;
}

void compute_bias(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q) {
  const int N = m.N();
  const double g = m.params().g;
  auto& gz = d.gz;
  // Coriolis/centripetal in absolute coordinates:
  //   c_θk = Σ_l W_kl sin(θ_k − θ_l) θ̇_l²,  c_p = −Σ_k s_k θ̇_k² [cos θ_k, sin θ_k].
  double cpx = 0.0, cpz = 0.0;
  for (int k = 0; k < N; ++k) {
    double a = 0.0, b = 0.0;
    for (int l = 0; l < N; ++l) {
      const double w = m.W()(k, l) * d.theta_dot(l) * d.theta_dot(l);
      a += w * d.cos_t(l);
      b += w * d.sin_t(l);
    }
    gz(k) = d.sin_t(k) * a - d.cos_t(k) * b;
    const double w = m.s()(k) * d.theta_dot(k) * d.theta_dot(k);
    cpx -= w * d.cos_t(k);
    cpz -= w * d.sin_t(k);
  }
  gz(N) = cpx;
  gz(N + 1) = cpz;
  apply_Tt_left_vec(N, gz);
  d.coriolis.setZero();
  d.coriolis.head(m.nq1()) = gz;

  // Gravity: V = g (m p_z + Σ s_k sin θ_k).
  for (int k = 0; k < N; ++k) gz(k) = g * m.s()(k) * d.cos_t(k);
  gz(N) = 0.0;
  gz(N + 1) = g * m.total_mass();
  apply_Tt_left_vec(N, gz);
  d.gravity.setZero();
  d.gravity.head(m.nq1()) = gz;

  // Springs: V = ½ Σ K_j (β_j − α_j)².
  d.spring.setZero();
  if (m.flexible()) {
    for (int j = 0; j < N - 1; ++j) {
      const double tau = m.K()(j) * (q(m.i_beta(j)) - q(m.i_alpha(j)));
      d.spring(m.i_alpha(j)) = -tau;
      d.spring(m.i_beta(j)) = tau;
    }
  }
  d.bias = d.coriolis + d.gravity + d.spring;
}

bool forward_dynamics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                      const Eigen::Ref<const VectorXd>& qd, const Eigen::Ref<const VectorXd>& u,
                      const Eigen::Ref<const VectorXd>& Q, Eigen::Ref<VectorXd> qdd) {
  update_kinematics(m, d, q, qd);
  compute_mass_matrix(m, d);
  if (!d.mass_valid) return false;
  compute_bias(m, d, q);
  d.rhs = -d.bias;
  if (Q.size() > 0) d.rhs += Q;
  // Motor torques act on β (flexible) or directly on α (rigid).
  const int first = m.flexible() ? m.i_beta(0) : m.i_alpha(0);
  if (u.size() > 0) d.rhs.segment(first, m.joints()) += u;
  d.llt.solveInPlace(d.rhs);
  qdd = d.rhs;
  return true;
}

void solve_mass(const Data& d, Eigen::Ref<VectorXd> b) { d.llt.solveInPlace(b); }

double kinetic_energy(const Data& d, const Eigen::Ref<const VectorXd>& qd) {
  double e = 0.0;  // ½ q̇ᵀ M q̇ without a temporary
  for (Eigen::Index i = 0; i < qd.size(); ++i) e += qd(i) * d.M.row(i).dot(qd);
  return 0.5 * e;
}

double gravity_energy(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& q) {
  return m.params().g * (m.total_mass() * q(m.i_pz()) + m.s().dot(d.sin_t));
}

double spring_energy(const Model& m, const Eigen::Ref<const VectorXd>& q) {
  if (!m.flexible()) return 0.0;
  double e = 0.0;
  for (int j = 0; j < m.joints(); ++j) {
    const double dx = q(m.i_beta(j)) - q(m.i_alpha(j));
    e += 0.5 * m.K()(j) * dx * dx;
  }
  return e;
}

void sea_torques(const Model& m, const Eigen::Ref<const VectorXd>& q, Eigen::Ref<VectorXd> tau) {
  for (int j = 0; j < m.joints(); ++j)
    tau(j) = m.flexible() ? m.K()(j) * (q(m.i_beta(j)) - q(m.i_alpha(j))) : 0.0;
}

}  // namespace pedalwave::model
