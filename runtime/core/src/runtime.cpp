#include "pedalwave/runtime/runtime.hpp"

#include <algorithm>
#include <csignal>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <system_error>

namespace pedalwave::runtime {
namespace {

// ---- Process-wide stop flag (signal handler side) ----------------------------------------------
std::atomic<int> g_stop_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the signal flag must be lock-free");
static_assert(std::atomic<bool>::is_always_lock_free, "the stop flag must be lock-free");
static_assert(std::atomic<Mode>::is_always_lock_free, "the mode snapshot must be lock-free");

extern "C" void pedalwave_on_stop_signal(int sig) {
  g_stop_signal.store(sig, std::memory_order_relaxed);  // async-signal-safe: lock-free store only
}

constexpr std::uint32_t bit(FaultClass f) noexcept { return 1u << static_cast<unsigned>(f); }
static_assert(static_cast<unsigned>(FaultClass::kCount) <= 32, "fault_flags is 32 bits");

// Bounded copy into the event's fixed text, always NUL-terminated (no printf: nothing allocates).
void copy_text(std::array<char, 96>& dst, const char* a) noexcept {
  std::size_t i = 0;
  if (a) {
    for (; a[i] != '\0' && i + 1 < dst.size(); ++i) dst[i] = a[i];
  }
  dst[i] = '\0';
}

// First non-finite entry among the first n, or −1.
int first_non_finite(const std::array<double, drivers::kMaxJoints>& a, int n) noexcept {
  for (int j = 0; j < n; ++j)
    if (!std::isfinite(a[static_cast<std::size_t>(j)])) return j;
  return -1;
}

int rank(Severity s) noexcept { return static_cast<int>(s); }

// The event text of a stop by signal, naming the signal (a static string: the loop allocates nothing).
const char* stop_signal_text(int sig) noexcept {
  switch (sig) {
    case SIGINT: return "stop signal SIGINT";
    case SIGTERM: return "stop signal SIGTERM";
    case SIGHUP: return "stop signal SIGHUP";
    case SIGQUIT: return "stop signal SIGQUIT";
    default: return "stop signal";
  }
}

}  // namespace

// ---- Free functions ------------------------------------------------------------------------------
void install_stop_signal_handlers() {
  struct sigaction sa {};
  sa.sa_handler = pedalwave_on_stop_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: clock_nanosleep returns EINTR and the loop looks at the flag
  // SIGHUP (the terminal closed) and SIGQUIT (Ctrl-\\) would otherwise kill the process without
  // the safe command: they end the run like SIGTERM.
  for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) {
    if (sigaction(sig, &sa, nullptr) != 0)
      throw std::system_error(errno, std::generic_category(), "sigaction(" + std::to_string(sig) + ")");
  }
}
int pending_stop_signal() noexcept { return g_stop_signal.load(std::memory_order_relaxed); }
void clear_stop_signal() noexcept { g_stop_signal.store(0, std::memory_order_relaxed); }

const char* to_string(Reaction r) noexcept {
  switch (r) {
    case Reaction::kBySeverity: return "by_severity";
    case Reaction::kContinue: return "continue";
    case Reaction::kHold: return "hold";
    case Reaction::kSafeStop: return "safe_stop";
  }
  return "?";
}

const char* to_string(ExitReason r) noexcept {
  switch (r) {
    case ExitReason::kNone: return "none";
    case ExitReason::kCycleLimit: return "cycle_limit";
    case ExitReason::kStopRequested: return "stop_requested";
    case ExitReason::kSignal: return "signal";
    case ExitReason::kEmergencyStop: return "emergency_stop";
    case ExitReason::kFault: return "fault";
  }
  return "?";
}

