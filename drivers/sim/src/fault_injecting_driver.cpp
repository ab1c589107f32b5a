#include "pedalwave/drivers/fault_injecting_driver.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace pedalwave::drivers {

using model::FaultType;

FaultInjectingDriver::FaultInjectingDriver(Driver& inner, SimDriver* sim,
                                           const std::vector<model::FaultSpec>& faults,
                                           std::uint64_t seed)
    : inner_(inner), sim_(sim), rng_(seed), history_(kHistory) {
  faults_.reserve(kMaxFaults);
  for (const model::FaultSpec& f : faults) add(f);
}

FaultInjectingDriver::FaultInjectingDriver(SimDriver& sim, std::uint64_t seed)
    : FaultInjectingDriver(sim, &sim, sim.sim().plant().scene().faults, seed) {}

void FaultInjectingDriver::validate(const model::FaultSpec& f) const {
  const std::string what = "fault " + std::string(model::to_string(f.type)) + " (joint " +
                           std::to_string(f.joint) + ")";
  auto fail = [&](const char* key, double v, const char* expected) {
    throw std::invalid_argument(what + ": " + key + " = " + std::to_string(v) + ": " + expected);
  };
  if (static_cast<int>(faults_.size()) >= kMaxFaults)
    fail("count", static_cast<double>(faults_.size() + 1), "at most 32 faults per driver");
  if (f.type >= FaultType::kCount) fail("type", static_cast<double>(f.type), "a known fault type");
  if (f.type != FaultType::kRepeatedFrame && (f.joint < 0 || f.joint >= inner_.joints()))
    fail("joint", f.joint, "a joint index 0 … N-2 of this robot");
  if (!std::isfinite(f.t_start) || f.t_start < 0) fail("t_start", f.t_start, "finite, >= 0 [s]");
  if (!(f.duration > 0)) fail("duration", f.duration, "> 0 [s] (or infinite)");
  if (f.type != FaultType::kNaN && !std::isfinite(f.value)) fail("value", f.value, "finite");
  if (model::is_physical(f.type) && sim_ == nullptr)
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
      if (f.value < 1 || f.value > kHistory - 1) fail("value", f.value, "a delay of 1 … 15 cycles");
      break;
    default:
      break;
  }
}

void FaultInjectingDriver::add(const model::FaultSpec& f) {
  validate(f);
  faults_.push_back(f);
}

void FaultInjectingDriver::clear() {
  faults_.clear();
  holding_.fill(false);
  physical_dirty_ = true;
}

IoStatus FaultInjectingDriver::read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) {
  IoStatus status = inner_.read(now_ns, deadline_ns, clean_);
  if (!started_) {
    started_ = true;
    stamp0_ = clean_.stamp_ns;
  }
  t_ = static_cast<double>(clean_.stamp_ns - stamp0_) * 1e-9;
  const std::uint64_t now = cycles_++;
  history_[static_cast<std::size_t>(now % kHistory)] = clean_;
  out = clean_;
  for (std::size_t i = 0; i < faults_.size(); ++i) {
    const model::FaultSpec& f = faults_[i];
    if (!active(f)) {
      holding_[i] = false;
      continue;
    }
    const auto j = static_cast<std::size_t>(f.joint < 0 ? 0 : f.joint);
    const bool onset = !holding_[i];
    holding_[i] = true;
    switch (f.type) {
      case FaultType::kEncoderStuck:
        if (onset) held_a_[i] = out.beta[j];
        out.beta[j] = held_a_[i];
        out.beta_dot[j] = 0.0;
        break;
      case FaultType::kEncoderOffset:
        out.beta[j] += f.value;
        break;
      case FaultType::kEncoderNoise:
        out.beta[j] += f.value * unit_(rng_);
        break;
      case FaultType::kDeflectionStuck:
        if (onset) held_a_[i] = out.deflection[j];
        out.deflection[j] = held_a_[i];
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
      case FaultType::kModuleSilent:
        // No new frame from this module: the driver repeats its last values, flagged missing.
        if (onset) {
          held_a_[i] = now > 0 ? last_out_.beta[j] : out.beta[j];
          held_b_[i] = now > 0 ? last_out_.beta_dot[j] : out.beta_dot[j];
          held_c_[i] = now > 0 ? last_out_.deflection[j] : out.deflection[j];
        }
        out.beta[j] = held_a_[i];
        out.beta_dot[j] = held_b_[i];
        out.deflection[j] = held_c_[i];
        out.status[j] |= kStatusMissing;
        status = IoStatus::kPartial;
        break;
      case FaultType::kStale: {
        const auto d = static_cast<std::uint64_t>(std::lround(f.value));
        if (now >= d) {
          const Feedback& old = history_[static_cast<std::size_t>((now - d) % kHistory)];
          out.beta[j] = old.beta[j];
          out.beta_dot[j] = old.beta_dot[j];
          out.deflection[j] = old.deflection[j];
        }
        out.status[j] |= kStatusStale;
        status = IoStatus::kPartial;
        break;
      }
      case FaultType::kOutOfOrder:
        if ((now & 1u) == 0 && now >= 2) {
          const Feedback& old = history_[static_cast<std::size_t>((now - 2) % kHistory)];
          out.beta[j] = old.beta[j];
          out.beta_dot[j] = old.beta_dot[j];
          out.deflection[j] = old.deflection[j];
          out.status[j] |= kStatusOutOfOrder;
          status = IoStatus::kPartial;
        }
        break;
      case FaultType::kRepeatedFrame:
        if ((now & 1u) == 0 && now >= 1) out = last_out_;
        break;
      default:  // physical: applied in write()
        break;
    }
  }
  last_out_ = out;
  return status;
}

void FaultInjectingDriver::apply_physical() {
  if (sim_ == nullptr) return;
  bool any = false;
  for (const model::FaultSpec& f : faults_) any |= model::is_physical(f.type);
  if (!any && !physical_dirty_) return;
  model::PlantFaults& pf = sim_->sim().plant().faults();
  pf.clear();
  physical_dirty_ = false;
  for (const model::FaultSpec& f : faults_) {
    if (!model::is_physical(f.type) || !active(f)) continue;
    physical_dirty_ = true;  // must be healed when it ends
    switch (f.type) {
      case FaultType::kTorqueGain: pf.torque_gain(f.joint) = f.value; break;
      case FaultType::kMotorFriction: pf.motor_friction(f.joint) = f.value; break;
      case FaultType::kSpringScale: pf.spring_scale(f.joint) = f.value; break;
      case FaultType::kJointLoad: pf.joint_load(f.joint) = f.value; break;
      default: break;
    }
  }
}

IoStatus FaultInjectingDriver::write(const Command& cmd) {
  apply_physical();
  return inner_.write(cmd);
}

}  // namespace pedalwave::drivers
