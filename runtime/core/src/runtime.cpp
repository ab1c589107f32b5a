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
  set_mode(Mode::kReady, "loop started");

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

bool Runtime::cycle_body(std::int64_t deadline, std::int64_t prev_deadline, std::int64_t wake,
                         StopDecision& stop) {
  // ---- 0. Start the record; stop sources that need no measurement ----
  sample_ = CycleSample{};
  sample_.seq = seq_;
  sample_.t_ns = wake;
  sample_.joints = joints_;
  const std::int64_t latency = wake - deadline;
  metrics_.wake.record(latency);
  sample_.wake_latency_ns = static_cast<std::int32_t>(
      std::clamp<std::int64_t>(latency, std::numeric_limits<std::int32_t>::min(),
                               std::numeric_limits<std::int32_t>::max()));
  if (const int sig = pending_stop_signal(); sig != 0) {
    result_.signal = sig;
    stop.stop = true;
    stop.reason = ExitReason::kSignal;
    stop.text = stop_signal_text(sig);
    return false;
  }
  if (stop_requested_.load(std::memory_order_relaxed)) {
    stop.stop = true;
    stop.reason = ExitReason::kStopRequested;
    stop.text = "stop requested";
    return false;
  }
  take_operator_commands(stop);
  if (stop.stop) return false;  // emergency stop: honoured before anything else
  cur_deadline_ = deadline;

  // ---- 1. read ----
  driver_.begin_cycle(deadline);
  const drivers::IoStatus io = driver_.read(wake, wake + read_budget_ns_, fb_);
  const std::int64_t t_read = clock_.now();
  fb_.joints = joints_;
  fill_measured(fb_);

  // Freshness per joint: a joint is fresh when the read succeeded for it this cycle.
  constexpr std::uint16_t kNotFresh =
      drivers::kStatusMissing | drivers::kStatusStale | drivers::kStatusBusError;
  std::int64_t worst_age = 0;
  int worst_joint = -1;
  int stale_joints = 0;
  for (int j = 0; j < joints_; ++j) {
    const auto js = static_cast<std::size_t>(j);
    const bool fresh = io == drivers::IoStatus::kOk ||
                       (io == drivers::IoStatus::kPartial && (fb_.status[js] & kNotFresh) == 0);
    if (fresh) last_fresh_ns_[js] = wake;
    const std::int64_t age = wake - last_fresh_ns_[js];
    if (age > stale_timeout_ns_) ++stale_joints;
    if (age > worst_age) {
      worst_age = age;
      worst_joint = j;
    }
  }

  // Runtime's own checks (most severe first wins the joint field).
  Verdict rt;
  if (stale_joints > 0) {
    rt.fault = FaultClass::kStaleData;
    rt.severity = Severity::kStop;
    rt.joint = static_cast<std::int16_t>(stale_joints == joints_ ? -1 : worst_joint);
    rt.value = static_cast<double>(worst_age) * 1e-9;
    rt.threshold = cfg_.stale_timeout;
    rt.text = "sensor feedback stale longer than stale_timeout";
    rt.flags |= bit(FaultClass::kStaleData);
  }
  {
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

  // ---- operator commands that act on the measurement (start, stop walking, set gait) ----
  for (int i = 0; i < n_pending_; ++i) apply_operator_command(pending_[static_cast<std::size_t>(i)]);
  n_pending_ = 0;
  if (cfg_.auto_start && seq_ == 0 && modes_.mode() == Mode::kReady) {
    OperatorCommand go;
    go.kind = OperatorCommandKind::kStartWalking;
    apply_operator_command(go);
  }

  const bool running = modes_.mode() == Mode::kRunning;
  const double t = running ? static_cast<double>(deadline - running_since_ns_) * 1e-9 : 0.0;
  const double dt = static_cast<double>(deadline - prev_deadline) * 1e-9;
  sample_.t = t;

  // ---- 2. observe ----
  Verdict ov;
  if (observer_) {
    const drivers::CommandHistory cmds(history_.data(), kCommandHistory, newest_written_);
    ov = observer_->observe(fb_, cmds, t, dt, sample_);
  }
  const std::int64_t t_obs = clock_.now();
  if (ov.fault != FaultClass::kNone) ov.flags |= bit(ov.fault);

  // Publish the fault state, one event per newly active class, then react.
  const std::uint32_t flags = rt.flags | ov.flags;
  sample_.fault_flags = flags;
  const Verdict& worst = rank(rt.severity) >= rank(ov.severity) && rt.fault != FaultClass::kNone ? rt : ov;
  sample_.fault_joint = worst.joint;
  if (rt.fault != FaultClass::kNone && (active_flags_ & bit(rt.fault)) == 0)
    push_event(modes_.mode(), modes_.mode(), &rt, rt.text);
  if (ov.fault != FaultClass::kNone && (active_flags_ & bit(ov.fault)) == 0)
    push_event(modes_.mode(), modes_.mode(), &ov, ov.text ? ov.text : "observer fault");
  active_flags_ = flags;
  react(rt, stop);
  react(ov, stop);
  sample_.t_read_ns = static_cast<std::int32_t>(t_read - wake);
  sample_.t_observe_ns = static_cast<std::int32_t>(t_obs - t_read);
  metrics_.read.record(t_read - wake);
  metrics_.observe.record(t_obs - t_read);
  if (stop.stop) return false;  // the safe stop replaces this cycle's write

  // ---- 3. control ----
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
  const std::int64_t t_ctl = clock_.now();
  sample_.t_control_ns = static_cast<std::int32_t>(t_ctl - t_obs);
  metrics_.control.record(t_ctl - t_obs);
  {
    int j = first_non_finite(cmd_.tau, joints_);
    if (j < 0) j = first_non_finite(cmd_.beta_ref, joints_);
    if (j < 0) j = first_non_finite(cmd_.beta_dot_ref, joints_);
    if (j < 0) j = first_non_finite(cmd_.kp, joints_);
    if (j < 0) j = first_non_finite(cmd_.kd, joints_);
    if (j >= 0) {
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
      // A NaN command is never sent, whatever the reaction table says.
      stop.stop = true;
      stop.reason = ExitReason::kFault;
      stop.verdict = v;
      stop.text = v.text;
      return false;
    }
  }
  for (int j = 0; j < joints_; ++j) {
    const auto js = static_cast<std::size_t>(j);
    sample_.u[js] = cmd_.torque_off ? 0.0
                                    : cmd_.tau[js] + cmd_.kp[js] * (cmd_.beta_ref[js] - fb_.beta[js]) +
                                          cmd_.kd[js] * (cmd_.beta_dot_ref[js] - fb_.beta_dot[js]);
  }

  // ---- 4. write ----
  driver_.write(cmd_);
  history_[static_cast<std::size_t>(seq_ % kCommandHistory)] = cmd_;
  newest_written_ = seq_;
  const std::int64_t t_wr = clock_.now();
  sample_.t_write_ns = static_cast<std::int32_t>(t_wr - t_ctl);
  metrics_.write.record(t_wr - t_ctl);
  return true;
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
      if (m == Mode::kReady) {
        running_since_ns_ = cur_deadline_;
        held_ = false;
        controller_.start(fb_);
        set_mode(Mode::kRunning, "start walking", &info);
      } else if (m == Mode::kRunning && held_) {
        held_ = false;
        controller_.resume(fb_);
        push_event(m, m, &info, "start walking: gait resumed");
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
    sample_.alpha[js] = fb.beta[js] - fb.deflection[js];
    sample_.tau_sea[js] = cfg_.description.spring_stiffness[js] * fb.deflection[js];
  }
}

}  // namespace pedalwave::runtime
