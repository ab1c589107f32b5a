// CiA 402 (IEC 61800-7-201) drive profile: the device control state machine as pure functions —
// the statusword (0x6041) decoded to a state, the controlword (0x6040) the host sends to bring a
// drive to Operation Enabled (shutdown 0x06 → switch on 0x07 → enable operation 0x0F; fault reset
// on a rising bit 7), and the drive's own transitions (for an emulated drive and the tests).
// Used by the CANopen master (canopen_driver.hpp) and the emulated drives (canopen_emulator.hpp).
#pragma once

#include <cstdint>

namespace pedalwave::drivers::cia402 {

// Objects of the profile the CANopen option will use.
inline constexpr std::uint16_t kObjControlword = 0x6040;
inline constexpr std::uint16_t kObjStatusword = 0x6041;
inline constexpr std::uint16_t kObjModesOfOperation = 0x6060;         // int8
inline constexpr std::uint16_t kObjModesOfOperationDisplay = 0x6061;  // int8
inline constexpr std::uint16_t kObjPositionActual = 0x6064;           // int32 [inc]
inline constexpr std::uint16_t kObjVelocityActual = 0x606C;           // int32
inline constexpr std::uint16_t kObjTargetTorque = 0x6071;             // int16 [‰ of rated torque]
inline constexpr std::uint16_t kObjTorqueActual = 0x6077;             // int16 [‰ of rated torque]
inline constexpr std::uint16_t kObjTargetPosition = 0x607A;           // int32 [inc]
// Modes of operation (0x6060).
inline constexpr std::int8_t kModeCsp = 8;   // cyclic synchronous position
inline constexpr std::int8_t kModeCsv = 9;   // cyclic synchronous velocity
inline constexpr std::int8_t kModeCst = 10;  // cyclic synchronous torque

enum class State : std::uint8_t {
  kNotReadyToSwitchOn,
  kSwitchOnDisabled,
  kReadyToSwitchOn,
  kSwitchedOn,
  kOperationEnabled,
  kQuickStopActive,
  kFaultReactionActive,
  kFault,
  kUnknown,  // a statusword matching no state
};
const char* to_string(State s) noexcept;

// Controlword commands (bits 7, 3 … 0).
inline constexpr std::uint16_t kCwDisableVoltage = 0x0000;
inline constexpr std::uint16_t kCwQuickStop = 0x0002;
inline constexpr std::uint16_t kCwShutdown = 0x0006;
inline constexpr std::uint16_t kCwSwitchOn = 0x0007;          // also: disable operation
inline constexpr std::uint16_t kCwEnableOperation = 0x000F;   // also: switch on + enable operation
inline constexpr std::uint16_t kCwFaultReset = 0x0080;        // acts on the rising edge of bit 7

// The state a statusword reports (bits 6, 5, 3 … 0).
State decode_statusword(std::uint16_t sw) noexcept;
// The state bits of a statusword for state s (kUnknown: 0).
std::uint16_t statusword_bits(State s) noexcept;
// What the host sends next to bring a drive in state s to Operation Enabled: shutdown, switch on,
// enable operation (kept while enabled); in Fault a fault reset edge (0x80 after a controlword
// without bit 7, else 0x00 first); in Quick Stop Active disable voltage; while the drive is on
// its own (not ready, fault reaction) disable voltage. `previous`: the last controlword sent.
std::uint16_t controlword_to_enable(State s, std::uint16_t previous) noexcept;
// The drive's transition on controlword `cw` (after `previous`), CiA 402's transitions 1 … 16
// (1 and 14, automatic, on any controlword).
State drive_transition(State s, std::uint16_t cw, std::uint16_t previous) noexcept;

}  // namespace pedalwave::drivers::cia402
