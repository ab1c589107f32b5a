#include "pedalwave/drivers/cia402.hpp"

namespace pedalwave::drivers::cia402 {
namespace {
bool is_shutdown(std::uint16_t cw) noexcept { return (cw & 0x87) == 0x06; }
bool is_switch_on(std::uint16_t cw) noexcept { return (cw & 0x8F) == 0x07; }
bool is_enable(std::uint16_t cw) noexcept { return (cw & 0x8F) == 0x0F; }
bool is_disable_voltage(std::uint16_t cw) noexcept { return (cw & 0x82) == 0x00; }
bool is_quick_stop(std::uint16_t cw) noexcept { return (cw & 0x86) == 0x02; }
}  // namespace

const char* to_string(State s) noexcept {
  switch (s) {
    case State::kNotReadyToSwitchOn: return "not ready to switch on";
    case State::kSwitchOnDisabled: return "switch on disabled";
    case State::kReadyToSwitchOn: return "ready to switch on";
    case State::kSwitchedOn: return "switched on";
    case State::kOperationEnabled: return "operation enabled";
    case State::kQuickStopActive: return "quick stop active";
    case State::kFaultReactionActive: return "fault reaction active";
    case State::kFault: return "fault";
    case State::kUnknown: return "unknown";
  }
  return "?";
}

State decode_statusword(std::uint16_t sw) noexcept {
  switch (sw & 0x4F) {
    case 0x00: return State::kNotReadyToSwitchOn;
    case 0x40: return State::kSwitchOnDisabled;
    case 0x0F: return State::kFaultReactionActive;
    case 0x08: return State::kFault;
    default: break;
  }
  switch (sw & 0x6F) {
    case 0x21: return State::kReadyToSwitchOn;
    case 0x23: return State::kSwitchedOn;
    case 0x27: return State::kOperationEnabled;
    case 0x07: return State::kQuickStopActive;
    default: return State::kUnknown;
  }
}

std::uint16_t statusword_bits(State s) noexcept {
  switch (s) {
    case State::kNotReadyToSwitchOn: return 0x00;
    case State::kSwitchOnDisabled: return 0x40;
    case State::kReadyToSwitchOn: return 0x21;
    case State::kSwitchedOn: return 0x23;
    case State::kOperationEnabled: return 0x27;
    case State::kQuickStopActive: return 0x07;
    case State::kFaultReactionActive: return 0x0F;
    case State::kFault: return 0x08;
    case State::kUnknown: return 0x00;
  }
  return 0x00;
}

std::uint16_t controlword_to_enable(State s, std::uint16_t previous) noexcept {
  switch (s) {
    case State::kSwitchOnDisabled: return kCwShutdown;
    case State::kReadyToSwitchOn: return kCwSwitchOn;
    case State::kSwitchedOn:
    case State::kOperationEnabled: return kCwEnableOperation;
    case State::kFault: return (previous & 0x80) ? kCwDisableVoltage : kCwFaultReset;
    case State::kQuickStopActive:
    case State::kNotReadyToSwitchOn:
    case State::kFaultReactionActive:
    case State::kUnknown: return kCwDisableVoltage;
  }
  return kCwDisableVoltage;
}

State drive_transition(State s, std::uint16_t cw, std::uint16_t previous) noexcept {
  switch (s) {
    case State::kNotReadyToSwitchOn: return State::kSwitchOnDisabled;           // 1
    case State::kSwitchOnDisabled:
      return is_shutdown(cw) ? State::kReadyToSwitchOn : s;                     // 2
    case State::kReadyToSwitchOn:
      if (is_switch_on(cw)) return State::kSwitchedOn;                          // 3
      if (is_enable(cw)) return State::kOperationEnabled;                       // 3 + 4
      if (is_disable_voltage(cw) || is_quick_stop(cw)) return State::kSwitchOnDisabled;  // 7
      return s;
    case State::kSwitchedOn:
      if (is_enable(cw)) return State::kOperationEnabled;                       // 4
      if (is_shutdown(cw)) return State::kReadyToSwitchOn;                      // 6
      if (is_disable_voltage(cw) || is_quick_stop(cw)) return State::kSwitchOnDisabled;  // 10
      return s;
    case State::kOperationEnabled:
      if (is_switch_on(cw)) return State::kSwitchedOn;                          // 5
      if (is_shutdown(cw)) return State::kReadyToSwitchOn;                      // 8
      if (is_disable_voltage(cw)) return State::kSwitchOnDisabled;              // 9
      if (is_quick_stop(cw)) return State::kQuickStopActive;                    // 11
      return s;
    case State::kQuickStopActive:
      if (is_disable_voltage(cw)) return State::kSwitchOnDisabled;              // 12
      if (is_enable(cw)) return State::kOperationEnabled;                       // 16
      return s;
    case State::kFaultReactionActive: return State::kFault;                     // 14
    case State::kFault:
      return (cw & 0x80) && !(previous & 0x80) ? State::kSwitchOnDisabled : s;  // 15
    case State::kUnknown: return s;
  }
  return s;
}

}  // namespace pedalwave::drivers::cia402
