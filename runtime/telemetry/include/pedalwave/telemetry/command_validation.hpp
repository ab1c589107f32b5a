// Validation of an operator command received from the network, before it may reach the runtime's
// mailbox. Pure function of (command, configuration).
#pragma once

#include <string>

#include "pedalwave/interface/telemetry_sink.hpp"
#include "pedalwave/telemetry/config.hpp"

namespace pedalwave::telemetry {

struct CommandDecision {
  bool accepted = false;
  std::string reason;   // "accepted" / "emergency stop: always honoured" / why it was rejected
};

// Rules, in order:
//  1. kind outside OperatorCommandKind              → rejected ("unknown command kind ...")
//  2. kEmergencyStop                                → accepted, always (fields ignored, even NaN;
//                                                     even with commands disabled)
//  3. cfg.enable_commands == false                  → rejected ("commands disabled ...")
//  4. kSetGait: amplitude, omega, eta each finite and within cfg.command_bounds (closed
//     intervals)                                    → else rejected, naming field, value, bounds
//  5. kStartWalking, kStopWalking                   → accepted (gait fields ignored)
CommandDecision validate_command(const runtime::OperatorCommand& c, const TelemetryConfig& cfg);

}  // namespace pedalwave::telemetry
