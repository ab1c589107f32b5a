// ROS 2 conventions of the telemetry: the standard topics (sensor_msgs/JointState, URDF,
// /tf, /diagnostics) against the samples published, robot namespaces and addressed commands,
// acks that report the runtime's outcome, gap-checkable event_seq, domain/discovery resolution
// from the ROS 2 environment, and discovery with Cyclone's default configuration across
// processes. Real Cyclone DDS (in-process; one test with a second process).
#include <gtest/gtest.h>
#include <ifaddrs.h>
#include <net/if.h>

#include <cmath>
#include <cstring>
#include <sstream>
#include <ctime>
#include <map>
#include <mutex>
#include <thread>

#include "collector.hpp"
#include "dds_test_support.hpp"
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/monitor_view.hpp"
#include "pedalwave/telemetry/names.hpp"
#include "pedalwave/telemetry/ros_standard.hpp"
#include "pedalwave/telemetry/synthetic.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::test {
namespace {

using namespace std::chrono_literals;
using runtime::Mode;
using runtime::OperatorCommand;
using runtime::OperatorCommandKind;
using telemetry::AckStatus;

telemetry::TelemetryConfig robot_config(std::uint32_t domain, const std::string& name) {
  telemetry::TelemetryConfig c;
  c.domain_id = domain;
  c.robot_name = name;
  return c;
}

telemetry::SubscriberConfig monitor_config(std::uint32_t domain, const std::string& robot,
                                           bool standard = false) {
  telemetry::SubscriberConfig c;
  c.domain_id = domain;
  c.robot = robot;
  c.standard_topics = standard;
  c.state_history_depth = 1000;
  c.sender = "test";
  return c;
}

// Everything of the standard topics.
struct StandardCollector : telemetry::TelemetryListener {
  std::vector<std::string> urdf;
  std::vector<telemetry::RosJointStatesMsg> js;
  std::vector<telemetry::DiagnosticArrayMsg> diag;
  std::vector<telemetry::TfMsg> tf;
  void on_urdf(const std::string& u, const telemetry::MessageInfo&) override { urdf.push_back(u); }
  void on_joint_states(const telemetry::RosJointStatesMsg& m,
                       const telemetry::MessageInfo&) override {
    js.push_back(m);
  }
  void on_diagnostics(const telemetry::DiagnosticArrayMsg& m,
                      const telemetry::MessageInfo&) override {
    diag.push_back(m);
  }
  void on_tf(const telemetry::TfMsg& m, const telemetry::MessageInfo&) override { tf.push_back(m); }
};

std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (auto p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

// Planar pose composition (the XZ plane, rotation from +X towards +Z), from a TransformMsg.
struct Pose {
  double x = 0, z = 0, theta = 0;
};
Pose compose(const Pose& a, const telemetry::TransformMsg& t) {
  EXPECT_NEAR(t.translation[1], 0.0, 1e-15);
  EXPECT_NEAR(t.rotation[0], 0.0, 1e-15);
  EXPECT_NEAR(t.rotation[2], 0.0, 1e-15);
  // planar_quaternion: (0, −sin(θ/2), 0, cos(θ/2)).
  const double dtheta = -2.0 * std::atan2(t.rotation[1], t.rotation[3]);
  return {a.x + std::cos(a.theta) * t.translation[0] - std::sin(a.theta) * t.translation[2],
          a.z + std::sin(a.theta) * t.translation[0] + std::cos(a.theta) * t.translation[2],
          a.theta + dtheta};
}

TEST(Ros2Standard, JointStatesUrdfTfAndDiagnosticsMatchTheSamples) {
  DomainLease lease;
  auto cfg = robot_config(lease.id(), "snake1");
  cfg.decimation.joint_state = 2;
  telemetry::DdsTelemetry tel(cfg);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), "snake1", true));
  StandardCollector got;
  sub.add_listener(got);
  Collector own;
  sub.add_listener(own);
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (tel.joint_state_readers() == 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(5ms);
  ASSERT_GT(tel.joint_state_readers(), 0);

  const telemetry::SyntheticRobot robot(5, 1000.0);   // N = 6
  runtime::RobotDescription d = robot.description();
  tel.on_description(d);
  constexpr int kCycles = 40;
  const std::int64_t offset_before = clock_ns(CLOCK_REALTIME) - clock_ns(CLOCK_MONOTONIC);
  for (int i = 0; i < kCycles; ++i) tel.on_cycle(robot.sample(static_cast<std::uint64_t>(i)));
  const std::int64_t offset_after = clock_ns(CLOCK_REALTIME) - clock_ns(CLOCK_MONOTONIC);
  runtime::EventSample fault = robot.fault_event(3, 41);
  fault.severity = runtime::Severity::kStop;
  tel.on_event(fault);

  ASSERT_TRUE(poll_until(sub, [&] {
    return got.urdf.size() == 1 && got.js.size() == kCycles / 2 && got.tf.size() == kCycles / 2 &&
           !got.diag.empty() && got.diag.back().status.size() == 3 &&
           got.diag.back().status[2].level == 2 && own.joint.size() == kCycles / 2;
  })) << "urdf " << got.urdf.size() << " js " << got.js.size() << " tf " << got.tf.size()
      << " diag " << got.diag.size();

  // URDF: 6 links, 5 revolute joints about +Y, 2l apart, names under the robot's prefix.
  const std::string& u = got.urdf[0];
  EXPECT_EQ(count(u, "<link name=\"snake1/link_"), 6u) << u;
  EXPECT_EQ(count(u, "type=\"revolute\""), 5u) << u;
  EXPECT_NE(u.find("<joint name=\"snake1/joint_5\""), std::string::npos) << u;
  EXPECT_NE(u.find("<child link=\"snake1/link_6\"/>"), std::string::npos) << u;
  EXPECT_EQ(count(u, "<axis xyz=\"0 1 0\"/>"), 5u);
  std::ostringstream origin;
  origin.precision(17);
  origin << "<origin xyz=\"" << d.link_length << " 0 0\"";
  EXPECT_EQ(count(u, origin.str()), 5u) << origin.str() << "\n" << u;

  // sensor_msgs/JointState: names, α, α̇ (backward difference over consecutive cycles), SEA torque,
  // stamped in ROS time (CLOCK_REALTIME) and by the robot's frame.
  for (std::size_t k = 0; k < got.js.size(); ++k) {
    const auto& m = got.js[k];
    const std::uint64_t seq = 2 * k;
    const runtime::CycleSample s = robot.sample(seq);
    ASSERT_EQ(m.name.size(), 5u);
    EXPECT_EQ(m.name[0], "snake1/joint_1");
    EXPECT_EQ(m.name[4], "snake1/joint_5");
    EXPECT_EQ(m.frame_id, "snake1");
    const std::int64_t lo = s.t_ns + std::min(offset_before, offset_after) - 1'000'000;
    const std::int64_t hi = s.t_ns + std::max(offset_before, offset_after) + 1'000'000;
    EXPECT_GE(m.stamp_ns, lo);
    EXPECT_LE(m.stamp_ns, hi);
    EXPECT_EQ(m.stamp_ns, own.joint[k].ros_stamp_ns) << "both views carry one stamp";
    for (std::size_t j = 0; j < 5; ++j) {
      EXPECT_EQ(m.position[j], s.alpha[j]);
      EXPECT_EQ(m.effort[j], s.tau_sea[j]);
      if (seq == 0) {
        EXPECT_EQ(m.velocity[j], s.beta_dot[j]) << "first sample: beta_dot stands in";
      } else {
        const runtime::CycleSample p = robot.sample(seq - 1);
        const double dt = static_cast<double>(s.t_ns - p.t_ns) * 1e-9;
        EXPECT_DOUBLE_EQ(m.velocity[j], (s.alpha[j] - p.alpha[j]) / dt);
      }
    }
  }

  // /tf: odom → link_1 → … → link_6; the mean of the link centres is (p_x, p_z), link 6's angle
  // is θ_N, each joint turns by −α_j (model-spec §1).
  for (std::size_t k = 0; k < got.tf.size(); ++k) {
    const auto& tf = got.tf[k];
    const runtime::CycleSample s = robot.sample(2 * k);
    ASSERT_EQ(tf.transforms.size(), 6u);
    EXPECT_EQ(tf.transforms[0].parent, "snake1/odom");
    EXPECT_EQ(tf.transforms[0].child, "snake1/link_1");
    EXPECT_EQ(tf.transforms[5].parent, "snake1/link_5");
    EXPECT_EQ(tf.transforms[5].child, "snake1/link_6");
    EXPECT_EQ(tf.transforms[0].stamp_ns, got.js[k].stamp_ns);
    Pose p;
    double cx = 0, cz = 0;
    for (std::size_t i = 0; i < 6; ++i) {
      p = compose(p, tf.transforms[i]);
      cx += p.x + 0.5 * d.link_length * std::cos(p.theta);
      cz += p.z + 0.5 * d.link_length * std::sin(p.theta);
      if (i >= 1) {
        EXPECT_NEAR(-2.0 * std::atan2(tf.transforms[i].rotation[1], tf.transforms[i].rotation[3]),
                    -s.alpha[i - 1], 1e-12);
      }
    }
    EXPECT_NEAR(cx / 6, s.body[1], 1e-9);
    EXPECT_NEAR(cz / 6, s.body[2], 1e-9);
    EXPECT_NEAR(std::remainder(p.theta - s.body[0], 2 * M_PI), 0.0, 1e-9);
  }

  // /diagnostics: mode, loop, faults; the stopping fault is an ERROR naming its class and joint.
  const auto& last = got.diag.back();
  EXPECT_EQ(last.status[0].name, "snake1: mode");
  EXPECT_EQ(last.status[1].name, "snake1: real-time loop");
  EXPECT_EQ(last.status[2].name, "snake1: faults");
  EXPECT_EQ(last.status[2].hardware_id, "snake1");
  std::map<std::string, std::string> kv(last.status[2].values.begin(), last.status[2].values.end());
  EXPECT_EQ(kv["class"], telemetry::fault_class_name(static_cast<std::uint8_t>(fault.fault)));
  EXPECT_EQ(kv["severity"], "stop");
  EXPECT_EQ(kv["joint"], fault.joint >= 0 ? std::to_string(fault.joint + 1) : "none");
  EXPECT_EQ(kv["faults_so_far"], "1");
  EXPECT_EQ(got.diag.front().status[2].level, 0) << "before the fault: OK";
  EXPECT_EQ(got.diag.front().status[2].message, "no fault");
}

