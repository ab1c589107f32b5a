#include "pedalwave/toolkit/json.hpp"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "pedalwave/toolkit/csv.hpp"  // format_double

namespace pedalwave::toolkit {

namespace {

const char* type_name(Json::Type t) {
  switch (t) {
    case Json::Type::null: return "null";
    case Json::Type::boolean: return "boolean";
    case Json::Type::number: return "number";
    case Json::Type::string: return "string";
    case Json::Type::array: return "array";
    case Json::Type::object: return "object";
  }
  return "?";
}

[[noreturn]] void mismatch(Json::Type want, Json::Type got) {
  throw JsonError(std::string("JSON: expected a ") + type_name(want) + ", found a " + type_name(got));
}

// Recursive-descent reader over the whole text; positions are reported as line:column.
class Reader {
 public:
  Reader(std::string_view text, const std::string& source) : s_(text), source_(source) {}

  Json document() {
    Json v = value(0);
    skip_space();
    if (i_ != s_.size()) fail("end of input after the value");
    return v;
  }

 private:
  static constexpr int kMaxDepth = 512;

  [[noreturn]] void fail(const std::string& expected) const {
    std::size_t line = 1, col = 1;
    for (std::size_t k = 0; k < i_ && k < s_.size(); ++k) {
      if (s_[k] == '\n') {
        ++line;
        col = 1;
      } else {
        ++col;
      }
    }
    std::string found = i_ < s_.size() ? "'" + std::string(1, s_[i_]) + "'" : "end of input";
    throw JsonError(source_ + ":" + std::to_string(line) + ":" + std::to_string(col) + ": expected " +
                    expected + ", found " + found);
  }

  void skip_space() {
    while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\n' || s_[i_] == '\r')) ++i_;
  }

  bool literal(std::string_view word) {
    if (s_.substr(i_, word.size()) != word) return false;
    i_ += word.size();
    return true;
  }

  Json value(int depth) {
    if (depth > kMaxDepth) fail("at most 512 nested arrays/objects");
    skip_space();
    if (i_ >= s_.size()) fail("a value");
    const char c = s_[i_];
    if (c == '{') return object(depth);
    if (c == '[') return array(depth);
    if (c == '"') return Json(string());
    if (literal("true")) return Json(true);
    if (literal("false")) return Json(false);
    if (literal("null")) return Json();
    if (c == '-' || (c >= '0' && c <= '9')) return Json(number());
    fail("a value (object, array, string, number, true, false or null)");
  }

  Json object(int depth) {
    ++i_;  // '{'
    Json o = Json::object();
    skip_space();
    if (i_ < s_.size() && s_[i_] == '}') {
      ++i_;
      return o;
    }
    for (;;) {
      skip_space();
      if (i_ >= s_.size() || s_[i_] != '"') fail("a member name (a string)");
      std::string key = string();
      skip_space();
      if (i_ >= s_.size() || s_[i_] != ':') fail("':' after the member name");
      ++i_;
      o.add(key, value(depth + 1));
      skip_space();
      if (i_ < s_.size() && s_[i_] == ',') {
        ++i_;
        continue;
      }
      if (i_ < s_.size() && s_[i_] == '}') {
        ++i_;
        return o;
      }
      fail("',' or '}' in an object");
    }
  }

  Json array(int depth) {
    ++i_;  // '['
    Json a = Json::array();
    skip_space();
    if (i_ < s_.size() && s_[i_] == ']') {
      ++i_;
      return a;
    }
    for (;;) {
      a.push(value(depth + 1));
      skip_space();
      if (i_ < s_.size() && s_[i_] == ',') {
        ++i_;
        continue;
      }
      if (i_ < s_.size() && s_[i_] == ']') {
        ++i_;
        return a;
      }
      fail("',' or ']' in an array");
    }
  }

