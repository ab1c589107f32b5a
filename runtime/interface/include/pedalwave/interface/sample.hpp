// The plain sample the real-time cycle pushes into the wait-free ring once per cycle, and the
// event records (mode changes, faults). Trivially copyable, fixed size: the telemetry thread
// (non-real-time) turns them into DDS messages and log lines.
#pragma once

#include <array>
#include <cstdint>
#include <type_traits>

#include "pedalwave/interface/io.hpp"

namespace pedalwave::runtime {

using drivers::kMaxJoints;

enum class Mode : std::uint8_t {
  kUnconfigured = 0,
  kConfigured,
  kCalibrating,
  kReady,
  kRunning,
  kFault,
  kSafeStop,
};
const char* to_string(Mode m) noexcept;

// Fault classes (observer + runtime). Bit positions in CycleSample::fault_flags.
enum class FaultClass : std::uint8_t {
  kNone = 0,
  kActuatorTorque,     // torque loss / gain error
  kMotorFriction,      // motor friction increase
  kEncoderStuck,
  kEncoderJump,        // offset jump
  kEncoderNoise,       // noise burst
  kDeflectionStuck,
  kDeflectionBias,
  kDeflectionScale,
  kSpringBroken,       // stiffness drop
  kModuleSilent,       // module stopped answering
  kStaleData,          // stale / out-of-order data
  kImplausible,        // NaN / out-of-range values
  kSaturation,         // persistent torque saturation
  kOverrun,            // cycle deadline missed persistently
  kException,          // an exception escaped a stage or the driver (caught at the loop boundary)
  kStaleFeedback,      // a host-side law's feedback older than the driver's limit (X-series bus)
  kCount
};
const char* to_string(FaultClass f) noexcept;

enum class Severity : std::uint8_t { kInfo = 0, kWarning, kDegrade, kStop };
const char* to_string(Severity s) noexcept;  // "info", "warning", "degrade", "stop"

// One cycle of state, published at the loop rate (decimated by telemetry).
struct CycleSample {
  std::uint64_t seq = 0;                  // cycle number [-]
  std::int64_t t_ns = 0;                  // cycle wake-up time, CLOCK_MONOTONIC [ns]
  double t = 0.0;                         // controller time since RUNNING [s]
  Mode mode = Mode::kUnconfigured;
  int joints = 0;                         // N-1 [-]
  // Joint state (measured)
  std::array<double, kMaxJoints> beta{};        // [rad]
  std::array<double, kMaxJoints> beta_dot{};    // [rad/s]
  std::array<double, kMaxJoints> alpha{};       // β − deflection [rad]
  std::array<double, kMaxJoints> deflection{};  // [rad]
  std::array<double, kMaxJoints> tau_sea{};     // SEA torque K(β − α) [N·m]
  // Controller state
  std::array<double, kMaxJoints> alpha_d{};     // desired joint angle [rad]
  std::array<double, kMaxJoints> eta{};         // spatial frequencies Π = [η_j] [rad]
  std::array<double, kMaxJoints> u{};           // commanded torque (output side) [N·m]
  // Observer
  std::array<double, kMaxJoints> residual{};    // motor-side momentum residual [N·m]
  std::array<double, kMaxJoints> tau_ext{};     // external joint-torque estimate [N·m]
  std::array<double, 6> body{};                 // predicted θ_N, p_x, p_z [rad, m, m] and rates
  std::uint32_t fault_flags = 0;                // bit (1 << FaultClass)
  std::int16_t fault_joint = -1;                // isolated joint (0-based data field), −1 none
  double forward_speed = 0.0;                   // estimated forward speed [m/s]
  // Loop timing
  std::int32_t wake_latency_ns = 0;             // actual wake-up − deadline [ns]
  std::int32_t t_read_ns = 0, t_observe_ns = 0, t_control_ns = 0, t_write_ns = 0;  // [ns]
  std::uint32_t overruns = 0;                   // cumulative overruns [-]
  std::uint64_t ring_drops = 0;                 // cumulative samples dropped by the ring [-]
};
static_assert(std::is_trivially_copyable_v<CycleSample>);

// A mode change or a fault event (reliable, transient-local on the bus).
struct EventSample {
  std::uint64_t seq = 0;               // cycle at which it happened
  std::int64_t t_ns = 0;               // [ns]
  Mode from = Mode::kUnconfigured, to = Mode::kUnconfigured;
  FaultClass fault = FaultClass::kNone;
  Severity severity = Severity::kInfo;
  std::int16_t joint = -1;             // 0-based joint (data field; texts say "joint joint+1"), −1 none
  double value = 0.0;                  // evidence: residual / measured value
  double threshold = 0.0;              // evidence: threshold crossed
  std::array<char, 96> text{};         // short, NUL-terminated reason
};
static_assert(std::is_trivially_copyable_v<EventSample>);

}  // namespace pedalwave::runtime