TEST(Ros2Standard, MonotonicStampsWhenConfigured) {
  DomainLease lease;
  auto cfg = robot_config(lease.id(), "mono");
  cfg.stamp_clock = telemetry::StampClock::kMonotonic;
  telemetry::DdsTelemetry tel(cfg);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), "mono", true));
  StandardCollector got;
  sub.add_listener(got);
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (tel.joint_state_readers() == 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(5ms);
  const telemetry::SyntheticRobot robot(3, 100.0);
  tel.on_description(robot.description());
  tel.on_cycle(robot.sample(7));
  ASSERT_TRUE(poll_until(sub, [&] { return got.js.size() == 1; }));
  EXPECT_EQ(got.js[0].stamp_ns, robot.sample(7).t_ns);
}

// robot_description is transient-local, as robot_state_publisher's: a subscriber started after the
// robot (RViz opened later) still gets the URDF, exactly once; the volatile joint_states are not
// replayed.
TEST(Ros2Standard, ALateSubscriberGetsTheUrdf) {
  DomainLease lease;
  telemetry::DdsTelemetry tel(robot_config(lease.id(), "late"));
  const telemetry::SyntheticRobot robot(4, 100.0);
  tel.on_description(robot.description());
  for (std::uint64_t i = 0; i < 20; ++i) tel.on_cycle(robot.sample(i));
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), "late", true));
  StandardCollector got;
  sub.add_listener(got);
  ASSERT_TRUE(poll_until(sub, [&] { return !got.urdf.empty(); }));
  sub.poll(300ms);
  EXPECT_EQ(got.urdf.size(), 1u);
  EXPECT_EQ(count(got.urdf[0], "<link name=\"late/link_"), 5u);
  EXPECT_TRUE(got.js.empty()) << "joint_states are volatile";
}

