// Pedal-wave gait generator (model-spec.md §7, P-1 and its extended form P-34).
//
//   α^d_j(τ)  = A_p sin(φ_j),                 φ_j = ω τ + η_j (j−1),   j = 1 … N−1
//   α̇^d_j(τ)  = A_p cos(φ_j) · φ̇_j,           φ̇_j = ω + η̇_j (j−1)
//   α̈^d_j(τ)  = −A_p sin(φ_j) · φ̇_j² + A_p cos(φ_j) · η̈_j (j−1)
//
// τ is the gait's own time [s] (the caller's time minus the start time and any frozen intervals,
// see GaitController); η_j [rad] is the spatial frequency (phase lag per joint index) of joint j,
// η̇_j [rad/s] and η̈_j [rad/s²] its rates (from the adaptive admittance law, P-35; zero for the
// plain gait P-1). The η̇ term in α̇^d is what makes α̇^d the exact time derivative of α^d when
// Π = [η_1 … η_{N−1}] varies. Pure functions: no clock, no allocation, no throw.
#pragma once

#include <cmath>
#include <numbers>

namespace pedalwave::control {

// Gait parameters (P-1). Defaults are the paper's (model-spec.md §8).
struct GaitParams {
  double A_p = std::numbers::pi / 4.0;  // amplitude A_p [rad], finite, >= 0
  double omega = std::numbers::pi;      // temporal frequency ω [rad/s], finite (sign = direction)
};

// Throws std::invalid_argument naming the field, its value and what was expected.
void validate(const GaitParams& p);

// The desired joint trajectory at one instant for one joint.
struct GaitPoint {
  double alpha_d = 0.0;       // α^d_j desired relative joint angle [rad]
  double alpha_d_dot = 0.0;   // α̇^d_j [rad/s]
  double alpha_d_ddot = 0.0;  // α̈^d_j [rad/s²]
};

// Evaluates P-34 (and its first two time derivatives) for joint j (1-based, j = 1 … N−1) at gait
// time tau [s], given η_j [rad], η̇_j [rad/s], η̈_j [rad/s²].
// The phase is computed as omega*tau + eta*(j−1) in that order, so with η̇ = η̈ = 0 the result is
// bit-for-bit A_p*sin(omega*tau + eta*(j−1)).
inline GaitPoint gait_joint(const GaitParams& p, double tau, int j, double eta, double eta_dot,
                            double eta_ddot) noexcept {
  const double k = static_cast<double>(j - 1);  // joint index offset (j−1) [-]
  const double phi = p.omega * tau + eta * k;   // phase φ_j [rad]
  const double phi_dot = p.omega + eta_dot * k; // phase rate φ̇_j [rad/s]
  const double s = std::sin(phi);
  const double c = std::cos(phi);
  GaitPoint g;
  g.alpha_d = p.A_p * s;
  g.alpha_d_dot = p.A_p * c * phi_dot;
  g.alpha_d_ddot = -p.A_p * s * phi_dot * phi_dot + p.A_p * c * eta_ddot * k;
  return g;
}

}  // namespace pedalwave::control
