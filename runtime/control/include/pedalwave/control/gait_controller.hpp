// GaitController: the control layer's cycle function, composing (model-spec.md §7)
//   adaptive admittance on Π (P-35, admittance.hpp) → gait α^d, α̇^d, α̈^d (P-34, gait.hpp)
//   → joint PD on motor-side measurements (P-33, joint_pd.hpp) → torque limits, last.
//
// update(t, dt, measurement, state, out) at time t [s] (the caller's clock, never read here):
//   1. Q_e,j = −K_j · deflection_j = K_j (α_j − β_j)   [N·m] (sign: admittance.hpp)
//   2. gait time τ = t − t_offset (t_offset = reset's t0 plus all frozen intervals)
//   3. Π(t), Π̇(t) from the state; Π̈(t) from the law with Q_e(t)
//   4. α^d_j = A_p sin(ω τ + η_j (j−1)) and derivatives, with η̇_j, η̈_j
//   5. u_j = −K_p,j (β_j − α^d_j) − K_D,j (β̇_j − α̇^d_j) + tau_ff_j, then |u| ≤ tau_max, rate limit
//   6. advance the admittance state from t to t + dt with Q_e(t) held (exact ZOH), so dt is the
//      period until the next update (= the control period in a fixed-rate loop) and Π(t) depends
//      on measurements up to t − dt (causal).
// Placement kHost: out.u is the torque to send. Placement kModule: out.u is the host's evaluation
// of the law the module applies (for telemetry/observer, limited and flagged the same way) and
// fill_command() sends set-points and gains instead.
//
// Freeze/hold (the runtime's "freeze the gait and hold" fault reaction): after freeze(), every
// update outputs the α^d of the last update (same τ, same Π), α̇^d = α̈^d = 0, the admittance is not
// advanced and the gait time stops; the PD keeps holding the joints at that α^d. resume() continues
// from the same phase (α^d is continuous across freeze/resume).
//
// Non-finite inputs: a joint with non-finite β or β̇ gets u = 0 (kJointBadMotor); a non-finite
// deflection holds that joint's η (kJointBadTorque); a bad dt holds the admittance and skips the
// rate limit, a non-finite t also holds the gait phase (kControlBadDt). Nothing in update allocates, locks, logs, throws or reads a clock.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "pedalwave/control/admittance.hpp"
#include "pedalwave/control/gait.hpp"
#include "pedalwave/control/joint_pd.hpp"
#include "pedalwave/control/host_pd_stability.hpp"
#include "pedalwave/control/types.hpp"
#include "pedalwave/interface/io.hpp"

