// Text tables (tools/common/src/table.cpp): alignment, Unicode widths, Markdown, errors.
#include <gtest/gtest.h>

#include <sstream>
#include <stdexcept>
#include <string>

#include "pedalwave/toolkit/table.hpp"

namespace tk = pedalwave::toolkit;

TEST(Table, TextAlignsNumbersRightAndTextLeft) {
  tk::Table t({"method", "error [m]", "τ [N·m]"});
  t.add_row({"RK4", "2.5e-07", "1.5"});
  t.add_row({"semi-implicit Euler", "0.001", "-12"});
  const std::string expected =
      "method               error [m]  τ [N·m]\n"
      "-------------------  ---------  -------\n"
      "RK4                    2.5e-07      1.5\n"
      "semi-implicit Euler      0.001      -12\n";
  EXPECT_EQ(t.to_text(), expected);
  std::ostringstream os;
  os << t;
  EXPECT_EQ(os.str(), expected);
}

TEST(Table, MarkdownHasAlignmentRowAndEscapesPipes) {
  tk::Table t({"scene", "speed [m/s]"});
  t.add_row({"flat | μ=0.82", "0.031"});
  t.add_row({"stair", "0.02"});
  const std::string md = t.to_markdown();
  const std::string expected =
      "| scene          | speed [m/s] |\n"
      "| -------------- | ----------: |\n"
      "| flat \\| μ=0.82 |       0.031 |\n"
      "| stair          |        0.02 |\n";
  EXPECT_EQ(md, expected);
}

TEST(Table, ExplicitAlignmentAndNumberFormatting) {
  tk::Table t({"a", "b"}, {tk::Align::right, tk::Align::center});
  t.add_row({"x", "y"});
  t.add_row({"long", "wide cell"});
  const std::string s = t.to_text();
  EXPECT_NE(s.find("   x      y"), std::string::npos) << s;
  EXPECT_EQ(tk::Table::num(12.5), "12.5");
  EXPECT_EQ(tk::Table::num(0.000123), "1.230e-04");
  EXPECT_EQ(tk::Table::num(2.0 / 3.0, 3), "0.667");
  EXPECT_EQ(tk::Table::num(1e7, 2), "1.0e+07");
  EXPECT_EQ(tk::Table::num(0.0), "0");
}

TEST(Table, RowSizeMismatchIsAnError) {
  tk::Table t({"a", "b", "c"});
  try {
    t.add_row({"1", "2"});
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("table row 1 has 2 cells but the header names 3 columns"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(tk::Table({}), std::invalid_argument);
  EXPECT_THROW(tk::Table({"a"}, {tk::Align::left, tk::Align::left}), std::invalid_argument);
}