  // The JSON number grammar: -?(0|[1-9][0-9]*)(.[0-9]+)?([eE][+-]?[0-9]+)?
  double number() {
    const std::size_t start = i_;
    auto digits = [&] {
      const std::size_t d0 = i_;
      while (i_ < s_.size() && s_[i_] >= '0' && s_[i_] <= '9') ++i_;
      return i_ > d0;
    };
    if (s_[i_] == '-') ++i_;
    if (i_ < s_.size() && s_[i_] == '0') {
      ++i_;
    } else if (!digits()) {
      fail("a digit in a number");
    }
    if (i_ < s_.size() && s_[i_] == '.') {
      ++i_;
      if (!digits()) fail("a digit after the decimal point");
    }
    if (i_ < s_.size() && (s_[i_] == 'e' || s_[i_] == 'E')) {
      ++i_;
      if (i_ < s_.size() && (s_[i_] == '+' || s_[i_] == '-')) ++i_;
      if (!digits()) fail("a digit in the exponent");
    }
    double v = 0.0;
    const auto r = std::from_chars(s_.data() + start, s_.data() + i_, v);
    if (r.ec == std::errc::result_out_of_range) {
      // beyond double's range: saturate to ±inf / underflow to 0 as strtod does (grammar checked)
      v = std::strtod(std::string(s_.substr(start, i_ - start)).c_str(), nullptr);
    } else if (r.ec != std::errc() || r.ptr != s_.data() + i_) {
      i_ = start;
      fail("a number");
    }
    return v;
  }

  unsigned hex4() {
    if (i_ + 4 > s_.size()) fail("four hex digits after \\u");
    unsigned v = 0;
    for (int k = 0; k < 4; ++k, ++i_) {
      const char c = s_[i_];
      v <<= 4;
      if (c >= '0' && c <= '9') v |= static_cast<unsigned>(c - '0');
      else if (c >= 'a' && c <= 'f') v |= static_cast<unsigned>(c - 'a' + 10);
      else if (c >= 'A' && c <= 'F') v |= static_cast<unsigned>(c - 'A' + 10);
      else fail("a hex digit in \\u escape");
    }
    return v;
  }

  static void append_utf8(std::string& out, unsigned cp) {
    if (cp < 0x80) {
      out += static_cast<char>(cp);
    } else if (cp < 0x800) {
      out += static_cast<char>(0xC0 | (cp >> 6));
      out += static_cast<char>(0x80 | (cp & 0x3F));
    } else if (cp < 0x10000) {
      out += static_cast<char>(0xE0 | (cp >> 12));
      out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (cp & 0x3F));
    } else {
      out += static_cast<char>(0xF0 | (cp >> 18));
      out += static_cast<char>(0x80 | ((cp >> 12) & 0x3F));
      out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (cp & 0x3F));
    }
  }

  std::string string() {
    ++i_;  // opening quote
    std::string out;
    for (;;) {
      if (i_ >= s_.size()) fail("'\"' to close the string");
      const char c = s_[i_];
      if (c == '"') {
        ++i_;
        return out;
      }
      if (static_cast<unsigned char>(c) < 0x20) fail("an escaped control character in a string");
      if (c != '\\') {
        out += c;
        ++i_;
        continue;
      }
      ++i_;
      if (i_ >= s_.size()) fail("an escape after '\\'");
      const char e = s_[i_++];
      switch (e) {
        case '"': out += '"'; break;
        case '\\': out += '\\'; break;
        case '/': out += '/'; break;
        case 'b': out += '\b'; break;
        case 'f': out += '\f'; break;
        case 'n': out += '\n'; break;
        case 'r': out += '\r'; break;
        case 't': out += '\t'; break;
        case 'u': {
          unsigned cp = hex4();
          if (cp >= 0xD800 && cp <= 0xDBFF) {  // high surrogate: a low one must follow
            if (!literal("\\u")) fail("a low surrogate \\uDC00…\\uDFFF after a high surrogate");
            const unsigned lo = hex4();
            if (lo < 0xDC00 || lo > 0xDFFF) fail("a low surrogate \\uDC00…\\uDFFF after a high surrogate");
            cp = 0x10000 + ((cp - 0xD800) << 10) + (lo - 0xDC00);
          } else if (cp >= 0xDC00 && cp <= 0xDFFF) {
            fail("a high surrogate before a low surrogate");
          }
          append_utf8(out, cp);
          break;
        }
        default:
          --i_;
          fail("one of \\\" \\\\ \\/ \\b \\f \\n \\r \\t \\u");
      }
    }
  }

  std::string_view s_;
  std::string source_;
  std::size_t i_ = 0;
};

const Json& shared_null() {
  static const Json null;
  return null;
}

}  // namespace

Json Json::parse(std::string_view text, const std::string& source) { return Reader(text, source).document(); }