void validate(const RuntimeConfig& cfg, ValidateScope scope) {
  validate(cfg.rt, scope);
  auto fail = [](const std::string& item, double value, const std::string& expected) {
    std::ostringstream os;
    os << "runtime config: " << item << " = " << value << ", expected " << expected;
    throw std::invalid_argument(os.str());
  };
  const double period = 1.0 / cfg.rt.rate_hz;
  const CalibrationConfig& cal = cfg.calibration;
  if (!std::isfinite(cal.duration) || cal.duration < 0.0 || (cal.duration > 0 && cal.duration * cfg.rt.rate_hz < 1.0 - 1e-9) ||
      cal.duration > 60.0)
    fail("calibration.duration", cal.duration, "0 (off) or an averaging time in [one period, 60] s");
  if (!std::isfinite(cal.timeout) || cal.timeout < cal.duration || cal.timeout > 600.0)
    fail("calibration.timeout", cal.timeout, "a time in [calibration.duration, 600] s");
  if (!(cal.max_offset > 0.0 && cal.max_offset <= 1.0))
    fail("calibration.max_offset", cal.max_offset, "an angle in (0, 1] rad");
  if (!(cal.max_rate > 0.0 && cal.max_rate <= 10.0))
    fail("calibration.max_rate", cal.max_rate, "a rate in (0, 10] rad/s");
  if (!(cal.max_spread > 0.0 && cal.max_spread <= 1.0))
    fail("calibration.max_spread", cal.max_spread, "an angle in (0, 1] rad");
  if (!(cfg.read_budget > 0.0 && cfg.read_budget <= 1.0))
    fail("read_budget", cfg.read_budget, "a fraction of the period in (0, 1]");
  if (!std::isfinite(cfg.stale_timeout) || cfg.stale_timeout < period || cfg.stale_timeout > 10.0) {
    std::ostringstream exp;
    exp << "a timeout in [one period = " << period << ", 10] s";
    fail("stale_timeout", cfg.stale_timeout, exp.str());
  }
  if (cfg.max_commands_per_cycle < 1 || cfg.max_commands_per_cycle > 64)
    fail("max_commands_per_cycle", cfg.max_commands_per_cycle, "1..64");
  for (std::size_t i = 0; i < cfg.reactions.by_class.size(); ++i) {
    if (static_cast<unsigned>(cfg.reactions.by_class[i]) > static_cast<unsigned>(Reaction::kSafeStop))
      fail("reactions.by_class[" + std::string(to_string(static_cast<FaultClass>(i))) + "]",
           static_cast<double>(cfg.reactions.by_class[i]), "by_severity, continue, hold or safe_stop");
  }
  const Reaction sev[] = {cfg.reactions.on_info, cfg.reactions.on_warning, cfg.reactions.on_degrade,
                          cfg.reactions.on_stop};
  for (Reaction r : sev) {
    if (r == Reaction::kBySeverity || static_cast<unsigned>(r) > static_cast<unsigned>(Reaction::kSafeStop))
      fail("reactions.on_<severity>", static_cast<double>(r), "continue, hold or safe_stop");
  }
}

// ---- Runtime: set-up -----------------------------------------------------------------------------
Runtime::Runtime(const RuntimeConfig& cfg, drivers::Driver& driver, Controller& controller,
                 Observer* observer)
    : cfg_(cfg), driver_(driver), controller_(controller), observer_(observer) {
  validate(cfg_);
  joints_ = driver_.joints();
  if (joints_ < 1 || joints_ > drivers::kMaxJoints) {
    throw std::invalid_argument("driver: joints = " + std::to_string(joints_) + ", expected 1.." +
                                std::to_string(drivers::kMaxJoints));
  }
  period_ns_ = std::llround(1e9 / cfg_.rt.rate_hz);
  read_budget_ns_ = std::llround(cfg_.read_budget * static_cast<double>(period_ns_));
  stale_timeout_ns_ = std::llround(cfg_.stale_timeout * 1e9);
  fb_.joints = joints_;
  cmd_.joints = joints_;
  cmd_.torque_off = true;  // "last command" the observer sees before the first write
  history_[0] = cmd_;
  clock_ = LoopClock(cfg_.clock, cfg_.lockstep_start_ns);  // event stamps before run()
  set_mode(Mode::kConfigured, "configured");
}

