// Shared types of the control layer: fixed-size per-joint arrays (sized for kMaxJoints so that
// nothing in a cycle allocates) and the per-joint / per-update status bits.
#pragma once

#include <array>
#include <cstdint>

#include "pedalwave/interface/io.hpp"

namespace pedalwave::control {

inline constexpr int kMaxJoints = drivers::kMaxJoints;  // N−1 ≤ 63

using JointArray = std::array<double, kMaxJoints>;           // one value per joint, (N−1) used
using JointFlags = std::array<std::uint8_t, kMaxJoints>;     // JointFlag bits per joint

// Per-joint flags of one update (ControlOutput::flags).
enum JointFlag : std::uint8_t {
  kJointOk = 0,
  kJointSatMagnitude = 1u << 0,   // |u_j| was clamped to tau_max_j
  kJointSatRate = 1u << 1,        // u_j was rate-limited to tau_rate_max_j · dt
  kJointPiBound = 1u << 2,        // η_j was clamped to [eta_min, eta_max] by the admittance step
  kJointBadMotor = 1u << 3,       // β_j or β̇_j non-finite: u_j = 0 for this update
  kJointBadTorque = 1u << 4,      // deflection_j non-finite: η_j held (admittance not advanced)
};
inline constexpr std::uint8_t kJointSaturated = kJointSatMagnitude | kJointSatRate;

// Summary of one update (ControlOutput::status, also returned by GaitController::update).
enum ControlStatus : std::uint32_t {
  kControlOk = 0,
  kControlSaturated = 1u << 0,       // some joint's torque limit (magnitude or rate) was active
  kControlPiBound = 1u << 1,         // some η_j hit its bound
  kControlBadMeasurement = 1u << 2,  // some measurement non-finite (see flags) or spans too short
  kControlBadDt = 1u << 3,           // t non-finite (phase held), or dt non-finite or ≤ 0:
                                     // admittance held, no rate limit
  kControlFrozen = 1u << 4,          // gait frozen (hold): α^d held, α̇^d = 0, Π held
};

}  // namespace pedalwave::control
