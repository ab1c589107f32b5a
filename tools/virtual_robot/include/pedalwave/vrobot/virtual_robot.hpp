// The "virtual robot": a scene's plant model (model::Simulation) answering as the robot's SEA
// modules would, over a real bus transport (drivers/PROTOCOL.md §6), so the runtime with its real
// SocketCAN or serial driver can be run against it.
//
//   SimulationPlant   drivers::ModulePlant over model::Simulation: Command → ActuatorInput (the
//                     plant applies the module-side PD law u = τ + kp (β_ref − β) + kd (β̇_ref − β̇)
//                     at every integrator evaluation, i.e. at the module's own rate), measure →
//                     Feedback (the scene's sensor model), advance_to(t_ns) in plant steps.
//   VirtualRobot      a SimulationPlant + the drivers' CAN or serial module emulator (fault
//                     injection: latency, frame loss, bit errors, silent modules) on its own thread.
//   open_pty(), open_module_can_socket()   the transports the CLI offers.
//
// Threads: the plant is stepped only by the emulator's thread; progress() may be read from any
// thread; the recording and the Simulation itself only after VirtualRobot::stop().
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/drivers/fault_injector.hpp"
#include "pedalwave/drivers/canopen_emulator.hpp"
#include "pedalwave/drivers/module_emulator.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::vrobot {

struct PlantOptions {
  double max_gap = 1.0;             // a SYNC more than this after the previous one is not
                                    // integrated: the time origin moves instead (the host was
                                    // away; the plant waits, frozen) [s]
  double record_period = 0.01;      // COM recording period of plant time [s]; 0 = off
  std::size_t record_capacity = 0;  // samples preallocated; when full, recording stops [-]
  bool apply_scene_faults = true;   // inject the scene's `faults:` inside the modules (see
                                    // SimulationPlant); false: the list is ignored
  bool ignore_host_side_faults = false;  // skip the scene's stale / out_of_order /
                                         // repeated_frame faults instead of refusing the scene
  std::uint64_t fault_seed = 1;     // seed of the encoder_noise draws [-]
};

// Plant-side progress, readable from any thread (relaxed atomics).
struct PlantProgress {
  double t = 0.0;                 // plant time since the first SYNC [s]
  double com_x = 0.0;             // whole-robot COM along X [m]
  double com_x0 = 0.0;            // COM along X at plant time 0 [m]
  std::uint64_t steps = 0;        // plant steps taken [-]
  std::uint64_t gaps_skipped = 0; // SYNC gaps longer than max_gap not integrated [-]
  double gap_time_skipped = 0.0;  // plant time those gaps would have covered [s]
  std::uint64_t torque_off_applies = 0;  // commands applied with every module off after the
                                         // modules had been on (safe stops seen by the plant) [-]
  bool all_off = true;            // the last applied command has every module's output off
  bool failed = false;            // the plant failed (NaN, singular M): frozen since
};

// drivers::ModulePlant over a model::Simulation of `scene`.
// Time: plant time 0 is the first advance_to() (the first SYNC); afterwards
//   t_plant = (t_ns − origin_ns)·1e-9 exactly: fixed-step integrators take steps of h and a last,
//   shorter one, so every sample is taken at its SYNC's arrival time (a real module samples when
//   the SYNC arrives). Time never goes backwards (an earlier t_ns is a no-op).
// measure(): the scene's sensor model (noise/quantization when switched on); status bits:
//   kStatusSaturated when a torque limit is on and |u_j| reached it; kStatusEncoderFault on every
//   joint once the plant has failed (it stays frozen; the host must fault).
// Scene faults (opt.apply_scene_faults; drivers::FaultInjector, t = plant time since the first
//   SYNC), inside the modules:
//   physical (torque_gain, motor_friction, spring_scale, joint_load): into the model's PlantFaults
//     before each advance whose start time is ≥ t_start, healed after t_start + duration;
//   sensor (encoder_*, deflection_*, nan, implausible): on what measure() reports; the module's own
//     PD law (the plant's input law) keeps the true signals;
//   module_silent: answering(j) is false while active (the emulator sends nothing for module j);
//   stale, out_of_order, repeated_frame are the host's reception, not a module's: the constructor
//     refuses them (std::invalid_argument naming the fault, its index and the emulator's counter
//     faults to use instead) unless opt.ignore_host_side_faults.
// apply(), measure(), advance_to(), answering() allocate nothing.
class SimulationPlant final : public drivers::ModulePlant {
 public:
  // Builds the simulation (throws std::invalid_argument on a bad scene / options / fault).
  explicit SimulationPlant(const model::Scene& scene, const PlantOptions& opt = {});