RunResult Runtime::run() {
  if (ran_) throw std::logic_error("Runtime::run: called twice; a new run needs a new Runtime");
  ran_ = true;
  try {
    result_.rt = apply_rt(cfg_.rt);
  } catch (...) {
    // Not real-time yet, but the bus may be live: leave it in the safe state before reporting.
    StopDecision s;
    s.stop = true;
    s.reason = ExitReason::kStopRequested;
    s.text = "real-time setup refused (require_rt)";
    enter_safe_stop(s);
    throw;
  }
  if (observer_) observer_->reset();

  // ---- The loop (nothing below allocates, locks, logs or throws) ----
  const std::int64_t start =
      cfg_.clock == ClockMode::kLockstep ? cfg_.lockstep_start_ns : monotonic_ns() + period_ns_;
  clock_ = LoopClock(cfg_.clock, start);
  last_fresh_ns_.fill(start);
  auto_start_pending_ = cfg_.auto_start;
  if (cfg_.calibration.duration > 0) {
    cal_ = CalibrationSums{};
    const double per_s = 1e9 / static_cast<double>(period_ns_);
    cal_.needed = std::max<std::int64_t>(1, std::llround(cfg_.calibration.duration * per_s));
    cal_.timeout = std::max<std::int64_t>(cal_.needed, std::llround(cfg_.calibration.timeout * per_s));
    set_mode(Mode::kCalibrating, "loop started: zeroing the deflection sensors, torque off, at rest");
  } else {
    set_mode(Mode::kReady, "loop started");
  }

  std::int64_t deadline = start;
  std::int64_t prev_deadline = start - period_ns_;
  for (;;) {
    if (!clock_.sleep_until(deadline)) {
      // Interrupted by a signal: run the cycle now only if it asks us to stop.
      if (pending_stop_signal() == 0 && !stop_requested_.load(std::memory_order_relaxed)) continue;
    }
    const std::int64_t wake = clock_.now();
    const bool go_on = cycle(deadline, prev_deadline, wake);
    const std::int64_t end = clock_.now();
    metrics_.cycle.record(end - wake);
    ++metrics_.cycles;
    if (!go_on) break;
    const NextDeadline nd = next_deadline(deadline, period_ns_, end);
    if (nd.overrun) {
      ++metrics_.overruns;
      metrics_.skipped_periods += nd.skipped;
      if (nd.skipped > metrics_.max_skipped) metrics_.max_skipped = nd.skipped;
      ++consecutive_overruns_;
      if (cfg_.overrun_fault_after > 0 && consecutive_overruns_ >= cfg_.overrun_fault_after)
        overrun_fault_pending_ = true;
    } else {
      consecutive_overruns_ = 0;
    }
    prev_deadline = deadline;
    deadline = nd.deadline_ns;
  }

  result_.final_mode = modes_.mode();
  result_.cycles = metrics_.cycles;
  result_.overruns = metrics_.overruns;
  result_.skipped_periods = metrics_.skipped_periods;
  result_.max_skipped = metrics_.max_skipped;
  result_.cycle_drops = cycles_.drops();
  result_.event_drops = events_.drops();
  result_.joints = joints_;
  result_.deflection_zero = deflection_zero_;
  return result_;
}

// ---- Runtime: the cycle --------------------------------------------------------------------------
bool Runtime::cycle(std::int64_t deadline, std::int64_t prev_deadline, std::int64_t wake) noexcept {
  StopDecision stop;
  try {
    cycle_body(deadline, prev_deadline, wake, stop);
  } catch (...) {
    // A stage or the driver broke its no-throw contract: the loop boundary turns it into a fault.
    Verdict v;
    v.fault = FaultClass::kException;
    v.severity = Severity::kStop;
    v.flags = bit(FaultClass::kException);
    v.text = "exception escaped a stage or the driver";
    sample_.fault_flags |= v.flags;
    push_event(modes_.mode(), modes_.mode(), &v, v.text);
    stop.stop = true;
    stop.reason = ExitReason::kFault;
    stop.verdict = v;
    stop.text = v.text;
  }
  if (!stop.stop && cfg_.max_cycles > 0 && seq_ + 1 >= cfg_.max_cycles) {
    stop.stop = true;
    stop.reason = ExitReason::kCycleLimit;
    stop.text = "cycle limit reached";
  }
  if (stop.stop) enter_safe_stop(stop);

  // ---- publish: one plain sample, wait-free (dropped and counted when the ring is full) ----
  sample_.mode = modes_.mode();
  sample_.overruns = static_cast<std::uint32_t>(metrics_.overruns);
  sample_.ring_drops = cycles_.drops();
  cycles_.push(sample_);
  ++seq_;
  return !stop.stop;
}

