// Tick generation and number formatting of the plots (tools/common/src/ticks.cpp).
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "pedalwave/toolkit/ticks.hpp"

namespace tk = pedalwave::toolkit;

namespace {

// Mantissa of a step: 1, 2 or 5 for a nice step.
double mantissa(double step) { return step / std::pow(10.0, std::floor(std::log10(step) + 1e-12)); }

void expect_nice(double lo, double hi, int target) {
  SCOPED_TRACE("range [" + std::to_string(lo) + ", " + std::to_string(hi) + "] target " + std::to_string(target));
  const tk::LinearTicks t = tk::nice_linear_ticks(lo, hi, target);
  if (lo > hi) std::swap(lo, hi);
  ASSERT_GT(t.step, 0.0);
  const double m = mantissa(t.step);
  EXPECT_TRUE(std::abs(m - 1) < 1e-9 || std::abs(m - 2) < 1e-9 || std::abs(m - 5) < 1e-9) << "step " << t.step;
  ASSERT_GE(t.values.size(), static_cast<std::size_t>(target / 2));
  EXPECT_LE(t.values.size(), static_cast<std::size_t>(2 * target + 1));
  for (std::size_t i = 0; i < t.values.size(); ++i) {
    const double v = t.values[i];
    // inside the range (a hair of tolerance), an integer multiple of the step
    EXPECT_GE(v, lo - 1e-9 * t.step);
    EXPECT_LE(v, hi + 1e-9 * t.step);
    EXPECT_NEAR(v / t.step, std::round(v / t.step), 1e-9);
    if (i > 0) {
      EXPECT_NEAR(v - t.values[i - 1], t.step, 1e-9 * t.step);
    }
    EXPECT_FALSE(v == 0.0 && std::signbit(v)) << "-0 tick";
  }
  // nothing nice was left out at either end
  EXPECT_LT(t.values.front() - t.step, lo + 1e-9 * t.step);
  EXPECT_GT(t.values.back() + t.step, hi - 1e-9 * t.step);
}

}  // namespace

TEST(NiceTicks, PropertiesOnManyRanges) {
  expect_nice(0.0, 1.0, 6);
  expect_nice(0.0, 10.0, 6);
  expect_nice(-3.7, 12.2, 6);
  expect_nice(1e-6, 3e-6, 5);
  expect_nice(999.0, 1001.0, 4);
  expect_nice(-1e9, 1e9, 8);
  expect_nice(0.013, 0.0171, 6);
  expect_nice(-0.4, 10.4, 10);
  expect_nice(10.0, 0.0, 6);  // reversed
}

TEST(NiceTicks, KnownRanges) {
  const auto a = tk::nice_linear_ticks(0.0, 10.0, 6);
  EXPECT_EQ(a.step, 2.0);
  EXPECT_EQ(a.values, (std::vector<double>{0, 2, 4, 6, 8, 10}));
  const auto b = tk::nice_linear_ticks(-1.0, 1.0, 5);
  EXPECT_EQ(b.step, 0.5);
  EXPECT_EQ(b.values, (std::vector<double>{-1, -0.5, 0, 0.5, 1}));
  const auto c = tk::nice_linear_ticks(-0.4, 10.4, 6);  // padded data [0, 10]
  EXPECT_EQ(c.values.front(), 0.0);
  EXPECT_EQ(c.values.back(), 10.0);
}

TEST(NiceTicks, DegenerateRangeIsWidened) {
  const auto t = tk::nice_linear_ticks(5.0, 5.0, 5);
  ASSERT_GE(t.values.size(), 2u);
  EXPECT_LT(t.values.front(), 5.0);
  EXPECT_GT(t.values.back(), 5.0);
  const auto z = tk::nice_linear_ticks(0.0, 0.0, 5);
  EXPECT_LT(z.values.front(), 0.0);
  EXPECT_GT(z.values.back(), 0.0);
}

TEST(NiceTicks, RejectsNonFiniteRange) {
  EXPECT_THROW((void)tk::nice_linear_ticks(0.0, INFINITY, 5), std::invalid_argument);
  EXPECT_THROW((void)tk::nice_linear_ticks(NAN, 1.0, 5), std::invalid_argument);
  EXPECT_THROW((void)tk::nice_linear_ticks(0.0, 1.0, 1), std::invalid_argument);
}

TEST(NiceTicks, NiceStep) {
  EXPECT_EQ(tk::nice_step(0.9), 1.0);
  EXPECT_EQ(tk::nice_step(1.9), 2.0);
  EXPECT_EQ(tk::nice_step(3.5), 5.0);
  EXPECT_EQ(tk::nice_step(8.0), 10.0);
  EXPECT_DOUBLE_EQ(tk::nice_step(0.0021), 0.002);
  EXPECT_THROW((void)tk::nice_step(0.0), std::invalid_argument);
}

