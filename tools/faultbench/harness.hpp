// The fault-injection closed loop shared by tests/runtime/observer and pedalwave_faultbench: the scene's
// simulated plant (SimDriver, lockstep) wrapped by the FaultInjectingDriver, the runtime's gait
// controller (module-side PD, adaptive gain k_c) and the observer, called in the runtime's order
//   read → observe(fb, last command) → control → write
// one 1 kHz cycle per step(). Plus the campaign pieces: random faults of each kind and a run that
// stops at the first verdict.
#pragma once

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "pedalwave/control/gait_controller.hpp"
#include "pedalwave/drivers/fault_injecting_driver.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/model/scene.hpp"
#include "pedalwave/observer/runtime_observer.hpp"

namespace pedalwave::faultbench {

// Sensor noise of a plausible SEA module (README): 12-bit motor encoder behind the n = 255 gear,
// rate from the module, 14-bit magnetic deflection encoder.
model::SensorNoise module_noise(std::uint64_t seed);

// The shipped scenes, by name ("flat_high_friction", "flat_low_friction", "friction_change",
// "stair", "stair_grip"), as in config/scenes (built in code: the test and tool need no files).
model::Scene shipped_scene(const std::string& name);

// Observer parameters the campaign uses for a scene (observer_params + the calibrated thresholds
// of the README).
observer::ObserverParams campaign_params(const model::Scene& scene, double period = 1e-3);

struct LoopOptions {
  double k_c = 0.0;          // adaptive gain
  bool noise = true;         // sensor noise on (module_noise)
  std::uint64_t seed = 1;    // noise and injection seed
  double period = 1e-3;      // control period [s]
  double plant_h = 2.5e-4;   // plant step (implicit velocity) [s]; 0 = the scene's (README: the
                             // plant's O(h) error shows in the residual as h² k_p/T · β̇)
};

class FaultLoop {
 public:
  FaultLoop(const model::Scene& scene, const LoopOptions& opt,
            const observer::ObserverParams& op);
  FaultLoop(const model::Scene& scene, const LoopOptions& opt)
      : FaultLoop(scene, opt, campaign_params(scene, opt.period)) {}

  // One cycle; returns the plant status.
  model::StepStatus step();
  double t() const { return t_; }
  drivers::FaultInjectingDriver& injector() { return inj_; }
  drivers::SimDriver& sim() { return sim_; }
  observer::RuntimeObserver& observer() { return obs_; }
  // step() asks `o` instead of observer() from now on (e.g. a RecordingObserver wrapping it).
  void observe_through(runtime::Observer& o) { stage_ = &o; }
  const runtime::Verdict& verdict() const { return verdict_; }
  const runtime::CycleSample& sample() const { return sample_; }
  const drivers::Feedback& feedback() const { return fb_; }
  const drivers::Command& command() const { return cmd_; }
  const control::ControlOutput& control() const { return out_; }

 private:
  model::Scene scene_;
  LoopOptions opt_;
  drivers::SimDriver sim_;
  drivers::FaultInjectingDriver inj_;
  control::GaitController ctl_;
  control::GaitControllerState state_;
  observer::RuntimeObserver obs_;
  runtime::Observer* stage_ = &obs_;
  control::ControlOutput out_{};
  drivers::Feedback fb_{};
  drivers::Command cmd_{};
  runtime::CycleSample sample_{};
  runtime::Verdict verdict_{};
  double t_ = 0.0;
  std::uint64_t cycle_ = 0;
};

// Short snake_case name of a fault class ("actuator_torque", …).
const char* class_name(runtime::FaultClass f);

// What the campaign expects the observer to name for an injected fault type.
runtime::FaultClass expected_class(model::FaultType f);
// Expected joint (−1 for frame-level faults).
int expected_joint(const model::FaultSpec& f);

// A random fault of the given type: joint uniform over the N−1 joints, t_start uniform in
// [t_min, t_max], magnitude uniform in the detectable range of the README table.
model::FaultSpec random_fault(model::FaultType type, int joints, double t_min, double t_max,
                              std::mt19937_64& rng);

struct RunResult {
  bool detected = false;          // some verdict before the end
  bool false_alarm = false;       // a verdict before the fault's onset
  runtime::FaultClass fault = runtime::FaultClass::kNone;  // first verdict's class
  int joint = -1;                 // first verdict's joint
  double t_detect = 0.0;          // [s]
  double latency = 0.0;           // t_detect − t_start [s]
  double value = 0.0, threshold = 0.0;
  double estimate = 0.0;
  model::StepStatus status = model::StepStatus::kOk;
};

// Runs `scene` with `fault` (none: nominal) for at most `duration` [s], stopping `linger` [s]
// after the first verdict.
RunResult run_fault(const model::Scene& scene, const LoopOptions& opt,
                    const std::optional<model::FaultSpec>& fault, double duration,
                    double linger = 0.0);

// Nominal statistics of one run (threshold calibration): maxima over joints and time after t_skip.
struct NominalStats {
  double max_residual = 0.0;     // max |r| [N·m]
  double rms_residual = 0.0;     // [N·m]
  double max_consistency = 0.0;  // max |c| [rad]
  double max_saturation = 0.0;   // max low-passed saturation indicator [-]
  int max_hold_beta = 0, max_hold_defl = 0;  // longest bit-identical runs [cycles]
  int alarms = 0;                // latched faults at the end
  runtime::FaultClass first = runtime::FaultClass::kNone;
  int first_joint = -1;
  double first_t = 0.0;
  double first_value = 0.0;
  double seconds = 0.0;          // simulated [s]
  model::StepStatus status = model::StepStatus::kOk;
};
NominalStats run_nominal(const model::Scene& scene, const LoopOptions& opt, double duration,
                         double t_skip = 1.0);

}  // namespace pedalwave::faultbench
