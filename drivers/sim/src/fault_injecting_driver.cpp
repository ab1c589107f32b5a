#include "pedalwave/drivers/fault_injecting_driver.hpp"

#include <cmath>

namespace pedalwave::drivers {

using model::FaultType;

FaultInjectingDriver::FaultInjectingDriver(Driver& inner, SimDriver* sim,
                                           const std::vector<model::FaultSpec>& faults,
                                           std::uint64_t seed)
    : inner_(inner), sim_(sim), injector_(inner.joints(), sim != nullptr, seed),
      history_(kHistory) {
  for (const model::FaultSpec& f : faults) add(f);
}

FaultInjectingDriver::FaultInjectingDriver(SimDriver& sim, std::uint64_t seed)
    : FaultInjectingDriver(sim, &sim, sim.sim().plant().scene().faults, seed) {}

void FaultInjectingDriver::add(const model::FaultSpec& f) { injector_.add(f, "driver"); }

void FaultInjectingDriver::clear() { injector_.clear(); }

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
  // Every fault in list order: sensor faults by the injector, communication faults here.
  const std::vector<model::FaultSpec>& faults = injector_.faults();
  for (std::size_t i = 0; i < faults.size(); ++i) {
    const FaultInjector::Activity a = injector_.update(i, t_);
    if (!a.active) continue;
    if (is_sensor(faults[i].type)) injector_.apply_sensor(i, a.onset, out);
    else if (!model::is_physical(faults[i].type)) apply_communication(i, a.onset, now, out, status);
  }
  last_out_ = out;
  return status;
}

void FaultInjectingDriver::apply_communication(std::size_t i, bool onset, std::uint64_t now,
                                               Feedback& out, IoStatus& status) {
  const model::FaultSpec& f = injector_.faults()[i];
  const auto j = static_cast<std::size_t>(f.joint < 0 ? 0 : f.joint);
  switch (f.type) {
    case FaultType::kModuleSilent:
      // No new frame from this module: the driver repeats its last values, flagged missing.
      if (onset) {
        held_beta_[i] = now > 0 ? last_out_.beta[j] : out.beta[j];
        held_beta_dot_[i] = now > 0 ? last_out_.beta_dot[j] : out.beta_dot[j];
        held_deflection_[i] = now > 0 ? last_out_.deflection[j] : out.deflection[j];
      }
      out.beta[j] = held_beta_[i];
      out.beta_dot[j] = held_beta_dot_[i];
      out.deflection[j] = held_deflection_[i];
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
    default:  // sensor (FaultInjector) or physical (write())
      break;
  }
}

IoStatus FaultInjectingDriver::write(const Command& cmd) {
  // Physical faults into the plant before the wrapped driver advances it.
  if (sim_ != nullptr) injector_.apply_physical(t_, sim_->sim().plant().faults());
  return inner_.write(cmd);
}

}  // namespace pedalwave::drivers