// The cycle, as a table of contents. Each step is one function below, in this order; a step that
// decides to stop fills `stop`, and the cycle ends there (the safe stop replaces the write).
void Runtime::cycle_body(std::int64_t deadline, std::int64_t prev_deadline, std::int64_t wake,
                         StopDecision& stop) {
  start_record(deadline, wake);
  take_stop_requests(stop);  // signal, request_stop(), operator e-stop: before any measurement
  if (stop.stop) return;
  cur_deadline_ = deadline;

  Stamps at{.wake = wake};
  read_feedback(deadline, at);
  const Verdict rt = check_feedback(wake);
  if (modes_.mode() == Mode::kCalibrating) calibrate(stop);  // → READY with the zeros, or FAULT
  if (stop.stop) return;
  apply_operator_commands();  // start / stop walking / set gait act on this cycle's measurement

  const bool running = modes_.mode() == Mode::kRunning;
  const double t = running ? static_cast<double>(deadline - running_since_ns_) * 1e-9 : 0.0;
  const double dt = static_cast<double>(deadline - prev_deadline) * 1e-9;
  sample_.t = t;
  const Verdict ov = observe(t, dt, at);
  publish_faults(rt, ov);
  react(rt, stop);
  react(ov, stop);
  if (stop.stop) return;

  control(t, dt, at);
  check_command(stop);  // a NaN command is never sent
  if (stop.stop) return;
  write(at);
}

// ---- The cycle's steps -------------------------------------------------------------------------
void Runtime::start_record(std::int64_t deadline, std::int64_t wake) noexcept {
  sample_ = CycleSample{};
  sample_.seq = seq_;
  sample_.t_ns = wake;
  sample_.joints = joints_;
  const std::int64_t latency = wake - deadline;
  metrics_.wake.record(latency);
  sample_.wake_latency_ns = static_cast<std::int32_t>(
      std::clamp<std::int64_t>(latency, std::numeric_limits<std::int32_t>::min(),
                               std::numeric_limits<std::int32_t>::max()));
}

void Runtime::take_stop_requests(StopDecision& stop) noexcept {
  if (const int sig = pending_stop_signal(); sig != 0) {
    result_.signal = sig;
    stop.stop = true;
    stop.reason = ExitReason::kSignal;
    stop.text = stop_signal_text(sig);
    return;
  }
  if (stop_requested_.load(std::memory_order_relaxed)) {
    stop.stop = true;
    stop.reason = ExitReason::kStopRequested;
    stop.text = "stop requested";
    return;
  }
  take_operator_commands(stop);
}

void Runtime::read_feedback(std::int64_t deadline, Stamps& at) {
  driver_.begin_cycle(deadline);
  const drivers::IoStatus io = driver_.read(at.wake, at.wake + read_budget_ns_, fb_);
  at.read = clock_.now();
  fb_.joints = joints_;
  for (int j = 0; j < joints_; ++j)
    fb_.deflection[static_cast<std::size_t>(j)] -= deflection_zero_[static_cast<std::size_t>(j)];
  fill_measured(fb_);
  // Freshness per joint: a joint is fresh when the read succeeded for it this cycle.
  constexpr std::uint16_t kNotFresh =
      drivers::kStatusMissing | drivers::kStatusStale | drivers::kStatusBusError;
  for (int j = 0; j < joints_; ++j) {
    const auto js = static_cast<std::size_t>(j);
    const bool fresh = io == drivers::IoStatus::kOk ||
                       (io == drivers::IoStatus::kPartial && (fb_.status[js] & kNotFresh) == 0);
    if (fresh) {
      last_fresh_ns_[js] = at.wake;
      if (!heard_[js]) {
        heard_[js] = true;
        ++heard_count_;
      }
    }
  }
  sample_.t_read_ns = static_cast<std::int32_t>(at.read - at.wake);
  metrics_.read.record(at.read - at.wake);
}

