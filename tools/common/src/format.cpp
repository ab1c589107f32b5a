#include "pedalwave/toolkit/format.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>

namespace pedalwave::toolkit {

namespace {
// fmt writes "nan"/"inf" like printf; keep one spelling whatever the sign bit of a NaN.
bool special(double v, std::string* out) {
  if (std::isnan(v)) return *out = "nan", true;
  if (std::isinf(v)) return *out = v > 0 ? "inf" : "-inf", true;
  return false;
}
}  // namespace

std::string sig(double v, int digits) {
  std::string s;
  if (special(v, &s)) return s;
  return fmt::format("{:.{}g}", v, std::clamp(digits, 1, 17));
}

std::string fixed(double v, int decimals) {
  std::string s;
  if (special(v, &s)) return s;
  return fmt::format("{:.{}f}", v, std::clamp(decimals, 0, 30));
}

std::string sci(double v, int decimals) {
  std::string s;
  if (special(v, &s)) return s;
  return fmt::format("{:.{}e}", v, std::clamp(decimals, 0, 30));
}

std::string num(double v, int significant) {
  std::string s;
  if (special(v, &s)) return s;
  significant = std::clamp(significant, 1, 17);
  const double a = std::abs(v);
  if (v != 0.0 && (a < 1e-3 || a >= 1e6)) return fmt::format("{:.{}e}", v, significant - 1);
  return fmt::format("{:.{}g}", v, significant);
}

std::string exact(double v) {
  std::string s;
  if (special(v, &s)) return s;
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

}  // namespace pedalwave::toolkit
