#include "pedalwave/config/yaml_reader.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

namespace pedalwave::config {

std::string one_line(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '\n') out += "\\n";
    else if (c == '\r') out += "\\r";
    else if (c == '\t') out += "\\t";
    else if (u < 0x20 || u == 0x7f) {
      static const char* hex = "0123456789abcdef";
      out += "\\x";
      out += hex[u >> 4];
      out += hex[u & 15];
    } else {
      out += c;
    }
  }
  return out;
}

namespace {

std::string mark_text(const std::string& file, const YAML::Mark& m) {
  std::ostringstream os;
  os << file;
  if (m.line >= 0) os << ":" << m.line + 1 << ":" << m.column + 1;
  return os.str();
}

std::string value_text(const YAML::Node& n) {
  if (n.IsScalar()) return " = \"" + n.Scalar() + "\"";
  if (n.IsSequence()) return " = [list]";
  if (n.IsMap()) return " = {map}";
  return "";
}

// Where an empty element of a block list (`-` alone on its line) stands: yaml-cpp marks it at
// the next token, often lines below; this is the `-` before that mark (else the mark itself).
YAML::Mark dash_before(const std::string& text, const YAML::Mark& m) {
  std::size_t end = std::min(static_cast<std::size_t>(std::max(m.pos, 0)), text.size());
  for (int line = m.line;; --line) {
    const std::size_t nl = end == 0 ? std::string::npos : text.rfind('\n', end - 1);
    const std::size_t begin = nl == std::string::npos ? 0 : nl + 1;
    std::string part = text.substr(begin, end - begin);
    for (std::size_t i = 0; i < part.size(); ++i)  // a comment: `#` first or after a blank
      if (part[i] == '#' && (i == 0 || part[i - 1] == ' ' || part[i - 1] == '\t')) {
        part.resize(i);
        break;
      }
    if (const std::size_t last = part.find_last_not_of(" \t\r"); last != std::string::npos) {
      if (part[last] != '-') return m;
      YAML::Mark dash;
      dash.pos = static_cast<int>(begin + last);
      dash.line = line;
      dash.column = static_cast<int>(last);
      return dash;
    }
    if (nl == std::string::npos) return m;
    end = nl;
  }
}

// Every map of the document, at any depth, has each key once (yaml-cpp keeps both entries and
// node[key] returns the first: a repeated key would silently lose its second value), and every
// list element has a value (`-` alone is no obstacle, no fault, no stiffness).
void check_unique_keys(const YAML::Node& n, const std::string& text, const std::string& file,
                       const std::string& path, int depth) {
  if (depth > 64) {
    throw ConfigError(mark_text(file, n.Mark()) + ": " + (path.empty() ? "(top level)" : path) +
                      ": expected at most 64 levels of nesting");
  }
  if (n.IsMap()) {
    std::map<std::string, YAML::Mark> seen;
    for (const auto& kv : n) {
      const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : "{complex key}";
      const std::string child = path.empty() ? key : path + "." + key;
      const auto [first, fresh] = seen.emplace(key, kv.first.Mark());
      if (!fresh) {
        std::ostringstream os;
        os << mark_text(file, kv.first.Mark()) << ": " << child << value_text(kv.second)
           << ": expected each key once (duplicate key: '" << key << "' is already given at line "
           << first->second.line + 1 << ")";
        throw ConfigError(os.str());
      }
      check_unique_keys(kv.second, text, file, child, depth + 1);
    }
  } else if (n.IsSequence()) {
    for (std::size_t i = 0; i < n.size(); ++i) {
      const std::string child = path + "[" + std::to_string(i) + "]";
      if (n[i].IsNull())
        throw ConfigError(mark_text(file, dash_before(text, n[i].Mark())) + ": " + child +
                          " = \"\": expected a value (the list element is empty: give it one or "
                          "remove the '-')");
      check_unique_keys(n[i], text, file, child, depth + 1);
    }
  }
}

}  // namespace

Reader Reader::load_file(const std::string& path) {
  // Only a regular file of a sane size: a directory opens "fine" and reads nothing (the defaults
  // would run), /dev/zero or a pipe never ends.
  std::error_code ec;
  const auto st = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(st))
    throw ConfigError(path + ": cannot open the file (does it exist? is it readable?)");
  if (std::filesystem::is_directory(st))
    throw ConfigError(path + ": is a directory: expected a YAML file");
  if (!std::filesystem::is_regular_file(st))
    throw ConfigError(path + ": is not a regular file (a device, a pipe or a socket): expected a YAML file");
  const auto bytes = std::filesystem::file_size(path, ec);
  if (ec || bytes > kMaxFileBytes)
    throw ConfigError(path + ": is " + (ec ? std::string("of unknown size") : std::to_string(bytes) + " bytes") +
                      ": expected a YAML file of at most " + std::to_string(kMaxFileBytes) + " bytes");
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open the file (does it exist? is it readable?)");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  Reader r = parse(text, path);  // syntax errors and duplicate keys first
  // An empty file (or only comments, `---`, `~`) would run every default: refused.
  if (const YAML::Node doc = YAML::Load(text); !doc.IsDefined() || doc.IsNull())
    throw ConfigError(path + ":1:1: (top level) = \"\": expected a YAML map of keys (the file is empty)");
  return r;
}