// The runtime's own checks of the feedback; the most severe one names the joint.
Verdict Runtime::check_feedback(std::int64_t wake) const noexcept {
  Verdict rt;
  std::int64_t worst_age = 0;
  int worst_joint = -1;
  int stale_joints = 0;
  for (int j = 0; j < joints_; ++j) {
    const std::int64_t age = wake - last_fresh_ns_[static_cast<std::size_t>(j)];
    if (age > stale_timeout_ns_) ++stale_joints;
    if (age > worst_age) {
      worst_age = age;
      worst_joint = j;
    }
  }
  if (stale_joints > 0) {
    rt.fault = FaultClass::kStaleData;
    rt.severity = Severity::kStop;
    rt.joint = static_cast<std::int16_t>(stale_joints == joints_ ? -1 : worst_joint);
    rt.value = static_cast<double>(worst_age) * 1e-9;
    rt.threshold = cfg_.stale_timeout;
    rt.text = "sensor feedback stale longer than stale_timeout";
    rt.flags |= bit(FaultClass::kStaleData);
  }
  int j = first_non_finite(fb_.beta, joints_);
  if (j < 0) j = first_non_finite(fb_.beta_dot, joints_);
  if (j < 0) j = first_non_finite(fb_.deflection, joints_);
  if (j >= 0) {
    rt.fault = FaultClass::kImplausible;
    rt.severity = Severity::kStop;
    rt.joint = static_cast<std::int16_t>(j);
    rt.value = std::numeric_limits<double>::quiet_NaN();
    rt.threshold = 0.0;
    rt.text = "non-finite measurement (NaN/Inf)";
    rt.flags |= bit(FaultClass::kImplausible);
  }
  if (overrun_fault_pending_) {
    if (rank(rt.severity) < rank(Severity::kStop) || rt.fault == FaultClass::kNone) {
      rt.fault = FaultClass::kOverrun;
      rt.severity = Severity::kStop;
      rt.joint = -1;
      rt.value = consecutive_overruns_;
      rt.threshold = cfg_.overrun_fault_after;
      rt.text = "consecutive deadline overruns";
    }
    rt.flags |= bit(FaultClass::kOverrun);
  }
  return rt;
}

void Runtime::apply_operator_commands() {
  for (int i = 0; i < n_pending_; ++i) apply_operator_command(pending_[static_cast<std::size_t>(i)]);
  n_pending_ = 0;
  // auto_start: RUNNING once READY and every joint has reported at least once (a controller that
  // runs the PD on the host must not act on a joint it has no measurement of).
  if (auto_start_pending_ && modes_.mode() == Mode::kReady && heard_count_ == joints_) {
    auto_start_pending_ = false;
    OperatorCommand go;
    go.kind = OperatorCommandKind::kStartWalking;
    apply_operator_command(go);
  }
}

Verdict Runtime::observe(double t, double dt, Stamps& at) {
  Verdict ov;
  // The observer starts with READY, on zeroed sensors (CALIBRATING's readings carry the offsets).
  if (observer_ && modes_.mode() != Mode::kCalibrating) {
    const drivers::CommandHistory cmds(history_.data(), kCommandHistory, newest_written_);
    ov = observer_->observe(fb_, cmds, t, dt, sample_);
  }
  if (ov.fault != FaultClass::kNone) ov.flags |= bit(ov.fault);
  at.observe = clock_.now();
  sample_.t_observe_ns = static_cast<std::int32_t>(at.observe - at.read);
  metrics_.observe.record(at.observe - at.read);
  return ov;
}

// The fault state into the sample, and one event per newly active fault class.
void Runtime::publish_faults(const Verdict& rt, const Verdict& ov) noexcept {
  const std::uint32_t flags = rt.flags | ov.flags;
  sample_.fault_flags = flags;
  const Verdict& worst = rank(rt.severity) >= rank(ov.severity) && rt.fault != FaultClass::kNone ? rt : ov;
  sample_.fault_joint = worst.joint;
  if (rt.fault != FaultClass::kNone && (active_flags_ & bit(rt.fault)) == 0)
    push_event(modes_.mode(), modes_.mode(), &rt, rt.text);
  if (ov.fault != FaultClass::kNone && (active_flags_ & bit(ov.fault)) == 0)
    push_event(modes_.mode(), modes_.mode(), &ov, ov.text ? ov.text : "observer fault");
  active_flags_ = flags;
}

