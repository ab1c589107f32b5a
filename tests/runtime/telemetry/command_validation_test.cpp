// validate_command: the pure rules that stand between the network and the runtime's mailbox.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "pedalwave/telemetry/command_validation.hpp"

namespace pedalwave::telemetry {
namespace {

using runtime::OperatorCommand;
using runtime::OperatorCommandKind;

OperatorCommand gait(double a, double w, double eta) {
  OperatorCommand c;
  c.kind = OperatorCommandKind::kSetGait;
  c.amplitude = a;
  c.omega = w;
  c.eta = eta;
  return c;
}

TEST(CommandValidation, GaitWithinClosedBoundsIsAccepted) {
  const TelemetryConfig cfg;
  EXPECT_TRUE(validate_command(gait(0.5, 3.0, 0.6), cfg).accepted);
  const auto& b = cfg.command_bounds;
  EXPECT_TRUE(validate_command(gait(b.amplitude_min, b.omega_min, b.eta_min), cfg).accepted);
  EXPECT_TRUE(validate_command(gait(b.amplitude_max, b.omega_max, b.eta_max), cfg).accepted);
}

TEST(CommandValidation, EachGaitFieldIsCheckedAgainstItsOwnBounds) {
  TelemetryConfig cfg;
  cfg.command_bounds = {0.1, 0.9, 1.0, 6.0, 0.2, 1.0};
  struct Case {
    OperatorCommand c;
    const char* field;
  };
  const double inf = std::numeric_limits<double>::infinity();
  for (const Case& k : {Case{gait(0.95, 3.0, 0.5), "amplitude = 0.95 rad out of bounds [0.1, 0.9]"},
                        Case{gait(0.05, 3.0, 0.5), "amplitude = 0.05"},
                        Case{gait(0.5, 6.5, 0.5), "omega = 6.5 rad/s out of bounds [1, 6]"},
                        Case{gait(0.5, 3.0, 1.1), "eta = 1.1 rad out of bounds [0.2, 1]"},
                        Case{gait(std::nan(""), 3.0, 0.5), "amplitude = nan is not a finite"},
                        Case{gait(0.5, inf, 0.5), "omega = inf is not a finite"},
                        Case{gait(0.5, 3.0, -inf), "eta = -inf is not a finite"}}) {
    const auto d = validate_command(k.c, cfg);
    EXPECT_FALSE(d.accepted) << k.field;
    EXPECT_NE(d.reason.find(k.field), std::string::npos) << d.reason;
  }
}

TEST(CommandValidation, StartAndStopIgnoreGaitFields) {
  const TelemetryConfig cfg;
  OperatorCommand c;
  c.kind = OperatorCommandKind::kStartWalking;
  c.amplitude = std::nan("");
  EXPECT_TRUE(validate_command(c, cfg).accepted);
  c.kind = OperatorCommandKind::kStopWalking;
  EXPECT_TRUE(validate_command(c, cfg).accepted);
}

TEST(CommandValidation, UnknownKindIsRejected) {
  OperatorCommand c;
  c.kind = static_cast<OperatorCommandKind>(4);
  const auto d = validate_command(c, TelemetryConfig{});
  EXPECT_FALSE(d.accepted);
  EXPECT_NE(d.reason.find("unknown command kind 4"), std::string::npos) << d.reason;
}

TEST(CommandValidation, DisabledRejectsEverythingButEmergencyStop) {
  TelemetryConfig cfg;
  cfg.enable_commands = false;
  for (auto k : {OperatorCommandKind::kStartWalking, OperatorCommandKind::kStopWalking,
                 OperatorCommandKind::kSetGait}) {
    OperatorCommand c = gait(0.5, 3.0, 0.6);
    c.kind = k;
    const auto d = validate_command(c, cfg);
    EXPECT_FALSE(d.accepted);
    EXPECT_NE(d.reason.find("commands disabled"), std::string::npos) << d.reason;
  }
  OperatorCommand stop;
  stop.kind = OperatorCommandKind::kEmergencyStop;
  stop.omega = std::nan("");
  EXPECT_TRUE(validate_command(stop, cfg).accepted);
  cfg.enable_commands = true;
  EXPECT_TRUE(validate_command(stop, cfg).accepted);
}

}  // namespace
}  // namespace pedalwave::telemetry