// ---- Namespaces, addressed commands, outcome acks ---------------------------------------------

struct Robot {
  std::mutex mu;
  std::vector<OperatorCommand> handled;
  std::unique_ptr<telemetry::DdsTelemetry> tel;
  Robot(std::uint32_t domain, const std::string& name, double outcome_timeout_s = 2.0) {
    auto cfg = robot_config(domain, name);
    cfg.command_outcome_timeout_s = outcome_timeout_s;
    tel = std::make_unique<telemetry::DdsTelemetry>(cfg, [this](const OperatorCommand& c) {
      std::lock_guard lock(mu);
      handled.push_back(c);
      return true;
    });
  }
  std::size_t n_handled() {
    std::lock_guard lock(mu);
    return handled.size();
  }
};

OperatorCommand cmd(std::uint64_t id, OperatorCommandKind k) {
  OperatorCommand c;
  c.kind = k;
  c.id = id;
  if (k == OperatorCommandKind::kSetGait) {
    c.amplitude = 0.5;
    c.omega = 3.0;
    c.eta = 0.7;
  }
  return c;
}

// The runtime's outcome event for a command (what Runtime::apply_operator_command pushes).
runtime::EventSample outcome(std::uint64_t id, const char* text, runtime::Severity sev,
                             Mode from = Mode::kRunning, Mode to = Mode::kRunning) {
  runtime::EventSample e;
  e.seq = 100;
  e.from = from;
  e.to = to;
  e.severity = sev;
  e.value = static_cast<double>(id);
  std::strncpy(e.text.data(), text, e.text.size() - 1);
  return e;
}

