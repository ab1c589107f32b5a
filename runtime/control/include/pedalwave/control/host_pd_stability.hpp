// Discrete stability of a host-side joint PD (P-33 computed on the host, sent as a torque held by
// a zero-order hold for one control period T).
//
// Motor-side loop (model-spec.md §4, last N−1 rows, one joint, link side held):
//   J β̈ = u − K (β − α),   J = n² I_r (reflected rotor inertia, ≈ 3.25e-3 kg·m² for n = 255,
//   I_r = 5e-8 kg·m²), K the SEA spring, u_k = −K_p β_k − K_D β̇_k held over [kT, (k+1)T).
// With x = [β; β̇], A = [0 1; −K/J 0], B = [0; 1/J], the exact ZOH map is
//   x_{k+1} = (Φ − Γ F) x_k,   Φ = e^{A T},   Γ = ∫_0^T e^{A s} ds B,   F = [K_p  K_D],
// and the loop is stable iff the spectral radius ρ(Φ − Γ F) < 1.
//
// Velocity feedback alone (K_p = K = 0): Φ − ΓF = [1, T − K_D T²/(2J); 0, 1 − K_D T/J], so the rate
// is multiplied by 1 − K_D T/J each step and |1 − K_D T/J| < 1 needs T < 2 J / K_D (necessary).
// With K_p and K = 0 (Jury test on z² − (2 − a − d) z + (1 + a − d), a = K_p T²/(2J), d = K_D T/J):
// stable iff T < 2 J / K_D and T < 2 K_D / K_p, so for the paper's gains the bound is exactly
//   T < 2 J / K_D = 2 · 3.25e-3 / 15 = 4.33e-4 s  → control rate ≥ 2308 Hz.
// With the spring K = 3 N·m/rad to a fixed link the exact limit moves by < 0.1 % (the spring's
// time scale √(J/K) ≈ 33 ms is far slower than T). A host-side PD at 1 kHz has ρ ≈ 3.6 (diverges
// within a few ms); that is why the default placement is module-side (joint_pd.hpp).
//
// Options: a free link of inertia I_link on the spring (4 states [β, β̇, α, α̇]: J β̈ = u − K(β−α),
// I_link α̈ = K(β−α)), and whole periods of delay between sampling and applying u (augmented states).
// Configuration-time code: allocates, may throw std::invalid_argument on invalid inputs.
#pragma once

#include <string>

#include <Eigen/Core>

namespace pedalwave::control {

struct HostPdLoopOptions {
  double link_inertia = 0.0;  // I_link [kg·m²]; 0 → the link is fixed (spring to ground)
  int delay_steps = 0;        // whole control periods between sampling β and applying u [-], 0…8
};

struct HostPdStability {
  double spectral_radius = 0.0;  // ρ(Φ − ΓF) at the given T [-]
  bool stable = false;           // ρ < 1 (asymptotically stable; ρ = 1 counts as unstable)
  double velocity_bound = 0.0;   // 2 J / K_D, the velocity-feedback-only necessary bound [s] (inf if K_D = 0)
  double critical_period = 0.0;  // smallest T ≥ 1e-6 s with ρ ≥ 1 for the same loop [s]; inf if none ≤ 10 s
  double min_rate = 0.0;         // 1 / critical_period: the control rate must exceed this [Hz]
};

// The discrete closed-loop matrix Φ − ΓF (augmented for the options). Throws on invalid input
// (J ≤ 0, K_spring, K_p, K_D < 0 or non-finite, T ≤ 0, I_link < 0, delay_steps outside 0…8).
Eigen::MatrixXd host_pd_closed_loop(double J, double K_spring, double K_p, double K_D, double T,
                                    const HostPdLoopOptions& options = {});

// ρ of host_pd_closed_loop(...) [-].
double host_pd_spectral_radius(double J, double K_spring, double K_p, double K_D, double T,
                               const HostPdLoopOptions& options = {});

// Spectral radius and verdict at T, plus the critical period for the same loop (found by a
// geometric scan from 1e-6 s, refined by bisection to 1e-9 relative).
HostPdStability check_host_pd_stability(double J, double K_spring, double K_p, double K_D, double T,
                                        const HostPdLoopOptions& options = {});

// One-line human-readable summary with all the numbers (for logs and error messages).
std::string describe(const HostPdStability& s, double J, double K_spring, double K_p, double K_D,
                     double T);

}  // namespace pedalwave::control
