// MonitorState: what the monitor shows, with synthetic times (no DDS).
#include <gtest/gtest.h>

#include "pedalwave/telemetry/monitor_view.hpp"

namespace pedalwave::telemetry {
namespace {

constexpr std::int64_t kMs = 1'000'000;

JointStateMsg joint(std::uint64_t seq, std::size_t n) {
  JointStateMsg m;
  m.seq = seq;
  m.beta.assign(n, 0.1);
  m.beta_dot.assign(n, 0.0);
  m.alpha.assign(n, 0.1);
  m.deflection.assign(n, 0.0);
  m.tau_sea.assign(n, 0.5);
  if (n > 1) m.tau_sea[1] = -1.5;
  return m;
}

MessageInfo at(std::int64_t t_ns, std::uint64_t publication = 1) { return {t_ns, 0, publication}; }

TEST(MonitorState, RendersJointsModeFaultsAndTiming) {
  MonitorState m(500 * kMs);
  DescriptionMsg d;
  d.name = "snake7";
  d.driver = "sim";
  d.links = 4;
  d.rate_hz = 1000.0;
  m.on_description(d, at(0));
  EXPECT_FALSE(m.complete());
  m.on_joint_state(joint(10, 3), at(1 * kMs));
  ControllerStateMsg c;
  c.seq = 10;
  c.mode_name = "running";
  m.on_controller_state(c, at(1 * kMs));
  ObserverStateMsg o;
  o.residual = {0.01, 0.02, 0.3};
  o.tau_ext = {0.0, 0.0, 0.0};
  o.fault_flags = 1u << 3;  // encoder_stuck
  o.fault_joint = 2;
  o.forward_speed = 0.125;
  m.on_observer_state(o, at(1 * kMs));
  LoopTimingMsg t;
  t.wake_latency_ns = 12'300;
  t.overruns = 4;
  m.on_loop_timing(t, at(1 * kMs));
  EXPECT_TRUE(m.complete());
  FaultEventMsg f;
  f.class_name = "encoder_stuck";
  f.severity_name = "stop";
  f.joint = 2;
  f.value = 0.3;
  f.threshold = 0.1;
  m.on_fault_event(f, at(2 * kMs));

  const std::string plain = m.render(3 * kMs, false);
  EXPECT_NE(plain.find("snake7"), std::string::npos) << plain;
  EXPECT_NE(plain.find("LIVE"), std::string::npos) << plain;
  EXPECT_NE(plain.find("mode running"), std::string::npos) << plain;
  EXPECT_NE(plain.find("+0.1250 m/s"), std::string::npos) << plain;
  // Fields are 0-based, the screen 1-based: fault_joint = 2 is the third joint.
  EXPECT_NE(plain.find("faults: encoder_stuck  isolated joint 3"), std::string::npos) << plain;
  EXPECT_NE(plain.find("FAULT encoder_stuck (stop) joint 3"), std::string::npos) << plain;
  EXPECT_NE(plain.find("stop     joint   3"), std::string::npos) << plain;
  EXPECT_NE(plain.find("wake latency 12.3 us"), std::string::npos) << plain;
  EXPECT_NE(plain.find("overruns 4"), std::string::npos) << plain;
  EXPECT_NE(plain.find("-1.5000"), std::string::npos) << "joint 1 torque missing\n" << plain;
  EXPECT_NE(plain.find("|############|"), std::string::npos) << "largest torque = full bar";
  EXPECT_EQ(plain.find("\x1b["), std::string::npos) << "no ANSI codes when not asked";
  const std::string ansi = m.render(3 * kMs, true);
  EXPECT_NE(ansi.find("\x1b[K"), std::string::npos);
}

TEST(MonitorState, NoticesSilenceComebackAndRestart) {
  MonitorState m(500 * kMs);
  m.tick(0);
  m.on_joint_state(joint(100, 2), at(10 * kMs, 7));
  m.on_joint_state(joint(101, 2), at(11 * kMs, 7));
  m.tick(400 * kMs);
  EXPECT_FALSE(m.liveness().silent());
  m.tick(600 * kMs);
  EXPECT_TRUE(m.liveness().silent());
  EXPECT_NE(m.render(900 * kMs, false).find("SILENT for 0.9 s"), std::string::npos);
  // A different publisher with seq from 0: a restart.
  m.on_joint_state(joint(0, 2), at(1000 * kMs, 8));
  EXPECT_FALSE(m.liveness().silent());
  EXPECT_EQ(m.restarts(), 1u);
  const auto notes = m.take_new_notices();
  ASSERT_EQ(notes.size(), 4u);
  EXPECT_NE(notes[0].find("robot found"), std::string::npos) << notes[0];
  EXPECT_NE(notes[1].find("SILENT"), std::string::npos) << notes[1];
  EXPECT_NE(notes[2].find("restarted"), std::string::npos) << notes[2];
  EXPECT_NE(notes[3].find("back"), std::string::npos) << notes[3];
  EXPECT_TRUE(m.take_new_notices().empty());
}

TEST(MonitorState, ReceiveRatesOverOneSecondWindows) {
  MonitorState m(500 * kMs);
  for (int i = 0; i < 200; ++i) {
    m.on_joint_state(joint(static_cast<std::uint64_t>(i), 1), at(i * 5 * kMs));
    if (i % 2 == 0) {
      LoopTimingMsg t;
      t.seq = static_cast<std::uint64_t>(i);
      m.on_loop_timing(t, at(i * 5 * kMs));
    }
  }
  m.tick(1000 * kMs);
  EXPECT_NEAR(m.rate_hz(MonitorState::kJoint), 200.0, 1.0);
  EXPECT_NEAR(m.rate_hz(MonitorState::kTiming), 100.0, 1.0);
  EXPECT_EQ(m.received(MonitorState::kJoint), 200u);
}

}  // namespace
}  // namespace pedalwave::telemetry