std::vector<telemetry::CommandAckMsg> acks_of(const Collector& got, std::uint64_t id) {
  std::vector<telemetry::CommandAckMsg> out;
  for (const auto& a : got.acks)
    if (a.id == id) out.push_back(a);
  return out;
}

TEST(Ros2Conventions, TwoRobotsOnOneDomainKeepTheirTopicsAndCommandsApart) {
  DomainLease lease;
  Robot a(lease.id(), "alpha"), b(lease.id(), "beta");
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), "alpha"));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(sub.wait_for_robot(10s));
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while ((a.tel->joint_state_readers() == 0) && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(5ms);
  EXPECT_EQ(b.tel->joint_state_readers(), 0) << "beta's topics are under /beta";

  // Both publish; the subscriber of /alpha sees only alpha's samples (seq ranges differ).
  const telemetry::SyntheticRobot sr(4, 100.0);
  for (std::uint64_t i = 0; i < 10; ++i) a.tel->on_cycle(sr.sample(i));
  for (std::uint64_t i = 1000; i < 1010; ++i) b.tel->on_cycle(sr.sample(i));
  a.tel->on_description(sr.description());
  ASSERT_TRUE(poll_until(sub, [&] { return got.joint.size() >= 10 && got.descs.size() == 1; }));
  sub.poll(200ms);
  ASSERT_EQ(got.joint.size(), 10u);
  for (const auto& m : got.joint) EXPECT_LT(m.seq, 10u);
  EXPECT_EQ(got.descs[0].ros_namespace, "/alpha");

  // A command for alpha: alpha queues it, beta ignores it (no ack, handler not called).
  ASSERT_TRUE(sub.send_command(cmd(1, OperatorCommandKind::kStopWalking)));
  ASSERT_TRUE(poll_until(sub, [&] { return !acks_of(got, 1).empty(); }));
  sub.poll(300ms);
  auto acks = acks_of(got, 1);
  ASSERT_EQ(acks.size(), 1u);
  EXPECT_EQ(acks[0].robot, "alpha");
  EXPECT_EQ(acks[0].status, AckStatus::kQueued);
  EXPECT_EQ(a.n_handled(), 1u);
  EXPECT_EQ(b.n_handled(), 0u);
  EXPECT_EQ(b.tel->stats().commands_ignored, 1u);

  // A command for beta sent from alpha's monitor: only beta acts.
  ASSERT_TRUE(sub.send_command(cmd(2, OperatorCommandKind::kStopWalking), "beta"));
  ASSERT_TRUE(poll_until(sub, [&] { return !acks_of(got, 2).empty(); }));
  sub.poll(300ms);
  acks = acks_of(got, 2);
  ASSERT_EQ(acks.size(), 1u);
  EXPECT_EQ(acks[0].robot, "beta");
  EXPECT_EQ(a.n_handled(), 1u);
  EXPECT_EQ(b.n_handled(), 1u);

  // "*": every robot.
  ASSERT_TRUE(sub.send_command(cmd(3, OperatorCommandKind::kEmergencyStop), "*"));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 3).size() == 2; }));
  EXPECT_EQ(a.n_handled(), 2u);
  EXPECT_EQ(b.n_handled(), 2u);
}

