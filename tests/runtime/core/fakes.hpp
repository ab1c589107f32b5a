// Test doubles for the runtime cycle: a driver that records what it was sent and can be scripted
// to misbehave at a given cycle, and a controller/observer pair that are deterministic and
// allocation-free themselves (so "the cycle allocates nothing" measures the runtime).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/runtime/runtime.hpp"

namespace pedalwave::test {

namespace rt = pedalwave::runtime;
namespace dr = pedalwave::drivers;

inline constexpr std::uint64_t kNever = std::numeric_limits<std::uint64_t>::max();

enum class Call : std::uint8_t { kNone, kRead, kWrite, kSafeStop };

// Counts allocations (and, if a counter is given, lock acquisitions) made by the thread that
// calls it, from start() to the latest sample(). The stages call it on the real-time thread.
struct Probe {
  std::uint64_t (*lock_counter)() = nullptr;  // thread-local lock count, optional
  bool started = false;
  std::uint64_t alloc0 = 0, lock0 = 0;
  std::uint64_t allocs = 0, locks = 0;  // since start() [-]
  std::uint64_t samples = 0;
  void start();
  void sample();
};

class FakeDriver : public dr::Driver {
 public:
  explicit FakeDriver(int joints) : joints_(joints) {}
  int joints() const override { return joints_; }

  void begin_cycle(std::int64_t scheduled_ns) noexcept override { pending_scheduled_ns = scheduled_ns; }

  dr::IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, dr::Feedback& out) override {
    const std::uint64_t k = reads++;
    if (k < scheduled.size()) scheduled[k] = pending_scheduled_ns;  // what begin_cycle said
    pending_scheduled_ns = 0;
    last_call = Call::kRead;
    last_read_deadline_ns = deadline_ns;
    last_read_now_ns = now_ns;
    if (k == throw_at_read) throw std::runtime_error("fake driver: read failed");
    out.joints = joints_;
    out.seq = k;
    out.stamp_ns = now_ns;
    // A smooth, deterministic motion: β_j = 0.1 sin(0.01 k + j).
    for (int j = 0; j < joints_; ++j) {
      const auto js = static_cast<std::size_t>(j);
      const double ph = 0.01 * static_cast<double>(k) + j;
      out.beta[js] = 0.1 * std::sin(ph);
      out.beta_dot[js] = 0.1 * std::cos(ph);
      out.deflection[js] = 0.01 * std::sin(ph);
      out.status[js] = dr::kStatusOk;
    }
    // At rest (reads in [rest_from, rest_until)): β still, β̇ 0, deflection a sensor offset plus a small
    // zero-mean ripple; moving_joint (≥ 0) keeps moving.
    if (k >= rest_from && k < rest_until) {
      for (int j = 0; j < joints_; ++j) {
        if (j == moving_joint) continue;
        const auto js = static_cast<std::size_t>(j);
        out.beta[js] = 0.05 * j;
        out.beta_dot[js] = 0.0;
        out.deflection[js] = deflection_offset[js] + ripple * ((k & 1) ? 1.0 : -1.0);
      }
    } else {
      for (int j = 0; j < joints_; ++j) out.deflection[static_cast<std::size_t>(j)] += deflection_offset[static_cast<std::size_t>(j)];
    }
    if (k == nan_at_read) out.beta[static_cast<std::size_t>(nan_joint)] = std::numeric_limits<double>::quiet_NaN();
    if (k >= fail_from && k < fail_until) return fail_status;
    if (k >= missing_from && k < missing_until) {
      out.status[static_cast<std::size_t>(missing_joint)] = dr::kStatusMissing;
      return dr::IoStatus::kPartial;
    }
    return dr::IoStatus::kOk;
  }

  dr::IoStatus write(const dr::Command& cmd) override {
    if (probe && writes == probe_from_write) probe->start();
    if (probe) probe->sample();
    ++writes;
    last_call = Call::kWrite;
    last_cmd = cmd;
    for (int j = 0; j < cmd.joints; ++j) {
      const auto js = static_cast<std::size_t>(j);
      if (!std::isfinite(cmd.tau[js]) || !std::isfinite(cmd.beta_ref[js]) ||
          !std::isfinite(cmd.kp[js]) || !std::isfinite(cmd.kd[js]) || !std::isfinite(cmd.beta_dot_ref[js]))
        ++non_finite_writes;
    }
    if (cmd.torque_off) ++torque_off_writes;
    return dr::IoStatus::kOk;
  }

  void safe_stop() override {
    if (probe) probe->sample();
    ++safe_stops;
    last_call = Call::kSafeStop;
  }
  const dr::DriverCounters& counters() const override { return counters_; }

  // Script (cycle index = read index).
  std::uint64_t fail_from = kNever, fail_until = kNever;  // read returns fail_status in [from, until)
  dr::IoStatus fail_status = dr::IoStatus::kTimeout;
  std::uint64_t missing_from = kNever, missing_until = kNever;  // one joint missing (kPartial)
  int missing_joint = 0;
  std::uint64_t nan_at_read = kNever;
  int nan_joint = 0;
  std::uint64_t throw_at_read = kNever;
  std::uint64_t rest_from = 0, rest_until = 0;  // reads in [from, until): the robot at rest
  int moving_joint = -1;                       // … except this joint
  double ripple = 0.0;                         // ± deflection ripple at rest [rad]
  std::array<double, dr::kMaxJoints> deflection_offset{};  // sensor offsets, always [rad]

