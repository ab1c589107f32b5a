#include "pedalwave/mcap/ros2_decode.hpp"

#include <algorithm>
#include <stdexcept>

#include "pedalwave/mcap/cdr_reader.hpp"
#include "pedalwave/mcap/ros2msg.hpp"

namespace pedalwave::mcap {
namespace {

std::string_view trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

bool is_primitive(std::string_view t) {
  for (std::string_view p : {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
                             "uint32", "int64", "uint64", "string", "wstring"})
    if (t == p) return true;
  return false;
}

std::size_t parse_count(std::string_view s, const std::string& where) {
  if (s.empty() || s.size() > 9 || !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; }))
    throw std::invalid_argument(where + ": array size '" + std::string(s) + "': expected a number");
  return static_cast<std::size_t>(std::stoul(std::string(s)));
}

constexpr int kMaxDepth = 32;

void decode_into(const std::map<std::string, std::vector<Ros2MsgDecoder::Field>>& types, const std::string& type,
                 const std::string& prefix, CdrReader& cdr, DecodedMessage& out, int depth) {
  if (depth > kMaxDepth) throw std::runtime_error("CDR: messages nested deeper than 32 in " + type);
  for (const Ros2MsgDecoder::Field& f : types.at(type)) {
    const std::string name = prefix.empty() ? f.name : prefix + "." + f.name;
    std::size_t n = 1;
    using Shape = Ros2MsgDecoder::Field::Shape;
    if (f.shape == Shape::fixed) n = f.count;
    if (f.shape == Shape::sequence) {
      std::size_t min_size = 1;
      if (f.primitive && f.type != "string") {
        const std::string& t = f.type;
        min_size = (t == "float64" || t == "int64" || t == "uint64") ? 8
                   : (t == "float32" || t == "int32" || t == "uint32") ? 4
                   : (t == "int16" || t == "uint16") ? 2 : 1;
      } else if (f.type == "string") {
        min_size = 5;
      } else {
        min_size = 1;  // a message is at least one byte (ROS 2 gives an empty one a uint8 member)
      }
      n = cdr.read_sequence_length(name.c_str(), min_size, f.count == 0 ? static_cast<std::size_t>(-1) : f.count);
    }
    if (!f.primitive) {
      for (std::size_t i = 0; i < n; ++i) decode_into(types, f.type, name, cdr, out, depth + 1);
      if (n == 0) out.numbers.try_emplace(name);  // present, empty
      continue;
    }
    if (f.type == "string") {
      auto& v = out.strings[name];
      for (std::size_t i = 0; i < n; ++i) v.push_back(cdr.read_string(name.c_str()));
      continue;
    }
    auto& v = out.numbers[name];
    const char* c = name.c_str();
    for (std::size_t i = 0; i < n; ++i) {
      const std::string& t = f.type;
      double x = 0;
      if (t == "float64") x = cdr.read_f64(c);
      else if (t == "float32") x = cdr.read_f32(c);
      else if (t == "int64") x = static_cast<double>(cdr.read_i64(c));
      else if (t == "uint64") x = static_cast<double>(cdr.read_u64(c));
      else if (t == "int32") x = cdr.read_i32(c);
      else if (t == "uint32") x = cdr.read_u32(c);
      else if (t == "int16") x = cdr.read_i16(c);
      else if (t == "uint16") x = cdr.read_u16(c);
      else if (t == "int8") x = cdr.read_i8(c);
      else if (t == "bool") x = cdr.read_bool(c) ? 1 : 0;
      else x = cdr.read_u8(c);  // uint8, byte, char
      v.push_back(x);
    }
  }
}

}  // namespace

const std::vector<double>& DecodedMessage::at(const std::string& field) const {
  const auto it = numbers.find(field);
  if (it != numbers.end()) return it->second;
  std::string have;
  for (const auto& [k, v] : numbers) have += (have.empty() ? "" : ", ") + k;
  throw std::runtime_error("no numeric field '" + field + "' in the message: expected one of " + have);
}

