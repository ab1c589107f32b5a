#include "convert.hpp"

#include <algorithm>
#include <cstring>

#include "pedalwave/telemetry/names.hpp"

namespace pedalwave::telemetry::detail {
namespace {

// A sequence viewing n entries of a (const) array; _release = false: Cyclone never frees it.
template <std::size_t M>
dds_sequence_double view(const std::array<double, M>& a, int n) noexcept {
  dds_sequence_double s{};
  s._maximum = static_cast<std::uint32_t>(n);
  s._length = static_cast<std::uint32_t>(n);
  s._buffer = const_cast<double*>(a.data());  // NOLINT: read-only use by dds_write
  s._release = false;
  return s;
}

std::vector<double> copy(const dds_sequence_double& s) {
  if (s._buffer == nullptr) return {};
  return std::vector<double>(s._buffer, s._buffer + s._length);
}

template <std::size_t M>
std::string str(const char (&a)[M]) {
  return std::string(a, strnlen(a, M));
}

std::uint8_t u8(auto e) noexcept { return static_cast<std::uint8_t>(e); }

}  // namespace

int clamp_joints(int joints) noexcept { return std::clamp(joints, 0, runtime::kMaxJoints); }

void fill(const runtime::CycleSample& s, pedalwave_msg_dds__JointState_& m) noexcept {
  const int n = clamp_joints(s.joints);
  m.seq = s.seq;
  m.stamp_ns = s.t_ns;
  m.t = s.t;
  m.beta = view(s.beta, n);
  m.beta_dot = view(s.beta_dot, n);
  m.alpha = view(s.alpha, n);
  m.deflection = view(s.deflection, n);
  m.tau_sea = view(s.tau_sea, n);
}

void fill(const runtime::CycleSample& s, pedalwave_msg_dds__ControllerState_& m) noexcept {
  const int n = clamp_joints(s.joints);
  m.seq = s.seq;
  m.stamp_ns = s.t_ns;
  m.t = s.t;
  m.mode = u8(s.mode);
  copy_bounded(m.mode_name, mode_c_str(u8(s.mode)));
  m.alpha_d = view(s.alpha_d, n);
  m.pi = view(s.pi, n);
  m.u = view(s.u, n);
}

void fill(const runtime::CycleSample& s, pedalwave_msg_dds__ObserverState_& m) noexcept {
  const int n = clamp_joints(s.joints);
  m.seq = s.seq;
  m.stamp_ns = s.t_ns;
  m.residual = view(s.residual, n);
  m.tau_ext = view(s.tau_ext, n);
  std::copy(s.body.begin(), s.body.end(), m.body);
  m.fault_flags = s.fault_flags;
  m.fault_joint = s.fault_joint;
  m.forward_speed = s.forward_speed;
}

void fill(const runtime::CycleSample& s, pedalwave_msg_dds__LoopTiming_& m) noexcept {
  m.seq = s.seq;
  m.stamp_ns = s.t_ns;
  m.wake_latency_ns = s.wake_latency_ns;
  m.t_read_ns = s.t_read_ns;
  m.t_observe_ns = s.t_observe_ns;
  m.t_control_ns = s.t_control_ns;
  m.t_write_ns = s.t_write_ns;
  m.overruns = s.overruns;
  m.ring_drops = s.ring_drops;
}

void fill(const runtime::EventSample& e, pedalwave_msg_dds__ModeEvent_& m) noexcept {
  m.seq = e.seq;
  m.stamp_ns = e.t_ns;
  m.from_mode = u8(e.from);
  m.to_mode = u8(e.to);
  copy_bounded(m.from_name, mode_c_str(u8(e.from)));
  copy_bounded(m.to_name, mode_c_str(u8(e.to)));
  // EventSample::text is NUL-terminated by contract; copy_bounded stops at the array end anyway.
  char text[sizeof(e.text) + 1];
  std::copy(e.text.begin(), e.text.end(), text);
  text[sizeof(e.text)] = '\0';
  copy_bounded(m.text, text);
}

void fill(const runtime::EventSample& e, pedalwave_msg_dds__FaultEvent_& m) noexcept {
  m.seq = e.seq;
  m.stamp_ns = e.t_ns;
  m.fault_class = u8(e.fault);
  copy_bounded(m.class_name, fault_class_c_str(u8(e.fault)));
  m.severity = u8(e.severity);
  copy_bounded(m.severity_name, severity_c_str(u8(e.severity)));
  m.joint = e.joint;
  m.value = e.value;
  m.threshold = e.threshold;
  m.mode = u8(e.to);
  char text[sizeof(e.text) + 1];
  std::copy(e.text.begin(), e.text.end(), text);
  text[sizeof(e.text)] = '\0';
  copy_bounded(m.text, text);
}

void fill(const runtime::RobotDescription& d, const Decimation& dec,
          pedalwave_msg_dds__RobotDescription_& m) noexcept {
  m.links = d.links;
  m.link_length = d.link_length;
  m.link_mass = d.link_mass;
  m.rotor_mass = d.rotor_mass;
  m.rotor_inertia = d.rotor_inertia;
  m.gear_ratio = d.gear_ratio;
  m.spring_stiffness = view(d.spring_stiffness, clamp_joints(d.links - 1));
  m.rate_hz = d.rate_hz;
  m.joint_state_rate_hz = d.rate_hz / dec.joint_state;
  m.controller_state_rate_hz = d.rate_hz / dec.controller_state;
  m.observer_state_rate_hz = d.rate_hz / dec.observer_state;
  m.loop_timing_rate_hz = d.rate_hz / dec.loop_timing;
  char name[sizeof(d.name) + 1];
  std::copy(d.name.begin(), d.name.end(), name);
  name[sizeof(d.name)] = '\0';
  copy_bounded(m.name, name);
  char driver[sizeof(d.driver) + 1];
  std::copy(d.driver.begin(), d.driver.end(), driver);
  driver[sizeof(d.driver)] = '\0';
  copy_bounded(m.driver, driver);
}

void fill(const runtime::OperatorCommand& c, const char* sender,
          pedalwave_msg_dds__OperatorCommand_& m) noexcept {
  m.kind = u8(c.kind);
  m.id = c.id;
  m.amplitude = c.amplitude;
  m.omega = c.omega;
  m.eta = c.eta;
  copy_bounded(m.sender, sender);
}

JointStateMsg decode(const pedalwave_msg_dds__JointState_& m) {
  return {m.seq, m.stamp_ns, m.t, copy(m.beta), copy(m.beta_dot), copy(m.alpha),
          copy(m.deflection), copy(m.tau_sea)};
}

ControllerStateMsg decode(const pedalwave_msg_dds__ControllerState_& m) {
  return {m.seq, m.stamp_ns, m.t, m.mode, str(m.mode_name), copy(m.alpha_d), copy(m.pi),
          copy(m.u)};
}

ObserverStateMsg decode(const pedalwave_msg_dds__ObserverState_& m) {
  ObserverStateMsg o;
  o.seq = m.seq;
  o.stamp_ns = m.stamp_ns;
  o.residual = copy(m.residual);
  o.tau_ext = copy(m.tau_ext);
  std::copy(std::begin(m.body), std::end(m.body), o.body.begin());
  o.fault_flags = m.fault_flags;
  o.fault_joint = m.fault_joint;
  o.forward_speed = m.forward_speed;
  return o;
}

LoopTimingMsg decode(const pedalwave_msg_dds__LoopTiming_& m) {
  return {m.seq,          m.stamp_ns,     m.wake_latency_ns, m.t_read_ns, m.t_observe_ns,
          m.t_control_ns, m.t_write_ns,   m.overruns,        m.ring_drops};
}

ModeEventMsg decode(const pedalwave_msg_dds__ModeEvent_& m) {
  return {m.seq, m.stamp_ns, m.from_mode, m.to_mode, str(m.from_name), str(m.to_name),
          str(m.text)};
}

FaultEventMsg decode(const pedalwave_msg_dds__FaultEvent_& m) {
  return {m.seq,   m.stamp_ns, m.fault_class, str(m.class_name), m.severity, str(m.severity_name),
          m.joint, m.value,    m.threshold,   m.mode,            str(m.text)};
}

DescriptionMsg decode(const pedalwave_msg_dds__RobotDescription_& m) {
  DescriptionMsg d;
  d.links = m.links;
  d.link_length = m.link_length;
  d.link_mass = m.link_mass;
  d.rotor_mass = m.rotor_mass;
  d.rotor_inertia = m.rotor_inertia;
  d.gear_ratio = m.gear_ratio;
  d.spring_stiffness = copy(m.spring_stiffness);
  d.rate_hz = m.rate_hz;
  d.joint_state_rate_hz = m.joint_state_rate_hz;
  d.controller_state_rate_hz = m.controller_state_rate_hz;
  d.observer_state_rate_hz = m.observer_state_rate_hz;
  d.loop_timing_rate_hz = m.loop_timing_rate_hz;
  d.name = str(m.name);
  d.driver = str(m.driver);
  return d;
}

CommandAckMsg decode(const pedalwave_msg_dds__CommandAck_& m) {
  return {m.id, m.kind, m.accepted, m.stamp_ns, str(m.reason)};
}

OperatorCommandMsg decode(const pedalwave_msg_dds__OperatorCommand_& m) {
  return {m.kind, m.id, m.amplitude, m.omega, m.eta, str(m.sender)};
}

runtime::OperatorCommand to_command(const pedalwave_msg_dds__OperatorCommand_& m) noexcept {
  runtime::OperatorCommand c;
  c.kind = static_cast<runtime::OperatorCommandKind>(m.kind);
  c.id = m.id;
  c.amplitude = m.amplitude;
  c.omega = m.omega;
  c.eta = m.eta;
  return c;
}

}  // namespace pedalwave::telemetry::detail
