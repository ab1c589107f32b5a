// A minimal JSON value, reader and writer for the tools' reports (RFC 8259: objects, arrays,
// strings with escapes incl. \uXXXX and surrogate pairs, numbers, true/false/null).
//
//   const Json r = Json::parse_file("out/soak/report.json");   // throws JsonError naming the file
//   double p99 = r["timing_us"]["wake"]["p99"].number();        // operator[] on a missing key → null
//   Json out = Json::object();  out.set("nproc", 2);  out.dump(2);
//
// Numbers are doubles (integers are exact up to 2^53). Objects keep their members in the order
// they were read or set; a key repeated in the input is kept every time in members() and
// operator[] finds its last value (as most readers do). Offline code: allocation is fine here.
#pragma once

#include <cstddef>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace pedalwave::toolkit {

// Parse and type errors; what() names the source (file or "<text>"), the line and column.
class JsonError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Json {
 public:
  enum class Type { null, boolean, number, string, array, object };
  using Array = std::vector<Json>;
  using Member = std::pair<std::string, Json>;
  using Object = std::vector<Member>;

  Json() = default;  // null
  Json(std::nullptr_t) {}
  Json(bool b) : type_(Type::boolean), bool_(b) {}
  Json(double v) : type_(Type::number), number_(v) {}
  Json(int v) : Json(static_cast<double>(v)) {}
  Json(long v) : Json(static_cast<double>(v)) {}
  Json(long long v) : Json(static_cast<double>(v)) {}
  Json(unsigned v) : Json(static_cast<double>(v)) {}
  Json(unsigned long v) : Json(static_cast<double>(v)) {}
  Json(unsigned long long v) : Json(static_cast<double>(v)) {}
  Json(std::string s) : type_(Type::string), string_(std::move(s)) {}
  Json(const char* s) : Json(std::string(s)) {}
  Json(Array a) : type_(Type::array), array_(std::move(a)) {}

  [[nodiscard]] static Json array() { return Json(Array{}); }
  [[nodiscard]] static Json object() {
    Json j;
    j.type_ = Type::object;
    return j;
  }

  // Throws JsonError "<source>:<line>:<col>: <what was expected>" on malformed input or
  // trailing characters; nesting deeper than 512 levels is refused.
  [[nodiscard]] static Json parse(std::string_view text, const std::string& source = "<text>");
  // Throws JsonError naming the file when it cannot be read or does not parse.
  [[nodiscard]] static Json parse_file(const std::filesystem::path& path);

  [[nodiscard]] Type type() const { return type_; }
  [[nodiscard]] bool is_null() const { return type_ == Type::null; }
  [[nodiscard]] bool is_bool() const { return type_ == Type::boolean; }
  [[nodiscard]] bool is_number() const { return type_ == Type::number; }
  [[nodiscard]] bool is_string() const { return type_ == Type::string; }
  [[nodiscard]] bool is_array() const { return type_ == Type::array; }
  [[nodiscard]] bool is_object() const { return type_ == Type::object; }

  // Typed access; throws JsonError "expected a <type>, found a <type>" on a mismatch.
  [[nodiscard]] bool boolean() const;
  [[nodiscard]] double number() const;
  [[nodiscard]] const std::string& string() const;
  [[nodiscard]] const Array& items() const;
  [[nodiscard]] const Object& members() const;
  // Typed access with a fallback when the value is null (missing) or of another type.
  [[nodiscard]] double number_or(double fallback) const { return is_number() ? number_ : fallback; }
  [[nodiscard]] std::string string_or(std::string fallback) const {
    return is_string() ? string_ : std::move(fallback);
  }

  // Object member (the last one of a repeated key), or a shared null when this is not an object or
  // has no such key.
  [[nodiscard]] const Json& operator[](std::string_view key) const;
  // Array element, or a shared null when this is not an array or i is out of range.
  [[nodiscard]] const Json& operator[](std::size_t i) const;
  [[nodiscard]] bool contains(std::string_view key) const;
  // Number of array elements or object members (0 otherwise).
  [[nodiscard]] std::size_t size() const;

  // Building: set() replaces an existing key (or appends); add() appends even when the key exists
  // (the reader keeps repeated keys so); push() appends to an array. They turn a null into the
  // container; throw JsonError on another type.
  Json& set(const std::string& key, Json value);
  Json& add(const std::string& key, Json value);
  Json& push(Json value);

  // Text: indent < 0 = one line; otherwise newlines and `indent` spaces per level. Numbers are the
  // shortest text that reads back to the same double; non-finite numbers are written as null.
  [[nodiscard]] std::string dump(int indent = -1) const;

 private:
  void dump_to(std::string& out, int indent, int level) const;
  Type type_ = Type::null;
  bool bool_ = false;
  double number_ = 0.0;
  std::string string_;
  Array array_;
  Object object_;
};

// The JSON text of a string: quotes and the escapes \" \\ \n \r \t \b \f \u00XX.
[[nodiscard]] std::string json_quote(std::string_view s);

}  // namespace pedalwave::toolkit
