#include "pedalwave/mcap/ros2msg.hpp"

#include <algorithm>
#include <array>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>

namespace pedalwave::mcap {
namespace {

constexpr std::array<std::string_view, 16> kPrimitives = {
    "bool",  "byte",   "char",  "float32", "float64", "int8",   "uint8",  "int16",
    "uint16", "int32", "uint32", "int64",  "uint64",  "string", "wstring", "time"};

bool is_primitive(std::string_view t) {
  // "time"/"duration" are ROS 1 built-ins; ROS 2 spells them builtin_interfaces/Time, but Foxglove's
  // parser accepts them, so they are not dependencies either.
  return t == "duration" || std::find(kPrimitives.begin(), kPrimitives.end(), t) != kPrimitives.end();
}

std::string_view trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

bool valid_identifier(std::string_view s) {
  if (s.empty()) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
  });
}

}  // namespace

MsgTypeName parse_msg_type_name(std::string_view text) {
  MsgTypeName t;
  const auto first = text.find('/');
  const auto last = text.rfind('/');
  if (first != std::string_view::npos) {
    t.package = std::string(text.substr(0, first));
    t.name = std::string(text.substr(last + 1));
    const std::string_view middle = first == last ? std::string_view{} : text.substr(first + 1, last - first - 1);
    if ((first == last || middle == "msg") && valid_identifier(t.package) && valid_identifier(t.name)) return t;
  }
  throw std::invalid_argument("ROS 2 message type '" + std::string(text) +
                              "': expected <package>/msg/<Type> or <package>/<Type>");
}

std::optional<std::string> MsgDirectoryLookup::find(const MsgTypeName& type) const {
  for (const auto& dir : dirs_) {
    const auto file = dir / type.package / "msg" / (type.name + ".msg");
    std::ifstream in(file, std::ios::binary);
    if (!in) continue;
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }
  return std::nullopt;
}

std::string MsgDirectoryLookup::where() const {
  std::string s;
  for (const auto& d : dirs_) s += (s.empty() ? "" : ", ") + (d / "<package>/msg/<Type>.msg").string();
  return s.empty() ? "no directories" : s;
}

MsgMapLookup::MsgMapLookup(std::map<std::string, std::string> by_full_name) {
  for (auto& [k, v] : by_full_name) add(k, std::move(v));
}

void MsgMapLookup::add(std::string_view type, std::string text) {
  texts_[parse_msg_type_name(type).full()] = std::move(text);
}

std::optional<std::string> MsgMapLookup::find(const MsgTypeName& type) const {
  const auto it = texts_.find(type.full());
  if (it == texts_.end()) return std::nullopt;
  return it->second;
}

std::vector<MsgTypeName> msg_dependencies(std::string_view msg_text, std::string_view own_package) {
  std::vector<MsgTypeName> deps;
  std::size_t line_no = 0;
  std::size_t pos = 0;
  while (pos <= msg_text.size()) {
    const auto end = std::min(msg_text.find('\n', pos), msg_text.size());
    const std::string_view raw = msg_text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    // The type is the first word; a comment may follow anywhere after it.
    std::string_view line = trim(raw);
    if (line.empty() || line.front() == '#') continue;
    const auto space = line.find_first_of(" \t");
    if (space == std::string_view::npos)
      throw std::invalid_argument("ROS 2 .msg line " + std::to_string(line_no) + " '" + std::string(line) +
                                  "': expected '<type> <name>'");
    std::string_view type = line.substr(0, space);
    type = type.substr(0, type.find('['));   // arrays: T[], T[N], T[<=N]
    type = type.substr(0, type.find("<="));  // bounded strings: string<=N
    if (is_primitive(type)) continue;
    MsgTypeName dep;
    if (type.find('/') == std::string_view::npos) {
      if (!valid_identifier(type))
        throw std::invalid_argument("ROS 2 .msg line " + std::to_string(line_no) + " '" + std::string(line) +
                                    "': '" + std::string(type) + "' is not a type name");
      dep = {std::string(own_package), std::string(type)};
    } else {
      try {
        dep = parse_msg_type_name(type);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("ROS 2 .msg line " + std::to_string(line_no) + ": " + e.what());
      }
    }
    if (std::find(deps.begin(), deps.end(), dep) == deps.end()) deps.push_back(std::move(dep));
  }
  return deps;
}

std::string concatenate_msg_definitions(std::string_view type, const MsgLookup& lookup) {
  const MsgTypeName top = parse_msg_type_name(type);
  const auto top_text = lookup.find(top);
  if (!top_text)
    throw std::invalid_argument("ROS 2 message type " + top.full() + ": no definition found (looked in " +
                                lookup.where() + ")");
  std::string out = *top_text;
  std::vector<MsgTypeName> done{top};
  // Depth-first over the dependencies, each type once, in order of first use.
  std::function<void(const MsgTypeName&, const std::string&)> visit = [&](const MsgTypeName& of,
                                                                          const std::string& text) {
    std::vector<MsgTypeName> deps;
    try {
      deps = msg_dependencies(text, of.package);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(of.full() + ": " + e.what());
    }
    for (const auto& dep : deps) {
      if (std::find(done.begin(), done.end(), dep) != done.end()) continue;
      done.push_back(dep);
      const auto dep_text = lookup.find(dep);
      if (!dep_text)
        throw std::invalid_argument("ROS 2 message type " + dep.full() + " (used by " + of.full() +
                                    "): no definition found (looked in " + lookup.where() + ")");
      if (!out.empty() && out.back() != '\n') out += '\n';
      out += std::string(80, '=');
      out += "\nMSG: " + dep.short_form() + "\n";
      out += *dep_text;
      visit(dep, *dep_text);
    }
  };
  visit(top, *top_text);
  return out;
}

std::string offered_qos_profiles_yaml(const QosProfile& qos, QosYamlStyle style) {
  std::ostringstream y;
  if (style == QosYamlStyle::names) {
    // rmw's policy names; infinite durations as RMW_DURATION_INFINITE {9223372036 s, 854775807 ns}.
    const char* inf = "\n    sec: 9223372036\n    nsec: 854775807\n";
    y << "- history: keep_last\n"
      << "  depth: " << qos.depth << "\n"
      << "  reliability: " << (qos.reliable ? "reliable" : "best_effort") << "\n"
      << "  durability: " << (qos.transient_local ? "transient_local" : "volatile") << "\n"
      << "  deadline:" << inf << "  lifespan:" << inf << "  liveliness: automatic\n"
      << "  liveliness_lease_duration:" << inf << "  avoid_ros_namespace_conventions: false";
  } else {
    // rmw enums: history 1 = KEEP_LAST; reliability 1 = RELIABLE, 2 = BEST_EFFORT;
    // durability 1 = TRANSIENT_LOCAL, 2 = VOLATILE; liveliness 1 = AUTOMATIC. Infinite durations as
    // Humble writes them.
    const char* inf = "\n    sec: 2147483647\n    nsec: 4294967295\n";
    y << "- history: 1\n"
      << "  depth: " << qos.depth << "\n"
      << "  reliability: " << (qos.reliable ? 1 : 2) << "\n"
      << "  durability: " << (qos.transient_local ? 1 : 2) << "\n"
      << "  deadline:" << inf << "  lifespan:" << inf << "  liveliness: 1\n"
      << "  liveliness_lease_duration:" << inf << "  avoid_ros_namespace_conventions: false";
  }
  return y.str();
}

}  // namespace pedalwave::mcap
