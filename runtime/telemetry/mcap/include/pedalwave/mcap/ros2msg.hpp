// ROS 2 schemas for MCAP: the `ros2msg` schema encoding and the `offered_qos_profiles` channel
// metadata of the ros2 profile (MCAP spec appendix, "Well-known schema encodings" / "profiles").
//
// A ros2msg schema is the type's .msg text followed by the .msg text of every type it depends on
// (directly or through another dependency), each preceded by a line of exactly 80 '=' and a line
// "MSG: <package>/<Type>" — the package resource name without "/msg/", the form ROS 2 .msg fields
// use (`std_msgs/Header header`) and the form rosbag2 and Foxglove's parser resolve.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pedalwave::mcap {

// A ROS 2 message type name, "pkg/msg/Type" (also accepted: "pkg/Type").
struct MsgTypeName {
  std::string package;  // "sensor_msgs"
  std::string name;     // "JointState"
  [[nodiscard]] std::string full() const { return package + "/msg/" + name; }   // "sensor_msgs/msg/JointState"
  [[nodiscard]] std::string short_form() const { return package + "/" + name; } // "sensor_msgs/JointState"
  friend bool operator==(const MsgTypeName&, const MsgTypeName&) = default;
};
// Parses "pkg/msg/Type" or "pkg/Type"; throws std::invalid_argument naming the text otherwise.
[[nodiscard]] MsgTypeName parse_msg_type_name(std::string_view text);

// Finds the .msg text of a type; nullopt when it does not know it. where() says where it looked
// (for error messages).
class MsgLookup {
 public:
  virtual ~MsgLookup() = default;
  [[nodiscard]] virtual std::optional<std::string> find(const MsgTypeName& type) const = 0;
  [[nodiscard]] virtual std::string where() const = 0;
};

// Looks for <dir>/<package>/msg/<Type>.msg in each directory in turn (the layout of a ROS 2
// install's share/ folder and of a source tree of interface packages).
class MsgDirectoryLookup final : public MsgLookup {
 public:
  explicit MsgDirectoryLookup(std::vector<std::filesystem::path> dirs) : dirs_(std::move(dirs)) {}
  [[nodiscard]] std::optional<std::string> find(const MsgTypeName& type) const override;
  [[nodiscard]] std::string where() const override;

 private:
  std::vector<std::filesystem::path> dirs_;
};

// Definitions held in memory, by full name ("std_msgs/msg/String" → "string data\n").
class MsgMapLookup final : public MsgLookup {
 public:
  MsgMapLookup() = default;
  explicit MsgMapLookup(std::map<std::string, std::string> by_full_name);
  void add(std::string_view type, std::string text);
  [[nodiscard]] std::optional<std::string> find(const MsgTypeName& type) const override;
  [[nodiscard]] std::string where() const override { return "the definitions given in memory"; }

 private:
  std::map<std::string, std::string> texts_;  // by full name
};

// The types a .msg text refers to, in order of first use, without duplicates and without the
// primitive types (bool byte char float32 float64 int8…uint64 string wstring). Comments, constants
// (`int32 X=1`), array suffixes ([], [N], [<=N]) and bounded strings (string<=N) are understood;
// an unqualified type name is of `own_package`. Throws std::invalid_argument naming the line for a
// field line it cannot read.
[[nodiscard]] std::vector<MsgTypeName> msg_dependencies(std::string_view msg_text, std::string_view own_package);

// The ros2msg schema of `type`: its text, then each dependency (depth-first, first use first, each
// once) after the 80-'=' line and "MSG: pkg/Type". Throws std::invalid_argument naming the type,
// the type that needs it and where the lookup looked when a definition is missing.
[[nodiscard]] std::string concatenate_msg_definitions(std::string_view type, const MsgLookup& lookup);

// QoS of a recorded topic, as rosbag2 stores it in the channel's offered_qos_profiles metadata.
struct QosProfile {
  bool reliable = true;          // RELIABLE (else BEST_EFFORT)
  bool transient_local = false;  // TRANSIENT_LOCAL durability (latched, e.g. robot_description)
  unsigned depth = 10;           // KEEP_LAST depth
};
// rosbag2 changed how it spells the QoS policies (rosbag2 metadata version 9, ros2/rosbag2#1476):
// ROS 2 Jazzy and later read names ("keep_last", "reliable", …) and, for a file that does not say
// which version wrote it, expect them; Humble and Iron read the rmw enum values as integers.
enum class QosYamlStyle : std::uint8_t {
  names,     // ROS 2 Jazzy, Kilted, Rolling (metadata version >= 9)
  integers,  // ROS 2 Humble, Iron (metadata version <= 8)
};
// A one-entry YAML list in rosbag2's offered_qos_profiles form: history, depth, reliability,
// durability, deadline, lifespan, liveliness, liveliness_lease_duration (infinite durations as the
// distribution writes them), avoid_ros_namespace_conventions.
[[nodiscard]] std::string offered_qos_profiles_yaml(const QosProfile& qos,
                                                    QosYamlStyle style = QosYamlStyle::names);

}  // namespace pedalwave::mcap