  void apply(const drivers::Command& cmd) override;
  void measure(drivers::Feedback& out) override;
  void advance_to(std::int64_t t_ns) override;
  // The modules' thread was held for ns: the time origin moves by ns (not integrated; counted
  // with the idle gaps in progress()).
  void hold(std::int64_t ns) override;
  bool answering(int j) const override;

  // The scene faults applied inside the modules (empty when !opt.apply_scene_faults) and those
  // skipped (host-side ones with opt.ignore_host_side_faults, or all with !apply_scene_faults).
  const std::vector<model::FaultSpec>& faults() const { return injector_.faults(); }
  const std::vector<model::FaultSpec>& skipped_faults() const { return skipped_; }
  // Plant time at which applied fault i first acted [s]; NaN while it has not (any thread).
  double fault_onset(std::size_t i) const { return onset_t_[i].load(std::memory_order_relaxed); }
  // The host's CLOCK_MONOTONIC then [ns] (plant time 0's host time, moved by the holds before it):
  // to compare the onset with the loop's clock. 0 while it has not acted.
  std::int64_t fault_onset_ns(std::size_t i) const { return onset_ns_[i].load(std::memory_order_relaxed); }

  int joints() const { return joints_; }
  PlantProgress progress() const;
  model::StepStatus plant_status() const { return static_cast<model::StepStatus>(status_.load()); }

  // Only while no thread steps the plant (before start / after stop):
  model::Simulation& sim() { return *sim_; }
  const std::vector<double>& recorded_t() const { return rec_t_; }   // [s], (count)
  const std::vector<double>& recorded_x() const { return rec_x_; }   // COM x [m], (count)
  // Average COM speed along +X between the first recorded sample at t ≥ t_from and the last
  // one [m/s]; NaN when the recording does not cover that span.
  double forward_speed(double t_from) const;

 private:
  double com_x_now();
  void record();
  void note_active(double t, bool physical);  // fault_onset() of the faults active at t

  PlantOptions opt_;
  std::unique_ptr<model::Simulation> sim_;
  model::Data data_;
  int joints_ = 0;
  bool fixed_step_ = true;          // fixed-step integrator (steps of h_)
  double h_ = 0.0;                  // its step [s]
  model::Measurement meas_;
  Eigen::VectorXd u_;
  bool started_ = false;
  std::int64_t origin_ns_ = 0;
  double next_record_t_ = 0.0;
  bool was_on_ = false;
  std::vector<double> rec_t_, rec_x_;
  std::atomic<int> status_{0};
  std::atomic<double> t_{0.0}, com_x_{0.0}, com_x0_{0.0}, gap_time_{0.0};
  std::atomic<std::uint64_t> steps_{0}, gaps_{0}, off_applies_{0};
  std::atomic<bool> all_off_{true};
  drivers::FaultInjector injector_;      // the scene's faults applied inside the modules
  std::vector<model::FaultSpec> skipped_;
  std::array<std::atomic<double>, drivers::FaultInjector::kMaxFaults> onset_t_{};
  std::array<std::atomic<std::int64_t>, drivers::FaultInjector::kMaxFaults> onset_ns_{};
};

// One fault as text, joints 1-based: "encoder_stuck on joint 3 from 4.0 s",
// "torque_gain 0.25 on joint 2 from 1.5 s for 2.0 s".
std::string describe(const model::FaultSpec& f);