TEST(Ros2Conventions, AcksReportTheRuntimesOutcomeNotJustReception) {
  DomainLease lease;
  Robot r(lease.id(), "snake", /*outcome_timeout_s=*/0.3);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), "snake"));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(sub.wait_for_robot(10s));

  // set_gait refused by the controller: QUEUED, then REJECTED with the runtime's reason.
  ASSERT_TRUE(sub.send_command(cmd(10, OperatorCommandKind::kSetGait)));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 10).size() == 1; }));
  EXPECT_EQ(acks_of(got, 10)[0].status, AckStatus::kQueued);
  // An unrelated note and another command's outcome do not resolve it.
  r.tel->on_event(outcome(99, "set gait accepted", runtime::Severity::kInfo));
  r.tel->on_event(outcome(10, "stop walking rejected: not walking", runtime::Severity::kWarning));
  r.tel->on_event(outcome(10, "set gait rejected by the controller's bounds",
                          runtime::Severity::kWarning));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 10).size() == 2; }));
  sub.poll(100ms);
  auto acks = acks_of(got, 10);
  ASSERT_EQ(acks.size(), 2u);
  EXPECT_EQ(acks[1].status, AckStatus::kRejected);
  EXPECT_EQ(acks[1].reason, "set gait rejected by the controller's bounds");

  // start walking executed (the READY → RUNNING transition carries the id).
  ASSERT_TRUE(sub.send_command(cmd(11, OperatorCommandKind::kStartWalking)));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 11).size() == 1; }));
  r.tel->on_event(outcome(11, "start walking", runtime::Severity::kInfo, Mode::kReady,
                          Mode::kRunning));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 11).size() == 2; }));
  EXPECT_EQ(acks_of(got, 11)[1].status, AckStatus::kExecuted);

  // Emergency stop: executed by the SAFE_STOP transition.
  ASSERT_TRUE(sub.send_command(cmd(12, OperatorCommandKind::kEmergencyStop)));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 12).size() == 1; }));
  r.tel->on_event(outcome(0, "operator emergency stop", runtime::Severity::kInfo, Mode::kRunning,
                          Mode::kSafeStop));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 12).size() == 2; }));
  EXPECT_EQ(acks_of(got, 12)[1].status, AckStatus::kExecuted);

  // No outcome at all: REJECTED after the timeout, exactly one final ack.
  ASSERT_TRUE(sub.send_command(cmd(13, OperatorCommandKind::kStopWalking)));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 13).size() == 2; }));
  sub.poll(500ms);
  acks = acks_of(got, 13);
  ASSERT_EQ(acks.size(), 2u);
  EXPECT_EQ(acks[1].status, AckStatus::kRejected);
  EXPECT_NE(acks[1].reason.find("no outcome"), std::string::npos) << acks[1].reason;

  const auto st = r.tel->stats();
  EXPECT_EQ(st.commands_accepted, 4u);
  EXPECT_EQ(st.commands_executed, 2u);
  EXPECT_EQ(st.commands_rejected, 2u);
}

