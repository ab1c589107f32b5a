// Axis tick generation and number formatting for the plots.
//
// Linear axes: "nice" steps 1, 2 or 5 × 10^k, ticks at integer multiples of the step.
// Log10 axes: major ticks at decades 10^d (every `stride`-th decade when the range is wide),
// minor ticks at m × 10^d (m = 2..9) when every decade is labelled, otherwise at the unlabelled
// decades. Labels: plain decimals in [0.01, 10^4), SI prefixes outside (2.5k, 500µ), and 10ⁿ
// (Unicode superscripts) on log axes.
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace pedalwave::toolkit {

struct LinearTicks {
  double step = 0.0;           // distance between ticks, 1, 2 or 5 × 10^k [axis unit]
  std::vector<double> values;  // tick positions inside [lo, hi], ascending [axis unit], (n)
};

// Nice ticks for the closed range [lo, hi] (lo > hi is swapped; lo == hi is widened around the
// value), about `target` of them (the count is within [target/2, 2·target+1]). Values are exact
// multiples k·step computed as k × step (no accumulated error) and -0 is written as 0.
// Throws std::invalid_argument if lo or hi is not finite or target < 2.
[[nodiscard]] LinearTicks nice_linear_ticks(double lo, double hi, int target = 6);

// The 1, 2 or 5 × 10^k value nearest to x > 0 in log distance. Throws std::invalid_argument for x ≤ 0 or non-finite.
[[nodiscard]] double nice_step(double x);

struct LogTicks {
  int stride = 1;              // decades between labelled (major) ticks, ≥ 1
  std::vector<double> major;   // 10^d inside [lo, hi], ascending, (n_major)
  std::vector<double> minor;   // unlabelled ticks inside [lo, hi], ascending, (n_minor)
};

// Ticks of a log10 axis on [lo, hi], 0 < lo ≤ hi, with at most max_major labelled decades
// (the stride grows 1, 2, 3, 5, 10, ... decades until they fit). Throws std::invalid_argument
// naming the value when lo or hi is not a finite positive number, or max_major < 2.
[[nodiscard]] LogTicks log_ticks(double lo, double hi, int max_major = 8);

// Labels for linear ticks `values` spaced by `step`, formatted consistently along the axis:
// plain decimals with as many digits as the step needs when every |value| is 0 or in
// [0.01, 10^4); otherwise one SI prefix chosen from the largest |value| (e.g. "1.5k", "250µ").
[[nodiscard]] std::vector<std::string> format_linear_ticks(std::span<const double> values,
                                                           double step);

// "10⁻³" style label of a decade tick 10^d.
[[nodiscard]] std::string format_decade(int d);

// A value with `significant` digits and an SI prefix and unit: format_si(0.0012, "m") = "1.2 mm",
// format_si(1500, "Hz") = "1.5 kHz", format_si(0, "s") = "0 s". Trailing zeros are trimmed.
// Without a unit the prefix is appended directly ("1.2m"). NaN/Inf give "nan", "inf", "-inf".
[[nodiscard]] std::string format_si(double value, std::string_view unit = "", int significant = 3);

// A duration for people: "350 ms", "12.3 s", "2 min 05 s", "1 h 02 min".
[[nodiscard]] std::string format_duration(double seconds);

// Approximate rendered width of UTF-8 text in the plots' sans-serif font [px].
[[nodiscard]] double text_width_px(std::string_view text, double font_px);

}  // namespace pedalwave::toolkit
