// Printable names of the runtime's enumerations, as they travel in the *_name string fields of the
// telemetry messages and appear in the monitor and the CSV files. Owned by telemetry (the runtime
// declares its own to_string; these do not depend on the runtime library being linked).
#pragma once

#include <cstdint>
#include <string>

#include "pedalwave/interface/telemetry_sink.hpp"

namespace pedalwave::telemetry {

// "running", "fault", ...; "mode?<n>" for a value outside the enumeration.
std::string mode_name(std::uint8_t mode);
// "encoder_stuck", ...; "none" for kNone; "fault?<n>" outside the enumeration.
std::string fault_class_name(std::uint8_t fault);
// "info", "warning", "degrade", "stop"; "severity?<n>" outside.
std::string severity_name(std::uint8_t severity);
// "start_walking", "stop_walking", "emergency_stop", "set_gait"; "command?<n>" outside.
std::string command_kind_name(std::uint8_t kind);

// Non-allocating variants: static strings, "?" outside the enumeration.
const char* mode_c_str(std::uint8_t mode) noexcept;
const char* fault_class_c_str(std::uint8_t fault) noexcept;
const char* severity_c_str(std::uint8_t severity) noexcept;

// Comma-separated names of the bits set in CycleSample::fault_flags ("" when none).
std::string fault_flags_names(std::uint32_t flags);

// Copies s into a fixed char array, truncating, always NUL-terminated.
template <std::size_t M>
void copy_bounded(char (&dst)[M], const char* s) noexcept {
  std::size_t i = 0;
  if (s != nullptr) {
    for (; i + 1 < M && s[i] != '\0'; ++i) dst[i] = s[i];
  }
  dst[i] = '\0';
}

}  // namespace pedalwave::telemetry
