#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/interface/clock.hpp"

#include <time.h>

#include <cmath>
#include <cstring>
#include <stdexcept>

namespace pedalwave::drivers {

namespace {
using pedalwave::monotonic_ns;

// Seqlock copy of a trivially copyable value: the reader retries while a write is in flight.
template <class Slot, class T>
void seq_store(Slot& slot, const T& v) {
  const std::uint64_t s = slot.seq.load(std::memory_order_relaxed);
  slot.seq.store(s + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  std::memcpy(static_cast<void*>(&slot.value), &v, sizeof(T));
  std::atomic_thread_fence(std::memory_order_release);
  slot.seq.store(s + 2, std::memory_order_release);
}
template <class Slot, class T>
bool seq_load(const Slot& slot, T& out) {
  for (int tries = 0; tries < 64; ++tries) {
    const std::uint64_t s0 = slot.seq.load(std::memory_order_acquire);
    if (s0 & 1) continue;
    std::memcpy(static_cast<void*>(&out), &slot.value, sizeof(T));
    std::atomic_thread_fence(std::memory_order_acquire);
    if (slot.seq.load(std::memory_order_relaxed) == s0) return s0 != 0;
  }
  return false;  // writer too busy: keep the previous value (never wait)
}
}  // namespace

void to_actuator_input(const Command& cmd, model::ActuatorInput& in) noexcept {
  const int n = static_cast<int>(in.tau.size());
  for (int j = 0; j < n && j < cmd.joints; ++j) {
    const auto k = static_cast<std::size_t>(j);
    in.tau(j) = cmd.tau[k];
    in.beta_ref(j) = cmd.beta_ref[k];
    in.beta_dot_ref(j) = cmd.beta_dot_ref[k];
    in.kp(j) = cmd.kp[k];
    in.kd(j) = cmd.kd[k];
  }
  in.torque_off = cmd.torque_off;
}

void to_feedback(const model::Measurement& m, Feedback& fb) noexcept {
  const int n = static_cast<int>(m.beta.size());
  fb.joints = n;
  for (int j = 0; j < n; ++j) {
    const auto k = static_cast<std::size_t>(j);
    fb.beta[k] = m.beta(j);
    fb.beta_dot[k] = m.beta_dot(j);
    fb.deflection[k] = m.deflection(j);
    fb.status[k] = kStatusOk;
  }
}

SimDriver::SimDriver(const model::Scene& scene, const SimDriverOptions& opt)
    : SimDriver(scene, opt, scene.integrator) {}

SimDriver::SimDriver(const model::Scene& scene, const SimDriverOptions& opt,
                     const model::IntegratorOptions& integ)
    : opt_(opt), sim_(std::make_unique<model::Simulation>(scene, integ)) {
  if (!(opt_.period > 0) || !std::isfinite(opt_.period))
    throw std::invalid_argument("sim driver: period = " + std::to_string(opt_.period) +
                                " s: expected a finite period > 0");
  if (!(opt_.command_timeout > 0))
    throw std::invalid_argument("sim driver: command_timeout = " +
                                std::to_string(opt_.command_timeout) + " s: expected > 0");
  joints_ = sim_->plant().model().joints();
  if (joints_ > kMaxJoints)
    throw std::invalid_argument("sim driver: the scene's robot has " + std::to_string(joints_) +
                                " joints, more than kMaxJoints = " + std::to_string(kMaxJoints));
  const auto J = static_cast<Eigen::Index>(joints_);
  meas_.beta = Eigen::VectorXd::Zero(J);
  meas_.beta_dot = Eigen::VectorXd::Zero(J);
  meas_.deflection = Eigen::VectorXd::Zero(J);
  cmd_.joints = joints_;
  // Recorder: everything allocated here, before any cycle.
  if (opt_.record_every > 0 && opt_.record_capacity > 0) {
    const model::Simulation& s = *sim_;
    rec_.nq = static_cast<int>(s.q().size());
    rec_.t.assign(opt_.record_capacity, 0.0);
    rec_.q.assign(opt_.record_capacity * static_cast<std::size_t>(rec_.nq), 0.0);
    rec_.v.assign(opt_.record_capacity * static_cast<std::size_t>(rec_.nq), 0.0);
    rec_.u.assign(opt_.record_capacity * static_cast<std::size_t>(joints_), 0.0);
    u_rec_ = Eigen::VectorXd::Zero(J);
  }
}

SimDriver::~SimDriver() { stop(); }

void SimDriver::measure_into(Feedback& fb) {
  model::Simulation& s = *sim_;
  s.plant().measure(s.q(), s.v(), meas_);
  to_feedback(meas_, fb);
  fb.seq = ++seq_;
  if (watchdog_off_ || safe_stopped_)
    for (int j = 0; j < joints_; ++j) fb.status[static_cast<std::size_t>(j)] |= kStatusTorqueOff;
}

void SimDriver::apply(const Command& cmd) {
  cmd_ = cmd;
  cmd_.joints = joints_;
  last_cmd_t_ = sim_->t();
  watchdog_off_ = false;
}

// Latest command → plant input (or torque off by the watchdog / safe stop), then one period.
void SimDriver::advance_one_period() {
  model::Simulation& s = *sim_;
  if (status_.load(std::memory_order_relaxed) != 0) return;  // the plant failed: frozen
  if (s.t() - last_cmd_t_ > opt_.command_timeout) watchdog_off_ = true;
  to_actuator_input(cmd_, s.plant().input());
  if (watchdog_off_ || safe_stopped_) s.plant().input().torque_off = true;
  // Record the state at the start of the period, with the torque the modules apply now.
  if (opt_.record_every > 0 && periods_ % static_cast<std::uint64_t>(opt_.record_every) == 0 &&
      rec_.count < rec_.t.size()) {
    const std::size_t i = rec_.count++;
    const auto nq = static_cast<std::size_t>(rec_.nq);
    rec_.t[i] = s.t();
    for (std::size_t c = 0; c < nq; ++c) {
      rec_.q[i * nq + c] = s.q()(static_cast<Eigen::Index>(c));
      rec_.v[i * nq + c] = s.v()(static_cast<Eigen::Index>(c));
    }
    s.plant().motor_torques(s.q(), s.v(), u_rec_);
    for (int j = 0; j < joints_; ++j)
      rec_.u[i * static_cast<std::size_t>(joints_) + static_cast<std::size_t>(j)] = u_rec_(j);
  }
  ++periods_;
  const model::StepStatus st = s.advance_to(s.t() + opt_.period);
  if (st != model::StepStatus::kOk) status_.store(static_cast<int>(st));
}

IoStatus SimDriver::read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) {
  (void)deadline_ns;
  if (opt_.clock == SimClock::kLockstep) {
    // The plant follows the loop's clock: when the loop skipped periods (an overrun), the robot
    // kept moving under the last command for that time too.
    // Whole periods only: the loop skips whole periods, and its dt is deadline-based, so the
    // plant must advance by exactly the skipped periods (wake-up jitter is not plant time). The
    // scheduled time (begin_cycle) is exact; the wake-up time is a fallback that miscounts when a
    // wake-up is late by half a period or more (the plant would then run ahead of the loop's dt).
    const std::int64_t loop_ns = scheduled_ns_ != 0 ? scheduled_ns_ : now_ns;
    scheduled_ns_ = 0;
    if (last_read_ns_ != 0 && loop_ns > last_read_ns_) {
      const double gap = static_cast<double>(loop_ns - last_read_ns_) * 1e-9 / opt_.period;
      const long skipped = std::lround(gap) - 1;
      if (skipped > 0) {
        model::Simulation& s = *sim_;
        const model::StepStatus st = s.advance_to(s.t() + static_cast<double>(skipped) * opt_.period);
        if (st != model::StepStatus::kOk) status_.store(static_cast<int>(st));
      }
    }
    last_read_ns_ = loop_ns;
    measure_into(out);
    out.stamp_ns = static_cast<std::int64_t>(std::llround(sim_->t() * 1e9));
  } else {
    if (!running_.load(std::memory_order_acquire)) return IoStatus::kTimeout;
    if (!seq_load(fb_shared_, out)) return IoStatus::kTimeout;
    (void)now_ns;
  }
  ++counters_.frames_rx;
  if (status_.load(std::memory_order_relaxed) != 0) return IoStatus::kBusError;
  return IoStatus::kOk;
}

IoStatus SimDriver::write(const Command& cmd) {
  ++counters_.frames_tx;
  if (opt_.clock == SimClock::kLockstep) {
    apply(cmd);
    advance_one_period();
  } else {
    seq_store(cmd_shared_, cmd);
  }
  return status_.load(std::memory_order_relaxed) != 0 ? IoStatus::kBusError : IoStatus::kOk;
}

void SimDriver::safe_stop() {
  Command off{};
  off.joints = joints_;
  off.torque_off = true;
  if (opt_.clock == SimClock::kLockstep) {
    apply(off);
    safe_stopped_ = true;
  } else {
    seq_store(cmd_shared_, off);
  }
}

void SimDriver::start() {
  if (opt_.clock != SimClock::kFreeRunning || running_.exchange(true)) return;
  Feedback fb{};
  measure_into(fb);
  fb.stamp_ns = monotonic_ns();
  seq_store(fb_shared_, fb);
  thread_ = std::thread([this] { plant_thread(); });
}

void SimDriver::stop() {
  if (!running_.exchange(false)) return;
  if (thread_.joinable()) thread_.join();
}

// Free-running plant: advances one period per period of CLOCK_MONOTONIC (absolute deadlines),
// taking the newest command each time and publishing the newest measurement.
void SimDriver::plant_thread() {
  const auto period_ns = static_cast<std::int64_t>(std::llround(opt_.period * 1e9));
  std::int64_t next = monotonic_ns();
  std::uint64_t last_cmd_seq = 0;
  Command cmd{};
  Feedback fb{};
  while (running_.load(std::memory_order_acquire)) {
    next += period_ns;
    timespec ts{static_cast<time_t>(next / 1'000'000'000), static_cast<long>(next % 1'000'000'000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
    const std::uint64_t s = cmd_shared_.seq.load(std::memory_order_acquire);
    if (s != last_cmd_seq && seq_load(cmd_shared_, cmd)) {
      last_cmd_seq = s;
      if (cmd.torque_off) safe_stopped_ = true;
      apply(cmd);
    }
    advance_one_period();
    measure_into(fb);
    fb.stamp_ns = monotonic_ns();
    seq_store(fb_shared_, fb);
  }
}

}  // namespace pedalwave::drivers
