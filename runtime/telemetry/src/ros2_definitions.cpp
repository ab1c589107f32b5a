#include "pedalwave/telemetry/ros2_definitions.hpp"

namespace pedalwave::telemetry {

const mcap::MsgLookup& ros2_definitions() {
  static const mcap::MsgMapLookup lookup = [] {
    mcap::MsgMapLookup l;
    for (const auto& [name, text] : ros2_msg_texts()) l.add(name, text);
    return l;
  }();
  return lookup;
}

std::string ros2msg_schema(const std::string& type) {
  return mcap::concatenate_msg_definitions(type, ros2_definitions());
}

}  // namespace pedalwave::telemetry
