#include "pedalwave/model/dynamics.hpp"

#include <cmath>

namespace pedalwave::model {

namespace {

// In-place lower Cholesky of the leading n×n block of A (the upper triangle is left as it was).
// Plain loops: at n = N + 2 ≈ 8 they beat a general blocked factorization several times over.
bool cholesky_in_place(MatrixXd& A, int n) {
  for (int j = 0; j < n; ++j) {
    double d = A(j, j);
    for (int k = 0; k < j; ++k) d -= A(j, k) * A(j, k);
    if (!(d > 0.0)) return false;  // also catches NaN
    d = std::sqrt(d);
    A(j, j) = d;
    const double inv = 1.0 / d;
    for (int i = j + 1; i < n; ++i) {
      double s = A(i, j);
      for (int k = 0; k < j; ++k) s -= A(i, k) * A(j, k);
      A(i, j) = s * inv;
    }
  }
  return true;
}

// Solve L Lᵀ x = b in place (L the lower factor in the leading n×n block).
void cholesky_solve(const MatrixXd& L, int n, Eigen::Ref<VectorXd> b) {
  for (int i = 0; i < n; ++i) {
    double s = b(i);
    for (int k = 0; k < i; ++k) s -= L(i, k) * b(k);
    b(i) = s / L(i, i);
  }
  for (int i = n - 1; i >= 0; --i) {
    double s = b(i);
    for (int k = i + 1; k < n; ++k) s -= L(k, i) * b(k);
    b(i) = s / L(i, i);
  }
}

// d.Mz = Tᵀ Mz T, the body block of M without the rotors' spin (at the last update_kinematics).
void assemble_body_mass(const Model& m, Data& d) {
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
  // q_1 coordinates: Tᵀ Mz T.
  apply_T_right(N, Mz);
  apply_Tt_left(N, Mz);
}

}  // namespace

void factor_mass(const Model& m, Data& d) {
  assemble_body_mass(m, d);
  auto& Mz = d.Mz;
  // Factor the Schur complement of the (constant, diagonal) motor block: Tᵀ Mz T + spin_schur.
  d.chol = Mz + m.spin_schur();
  d.mass_valid = cholesky_in_place(d.chol, m.nq1());
}

void compute_mass_matrix(const Model& m, Data& d, bool factor) {
  if (factor)
    factor_mass(m, d);
  else
    assemble_body_mass(m, d);
  // The rotors' spin inertia I_r Lᵀ L on all of q.
  d.M = m.M_spin();
  d.M.topLeftCorner(m.nq1(), m.nq1()) += d.Mz;
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
                      const Eigen::Ref<const VectorXd>& Q, Eigen::Ref<VectorXd> qdd,
                      ForwardSolver solver) {
  update_kinematics(m, d, q, qd);
  return solve_forward_dynamics(m, d, q, qd, u, Q, qdd, solver);
}

bool solve_forward_dynamics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                            const Eigen::Ref<const VectorXd>& qd, const Eigen::Ref<const VectorXd>& u,
                            const Eigen::Ref<const VectorXd>& Q, Eigen::Ref<VectorXd> qdd,
                            ForwardSolver solver) {
  if (solver == ForwardSolver::kRecursive) return recursive_forward_dynamics(m, d, q, qd, u, Q, qdd);
  factor_mass(m, d);
  if (!d.mass_valid) return false;
  compute_bias(m, d, q);
  d.rhs = -d.bias;
  if (Q.size() > 0) d.rhs += Q;
  // Motor torques act on β (flexible) or directly on α (rigid).
  const int first = m.flexible() ? m.i_beta(0) : m.i_alpha(0);
  if (u.size() > 0) d.rhs.segment(first, m.joints()) += u;
  solve_mass(m, d, d.rhs);
  qdd = d.rhs;
  return true;
}

void solve_mass(const Model& m, const Data& d, Eigen::Ref<VectorXd> b) {
  const int n1 = m.nq1(), J = m.flexible() ? m.joints() : 0;
  // M = [A, S12; S21, D] with D diagonal: (A − S12 D⁻¹ S21) x_1 = b_1 − S12 D⁻¹ b_β, then
  // x_β = D⁻¹ b_β − (S12 D⁻¹)ᵀ x_1. C = S12 D⁻¹ is constant (Model::spin_coupling).
  const auto& C = m.spin_coupling();
  for (int j = 0; j < J; ++j) {
    const double bb = b(n1 + j);
    if (bb != 0.0)
      for (int i = 0; i < n1; ++i) b(i) -= C(i, j) * bb;
  }
  cholesky_solve(d.chol, n1, b.head(n1));
  const auto& dinv = m.motor_inertia_inv();
  for (int j = 0; j < J; ++j) {
    double s = dinv(j) * b(n1 + j);
    for (int i = 0; i < n1; ++i) s -= C(i, j) * b(i);
    b(n1 + j) = s;
  }
}

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
