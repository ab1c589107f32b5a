#include "pedalwave/toolkit/ticks.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace pedalwave::toolkit {

namespace {

std::string num_text(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// Removes trailing zeros (and a trailing '.') of a fixed-point text.
std::string trim_zeros(std::string s) {
  if (s.find('.') == std::string::npos) return s;
  while (!s.empty() && s.back() == '0') s.pop_back();
  if (!s.empty() && s.back() == '.') s.pop_back();
  return s;
}

std::string fixed(double v, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", std::max(decimals, 0), v);
  std::string s = buf;
  // "-0", "-0.00" → "0", "0.00"
  if (s[0] == '-' && s.find_first_not_of("-0.") == std::string::npos) s.erase(0, 1);
  return s;
}

struct Prefix {
  int exp3;
  const char* symbol;
};
constexpr std::array<Prefix, 17> kPrefixes{{{-24, "y"},
                                            {-21, "z"},
                                            {-18, "a"},
                                            {-15, "f"},
                                            {-12, "p"},
                                            {-9, "n"},
                                            {-6, "\u00b5"},
                                            {-3, "m"},
                                            {0, ""},
                                            {3, "k"},
                                            {6, "M"},
                                            {9, "G"},
                                            {12, "T"},
                                            {15, "P"},
                                            {18, "E"},
                                            {21, "Z"},
                                            {24, "Y"}}};

// Engineering exponent (multiple of 3) for |v| > 0, clamped to the prefix table.
int eng_exponent(double abs_v) {
  int e = static_cast<int>(std::floor(std::log10(abs_v) / 3.0 + 1e-12)) * 3;
  return std::clamp(e, -24, 24);
}

const char* prefix_symbol(int exp3) {
  for (const auto& p : kPrefixes) {
    if (p.exp3 == exp3) return p.symbol;
  }
  return "";
}

}  // namespace

double nice_step(double x) {
  if (!std::isfinite(x) || x <= 0.0) {
    throw std::invalid_argument("nice_step: step " + num_text(x) +
                                " is not a finite positive number");
  }
  const double e = std::floor(std::log10(x));
  const double base = std::pow(10.0, e);
  const double f = x / base;  // in [1, 10)
  // Nearest of 1, 2, 5, 10 in log distance.
  double best = 1.0;
  double best_d = std::numeric_limits<double>::infinity();
  for (double c : {1.0, 2.0, 5.0, 10.0}) {
    const double d = std::abs(std::log(f / c));
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  return best * base;
}

LinearTicks nice_linear_ticks(double lo, double hi, int target) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) {
    throw std::invalid_argument("nice_linear_ticks: range [" + num_text(lo) + ", " +
                                num_text(hi) + "] is not finite");
  }
  if (target < 2) {
    throw std::invalid_argument("nice_linear_ticks: target " + std::to_string(target) +
                                " ticks, expected at least 2");
  }
  if (lo > hi) std::swap(lo, hi);
  if (hi - lo <= std::abs(hi) * 1e-12 || hi == lo) {
    const double pad = (lo == 0.0) ? 1.0 : std::abs(lo) * 0.1;
    lo -= pad;
    hi += pad;
  }
  // Try the nice steps around span/target and keep the one whose tick count is nearest target.
  const double raw = (hi - lo) / static_cast<double>(target);
  const double base = nice_step(raw);
  LinearTicks best;
  std::size_t best_miss = std::numeric_limits<std::size_t>::max();
  for (double scale : {0.2, 0.5, 1.0, 2.0, 2.5, 5.0}) {
    double step = nice_step(base * scale);
    const double tol = step * 1e-9;
    const double k0 = std::ceil((lo - tol) / step);
    const double k1 = std::floor((hi + tol) / step);
    if (k1 - k0 > 1000.0) continue;
    LinearTicks t;
    t.step = step;
    for (double k = k0; k <= k1; k += 1.0) {
      double v = k * step;
      if (v == 0.0) v = 0.0;  // -0 → 0
      t.values.push_back(v);
    }
    const std::size_t n = t.values.size();
    const auto tgt = static_cast<std::size_t>(target);
    const std::size_t miss = (n > tgt ? n - tgt : tgt - n) * 2 + (n < tgt ? 1 : 0);
    if (n >= 2 && miss < best_miss) {
      best_miss = miss;
      best = std::move(t);
    }
  }
  return best;
}

LogTicks log_ticks(double lo, double hi, int max_major) {
  for (double v : {lo, hi}) {
    if (!std::isfinite(v) || v <= 0.0) {
      throw std::invalid_argument("log_ticks: bound " + num_text(v) +
                                  " is not a finite positive number (a log axis needs > 0)");
    }
  }
  if (max_major < 2) {
    throw std::invalid_argument("log_ticks: max_major " + std::to_string(max_major) +
                                ", expected at least 2");
  }
  if (lo > hi) std::swap(lo, hi);
  const double eps = 1e-9;
  const double llo = std::log10(lo);
  const double lhi = std::log10(hi);
  const int d0 = static_cast<int>(std::ceil(llo - eps));
  const int d1 = static_cast<int>(std::floor(lhi + eps));
  LogTicks t;
  const int n_dec = std::max(d1 - d0 + 1, 0);
  for (int s : {1, 2, 3, 5, 10, 20, 50, 100}) {
    t.stride = s;
    // labelled decades: multiples of s (aligned on 10^0 so labels are stable when panning)
    int count = 0;
    for (int d = d0; d <= d1; ++d) count += (d % s == 0) ? 1 : 0;
    if (count <= max_major || n_dec == 0) break;
  }
  auto inside = [&](double v) {
    const double lv = std::log10(v);
    return lv >= llo - eps && lv <= lhi + eps;
  };
  for (int d = d0 - 1; d <= d1 + 1; ++d) {
    const double dec = std::pow(10.0, d);
    if (t.stride == 1) {
      if (inside(dec)) t.major.push_back(dec);
      for (int m = 2; m <= 9; ++m) {
        const double v = m * dec;
        if (inside(v)) t.minor.push_back(v);
      }
    } else if (inside(dec)) {
      (d % t.stride == 0 ? t.major : t.minor).push_back(dec);
    }
  }
  std::sort(t.minor.begin(), t.minor.end());
  return t;
}

