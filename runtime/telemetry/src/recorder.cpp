#include "pedalwave/telemetry/recorder.hpp"

#include <spdlog/fmt/fmt.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "pedalwave/telemetry/names.hpp"

namespace pedalwave::telemetry {
namespace {

constexpr const char* kTopics[] = {"joint_state",  "controller_state", "observer_state",
                                   "loop_timing",  "mode_event",       "fault_event",
                                   "robot_description", "command",     "command_ack"};

std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

// ",name_0,name_1,..." for n joints.
std::string joint_header(const char* name, int n) {
  std::string h;
  for (int j = 0; j < n; ++j) h += fmt::format(",{}_{}", name, j);
  return h;
}

// ",v0,v1,..." padded with empty cells / truncated to n.
std::string joint_values(const std::vector<double>& v, int n) {
  std::string s;
  for (int j = 0; j < n; ++j) {
    s += ',';
    if (static_cast<std::size_t>(j) < v.size()) s += fmt::format("{}", v[static_cast<std::size_t>(j)]);
  }
  return s;
}

std::string prefix(const MessageInfo& i) { return fmt::format("{},{}", i.recv_ns, i.source_time_ns); }

constexpr const char* kInfoHeader = "recv_ns,source_time_ns";

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
    File f;
    f.path = stem_ + "." + t + ".csv";
    f.f = std::fopen(f.path.c_str(), "w");
    if (f.f == nullptr) {
      const std::string err = std::strerror(errno);
      for (auto& [name, open] : files_) std::fclose(open.f);
      throw std::runtime_error("recorder: cannot create \"" + f.path + "\": " + err);
    }
    files_.emplace(t, std::move(f));
  }
}

CsvRecorder::~CsvRecorder() {
  for (auto& [name, f] : files_) {
    if (f.f != nullptr) std::fclose(f.f);
  }
}

std::string CsvRecorder::file_for(const std::string& topic) const {
  return files_.at(topic).path;
}

std::uint64_t CsvRecorder::rows(const std::string& topic) const { return files_.at(topic).rows; }

void CsvRecorder::flush() {
  for (auto& [name, f] : files_) std::fflush(f.f);
}

CsvRecorder::File& CsvRecorder::file(const char* topic) { return files_.at(topic); }

void CsvRecorder::write_row(File& f, const std::string& row) {
  std::fputs(row.c_str(), f.f);
  std::fputc('\n', f.f);
  ++f.rows;
}

void CsvRecorder::on_joint_state(const JointStateMsg& m, const MessageInfo& i) {
  File& f = file("joint_state");
  const int n = static_cast<int>(m.beta.size());
  if (!f.header_written) {
    f.joints = n;
    write_row(f, fmt::format("{},seq,stamp_ns,t", kInfoHeader) + joint_header("beta", n) +
                     joint_header("beta_dot", n) + joint_header("alpha", n) +
                     joint_header("deflection", n) + joint_header("tau_sea", n));
    f.rows = 0;
    f.header_written = true;
  }
  if (n != f.joints) ++width_mismatches_;
  write_row(f, prefix(i) + fmt::format(",{},{},{}", m.seq, m.stamp_ns, m.t) +
                   joint_values(m.beta, f.joints) + joint_values(m.beta_dot, f.joints) +
                   joint_values(m.alpha, f.joints) + joint_values(m.deflection, f.joints) +
                   joint_values(m.tau_sea, f.joints));
}

void CsvRecorder::on_controller_state(const ControllerStateMsg& m, const MessageInfo& i) {
  File& f = file("controller_state");
  const int n = static_cast<int>(m.alpha_d.size());
  if (!f.header_written) {
    f.joints = n;
    write_row(f, fmt::format("{},seq,stamp_ns,t,mode,mode_name", kInfoHeader) +
                     joint_header("alpha_d", n) + joint_header("eta", n) + joint_header("u", n));
    f.rows = 0;
    f.header_written = true;
  }
  if (n != f.joints) ++width_mismatches_;
  write_row(f, prefix(i) +
                   fmt::format(",{},{},{},{},{}", m.seq, m.stamp_ns, m.t, m.mode, m.mode_name) +
                   joint_values(m.alpha_d, f.joints) + joint_values(m.eta, f.joints) +
                   joint_values(m.u, f.joints));
}

void CsvRecorder::on_observer_state(const ObserverStateMsg& m, const MessageInfo& i) {
  File& f = file("observer_state");
  const int n = static_cast<int>(m.residual.size());
  if (!f.header_written) {
    f.joints = n;
    write_row(f, fmt::format("{},seq,stamp_ns", kInfoHeader) + joint_header("residual", n) +
                     joint_header("tau_ext", n) +
                     ",theta_N,p_x,p_z,theta_N_dot,p_x_dot,p_z_dot,fault_flags,fault_names,"
                     "fault_joint,forward_speed");
    f.rows = 0;
    f.header_written = true;
  }
  if (n != f.joints) ++width_mismatches_;
  write_row(f, prefix(i) + fmt::format(",{},{}", m.seq, m.stamp_ns) +
                   joint_values(m.residual, f.joints) + joint_values(m.tau_ext, f.joints) +
                   fmt::format(",{},{},{},{},{},{},{},{},{},{}", m.body[0], m.body[1], m.body[2],
                               m.body[3], m.body[4], m.body[5], m.fault_flags,
                               quoted(fault_flags_names(m.fault_flags)), m.fault_joint,
                               m.forward_speed));
}

