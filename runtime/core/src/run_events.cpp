#include "pedalwave/runtime/run_events.hpp"

#include <cstdio>
#include <string_view>

#include "pedalwave/runtime/runtime.hpp"

namespace pedalwave::runtime {

namespace {

std::string_view text_of(const EventSample& e) noexcept {
  return {e.text.data(), std::char_traits<char>::length(e.text.data())};
}

// The runtime's own fixed texts (runtime.cpp) that tell two outcomes of the same shape apart.
bool is_emergency_stop(const EventSample& e) noexcept {
  return e.to == Mode::kSafeStop && text_of(e) == "operator emergency stop";
}
bool is_stop_walking(const EventSample& e) noexcept { return text_of(e).starts_with("stop walking:"); }

std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

std::string joint_text(std::int16_t joint) {  // 1-based, as every printed joint
  return joint >= 0 ? std::string(" joint ") + std::to_string(joint + 1) : std::string();
}

std::string time_text(const RunEvent& e, const EventLog& log) {
  char b[48];
  std::snprintf(b, sizeof b, "%.1f s", log.seconds(e.sample));
  return b;
}

const char* reaction_words(EventReaction r) noexcept {
  switch (r) {
    case EventReaction::kNone: return "";
    case EventReaction::kContinue: return "continue";
    case EventReaction::kHold: return "hold";
    case EventReaction::kSafeStop: return "safe stop";
  }
  return "?";
}

// "stop walking: gait frozen, holding" → {"stop walking", "gait frozen, holding"}.
std::pair<std::string, std::string> split_outcome(std::string_view t) {
  const auto k = t.find(": ");
  if (k == std::string_view::npos) return {std::string(t), std::string()};
  return {std::string(t.substr(0, k)), std::string(t.substr(k + 2))};
}

std::string evidence(const EventSample& s) {
  return std::string(to_string(s.fault)) + joint_text(s.joint) + " (value " + num(s.value) +
         ", threshold " + num(s.threshold) + ")";
}

}  // namespace

const char* to_string(EventKind k) noexcept {
  switch (k) {
    case EventKind::kFault: return "fault";
    case EventKind::kWarning: return "warning";
    case EventKind::kMode: return "mode";
    case EventKind::kOperator: return "operator";
  }
  return "?";
}

const char* to_string(EventReaction r) noexcept {
  switch (r) {
    case EventReaction::kNone: return "none";
    case EventReaction::kContinue: return "continue";
    case EventReaction::kHold: return "hold";
    case EventReaction::kSafeStop: return "safe_stop";
  }
  return "?";
}

EventKind classify(const EventSample& e) noexcept {
  if (e.from != e.to) return EventKind::kMode;
  if (e.fault != FaultClass::kNone)
    return e.severity >= Severity::kDegrade ? EventKind::kFault : EventKind::kWarning;
  return EventKind::kOperator;  // every other same-mode event is an operator-command outcome
}

EventReaction reaction_of(const EventSample& e, const ReactionTable& reactions) noexcept {
  switch (classify(e)) {
    case EventKind::kMode:
      return e.to == Mode::kFault || e.to == Mode::kSafeStop ? EventReaction::kSafeStop
                                                             : EventReaction::kNone;
    case EventKind::kOperator:
      if (e.severity >= Severity::kWarning) return EventReaction::kNone;  // rejected
      return is_stop_walking(e) ? EventReaction::kHold : EventReaction::kContinue;
    case EventKind::kFault:
    case EventKind::kWarning: break;
  }
  // An exception is caught at the loop boundary and always stops, whatever the table says.
  if (e.fault == FaultClass::kException) return EventReaction::kSafeStop;
  Verdict v;
  v.fault = e.fault;
  v.severity = e.severity;
  v.joint = e.joint;
  switch (reactions(v)) {
    case Reaction::kBySeverity:
    case Reaction::kContinue: return EventReaction::kContinue;
    case Reaction::kHold: return EventReaction::kHold;
    case Reaction::kSafeStop: return EventReaction::kSafeStop;
  }
  return EventReaction::kNone;
}

EventLog::EventLog() {
  head_.reserve(kHead);
  tail_.reserve(kTail);
}

void EventLog::clear() noexcept {
  head_.clear();
  tail_.clear();
  tail_next_ = 0;
  total_ = 0;
  t0_ns_ = 0;
  have_t0_ = t0_is_start_ = false;
}

RunEvent* EventLog::last_evidence(FaultClass f, std::int16_t joint) noexcept {
  auto match = [&](RunEvent& r) {
    return r.sample.from == r.sample.to && r.sample.fault == f && r.sample.joint == joint;
  };
  // Newest first: the tail ring (newest just before tail_next_), then the head.
  for (std::size_t k = 0; k < tail_.size(); ++k) {
    const std::size_t i = (tail_next_ + tail_.size() - 1 - k) % tail_.size();
    if (match(tail_[i])) return &tail_[i];
  }
  for (auto it = head_.rbegin(); it != head_.rend(); ++it)
    if (match(*it)) return &*it;
  return nullptr;
}

void EventLog::add(const EventSample& e, const ReactionTable& reactions) {
  ++total_;
  if (!have_t0_ || (!t0_is_start_ && e.to == Mode::kReady && e.from != e.to)) {
    t0_ns_ = e.t_ns;
    have_t0_ = true;
    t0_is_start_ = e.to == Mode::kReady && e.from != e.to;
  }
  RunEvent r;
  r.sample = e;
  r.kind = classify(e);
  r.reaction = reaction_of(e, reactions);
  switch (r.kind) {
    case EventKind::kFault:
    case EventKind::kWarning:
    case EventKind::kOperator: r.listed = true; break;
    case EventKind::kMode:
      if (e.to == Mode::kFault) {
        // The stopping fault: its evidence event (if kept) gets the reaction the runtime took.
        RunEvent* ev = last_evidence(e.fault, e.joint);
        if (ev) ev->reaction = EventReaction::kSafeStop;
        r.listed = ev == nullptr;
      } else {
        r.listed = is_emergency_stop(e);
      }
      break;
  }
  if (head_.size() < kHead) {
    head_.push_back(r);
  } else if (tail_.size() < kTail) {
    tail_.push_back(r);
  } else {
    tail_[tail_next_] = r;  // overwrite the oldest of the tail; it becomes a dropped one
    tail_next_ = (tail_next_ + 1) % kTail;
  }
}

std::vector<RunEvent> EventLog::events() const {
  std::vector<RunEvent> out(head_);
  for (std::size_t k = 0; k < tail_.size(); ++k) out.push_back(tail_[(tail_next_ + k) % tail_.size()]);
  return out;
}

std::string format_event(const RunEvent& e, const EventLog& log) {
  const EventSample& s = e.sample;
  char stamp[96];
  std::snprintf(stamp, sizeof stamp, "[t %.3f s, cycle %llu] ", log.seconds(s),
                static_cast<unsigned long long>(s.seq));
  std::string out = stamp;
  out += to_string(e.kind);
  switch (e.kind) {
    case EventKind::kFault:
    case EventKind::kWarning:
      out.append(" ").append(evidence(s)).append(" severity ").append(to_string(s.severity));
      break;
    case EventKind::kMode:
      out.append(" ").append(to_string(s.from)).append(" → ").append(to_string(s.to));
      if (s.fault != FaultClass::kNone) out.append(" (").append(evidence(s)).append(")");
      break;
    case EventKind::kOperator:
      if (s.severity >= Severity::kWarning) out += " (rejected)";
      break;
  }
  out += ": ";
  out += text_of(s);
  if (e.reaction != EventReaction::kNone) out.append(" → ").append(reaction_words(e.reaction));
  return out;
}

std::string format_event_short(const RunEvent& e, const EventLog& log) {
  const EventSample& s = e.sample;
  const std::string_view text = text_of(s);
  switch (e.kind) {
    case EventKind::kFault:
    case EventKind::kWarning: {
      std::string out = std::string(e.kind == EventKind::kWarning ? "warning " : "fault ") + evidence(s);
      if (text.starts_with("fault reaction: "))  // the reaction itself: say what it did, and when
        return out + " at " + time_text(e, log) + " → " + std::string(text.substr(16));
      return out + " → " + reaction_words(e.reaction);
    }
    case EventKind::kOperator: {
      const auto [what, outcome] = split_outcome(text);
      std::string out = std::string("operator ") + what + " at " + time_text(e, log);
      return outcome.empty() ? out : out + " → " + outcome;
    }
    case EventKind::kMode: {
      std::string out = std::string(text) + " at " + time_text(e, log) + " (" + to_string(s.from) +
                        " → " + to_string(s.to) + ")";
      if (s.fault != FaultClass::kNone) out.append(", ").append(evidence(s));
      return out;
    }
  }
  return std::string(text);
}

std::string format_exit_line(const RunResult& r, const EventLog& log) {
  std::string out = std::string("exit: ") + to_string(r.reason) + ", final mode " + to_string(r.final_mode);
  if (r.reason == ExitReason::kSignal) out.append(", signal ").append(std::to_string(r.signal));
  if (r.fault != FaultClass::kNone)
    out += std::string(", fault ") + to_string(r.fault) + (r.fault_joint >= 0 ? " on" : "") +
           joint_text(r.fault_joint);
  else
    out += ", no stopping fault";
  // The listed events, a fault's evidence folded into the hold reaction of the same cycle that
  // follows it ("fault X joint N (…) at t s → gait frozen, holding" says both).
  std::vector<RunEvent> shown_events;
  for (const RunEvent& e : log.events()) {
    if (!e.listed) continue;
    if (!shown_events.empty() && text_of(e.sample).starts_with("fault reaction: ")) {
      const EventSample& prev = shown_events.back().sample;
      if (prev.seq == e.sample.seq && prev.fault == e.sample.fault && prev.joint == e.sample.joint &&
          prev.from == prev.to && !text_of(prev).starts_with("fault reaction: "))
        shown_events.pop_back();
    }
    shown_events.push_back(e);
  }
  const std::size_t listed = shown_events.size();
  if (listed == 0) {
    out += "; no events (no warnings, holds or operator commands)";
  } else {
    constexpr std::size_t kShown = 8;
    out.append("; ").append(std::to_string(listed)).append(listed == 1 ? " event: " : " events: ");
    std::size_t shown = 0;
    for (const RunEvent& e : shown_events) {
      if (shown == kShown) {
        out.append("; … and ").append(std::to_string(listed - shown)).append(" more (see the summary)");
        break;
      }
      out.append(shown++ ? "; " : "").append(format_event_short(e, log));
    }
  }
  if (log.dropped() > 0) out.append("; ").append(std::to_string(log.dropped())).append(" more events not kept");
  return out;
}

}  // namespace pedalwave::runtime