void Runtime::control(double t, double dt, Stamps& at) {
  cmd_.joints = joints_;
  cmd_.seq = seq_;
  cmd_.torque_off = false;
  if (modes_.mode() == Mode::kRunning) {
    const CycleIo cio{fb_, cmd_, sample_, t, dt};
    if (held_) controller_.hold(cio);
    else controller_.control(cio);
  } else {
    // READY: modules passive until the operator starts walking.
    cmd_.tau.fill(0.0);
    cmd_.beta_ref.fill(0.0);
    cmd_.beta_dot_ref.fill(0.0);
    cmd_.kp.fill(0.0);
    cmd_.kd.fill(0.0);
    cmd_.torque_off = true;
  }
  at.control = clock_.now();
  sample_.t_control_ns = static_cast<std::int32_t>(at.control - at.observe);
  metrics_.control.record(at.control - at.observe);
  // What the modules will apply at this measurement (the module PD law), for telemetry.
  for (int j = 0; j < joints_; ++j) {
    const auto js = static_cast<std::size_t>(j);
    sample_.u[js] = drivers::module_torque(cmd_, js, fb_.beta[js], fb_.beta_dot[js]);
  }
}

void Runtime::check_command(StopDecision& stop) noexcept {
  int j = first_non_finite(cmd_.tau, joints_);
  if (j < 0) j = first_non_finite(cmd_.beta_ref, joints_);
  if (j < 0) j = first_non_finite(cmd_.beta_dot_ref, joints_);
  if (j < 0) j = first_non_finite(cmd_.kp, joints_);
  if (j < 0) j = first_non_finite(cmd_.kd, joints_);
  if (j < 0) return;
  Verdict v;
  v.fault = FaultClass::kImplausible;
  v.severity = Severity::kStop;
  v.joint = static_cast<std::int16_t>(j);
  v.value = std::numeric_limits<double>::quiet_NaN();
  v.flags = bit(FaultClass::kImplausible);
  v.text = "non-finite command (NaN/Inf): not sent";
  sample_.fault_flags |= v.flags;
  sample_.fault_joint = v.joint;
  push_event(modes_.mode(), modes_.mode(), &v, v.text);
  // Whatever the reaction table says.
  stop.stop = true;
  stop.reason = ExitReason::kFault;
  stop.verdict = v;
  stop.text = v.text;
}

void Runtime::write(Stamps& at) {
  driver_.write(cmd_);
  history_[static_cast<std::size_t>(seq_ % kCommandHistory)] = cmd_;
  newest_written_ = seq_;
  at.write = clock_.now();
  sample_.t_write_ns = static_cast<std::int32_t>(at.write - at.control);
  metrics_.write.record(at.write - at.control);
}

