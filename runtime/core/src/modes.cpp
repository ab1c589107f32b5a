#include "pedalwave/runtime/modes.hpp"

namespace pedalwave::runtime {

const char* to_string(Mode m) noexcept {
  switch (m) {
    case Mode::kUnconfigured: return "UNCONFIGURED";
    case Mode::kConfigured: return "CONFIGURED";
    case Mode::kCalibrating: return "CALIBRATING";
    case Mode::kReady: return "READY";
    case Mode::kRunning: return "RUNNING";
    case Mode::kFault: return "FAULT";
    case Mode::kSafeStop: return "SAFE_STOP";
  }
  return "?";
}

const char* to_string(FaultClass f) noexcept {
  switch (f) {
    case FaultClass::kNone: return "none";
    case FaultClass::kActuatorTorque: return "actuator_torque";
    case FaultClass::kMotorFriction: return "motor_friction";
    case FaultClass::kEncoderStuck: return "encoder_stuck";
    case FaultClass::kEncoderJump: return "encoder_jump";
    case FaultClass::kEncoderNoise: return "encoder_noise";
    case FaultClass::kDeflectionStuck: return "deflection_stuck";
    case FaultClass::kDeflectionBias: return "deflection_bias";
    case FaultClass::kDeflectionScale: return "deflection_scale";
    case FaultClass::kSpringBroken: return "spring_broken";
    case FaultClass::kModuleSilent: return "module_silent";
    case FaultClass::kStaleData: return "stale_data";
    case FaultClass::kImplausible: return "implausible";
    case FaultClass::kSaturation: return "saturation";
    case FaultClass::kOverrun: return "overrun";
    case FaultClass::kException: return "exception";
    case FaultClass::kStaleFeedback: return "stale_feedback";
    case FaultClass::kCount: break;
  }
  return "?";
}

const char* to_string(Severity s) noexcept {
  switch (s) {
    case Severity::kInfo: return "info";
    case Severity::kWarning: return "warning";
    case Severity::kDegrade: return "degrade";
    case Severity::kStop: return "stop";
  }
  return "?";
}

const char* to_string(TransitionStatus s) noexcept {
  switch (s) {
    case TransitionStatus::kOk: return "ok";
    case TransitionStatus::kNoChange: return "no_change";
    case TransitionStatus::kIllegal: return "illegal";
  }
  return "?";
}

bool transition_allowed(Mode from, Mode to) noexcept {
  using M = Mode;
  switch (from) {
    case M::kUnconfigured: return to == M::kConfigured;
    case M::kConfigured: return to == M::kCalibrating || to == M::kReady || to == M::kSafeStop;
    case M::kCalibrating: return to == M::kReady || to == M::kFault || to == M::kSafeStop;
    case M::kReady:
      return to == M::kCalibrating || to == M::kRunning || to == M::kFault || to == M::kSafeStop;
    case M::kRunning: return to == M::kFault || to == M::kSafeStop;
    case M::kFault: return to == M::kSafeStop;
    case M::kSafeStop: return false;
  }
  return false;
}

}  // namespace pedalwave::runtime
