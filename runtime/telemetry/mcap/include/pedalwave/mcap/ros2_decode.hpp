// Decoding a recorded ROS 2 message by its own schema: the ros2msg schema a file carries (the
// type's .msg text and, after each line of 80 '=', "MSG: pkg/Type" and a dependency's text — what
// concatenate_msg_definitions() writes) compiled into a field list, and the message's CDR (XCDR1 LE)
// read field by field with CdrReader into flat named values:
//
//   "seq"                → {42}                  (a scalar: one value)
//   "beta"               → {β_1, …, β_{N−1}}     (a sequence or fixed array: every element)
//   "header.stamp.sec"   → {…}                   (nested messages: the path joined by '.')
//   "transforms.child_frame_id" (strings)        (an array of messages: its elements' values in order)
//
// Numbers are held as double (bool, byte, char and integers too: exact up to 2^53); strings apart.
// A recording made with an older or newer version of a message decodes by the schema it carries,
// so a reader looks fields up by name, not by position.
#pragma once

#include <cstddef>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace pedalwave::mcap {

struct DecodedMessage {
  std::map<std::string, std::vector<double>> numbers;
  std::map<std::string, std::vector<std::string>> strings;
  // The values of a numeric field; throws std::runtime_error naming the field and the fields present.
  [[nodiscard]] const std::vector<double>& at(const std::string& field) const;
  // Its single value (a scalar field).
  [[nodiscard]] double scalar(const std::string& field) const;
};

class Ros2MsgDecoder {
 public:
  // type_name "pkg/msg/Type" (or "pkg/Type"), schema_text the ros2msg schema. Throws
  // std::invalid_argument naming the type, the line and what was expected (an unknown type, a
  // field line it cannot read, wstring).
  Ros2MsgDecoder(std::string_view type_name, std::string_view schema_text);

  // Throws std::runtime_error ("CDR offset n: …", naming the field) for a message that does not
  // match the schema (cut short, a sequence longer than its bound or than the message).
  [[nodiscard]] DecodedMessage decode(std::span<const std::byte> cdr) const;

  [[nodiscard]] const std::string& type() const noexcept { return root_; }

  struct Field {
    std::string type;      // primitive ("float64", "string") or "pkg/Type"
    bool primitive = true;
    std::string name;
    enum class Shape : unsigned char { scalar, fixed, sequence } shape = Shape::scalar;
    std::size_t count = 0;  // fixed: N; sequence: the bound (0 = unbounded)
  };

 private:
  std::string root_;                                      // "pkg/Type"
  std::map<std::string, std::vector<Field>> types_;       // by "pkg/Type"
};

}  // namespace pedalwave::mcap
