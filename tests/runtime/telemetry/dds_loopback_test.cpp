// Real Cyclone DDS, publisher and subscriber in one process (one domain instance, Cyclone's local
// delivery): every topic field by field, decimation, transient-local late joiner, commands.
#include <gtest/gtest.h>

#include <cmath>
#include <mutex>
#include <thread>

#include "collector.hpp"
#include "dds_test_support.hpp"
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/synthetic.hpp"

namespace pedalwave::test {
namespace {

using namespace std::chrono_literals;
using runtime::Mode;
using runtime::OperatorCommand;
using runtime::OperatorCommandKind;

telemetry::TelemetryConfig robot_config(std::uint32_t domain) {
  telemetry::TelemetryConfig c;
  c.domain_id = domain;
  return c;
}

telemetry::SubscriberConfig monitor_config(std::uint32_t domain, int depth = 256) {
  telemetry::SubscriberConfig c;
  c.domain_id = domain;
  c.state_history_depth = depth;
  c.sender = "test";
  return c;
}

// Waits until the writer and the reader of joint_state see each other.
void wait_matched(const telemetry::DdsTelemetry& tel, const telemetry::TelemetrySubscriber& sub) {
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while ((tel.joint_state_readers() == 0 || sub.joint_state_writers() == 0) &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_GT(tel.joint_state_readers(), 0) << "subscriber never matched the publisher";
}

TEST(DdsLoopback, EveryTopicArrivesFieldByFieldWithDecimation) {
  DomainLease lease;
  auto cfg = robot_config(lease.id());
  cfg.decimation.controller_state = 2;
  cfg.decimation.loop_timing = 5;
  telemetry::DdsTelemetry tel(cfg);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), 1000));
  Collector got;
  sub.add_listener(got);
  wait_matched(tel, sub);

  const telemetry::SyntheticRobot robot(7, 1000.0);
  tel.on_description(robot.description());
  tel.on_event(robot.mode_event(Mode::kReady, Mode::kRunning, 0));
  std::vector<runtime::EventSample> faults;
  for (std::uint64_t k = 0; k < 3; ++k) faults.push_back(robot.fault_event(k, 10 + k));
  for (const auto& f : faults) tel.on_event(f);
  // A fault that also changes the mode goes to both topics; a note (no fault, no change) to
  // mode_event only.
  runtime::EventSample both = robot.fault_event(7, 20);
  tel.on_event(both);
  runtime::EventSample note = robot.mode_event(Mode::kRunning, Mode::kRunning, 30);
  tel.on_event(note);
  constexpr int kCycles = 500;
  for (int i = 0; i < kCycles; ++i) tel.on_cycle(robot.sample(static_cast<std::uint64_t>(i)));

  ASSERT_TRUE(poll_until(sub, [&] {
    return got.joint.size() == kCycles && got.ctrl.size() == kCycles / 2 &&
           got.obs.size() == kCycles && got.timing.size() == kCycles / 5 &&
           got.faults.size() == 4 && got.modes.size() == 3 && got.descs.size() == 1;
  })) << "joint " << got.joint.size() << " ctrl " << got.ctrl.size() << " obs " << got.obs.size()
      << " timing " << got.timing.size() << " faults " << got.faults.size() << " modes "
      << got.modes.size() << " descs " << got.descs.size();

  for (const auto& m : got.joint) expect_matches(m, robot.sample(m.seq));
  for (const auto& m : got.ctrl) {
    EXPECT_EQ(m.seq % 2, 0u);
    expect_matches(m, robot.sample(m.seq));
    EXPECT_EQ(m.mode_name, "running");
  }
  for (const auto& m : got.obs) expect_matches(m, robot.sample(m.seq));
  for (const auto& m : got.timing) {
    EXPECT_EQ(m.seq % 5, 0u);
    expect_matches(m, robot.sample(m.seq));
  }
  for (std::size_t k = 0; k < 3; ++k) expect_matches(got.faults[k], faults[k]);
  expect_matches(got.faults[3], both);
  EXPECT_EQ(got.faults[0].class_name, "actuator_torque");
  EXPECT_EQ(got.modes[0].from_name, "ready");
  EXPECT_EQ(got.modes[0].to_name, "running");
  EXPECT_EQ(got.modes[1].seq, both.seq);
  EXPECT_EQ(got.modes[1].to_name, "fault");
  EXPECT_EQ(got.modes[2].from, got.modes[2].to);
  EXPECT_EQ(got.modes[2].text, std::string(note.text.data()));
  expect_matches(got.descs[0], robot.description());
  EXPECT_EQ(got.descs[0].joint_state_rate_hz, 1000.0);
  EXPECT_EQ(got.descs[0].controller_state_rate_hz, 500.0);
  EXPECT_EQ(got.descs[0].loop_timing_rate_hz, 200.0);