TEST(Ros2Conventions, ARobotStoppingWithACommandQueuedStillGivesItsFinalAck) {
  DomainLease lease;
  auto r = std::make_unique<Robot>(lease.id(), "stopping", /*outcome_timeout_s=*/60.0);
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), "stopping"));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(sub.wait_for_robot(10s));
  ASSERT_TRUE(sub.send_command(cmd(20, OperatorCommandKind::kStopWalking)));
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 20).size() == 1; }));
  r.reset();   // the daemon ends before the loop said anything about it
  ASSERT_TRUE(poll_until(sub, [&] { return acks_of(got, 20).size() == 2; }));
  EXPECT_EQ(acks_of(got, 20)[1].status, AckStatus::kRejected);
  EXPECT_NE(acks_of(got, 20)[1].reason.find("stopped before"), std::string::npos);
}

TEST(Ros2Conventions, EventSeqCountsEachEventTopicWithoutGaps) {
  DomainLease lease;
  telemetry::DdsTelemetry tel(robot_config(lease.id(), "ev"));
  const telemetry::SyntheticRobot robot(3, 100.0);
  for (std::uint64_t k = 0; k < 3; ++k) tel.on_event(robot.fault_event(k, 5));   // seq 5 thrice
  tel.on_event(robot.mode_event(Mode::kReady, Mode::kRunning, 5));
  tel.on_event(robot.mode_event(Mode::kRunning, Mode::kRunning, 5));
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id(), "ev"));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(poll_until(sub, [&] { return got.faults.size() >= 3 && got.modes.size() >= 2; }));
  // The cycle number repeats; event_seq does not.
  std::vector<std::uint64_t> fs, ms;
  for (const auto& f : got.faults) fs.push_back(f.event_seq);
  for (const auto& m : got.modes) ms.push_back(m.event_seq);
  std::vector<std::uint64_t> want_f{1, 2, 3};
  // A fault whose mode changes is on both topics; robot.fault_event may change the mode.
  ASSERT_GE(ms.size(), 2u);
  for (std::size_t i = 0; i < ms.size(); ++i) EXPECT_EQ(ms[i], i + 1);
  EXPECT_EQ(fs, want_f);
}

// ---- Domain and discovery ---------------------------------------------------------------------

TEST(Ros2Conventions, DomainAndDiscoveryFollowCliThenFileThenRosEnvironment) {
  std::map<std::string, std::string> env;
  const auto getenv = [&env](const char* k) -> const char* {
    const auto it = env.find(k);
    return it == env.end() ? nullptr : it->second.c_str();
  };
  telemetry::DomainRequest req;
  auto c = telemetry::resolve_domain(req, getenv);
  EXPECT_EQ(c.domain.domain_id, 0u);
  EXPECT_EQ(c.domain_source, "default");
  EXPECT_EQ(c.domain.interface, "") << "default: Cyclone's own choice, as a default ROS 2 node";

  env["ROS_DOMAIN_ID"] = "42";
  env["CYCLONEDDS_URI"] = "file:///etc/cyclone.xml";
  c = telemetry::resolve_domain(req, getenv);
  EXPECT_EQ(c.domain.domain_id, 42u);
  EXPECT_EQ(c.domain_source, "ROS_DOMAIN_ID=42");
  EXPECT_EQ(c.domain.interface, "");
  EXPECT_EQ(c.discovery_source, "CYCLONEDDS_URI=file:///etc/cyclone.xml");
  EXPECT_EQ(telemetry::cyclone_config_xml(c.domain, "file:///etc/cyclone.xml"),
            "file:///etc/cyclone.xml");

  const std::uint32_t file_domain = 7, cli_domain = 9;
  const std::string eth = "eth0";
  req.config_domain = &file_domain;
  req.config_interface = &eth;
  c = telemetry::resolve_domain(req, getenv);
  EXPECT_EQ(c.domain.domain_id, 7u);
  EXPECT_EQ(c.domain_source, "config");
  EXPECT_EQ(c.domain.interface, "eth0");
  req.cli_domain = &cli_domain;
  EXPECT_EQ(telemetry::resolve_domain(req, getenv).domain.domain_id, 9u);
  EXPECT_EQ(telemetry::resolve_domain(req, getenv).domain_source, "--domain");

  telemetry::DomainRequest lo;
  lo.config_localhost_only = true;
  EXPECT_EQ(telemetry::resolve_domain(lo, getenv).domain.interface, "lo");
  env.erase("CYCLONEDDS_URI");
  env["ROS_LOCALHOST_ONLY"] = "1";
  EXPECT_EQ(telemetry::resolve_domain(telemetry::DomainRequest{}, getenv).domain.interface, "lo");

  env["ROS_DOMAIN_ID"] = "300";
  try {
    telemetry::resolve_domain(telemetry::DomainRequest{}, getenv);
    ADD_FAILURE() << "ROS_DOMAIN_ID=300 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("ROS_DOMAIN_ID = \"300\": expected an integer 0..232"),
              std::string::npos) << e.what();
  }
  // Cyclone's choice plus peers: the URI, then a fragment with the peers.
  telemetry::DomainConfig d;
  d.interface = "";
  d.peers = {"10.0.0.2"};
  EXPECT_EQ(telemetry::cyclone_config_xml(d, nullptr),
            "<CycloneDDS><Domain Id=\"any\"><Discovery><Peers><Peer address=\"10.0.0.2\"/>"
            "</Peers></Discovery></Domain></CycloneDDS>");
}

