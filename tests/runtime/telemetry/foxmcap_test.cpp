// The recording and live-view plumbing of the monitor: the subscriber's topic list and raw CDR tap,
// the ros2msg schemas compiled into the library, McapRecorder's and FoxgloveServer's errors, and
// the daemon recorder's file names. (The files and the WebSocket protocol themselves are checked
// with the official npm reader and client: foxmcap/run.sh, ctest pedalwave_telemetry_foxglove_mcap.)
#include <gtest/gtest.h>

#include <map>
#include <thread>

#include "collector.hpp"
#include "dds_test_support.hpp"
#include "pedalwave/mcap/cdr.hpp"
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/foxglove_server.hpp"
#include "pedalwave/telemetry/mcap_recorder.hpp"
#include "pedalwave/telemetry/ros2_definitions.hpp"
#include "pedalwave/telemetry/synthetic.hpp"

namespace pedalwave::test {
namespace {

using namespace std::chrono_literals;

telemetry::SubscriberConfig monitor(std::uint32_t domain) {
  telemetry::SubscriberConfig c;
  c.domain_id = domain;
  c.robot = "snake1";
  c.standard_topics = true;
  c.state_history_depth = 1000;
  return c;
}

TEST(Recording, McapIsChosenByTheExtension) {
  EXPECT_TRUE(telemetry::is_mcap_path("run.mcap"));
  EXPECT_TRUE(telemetry::is_mcap_path("/tmp/RUN.MCAP"));
  EXPECT_FALSE(telemetry::is_mcap_path("run.csv"));
  EXPECT_FALSE(telemetry::is_mcap_path("run"));
  EXPECT_FALSE(telemetry::is_mcap_path(".mcap"));
  EXPECT_FALSE(telemetry::is_mcap_path("run.mcap.csv"));
}

TEST(Recording, TimeInTheDaemonsFileName) {
  EXPECT_EQ(telemetry::expand_time("/var/lib/pedalwave/run-{time}.mcap", 1767225600),
            "/var/lib/pedalwave/run-20260101T000000Z.mcap");
  EXPECT_EQ(telemetry::expand_time("a{time}b{time}.mcap", 86399), "a19700101T235959Zb19700101T235959Z.mcap");
  EXPECT_EQ(telemetry::expand_time("run.mcap", 5), "run.mcap");
}

TEST(Recording, EveryTopicWithItsTypeQosAndSchema) {
  DomainLease lease;
  telemetry::TelemetrySubscriber sub(monitor(lease.id()));
  std::map<std::string, telemetry::TopicInfo> by_name;
  for (const auto& t : sub.topics()) by_name[t.topic] = t;
  ASSERT_EQ(by_name.size(), 14u);
  EXPECT_EQ(by_name.at("/pedalwave/emergency_stop").type, "pedalwave/msg/OperatorCommand");
  const auto& js = by_name.at("/snake1/joint_states");
  EXPECT_EQ(js.type, "sensor_msgs/msg/JointState");
  EXPECT_TRUE(js.reliable);
  EXPECT_FALSE(js.transient_local);
  EXPECT_EQ(js.depth, 10u);
  const auto& own = by_name.at("/snake1/pedalwave/joint_state");
  EXPECT_EQ(own.type, "pedalwave/msg/JointState");
  EXPECT_FALSE(own.reliable);
  EXPECT_EQ(own.depth, 4u);
  const auto& faults = by_name.at("/snake1/pedalwave/fault_event");
  EXPECT_TRUE(faults.reliable && faults.transient_local);
  EXPECT_EQ(faults.depth, 100u);
  const auto& urdf = by_name.at("/snake1/robot_description");
  EXPECT_EQ(urdf.type, "std_msgs/msg/String");
  EXPECT_TRUE(urdf.transient_local);
  EXPECT_EQ(urdf.depth, 1u);
  EXPECT_EQ(by_name.at("/tf").type, "tf2_msgs/msg/TFMessage");
  EXPECT_EQ(by_name.at("/diagnostics").type, "diagnostic_msgs/msg/DiagnosticArray");
  EXPECT_EQ(by_name.at("/pedalwave/command").type, "pedalwave/msg/OperatorCommand");
  for (const auto& [name, t] : by_name) {
    const std::string schema = telemetry::ros2msg_schema(t.type);
    EXPECT_FALSE(schema.empty()) << name;
    if (t.type != "std_msgs/msg/String" && t.type != "pedalwave/msg/RobotDescription" &&
        t.type != "pedalwave/msg/OperatorCommand" && t.type != "tf2_msgs/msg/TFMessage") {
      EXPECT_NE(schema.find("\nMSG: std_msgs/Header\n"), std::string::npos) << name << "\n" << schema;
    }
  }
  const std::string tf = telemetry::ros2msg_schema("tf2_msgs/msg/TFMessage");
  for (const char* dep : {"geometry_msgs/TransformStamped", "std_msgs/Header", "builtin_interfaces/Time",
                          "geometry_msgs/Transform", "geometry_msgs/Vector3", "geometry_msgs/Quaternion"})
    EXPECT_NE(tf.find(std::string("\nMSG: ") + dep + "\n"), std::string::npos) << dep << "\n" << tf;
  EXPECT_THROW((void)telemetry::ros2msg_schema("nope_msgs/msg/Nothing"), std::invalid_argument);
}

// What the raw tap hands over is the serialized sample: the URDF's bytes are exactly CDR of the
// string (+ the padding the encapsulation options announce), and every topic's count equals the
// decoded listeners'.
struct RawCollector : telemetry::RawMessageListener {
  std::map<std::size_t, std::vector<std::vector<std::byte>>> raw;
  void on_raw(std::size_t topic, std::span<const std::byte> cdr, const telemetry::MessageInfo&) override {
    raw[topic].emplace_back(cdr.begin(), cdr.end());
  }
};
struct UrdfCollector : telemetry::TelemetryListener {
  std::vector<std::string> urdf;
  void on_urdf(const std::string& u, const telemetry::MessageInfo&) override { urdf.push_back(u); }
};

TEST(Recording, TheRawTapGivesTheSerializedSamples) {
  DomainLease lease;
  telemetry::TelemetryConfig cfg;
  cfg.domain_id = lease.id();
  cfg.robot_name = "snake1";
  telemetry::DdsTelemetry tel(cfg);
  telemetry::TelemetrySubscriber sub(monitor(lease.id()));
  RawCollector raw;
  UrdfCollector urdf;
  Collector own;
  sub.add_raw_listener(raw);
  sub.add_listener(urdf);
  sub.add_listener(own);
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (tel.joint_state_readers() == 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(5ms);
  ASSERT_GT(tel.joint_state_readers(), 0);
  const telemetry::SyntheticRobot robot(5, 1000.0);
  tel.on_description(robot.description());
  for (std::uint64_t i = 0; i < 20; ++i) tel.on_cycle(robot.sample(i));
  ASSERT_TRUE(poll_until(sub, [&] { return urdf.urdf.size() == 1 && own.joint.size() == 20; }));

  std::size_t urdf_topic = 0, joint_topic = 0;
  for (std::size_t i = 0; i < sub.topics().size(); ++i) {
    if (sub.topics()[i].topic == "/snake1/robot_description") urdf_topic = i;
    if (sub.topics()[i].topic == "/snake1/pedalwave/joint_state") joint_topic = i;
  }
  ASSERT_EQ(raw.raw[urdf_topic].size(), 1u);
  ASSERT_EQ(raw.raw[joint_topic].size(), 20u);
  mcap::CdrWriter cdr;
  cdr.write_string(urdf.urdf[0]);
  const auto& got = raw.raw[urdf_topic][0];
  ASSERT_GE(got.size(), cdr.bytes().size());
  const auto padding = static_cast<std::size_t>(std::to_integer<unsigned>(got[3]) & 3u);
  ASSERT_EQ(got.size(), cdr.bytes().size() + padding);
  EXPECT_EQ(got[0], std::byte{0x00});
  EXPECT_EQ(got[1], std::byte{0x01});  // CDR_LE: plain CDR (XCDR1), little-endian
  EXPECT_TRUE(std::equal(cdr.bytes().begin() + 4, cdr.bytes().end(), got.begin() + 4));
  for (const auto& m : raw.raw[joint_topic]) {
    EXPECT_EQ(m[1], std::byte{0x01});
    EXPECT_GT(m.size(), 4u + 5 * 5 * 4);
  }
}

TEST(Recording, AnUnwritableFileIsNamed) {
  DomainLease lease;
  telemetry::TelemetrySubscriber sub(monitor(lease.id()));
  try {
    telemetry::McapRecorder r("/nonexistent-folder/run.mcap", sub.topics());
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent-folder/run.mcap"), std::string::npos) << e.what();
  }
}

TEST(FoxgloveServer, ListensOnAFreePortAndRefusesOneInUse) {
  DomainLease lease;
  telemetry::TelemetrySubscriber sub(monitor(lease.id()));
  telemetry::FoxgloveServer a(sub.topics(), {.address = "127.0.0.1", .port = 0});
  ASSERT_GT(a.port(), 0);
  EXPECT_EQ(a.clients(), 0);
  try {
    telemetry::FoxgloveServer b(sub.topics(), {.address = "127.0.0.1", .port = a.port()});
    FAIL() << "a second server on port " << a.port();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(a.port()) + ": Address already in use"),
              std::string::npos)
        << e.what();
  }
  try {
    telemetry::FoxgloveServer c(sub.topics(), {.address = "localhost:1", .port = 0});
    FAIL() << "a bad address";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("address \"localhost:1\": expected an IPv4 address"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(telemetry::FoxgloveServer(sub.topics(), {.port = 70000}), std::invalid_argument);
}

}  // namespace
}  // namespace pedalwave::test