// One CALIBRATING cycle. The zeros are the means over `duration` of consecutive cycles at rest;
// a joint that moves (|β̇| > max_rate, or its deflection spreads over more than max_spread)
// starts the window again — someone touching the robot delays READY, it does not zero a load.
// Not at rest within `timeout`, too few fresh readings, or an offset beyond max_offset: a FAULT
// naming the joint, and the zeros stay 0.
void Runtime::calibrate(StopDecision& stop) noexcept {
  const CalibrationConfig& c = cfg_.calibration;
  ++cal_.cycles;
  bool moved = false;
  for (int j = 0; j < joints_; ++j) {
    const auto js = static_cast<std::size_t>(j);
    if (last_fresh_ns_[js] != sample_.t_ns) continue;  // this joint's reading is not new
    const double d = fb_.deflection[js];
    if (cal_.n[js] == 0) cal_.lo[js] = cal_.hi[js] = d;
    cal_.lo[js] = std::min(cal_.lo[js], d);
    cal_.hi[js] = std::max(cal_.hi[js], d);
    cal_.sum[js] += d;
    ++cal_.n[js];
    const double rate = std::abs(fb_.beta_dot[js]);
    if (!moved && rate > c.max_rate) {
      moved = true;
      cal_.why = {j, rate, c.max_rate, "calibration: not at rest within timeout (|motor rate| above max_rate)"};
    } else if (!moved && cal_.hi[js] - cal_.lo[js] > c.max_spread) {
      moved = true;
      cal_.why = {j, cal_.hi[js] - cal_.lo[js], c.max_spread,
                  "calibration: not at rest within timeout (deflection moved more than max_spread)"};
    }
  }
  if (moved) {
    cal_.window = 0;
    cal_.n.fill(0);
    cal_.sum.fill(0.0);
  } else {
    ++cal_.window;
  }

  Verdict v;
  v.fault = FaultClass::kImplausible;
  v.severity = Severity::kStop;
  v.flags = bit(FaultClass::kImplausible);
  if (cal_.window >= cal_.needed) {
    for (int j = 0; j < joints_ && v.text == nullptr; ++j) {
      const auto js = static_cast<std::size_t>(j);
      v.joint = static_cast<std::int16_t>(j);
      const double mean = cal_.n[js] > 0 ? cal_.sum[js] / static_cast<double>(cal_.n[js]) : 0.0;
      if (cal_.n[js] < (cal_.needed + 1) / 2) {
        v.value = static_cast<double>(cal_.n[js]);
        v.threshold = static_cast<double>((cal_.needed + 1) / 2);
        v.text = "calibration: too few fresh deflection readings to zero the sensor";
      } else if (std::abs(mean) > c.max_offset) {
        v.value = mean;
        v.threshold = c.max_offset;
        v.text = "calibration: deflection offset beyond max_offset: sensor broken or mounted wrong";
      }
    }
  } else if (cal_.cycles >= cal_.timeout) {
    v.joint = static_cast<std::int16_t>(cal_.why.joint);
    v.value = cal_.why.value;
    v.threshold = cal_.why.threshold;
    v.text = cal_.why.text;
  } else {
    return;  // still averaging, or waiting for rest
  }
  if (v.text != nullptr) {
    sample_.fault_flags |= v.flags;
    sample_.fault_joint = v.joint;
    stop.stop = true;
    stop.reason = ExitReason::kFault;
    stop.verdict = v;
    stop.text = v.text;
    return;
  }
  // Zeroed: this cycle's readings too, so the observer and the controller see them corrected.
  Verdict info;
  info.joint = -1;
  for (int j = 0; j < joints_; ++j) {
    const auto js = static_cast<std::size_t>(j);
    deflection_zero_[js] = cal_.sum[js] / static_cast<double>(cal_.n[js]);
    if (info.joint < 0 || std::abs(deflection_zero_[js]) > std::abs(info.value)) {
      info.joint = static_cast<std::int16_t>(j);
      info.value = deflection_zero_[js];
    }
    fb_.deflection[js] -= deflection_zero_[js];
  }
  fill_measured(fb_);
  info.threshold = c.max_offset;
  result_.calibrated = true;
  set_mode(Mode::kReady, "deflection sensors zeroed (value: the largest offset, on its joint)", &info);
}

void Runtime::take_operator_commands(StopDecision& stop) noexcept {
  n_pending_ = 0;
  OperatorCommand c;
  for (int i = 0; i < cfg_.max_commands_per_cycle && commands_.pop(c); ++i) {
    if (c.kind == OperatorCommandKind::kEmergencyStop) {
      // Always honoured, in every mode; anything queued behind it is moot.
      stop.stop = true;
      stop.reason = ExitReason::kEmergencyStop;
      stop.text = "operator emergency stop";
      return;
    }
    pending_[static_cast<std::size_t>(n_pending_++)] = c;
  }
}

