// The fault catalogue (model::FaultSpec, a scene's `faults:` list) as one reusable piece: what a
// fault does, when it is active and which values it accepts. Used by the host-side decorator
// (FaultInjectingDriver, with the in-process SimDriver) and inside the virtual robot's modules
// (vrobot::SimulationPlant), so both inject exactly the same faults.
//
// Time base: t is the caller's time since its run started [s] (FaultInjectingDriver: since the
// first read(); SimulationPlant: plant time since the first SYNC). Fault i is active while
//   t_start_i ≤ t < t_start_i + duration_i.
//
// What it applies (the communication faults — module_silent, stale, out_of_order, repeated_frame —
// are data effects of the bus and the host's driver; the caller implements them, see is_sensor()):
//   sensor faults    apply_sensors(t, fb) / apply_sensor(i, onset, fb) on one Feedback:
//                    encoder_stuck (β_j frozen at onset, β̇_j = 0), encoder_offset (β_j += value),
//                    encoder_noise (β_j += value·N(0,1), one draw per active cycle, in list order),
//                    deflection_stuck (frozen at onset), deflection_bias (+= value),
//                    deflection_scale (*= value), nan (deflection_j = NaN), implausible (β_j = value)
//   physical faults  apply_physical(t, pf): model::PlantFaults (torque_gain, motor_friction,
//                    spring_scale, joint_load) of the faults active at t; healed when they end.
//
// Everything is sized at construction (at most kMaxFaults faults); add()/clear() are for
// configuration time; the apply functions allocate nothing, lock nothing, throw nothing.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <random>
#include <string_view>
#include <vector>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::drivers {

// A fault on what a module reports (its encoder or its deflection sensor).
inline bool is_sensor(model::FaultType f) {
  return f >= model::FaultType::kEncoderStuck && f <= model::FaultType::kImplausible;
}
// A fault of the host's reception, not of a module: stale, out-of-order and repeated frames.
inline bool is_host_side(model::FaultType f) {
  return f >= model::FaultType::kStale && f < model::FaultType::kCount;
}

class FaultInjector {
 public:
  static constexpr int kMaxFaults = 32;      // faults one injector carries [-]
  static constexpr int kMaxStaleDelay = 15;  // largest `stale` delay [cycles]

  // `joints`: N-1 of the robot the faults act on; `physical`: physical faults can be applied (a
  // simulated plant is there; false: adding one throws); `seed` of the encoder-noise draws.
  FaultInjector(int joints, bool physical, std::uint64_t seed = 1);

  // Throws std::invalid_argument for a fault that cannot be added next to `count` others:
  // "fault <type> (joint <j>): <key> = <value>: <expected>"; `holder` names the owner in the
  // count limit ("at most 32 faults per <holder>").
  void validate(const model::FaultSpec& f, std::string_view holder = "driver") const;
  // Validates (as above) and appends one fault (configuration time).
  void add(const model::FaultSpec& f, std::string_view holder = "driver");
  // Removes every fault (the plant's physical faults are healed at the next apply_physical()).
  void clear();
  const std::vector<model::FaultSpec>& faults() const { return faults_; }
  int joints() const { return joints_; }

  static bool active(const model::FaultSpec& f, double t) {
    return t >= f.t_start && t < f.t_start + f.duration;
  }

  // Per fault i at time t: is it active, and is this its first active evaluation since it was
  // last inactive (onset: a stuck value is frozen now)? Updates the onset tracking of fault i.
  struct Activity {
    bool active = false;
    bool onset = false;
  };
  Activity update(std::size_t i, double t) noexcept;
  // Sensor fault i (no effect for any other type) on `out`; `onset` from update().
  void apply_sensor(std::size_t i, bool onset, Feedback& out) noexcept;
  // Every fault in list order: update(i, t), then the sensor faults on `out` (communication and
  // physical faults are only tracked).
  void apply_sensors(double t, Feedback& out) noexcept;
  // Writes the physical faults active at t into `pf` (the others healthy); leaves `pf` untouched
  // when there never were physical faults. Returns true if any is active.
  bool apply_physical(double t, model::PlantFaults& pf) noexcept;
  // True if a module_silent fault on joint j is active at t.
  bool silent(int j, double t) const noexcept;

 private:
  int joints_;
  bool physical_;
  std::vector<model::FaultSpec> faults_;  // reserved kMaxFaults
  std::mt19937_64 rng_;
  std::normal_distribution<double> unit_{0.0, 1.0};
  std::array<double, kMaxFaults> held_{};     // per fault: value frozen at onset (stuck) [rad]
  std::array<bool, kMaxFaults> holding_{};    // per fault: active at its last update()
  bool physical_dirty_ = false;               // plant faults were set and must be re-evaluated
};

}  // namespace pedalwave::drivers
