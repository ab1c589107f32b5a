// The tools' one number formatter (fmt): every number a tool prints, writes into Markdown or
// fills into a report goes through one of these, so "3 significant digits" means the same
// everywhere. NaN and infinities come out as "nan", "inf", "-inf"; a caller that wants "—" or
// "never" for a missing value says so itself.
//
//   sig(0.021834, 3)    = "0.0218"     shortest of `digits` significant digits (printf %.Ng,
//   sig(1234567.0, 3)   = "1.23e+06"    std::ostream with precision(N))
//   fixed(2.1834, 2)    = "2.18"       `decimals` after the point (printf %.Nf)
//   sci(0.00025, 1)     = "2.5e-04"    exponent form, `decimals` after the point (printf %.Ne)
//   num(0.000123, 3)    = "1.23e-04"   Table::num: `significant` digits, exponent form outside
//   num(12.5)           = "12.5"        [1e-3, 1e6)
//   exact(0.1)          = "0.1"        shortest text that reads back to the same double (CSV, JSON)
#pragma once

#include <string>

namespace pedalwave::toolkit {

[[nodiscard]] std::string sig(double v, int digits = 6);
[[nodiscard]] std::string fixed(double v, int decimals);
[[nodiscard]] std::string sci(double v, int decimals);
[[nodiscard]] std::string num(double v, int significant = 4);
[[nodiscard]] std::string exact(double v);

}  // namespace pedalwave::toolkit