TEST(Ros2Conventions, NamespacesAreValidatedAndDerivedFromTheName) {
  EXPECT_EQ(telemetry::ros_namespace_for("serial-robot"), "/serial_robot");
  EXPECT_EQ(telemetry::ros_namespace_for("3d"), "/_3d");
  EXPECT_NO_THROW(telemetry::validate_ros_namespace("ns", "/lab/snake_1"));
  for (const char* bad : {"snake", "/a//b", "/a/", "/1a", "/a-b", "/"}) {
    EXPECT_THROW(telemetry::validate_ros_namespace("ns", bad), std::invalid_argument) << bad;
  }
  EXPECT_EQ(telemetry::frame_prefix("/lab/snake"), "lab/snake/");
  EXPECT_EQ(telemetry::frame_prefix(""), "");
}

// A non-loopback interface that is up and multicast-capable: what Cyclone's default picks.
bool have_multicast_interface() {
  ifaddrs* list = nullptr;
  if (getifaddrs(&list) != 0) return false;
  bool found = false;
  for (ifaddrs* a = list; a != nullptr; a = a->ifa_next) {
    const unsigned f = a->ifa_flags;
    if ((f & IFF_UP) && (f & IFF_MULTICAST) && !(f & IFF_LOOPBACK) && a->ifa_addr != nullptr &&
        a->ifa_addr->sa_family == AF_INET)
      found = true;
  }
  freeifaddrs(list);
  return found;
}

// The robot in another process with Cyclone's default configuration (as a ROS 2 node starts
// without CYCLONEDDS_URI); this process subscribes with the default configuration too.
TEST(Ros2Conventions, DefaultCycloneParticipantsDiscoverEachOtherAcrossProcesses) {
  if (!have_multicast_interface())
    GTEST_SKIP() << "*** SKIPPED: no non-loopback multicast interface up: Cyclone's default "
                    "discovery has nothing to run on here ***";
  if (std::getenv("CYCLONEDDS_URI") != nullptr)
    GTEST_SKIP() << "*** SKIPPED: CYCLONEDDS_URI is set; this test needs Cyclone's defaults ***";
  DomainLease lease;
  Child peer({peer_path(), "publish", "--domain", std::to_string(lease.id()), "--interface",
              "default", "--robot", "defaults", "--joints", "4", "--rate", "200", "--cycles",
              "200", "--events", "2", "--wait-reader-s", "20", "--linger-s", "1"});
  auto cfg = monitor_config(lease.id(), "defaults");
  cfg.interface = "";
  telemetry::TelemetrySubscriber sub(cfg);
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(poll_until(sub, [&] {
    return got.descs.size() == 1 && got.faults.size() == 2 && got.joint.size() >= 150;
  }, 30000ms)) << "descs " << got.descs.size() << " faults " << got.faults.size() << " joint "
               << got.joint.size();
  EXPECT_EQ(got.descs[0].ros_namespace, "/defaults");
  EXPECT_EQ(peer.wait(), 0);
}

