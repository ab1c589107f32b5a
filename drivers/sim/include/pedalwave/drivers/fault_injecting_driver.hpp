// A decorator driver that injects faults (model::FaultSpec, a scene's `faults:` list) into any
// Driver: sensor and communication faults on the Feedback it returns, and — when the wrapped
// driver is a SimDriver — the physical ones (actuator gain, motor friction, spring stiffness,
// joint load) on the simulated Plant's PlantFaults. The sensor and physical faults and the
// validation are the shared FaultInjector's (fault_injector.hpp); the communication faults (a
// silent module as repeated values + kStatusMissing, stale, out-of-order, repeated frames) are
// host-side data effects and are applied here, each at its place in the list order.
//
// Time base: a fault's t_start/duration are seconds since the first read(), measured with the
// Feedback stamps of the wrapped driver (lockstep SimDriver: plant time, so t_start is exact on the
// cycle grid: the first cycle whose read() time is ≥ t_start sees the fault). Physical faults are
// written into the plant in write(), before the wrapped driver advances it, from the first cycle
// whose read() time is ≥ t_start; they are cleared again after `duration`.
//
// Sensor faults change only what the host reads: the simulated module's own control loop (the
// module-side PD) keeps using the true signals (a corrupted report, not a corrupted module loop).
// A module that stops answering keeps its last command (a real module's watchdog would switch its
// torque off after its command timeout; the plant's torque is not changed here).
//
// read()/write() allocate nothing, lock nothing, throw nothing; everything is sized at
// construction (at most kMaxFaults faults, kHistory cycles of history).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "pedalwave/drivers/fault_injector.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::drivers {

class FaultInjectingDriver final : public Driver {
 public:
  static constexpr int kMaxFaults = FaultInjector::kMaxFaults;  // faults one decorator carries [-]
  static constexpr int kHistory = 16;    // cycles of feedback history (stale/out-of-order) [-]
  static_assert(kHistory == FaultInjector::kMaxStaleDelay + 1);

  // Wraps `inner` (not owned, must outlive this). `sim` may be &inner when it is a SimDriver
  // (physical faults need it; nullptr: physical faults throw at add()). Throws
  // std::invalid_argument for an invalid fault (message names the fault, the value, the range).
  FaultInjectingDriver(Driver& inner, SimDriver* sim, const std::vector<model::FaultSpec>& faults,
                       std::uint64_t seed = 1);
  // The common case: wrap a SimDriver, faults from its scene or given.
  explicit FaultInjectingDriver(SimDriver& sim, std::uint64_t seed = 1);

  // Adds one fault (configuration time, not in the cycle). Throws as the constructor.
  void add(const model::FaultSpec& f);
  // Removes every fault (the plant's physical faults are healed at the next write()).
  void clear();
  const std::vector<model::FaultSpec>& faults() const { return injector_.faults(); }

  int joints() const override { return inner_.joints(); }
  IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) override;
  void begin_cycle(std::int64_t scheduled_ns) noexcept override { inner_.begin_cycle(scheduled_ns); }
  IoStatus write(const Command& cmd) override;
  void safe_stop() override { inner_.safe_stop(); }
  const DriverCounters& counters() const override { return inner_.counters(); }
  FeedbackSpec feedback_spec() const override { return inner_.feedback_spec(); }

  // Time of the last read() since the first one [s].
  double time() const { return t_; }
  // The wrapped SimDriver's plant faults (nullptr without a SimDriver).
  model::PlantFaults* plant_faults() { return sim_ ? &sim_->sim().plant().faults() : nullptr; }
  // The last Feedback of the wrapped driver, before injection (the truth as the bus carried it).
  const Feedback& clean_feedback() const { return clean_; }

 private:
  // Communication fault i (active, `onset` as FaultInjector::update) on `out`; cycle `now`.
  void apply_communication(std::size_t i, bool onset, std::uint64_t now, Feedback& out,
                           IoStatus& status);

  Driver& inner_;
  SimDriver* sim_;
  FaultInjector injector_;         // the faults, their sensor and physical effects
  double t_ = 0.0;                 // time of the last read [s]
  bool started_ = false;
  std::int64_t stamp0_ = 0;        // stamp of the first read [ns]
  std::uint64_t cycles_ = 0;       // reads so far [-]
  Feedback clean_{};               // this cycle, before injection
  Feedback last_out_{};            // the previous cycle as delivered (repeated frame)
  std::vector<Feedback> history_;  // clean feedback of the last kHistory cycles (ring)
  std::array<double, kMaxFaults> held_beta_{};  // per fault: values frozen at onset (silent)
  std::array<double, kMaxFaults> held_beta_dot_{};
  std::array<double, kMaxFaults> held_deflection_{};
};

}  // namespace pedalwave::drivers
