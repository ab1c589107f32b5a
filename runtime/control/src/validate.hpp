// Internal helpers: configuration checks that throw std::invalid_argument with a message naming
// the parameter, the value and what was expected (STYLE.md §10). Configuration time only.
#pragma once

#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "pedalwave/interface/io.hpp"

namespace pedalwave::control::detail {

inline std::string format_value(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

[[noreturn]] inline void fail(std::string_view name, const std::string& value,
                              std::string_view expected) {
  std::string msg = "control: ";
  msg += name;
  msg += " = ";
  msg += value;
  msg += " (expected ";
  msg += expected;
  msg += ")";
  throw std::invalid_argument(msg);
}

// value must be finite and > 0.
inline void require_positive(std::string_view name, double v, std::string_view unit) {
  if (!(std::isfinite(v) && v > 0.0)) fail(name, format_value(v), std::string("a finite value > 0 ") + std::string(unit));
}
// value must be finite and >= 0.
inline void require_non_negative(std::string_view name, double v, std::string_view unit) {
  if (!(std::isfinite(v) && v >= 0.0)) fail(name, format_value(v), std::string("a finite value >= 0 ") + std::string(unit));
}
// value must be finite.
inline void require_finite(std::string_view name, double v, std::string_view unit) {
  if (!std::isfinite(v)) fail(name, format_value(v), std::string("a finite value ") + std::string(unit));
}

inline void require_joints(int joints) {
  if (joints < 1 || joints > drivers::kMaxJoints) {
    fail("joints", std::to_string(joints),
         "an integer in 1.." + std::to_string(drivers::kMaxJoints) + " (N-1 joints)");
  }
}

// Expands a per-joint parameter given as 1 value (same for all joints) or `joints` values into a
// fixed-size array; throws if the count is wrong.
inline std::array<double, drivers::kMaxJoints> per_joint(std::string_view name,
                                                         const std::vector<double>& values,
                                                         int joints) {
  std::array<double, drivers::kMaxJoints> out{};
  if (values.size() == 1) {
    for (int j = 0; j < joints; ++j) out[static_cast<std::size_t>(j)] = values[0];
  } else if (values.size() == static_cast<std::size_t>(joints)) {
    for (int j = 0; j < joints; ++j) out[static_cast<std::size_t>(j)] = values[static_cast<std::size_t>(j)];
  } else {
    fail(std::string(name) + ".size()", std::to_string(values.size()),
         "1 (same value for every joint) or " + std::to_string(joints) + " (one per joint)");
  }
  return out;
}

inline std::string indexed(std::string_view name, int j) {
  return std::string(name) + "[" + std::to_string(j) + "]";
}

}  // namespace pedalwave::control::detail
