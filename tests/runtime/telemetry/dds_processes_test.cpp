// Real Cyclone DDS across processes on loopback (unicast discovery to 127.0.0.1): the test process
// is one side, the test peer (peer_main.cpp) the other. Content and rates, late joiner, robot
// restart (peer killed and started again), writer surviving its reader's death.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>

#include "collector.hpp"
#include "dds_test_support.hpp"
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/monitor_view.hpp"
#include "pedalwave/telemetry/synthetic.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::test {
namespace {

using namespace std::chrono_literals;

telemetry::SubscriberConfig monitor_config(std::uint32_t domain) {
  telemetry::SubscriberConfig c;
  c.domain_id = domain;
  c.state_history_depth = 1000;
  return c;
}

std::vector<std::string> publisher(std::uint32_t domain, int joints, long cycles, int events,
                                   std::uint64_t start_seq = 0, int decimate_timing = 1,
                                   double linger_s = 0.5) {
  return {peer_path(),          "publish",
          "--domain",           std::to_string(domain),
          "--joints",           std::to_string(joints),
          "--rate",             "1000",
          "--cycles",           std::to_string(cycles),
          "--events",           std::to_string(events),
          "--start-seq",        std::to_string(start_seq),
          "--decimate-timing",  std::to_string(decimate_timing),
          "--wait-reader-s",    "10",
          "--linger-s",         std::to_string(linger_s)};
}

// Stated loss bound for best-effort state topics between two processes on loopback at 1 kHz.
constexpr double kMaxLoss = 0.05;

TEST(DdsProcesses, EveryTopicArrivesAcrossProcessesWithinStatedLoss) {
  DomainLease lease;
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  sub.add_listener(got);
  constexpr int kJoints = 6;
  constexpr long kCycles = 2000;  // 2 s at 1 kHz
  Child peer(publisher(lease.id(), kJoints, kCycles, 5, 0, 10));
  // Poll while the peer publishes; it ends with "done ..." after its last cycle.
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  std::atomic<bool> exited{false};
  std::thread waiter([&] {
    peer.wait_for_line("done");
    exited = true;
  });
  while (!exited && std::chrono::steady_clock::now() < deadline) sub.poll(20ms);
  waiter.join();
  for (int i = 0; i < 25; ++i) sub.poll(20ms);  // drain what is in flight
  EXPECT_EQ(peer.wait(), 0);

  const telemetry::SyntheticRobot robot(kJoints, 1000.0);
  const auto at_least = [](std::size_t n, double expected) {
    return static_cast<double>(n) >= (1.0 - kMaxLoss) * expected;
  };
  EXPECT_TRUE(at_least(got.joint.size(), kCycles)) << got.joint.size();
  EXPECT_TRUE(at_least(got.ctrl.size(), kCycles)) << got.ctrl.size();
  EXPECT_TRUE(at_least(got.obs.size(), kCycles)) << got.obs.size();
  EXPECT_TRUE(at_least(got.timing.size(), kCycles / 10.0)) << got.timing.size();
  EXPECT_LE(got.joint.size(), static_cast<std::size_t>(kCycles));
  EXPECT_LE(got.timing.size(), static_cast<std::size_t>(kCycles / 10)) << "decimation ignored";
  for (const auto& m : got.joint) expect_matches(m, robot.sample(m.seq));
  for (const auto& m : got.ctrl) expect_matches(m, robot.sample(m.seq));
  for (const auto& m : got.obs) expect_matches(m, robot.sample(m.seq));
  for (const auto& m : got.timing) {
    EXPECT_EQ(m.seq % 10, 0u);
    expect_matches(m, robot.sample(m.seq));
  }
  // Reliable topics: every event, exactly once, in order.
  ASSERT_EQ(got.faults.size(), 5u);
  for (std::size_t k = 0; k < 5; ++k) expect_matches(got.faults[k], robot.fault_event(k, 0));
  ASSERT_EQ(got.descs.size(), 1u);
  expect_matches(got.descs[0], robot.description());
  // Samples arrive in order from one writer.
  for (std::size_t i = 1; i < got.joint.size(); ++i) EXPECT_LT(got.joint[i - 1].seq, got.joint[i].seq);
}

TEST(DdsProcesses, LateJoinerGetsDescriptionAndLast100FaultsFromAnotherProcess) {
  DomainLease lease;
  // No reader yet: the peer publishes 150 faults into nothing and waits (up to 10 s) for one.
  Child peer(publisher(lease.id(), 4, 100, 150));
  ASSERT_EQ(peer.wait_for_line("events-published"), "events-published");
  std::this_thread::sleep_for(300ms);
  telemetry::TelemetrySubscriber late(monitor_config(lease.id()));
  Collector got;
  late.add_listener(got);
  ASSERT_TRUE(poll_until(late, [&] { return got.faults.size() >= 100 && !got.descs.empty(); }))
      << "faults " << got.faults.size() << " descs " << got.descs.size();
  late.poll(200ms);
  const telemetry::SyntheticRobot robot(4, 1000.0);
  ASSERT_EQ(got.faults.size(), 100u);
  for (std::size_t i = 0; i < 100; ++i) expect_matches(got.faults[i], robot.fault_event(50 + i, 0));
  expect_matches(got.descs.front(), robot.description());
  peer.kill_hard();
}

TEST(DdsProcesses, MonitorSurvivesRobotKilledAndRestarted) {
  DomainLease lease;
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  telemetry::MonitorState monitor(300'000'000);  // silent after 300 ms
  sub.add_listener(got);
  sub.add_listener(monitor);
  const auto now_ns = [] { return pedalwave::monotonic_ns(); };
  const auto pump = [&](std::chrono::milliseconds d) {
    const auto end = std::chrono::steady_clock::now() + d;
    while (std::chrono::steady_clock::now() < end) {
      sub.poll(20ms);
      monitor.tick(now_ns());
    }
  };

  {
    // First life: runs long, killed (SIGKILL: no goodbye on the wire) after ~300 samples.
    Child first(publisher(lease.id(), 6, 60000, 2, 1000));
    ASSERT_TRUE(poll_until(sub, [&] { return got.joint.size() >= 300; }));
    first.kill_hard();
  }
  const std::size_t before = got.joint.size();
  pump(800ms);  // silence
  EXPECT_TRUE(monitor.liveness().silent()) << "monitor did not notice the robot went silent";
  EXPECT_EQ(monitor.liveness().silences(), 1u);

  // Second life: same domain, seq from 0 again.
  Child second(publisher(lease.id(), 6, 1000, 2, 0));
  ASSERT_TRUE(poll_until(sub, [&] {
    monitor.tick(now_ns());
    return got.joint.size() >= before + 500;
  })) << "no samples after the restart";
  EXPECT_FALSE(monitor.liveness().silent()) << "monitor did not notice the robot came back";
  EXPECT_GE(monitor.restarts(), 1u);
  EXPECT_LT(got.joint.back().seq, 1000u) << "samples after restart should be the new run's";
  EXPECT_GE(got.descs.size(), 2u) << "the restarted robot's description was not received";
  bool back = false;
  for (const auto& n : monitor.take_new_notices()) back = back || n.find("back") != std::string::npos;
  EXPECT_TRUE(back);
  second.kill_hard();
}

TEST(DdsProcesses, WriterSurvivesItsReaderDying) {
  DomainLease lease;
  telemetry::TelemetryConfig cfg;
  cfg.domain_id = lease.id();
  telemetry::DdsTelemetry tel(cfg);
  const telemetry::SyntheticRobot robot(24, 1000.0);
  tel.on_description(robot.description());

  Child reader({peer_path(), "subscribe", "--domain", std::to_string(lease.id())});
  ASSERT_EQ(reader.wait_for_line("subscribed"), "subscribed");
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (tel.joint_state_readers() == 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_EQ(tel.joint_state_readers(), 1);
  std::uint64_t seq = 0;
  for (; seq < 300; ++seq) {
    tel.on_cycle(robot.sample(seq));
    std::this_thread::sleep_for(1ms);
  }
  ASSERT_NE(reader.wait_for_line("received"), "") << "the peer reader received nothing";
  reader.kill_hard();  // reader dies without unmatching; its lease runs on for seconds

  // The writer keeps going at full speed: state is best-effort, events reliable but keep-last.
  for (std::uint64_t k = 0; k < 200; ++k) tel.on_event(robot.fault_event(k, seq));
  for (; seq < 3300; ++seq) tel.on_cycle(robot.sample(seq));
  auto st = tel.stats();
  EXPECT_EQ(st.write_errors, 0u);
  EXPECT_EQ(st.joint_state, 3300u);
  EXPECT_EQ(st.fault_events, 200u);

  // And a new monitor still gets everything it should.
  telemetry::TelemetrySubscriber sub(monitor_config(lease.id()));
  Collector got;
  sub.add_listener(got);
  ASSERT_TRUE(poll_until(sub, [&] { return got.faults.size() >= 100 && !got.descs.empty(); }));
  while (sub.joint_state_writers() == 0) sub.poll(10ms);
  std::this_thread::sleep_for(100ms);
  for (std::uint64_t end = seq + 100; seq < end; ++seq) tel.on_cycle(robot.sample(seq));
  ASSERT_TRUE(poll_until(sub, [&] { return !got.joint.empty(); }));
  EXPECT_GE(got.joint.front().seq, 3300u);
  expect_matches(got.joint.front(), robot.sample(got.joint.front().seq));
  expect_matches(got.faults.back(), robot.fault_event(199, 300));
  EXPECT_EQ(tel.stats().write_errors, 0u);
}

}  // namespace
}  // namespace pedalwave::test
