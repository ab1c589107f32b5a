// The ROS 2 message definitions of the telemetry's topics (runtime/telemetry/ros2/<pkg>/msg/*.msg),
// compiled into the library at build time: what the MCAP recorder and the Foxglove WebSocket
// server put in their `ros2msg` schemas, the same texts the wire types are generated from.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "pedalwave/mcap/ros2msg.hpp"

namespace pedalwave::telemetry {

// (full type name "pkg/msg/Type", .msg text) of every message of the interface packages.
const std::vector<std::pair<const char*, const char*>>& ros2_msg_texts();
// The same as a lookup for pedalwave::mcap::concatenate_msg_definitions.
const mcap::MsgLookup& ros2_definitions();
// The ros2msg schema of `type` ("sensor_msgs/msg/JointState"): its .msg text and, after the
// 80-'=' separator lines, every type it depends on. Throws std::invalid_argument for an unknown type.
std::string ros2msg_schema(const std::string& type);

}  // namespace pedalwave::telemetry
