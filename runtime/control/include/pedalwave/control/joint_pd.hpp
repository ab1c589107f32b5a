// Joint PD controller on motor-side measurements (model-spec.md §7, P-33), torque limits, and the
// hand-off to a drivers::Command for either PD placement.
//
//   u_j = −K_p,j (β_j − α^d_j) − K_D,j (β̇_j − α̇^d_j)        [N·m, output (link) side]
//
// Placement (configured, PdPlacement):
//  - kHost:   u is computed here at the control rate and sent as a torque (Command::tau = u,
//             kp = kd = 0); the module holds it until the next cycle (zero-order hold). Stable only
//             if the control period is short enough for the reflected rotor inertia J = n² I_r:
//             see host_pd_stability.hpp (T < 2 J / K_D is necessary; ≈ 0.43 ms for the defaults, i.e.
//             1 kHz is UNSTABLE) — GaitController refuses an unstable host-side configuration.
//  - kModule: the module applies u_j = tau_j + kp_j (beta_ref_j − β_j) + kd_j (beta_dot_ref_j − β̇_j)
//             at its own internal rate (interface/io.hpp), with beta_ref = α^d, beta_dot_ref = α̇^d,
//             kp = K_p, kd = K_D, tau = the (limited) feed-forward torque (0 for the paper's law).
//             This is the same law, so both placements agree at the sampling instants.
// Limits are applied last (after PD + feed-forward): |u_j| ≤ tau_max_j, then
// |u_j(k) − u_j(k−1)| ≤ tau_rate_max_j · dt. Because the previous command is already within
// ±tau_max, the rate-limited result stays within it too.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "pedalwave/control/types.hpp"
#include "pedalwave/interface/io.hpp"

namespace pedalwave::control {

enum class PdPlacement : std::uint8_t {
  kHost = 0,    // host computes u (torque command, ZOH at the control rate)
  kModule = 1,  // module applies the PD law at its own rate from set-points and gains
};

// PD gains (P-33). Per-joint vectors take 1 value (all joints) or N−1 values.
struct PdParams {
  std::vector<double> K_p{30.0};  // stiffness K_p,j [N·m/rad], finite, >= 0
  std::vector<double> K_D{15.0};  // damping K_D,j [N·m·s/rad], finite, >= 0
  PdPlacement placement = PdPlacement::kModule;  // default: stable for the paper's gains at 1 kHz
};

// Torque limits, applied last. +inf disables a limit (the default: the paper has none; a deployment
// should set tau_max to the module's continuous torque).
struct TorqueLimitParams {
  std::vector<double> tau_max{std::numeric_limits<double>::infinity()};       // |u_j| bound [N·m], > 0
  std::vector<double> tau_rate_max{std::numeric_limits<double>::infinity()};  // |Δu_j|/dt bound [N·m/s], > 0
};

// P-33 for one joint [N·m].
inline double pd_torque(double K_p, double K_D, double beta, double beta_dot, double alpha_d,
                        double alpha_d_dot) noexcept {
  return -K_p * (beta - alpha_d) - K_D * (beta_dot - alpha_d_dot);
}

struct LimitedTorque {
  double u = 0.0;           // torque after limits [N·m]
  std::uint8_t flags = 0;   // kJointSatMagnitude | kJointSatRate when active
};

// Clamps u_raw [N·m] to ±tau_max, then to u_prev ± tau_rate_max·dt (skipped when tau_rate_max is
// +inf or dt is not a finite positive number). Flags say which limit changed the value.
inline LimitedTorque limit_torque(double u_raw, double u_prev, double tau_max, double tau_rate_max,
                                  double dt) noexcept {
  LimitedTorque r;
  r.u = u_raw;
  if (r.u > tau_max) {
    r.u = tau_max;
    r.flags |= kJointSatMagnitude;
  } else if (r.u < -tau_max) {
    r.u = -tau_max;
    r.flags |= kJointSatMagnitude;
  }
  if (std::isfinite(tau_rate_max) && std::isfinite(dt) && dt > 0.0) {
    const double step = tau_rate_max * dt;  // largest change this period [N·m]
    if (r.u > u_prev + step) {
      r.u = u_prev + step;
      r.flags |= kJointSatRate;
    } else if (r.u < u_prev - step) {
      r.u = u_prev - step;
      r.flags |= kJointSatRate;
    }
  }
  return r;
}

// Fills cmd.joints and the per-joint fields of a drivers::Command for the given placement
// (cmd.seq and cmd.torque_off are left to the caller). All spans have at least `joints` entries.
//   kHost:   tau = u, beta_ref = α^d, beta_dot_ref = α̇^d, kp = kd = 0 (set-points for telemetry only)
//   kModule: tau = tau_ff, beta_ref = α^d, beta_dot_ref = α̇^d, kp = K_p, kd = K_D
void fill_command(PdPlacement placement, int joints, std::span<const double> K_p,
                  std::span<const double> K_D, std::span<const double> u,
                  std::span<const double> tau_ff, std::span<const double> alpha_d,
                  std::span<const double> alpha_d_dot, drivers::Command& cmd) noexcept;

}  // namespace pedalwave::control
