// The plant model's constant part (Model, built once from validated Params) and its workspace
// (Data, sized once from a Model; everything an evaluation writes lives here, so evaluations
// allocate nothing). Pinocchio's Model/Data split.
//
// Coordinates (model-spec.md §1), 0-based in code:
//   q = [α_0 … α_{N-2}, θ_N, p_x, p_z, β_0 … β_{N-2}]   (flexible, nq = 2N+1)
//   q = [α_0 … α_{N-2}, θ_N, p_x, p_z]                   (rigid,    nq = N+2)
// Absolute link angles θ_i (i = 0 … N-1, link N-1 carries θ_N): θ_i = θ_N + Σ_{k=i}^{N-2} α_k.
// Internally the dynamics is assembled in "absolute" coordinates z = [θ_0 … θ_{N-1}, p_x, p_z]
// and mapped to q_1 = [α, θ_N, p] by the constant T (z = T q_1, the paper's C with V and F);
// applying T from the right is a running sum over the θ columns.
//
// Points along the body (2N+1 candidate contact points, also the point masses): point k sits at
// arc length k·l from the tail tip: k = 0 tail tip, k = 2i+1 COM of link i, k = 2j+2 joint j
// (rotor j), k = 2N head tip. Position: [x_k, z_k] = [p_x, p_z] + Σ_i c_ki [cos θ_i, sin θ_i] with
// the constant coefficients c (the paper's H, A, B matrices, x_0 eliminated through p).
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <vector>

#include "pedalwave/model/params.hpp"

namespace pedalwave::model {

using Eigen::MatrixXd;
using Eigen::VectorXd;
using Vec2 = Eigen::Vector2d;

class Model {
 public:
  // Validates p (throws std::invalid_argument) and precomputes the constant matrices.
  explicit Model(const Params& p);

  const Params& params() const { return p_; }
  int N() const { return p_.N; }
  int joints() const { return p_.N - 1; }             // N-1
  int nq() const { return nq_; }                      // 2N+1 flexible, N+2 rigid
  int nq1() const { return p_.N + 2; }                // body coordinates
  int points() const { return 2 * p_.N + 1; }         // candidate contact points
  bool flexible() const { return p_.joints == JointModel::kFlexible; }

  // Indices into q.
  int i_alpha(int j) const { return j; }
  int i_theta_N() const { return p_.N - 1; }
  int i_px() const { return p_.N; }
  int i_pz() const { return p_.N + 1; }
  int i_beta(int j) const { return p_.N + 2 + j; }    // flexible only

  // Point indices.
  static int point_tail() { return 0; }
  static int point_com(int i) { return 2 * i + 1; }
  static int point_joint(int j) { return 2 * j + 2; }
  int point_head() const { return 2 * p_.N; }

  // Constants.
  const MatrixXd& point_coeff() const { return c_; }    // (2N+1)×N [m]
  const VectorXd& point_mass() const { return m_pt_; }  // (2N+1) [kg]
  const MatrixXd& W() const { return W_; }              // N×N Σ_b m_b c_b c_bᵀ [kg·m²]
  const VectorXd& s() const { return s_; }              // N   Σ_b m_b c_b [kg·m]
  double total_mass() const { return m_total_; }        // [kg]
  const VectorXd& K() const { return K_; }              // (N-1) [N·m/rad]
  const MatrixXd& L() const { return L_; }              // (N-1)×nq rotor spin map θ̇^r = L q̇
  const MatrixXd& M_spin() const { return M_spin_; }    // nq×nq  I_r Lᵀ L [kg·m²]

