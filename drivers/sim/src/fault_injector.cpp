#include "pedalwave/drivers/fault_injector.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace pedalwave::drivers {

using model::FaultType;

FaultInjector::FaultInjector(int joints, bool physical, std::uint64_t seed)
    : joints_(joints), physical_(physical), rng_(seed) {
  faults_.reserve(kMaxFaults);
}

void FaultInjector::validate(const model::FaultSpec& f, std::string_view holder) const {
  const std::string what = "fault " + std::string(model::to_string(f.type)) + " (joint " +
                           std::to_string(f.joint) + ")";
  auto fail = [&](const char* key, double v, const std::string& expected) {
    throw std::invalid_argument(what + ": " + key + " = " + std::to_string(v) + ": " + expected);
  };
  if (static_cast<int>(faults_.size()) >= kMaxFaults)
    fail("count", static_cast<double>(faults_.size() + 1),
         "at most " + std::to_string(kMaxFaults) + " faults per " + std::string(holder));
  if (f.type >= FaultType::kCount) fail("type", static_cast<double>(f.type), "a known fault type");
  if (f.type != FaultType::kRepeatedFrame && (f.joint < 0 || f.joint >= joints_))
    fail("joint", f.joint, "a joint index 0 … N-2 of this robot");
  if (!std::isfinite(f.t_start) || f.t_start < 0) fail("t_start", f.t_start, "finite, >= 0 [s]");
  if (!(f.duration > 0)) fail("duration", f.duration, "> 0 [s] (or infinite)");
  if (f.type != FaultType::kNaN && !std::isfinite(f.value)) fail("value", f.value, "finite");
  if (model::is_physical(f.type) && !physical_)
    fail("joint", f.joint, "a wrapped SimDriver (physical faults act on the simulated plant)");
  switch (f.type) {
    case FaultType::kTorqueGain:
    case FaultType::kMotorFriction:
      if (f.value < 0) fail("value", f.value, ">= 0");
      break;
    case FaultType::kSpringScale:
      if (!(f.value > 0)) fail("value", f.value, "> 0 (a stiffness factor)");
      break;
    case FaultType::kEncoderNoise:
      if (f.value < 0) fail("value", f.value, ">= 0 (a standard deviation [rad])");
      break;
    case FaultType::kStale:
      if (f.value < 1 || f.value > kMaxStaleDelay)
        fail("value", f.value, "a delay of 1 … " + std::to_string(kMaxStaleDelay) + " cycles");
      break;
    default:
      break;
  }
}

void FaultInjector::add(const model::FaultSpec& f, std::string_view holder) {
  validate(f, holder);
  faults_.push_back(f);
}

void FaultInjector::clear() {
  faults_.clear();
  holding_.fill(false);
  physical_dirty_ = true;
}

FaultInjector::Activity FaultInjector::update(std::size_t i, double t) noexcept {
  if (!active(faults_[i], t)) {
    holding_[i] = false;
    return {};
  }
  const bool onset = !holding_[i];
  holding_[i] = true;
  return {true, onset};
}

void FaultInjector::apply_sensor(std::size_t i, bool onset, Feedback& out) noexcept {
  const model::FaultSpec& f = faults_[i];
  const auto j = static_cast<std::size_t>(f.joint < 0 ? 0 : f.joint);
  switch (f.type) {
    case FaultType::kEncoderStuck:
      if (onset) held_[i] = out.beta[j];
      out.beta[j] = held_[i];
      out.beta_dot[j] = 0.0;
      break;
    case FaultType::kEncoderOffset:
      out.beta[j] += f.value;
      break;
    case FaultType::kEncoderNoise:
      out.beta[j] += f.value * unit_(rng_);
      break;
    case FaultType::kDeflectionStuck:
      if (onset) held_[i] = out.deflection[j];
      out.deflection[j] = held_[i];
      break;
    case FaultType::kDeflectionBias:
      out.deflection[j] += f.value;
      break;
    case FaultType::kDeflectionScale:
      out.deflection[j] *= f.value;
      break;
    case FaultType::kNaN:
      out.deflection[j] = std::numeric_limits<double>::quiet_NaN();
      break;
    case FaultType::kImplausible:
      out.beta[j] = f.value;
      break;
    default:  // physical or communication: not a sensor fault
      break;
  }
}

void FaultInjector::apply_sensors(double t, Feedback& out) noexcept {
  for (std::size_t i = 0; i < faults_.size(); ++i) {
    const Activity a = update(i, t);
    if (a.active) apply_sensor(i, a.onset, out);
  }
}

bool FaultInjector::apply_physical(double t, model::PlantFaults& pf) noexcept {
  bool any = false;
  for (const model::FaultSpec& f : faults_) any |= model::is_physical(f.type);
  if (!any && !physical_dirty_) return false;
  // Healthy, then the faults active now (a fault that ended is healed here).
  pf.clear();
  physical_dirty_ = false;
  for (const model::FaultSpec& f : faults_) {
    if (!model::is_physical(f.type) || !active(f, t)) continue;
    physical_dirty_ = true;  // must be healed when it ends
    switch (f.type) {
      case FaultType::kTorqueGain: pf.torque_gain(f.joint) = f.value; break;
      case FaultType::kMotorFriction: pf.motor_friction(f.joint) = f.value; break;
      case FaultType::kSpringScale: pf.spring_scale(f.joint) = f.value; break;
      case FaultType::kJointLoad: pf.joint_load(f.joint) = f.value; break;
      default: break;
    }
  }
  return physical_dirty_;
}

bool FaultInjector::silent(int j, double t) const noexcept {
  for (const model::FaultSpec& f : faults_)
    if (f.type == FaultType::kModuleSilent && f.joint == j && active(f, t)) return true;
  return false;
}

}  // namespace pedalwave::drivers
