// Reading YAML into parameter structs with errors a person can act on: every failure names the
// file, the line, the full key path, the value found and what was expected, e.g.
//   config/scenes/stair.yaml:12:7: ground.mu = "high": expected a number >= 0
// Unknown keys are errors too (a typo must not silently fall back to a default), and so are
// duplicate keys at any depth (block or flow maps: `{N: 6, N: 40}`), a key written with no value
// (`ground:` alone is not "no ground", `duration:` not the default duration), an empty list
// element (`-` alone), an empty file, and a path that is not a regular file of at most
// kMaxFileBytes (a directory, /dev/zero, a pipe). An empty flow list or map (`faults: []`,
// `ground: {}`) is a value.
#pragma once

#include <functional>
#include <initializer_list>
#include <optional>
#include <stdexcept>
#include <span>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

namespace pedalwave::config {

// The text of a message on one line: control characters (a quoted key or value may hold a
// newline, "durat\n") are written as escapes, \n \r \t \xNN.
std::string one_line(const std::string& text);

// Every configuration error; its message is always one line (one_line).
class ConfigError : public std::runtime_error {
 public:
  explicit ConfigError(const std::string& what) : std::runtime_error(one_line(what)) {}
};

inline constexpr std::size_t kMaxFileBytes = 1u << 20;  // configuration files are small [bytes]

class Reader {
 public:
  // Loads a file (throws ConfigError naming the file on I/O or syntax errors, a file that is not
  // a regular file or is larger than kMaxFileBytes, an empty document, or a duplicate key).
  static Reader load_file(const std::string& path);
  // Parses text (for tests and inline scenes); `name` stands for the file in messages. Empty text
  // is an empty map here (inline scenes may be empty); duplicate keys and empty list elements are
  // errors.
  static Reader parse(const std::string& text, const std::string& name);

  Reader(YAML::Node node, std::string file, std::string path);

  // The key is written, with or without a value: `ground:` alone is given, with none, and every
  // getter of it throws ("ground = "": expected … (the key has no value; remove it for the
  // default)") instead of returning the default.
  bool has(const std::string& key) const;
  bool is_map() const { return node_.IsMap(); }
  bool is_sequence() const { return node_.IsSequence(); }
  bool is_scalar() const { return node_.IsScalar(); }
  std::size_t size() const { return node_.size(); }
  const std::string& path() const { return path_; }
  const std::string& file() const { return file_; }

  Reader operator[](const std::string& key) const;  // child map entry (must exist)
  Reader at(std::size_t i) const;                    // sequence element
  // A key the file must give, with a value: absent → "<path>: expected <expected> (the key is
  // required)"; no value → "<path> = "": expected <expected> (the key has no value; it is
  // required)".
  Reader required(const std::string& key, const std::string& expected) const;

  // Scalars of this node.
  double as_number() const;
  long long as_integer() const;
  bool as_bool() const;
  std::string as_string() const;
  // Typed getters with defaults (absent key → default) and range checks.
  double number(const std::string& key, double def) const;
  double number(const std::string& key) const;  // required
  double positive(const std::string& key, double def) const;
  double non_negative(const std::string& key, double def) const;
  long long integer(const std::string& key, long long def, long long lo, long long hi) const;
  bool boolean(const std::string& key, bool def) const;
  std::string string(const std::string& key, const std::string& def) const;
  // A finite number within [lo, hi] (lo excluded when lo_open), e.g. robot.K in (0, 1e6]; `unit`
  // is shown in the message ("expected a number in (0, 1e+06] [N·m/rad]").
  double bounded(const std::string& key, double def, double lo, double hi, const char* unit,
                 bool lo_open = false) const;
  // The same for a number or a list of numbers (every element checked, by its index).
  std::vector<double> bounded_numbers(const std::string& key, double lo, double hi,
                                      const char* unit, bool lo_open = false) const;
  // One of the given words.
  std::string choice(const std::string& key, const std::string& def,
                     std::initializer_list<const char*> allowed) const;
  // A number or a list of numbers.
  std::vector<double> numbers(const std::string& key) const;

  // Every key of this map must be one of `allowed` (not a map: "expected a map of <path> keys").
  void allow_only(std::initializer_list<const char*> allowed) const;
  void allow_only(std::span<const char* const> allowed) const;

  // Throws ConfigError: "<file>:<line>:<col>: <path> = <value>: expected <expected>"; a key with
  // no value: "<path> = "": expected <expected> (the key has no value; remove it for the
  // default)", at the key's line.
  [[noreturn]] void fail(const std::string& expected) const;
  [[noreturn]] void fail_key(const std::string& key, const std::string& expected) const;

 private:
  // `mark`: where the node stands; a key with no value stands at its key (yaml-cpp marks the
  // empty value at the next token, often on a later line).
  Reader(YAML::Node node, std::string file, std::string path, YAML::Mark mark);
  std::string location() const;
  std::string child_path(const std::string& key) const;
  // fail() with `note` in parentheses after the expectation ("" = none).
  [[noreturn]] void fail_with(const std::string& expected, const std::string& note) const;

  YAML::Node node_;
  std::string file_;
  std::string path_;
  YAML::Mark mark_;
};

}  // namespace pedalwave::config
