#include "convert.hpp"

#include <algorithm>
#include <cstring>

#include "pedalwave/telemetry/names.hpp"

namespace pedalwave::telemetry::detail {
namespace {

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

builtin_interfaces_msg_dds__Time_ ros_time(std::int64_t ns) noexcept {
  // builtin_interfaces/Time: sec (int32) + nanosec in [0, 1e9), also for negative times.
  std::int64_t sec = ns / 1'000'000'000;
  std::int64_t nsec = ns % 1'000'000'000;
  if (nsec < 0) {
    nsec += 1'000'000'000;
    --sec;
  }
  return {static_cast<std::int32_t>(sec), static_cast<std::uint32_t>(nsec)};
}

std::int64_t stamp_ns(const builtin_interfaces_msg_dds__Time_& t) noexcept {
  return static_cast<std::int64_t>(t.sec) * 1'000'000'000 + static_cast<std::int64_t>(t.nanosec);
}

void fill_header(const HeaderContext& h, std::int64_t t_ns,
                 std_msgs_msg_dds__Header_& m) noexcept {
  m.stamp = ros_time(t_ns + h.offset_ns);
  m.frame_id = const_cast<char*>(h.frame_id);  // NOLINT: read-only use by dds_write
}

void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__JointState_& m) noexcept {
  const int n = clamp_joints(s.joints);
  fill_header(h, s.t_ns, m.header);
  m.seq = s.seq;
  m.stamp_ns = s.t_ns;
  m.t = s.t;
  m.beta = view(s.beta, n);
  m.beta_dot = view(s.beta_dot, n);
  m.alpha = view(s.alpha, n);
  m.deflection = view(s.deflection, n);
  m.tau_sea = view(s.tau_sea, n);
}

void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__ControllerState_& m) noexcept {
  const int n = clamp_joints(s.joints);
  fill_header(h, s.t_ns, m.header);
  m.seq = s.seq;
  m.stamp_ns = s.t_ns;
  m.t = s.t;
  m.mode = u8(s.mode);
  copy_bounded(m.mode_name, mode_c_str(u8(s.mode)));
  m.alpha_d = view(s.alpha_d, n);
  m.eta = view(s.eta, n);
  m.u = view(s.u, n);
}

void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__ObserverState_& m) noexcept {
  const int n = clamp_joints(s.joints);
  fill_header(h, s.t_ns, m.header);
  m.seq = s.seq;
  m.stamp_ns = s.t_ns;
  m.residual = view(s.residual, n);
  m.tau_ext = view(s.tau_ext, n);
  std::copy(s.body.begin(), s.body.end(), m.body);
  m.fault_flags = s.fault_flags;
  m.fault_joint = s.fault_joint;
  m.forward_speed = s.forward_speed;
}

