#include "pedalwave/telemetry/command_validation.hpp"

#include <cmath>
#include <sstream>

#include "pedalwave/telemetry/names.hpp"

namespace pedalwave::telemetry {
namespace {

using runtime::OperatorCommandKind;

// Empty when v is finite and in [lo, hi]; else the reason.
std::string check_field(const char* name, double v, double lo, double hi, const char* unit) {
  std::ostringstream os;
  if (!std::isfinite(v)) {
    os << name << " = " << v << " is not a finite number";
  } else if (v < lo || v > hi) {
    os << name << " = " << v << " " << unit << " out of bounds [" << lo << ", " << hi << "] "
       << unit;
  }
  return os.str();
}

}  // namespace

CommandDecision validate_command(const runtime::OperatorCommand& c, const TelemetryConfig& cfg) {
  const auto kind = static_cast<std::uint8_t>(c.kind);
  if (kind > static_cast<std::uint8_t>(OperatorCommandKind::kSetGait)) {
    return {false, "unknown command kind " + std::to_string(kind) +
                       " (expected 0..3: start_walking, stop_walking, emergency_stop, set_gait)"};
  }
  if (c.kind == OperatorCommandKind::kEmergencyStop) {
    return {true, "emergency stop: always honoured"};
  }
  if (!cfg.enable_commands) {
    return {false, command_kind_name(kind) +
                       " rejected: commands disabled by configuration (enable_commands = false); "
                       "only emergency_stop is honoured"};
  }
  if (c.kind == OperatorCommandKind::kSetGait) {
    const auto& b = cfg.command_bounds;
    for (const auto& r : {check_field("amplitude", c.amplitude, b.amplitude_min, b.amplitude_max,
                                      "rad"),
                          check_field("omega", c.omega, b.omega_min, b.omega_max, "rad/s"),
                          check_field("eta", c.eta, b.eta_min, b.eta_max, "rad")}) {
      if (!r.empty()) return {false, "set_gait rejected: " + r};
    }
  }
  return {true, "accepted"};
}

}  // namespace pedalwave::telemetry
