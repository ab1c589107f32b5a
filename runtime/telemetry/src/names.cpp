#include "pedalwave/telemetry/names.hpp"
#include "pedalwave/telemetry/messages.hpp"

#include <array>

namespace pedalwave::telemetry {
namespace {

constexpr std::array<const char*, 7> kModeNames = {
    "unconfigured", "configured", "calibrating", "ready", "running", "fault", "safe_stop"};

// Indexed by runtime::FaultClass. May name more classes than the runtime header currently has
// (the static_assert below fails if the runtime adds one we do not name).
constexpr std::array<const char*, 17> kFaultNames = {
    "none",          "actuator_torque",  "motor_friction",  "encoder_stuck",
    "encoder_jump",  "encoder_noise",    "deflection_stuck", "deflection_bias",
    "deflection_scale", "spring_broken", "module_silent",   "stale_data",
    "implausible",   "saturation",       "overrun",         "exception",
    "stale_feedback"};
static_assert(kFaultNames.size() >= static_cast<std::size_t>(runtime::FaultClass::kCount),
              "a runtime::FaultClass has no telemetry name: add it to kFaultNames");
constexpr std::size_t kFaultCount = static_cast<std::size_t>(runtime::FaultClass::kCount);

constexpr std::array<const char*, 4> kSeverityNames = {"info", "warning", "degrade", "stop"};

constexpr std::array<const char*, 4> kCommandNames = {"start_walking", "stop_walking",
                                                      "emergency_stop", "set_gait"};

template <std::size_t M>
std::string lookup(const std::array<const char*, M>& table, std::uint8_t v, const char* what) {
  if (v < M) return table[v];
  return std::string(what) + "?" + std::to_string(static_cast<unsigned>(v));
}

}  // namespace

std::string mode_name(std::uint8_t mode) { return lookup(kModeNames, mode, "mode"); }
std::string fault_class_name(std::uint8_t fault) {
  if (fault < kFaultCount) return kFaultNames[fault];
  return "fault?" + std::to_string(static_cast<unsigned>(fault));
}
std::string severity_name(std::uint8_t severity) {
  return lookup(kSeverityNames, severity, "severity");
}
std::string command_kind_name(std::uint8_t kind) { return lookup(kCommandNames, kind, "command"); }

const char* mode_c_str(std::uint8_t mode) noexcept {
  return mode < kModeNames.size() ? kModeNames[mode] : "?";
}
const char* fault_class_c_str(std::uint8_t fault) noexcept {
  return fault < kFaultCount ? kFaultNames[fault] : "?";
}
const char* severity_c_str(std::uint8_t severity) noexcept {
  return severity < kSeverityNames.size() ? kSeverityNames[severity] : "?";
}

std::string fault_flags_names(std::uint32_t flags) {
  std::string out;
  for (std::size_t b = 1; b < kFaultCount; ++b) {
    if ((flags & (1u << b)) != 0u) {
      if (!out.empty()) out += ',';
      out += kFaultNames[b];
    }
  }
  // Bits outside the known classes are shown numerically, never silently dropped.
  const std::uint32_t known = (1u << kFaultCount) - 1u;
  if ((flags & ~known) != 0u) {
    if (!out.empty()) out += ',';
    out += "unknown_bits=0x";
    constexpr const char* hex = "0123456789abcdef";
    const std::uint32_t rest = flags & ~known;
    for (int shift = 28; shift >= 0; shift -= 4) out += hex[(rest >> shift) & 0xFu];
  }
  return out;
}

}  // namespace pedalwave::telemetry

namespace pedalwave::telemetry {
const char* to_string(AckStatus s) noexcept {
  switch (s) {
    case AckStatus::kRejected: return "rejected";
    case AckStatus::kQueued: return "queued";
    case AckStatus::kExecuted: return "executed";
  }
  return "?";
}
}  // namespace pedalwave::telemetry