  const auto st = tel.stats();
  EXPECT_EQ(st.joint_state, static_cast<std::uint64_t>(kCycles));
  EXPECT_EQ(st.controller_state, static_cast<std::uint64_t>(kCycles / 2));
  EXPECT_EQ(st.loop_timing, static_cast<std::uint64_t>(kCycles / 5));
  EXPECT_EQ(st.fault_events, 4u);
  EXPECT_EQ(st.mode_events, 3u);
  EXPECT_EQ(st.write_errors, 0u);
}

TEST(DdsLoopback, JointCountOutsideRangeIsClampedNotOverrun) {
  DomainLease lease;
  telemetry::DdsTelemetry tel(robot_config(lease.id()));
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  sub.add_listener(got);
  wait_matched(tel, sub);
  runtime::CycleSample s = telemetry::SyntheticRobot(3, 100.0).sample(1);
  s.joints = 1000;  // corrupt: more than kMaxJoints
  tel.on_cycle(s);
  s.seq = 2;
  s.joints = -4;
  tel.on_cycle(s);
  ASSERT_TRUE(poll_until(sub, [&] { return got.joint.size() == 2; }));
  EXPECT_EQ(got.joint[0].beta.size(), static_cast<std::size_t>(runtime::kMaxJoints));
  EXPECT_EQ(got.joint[1].beta.size(), 0u);
}

TEST(DdsLoopback, LateJoinerGetsDescriptionAndLast100FaultEvents) {
  DomainLease lease;
  telemetry::DdsTelemetry tel(robot_config(lease.id()));
  const telemetry::SyntheticRobot robot(5, 500.0);
  tel.on_description(robot.description());
  for (std::uint64_t k = 0; k < 150; ++k) tel.on_event(robot.fault_event(k, 1000 + k));
  for (std::uint64_t i = 0; i < 50; ++i) tel.on_cycle(robot.sample(i));  // volatile: not replayed

  telemetry::TelemetrySubscriber late(monitor_config(lease.id()));
  Collector got;
  late.add_listener(got);
  ASSERT_TRUE(poll_until(late, [&] { return got.faults.size() >= 100 && got.descs.size() == 1; }))
      << "faults " << got.faults.size() << " descs " << got.descs.size();
  late.poll(300ms);  // nothing more may come
  ASSERT_EQ(got.faults.size(), 100u);
  for (std::size_t i = 0; i < 100; ++i) expect_matches(got.faults[i], robot.fault_event(50 + i, 1050 + i));
  expect_matches(got.descs[0], robot.description());
  EXPECT_TRUE(got.joint.empty()) << "state topics are volatile: no history for late joiners";
}

// ---- Commands ---------------------------------------------------------------------------------

struct CommandFixture : ::testing::Test {
  DomainLease lease;
  std::mutex mu;
  std::vector<OperatorCommand> handled;
  bool mailbox_accepts = true;

  std::unique_ptr<telemetry::DdsTelemetry> make_robot(bool enable, bool with_handler = true) {
    auto cfg = robot_config(lease.id());
    cfg.enable_commands = enable;
    telemetry::CommandHandler h;
    if (with_handler) {
      h = [this](const OperatorCommand& c) {
        std::lock_guard lock(mu);
        if (!mailbox_accepts) return false;
        handled.push_back(c);
        return true;
      };
    }
    return std::make_unique<telemetry::DdsTelemetry>(cfg, h);
  }

  // Sends c and returns its ack.
  telemetry::CommandAckMsg roundtrip(telemetry::TelemetrySubscriber& sub, Collector& got,
                                     const OperatorCommand& c) {
    const std::size_t before = got.acks.size();
    EXPECT_TRUE(sub.send_command(c));
    EXPECT_TRUE(poll_until(sub, [&] { return got.acks.size() > before; })) << "no ack";
    if (got.acks.size() <= before) return {};
    EXPECT_EQ(got.acks.back().id, c.id);
    EXPECT_EQ(got.acks.back().kind, static_cast<std::uint8_t>(c.kind));
    return got.acks.back();
  }

  std::size_t handled_count() {
    std::lock_guard lock(mu);
    return handled.size();
  }
};

OperatorCommand gait(std::uint64_t id, double a, double w, double eta) {
  OperatorCommand c;
  c.kind = OperatorCommandKind::kSetGait;
  c.id = id;
  c.amplitude = a;
  c.omega = w;
  c.eta = eta;
  return c;
}

OperatorCommand simple(std::uint64_t id, OperatorCommandKind k) {
  OperatorCommand c;
  c.kind = k;
  c.id = id;
  return c;
}