TEST(LogTicks, MajorsAtDecadesMinorsBetween) {
  const auto t = tk::log_ticks(3e-7, 2e-2);
  EXPECT_EQ(t.stride, 1);
  ASSERT_EQ(t.major.size(), 5u);
  for (std::size_t i = 0; i < t.major.size(); ++i) {
    EXPECT_DOUBLE_EQ(t.major[i], std::pow(10.0, -6 + static_cast<int>(i)));
  }
  // minors: 3..9 × 1e-7, 2..9 × 1e-6 .. 1e-3, 2 × 1e-2 → 7 + 4·8 + 1 = 40
  EXPECT_EQ(t.minor.size(), 40u);
  EXPECT_DOUBLE_EQ(t.minor.front(), 3e-7);
  EXPECT_DOUBLE_EQ(t.minor.back(), 2e-2);
  for (double v : t.minor) {
    EXPECT_GE(v, 3e-7 * (1 - 1e-9));
    EXPECT_LE(v, 2e-2 * (1 + 1e-9));
    const double m = v / std::pow(10.0, std::floor(std::log10(v) + 1e-9));
    EXPECT_NEAR(m, std::round(m), 1e-9);  // integer multiples of the decade
    EXPECT_GT(std::round(m), 1.0);
  }
}

TEST(LogTicks, WideRangeLabelsEveryOtherDecade) {
  const auto t = tk::log_ticks(1e-12, 1.0, 8);  // 13 decades
  EXPECT_EQ(t.stride, 2);
  ASSERT_EQ(t.major.size(), 7u);
  EXPECT_DOUBLE_EQ(t.major.front(), 1e-12);
  EXPECT_DOUBLE_EQ(t.major.back(), 1.0);
  EXPECT_EQ(t.minor.size(), 6u);  // the odd decades
  EXPECT_LE(t.major.size(), 8u);
}

TEST(LogTicks, RejectsNonPositive) {
  EXPECT_THROW((void)tk::log_ticks(0.0, 1.0), std::invalid_argument);
  EXPECT_THROW((void)tk::log_ticks(-1.0, 1.0), std::invalid_argument);
  try {
    (void)tk::log_ticks(-2.5, 1.0);
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("-2.5"), std::string::npos) << e.what();
  }
}

TEST(Format, LinearTickLabels) {
  const std::vector<double> a{0, 0.1, 0.2, 0.30000000000000004};
  EXPECT_EQ(tk::format_linear_ticks(a, 0.1), (std::vector<std::string>{"0", "0.1", "0.2", "0.3"}));
  const std::vector<double> b{-1, -0.5, 0, 0.5, 1};
  EXPECT_EQ(tk::format_linear_ticks(b, 0.5), (std::vector<std::string>{"-1.0", "-0.5", "0", "0.5", "1.0"}));
  const std::vector<double> c{0, 5000, 10000, 15000};
  EXPECT_EQ(tk::format_linear_ticks(c, 5000), (std::vector<std::string>{"0", "5k", "10k", "15k"}));
  const std::vector<double> d{0, 0.0005, 0.001};
  EXPECT_EQ(tk::format_linear_ticks(d, 0.0005), (std::vector<std::string>{"0", "0.5m", "1.0m"}));
  const std::vector<double> e{2e-6, 4e-6, 6e-6};
  EXPECT_EQ(tk::format_linear_ticks(e, 2e-6), (std::vector<std::string>{"2\u00b5", "4\u00b5", "6\u00b5"}));
  const std::vector<double> f{0, 2.5, 5, 7.5};
  EXPECT_EQ(tk::format_linear_ticks(f, 2.5), (std::vector<std::string>{"0", "2.5", "5.0", "7.5"}));
}

TEST(Format, Decades) {
  EXPECT_EQ(tk::format_decade(-3), "10\u207b\u00b3");
  EXPECT_EQ(tk::format_decade(0), "10\u2070");
  EXPECT_EQ(tk::format_decade(12), "10\u00b9\u00b2");
}

TEST(Format, SiPrefixes) {
  EXPECT_EQ(tk::format_si(0.0012, "m"), "1.2 mm");
  EXPECT_EQ(tk::format_si(1500, "Hz"), "1.5 kHz");
  EXPECT_EQ(tk::format_si(999.96, "V"), "1 kV");
  EXPECT_EQ(tk::format_si(0, "s"), "0 s");
  EXPECT_EQ(tk::format_si(-2.5e-6, "s"), "-2.5 \u00b5s");
  EXPECT_EQ(tk::format_si(0.001), "1m");
  EXPECT_EQ(tk::format_si(123456, "", 4), "123.5k");
  EXPECT_EQ(tk::format_si(NAN, "m"), "nan");
}

TEST(Format, Durations) {
  EXPECT_EQ(tk::format_duration(0.35), "350 ms");
  EXPECT_EQ(tk::format_duration(12.34), "12.3 s");
  EXPECT_EQ(tk::format_duration(125.0), "2 min 05 s");
  EXPECT_EQ(tk::format_duration(3720.0), "1 h 02 min");
}
