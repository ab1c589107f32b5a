// Adaptive admittance law on the spatial frequencies Π = [η_1 … η_{N−1}] (model-spec.md §7, P-35):
//
//   M_d (Π̈ − Π̈_n) + D_d (Π̇ − Π̇_n) + K_d (Π − Π_n) = k_c Q_e,      Π_n constant (Π̇_n = Π̈_n = 0)
//
// Q_e [N·m] are the measured SEA torques as the paper defines them, the first N−1 entries of K_T q:
//   Q_e,j = K_j (α_j − β_j) = −K_j · deflection_j,   deflection_j = β_j − α_j (drivers::Feedback).
// (So a joint whose motor leads its link, β > α, gives Q_e < 0.) The gains are the same for every
// joint; each joint's law is an independent 2-state system in x = η_j − η_n,j [rad], v = η̇_j [rad/s]:
//
//   d/dt [x; v] = A [x; v] + [0; 1] f,   A = [0 1; −K_d/M_d  −D_d/M_d],   f = k_c Q_e / M_d [rad/s²]
//
// Discretization (decision): exact zero-order-hold (ZOH). Q_e is a sampled measurement that is
// constant over one control period, so the ZOH map
//   [x; v](t+T) = Φ [x; v](t) + Γ f,   Φ = e^{A T},   Γ = ∫_0^T e^{A s} ds [0; 1]
// is the exact solution of the continuous law for that input: no discretization error at any rate,
// and the discrete eigenvalues are e^{λ T} with λ the continuous ones (Re λ < 0 when M_d, D_d,
// K_d > 0), so |e^{λ T}| < 1 for every T > 0 — stable for 100 Hz … 20 kHz and beyond. Φ and Γ are
// computed in closed form (2×2 matrix exponential via Cayley–Hamilton; cosh/sinh, cos/sin or the
// critically damped limit), no allocation, cached per dt in the state and recomputed only if dt
// changes. Semi-implicit Euler would also be stable here but adds O(T) error; exact ZOH costs
// one exp and one cos/cosh per dt change.
// Defaults (paper): M_d = 1, D_d = 10, K_d = 17.5 → ω_n = √(K_d/M_d) = 4.18 rad/s,
// ζ = D_d / (2 √(K_d M_d)) = 1.195 (over-damped: no overshoot), continuous poles −2.261, −7.739 s⁻¹.
// k_c = 0 gives Π = Π_n bit-for-bit (f is forced to 0, so a non-finite Q_e cannot leak in).
#pragma once

#include <cstdint>
#include <limits>
#include <numbers>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "pedalwave/control/types.hpp"

namespace pedalwave::control {

// Parameters of P-35. Per-joint vectors take 1 value (all joints) or N−1 values.
struct AdmittanceParams {
  double M_d = 1.0;    // desired inertia M_d [N·m·s²/rad], finite, > 0
  double D_d = 10.0;   // desired damping D_d [N·m·s/rad], finite, > 0
  double K_d = 17.5;   // desired stiffness K_d [N·m/rad], finite, > 0
  double k_c = 0.0;    // coupling gain k_c [-] (k_c Q_e is a torque like K_d Π), finite; 0 = open loop
  std::vector<double> eta_n{-2.0 * std::numbers::pi / 5.0};  // nominal η_n,j [rad], (1 or N−1)
  double eta_min = -std::numeric_limits<double>::infinity();  // lower bound on η_j [rad]
  double eta_max = std::numeric_limits<double>::infinity();   // upper bound on η_j [rad]
};

// Exact ZOH discretization of one joint's admittance for one period.
struct AdmittanceZoh {
  double dt = 0.0;                                  // period these matrices are for [s]
  Eigen::Matrix2d Phi = Eigen::Matrix2d::Identity();  // e^{A dt} [-, s; 1/s², -]
  Eigen::Vector2d Gamma = Eigen::Vector2d::Zero();    // ∫_0^dt e^{A s} ds [0;1] [s², s]
};

// Closed-form ZOH of d/dt[x;v] = [0 1; −K_d/M_d −D_d/M_d][x;v] + [0;1] f for period dt > 0.
// Requires M_d, K_d > 0, D_d ≥ 0, dt > 0 (not checked: a construction-time invariant).
AdmittanceZoh discretize_admittance(double M_d, double D_d, double K_d, double dt) noexcept;

// Largest eigenvalue modulus of Φ (the discrete admittance's spectral radius) [-].
double spectral_radius(const AdmittanceZoh& zoh) noexcept;

// Everything one admittance step writes. Sized for kMaxJoints; `joints` used.
struct AdmittanceState {
  int joints = 0;      // N−1 [-]
  JointArray x{};      // Π − Π_n, deviation of η_j from nominal [rad], (N−1)
  JointArray v{};      // Π̇, rate of η_j [rad/s], (N−1)
  AdmittanceZoh zoh;   // ZOH matrices cached for zoh.dt
};

class Admittance {
 public:
  // Validates (throws std::invalid_argument naming the field, value and expectation) and
  // precomputes the ZOH matrices for the nominal period [s] (> 0).
  Admittance(const AdmittanceParams& params, int joints, double period);

  int joints() const noexcept { return joints_; }
  const AdmittanceParams& params() const noexcept { return params_; }
  // η_n,j for 0-based joint index i [rad].
  double eta_n(int i) const noexcept { return Pi_n_[static_cast<std::size_t>(i)]; }
  const AdmittanceZoh& nominal_zoh() const noexcept { return nominal_; }

  // Π = Π_n, Π̇ = 0, ZOH cache = nominal period.
  void reset(AdmittanceState& s) const noexcept;

  // η_j (0-based i) [rad]: Π_n + x; exactly Π_n while x == 0.
  double eta(const AdmittanceState& s, int i) const noexcept {
    return Pi_n_[static_cast<std::size_t>(i)] + s.x[static_cast<std::size_t>(i)];
  }
  double eta_dot(const AdmittanceState& s, int i) const noexcept {
    return s.v[static_cast<std::size_t>(i)];
  }
  // η̈_j from the law itself for the current Q_e [N·m]: (k_c Q_e − D_d v − K_d x) / M_d [rad/s²].
  double eta_ddot(const AdmittanceState& s, int i, double Q_e) const noexcept;

  // Advances every joint from t to t + dt with Q_e [N·m] (N−1 values) held over the interval.
  // Joint i with a non-finite Q_e (and k_c ≠ 0) is held and flagged kJointBadTorque; a joint whose
  // η leaves [eta_min, eta_max] is clamped (its outward rate zeroed) and flagged kJointPiBound.
  // Flags are OR-ed into `flags`. dt must be finite and > 0 (the caller checks). No allocation.
  void step(AdmittanceState& s, std::span<const double> Q_e, double dt,
            std::span<std::uint8_t> flags) const noexcept;

 private:
  AdmittanceParams params_;
  int joints_;
  JointArray Pi_n_{};
  AdmittanceZoh nominal_;
};

}  // namespace pedalwave::control
