// A TelemetryListener that keeps every message, and field-by-field comparisons against the
// runtime structs the publisher was given.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "pedalwave/interface/telemetry_sink.hpp"
#include "pedalwave/telemetry/subscriber.hpp"

namespace pedalwave::test {

struct Collector : telemetry::TelemetryListener {
  std::vector<telemetry::JointStateMsg> joint;
  std::vector<telemetry::ControllerStateMsg> ctrl;
  std::vector<telemetry::ObserverStateMsg> obs;
  std::vector<telemetry::LoopTimingMsg> timing;
  std::vector<telemetry::ModeEventMsg> modes;
  std::vector<telemetry::FaultEventMsg> faults;
  std::vector<telemetry::DescriptionMsg> descs;
  std::vector<telemetry::OperatorCommandMsg> commands;
  std::vector<telemetry::CommandAckMsg> acks;
  std::vector<telemetry::MessageInfo> joint_info;

  void on_joint_state(const telemetry::JointStateMsg& m, const telemetry::MessageInfo& i) override {
    joint.push_back(m);
    joint_info.push_back(i);
  }
  void on_controller_state(const telemetry::ControllerStateMsg& m,
                           const telemetry::MessageInfo&) override {
    ctrl.push_back(m);
  }
  void on_observer_state(const telemetry::ObserverStateMsg& m,
                         const telemetry::MessageInfo&) override {
    obs.push_back(m);
  }
  void on_loop_timing(const telemetry::LoopTimingMsg& m, const telemetry::MessageInfo&) override {
    timing.push_back(m);
  }
  void on_mode_event(const telemetry::ModeEventMsg& m, const telemetry::MessageInfo&) override {
    modes.push_back(m);
  }
  void on_fault_event(const telemetry::FaultEventMsg& m, const telemetry::MessageInfo&) override {
    faults.push_back(m);
  }
  void on_description(const telemetry::DescriptionMsg& m, const telemetry::MessageInfo&) override {
    descs.push_back(m);
  }
  void on_command(const telemetry::OperatorCommandMsg& m, const telemetry::MessageInfo&) override {
    commands.push_back(m);
  }
  void on_command_ack(const telemetry::CommandAckMsg& m, const telemetry::MessageInfo&) override {
    acks.push_back(m);
  }
};

// Polls `sub` until pred() holds or `timeout` passes; returns pred().
inline bool poll_until(telemetry::TelemetrySubscriber& sub, const std::function<bool()>& pred,
                       std::chrono::milliseconds timeout = std::chrono::milliseconds(10000)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    sub.poll(std::chrono::milliseconds(20));
  }
  return true;
}

template <std::size_t M>
void expect_joint_vector(const std::vector<double>& got, const std::array<double, M>& want, int n,
                         const char* what) {
  ASSERT_EQ(got.size(), static_cast<std::size_t>(n)) << what;
  for (int j = 0; j < n; ++j) {
    EXPECT_EQ(got[static_cast<std::size_t>(j)], want[static_cast<std::size_t>(j)])
        << what << "[" << j << "]";
  }
}

inline void expect_matches(const telemetry::JointStateMsg& m, const runtime::CycleSample& s) {
  EXPECT_EQ(m.seq, s.seq);
  EXPECT_EQ(m.stamp_ns, s.t_ns);
  EXPECT_EQ(m.t, s.t);
  expect_joint_vector(m.beta, s.beta, s.joints, "beta");
  expect_joint_vector(m.beta_dot, s.beta_dot, s.joints, "beta_dot");
  expect_joint_vector(m.alpha, s.alpha, s.joints, "alpha");
  expect_joint_vector(m.deflection, s.deflection, s.joints, "deflection");
  expect_joint_vector(m.tau_sea, s.tau_sea, s.joints, "tau_sea");
}

inline void expect_matches(const telemetry::ControllerStateMsg& m, const runtime::CycleSample& s) {
  EXPECT_EQ(m.seq, s.seq);
  EXPECT_EQ(m.stamp_ns, s.t_ns);
  EXPECT_EQ(m.t, s.t);
  EXPECT_EQ(m.mode, static_cast<std::uint8_t>(s.mode));
  expect_joint_vector(m.alpha_d, s.alpha_d, s.joints, "alpha_d");
  expect_joint_vector(m.eta, s.eta, s.joints, "eta");
  expect_joint_vector(m.u, s.u, s.joints, "u");
}

inline void expect_matches(const telemetry::ObserverStateMsg& m, const runtime::CycleSample& s) {
  EXPECT_EQ(m.seq, s.seq);
  EXPECT_EQ(m.stamp_ns, s.t_ns);
  expect_joint_vector(m.residual, s.residual, s.joints, "residual");
  expect_joint_vector(m.tau_ext, s.tau_ext, s.joints, "tau_ext");
  for (std::size_t k = 0; k < 6; ++k) EXPECT_EQ(m.body[k], s.body[k]) << "body[" << k << "]";
  EXPECT_EQ(m.fault_flags, s.fault_flags);
  EXPECT_EQ(m.fault_joint, s.fault_joint);
  EXPECT_EQ(m.forward_speed, s.forward_speed);
}

inline void expect_matches(const telemetry::LoopTimingMsg& m, const runtime::CycleSample& s) {
  EXPECT_EQ(m.seq, s.seq);
  EXPECT_EQ(m.stamp_ns, s.t_ns);
  EXPECT_EQ(m.wake_latency_ns, s.wake_latency_ns);
  EXPECT_EQ(m.t_read_ns, s.t_read_ns);
  EXPECT_EQ(m.t_observe_ns, s.t_observe_ns);
  EXPECT_EQ(m.t_control_ns, s.t_control_ns);
  EXPECT_EQ(m.t_write_ns, s.t_write_ns);
  EXPECT_EQ(m.overruns, s.overruns);
  EXPECT_EQ(m.ring_drops, s.ring_drops);
}

inline void expect_matches(const telemetry::FaultEventMsg& m, const runtime::EventSample& e) {
  EXPECT_EQ(m.seq, e.seq);
  EXPECT_EQ(m.stamp_ns, e.t_ns);
  EXPECT_EQ(m.fault_class, static_cast<std::uint8_t>(e.fault));
  EXPECT_EQ(m.severity, static_cast<std::uint8_t>(e.severity));
  EXPECT_EQ(m.joint, e.joint);
  EXPECT_EQ(m.value, e.value);
  EXPECT_EQ(m.threshold, e.threshold);
  EXPECT_EQ(m.mode, static_cast<std::uint8_t>(e.to));
  EXPECT_EQ(m.text, std::string(e.text.data()));
}

inline void expect_matches(const telemetry::DescriptionMsg& m, const runtime::RobotDescription& d) {
  EXPECT_EQ(m.links, d.links);
  EXPECT_EQ(m.link_length, d.link_length);
  EXPECT_EQ(m.link_mass, d.link_mass);
  EXPECT_EQ(m.rotor_mass, d.rotor_mass);
  EXPECT_EQ(m.rotor_inertia, d.rotor_inertia);
  EXPECT_EQ(m.gear_ratio, d.gear_ratio);
  expect_joint_vector(m.spring_stiffness, d.spring_stiffness, d.links - 1, "spring_stiffness");
  EXPECT_EQ(m.rate_hz, d.rate_hz);
  EXPECT_EQ(m.name, std::string(d.name.data()));
  EXPECT_EQ(m.driver, std::string(d.driver.data()));
}

}  // namespace pedalwave::test