std::vector<std::string> format_linear_ticks(std::span<const double> values, double step) {
  std::vector<std::string> out;
  out.reserve(values.size());
  double max_abs = 0.0;
  for (double v : values) max_abs = std::max(max_abs, std::abs(v));
  const bool plain = max_abs == 0.0 || (max_abs >= 0.01 && max_abs < 1e4);
  int exp3 = 0;
  if (!plain) exp3 = eng_exponent(max_abs);
  const double scale = std::pow(10.0, -exp3);
  const double s = std::abs(step) * scale;
  int decimals = 0;
  if (s > 0.0 && std::isfinite(s)) {
    decimals = std::max(0, -static_cast<int>(std::floor(std::log10(s) + 1e-9)));
    // a step of 2.5 × 10^k needs one digit more than its exponent says
    const double m = s / std::pow(10.0, -decimals);
    if (std::abs(m - std::round(m)) > 1e-6) ++decimals;
  }
  for (double v : values) {
    if (v == 0.0) {
      out.emplace_back("0");
      continue;
    }
    std::string text = fixed(v * scale, decimals);
    if (!plain) text += prefix_symbol(exp3);
    out.push_back(std::move(text));
  }
  return out;
}

std::string format_decade(int d) {
  static constexpr std::array<const char*, 10> kSup{"\u2070", "\u00b9", "\u00b2", "\u00b3",
                                                    "\u2074", "\u2075", "\u2076", "\u2077",
                                                    "\u2078", "\u2079"};
  std::string s = "10";
  if (d < 0) s += "\u207b";  // superscript minus
  const std::string digits = std::to_string(d < 0 ? -d : d);
  for (char c : digits) s += kSup[static_cast<std::size_t>(c - '0')];
  return s;
}

std::string format_si(double value, std::string_view unit, int significant) {
  if (std::isnan(value)) return "nan";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  significant = std::clamp(significant, 1, 17);
  std::string sep = unit.empty() ? "" : " ";
  if (value == 0.0) return "0" + sep + std::string(unit);
  int exp3 = eng_exponent(std::abs(value));
  double scaled = value * std::pow(10.0, -exp3);
  // rounding can carry to 1000 (999.96 → "1000"): move to the next prefix
  auto digits_before = [](double a) {
    return static_cast<int>(std::floor(std::log10(std::abs(a)))) + 1;
  };
  int decimals = std::max(0, significant - digits_before(scaled));
  const double rounded = std::stod(fixed(scaled, decimals));
  if (std::abs(rounded) >= 1000.0 && exp3 < 24) {
    exp3 += 3;
    scaled = value * std::pow(10.0, -exp3);
    decimals = std::max(0, significant - digits_before(scaled));
  }
  return trim_zeros(fixed(scaled, decimals)) + sep + prefix_symbol(exp3) + std::string(unit);
}

std::string format_duration(double seconds) {
  if (!std::isfinite(seconds)) return "--";
  if (seconds < 0.0) seconds = 0.0;
  char buf[64];
  if (seconds < 1.0) {
    std::snprintf(buf, sizeof buf, "%.0f ms", seconds * 1e3);
  } else if (seconds < 60.0) {
    std::snprintf(buf, sizeof buf, "%.1f s", seconds);
  } else if (seconds < 3600.0) {
    const auto total = static_cast<long>(std::lround(seconds));
    std::snprintf(buf, sizeof buf, "%ld min %02ld s", total / 60, total % 60);
  } else {
    const auto total_min = static_cast<long>(std::lround(seconds / 60.0));
    std::snprintf(buf, sizeof buf, "%ld h %02ld min", total_min / 60, total_min % 60);
  }
  return buf;
}

double text_width_px(std::string_view text, double font_px) {
  // DejaVu Sans: digits and most lower case ≈ 0.6 em, upper case ≈ 0.7 em, spaces and narrow
  // punctuation ≈ 0.32 em. Continuation bytes of UTF-8 are not counted.
  double em = 0.0;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if ((c & 0xC0) == 0x80) continue;
    if (c >= 0x80) {
      // superscripts (U+2070..) are narrow; other symbols ≈ 0.62 em
      const bool sup = (c == 0xE2 && i + 1 < text.size() &&
                        static_cast<unsigned char>(text[i + 1]) == 0x81) ||
                       (c == 0xC2 && i + 1 < text.size() &&
                        (static_cast<unsigned char>(text[i + 1]) == 0xB2 ||
                         static_cast<unsigned char>(text[i + 1]) == 0xB3 ||
                         static_cast<unsigned char>(text[i + 1]) == 0xB9));
      em += sup ? 0.40 : 0.62;
    } else if (c == ' ' || c == '.' || c == ',' || c == ':' || c == ';' || c == 'i' ||
               c == 'l' || c == 'j' || c == '|' || c == '\'' || c == '!' || c == '(' ||
               c == ')' || c == '[' || c == ']' || c == 'f' || c == 't' || c == 'I') {
      em += 0.34;
    } else if (c >= 'A' && c <= 'Z') {
      em += 0.70;
    } else if (c == 'm' || c == 'w' || c == 'M' || c == 'W') {
      em += 0.90;
    } else {
      em += 0.60;
    }
  }
  return em * font_px;
}

}  // namespace pedalwave::toolkit
