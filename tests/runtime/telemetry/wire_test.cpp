// The bytes on the wire: what DdsTelemetry publishes on <ns>/joint_states, taken as serialized
// data (dds_takecdr), equals sensor_msgs/msg/JointState in plain CDR as rmw_cyclonedds writes it
// (XCDR1: little-endian encapsulation 0x0001, 8-byte primitives aligned to 8 from the payload
// start; no DHEADER, no member ids: final extensibility). The expected bytes are built here from
// the .msg definition and the sample, independently of Cyclone's serializer.
#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>
#include <gtest/gtest.h>

#include <ifaddrs.h>
#include <net/if.h>

#include <cstdlib>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

#include "Telemetry.h"
#include "dds_test_support.hpp"
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/subscriber.hpp"
#include "pedalwave/telemetry/synthetic.hpp"

namespace pedalwave::test {
namespace {

using namespace std::chrono_literals;

// A plain-CDR little-endian writer; `max_align` 8 = XCDR1, 4 = XCDR2 (to show the test tells
// them apart).
struct Cdr {
  explicit Cdr(std::size_t max_align) : max_align_(max_align) {}
  void align(std::size_t n) {
    n = std::min(n, max_align_);
    while (bytes.size() % n != 0) bytes.push_back(0);
  }
  template <typename T>
  void put(T v) {
    align(sizeof(T));
    const auto* p = reinterpret_cast<const unsigned char*>(&v);
    bytes.insert(bytes.end(), p, p + sizeof(T));
  }
  void str(const std::string& s) {
    put<std::uint32_t>(static_cast<std::uint32_t>(s.size() + 1));
    bytes.insert(bytes.end(), s.begin(), s.end());
    bytes.push_back(0);
  }
  void doubles(const double* v, std::size_t n) {
    put<std::uint32_t>(static_cast<std::uint32_t>(n));
    for (std::size_t i = 0; i < n; ++i) put<double>(v[i]);
  }
  std::vector<unsigned char> bytes;
  std::size_t max_align_;
};

// sensor_msgs/msg/JointState: Header header (Time stamp {int32 sec, uint32 nanosec},
// string frame_id), string[] name, float64[] position, velocity, effort.
std::vector<unsigned char> joint_state_cdr(std::size_t max_align, std::int64_t stamp_ns,
                                           const std::string& frame,
                                           const std::vector<std::string>& names,
                                           const std::vector<double>& pos,
                                           const std::vector<double>& vel,
                                           const std::vector<double>& eff) {
  Cdr c(max_align);
  c.put<std::int32_t>(static_cast<std::int32_t>(stamp_ns / 1'000'000'000));
  c.put<std::uint32_t>(static_cast<std::uint32_t>(stamp_ns % 1'000'000'000));
  c.str(frame);
  c.put<std::uint32_t>(static_cast<std::uint32_t>(names.size()));
  for (const auto& n : names) c.str(n);
  c.doubles(pos.data(), pos.size());
  c.doubles(vel.data(), vel.size());
  c.doubles(eff.data(), eff.size());
  return c.bytes;
}

// The e-stop topic (DDS Security can grant it more widely than the command topic): a robot honours
// only emergency_stop there; any other kind written on it, by a plain participant from the IDL
// alone, is REJECTED with that reason and never reaches the runtime.
TEST(Wire, OnlyAnEmergencyStopIsHonouredOnTheEmergencyStopTopic) {
  DomainLease lease;
  telemetry::TelemetryConfig cfg;
  cfg.domain_id = lease.id();
  cfg.robot_name = "estopper";
  std::vector<runtime::OperatorCommand> handled;   // the command thread; read after acks arrive
  std::mutex handled_mutex;
  telemetry::DdsTelemetry tel(cfg, [&](const runtime::OperatorCommand& c) {
    std::lock_guard lock(handled_mutex);
    handled.push_back(c);
    return true;
  });
  struct Acks : telemetry::TelemetryListener {
    std::vector<telemetry::CommandAckMsg> acks;
    void on_command_ack(const telemetry::CommandAckMsg& a, const telemetry::MessageInfo&) override {
      acks.push_back(a);
    }
  } acks;
  telemetry::SubscriberConfig scfg;
  scfg.domain_id = lease.id();
  scfg.robot = "estopper";
  telemetry::TelemetrySubscriber sub(scfg);
  sub.add_listener(acks);

  const dds_entity_t pp = dds_create_participant(lease.id(), nullptr, nullptr);
  ASSERT_GT(pp, 0);
  const dds_entity_t topic = dds_create_topic(pp, &pedalwave_msg_dds__OperatorCommand__desc,
                                              "rt/pedalwave/emergency_stop", nullptr, nullptr);
  ASSERT_GT(topic, 0);
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  const dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
  dds_qset_data_representation(q, 1, &xcdr1);
  const dds_entity_t writer = dds_create_writer(pp, topic, q, nullptr);
  dds_delete_qos(q);
  ASSERT_GT(writer, 0);
  // Matched by the robot's reader (the subscriber reads the topic too: wait for 2).
  dds_publication_matched_status_t st{};
  for (int i = 0; i < 2000 && st.current_count < 2; ++i) {
    dds_get_publication_matched_status(writer, &st);
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_GE(st.current_count, 2u);
  ASSERT_TRUE(sub.wait_for_robot(std::chrono::seconds(10)));

  pedalwave_msg_dds__OperatorCommand_ m{};
  std::strncpy(m.target, "estopper", sizeof m.target - 1);
  std::strncpy(m.sender, "raw", sizeof m.sender - 1);
  m.kind = static_cast<std::uint8_t>(runtime::OperatorCommandKind::kSetGait);
  m.id = 41;
  m.amplitude = 0.5;
  m.omega = 3.0;
  m.eta = 0.7;
  ASSERT_EQ(dds_write(writer, &m), DDS_RETCODE_OK);
  m.kind = static_cast<std::uint8_t>(runtime::OperatorCommandKind::kEmergencyStop);
  m.id = 42;
  ASSERT_EQ(dds_write(writer, &m), DDS_RETCODE_OK);

  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (acks.acks.size() < 2 && std::chrono::steady_clock::now() < deadline) sub.poll(50ms);
  ASSERT_EQ(acks.acks.size(), 2u);
  EXPECT_EQ(acks.acks[0].id, 41u);
  EXPECT_EQ(acks.acks[0].status, telemetry::AckStatus::kRejected);
  EXPECT_EQ(acks.acks[0].reason, "only emergency_stop is honoured on /pedalwave/emergency_stop");
  EXPECT_EQ(acks.acks[1].id, 42u);
  EXPECT_EQ(acks.acks[1].status, telemetry::AckStatus::kQueued) << acks.acks[1].reason;
  std::lock_guard lock(handled_mutex);
  ASSERT_EQ(handled.size(), 1u) << "only the e-stop reached the runtime";
  EXPECT_EQ(handled[0].kind, runtime::OperatorCommandKind::kEmergencyStop);
  EXPECT_EQ(handled[0].id, 42u);
  dds_delete(pp);
}

TEST(Wire, JointStatesArePlainXcdr1AsRmwCycloneddsWritesThem) {
  DomainLease lease;
  telemetry::TelemetryConfig cfg;
  cfg.domain_id = lease.id();
  cfg.robot_name = "abcdef";
  cfg.stamp_clock = telemetry::StampClock::kMonotonic;   // stamp = the sample's t_ns, exactly
  telemetry::DdsTelemetry tel(cfg);

  // A raw reader in the same domain instance, on the topic and type ROS 2 uses.
  const dds_entity_t pp = dds_create_participant(lease.id(), nullptr, nullptr);
  ASSERT_GT(pp, 0);
  const dds_entity_t topic = dds_create_topic(pp, &sensor_msgs_msg_dds__JointState__desc,
                                              "rt/abcdef/joint_states", nullptr, nullptr);
  ASSERT_GT(topic, 0);
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(q, DDS_HISTORY_KEEP_ALL, 0);
  const dds_entity_t reader = dds_create_reader(pp, topic, q, nullptr);
  dds_delete_qos(q);
  ASSERT_GT(reader, 0);
  dds_subscription_matched_status_t st{};
  for (int i = 0; i < 2000 && st.current_count == 0; ++i) {
    dds_get_subscription_matched_status(reader, &st);
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_GT(st.current_count, 0u);

  const telemetry::SyntheticRobot robot(2, 100.0);
  tel.on_description(robot.description());
  const runtime::CycleSample s = robot.sample(3);
  tel.on_cycle(s);

  ddsi_serdata* sd = nullptr;
  dds_sample_info_t info{};
  int got = 0;
  for (int i = 0; i < 2000 && got <= 0; ++i) {
    got = dds_takecdr(reader, &sd, 1, &info, DDS_ANY_STATE);
    if (got <= 0) std::this_thread::sleep_for(5ms);
  }
  ASSERT_EQ(got, 1);
  std::vector<unsigned char> wire(ddsi_serdata_size(sd));
  ddsi_serdata_to_ser(sd, 0, wire.size(), wire.data());
  ddsi_serdata_unref(sd);
  dds_delete(pp);

  ASSERT_GE(wire.size(), 4u);
  // Encapsulation: CDR_LE (0x0001) = XCDR1, options 0.
  EXPECT_EQ(wire[0], 0x00);
  EXPECT_EQ(wire[1], 0x01);
  const std::vector<unsigned char> payload(wire.begin() + 4, wire.end());

  const std::vector<double> pos(s.alpha.begin(), s.alpha.begin() + 2);
  const std::vector<double> vel(s.beta_dot.begin(), s.beta_dot.begin() + 2);   // first sample
  const std::vector<double> eff(s.tau_sea.begin(), s.tau_sea.begin() + 2);
  const auto xcdr1 = joint_state_cdr(8, s.t_ns, "abcdef", {"abcdef/joint_1", "abcdef/joint_2"},
                                     pos, vel, eff);
  const auto xcdr2 = joint_state_cdr(4, s.t_ns, "abcdef", {"abcdef/joint_1", "abcdef/joint_2"},
                                     pos, vel, eff);
  ASSERT_NE(xcdr1, xcdr2) << "the sample must tell the two encodings apart";
  // Cyclone may pad the serialized payload to a multiple of 4.
  ASSERT_GE(payload.size(), xcdr1.size());
  EXPECT_EQ(std::vector<unsigned char>(payload.begin(), payload.begin() + static_cast<long>(xcdr1.size())),
            xcdr1);
  EXPECT_LT(payload.size(), xcdr1.size() + 4);
}

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

// What a ROS 2 node on rmw_cyclonedds does: a participant created with no configuration at all
// (no dds_create_domain: Cyclone's defaults), a reader of sensor_msgs/msg/JointState on
// rt/<ns>/joint_states with ROS's default QoS. The robot is another process with the telemetry's
// default discovery. It is found and its samples decode.
TEST(Wire, APlainDefaultCycloneParticipantReadsTheRobotsJointStates) {
  if (!have_multicast_interface())
    GTEST_SKIP() << "*** SKIPPED: no non-loopback multicast interface up: Cyclone's default "
                    "discovery has nothing to run on here ***";
  if (std::getenv("CYCLONEDDS_URI") != nullptr)
    GTEST_SKIP() << "*** SKIPPED: CYCLONEDDS_URI is set; this test needs Cyclone's defaults ***";
  DomainLease lease;
  Child robot({peer_path(), "publish", "--domain", std::to_string(lease.id()), "--interface",
               "default", "--robot", "plain", "--joints", "3", "--rate", "200", "--cycles", "200",
               "--wait-reader-s", "20", "--linger-s", "1"});
  const dds_entity_t pp = dds_create_participant(lease.id(), nullptr, nullptr);
  ASSERT_GT(pp, 0);
  const dds_entity_t topic = dds_create_topic(pp, &sensor_msgs_msg_dds__JointState__desc,
                                              "rt/plain/joint_states", nullptr, nullptr);
  ASSERT_GT(topic, 0);
  dds_qos_t* q = dds_create_qos();   // ROS 2's default profile: reliable, volatile, keep-last 10
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1000);
  const dds_entity_t reader = dds_create_reader(pp, topic, q, nullptr);
  dds_delete_qos(q);
  ASSERT_GT(reader, 0);
  // The peer starts publishing once something reads its pedalwave joint_state: read that too.
  const dds_entity_t own_topic = dds_create_topic(pp, &pedalwave_msg_dds__JointState__desc,
                                                  "rt/plain/pedalwave/joint_state", nullptr, nullptr);
  ASSERT_GT(own_topic, 0);
  ASSERT_GT(dds_create_reader(pp, own_topic, nullptr, nullptr), 0);
  std::size_t n = 0;
  std::vector<std::string> names;
  for (int i = 0; i < 3000 && n < 150; ++i) {
    void* buf[16] = {};
    dds_sample_info_t info[16];
    const int got = dds_take(reader, buf, info, 16, 16);
    for (int k = 0; k < got; ++k) {
      if (!info[k].valid_data) continue;
      const auto* m = static_cast<const sensor_msgs_msg_dds__JointState_*>(buf[k]);
      ++n;
      if (names.empty())
        for (std::uint32_t j = 0; j < m->name._length; ++j) names.emplace_back(m->name._buffer[j]);
    }
    if (got > 0) dds_return_loan(reader, buf, got);
    else std::this_thread::sleep_for(10ms);
  }
  dds_delete(pp);
  EXPECT_GE(n, 150u) << "a default participant received " << n << " joint_states";
  EXPECT_EQ(names, (std::vector<std::string>{"plain/joint_1", "plain/joint_2", "plain/joint_3"}));
  EXPECT_EQ(robot.wait(), 0);
}

}  // namespace
}  // namespace pedalwave::test
