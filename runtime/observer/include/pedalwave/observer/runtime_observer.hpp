// The observer behind the runtime's Observer interface (runtime/core/.../stages.hpp): one
// FaultObserver per robot; observe() runs it and turns its latched faults into the Verdict the
// runtime reacts to (severity → ReactionTable), and fills the cycle sample's observer fields
// (residual, tau_ext, body, forward_speed). Allocation-free, lock-free, never throws in observe().
#pragma once

#include "pedalwave/observer/fault_observer.hpp"
#include "pedalwave/interface/stages.hpp"

namespace pedalwave::observer {

class RuntimeObserver final : public runtime::Observer {
 public:
  // Throws std::invalid_argument for invalid parameters (see validate(ObserverParams)).
  explicit RuntimeObserver(const ObserverParams& p) : core_(p) {}

  void reset() override { core_.reset(); }
  // Verdict: the most severe latched fault (ties: the earliest) with its evidence; flags = every
  // latched class; healthy: fault = kNone, severity = kInfo.
  runtime::Verdict observe(const drivers::Feedback& fb, const drivers::CommandHistory& cmds, double t,
                           double dt, runtime::CycleSample& sample) override;

  FaultObserver& core() { return core_; }
  const FaultObserver& core() const { return core_; }

 private:
  FaultObserver core_;
};

}  // namespace pedalwave::observer
