// Closed-loop simulation for offline tools (the simulation CLI, the work-precision study, the
// paper reproduction): the same controller and the same simulated-plant driver as the runtime,
// stepped in lockstep without threads or clocks. One step() is one control period:
//   driver.read → controller.update (sees only β, β̇, deflection) → driver.write (the plant applies
//   the command and integrates one period at its own step).
#pragma once

#include "pedalwave/control/gait_controller.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
#include <optional>

#include "pedalwave/model/scene.hpp"

namespace pedalwave::simloop {

// Controller parameters matching a scene's robot (K, n² I_r) and gait (A_p, ω, η), at a control
// rate [Hz], adaptive gain k_c; module-side PD with the paper's K_p = 30, K_D = 15.
control::GaitControllerParams controller_params(const model::Scene& scene, double rate_hz,
                                                double k_c);

struct Options {
  double rate_hz = 1000.0;  // control rate [Hz]
  bool controller = true;   // false: the plant gets zero commands (passive robot)
  double k_c = 0.0;         // adaptive admittance gain (0: open-loop gait)
};

class ClosedLoop {
 public:
  ClosedLoop(const model::Scene& scene, const Options& opt);  // the scene's integrator
  ClosedLoop(const model::Scene& scene, const Options& opt, const model::IntegratorOptions& integ);
  // With explicit controller parameters (rate_hz and joints must match).
  ClosedLoop(const model::Scene& scene, const Options& opt, const model::IntegratorOptions& integ,
             const control::GaitControllerParams& ctl);

  // One control period. Returns the plant's status (kOk, or the failure that froze it).
  model::StepStatus step();

  double t() const { return driver_.sim().t(); }
  double period() const { return period_; }
  model::Simulation& sim() { return driver_.sim(); }
  drivers::SimDriver& driver() { return driver_; }
  const control::ControlOutput& control() const { return out_; }
  const drivers::Feedback& feedback() const { return fb_; }
  const drivers::Command& command() const { return cmd_; }
  const control::GaitController* controller() const { return ctl_ ? &*ctl_ : nullptr; }

 private:
  Options opt_;
  double period_;
  drivers::SimDriver driver_;
  std::optional<control::GaitController> ctl_;
  control::GaitControllerState state_;
  control::ControlOutput out_{};
  drivers::Feedback fb_{};
  drivers::Command cmd_{};
  std::uint64_t cycle_ = 0;
};

}  // namespace pedalwave::simloop