TEST_F(CommandFixture, ValidCommandsReachTheHandlerAndAreAcked) {
  auto robot = make_robot(true);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(sub.wait_for_robot(10s));

  auto ack = roundtrip(sub, got, simple(1, OperatorCommandKind::kStartWalking));
  EXPECT_EQ(ack.status, telemetry::AckStatus::kQueued) << ack.reason;
  ack = roundtrip(sub, got, gait(2, 0.5, 3.0, 0.7));
  EXPECT_EQ(ack.status, telemetry::AckStatus::kQueued) << ack.reason;
  ack = roundtrip(sub, got, gait(3, 1.2, 12.0, 0.0));  // closed bounds: edges accepted
  EXPECT_EQ(ack.status, telemetry::AckStatus::kQueued) << ack.reason;
  std::lock_guard lock(mu);
  ASSERT_EQ(handled.size(), 3u);
  EXPECT_EQ(handled[0].kind, OperatorCommandKind::kStartWalking);
  EXPECT_EQ(handled[1].id, 2u);
  EXPECT_EQ(handled[1].amplitude, 0.5);
  EXPECT_EQ(handled[1].omega, 3.0);
  EXPECT_EQ(handled[1].eta, 0.7);
  EXPECT_EQ(robot->stats().commands_accepted, 3u);
}

TEST_F(CommandFixture, InvalidCommandsAreRejectedWithTheReasonPublished) {
  auto robot = make_robot(true);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(sub.wait_for_robot(10s));

  auto ack = roundtrip(sub, got, gait(10, 3.0, 1.0, 0.5));
  EXPECT_EQ(ack.status, telemetry::AckStatus::kRejected);
  EXPECT_NE(ack.reason.find("amplitude = 3"), std::string::npos) << ack.reason;
  EXPECT_NE(ack.reason.find("[0, 1.2]"), std::string::npos) << ack.reason;

  ack = roundtrip(sub, got, gait(11, 0.5, std::nan(""), 0.5));
  EXPECT_EQ(ack.status, telemetry::AckStatus::kRejected);
  EXPECT_NE(ack.reason.find("omega"), std::string::npos) << ack.reason;
  EXPECT_NE(ack.reason.find("not a finite"), std::string::npos) << ack.reason;

  ack = roundtrip(sub, got, gait(12, 0.5, 1.0, -0.1));
  EXPECT_EQ(ack.status, telemetry::AckStatus::kRejected);
  EXPECT_NE(ack.reason.find("eta"), std::string::npos) << ack.reason;

  ack = roundtrip(sub, got, simple(13, static_cast<OperatorCommandKind>(9)));
  EXPECT_EQ(ack.status, telemetry::AckStatus::kRejected);
  EXPECT_NE(ack.reason.find("unknown command kind 9"), std::string::npos) << ack.reason;

  EXPECT_EQ(handled_count(), 0u) << "a rejected command reached the runtime";
  EXPECT_EQ(robot->stats().commands_rejected, 4u);
}

TEST_F(CommandFixture, DisabledCommandsRejectAllButEmergencyStop) {
  auto robot = make_robot(false);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(sub.wait_for_robot(10s));

  for (auto c : {simple(20, OperatorCommandKind::kStartWalking),
                 simple(21, OperatorCommandKind::kStopWalking), gait(22, 0.5, 3.0, 0.7)}) {
    const auto ack = roundtrip(sub, got, c);
    EXPECT_EQ(ack.status, telemetry::AckStatus::kRejected);
    EXPECT_NE(ack.reason.find("disabled"), std::string::npos) << ack.reason;
  }
  EXPECT_EQ(handled_count(), 0u);
  // Emergency stop, even carrying garbage in the gait fields.
  OperatorCommand estop = simple(23, OperatorCommandKind::kEmergencyStop);
  estop.amplitude = std::nan("");
  const auto ack = roundtrip(sub, got, estop);
  EXPECT_EQ(ack.status, telemetry::AckStatus::kQueued) << ack.reason;
  std::lock_guard lock(mu);
  ASSERT_EQ(handled.size(), 1u);
  EXPECT_EQ(handled[0].kind, OperatorCommandKind::kEmergencyStop);
  EXPECT_EQ(handled[0].id, 23u);
}

TEST_F(CommandFixture, FullMailboxAndMissingHandlerAreRejections) {
  {
    auto robot = make_robot(true);
    telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
    Collector got;
    sub.add_listener(got);
    ASSERT_TRUE(sub.wait_for_robot(10s));
    {
      std::lock_guard lock(mu);
      mailbox_accepts = false;
    }
    const auto ack = roundtrip(sub, got, simple(30, OperatorCommandKind::kEmergencyStop));
    EXPECT_EQ(ack.status, telemetry::AckStatus::kRejected);
    EXPECT_NE(ack.reason.find("mailbox full"), std::string::npos) << ack.reason;
  }
  auto robot = make_robot(true, /*with_handler=*/false);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(sub.wait_for_robot(10s));
  const auto ack = roundtrip(sub, got, simple(31, OperatorCommandKind::kStopWalking));
  EXPECT_EQ(ack.status, telemetry::AckStatus::kRejected);
  EXPECT_NE(ack.reason.find("no command handler"), std::string::npos) << ack.reason;
}

}  // namespace
}  // namespace pedalwave::test
