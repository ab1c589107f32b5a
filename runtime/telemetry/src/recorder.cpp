#include "pedalwave/telemetry/recorder.hpp"

#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

#include "pedalwave/telemetry/names.hpp"

namespace pedalwave::telemetry {
namespace {

constexpr const char* kTopics[] = {"joint_state",  "controller_state", "observer_state",
                                   "loop_timing",  "mode_event",       "fault_event",
                                   "robot_description", "command",     "command_ack"};

// The recordings' number spelling (fixed from 1e-4 to 1e16, as fmt's "{}"), and no folder
// created: an unwritable path is an error at construction.
constexpr csv::Writer::Options kOptions{csv::Numbers::kFixed, false};

// The columns "recv_ns,source_time_ns" then `names`, comma-separated.
std::vector<std::string> columns(std::initializer_list<const char*> names) {
  std::vector<std::string> h = {"recv_ns", "source_time_ns"};
  for (const char* n : names) h.emplace_back(n);
  return h;
}

// name_1, name_2, ..., name_n for n joints (1-based, as every name a person reads; the message's
// arrays are 0-based: column name_j holds element j-1).
void add_joint_columns(std::vector<std::string>& h, const char* name, int n) {
  for (int j = 1; j <= n; ++j) h.push_back(std::string(name) + "_" + std::to_string(j));
}

// n cells: the values, padded with empty cells / truncated to n.
void joint_values(csv::Writer& w, const std::vector<double>& v, int n) {
  for (int j = 0; j < n; ++j) {
    if (static_cast<std::size_t>(j) < v.size()) w.number(v[static_cast<std::size_t>(j)]);
    else w.empty();
  }
}

void info(csv::Writer& w, const MessageInfo& i) { w.integer(i.recv_ns).integer(i.source_time_ns); }

}  // namespace

CsvRecorder::CsvRecorder(const std::string& path) {
  stem_ = path;
  if (stem_.size() >= 4 && stem_.compare(stem_.size() - 4, 4, ".csv") == 0) {
    stem_.resize(stem_.size() - 4);
  }
  if (stem_.empty()) {
    throw std::invalid_argument("recorder: path = \"" + path +
                                "\": expected a file name such as run.csv");
  }
  for (const char* t : kTopics) {
    try {
      files_.emplace(t, File{csv::Writer::header_later(stem_ + "." + t + ".csv", kOptions)});
    } catch (const csv::Error& e) {
      throw std::runtime_error(std::string("recorder: ") + e.what());
    }
  }
}

CsvRecorder::~CsvRecorder() = default;

std::string CsvRecorder::file_for(const std::string& topic) const {
  return files_.at(topic).w.path().string();
}

std::uint64_t CsvRecorder::rows(const std::string& topic) const {
  return files_.at(topic).w.rows_written();
}

void CsvRecorder::flush() {
  for (auto& [name, f] : files_) f.w.flush();
}

CsvRecorder::File& CsvRecorder::file(const char* topic) { return files_.at(topic); }

// The header from the topic's first message (its joint count fixes the per-joint columns); a
// later message with another joint count is counted.
csv::Writer& CsvRecorder::start(File& f, int joints, std::vector<std::string> (*header)(int)) {
  if (!f.w.has_header()) {
    f.joints = joints;
    f.w.header(header(joints));
  }
  if (joints != f.joints) ++width_mismatches_;
  return f.w;
}

void CsvRecorder::on_joint_state(const JointStateMsg& m, const MessageInfo& i) {
  File& f = file("joint_state");
  csv::Writer& w = start(f, static_cast<int>(m.beta.size()), [](int n) {
    auto h = columns({"seq", "stamp_ns", "t"});
    for (const char* name : {"beta", "beta_dot", "alpha", "deflection", "tau_sea"}) {
      add_joint_columns(h, name, n);
    }
    return h;
  });
  info(w, i);
  w.integer(m.seq).integer(m.stamp_ns).number(m.t);
  for (const auto* v : {&m.beta, &m.beta_dot, &m.alpha, &m.deflection, &m.tau_sea}) {
    joint_values(w, *v, f.joints);
  }
  w.end_row();
}

void CsvRecorder::on_controller_state(const ControllerStateMsg& m, const MessageInfo& i) {
  File& f = file("controller_state");
  csv::Writer& w = start(f, static_cast<int>(m.alpha_d.size()), [](int n) {
    auto h = columns({"seq", "stamp_ns", "t", "mode", "mode_name"});
    for (const char* name : {"alpha_d", "eta", "u"}) add_joint_columns(h, name, n);
    return h;
  });
  info(w, i);
  w.integer(m.seq).integer(m.stamp_ns).number(m.t).integer(m.mode).text(m.mode_name);
  for (const auto* v : {&m.alpha_d, &m.eta, &m.u}) joint_values(w, *v, f.joints);
  w.end_row();
}

void CsvRecorder::on_observer_state(const ObserverStateMsg& m, const MessageInfo& i) {
  File& f = file("observer_state");
  csv::Writer& w = start(f, static_cast<int>(m.residual.size()), [](int n) {
    auto h = columns({"seq", "stamp_ns"});
    add_joint_columns(h, "residual", n);
    add_joint_columns(h, "tau_ext", n);
    for (const char* name : {"theta_N", "p_x", "p_z", "theta_N_dot", "p_x_dot", "p_z_dot",
                             "fault_flags", "fault_names", "fault_joint", "forward_speed"}) {
      h.emplace_back(name);
    }
    return h;
  });
  info(w, i);
  w.integer(m.seq).integer(m.stamp_ns);
  joint_values(w, m.residual, f.joints);
  joint_values(w, m.tau_ext, f.joints);
  for (const double b : m.body) w.number(b);
  w.integer(m.fault_flags).quoted(fault_flags_names(m.fault_flags)).integer(m.fault_joint)
      .number(m.forward_speed);
  w.end_row();
}

void CsvRecorder::on_loop_timing(const LoopTimingMsg& m, const MessageInfo& i) {
  csv::Writer& w = start(file("loop_timing"), 0, [](int) {
    return columns({"seq", "stamp_ns", "wake_latency_ns", "t_read_ns", "t_observe_ns",
                    "t_control_ns", "t_write_ns", "overruns", "ring_drops"});
  });
  info(w, i);
  w.integer(m.seq).integer(m.stamp_ns).integer(m.wake_latency_ns).integer(m.t_read_ns)
      .integer(m.t_observe_ns).integer(m.t_control_ns).integer(m.t_write_ns).integer(m.overruns)
      .integer(m.ring_drops);
  w.end_row();
}

void CsvRecorder::on_mode_event(const ModeEventMsg& m, const MessageInfo& i) {
  csv::Writer& w = start(file("mode_event"), 0, [](int) {
    return columns({"seq", "stamp_ns", "from", "from_name", "to", "to_name", "text", "event_seq",
                    "value", "severity"});
  });
  info(w, i);
  w.integer(m.seq).integer(m.stamp_ns).integer(m.from).text(m.from_name).integer(m.to)
      .text(m.to_name).quoted(m.text).integer(m.event_seq).number(m.value).integer(m.severity);
  w.end_row();
}

void CsvRecorder::on_fault_event(const FaultEventMsg& m, const MessageInfo& i) {
  csv::Writer& w = start(file("fault_event"), 0, [](int) {
    return columns({"seq", "stamp_ns", "fault_class", "class_name", "severity", "severity_name",
                    "joint", "value", "threshold", "mode", "text", "event_seq"});
  });
  info(w, i);
  w.integer(m.seq).integer(m.stamp_ns).integer(m.fault_class).text(m.class_name)
      .integer(m.severity).text(m.severity_name).integer(m.joint).number(m.value)
      .number(m.threshold).integer(m.mode).quoted(m.text).integer(m.event_seq);
  w.end_row();
}

void CsvRecorder::on_description(const DescriptionMsg& m, const MessageInfo& i) {
  File& f = file("robot_description");
  csv::Writer& w = start(f, static_cast<int>(m.spring_stiffness.size()), [](int n) {
    auto h = columns({"links", "link_length", "link_mass", "rotor_mass", "rotor_inertia",
                      "gear_ratio", "rate_hz", "joint_state_rate_hz", "controller_state_rate_hz",
                      "observer_state_rate_hz", "loop_timing_rate_hz", "name", "driver"});
    add_joint_columns(h, "spring_stiffness", n);
    return h;
  });
  info(w, i);
  w.integer(m.links);
  for (const double v : {m.link_length, m.link_mass, m.rotor_mass, m.rotor_inertia, m.gear_ratio,
                         m.rate_hz, m.joint_state_rate_hz, m.controller_state_rate_hz,
                         m.observer_state_rate_hz, m.loop_timing_rate_hz}) {
    w.number(v);
  }
  w.quoted(m.name).quoted(m.driver);
  joint_values(w, m.spring_stiffness, f.joints);
  w.end_row();
}

void CsvRecorder::on_command(const OperatorCommandMsg& m, const MessageInfo& i) {
  csv::Writer& w = start(file("command"), 0, [](int) {
    return columns({"id", "kind", "kind_name", "amplitude", "omega", "eta", "sender", "target"});
  });
  info(w, i);
  w.integer(m.id).integer(m.kind).text(command_kind_name(m.kind)).number(m.amplitude)
      .number(m.omega).number(m.eta).quoted(m.sender).quoted(m.target);
  w.end_row();
}

void CsvRecorder::on_command_ack(const CommandAckMsg& m, const MessageInfo& i) {
  csv::Writer& w = start(file("command_ack"), 0, [](int) {
    return columns({"id", "kind", "kind_name", "status", "stamp_ns", "reason", "robot"});
  });
  info(w, i);
  w.integer(m.id).integer(m.kind).text(command_kind_name(m.kind)).text(to_string(m.status))
      .integer(m.stamp_ns).quoted(m.reason).quoted(m.robot);
  w.end_row();
}

}  // namespace pedalwave::telemetry