Json Json::parse_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw JsonError("JSON file '" + path.string() + "': cannot be opened");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse(ss.str(), path.string());
}

bool Json::boolean() const {
  if (type_ != Type::boolean) mismatch(Type::boolean, type_);
  return bool_;
}
double Json::number() const {
  if (type_ != Type::number) mismatch(Type::number, type_);
  return number_;
}
const std::string& Json::string() const {
  if (type_ != Type::string) mismatch(Type::string, type_);
  return string_;
}
const Json::Array& Json::items() const {
  if (type_ != Type::array) mismatch(Type::array, type_);
  return array_;
}
const Json::Object& Json::members() const {
  if (type_ != Type::object) mismatch(Type::object, type_);
  return object_;
}

const Json& Json::operator[](std::string_view key) const {
  if (type_ != Type::object) return shared_null();
  for (auto m = object_.rbegin(); m != object_.rend(); ++m)
    if (m->first == key) return m->second;
  return shared_null();
}

const Json& Json::operator[](std::size_t i) const {
  if (type_ != Type::array || i >= array_.size()) return shared_null();
  return array_[i];
}

bool Json::contains(std::string_view key) const {
  if (type_ != Type::object) return false;
  for (const Member& m : object_)
    if (m.first == key) return true;
  return false;
}

std::size_t Json::size() const {
  return type_ == Type::array ? array_.size() : type_ == Type::object ? object_.size() : 0;
}

Json& Json::set(const std::string& key, Json value) {
  if (type_ == Type::null) type_ = Type::object;
  if (type_ != Type::object) mismatch(Type::object, type_);
  for (Member& m : object_) {
    if (m.first == key) {
      m.second = std::move(value);
      return *this;
    }
  }
  object_.emplace_back(key, std::move(value));
  return *this;
}

Json& Json::add(const std::string& key, Json value) {
  if (type_ == Type::null) type_ = Type::object;
  if (type_ != Type::object) mismatch(Type::object, type_);
  object_.emplace_back(key, std::move(value));
  return *this;
}

Json& Json::push(Json value) {
  if (type_ == Type::null) type_ = Type::array;
  if (type_ != Type::array) mismatch(Type::array, type_);
  array_.push_back(std::move(value));
  return *this;
}

std::string json_quote(std::string_view s) {
  std::string out = "\"";
  for (const char c : s) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      case '\b': out += "\\b"; break;
      case '\f': out += "\\f"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          static const char* hex = "0123456789abcdef";
          out += "\\u00";
          out += hex[(c >> 4) & 0xF];
          out += hex[c & 0xF];
        } else {
          out += c;
        }
    }
  }
  out += '"';
  return out;
}

std::string Json::dump(int indent) const {
  std::string out;
  dump_to(out, indent, 0);
  return out;
}

void Json::dump_to(std::string& out, int indent, int level) const {
  auto newline = [&](int lvl) {
    if (indent < 0) return;
    out += '\n';
    out.append(static_cast<std::size_t>(indent * lvl), ' ');
  };
  switch (type_) {
    case Type::null: out += "null"; break;
    case Type::boolean: out += bool_ ? "true" : "false"; break;
    case Type::number: out += std::isfinite(number_) ? format_double(number_) : "null"; break;
    case Type::string: out += json_quote(string_); break;
    case Type::array: {
      // Arrays of scalars stay on one line (histogram bins, sample rows).
      bool flat = true;
      for (const Json& v : array_) flat = flat && !(v.is_object() || (v.is_array() && v.size() > 8));
      out += '[';
      for (std::size_t k = 0; k < array_.size(); ++k) {
        if (k) out += indent >= 0 && flat ? ", " : ",";
        if (!flat) newline(level + 1);
        array_[k].dump_to(out, indent, level + 1);
      }
      if (!flat && !array_.empty()) newline(level);
      out += ']';
      break;
    }
    case Type::object: {
      out += '{';
      for (std::size_t k = 0; k < object_.size(); ++k) {
        if (k) out += ',';
        newline(level + 1);
        out += json_quote(object_[k].first);
        out += indent >= 0 ? ": " : ":";
        object_[k].second.dump_to(out, indent, level + 1);
      }
      if (!object_.empty()) newline(level);
      out += '}';
      break;
    }
  }
}

}  // namespace pedalwave::toolkit