// kCanOpen: the modules as CANopen CiA 402 drives (drivers/canopen_emulator.hpp) on a CAN transport.
enum class Bus : std::uint8_t { kCan, kSerial, kCanOpen };

struct VirtualRobotOptions {
  Bus bus = Bus::kCan;
  drivers::EmulatorConfig emulator{};  // joints are taken from the scene (N-1); fd, lifetime,
                                       // bus timing, clocks, faults as given
  drivers::canopen::CanOpenEmulatorConfig canopen{};  // Bus::kCanOpen: node ids, units, faults
  PlantOptions plant{};
  int thread_priority = 0;  // SCHED_FIFO priority of the modules' thread (0: normal scheduling;
                            // refused → normal, said in thread_note())
  int thread_cpu = -1;      // pin the modules' thread to this CPU (−1: no pinning)
  // Largest plant step of a fixed-step integrator [s] (0: the scene's). The virtual robot is the
  // reference the onboard observer is checked against: its own integration error must stay well
  // inside the observer's budget. The implicit scheme evaluates the module PD at the end of each
  // step, an apparent viscous term k_p h/2 · β̇ (runtime/observer/README.md §1): ≤ 0.005 N·m at
  // h = 1.25e-4 s, a sixth of the residual threshold (0.019 N·m at the scenes' 5e-4 s).
  double max_step = 1.25e-4;
};

// The plant and the module emulator on `fd` (CAN: a raw CAN socket or a SOCK_SEQPACKET socket-pair
// end carrying can_frame/canfd_frame records; serial: a pty master or a tty). Takes ownership of
// fd (closed by the destructor). start() runs the emulator on its own thread until stop().
class VirtualRobot {
 public:
  VirtualRobot(const model::Scene& scene, int fd, const VirtualRobotOptions& opt);
  ~VirtualRobot();
  VirtualRobot(const VirtualRobot&) = delete;
  VirtualRobot& operator=(const VirtualRobot&) = delete;

  void start();
  void stop();  // idempotent; joins the thread
  // After start(): what the modules' thread got ("modules' thread: SCHED_FIFO 70" or why not).
  const std::string& thread_note() const { return thread_note_; }

  int joints() const { return plant_->joints(); }
  SimulationPlant& plant() { return *plant_; }
  drivers::ModuleBank& bank();
  const drivers::EmulatorStats& stats();
  drivers::canopen::CanOpenModuleEmulator* canopen() { return canopen_.get(); }  // Bus::kCanOpen
  // Multi-line report: frames, faults injected, plant time, COM distance and speed.
  std::string report();

 private:
  VirtualRobotOptions opt_;
  int fd_ = -1;
  std::unique_ptr<SimulationPlant> plant_;
  std::unique_ptr<drivers::CanModuleEmulator> can_;
  std::unique_ptr<drivers::SerialModuleEmulator> serial_;
  std::unique_ptr<drivers::canopen::CanOpenModuleEmulator> canopen_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::string thread_note_;
};

// A pseudo-terminal for the serial bus: the emulator talks on `master`; the host opens
// `slave_path` (e.g. SerialDriver / open_serial_port). `slave_keep` is the slave kept open by us
// in raw mode, so the line settings are raw before any host opens it (no echo of the modules'
// answers back to them) and the master does not hang up between hosts. Throws std::system_error.
struct Pty {
  int master = -1;
  int slave_keep = -1;
  std::string slave_path;
};
Pty open_pty();

// A raw CAN socket on `ifname` for the modules' side: receives SYNC (0x080), commands (0x200…),
// FD command groups (0x280…) and gains (0x300…), nothing else; receive queue enlarged to 4 MB
// (SO_RCVBUFFORCE when permitted) so a stalled modules' thread loses no host frame. Throws
// std::system_error.
int open_module_can_socket(const std::string& ifname, bool fd_frames);
// The same for CANopen drives: NMT (000h), SYNC (080h), RPDOs (200h–3FFh), SDO requests (600h–67Fh).
int open_canopen_module_socket(const std::string& ifname);

}  // namespace pedalwave::vrobot