double DecodedMessage::scalar(const std::string& field) const {
  const auto& v = at(field);
  if (v.size() != 1)
    throw std::runtime_error("field '" + field + "' has " + std::to_string(v.size()) + " values: expected one");
  return v.front();
}

Ros2MsgDecoder::Ros2MsgDecoder(std::string_view type_name, std::string_view text) {
  const MsgTypeName root = parse_msg_type_name(type_name);
  root_ = root.short_form();
  std::string current = root_, package = root.package;
  std::vector<Field>* fields = &types_[current];
  std::size_t line_no = 0, pos = 0;
  bool expect_msg = false;
  while (pos <= text.size()) {
    const auto end = std::min(text.find('\n', pos), text.size());
    const std::string_view raw = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    const std::string where = "ros2msg schema of " + root_ + ", line " + std::to_string(line_no);
    std::string_view line = trim(raw);
    if (line.size() >= 3 && line.find_first_not_of('=') == std::string_view::npos) {
      expect_msg = true;
      continue;
    }
    if (line.empty() || line.front() == '#') continue;
    if (expect_msg) {
      if (line.substr(0, 4) != "MSG:") throw std::invalid_argument(where + " '" + std::string(line) + "': expected 'MSG: pkg/Type' after the '=' line");
      const MsgTypeName t = parse_msg_type_name(trim(line.substr(4)));
      current = t.short_form();
      package = t.package;
      if (types_.count(current) != 0) throw std::invalid_argument(where + ": " + current + " defined twice");
      fields = &types_[current];
      expect_msg = false;
      continue;
    }
    if (const auto hash = line.find('#'); hash != std::string_view::npos) line = trim(line.substr(0, hash));
    const auto space = line.find_first_of(" \t");
    if (space == std::string_view::npos) throw std::invalid_argument(where + " '" + std::string(line) + "': expected '<type> <name>'");
    std::string_view type = line.substr(0, space);
    const std::string_view rest = trim(line.substr(space));
    if (rest.find('=') != std::string_view::npos) continue;  // a constant
    Field f;
    f.name = std::string(rest.substr(0, rest.find_first_of(" \t")));  // a default value may follow
    if (const auto br = type.find('['); br != std::string_view::npos) {
      if (type.back() != ']') throw std::invalid_argument(where + " '" + std::string(line) + "': expected T[], T[N] or T[<=N]");
      const std::string_view inside = type.substr(br + 1, type.size() - br - 2);
      if (inside.empty()) {
        f.shape = Field::Shape::sequence;
      } else if (inside.substr(0, 2) == "<=") {
        f.shape = Field::Shape::sequence;
        f.count = parse_count(inside.substr(2), where);
      } else {
        f.shape = Field::Shape::fixed;
        f.count = parse_count(inside, where);
      }
      type = type.substr(0, br);
    }
    type = type.substr(0, type.find("<="));  // string<=N
    if (type == "wstring") throw std::invalid_argument(where + ": wstring fields are not supported: expected string");
    if (is_primitive(type)) {
      f.type = std::string(type);
    } else {
      f.primitive = false;
      if (type == "Header") f.type = "std_msgs/Header";
      else if (type.find('/') == std::string_view::npos) f.type = package + "/" + std::string(type);
      else f.type = parse_msg_type_name(type).short_form();
    }
    fields->push_back(std::move(f));
  }
  // Every referenced type defined.
  for (const auto& [t, fs] : types_)
    for (const Field& f : fs)
      if (!f.primitive && types_.count(f.type) == 0)
        throw std::invalid_argument("ros2msg schema of " + root_ + ": " + t + "." + f.name + " has type " + f.type +
                                    ": expected its definition ('MSG: " + f.type + "') in the schema");
}

DecodedMessage Ros2MsgDecoder::decode(std::span<const std::byte> cdr) const {
  CdrReader r(cdr);
  DecodedMessage out;
  decode_into(types_, root_, "", r, out, 0);
  return out;
}

}  // namespace pedalwave::mcap
