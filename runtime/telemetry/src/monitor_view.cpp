#include "pedalwave/telemetry/monitor_view.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>

#include "pedalwave/telemetry/names.hpp"

namespace pedalwave::telemetry {
namespace {

constexpr std::int64_t kRateWindowNs = 1'000'000'000;
constexpr std::size_t kMaxFaults = 5;

// ANSI pieces (empty when not ansi).
struct Style {
  bool on;
  const char* red() const { return on ? "\x1b[1;31m" : ""; }
  const char* green() const { return on ? "\x1b[1;32m" : ""; }
  const char* yellow() const { return on ? "\x1b[1;33m" : ""; }
  const char* bold() const { return on ? "\x1b[1m" : ""; }
  const char* reset() const { return on ? "\x1b[0m" : ""; }
  const char* eol() const { return on ? "\x1b[K\n" : "\n"; }
};

// A joint as printed: 1-based ("joint 1" = the first joint = CAN node / DYNAMIXEL id 1) from the
// messages' 0-based field; "none" for −1.
std::string joint_name(int joint0) { return joint0 >= 0 ? std::to_string(joint0 + 1) : "none"; }

// A bar of `width` cells for |v| / full_scale, '#' filled.
std::string bar(double v, double full_scale, int width) {
  const double frac = full_scale > 0.0 ? std::min(std::fabs(v) / full_scale, 1.0) : 0.0;
  const int n = std::isfinite(frac) ? static_cast<int>(std::lround(frac * width)) : width;
  std::string b(static_cast<std::size_t>(width) + 2, ' ');
  b.front() = '|';
  b.back() = '|';
  for (int k = 0; k < n; ++k) b[static_cast<std::size_t>(k) + 1] = '#';
  return b;
}

double max_abs(const std::vector<double>& v) {
  double m = 0.0;
  for (double x : v) {
    if (std::isfinite(x)) m = std::max(m, std::fabs(x));
  }
  return m;
}

double at(const std::vector<double>& v, std::size_t j) {
  return j < v.size() ? v[j] : std::nan("");
}

}  // namespace

MonitorState::MonitorState(std::int64_t silence_timeout_ns, std::size_t max_notices)
    : silence_(silence_timeout_ns), max_notices_(max_notices), topics_(kTopicCount) {}

void MonitorState::notice(std::int64_t now_ns, std::string text) {
  if (start_ns_ < 0) start_ns_ = now_ns;
  std::string line = fmt::format("[+{:7.2f} s] {}", 1e-9 * static_cast<double>(now_ns - start_ns_),
                                 text);
  new_notices_.push_back(line);
  notices_.push_back(std::move(line));
  while (notices_.size() > max_notices_) notices_.pop_front();
}

void MonitorState::sample_arrived(Topic t, const MessageInfo& info) {
  if (start_ns_ < 0) start_ns_ = info.recv_ns;
  TopicStats& s = topics_[static_cast<std::size_t>(t)];
  ++s.count;
  ++s.window_count;
  if (s.window_start_ns < 0) s.window_start_ns = info.recv_ns;
  switch (silence_.on_sample(info.recv_ns)) {
    case SilenceTracker::Transition::kFirstContact:
      notice(info.recv_ns, "robot found: receiving telemetry");
      break;
    case SilenceTracker::Transition::kCameBack:
      notice(info.recv_ns, "robot is back: telemetry resumed");
      break;
    default:
      break;
  }
}

void MonitorState::on_joint_state(const JointStateMsg& m, const MessageInfo& i) {
  // A new publisher, or seq going backwards: the robot process restarted.
  if (publication_ != 0 && joint_ &&
      (i.publication != publication_ || m.seq < joint_->seq)) {
    ++restarts_;
    notice(i.recv_ns, fmt::format("robot restarted (seq {} after {})", m.seq, joint_->seq));
  }
  publication_ = i.publication;
  joint_ = m;
  sample_arrived(kJoint, i);
}

void MonitorState::on_controller_state(const ControllerStateMsg& m, const MessageInfo& i) {
  last_mode_name_ = m.mode_name;
  controller_ = m;
  sample_arrived(kController, i);
}

void MonitorState::on_observer_state(const ObserverStateMsg& m, const MessageInfo& i) {
  observer_ = m;
  sample_arrived(kObserver, i);
}

void MonitorState::on_loop_timing(const LoopTimingMsg& m, const MessageInfo& i) {
  timing_ = m;
  sample_arrived(kTiming, i);
}

void MonitorState::event_arrived(std::uint64_t& last, std::uint64_t event_seq,
                                 const MessageInfo& i, const char* topic) {
  // event_seq runs 1, 2, ... per robot run; a jump forward is lost events (a restart starts
  // again at 1; a late joiner's first event may be any number).
  if (last != 0 && event_seq > last + 1) {
    event_gaps_ += event_seq - last - 1;
    notice(i.recv_ns, fmt::format("LOST {} {} event(s) (event_seq {} after {})",
                                  event_seq - last - 1, topic, event_seq, last));
  }
  last = event_seq;
}

void MonitorState::on_mode_event(const ModeEventMsg& m, const MessageInfo& i) {
  last_mode_event_ = m;
  event_arrived(last_mode_seq_, m.event_seq, i, "mode");
  if (m.from != m.to) last_mode_name_ = m.to_name;
  notice(i.recv_ns, fmt::format("mode {} -> {}{}{}", m.from_name, m.to_name,
                                m.text.empty() ? "" : ": ", m.text));
}

void MonitorState::on_fault_event(const FaultEventMsg& m, const MessageInfo& i) {
  event_arrived(last_fault_seq_, m.event_seq, i, "fault");
  faults_.push_back(m);
  while (faults_.size() > kMaxFaults) faults_.pop_front();
  notice(i.recv_ns, fmt::format("FAULT {} ({}) joint {}: value {:.4g} vs threshold {:.4g}{}{}",
                                m.class_name, m.severity_name, joint_name(m.joint), m.value, m.threshold,
                                m.text.empty() ? "" : ": ", m.text));
}

void MonitorState::on_description(const DescriptionMsg& m, const MessageInfo& i) {
  description_ = m;
  notice(i.recv_ns, fmt::format("robot description: \"{}\", N = {}, {} Hz, driver {}", m.name,
                                m.links, m.rate_hz, m.driver));
}

void MonitorState::on_command_ack(const CommandAckMsg& m, const MessageInfo& i) {
  last_ack_ = m;
  notice(i.recv_ns, fmt::format("command {} id {} {}{}: {}", command_kind_name(m.kind), m.id,
                                m.status == AckStatus::kRejected ? "REJECTED" : to_string(m.status),
                                m.robot.empty() ? "" : " by " + m.robot, m.reason));
}

void MonitorState::tick(std::int64_t now_ns) {
  if (start_ns_ < 0) start_ns_ = now_ns;
  last_now_ns_ = now_ns;
  if (silence_.check(now_ns) == SilenceTracker::Transition::kWentSilent) {
    notice(now_ns, fmt::format("robot SILENT: no sample for more than {:.2f} s",
                               1e-9 * static_cast<double>(silence_.timeout_ns())));
  }
  for (TopicStats& s : topics_) {
    if (s.window_start_ns < 0) continue;
    const std::int64_t dt = now_ns - s.window_start_ns;
    // A provisional estimate after 0.2 s, so a short run (--once) shows a rate too.
    if (dt >= kRateWindowNs || (s.rate_hz == 0.0 && dt >= kRateWindowNs / 5)) {
      s.rate_hz = static_cast<double>(s.window_count) * 1e9 / static_cast<double>(dt);
      s.window_count = 0;
      s.window_start_ns = now_ns;
    }
  }
}

std::vector<std::string> MonitorState::take_new_notices() {
  std::vector<std::string> out;
  out.swap(new_notices_);
  return out;
}

bool MonitorState::complete() const {
  return description_.has_value() && joint_.has_value() && controller_.has_value() &&
         observer_.has_value() && timing_.has_value();
}

std::string MonitorState::render(std::int64_t now_ns, bool ansi) const {
  const Style st{ansi};
  std::string out;
  const auto line = [&](const std::string& s) {
    out += s;
    out += st.eol();
  };

  // Header: who, and whether it is talking.
  std::string status;
  if (!silence_.heard()) {
    status = fmt::format("{}WAITING for robot{}", st.yellow(), st.reset());
  } else if (silence_.silent()) {
    status = fmt::format("{}SILENT for {:.1f} s{}", st.red(),
                         1e-9 * static_cast<double>(now_ns - silence_.last_sample_ns()),
                         st.reset());
  } else {
    status = fmt::format("{}LIVE{}", st.green(), st.reset());
  }
  if (description_) {
    line(fmt::format("{}pedalwave monitor{}  robot \"{}\"  driver {}  N = {}  rate {} Hz   [{}]",
                     st.bold(), st.reset(), description_->name, description_->driver,
                     description_->links, description_->rate_hz, status));
  } else {
    line(fmt::format("{}pedalwave monitor{}  (no robot description yet)   [{}]", st.bold(),
                     st.reset(), status));
  }

  // Mode, time, speed, faults. A silent robot's mode is only what it last said.
  if (controller_) {
    const std::string& mode = last_mode_name_.empty() ? controller_->mode_name : last_mode_name_;
    const bool bad = mode == "fault" || mode == "safe_stop";
    const bool silent = silence_.silent();
    line(fmt::format("{} {}{}{}   t = {:.3f} s   seq {}   forward speed {} m/s",
                     silent ? "mode (last seen)" : "mode", silent ? st.yellow()
                                                                  : (bad ? st.red() : st.green()),
                     mode, st.reset(),
                     controller_->t, controller_->seq,
                     observer_ ? fmt::format("{:+.4f}", observer_->forward_speed)
                               : std::string("?")));
  } else {
    line("mode ?");
  }
  if (observer_) {
    const std::string names = fault_flags_names(observer_->fault_flags);
    if (names.empty()) {
      line(fmt::format("faults: {}none{}", st.green(), st.reset()));
    } else {
      line(fmt::format("faults: {}{}{}  isolated joint {}", st.red(), names, st.reset(),
                       joint_name(observer_->fault_joint)));
    }
  }
  if (timing_) {
    line(fmt::format("loop: wake latency {:.1f} us  read {:.1f}  observe {:.1f}  control {:.1f}  "
                     "write {:.1f} us   overruns {}  ring drops {}",
                     1e-3 * timing_->wake_latency_ns, 1e-3 * timing_->t_read_ns,
                     1e-3 * timing_->t_observe_ns, 1e-3 * timing_->t_control_ns,
                     1e-3 * timing_->t_write_ns, timing_->overruns, timing_->ring_drops));
  }
  line(fmt::format("received [Hz]: joint_state {:.0f}  controller {:.0f}  observer {:.0f}  "
                   "timing {:.0f}   restarts {}",
                   topics_[kJoint].rate_hz, topics_[kController].rate_hz,
                   topics_[kObserver].rate_hz, topics_[kTiming].rate_hz, restarts_));

  // Per-joint table.
  if (joint_) {
    const std::size_t n = joint_->tau_sea.size();
    const double tau_scale = std::max(max_abs(joint_->tau_sea), 1e-3);
    const double res_scale = observer_ ? std::max(max_abs(observer_->residual), 1e-3) : 1.0;
    line(fmt::format("{}joint    beta[rad]  tau_sea[N·m]              residual[N·m]             "
                     "tau_ext[N·m]{}",
                     st.bold(), st.reset()));
    for (std::size_t j = 0; j < n; ++j) {
      const double res = observer_ ? at(observer_->residual, j) : std::nan("");
      const double ext = observer_ ? at(observer_->tau_ext, j) : std::nan("");
      const bool isolated = observer_ && observer_->fault_joint == static_cast<int>(j);
      line(fmt::format("{}{:>5}{}  {:+9.4f}  {:+9.4f} {}  {:+9.4f} {}  {:+9.4f}",
                       isolated ? st.red() : "", j + 1, isolated ? st.reset() : "",
                       at(joint_->beta, j), at(joint_->tau_sea, j),
                       bar(at(joint_->tau_sea, j), tau_scale, 12), res,
                       bar(res, res_scale, 12), ext));
    }
  }

  // Recent faults and notices.
  if (!faults_.empty()) {
    line(fmt::format("{}recent faults{}", st.bold(), st.reset()));
    for (const auto& f : faults_) {
      line(fmt::format("  seq {:>9}  {}{:<17}{} {:<8} joint {:>3}  value {:.4g} / threshold "
                       "{:.4g}  {}",
                       f.seq, st.red(), f.class_name, st.reset(), f.severity_name, joint_name(f.joint),
                       f.value, f.threshold, f.text));
    }
  }
  line(fmt::format("{}notices{}", st.bold(), st.reset()));
  for (const auto& n : notices_) line("  " + n);
  return out;
}

}  // namespace pedalwave::telemetry
