#include "pedalwave/model/model.hpp"

#include <algorithm>
#include <stdexcept>

namespace pedalwave::model {

Model::Model(const Params& p) : p_(p) {
  validate(p_);
  const int N = p_.N;
  const int P = 2 * N + 1;
  nq_ = flexible() ? 2 * N + 1 : N + 2;

  // Point k sits at arc length k·l from the tail tip; link i spans [2il, 2(i+1)l]. Its position
  // relative to the tail tip is Σ_i a_ki [cos θ_i, sin θ_i] with a_ki = clamp(k l − 2 i l, 0, 2l).
  MatrixXd a(P, N);
  for (int k = 0; k < P; ++k)
    for (int i = 0; i < N; ++i) a(k, i) = std::clamp(k * p_.l - 2.0 * i * p_.l, 0.0, 2.0 * p_.l);
  // Eliminate the tail tip through p = mean of the link COMs (P-2..P-5).
  Eigen::RowVectorXd mean_com = Eigen::RowVectorXd::Zero(N);
  for (int i = 0; i < N; ++i) mean_com += a.row(point_com(i));
  mean_com /= N;
  c_ = a.rowwise() - mean_com;

  // Point masses: link COMs carry m_l, joints carry the rotors m_r, tips nothing.
  m_pt_ = VectorXd::Zero(P);
  for (int i = 0; i < N; ++i) m_pt_(point_com(i)) = p_.m_l;
  for (int j = 0; j < N - 1; ++j) m_pt_(point_joint(j)) = p_.m_r;
  m_total_ = m_pt_.sum();
  W_ = c_.transpose() * m_pt_.asDiagonal() * c_;
  s_ = c_.transpose() * m_pt_;

  K_.resize(N - 1);
  for (int j = 0; j < N - 1; ++j) K_(j) = p_.stiffness(j);

  // Rotor spin rate θ̇^r_j = θ̇_j − n β̇_j (stator on link j); θ_j = θ_N + Σ_{k≥j} α_k.
  L_ = MatrixXd::Zero(N - 1, nq_);
  for (int j = 0; j < N - 1; ++j) {
    for (int k = j; k < N - 1; ++k) L_(j, i_alpha(k)) = 1.0;
    L_(j, i_theta_N()) = 1.0;
    if (flexible())
      L_(j, i_beta(j)) = -p_.n;
    else if (p_.rigid_variant == RigidVariant::kExactLimit)
      L_(j, i_alpha(j)) -= p_.n;  // β ≡ α
  }
  M_spin_ = p_.I_r * L_.transpose() * L_;

  const int n1 = nq1(), J = N - 1;
  if (flexible()) {
    const auto S12 = M_spin_.topRightCorner(n1, J);
    d_inv_ = M_spin_.bottomRightCorner(J, J).diagonal().cwiseInverse();
    // The motor block must be diagonal (each rotor spins with its own β only).
    if (!(M_spin_.bottomRightCorner(J, J) - M_spin_.bottomRightCorner(J, J).diagonal().asDiagonal().toDenseMatrix())
             .isZero(0.0))
      throw std::logic_error("Model: the motor block of M_spin is not diagonal");
    spin_c_ = S12 * d_inv_.asDiagonal();
    spin_schur_ = M_spin_.topLeftCorner(n1, n1) - spin_c_ * S12.transpose();
  } else {
    spin_schur_ = M_spin_;
    spin_c_ = MatrixXd::Zero(n1, 0);
    d_inv_ = VectorXd::Zero(0);
  }
}

Data::Data(const Model& m)
    : theta(VectorXd::Zero(m.N())),
      theta_dot(VectorXd::Zero(m.N())),
      cos_t(VectorXd::Ones(m.N())),
      sin_t(VectorXd::Zero(m.N())),
      Mz(MatrixXd::Zero(m.nq1(), m.nq1())),
      M(MatrixXd::Zero(m.nq(), m.nq())),
      coriolis(VectorXd::Zero(m.nq())),
      gravity(VectorXd::Zero(m.nq())),
      spring(VectorXd::Zero(m.nq())),
      bias(VectorXd::Zero(m.nq())),
      rhs(VectorXd::Zero(m.nq())),
      gz(VectorXd::Zero(m.nq1())),
      chol(MatrixXd::Zero(m.nq1(), m.nq1())),
      links(static_cast<std::size_t>(m.N()), RecursiveLink{}) {}

}  // namespace pedalwave::model
