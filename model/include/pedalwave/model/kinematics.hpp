// Kinematics in the paper's matrix form (model-spec.md §2): positions and velocities of the 2N+1
// body points (tail tip, link COMs, joints = rotor COMs, head tip) and their Jacobians, all linear
// in cos θ, sin θ and q̇ with the constant coefficients of Model.
#pragma once

#include "pedalwave/model/model.hpp"

namespace pedalwave::model {

// Absolute angles and rates from q, q̇ (the q̇ may be empty: then theta_dot is not updated).
// Writes d.theta, d.cos_t, d.sin_t, d.theta_dot; invalidates the cached mass matrix.
void update_kinematics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                       const Eigen::Ref<const VectorXd>& qd);

// Point k position [m] and velocity [m/s] in the XZ plane (after update_kinematics).
Vec2 point_position(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& q, int k);
Vec2 point_velocity(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& qd, int k);

// Point Jacobian ∂[x_k, z_k]/∂q, written to J (2×nq, zero on the β columns).
void point_jacobian(const Model& m, const Data& d, int k, Eigen::Ref<MatrixXd> J);

// Q += J_kᵀ f: generalized force of a force f [N] applied at point k. O(N), no allocation.
void add_point_force(const Model& m, Data& d, int k, const Vec2& f, Eigen::Ref<VectorXd> Q);

// Generalized force of a torque τ [N·m] applied to link i about the Y axis (positive increases
// θ_i): Q += τ ∂θ_i/∂q.
void add_link_torque(const Model& m, int i, double tau, Eigen::Ref<VectorXd> Q);

// θ from q (absolute angles) into theta (N), no Data needed.
void absolute_angles(const Model& m, const Eigen::Ref<const VectorXd>& q, Eigen::Ref<VectorXd> theta);

// Whole-robot centre of mass (links and rotors) [m] and total linear momentum [kg·m/s].
Vec2 center_of_mass(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& q);
Vec2 linear_momentum(const Model& m, const Data& d, const Eigen::Ref<const VectorXd>& qd);

// In-place maps between absolute coordinates z = [θ, p] and q_1 = [α, θ_N, p] (z = T q_1):
//   A ← A T  (right-multiply the first N columns: running sum over columns)
//   A ← Tᵀ A (running sum over the first N rows)
void apply_T_right(int N, Eigen::Ref<MatrixXd> A);
void apply_Tt_left(int N, Eigen::Ref<MatrixXd> A);
void apply_Tt_left_vec(int N, Eigen::Ref<VectorXd> v);

}  // namespace pedalwave::model
