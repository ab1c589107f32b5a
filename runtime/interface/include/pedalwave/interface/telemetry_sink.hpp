// The boundary between the runtime and whatever publishes its state (DDS, a CSV recorder, a test).
// The real-time cycle never calls a sink: it pushes CycleSample/EventSample into wait-free rings;
// a non-real-time consumer thread drains them and calls the sink. Operator commands travel the
// other way through a wait-free mailbox (OperatorCommand), validated before they reach the cycle.
#pragma once

#include <array>
#include <cstdint>
#include <type_traits>

#include "pedalwave/interface/sample.hpp"

namespace pedalwave::runtime {

// The robot description a late-joining monitor needs to interpret the rest (published once,
// reliable + transient-local).
struct RobotDescription {
  int links = 0;                 // N [-]
  double link_length = 0.0;      // 2l [m]
  double link_mass = 0.0;        // m_l [kg]
  double rotor_mass = 0.0;       // m_r [kg]
  double rotor_inertia = 0.0;    // I_r [kg·m²]
  double gear_ratio = 0.0;       // n [-]
  std::array<double, kMaxJoints> spring_stiffness{};  // K_j [N·m/rad], (N-1)
  double rate_hz = 0.0;          // control rate [Hz]
  std::array<char, 64> name{};   // robot name
  std::array<char, 32> driver{}; // "sim", "socketcan", "dynamixel"
};
static_assert(std::is_trivially_copyable_v<RobotDescription>);

class TelemetrySink {
 public:
  virtual ~TelemetrySink() = default;
  virtual void on_description(const RobotDescription& d) = 0;
  virtual void on_cycle(const CycleSample& s) = 0;
  virtual void on_event(const EventSample& e) = 0;
};

// Operator commands (from DDS or a CLI), validated by the receiver against configured bounds.
enum class OperatorCommandKind : std::uint8_t {
  kStartWalking = 0,
  kStopWalking,      // freeze the gait and hold
  kEmergencyStop,    // safe torque off; always honoured
  kSetGait,          // new A_p, ω, η (within configured bounds)
};

struct OperatorCommand {
  OperatorCommandKind kind = OperatorCommandKind::kStopWalking;
  std::uint64_t id = 0;          // sender's sequence number, echoed in the rejection/ack
  double amplitude = 0.0;        // A_p [rad]            (kSetGait)
  double omega = 0.0;            // ω [rad/s]            (kSetGait)
  double eta = 0.0;              // nominal η [rad]      (kSetGait)
};
static_assert(std::is_trivially_copyable_v<OperatorCommand>);

}  // namespace pedalwave::runtime