void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__LoopTiming_& m) noexcept {
  fill_header(h, s.t_ns, m.header);
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

void fill(const runtime::EventSample& e, const HeaderContext& h, std::uint64_t event_seq,
          pedalwave_msg_dds__ModeEvent_& m) noexcept {
  fill_header(h, e.t_ns, m.header);
  m.event_seq = event_seq;
  m.value = e.value;
  m.severity = u8(e.severity);
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

void fill(const runtime::EventSample& e, const HeaderContext& h, std::uint64_t event_seq,
          pedalwave_msg_dds__FaultEvent_& m) noexcept {
  fill_header(h, e.t_ns, m.header);
  m.event_seq = event_seq;
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

void fill(const runtime::RobotDescription& d, const Decimation& dec, const char* ros_namespace,
          pedalwave_msg_dds__RobotDescription_& m) noexcept {
  copy_bounded(m.ros_namespace, ros_namespace);
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

void fill(const runtime::OperatorCommand& c, const char* target, const char* sender,
          pedalwave_msg_dds__OperatorCommand_& m) noexcept {
  copy_bounded(m.target, target);
  m.kind = u8(c.kind);
  m.id = c.id;
  m.amplitude = c.amplitude;
  m.omega = c.omega;
  m.eta = c.eta;
  copy_bounded(m.sender, sender);
}

JointStateMsg decode(const pedalwave_msg_dds__JointState_& m) {
  JointStateMsg o;
  o.seq = m.seq;
  o.stamp_ns = m.stamp_ns;
  o.ros_stamp_ns = stamp_ns(m.header.stamp);
  o.t = m.t;
  o.beta = copy(m.beta);
  o.beta_dot = copy(m.beta_dot);
  o.alpha = copy(m.alpha);
  o.deflection = copy(m.deflection);
  o.tau_sea = copy(m.tau_sea);
  return o;
}

ControllerStateMsg decode(const pedalwave_msg_dds__ControllerState_& m) {
  ControllerStateMsg o;
  o.seq = m.seq;
  o.stamp_ns = m.stamp_ns;
  o.ros_stamp_ns = stamp_ns(m.header.stamp);
  o.t = m.t;
  o.mode = m.mode;
  o.mode_name = str(m.mode_name);
  o.alpha_d = copy(m.alpha_d);
  o.eta = copy(m.eta);
  o.u = copy(m.u);
  return o;
}

ObserverStateMsg decode(const pedalwave_msg_dds__ObserverState_& m) {
  ObserverStateMsg o;
  o.seq = m.seq;
  o.stamp_ns = m.stamp_ns;
  o.ros_stamp_ns = stamp_ns(m.header.stamp);
  o.residual = copy(m.residual);
  o.tau_ext = copy(m.tau_ext);
  std::copy(std::begin(m.body), std::end(m.body), o.body.begin());
  o.fault_flags = m.fault_flags;
  o.fault_joint = m.fault_joint;
  o.forward_speed = m.forward_speed;
  return o;
}

LoopTimingMsg decode(const pedalwave_msg_dds__LoopTiming_& m) {
  LoopTimingMsg o;
  o.seq = m.seq;
  o.stamp_ns = m.stamp_ns;
  o.ros_stamp_ns = stamp_ns(m.header.stamp);
  o.wake_latency_ns = m.wake_latency_ns;
  o.t_read_ns = m.t_read_ns;
  o.t_observe_ns = m.t_observe_ns;
  o.t_control_ns = m.t_control_ns;
  o.t_write_ns = m.t_write_ns;
  o.overruns = m.overruns;
  o.ring_drops = m.ring_drops;
  return o;
}

ModeEventMsg decode(const pedalwave_msg_dds__ModeEvent_& m) {
  ModeEventMsg o;
  o.event_seq = m.event_seq;
  o.seq = m.seq;
  o.stamp_ns = m.stamp_ns;
  o.ros_stamp_ns = stamp_ns(m.header.stamp);
  o.from = m.from_mode;
  o.to = m.to_mode;
  o.from_name = str(m.from_name);
  o.to_name = str(m.to_name);
  o.text = str(m.text);
  o.value = m.value;
  o.severity = m.severity;
  return o;
}

FaultEventMsg decode(const pedalwave_msg_dds__FaultEvent_& m) {
  FaultEventMsg o;
  o.event_seq = m.event_seq;
  o.seq = m.seq;
  o.stamp_ns = m.stamp_ns;
  o.ros_stamp_ns = stamp_ns(m.header.stamp);
  o.fault_class = m.fault_class;
  o.class_name = str(m.class_name);
  o.severity = m.severity;
  o.severity_name = str(m.severity_name);
  o.joint = m.joint;
  o.value = m.value;
  o.threshold = m.threshold;
  o.mode = m.mode;
  o.text = str(m.text);
  return o;
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
  d.ros_namespace = str(m.ros_namespace);
  return d;
}

CommandAckMsg decode(const pedalwave_msg_dds__CommandAck_& m) {
  CommandAckMsg o;
  o.robot = str(m.robot);
  o.id = m.id;
  o.kind = m.kind;
  o.status = m.status <= 2 ? static_cast<AckStatus>(m.status) : AckStatus::kRejected;
  o.stamp_ns = m.stamp_ns;
  o.reason = str(m.reason);
  return o;
}

OperatorCommandMsg decode(const pedalwave_msg_dds__OperatorCommand_& m) {
  OperatorCommandMsg o;
  o.target = str(m.target);
  o.kind = m.kind;
  o.id = m.id;
  o.amplitude = m.amplitude;
  o.omega = m.omega;
  o.eta = m.eta;
  o.sender = str(m.sender);
  return o;
}

namespace {
std::string cstr(const char* s) { return s != nullptr ? std::string(s) : std::string(); }
}  // namespace

std::string decode(const std_msgs_msg_dds__String_& m) { return cstr(m.data); }

RosJointStatesMsg decode(const sensor_msgs_msg_dds__JointState_& m) {
  RosJointStatesMsg o;
  o.stamp_ns = stamp_ns(m.header.stamp);
  o.frame_id = cstr(m.header.frame_id);
  for (std::uint32_t i = 0; i < m.name._length; ++i) o.name.push_back(cstr(m.name._buffer[i]));
  o.position = copy(m.position);
  o.velocity = copy(m.velocity);
  o.effort = copy(m.effort);
  return o;
}

DiagnosticArrayMsg decode(const diagnostic_msgs_msg_dds__DiagnosticArray_& m) {
  DiagnosticArrayMsg o;
  o.stamp_ns = stamp_ns(m.header.stamp);
  for (std::uint32_t i = 0; i < m.status._length; ++i) {
    const auto& c = m.status._buffer[i];
    DiagnosticStatusMsg st;
    st.level = c.level;
    st.name = cstr(c.name);
    st.message = cstr(c.message);
    st.hardware_id = cstr(c.hardware_id);
    for (std::uint32_t k = 0; k < c.values._length; ++k) {
      st.values.emplace_back(cstr(c.values._buffer[k].key), cstr(c.values._buffer[k].value));
    }
    o.status.push_back(std::move(st));
  }
  return o;
}

TfMsg decode(const tf2_msgs_msg_dds__TFMessage_& m) {
  TfMsg o;
  for (std::uint32_t i = 0; i < m.transforms._length; ++i) {
    const auto& t = m.transforms._buffer[i];
    TransformMsg x;
    x.stamp_ns = stamp_ns(t.header.stamp);
    x.parent = cstr(t.header.frame_id);
    x.child = cstr(t.child_frame_id);
    x.translation = {t.transform.translation.x, t.transform.translation.y,
                     t.transform.translation.z};
    x.rotation = {t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
                  t.transform.rotation.w};
    o.transforms.push_back(std::move(x));
  }
  return o;
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
