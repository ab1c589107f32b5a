// toolkit/format.hpp: the one number formatter gives what the printf formats it replaced gave
// (%.Ng, %.Nf, Table::num's exponent rule), so the tools' outputs did not change with it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "pedalwave/toolkit/format.hpp"

namespace {

namespace tk = pedalwave::toolkit;

std::string printf_of(const char* f, int p, double v) {
  char b[128];
  std::snprintf(b, sizeof b, f, p, v);
  return b;
}

TEST(Format, SigFixedAndSciAreThePrintfFormats) {
  const std::vector<double> values{0.0,   -0.0,   1.0,     0.1,      0.0218,  -0.0213, 2.5e-4, 1e-4,  123456.0,
                                   1e6,   1.5e7,  -3.25e-3, 10.1,    0.99995, 9.9996,  1e-12,  1e300, 0.125,
                                   2.675, 1.0005, 323.456, 5e-8,     60.0,    151.0,   -7.5,   1e21,  0.5};
  for (double v : values)
    for (int p = 1; p <= 17; ++p) {
      EXPECT_EQ(tk::sig(v, p), printf_of("%.*g", p, v)) << v << " " << p;
      EXPECT_EQ(tk::sci(v, p - 1), printf_of("%.*e", p - 1, v)) << v << " " << p - 1;
      if (std::abs(v) < 1e22) {
        EXPECT_EQ(tk::fixed(v, p - 1), printf_of("%.*f", p - 1, v)) << v << " " << p - 1;
      }
    }
  EXPECT_EQ(tk::sig(0.021834, 3), "0.0218");
  EXPECT_EQ(tk::sig(1234567.0, 3), "1.23e+06");
  EXPECT_EQ(tk::fixed(2.1834, 2), "2.18");
}

TEST(Format, NumUsesTheExponentOutsideAThousandthToAMillion) {
  EXPECT_EQ(tk::num(0.000123, 3), "1.23e-04");
  EXPECT_EQ(tk::num(0.000123), "1.230e-04");
  EXPECT_EQ(tk::num(12.5), "12.5");
  EXPECT_EQ(tk::num(1e6, 3), "1.00e+06");
  EXPECT_EQ(tk::num(0.001, 2), "0.001");
  EXPECT_EQ(tk::num(0.0), "0");
}

TEST(Format, ExactReadsBackAndSpecialValuesHaveOneSpelling) {
  for (double v : {0.1, 1.0 / 3.0, 2.5e-4, -1e300, 2.2250738585072014e-308}) EXPECT_EQ(std::stod(tk::exact(v)), v) << v;
  EXPECT_EQ(tk::exact(0.1), "0.1");
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  for (const std::string& s : {tk::sig(nan, 3), tk::sig(-nan, 3), tk::fixed(nan, 2), tk::num(nan), tk::exact(-nan)})
    EXPECT_EQ(s, "nan");
  EXPECT_EQ(tk::sig(inf, 3), "inf");
  EXPECT_EQ(tk::fixed(-inf, 1), "-inf");
  EXPECT_EQ(tk::num(inf), "inf");
}

}  // namespace
