// The ros2msg schema: dependencies read from .msg text, the concatenated form (80 '=' and
// "MSG: pkg/Type" before each dependency, each once, depth-first), lookups and their errors, and the
// offered_qos_profiles metadata.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "pedalwave/mcap/ros2msg.hpp"

namespace fs = std::filesystem;
using namespace pedalwave::mcap;

namespace {

const std::string kSep(80, '=');

TEST(Ros2Msg, TypeNames) {
  EXPECT_EQ(parse_msg_type_name("sensor_msgs/msg/JointState").full(), "sensor_msgs/msg/JointState");
  EXPECT_EQ(parse_msg_type_name("std_msgs/Header").short_form(), "std_msgs/Header");
  EXPECT_EQ(parse_msg_type_name("std_msgs/Header").full(), "std_msgs/msg/Header");
  EXPECT_THROW((void)parse_msg_type_name("JointState"), std::invalid_argument);
  EXPECT_THROW((void)parse_msg_type_name("a/srv/B"), std::invalid_argument);
  EXPECT_THROW((void)parse_msg_type_name("a/msg/"), std::invalid_argument);
}

TEST(Ros2Msg, DependenciesOfAMsgText) {
  const std::string text =
      "# a comment with pkg/Type in it\n"
      "std_msgs/Header header   # trailing comment\n"
      "string[] name\n"
      "float64[3] fixed\n"
      "string<=8 bounded\n"
      "int32 CONSTANT=7\n"
      "geometry_msgs/msg/Point[<=4] points\n"
      "Local local\n"
      "std_msgs/Header again\n"
      "\n"
      "   \n";
  const auto deps = msg_dependencies(text, "my_pkg");
  ASSERT_EQ(deps.size(), 3u);
  EXPECT_EQ(deps[0].full(), "std_msgs/msg/Header");
  EXPECT_EQ(deps[1].full(), "geometry_msgs/msg/Point");
  EXPECT_EQ(deps[2].full(), "my_pkg/msg/Local");
  try {
    (void)msg_dependencies("int32 a\nnonsense\n", "p");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos) << e.what();
  }
}

MsgMapLookup joint_state_lookup() {
  MsgMapLookup l;
  l.add("sensor_msgs/msg/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n");
  l.add("std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id\n");
  l.add("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n");
  return l;
}

TEST(Ros2Msg, ConcatenatedFormWithNestedDependencies) {
  const std::string got = concatenate_msg_definitions("sensor_msgs/msg/JointState", joint_state_lookup());
  const std::string want =
      "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n" +
      kSep + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n" + kSep +
      "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
  EXPECT_EQ(got, want);
  // A type with no dependencies is its own text.
  MsgMapLookup s;
  s.add("std_msgs/String", "string data");
  EXPECT_EQ(concatenate_msg_definitions("std_msgs/msg/String", s), "string data");
}

// A diamond (two fields of types that share a dependency) lists the shared one once; a text
// without a final newline still gets its separator on a line of its own.
TEST(Ros2Msg, SharedDependenciesOnce) {
  MsgMapLookup l;
  l.add("p/msg/Top", "p/A a\np/B b");
  l.add("p/msg/A", "builtin_interfaces/Time t");
  l.add("p/msg/B", "builtin_interfaces/Time t\nA a");
  l.add("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n");
  const std::string got = concatenate_msg_definitions("p/msg/Top", l);
  EXPECT_EQ(got, "p/A a\np/B b\n" + kSep + "\nMSG: p/A\nbuiltin_interfaces/Time t\n" + kSep +
                     "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n" + kSep +
                     "\nMSG: p/B\nbuiltin_interfaces/Time t\nA a");
}

TEST(Ros2Msg, MissingDefinitionNamesTypeUserAndPlace) {
  MsgMapLookup l = joint_state_lookup();
  MsgMapLookup partial;
  partial.add("sensor_msgs/msg/JointState", *l.find(parse_msg_type_name("sensor_msgs/msg/JointState")));
  try {
    (void)concatenate_msg_definitions("sensor_msgs/msg/JointState", partial);
    FAIL();
  } catch (const std::invalid_argument& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("std_msgs/msg/Header"), std::string::npos) << w;
    EXPECT_NE(w.find("used by sensor_msgs/msg/JointState"), std::string::npos) << w;
    EXPECT_NE(w.find("in memory"), std::string::npos) << w;
  }
}

TEST(Ros2Msg, DirectoryLookupReadsPackageLayout) {
  const auto root = fs::temp_directory_path() / ("pedalwave_ros2msg_" + std::to_string(::getpid()));
  const auto first = root / "a", second = root / "b";
  fs::create_directories(first / "std_msgs" / "msg");
  fs::create_directories(second / "std_msgs" / "msg");
  fs::create_directories(second / "builtin_interfaces" / "msg");
  std::ofstream(first / "std_msgs" / "msg" / "Header.msg") << "builtin_interfaces/Time stamp\nstring frame_id\n";
  std::ofstream(second / "std_msgs" / "msg" / "Header.msg") << "shadowed\n";
  std::ofstream(second / "builtin_interfaces" / "msg" / "Time.msg") << "int32 sec\nuint32 nanosec\n";
  const MsgDirectoryLookup lookup({first, second});
  const std::string got = concatenate_msg_definitions("std_msgs/msg/Header", lookup);
  EXPECT_EQ(got, "builtin_interfaces/Time stamp\nstring frame_id\n" + kSep +
                     "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n");
  try {
    (void)concatenate_msg_definitions("std_msgs/msg/Missing", lookup);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find((first / "<package>/msg/<Type>.msg").string()), std::string::npos)
        << e.what();
  }
  fs::remove_all(root);
}

TEST(Ros2Msg, OfferedQosProfilesYamlInBothRosbag2Spellings) {
  // Names (Jazzy and later) by default.
  const std::string latched = offered_qos_profiles_yaml({.reliable = true, .transient_local = true, .depth = 1});
  EXPECT_NE(latched.find("- history: keep_last\n  depth: 1\n  reliability: reliable\n  durability: transient_local\n"),
            std::string::npos)
      << latched;
  EXPECT_NE(latched.find("  liveliness: automatic\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n"
                         "  avoid_ros_namespace_conventions: false"),
            std::string::npos)
      << latched;
  const std::string best = offered_qos_profiles_yaml({.reliable = false, .transient_local = false, .depth = 50});
  EXPECT_NE(best.find("depth: 50\n  reliability: best_effort\n  durability: volatile\n"), std::string::npos) << best;
  // Integers (Humble, Iron).
  const std::string humble =
      offered_qos_profiles_yaml({.reliable = true, .transient_local = true, .depth = 1}, QosYamlStyle::integers);
  EXPECT_NE(humble.find("- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1\n"), std::string::npos) << humble;
  EXPECT_NE(humble.find("liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295"), std::string::npos);
  const std::string humble_best =
      offered_qos_profiles_yaml({.reliable = false, .transient_local = false, .depth = 50}, QosYamlStyle::integers);
  EXPECT_NE(humble_best.find("depth: 50\n  reliability: 2\n  durability: 2\n"), std::string::npos) << humble_best;
}

}  // namespace