Reader Reader::parse(const std::string& text, const std::string& name) {
  try {
    YAML::Node n = YAML::Load(text);
    if (!n.IsDefined() || n.IsNull()) n = YAML::Node(YAML::NodeType::Map);
    check_unique_keys(n, text, name, "", 0);
    return Reader(n, name, "");
  } catch (const YAML::Exception& e) {
    std::ostringstream os;
    os << name << ":" << e.mark.line + 1 << ":" << e.mark.column + 1 << ": YAML syntax error: " << e.msg;
    throw ConfigError(os.str());
  }
}

Reader::Reader(YAML::Node node, std::string file, std::string path)
    : Reader(node, std::move(file), std::move(path), node.Mark()) {}

Reader::Reader(YAML::Node node, std::string file, std::string path, YAML::Mark mark)
    : node_(std::move(node)), file_(std::move(file)), path_(std::move(path)), mark_(mark) {}

std::string Reader::location() const { return mark_text(file_, mark_); }

std::string Reader::child_path(const std::string& key) const {
  return path_.empty() ? key : path_ + "." + key;
}

bool Reader::has(const std::string& key) const { return node_.IsMap() && node_[key].IsDefined(); }

Reader Reader::operator[](const std::string& key) const {
  if (!node_.IsMap()) fail("a map with key '" + key + "'");
  YAML::Node c = node_[key];
  if (!c.IsDefined()) fail_key(key, "a value (the key is required)");
  YAML::Mark m = c.Mark();
  if (c.IsNull())
    for (const auto& kv : node_)
      if (kv.first.IsScalar() && kv.first.Scalar() == key) m = kv.first.Mark();
  return Reader(c, file_, child_path(key), m);
}

Reader Reader::required(const std::string& key, const std::string& expected) const {
  if (!has(key)) fail_key(key, expected + " (the key is required)");
  const Reader c = (*this)[key];
  if (c.node_.IsNull()) c.fail_with(expected, "the key has no value; it is required");
  return c;
}

Reader Reader::at(std::size_t i) const {
  if (!node_.IsSequence() || i >= node_.size()) fail("a list with an element " + std::to_string(i));
  return Reader(node_[i], file_, path_ + "[" + std::to_string(i) + "]");
}

void Reader::fail(const std::string& expected) const {
  fail_with(expected, node_.IsNull() ? "the key has no value; remove it for the default" : "");
}

void Reader::fail_with(const std::string& expected, const std::string& note) const {
  std::ostringstream os;
  os << location() << ": " << (path_.empty() ? "(top level)" : path_);
  if (node_.IsNull())
    os << " = \"\"";
  else
    os << value_text(node_);
  os << ": expected " << expected;
  if (!note.empty()) os << " (" << note << ")";
  throw ConfigError(os.str());
}

void Reader::fail_key(const std::string& key, const std::string& expected) const {
  std::ostringstream os;
  os << location() << ": " << child_path(key) << ": expected " << expected;
  throw ConfigError(os.str());
}

double Reader::as_number() const {
  if (!node_.IsScalar()) fail("a number");
  const std::string s = node_.Scalar();
  // Accept plain numbers and the constants pi, -pi, k*pi, pi/k (angles read better that way).
  try {
    std::size_t pos = 0;
    const double v = std::stod(s, &pos);
    if (pos == s.size()) return v;
  } catch (...) {
  }
  auto trim = [](std::string x) {
    x.erase(0, x.find_first_not_of(" \t"));
    x.erase(x.find_last_not_of(" \t") + 1);
    return x;
  };
  std::string t = trim(s);
  double sign = 1.0;
  if (!t.empty() && t[0] == '-') sign = -1.0, t = trim(t.substr(1));
  double factor = 1.0, divisor = 1.0;
  const auto star = t.find('*');
  if (star != std::string::npos) {
    try {
      factor = std::stod(trim(t.substr(0, star)));
    } catch (...) {
      fail("a number (or an expression like pi/4, -2*pi/5)");
    }
    t = trim(t.substr(star + 1));
  }
  const auto slash = t.find('/');
  if (slash != std::string::npos) {
    try {
      divisor = std::stod(trim(t.substr(slash + 1)));
    } catch (...) {
      fail("a number (or an expression like pi/4, -2*pi/5)");
    }
    t = trim(t.substr(0, slash));
  }
  if (t != "pi" || divisor == 0) fail("a number (or an expression like pi/4, -2*pi/5)");
  return sign * factor * M_PI / divisor;
}

long long Reader::as_integer() const {
  const double v = as_number();
  if (v != std::floor(v) || std::abs(v) > 9e15) fail("an integer");
  return static_cast<long long>(v);
}