void CsvRecorder::on_loop_timing(const LoopTimingMsg& m, const MessageInfo& i) {
  File& f = file("loop_timing");
  if (!f.header_written) {
    write_row(f, fmt::format("{},seq,stamp_ns,wake_latency_ns,t_read_ns,t_observe_ns,"
                             "t_control_ns,t_write_ns,overruns,ring_drops",
                             kInfoHeader));
    f.rows = 0;
    f.header_written = true;
  }
  write_row(f, prefix(i) + fmt::format(",{},{},{},{},{},{},{},{},{}", m.seq, m.stamp_ns,
                                       m.wake_latency_ns, m.t_read_ns, m.t_observe_ns,
                                       m.t_control_ns, m.t_write_ns, m.overruns, m.ring_drops));
}

void CsvRecorder::on_mode_event(const ModeEventMsg& m, const MessageInfo& i) {
  File& f = file("mode_event");
  if (!f.header_written) {
    write_row(f, fmt::format("{},seq,stamp_ns,from,from_name,to,to_name,text,event_seq,value,"
                             "severity", kInfoHeader));
    f.rows = 0;
    f.header_written = true;
  }
  write_row(f, prefix(i) + fmt::format(",{},{},{},{},{},{},{},{},{},{}", m.seq, m.stamp_ns, m.from,
                                       m.from_name, m.to, m.to_name, quoted(m.text), m.event_seq,
                                       m.value, m.severity));
}

void CsvRecorder::on_fault_event(const FaultEventMsg& m, const MessageInfo& i) {
  File& f = file("fault_event");
  if (!f.header_written) {
    write_row(f, fmt::format("{},seq,stamp_ns,fault_class,class_name,severity,severity_name,"
                             "joint,value,threshold,mode,text,event_seq",
                             kInfoHeader));
    f.rows = 0;
    f.header_written = true;
  }
  write_row(f, prefix(i) + fmt::format(",{},{},{},{},{},{},{},{},{},{},{},{}", m.seq, m.stamp_ns,
                                       m.fault_class, m.class_name, m.severity, m.severity_name,
                                       m.joint, m.value, m.threshold, m.mode, quoted(m.text),
                                       m.event_seq));
}

void CsvRecorder::on_description(const DescriptionMsg& m, const MessageInfo& i) {
  File& f = file("robot_description");
  const int n = static_cast<int>(m.spring_stiffness.size());
  if (!f.header_written) {
    f.joints = n;
    write_row(f, fmt::format("{},links,link_length,link_mass,rotor_mass,rotor_inertia,"
                             "gear_ratio,rate_hz,joint_state_rate_hz,controller_state_rate_hz,"
                             "observer_state_rate_hz,loop_timing_rate_hz,name,driver",
                             kInfoHeader) +
                     joint_header("spring_stiffness", n));
    f.rows = 0;
    f.header_written = true;
  }
  if (n != f.joints) ++width_mismatches_;
  write_row(f, prefix(i) +
                   fmt::format(",{},{},{},{},{},{},{},{},{},{},{},{},{}", m.links, m.link_length,
                               m.link_mass, m.rotor_mass, m.rotor_inertia, m.gear_ratio,
                               m.rate_hz, m.joint_state_rate_hz, m.controller_state_rate_hz,
                               m.observer_state_rate_hz, m.loop_timing_rate_hz, quoted(m.name),
                               quoted(m.driver)) +
                   joint_values(m.spring_stiffness, f.joints));
}

void CsvRecorder::on_command(const OperatorCommandMsg& m, const MessageInfo& i) {
  File& f = file("command");
  if (!f.header_written) {
    write_row(f, fmt::format("{},id,kind,kind_name,amplitude,omega,eta,sender,target",
                             kInfoHeader));
    f.rows = 0;
    f.header_written = true;
  }
  write_row(f, prefix(i) + fmt::format(",{},{},{},{},{},{},{},{}", m.id, m.kind,
                                       command_kind_name(m.kind), m.amplitude, m.omega, m.eta,
                                       quoted(m.sender), quoted(m.target)));
}

void CsvRecorder::on_command_ack(const CommandAckMsg& m, const MessageInfo& i) {
  File& f = file("command_ack");
  if (!f.header_written) {
    write_row(f, fmt::format("{},id,kind,kind_name,status,stamp_ns,reason,robot", kInfoHeader));
    f.rows = 0;
    f.header_written = true;
  }
  write_row(f, prefix(i) + fmt::format(",{},{},{},{},{},{},{}", m.id, m.kind,
                                       command_kind_name(m.kind), to_string(m.status),
                                       m.stamp_ns, quoted(m.reason), quoted(m.robot)));
}

}  // namespace pedalwave::telemetry