  // The mass matrix's constant motor block, eliminated once (flexible): with q = [q_1, β],
  //   M = [Mb + S11, S12; S21, D],  Mb = Tᵀ Mz T (configuration-dependent),  S = M_spin,
  // D = diag(n² I_r) is diagonal, so M x = b is solved through the (N+2)² Schur complement
  //   Mb + S11 − S12 D⁻¹ S21  (= Mb + spin_schur(); analytically S11 − S12 D⁻¹ S21 = 0)
  // and x_β = D⁻¹ b_β − (S12 D⁻¹)ᵀ x_1. Rigid: spin_schur() = M_spin, no motor block.
  const MatrixXd& spin_schur() const { return spin_schur_; }     // (N+2)² [kg·m²]
  const MatrixXd& spin_coupling() const { return spin_c_; }      // (N+2)×(N−1)  S12 D⁻¹ [-]
  const VectorXd& motor_inertia_inv() const { return d_inv_; }   // (N−1)  D⁻¹ [1/(kg·m²)]

 private:
  Params p_;
  int nq_;
  MatrixXd c_;
  VectorXd m_pt_;
  MatrixXd W_;
  VectorXd s_;
  double m_total_;
  VectorXd K_;
  MatrixXd L_;
  MatrixXd M_spin_;
  MatrixXd spin_schur_;
  MatrixXd spin_c_;
  VectorXd d_inv_;
};

// One link's slot in the recursive (articulated-body) forward dynamics (dynamics.hpp,
// forward_dynamics with ForwardSolver::kRecursive). Spatial vectors are planar [rotation; x; z],
// expressed in a world-aligned frame at the link's reference point o_i (its joint to the parent
// link i+1; the root link N-1: its COM). Written by every evaluation; no meaning between calls.
struct RecursiveLink {
  double d[2];    // o_i − o_{i+1} [m] (root: unused)
  double r[2];    // link COM − o_i [m]
  double w;       // θ̇_i [rad/s]
  double vo[2];   // velocity of o_i [m/s]
  double vg[2];   // velocity of the link COM [m/s]
  double c[2];    // velocity-product acceleration of the joint (linear part; rotation is 0) [m/s²]
  double IA[6];   // articulated inertia at o_i: [I00, h_x, h_z, M_xx, M_xz, M_zz] [SI]
  double pA[3];   // articulated bias force at o_i [N·m, N, N]
  double U[3];    // IA S (+ the geared rotor's share, rigid exact limit) [SI]
  double D_inv;   // 1 / (Sᵀ IA S (+ rotor)) [1/(kg·m²)]
  double u;       // joint torque less the bias's share, τ − Sᵀ pA [N·m]
  double tau_b;   // flexible: generalized force on β_i, u_i + Q_β − K(β − α) [N·m]
  double a[3];    // spatial acceleration at o_i [rad/s², m/s², m/s²]
};

// Workspace: sized once from a Model; every evaluation writes here and allocates nothing.
struct Data {
  explicit Data(const Model& m);

  // Kinematics (update_kinematics)
  VectorXd theta;       // absolute link angles θ [rad], (N)
  VectorXd theta_dot;   // θ̇ [rad/s], (N)
  VectorXd cos_t, sin_t;  // cos θ, sin θ, (N)
  // Dynamics
  MatrixXd Mz;          // mass matrix in absolute coordinates z [SI], (N+2)²
  MatrixXd M;           // mass matrix in q [SI], nq×nq
  VectorXd coriolis;    // c(q, q̇) [N or N·m], (nq)
  VectorXd gravity;     // G(q), (nq)
  VectorXd spring;      // K_T q, (nq)
  VectorXd bias;        // coriolis + gravity + spring, (nq)
  VectorXd rhs;         // B u + Q − bias, (nq)
  VectorXd gz;          // scratch generalized force in z, (N+2)
  MatrixXd chol;        // lower Cholesky factor of the Schur complement (Model::spin_schur), (N+2)²
  bool mass_valid = false;   // chol factors M at the current q (factor_mass / compute_mass_matrix)
  // Recursive forward dynamics (ForwardSolver::kRecursive), (N)
  std::vector<RecursiveLink> links;
};

}  // namespace pedalwave::model