  Probe* probe = nullptr;  // sampled in write() and safe_stop()
  std::uint64_t probe_from_write = kNever;  // start the probe at this write (else the controller does)

  // Record.
  std::uint64_t reads = 0, writes = 0, safe_stops = 0, torque_off_writes = 0, non_finite_writes = 0;
  Call last_call = Call::kNone;
  dr::Command last_cmd{};
  std::int64_t last_read_deadline_ns = 0, last_read_now_ns = 0;
  std::array<std::int64_t, 256> scheduled{};  // begin_cycle's time before read k (0: not called)
  std::int64_t pending_scheduled_ns = 0;

 private:
  int joints_;
  dr::DriverCounters counters_{};
};

// A controller: gait-like torque from t plus a PD term on the measurement. Scriptable faults.
class FakeController : public rt::Controller {
 public:
  void start(const dr::Feedback&) override { ++starts; }
  void control(const rt::CycleIo& io) override {
    const std::uint64_t k = calls++;
    ++controls;
    first_t = calls == 1 ? io.t : first_t;
    last_t = io.t;
    last_dt = io.dt;
    maybe_act(k);
    for (int j = 0; j < io.cmd.joints; ++j) {
      const auto js = static_cast<std::size_t>(j);
      io.cmd.tau[js] = 0.5 * std::sin(2.0 * io.t + 0.3 * j) - 2.0 * io.fb.beta[js];
      io.cmd.kp[js] = 0.0;
      io.cmd.kd[js] = 0.0;
      io.sample.alpha_d[js] = 0.2 * std::sin(2.0 * io.t + 0.3 * j);
    }
    if (k == nan_at) io.cmd.tau[0] = std::numeric_limits<double>::quiet_NaN();
    if (k == throw_at) throw std::runtime_error("fake controller: bug");
  }
  void hold(const rt::CycleIo& io) override {
    const std::uint64_t k = calls++;
    ++holds;
    last_t = io.t;
    maybe_act(k);
    for (int j = 0; j < io.cmd.joints; ++j) {
      const auto js = static_cast<std::size_t>(j);
      io.cmd.tau[js] = 0.0;
      io.cmd.beta_ref[js] = io.fb.beta[js];
      io.cmd.kp[js] = 5.0;
      io.cmd.kd[js] = 0.1;
    }
  }
  void resume(const dr::Feedback&) override { ++resumes; }
  bool set_gait(const rt::OperatorCommand& c) override { return c.amplitude > 0.0 && c.amplitude < 1.0; }

  // Script, by call index k (control() and hold() together: the k-th RUNNING cycle).
  std::uint64_t nan_at = kNever, throw_at = kNever;
  std::uint64_t advance_at = kNever;       // lockstep: simulate a long compute at this call
  std::int64_t advance_ns = 0;
  std::uint64_t advance_every_from = kNever;  // from this call on, every call computes advance_ns
  std::uint64_t raise_at = kNever;         // raise(SIGTERM)
  std::uint64_t stop_at = kNever;          // runtime->request_stop()
  std::uint64_t post_at = kNever;          // runtime->post(post_cmd)
  rt::OperatorCommand post_cmd{};
  rt::Runtime* runtime = nullptr;
  // Allocation/lock probe: started at call probe_from (after warm-up), sampled every call.
  Probe* probe = nullptr;
  std::uint64_t probe_from = kNever;

  std::uint64_t starts = 0, calls = 0, controls = 0, holds = 0, resumes = 0;
  double first_t = -1.0, last_t = 0.0, last_dt = 0.0;

 private:
  void maybe_act(std::uint64_t k);
};

// An observer that returns one scripted verdict from a given call on (for `span` calls).
class FakeObserver : public rt::Observer {
 public:
  void reset() override { ++resets; }
  rt::Verdict observe(const dr::Feedback& fb, const dr::CommandHistory& cmds, double, double,
                      rt::CycleSample& s) override {
    const std::uint64_t k = calls++;
    last_cmd_torque_off = cmds.last().torque_off;
    for (int j = 0; j < fb.joints; ++j) s.residual[static_cast<std::size_t>(j)] = 1e-3 * j;
    if (k >= from && k - from < span) return verdict;
    return {};
  }
  std::uint64_t from = kNever, span = kNever;
  rt::Verdict verdict{};
  std::uint64_t calls = 0, resets = 0;
  bool last_cmd_torque_off = false;
};

// Lockstep configuration most tests use: 1 kHz, no RT privileges requested.
inline rt::RuntimeConfig lockstep_config(std::uint64_t max_cycles) {
  rt::RuntimeConfig c;
  c.clock = rt::ClockMode::kLockstep;
  c.lockstep_start_ns = 1'000'000'000;
  c.auto_start = true;
  c.max_cycles = max_cycles;
  c.stale_timeout = 0.02;
  for (std::size_t j = 0; j < c.description.spring_stiffness.size(); ++j) c.description.spring_stiffness[j] = 50.0;
  return c;
}

}  // namespace pedalwave::test