// CYCLONEDDS_URI is honoured when the configuration names no interface: the robot process gets
// the localhost-only configuration through the variable alone (its own setting: Cyclone's
// choice); this process listens on lo by unicast only. Without the variable the robot would sit
// on the default interface with ephemeral ports, which a lo/unicast listener cannot find.
TEST(Ros2Conventions, CycloneddsUriFromTheEnvironmentIsUsedWhenTheConfigurationGivesNoInterface) {
  DomainLease lease;
  telemetry::DomainConfig lo;
  lo.domain_id = lease.id();
  lo.interface = "lo";
  Child peer({peer_path(), "publish", "--domain", std::to_string(lease.id()), "--interface",
              "default", "--robot", "viaenv", "--joints", "3", "--rate", "200", "--cycles", "100",
              "--events", "1", "--wait-reader-s", "20", "--linger-s", "1"},
             {"CYCLONEDDS_URI=" + telemetry::cyclone_config_xml(lo)});
  auto cfg = monitor_config(lease.id(), "viaenv");
  cfg.interface = "lo";
  telemetry::TelemetrySubscriber sub(cfg);
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(poll_until(sub, [&] { return got.descs.size() == 1 && got.joint.size() >= 50; },
                         30000ms))
      << "descs " << got.descs.size() << " joint " << got.joint.size();
  EXPECT_EQ(peer.wait(), 0);
}

// ---- The monitor's view ------------------------------------------------------------------------

TEST(MonitorRos2, LostEventsAreCountedAndASilentRobotsModeIsLastSeen) {
  telemetry::MonitorState st(1'000'000'000);   // 1 s silence timeout
  telemetry::MessageInfo i{};
  i.recv_ns = 1'000'000'000;
  telemetry::ControllerStateMsg c;
  c.mode = static_cast<std::uint8_t>(Mode::kRunning);
  c.mode_name = "running";
  st.on_controller_state(c, i);
  st.tick(i.recv_ns);
  EXPECT_NE(st.render(i.recv_ns, false).find("mode running"), std::string::npos);

  telemetry::ModeEventMsg m;
  m.from = m.to = static_cast<std::uint8_t>(Mode::kRunning);
  m.event_seq = 1;
  st.on_mode_event(m, i);
  m.event_seq = 2;
  st.on_mode_event(m, i);
  m.event_seq = 5;
  st.on_mode_event(m, i);
  EXPECT_EQ(st.event_gaps(), 2u);
  bool noticed = false;
  for (const auto& n : st.take_new_notices())
    noticed |= n.find("LOST 2 mode event(s) (event_seq 5 after 2)") != std::string::npos;
  EXPECT_TRUE(noticed);
  m.event_seq = 1;   // a restarted robot counts again from 1: not a loss
  st.on_mode_event(m, i);
  EXPECT_EQ(st.event_gaps(), 2u);

  // The robot's last word was SAFE_STOP, then silence: the screen says so as "last seen".
  m.from = static_cast<std::uint8_t>(Mode::kRunning);
  m.to = static_cast<std::uint8_t>(Mode::kSafeStop);
  m.to_name = "safe_stop";
  m.event_seq = 2;
  st.on_mode_event(m, i);
  const std::int64_t later = i.recv_ns + 3'000'000'000;
  st.tick(later);
  const std::string screen = st.render(later, false);
  EXPECT_NE(screen.find("mode (last seen) safe_stop"), std::string::npos) << screen;
  EXPECT_EQ(screen.find("mode running"), std::string::npos) << screen;
}

}  // namespace
}  // namespace pedalwave::test
