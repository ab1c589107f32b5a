// The simulated plant behind the same Driver interface as the hardware (DESIGN.md "What it is
// for", 2): the runtime, the controllers and the cycle are unchanged; only the configuration says
// "sim". The plant is a model::Simulation of a scene (all its effects).
//
// Clocks:
//  kLockstep    deterministic: read() measures the plant at its current time; write() applies the
//               command and advances the plant by exactly one period. Same configuration → bit-
//               identical results. For tests, offline tools and the demo. If the loop's clock
//               (read's now_ns) jumped by more than a period — an overrun skipped periods — the
//               plant first advances by the missed time under the last command.
//  kFreeRunning the plant advances in real time on its own thread (period-sized chunks against
//               CLOCK_MONOTONIC); read()/write() exchange the latest measurement/command through
//               seqlocks: never block, never allocate. For demos and HIL-like runs.
// Commands have a lifetime: with no write() for command_timeout of plant time, the simulated
// modules switch their torque off and report kStatusTorqueOff (a real module's watchdog).
// Commands are applied without transport delay (the emulated CAN/serial path adds real ones).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/model/plant.hpp"

namespace pedalwave::drivers {

enum class SimClock : std::uint8_t { kLockstep, kFreeRunning };

struct SimDriverOptions {
  SimClock clock = SimClock::kLockstep;
  double period = 1e-3;            // plant advance per cycle (lockstep) / chunk (free-running) [s]
  double command_timeout = 0.05;   // command lifetime before the modules drop to torque off [s]
  int record_every = 0;            // record the true plant state every n periods; 0 = off [-]
  std::size_t record_capacity = 0; // samples the recorder holds (preallocated; then it stops) [-]
};

// The true plant trajectory (ground truth for plots and checks), recorded without allocating.
struct SimRecording {
  int nq = 0;                       // coordinates per sample [-]
  std::size_t count = 0;            // samples recorded [-]
  std::vector<double> t;            // [s], (capacity)
  std::vector<double> q;            // row-major count × nq (model-spec coordinates)
  std::vector<double> v;            // row-major count × nq
  std::vector<double> u;            // row-major count × (N-1): motor torque applied [N·m]
};

class SimDriver final : public Driver {
 public:
  // Builds the plant (throws std::invalid_argument on a bad scene/options). Integrator: the
  // scene's unless given.
  SimDriver(const model::Scene& scene, const SimDriverOptions& opt);
  SimDriver(const model::Scene& scene, const SimDriverOptions& opt,
            const model::IntegratorOptions& integ);
  ~SimDriver() override;

  int joints() const override { return joints_; }
  IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) override;
  // Lockstep: the plant's time follows the scheduled times (skipped periods included), not the
  // wake-up times (whose latency is not plant time). Without it, read() infers them from now_ns.
  void begin_cycle(std::int64_t scheduled_ns) noexcept override { scheduled_ns_ = scheduled_ns; }
  IoStatus write(const Command& cmd) override;
  void safe_stop() override;
  const DriverCounters& counters() const override { return counters_; }

  // Free-running: start/stop the plant thread (start() is called by the first read if needed).
  void start();
  void stop();

  // The plant (lockstep: safe to inspect between cycles; free-running: only after stop()).
  model::Simulation& sim() { return *sim_; }
  const model::Simulation& sim() const { return *sim_; }
  const SimDriverOptions& options() const { return opt_; }
  // First plant failure (NaN, singular M), or kOk.
  model::StepStatus plant_status() const { return static_cast<model::StepStatus>(status_.load()); }
  bool torque_off_by_watchdog() const { return watchdog_off_; }
  // The recorder (read after the loop has stopped).
  const SimRecording& recording() const { return rec_; }

 private:
  void measure_into(Feedback& fb);
  void apply(const Command& cmd);
  void advance_one_period();
  void plant_thread();

  SimDriverOptions opt_;
  std::unique_ptr<model::Simulation> sim_;
  int joints_;
  DriverCounters counters_;
  model::Measurement meas_;
  Command cmd_{};
  double last_cmd_t_ = 0.0;
  bool watchdog_off_ = false;
  bool safe_stopped_ = false;
  std::uint64_t seq_ = 0;
  std::atomic<int> status_{0};
  SimRecording rec_;
  std::uint64_t periods_ = 0;
  std::int64_t last_read_ns_ = 0;  // lockstep: the loop's time at the previous read [ns]
  std::int64_t scheduled_ns_ = 0;  // lockstep: this cycle's scheduled time (begin_cycle), 0 = none
  Eigen::VectorXd u_rec_;

  // Free-running exchange (seqlocks: writer increments to odd, copies, increments to even).
  struct alignas(64) SeqFeedback {
    std::atomic<std::uint64_t> seq{0};
    Feedback value{};
  } fb_shared_;
  struct alignas(64) SeqCommand {
    std::atomic<std::uint64_t> seq{0};
    Command value{};
  } cmd_shared_;
  std::atomic<bool> running_{false};
  std::thread thread_;
};

// Conversions between the driver's plain structs and the model's (N-1 entries).
void to_actuator_input(const Command& cmd, model::ActuatorInput& in) noexcept;
void to_feedback(const model::Measurement& m, Feedback& fb) noexcept;

}  // namespace pedalwave::drivers