bool Reader::as_bool() const {
  if (!node_.IsScalar()) fail("true or false");
  const std::string& s = node_.Scalar();
  if (s == "true" || s == "on" || s == "yes") return true;
  if (s == "false" || s == "off" || s == "no") return false;
  fail("true or false");
}

std::string Reader::as_string() const {
  if (!node_.IsScalar()) fail("a string");
  return node_.Scalar();
}

double Reader::number(const std::string& key, double def) const {
  if (!has(key)) return def;
  const double v = (*this)[key].as_number();
  if (!std::isfinite(v)) (*this)[key].fail("a finite number");
  return v;
}

double Reader::number(const std::string& key) const {
  required(key, "a number");
  return number(key, 0.0);
}

double Reader::positive(const std::string& key, double def) const {
  const double v = number(key, def);
  if (has(key) && !(v > 0)) (*this)[key].fail("a number > 0");
  return v;
}

double Reader::non_negative(const std::string& key, double def) const {
  const double v = number(key, def);
  if (has(key) && v < 0) (*this)[key].fail("a number >= 0");
  return v;
}

long long Reader::integer(const std::string& key, long long def, long long lo, long long hi) const {
  if (!has(key)) return def;
  const Reader r = (*this)[key];
  const std::string range = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  if (!r.is_scalar()) r.fail(range);
  const long long v = r.as_integer();
  if (v < lo || v > hi) r.fail(range);
  return v;
}

double Reader::bounded(const std::string& key, double def, double lo, double hi, const char* unit,
                       bool lo_open) const {
  if (!has(key)) return def;
  const Reader r = (*this)[key];
  std::ostringstream os;
  os << "a number in " << (lo_open ? "(" : "[") << lo << ", " << hi << "]";
  if (unit && *unit) os << " [" << unit << "]";
  if (!r.is_scalar()) r.fail(os.str());
  const double v = r.as_number();
  if (!std::isfinite(v) || (lo_open ? !(v > lo) : !(v >= lo)) || !(v <= hi)) r.fail(os.str());
  return v;
}

std::vector<double> Reader::bounded_numbers(const std::string& key, double lo, double hi,
                                            const char* unit, bool lo_open) const {
  std::vector<double> out;
  if (!has(key)) return out;
  const Reader r = (*this)[key];
  std::ostringstream os;
  os << "a number in " << (lo_open ? "(" : "[") << lo << ", " << hi << "]";
  if (unit && *unit) os << " [" << unit << "]";
  auto check = [&](const Reader& e) {
    const double v = e.as_number();
    if (!std::isfinite(v) || (lo_open ? !(v > lo) : !(v >= lo)) || !(v <= hi)) e.fail(os.str());
    return v;
  };
  if (r.is_scalar()) return {check(r)};
  if (!r.is_sequence()) r.fail("a number or a list of numbers");
  for (std::size_t i = 0; i < r.size(); ++i) out.push_back(check(r.at(i)));
  return out;
}

bool Reader::boolean(const std::string& key, bool def) const {
  return has(key) ? (*this)[key].as_bool() : def;
}

std::string Reader::string(const std::string& key, const std::string& def) const {
  return has(key) ? (*this)[key].as_string() : def;
}

std::string Reader::choice(const std::string& key, const std::string& def,
                           std::initializer_list<const char*> allowed) const {
  if (!has(key)) return def;
  const Reader r = (*this)[key];
  std::string list;
  for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
  if (!r.is_scalar()) r.fail("one of " + list);
  const std::string v = r.as_string();
  for (const char* a : allowed)
    if (v == a) return v;
  r.fail("one of " + list);
}

std::vector<double> Reader::numbers(const std::string& key) const {
  std::vector<double> out;
  if (!has(key)) return out;
  const Reader r = (*this)[key];
  if (r.is_scalar()) return {r.as_number()};
  if (!r.is_sequence()) r.fail("a number or a list of numbers");
  for (std::size_t i = 0; i < r.size(); ++i) out.push_back(r.at(i).as_number());
  return out;
}

void Reader::allow_only(std::initializer_list<const char*> allowed) const {
  allow_only(std::span<const char* const>(allowed.begin(), allowed.size()));
}

void Reader::allow_only(std::span<const char* const> allowed) const {
  if (!node_.IsMap()) fail(path_.empty() ? "a map of keys" : "a map of " + path_ + " keys");
  for (const auto& kv : node_) {
    // A key that is not a word (a list or a map as a key, `[a]: 1`) is no key of ours either.
    const std::string k = kv.first.IsScalar() ? kv.first.Scalar() : "{complex key}";
    bool ok = false;
    std::string list;
    for (const char* a : allowed) {
      ok |= k == a;
      list += list.empty() ? "" : ", ";
      list += a;
    }
    if (!ok) {
      std::ostringstream os;
      const YAML::Mark m = kv.first.Mark();
      os << file_ << ":" << m.line + 1 << ":" << m.column + 1 << ": unknown key '" << child_path(k)
         << "': expected one of " << list;
      throw ConfigError(os.str());
    }
  }
}

}  // namespace pedalwave::config
