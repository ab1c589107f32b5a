// Equations of motion (model-spec.md §4 flexible, §5 rigid) in stages:
//   kinematics → mass matrix → bias (Coriolis, gravity, spring) → forward dynamics.
//   M(q) q̈ + c(q, q̇) + K_T q + G(q) = B u + Q
// M: translational link+rotor inertia (W ∘ cos(θ_k − θ_l) in absolute coordinates, mapped by T),
// link rotation I_l, rotor spin I_r Lᵀ L. B u: motor torque on the β rows (flexible) or α rows
// (rigid). Q: any generalized external force (contact, friction, ...), nq.
// Forward dynamics has two solvers (ForwardSolver): the O(N) articulated-body recursion, which
// never forms M or the bias (the default, recursive_dynamics.cpp), and the staged dense solve below
// (the reference, and what the energies, implicit integrators and linearization use).
#pragma once

#include <cstdint>

#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/model.hpp"

namespace pedalwave::model {

// Factor M at the q given to the last update_kinematics, without assembling d.M: d.Mz holds the
// body block Tᵀ Mz T and d.chol the Cholesky factor of its Schur complement (Model::spin_schur);
// d.mass_valid tells whether M is positive definite. What the dense forward dynamics needs.
void factor_mass(const Model& m, Data& d);

// factor_mass, and the whole nq×nq d.M assembled (energies, implicit integrators, linearization).
// factor = false: d.M and d.Mz only (no Cholesky; d.chol and d.mass_valid untouched).
void compute_mass_matrix(const Model& m, Data& d, bool factor = true);

// d.coriolis, d.gravity, d.spring and d.bias at (q, q̇) (after update_kinematics with q̇).
void compute_bias(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q);

// How forward dynamics solves M q̈ = B u + Q − bias (the same equations, the same q̈ to rounding):
//   kRecursive  O(N): the articulated-body recursion of recursive_dynamics.cpp (the default).
//               Writes d.links only: d.M, d.chol, d.bias and its parts are not computed.
//   kDense      O(N²) assembly + O(N³) factorization: factor_mass (Schur complement of the motor
//               block, Cholesky of the (N+2)² body block), compute_bias, solve_mass. Also leaves
//               d.chol, d.coriolis, d.gravity, d.spring, d.bias at (q, q̇). The reference.
enum class ForwardSolver : std::uint8_t { kRecursive, kDense };

// q̈ = M⁻¹ (B u + Q − bias). Runs every stage (kinematics included). u: (N-1) output-side motor
// torques [N·m] or empty for none; Q: (nq) or empty for none. Returns false (qdd untouched) if M
// is not positive definite — impossible for validated parameters, but reported rather than
// producing NaN. Allocates nothing.
bool forward_dynamics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                      const Eigen::Ref<const VectorXd>& qd, const Eigen::Ref<const VectorXd>& u,
                      const Eigen::Ref<const VectorXd>& Q, Eigen::Ref<VectorXd> qdd,
                      ForwardSolver solver = ForwardSolver::kRecursive);

// forward_dynamics without the kinematics stage: needs update_kinematics(m, d, q, qd) first (the
// plant evaluates its contact forces in between).
bool solve_forward_dynamics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                            const Eigen::Ref<const VectorXd>& qd, const Eigen::Ref<const VectorXd>& u,
                            const Eigen::Ref<const VectorXd>& Q, Eigen::Ref<VectorXd> qdd,
                            ForwardSolver solver);

// The O(N) solver alone (after update_kinematics(m, d, q, qd)); see recursive_dynamics.cpp.
bool recursive_forward_dynamics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                                const Eigen::Ref<const VectorXd>& qd,
                                const Eigen::Ref<const VectorXd>& u,
                                const Eigen::Ref<const VectorXd>& Q, Eigen::Ref<VectorXd> qdd);

// Solve M x = b in place with the current factorization (after factor_mass or
// compute_mass_matrix): the motor block eliminated, (N+2)² Cholesky solve, back-substitution.
void solve_mass(const Model& m, const Data& d, Eigen::Ref<VectorXd> b);

// Energies [J] (after update_kinematics; kinetic also needs compute_mass_matrix).
double kinetic_energy(const Data& d, const Eigen::Ref<const VectorXd>& qd);
double gravity_energy(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& q);
double spring_energy(const Model& m, const Eigen::Ref<const VectorXd>& q);

// Spring (SEA) torques K(β − α) [N·m], (N-1); zero for rigid joints.
void sea_torques(const Model& m, const Eigen::Ref<const VectorXd>& q, Eigen::Ref<VectorXd> tau);

}  // namespace pedalwave::model