namespace pedalwave::control {

// Actuator constants the controller needs. Per-joint vectors take 1 value or N−1 values.
struct ActuatorParams {
  std::vector<double> K{3.0};  // SEA spring stiffness K_j [N·m/rad], finite, > 0 (for Q_e)
  std::vector<double> reflected_inertia{255.0 * 255.0 * 5e-8};  // J_j = n² I_r [kg·m²], > 0
                                                                 // (host-PD stability check)
};

struct GaitControllerParams {
  int joints = 5;                 // N−1 joints [-], 1 … kMaxJoints
  double period = 1e-3;           // nominal control period T [s], 5e-5 … 1e-2 (20 kHz … 100 Hz)
  GaitParams gait;                // P-1 / P-34
  AdmittanceParams admittance;    // P-35 (k_c = 0: open-loop gait)
  PdParams pd;                    // P-33 gains and placement
  TorqueLimitParams limits;       // applied last
  ActuatorParams actuator;        // K, n² I_r
};

// Motor-side measurements of one cycle (views; at least N−1 entries each).
struct Measurement {
  std::span<const double> beta;        // β_j motor output angle [rad], (N−1)
  std::span<const double> beta_dot;    // β̇_j motor output rate [rad/s], (N−1)
  std::span<const double> deflection;  // β_j − α_j spring deflection [rad], (N−1)
};

// Views into a drivers::Feedback (fb.joints entries each).
Measurement measurement_from(const drivers::Feedback& fb) noexcept;

// Everything an update writes between cycles. Make it with GaitController::make_state().
struct GaitControllerState {
  int joints = 0;            // N−1 [-]
  double t_offset = 0.0;     // gait time τ = t − t_offset [s]
  double tau_last = 0.0;     // τ of the last update (the held phase while frozen) [s]
  bool frozen = false;       // freeze/hold active
  AdmittanceState admittance;  // Π − Π_n, Π̇, cached ZOH
  JointArray u_prev{};       // last limited torque, for the rate limit [N·m], (N−1)
  JointArray alpha_d_held{}; // α^d of the last running update (output while frozen) [rad], (N−1)
  JointArray eta_held{};      // η_j of the last running update (output while frozen) [rad], (N−1)
};

// Results of one update. Plain data, fixed size.
struct ControlOutput {
  int joints = 0;              // N−1 [-]
  double tau = 0.0;            // gait time τ used [s]
  std::uint32_t status = 0;    // ControlStatus bits
  JointArray u{};              // torque after limits [N·m] (kHost: the command; kModule: predicted)
  JointArray u_raw{};          // PD + feed-forward before limits [N·m]
  JointArray tau_ff{};         // feed-forward after the magnitude limit [N·m]
  JointArray alpha_d{};        // α^d_j [rad]
  JointArray alpha_d_dot{};    // α̇^d_j [rad/s]
  JointArray alpha_d_ddot{};   // α̈^d_j [rad/s²]
  JointArray eta{};             // η_j [rad]
  JointArray eta_dot{};         // η̇_j [rad/s]
  JointArray eta_ddot{};        // η̈_j [rad/s²]
  JointArray Q_e{};            // measured SEA torque K_j (α_j − β_j) = −K_j·deflection_j [N·m]
  JointFlags flags{};          // JointFlag bits (saturation: flags & kJointSaturated)
  bool saturated(int j) const noexcept {
    return (flags[static_cast<std::size_t>(j)] & kJointSaturated) != 0;
  }
};

class GaitController {
 public:
  // Validates every parameter (std::invalid_argument naming the parameter, the value and what was
  // expected). With pd.placement == kHost, also refuses a host-side PD that is discretely unstable
  // at `period` (check_host_pd_stability for each joint, with the spring to a fixed link and with
  // K = 0, i.e. a very light link), with a message giving the numbers and the fix.
  explicit GaitController(const GaitControllerParams& params);

  const GaitControllerParams& params() const noexcept { return params_; }
  int joints() const noexcept { return joints_; }
  PdPlacement placement() const noexcept { return params_.pd.placement; }
  const Admittance& admittance() const noexcept { return admittance_; }
  // Worst host-PD stability over joints at the nominal period (computed for either placement).
  const HostPdStability& host_pd_stability() const noexcept { return host_pd_; }
  // Resolved per-joint gains and limits.
  const JointArray& K_p() const noexcept { return K_p_; }
  const JointArray& K_D() const noexcept { return K_D_; }
  const JointArray& tau_max() const noexcept { return tau_max_; }

  // A state sized for this controller and reset with t0 = 0 (allocates nothing; call before the loop).
  GaitControllerState make_state() const noexcept;
  // Π = Π_n, Π̇ = 0, not frozen, u_prev = 0, gait time τ = t − t0 [s].
  void reset(GaitControllerState& state, double t0 = 0.0) const noexcept;

  // One cycle (see the file comment). tau_ff: optional feed-forward torques [N·m] (N−1), empty = 0.
  // Returns out.status.
  std::uint32_t update(double t, double dt, const Measurement& m, GaitControllerState& state,
                       ControlOutput& out, std::span<const double> tau_ff = {}) const noexcept;

  // Freeze/hold and resume (take effect at the next update).
  void freeze(GaitControllerState& state) const noexcept { state.frozen = true; }
  void resume(GaitControllerState& state) const noexcept { state.frozen = false; }

  // Fills the drivers::Command for the configured placement from an update's output.
  void fill_command(const ControlOutput& out, drivers::Command& cmd) const noexcept;

 private:
  GaitControllerParams params_;
  int joints_;
  Admittance admittance_;
  JointArray K_{};
  JointArray J_{};
  JointArray K_p_{};
  JointArray K_D_{};
  JointArray tau_max_{};
  JointArray tau_rate_max_{};
  HostPdStability host_pd_;
};

}  // namespace pedalwave::control