void Runtime::apply_operator_command(const OperatorCommand& c) {
  const Mode m = modes_.mode();
  Verdict info;  // carries the command id as evidence
  info.value = static_cast<double>(c.id);
  switch (c.kind) {
    case OperatorCommandKind::kStartWalking:
      if (m == Mode::kReady && heard_count_ < joints_) {
        info.severity = Severity::kWarning;
        push_event(m, m, &info, "start walking rejected: a joint has not reported any feedback yet");
      } else if (m == Mode::kReady) {
        running_since_ns_ = cur_deadline_;
        held_ = false;
        controller_.start(fb_);
        set_mode(Mode::kRunning, "start walking", &info);
      } else if (m == Mode::kRunning && held_) {
        held_ = false;
        controller_.resume(fb_);
        push_event(m, m, &info, "start walking: gait resumed");
      } else if (m == Mode::kCalibrating) {
        info.severity = Severity::kWarning;
        push_event(m, m, &info, "start walking rejected: calibrating (READY follows)");
      } else {
        info.severity = Severity::kWarning;
        push_event(m, m, &info, "start walking rejected: not READY and not held");
      }
      break;
    case OperatorCommandKind::kStopWalking:
      if (m == Mode::kRunning && !held_) {
        held_ = true;
        push_event(m, m, &info, "stop walking: gait frozen, holding");
      } else {
        info.severity = Severity::kWarning;
        push_event(m, m, &info, "stop walking rejected: not walking");
      }
      break;
    case OperatorCommandKind::kSetGait:
      if (controller_.set_gait(c)) {
        push_event(m, m, &info, "set gait accepted");
      } else {
        info.severity = Severity::kWarning;
        push_event(m, m, &info, "set gait rejected by the controller's bounds");
      }
      break;
    case OperatorCommandKind::kEmergencyStop:
      break;  // handled in take_operator_commands()
  }
}

void Runtime::react(const Verdict& v, StopDecision& stop) {
  if (v.fault == FaultClass::kNone && v.severity == Severity::kInfo) return;
  switch (cfg_.reactions(v)) {
    case Reaction::kBySeverity:
    case Reaction::kContinue:
      break;
    case Reaction::kHold:
      if (modes_.mode() == Mode::kRunning && !held_) {
        held_ = true;
        push_event(modes_.mode(), modes_.mode(), &v, "fault reaction: gait frozen, holding");
      }
      break;
    case Reaction::kSafeStop:
      if (!stop.stop) {
        stop.stop = true;
        stop.reason = ExitReason::kFault;
        stop.verdict = v;
        stop.text = v.text ? v.text : "fault";
      }
      break;
  }
}

void Runtime::enter_safe_stop(const StopDecision& stop) noexcept {
  if (stop.reason == ExitReason::kFault) {
    set_mode(Mode::kFault, stop.text, &stop.verdict);
    result_.fault = stop.verdict.fault;
    result_.fault_joint = stop.verdict.joint;
  }
  // The safe command, before anything lets go of the bus.
  try {
    driver_.safe_stop();
  } catch (...) {
    // Nothing more can be done from here; the event below still records the stop.
  }
  cmd_.torque_off = true;
  sample_.u.fill(0.0);
  held_ = false;
  set_mode(Mode::kSafeStop, stop.text);
  result_.reason = stop.reason;
}

TransitionStatus Runtime::set_mode(Mode to, const char* why, const Verdict* v) noexcept {
  const Mode from = modes_.mode();
  const TransitionStatus s = modes_.request(to);
  if (s == TransitionStatus::kOk) {
    mode_snapshot_.store(to, std::memory_order_relaxed);
    push_event(from, to, v, why);
  }
  return s;
}

void Runtime::push_event(Mode from, Mode to, const Verdict* v, const char* text) noexcept {
  EventSample e;
  e.seq = seq_;
  e.t_ns = clock_.now();
  e.from = from;
  e.to = to;
  if (v) {
    e.fault = v->fault;
    e.severity = v->severity;
    e.joint = v->joint;
    e.value = v->value;
    e.threshold = v->threshold;
  }
  copy_text(e.text, text);
  events_.push(e);
}

void Runtime::fill_measured(const drivers::Feedback& fb) noexcept {
  for (int j = 0; j < joints_; ++j) {
    const auto js = static_cast<std::size_t>(j);
    sample_.beta[js] = fb.beta[js];
    sample_.beta_dot[js] = fb.beta_dot[js];
    sample_.deflection[js] = fb.deflection[js];
    sample_.alpha[js] = link_angle(fb.beta[js], fb.deflection[js]);
    sample_.tau_sea[js] = spring_torque(cfg_.description.spring_stiffness[js], fb.deflection[js]);
  }
}

}  // namespace pedalwave::runtime
