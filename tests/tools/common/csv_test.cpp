// CSV writer and reader (tools/common/src/csv.cpp): exact round trip, enforced column count,
// errors that name file, line and column.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/toolkit/csv.hpp"

namespace tk = pedalwave::toolkit;

namespace {

std::filesystem::path temp_file(const std::string& name) {
  const auto d = std::filesystem::temp_directory_path() / ("pedalwave_csv_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(d);
  return d / name;
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

std::string error_of(const std::string& text, const std::string& source) {
  try {
    (void)tk::CsvTable::parse(text, source);
  } catch (const tk::CsvError& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace

TEST(Csv, RoundTripIsExact) {
  const auto path = temp_file("roundtrip.csv");
  const std::vector<double> tricky{0.1,
                                   1.0 / 3.0,
                                   -0.0,
                                   1e-300,
                                   std::numeric_limits<double>::denorm_min(),
                                   std::numeric_limits<double>::max(),
                                   -std::numeric_limits<double>::min(),
                                   3.141592653589793,
                                   123456789012345678.0,
                                   std::numeric_limits<double>::infinity(),
                                   -std::numeric_limits<double>::infinity(),
                                   std::numeric_limits<double>::quiet_NaN()};
  {
    tk::CsvWriter w(path, {"value", "index", "square"});
    w.comment("round trip test\nsecond comment line");
    for (std::size_t i = 0; i < tricky.size(); ++i) {
      const double v = tricky[i];
      w.row({v, static_cast<double>(i), v * v});
    }
    // a pseudo-random sweep of ordinary values
    double x = 0.123456789;
    for (int i = 0; i < 2000; ++i) {
      x = std::fmod(x * 7919.0 + 0.1234567, 1.0) * std::pow(10.0, (i % 41) - 20);
      w.row({x, static_cast<double>(tricky.size() + i), -x / 7.0});
    }
    EXPECT_EQ(w.rows_written(), tricky.size() + 2000);
    w.close();
  }
  const auto t = tk::CsvTable::read(path);
  EXPECT_EQ(t.names(), (std::vector<std::string>{"value", "index", "square"}));
  ASSERT_EQ(t.rows(), tricky.size() + 2000);
  EXPECT_EQ(t.comments(), (std::vector<std::string>{"round trip test", "second comment line"}));
  const auto& v = t.column("value");
  for (std::size_t i = 0; i < tricky.size(); ++i) {
    if (std::isnan(tricky[i])) {
      EXPECT_TRUE(std::isnan(v[i]));
    } else {
      EXPECT_TRUE(same_bits(v[i], tricky[i])) << i << ": wrote " << tricky[i] << " read " << v[i];
    }
  }
  // the sweep, rewritten the same way, must read back bit for bit
  double x = 0.123456789;
  for (int i = 0; i < 2000; ++i) {
    x = std::fmod(x * 7919.0 + 0.1234567, 1.0) * std::pow(10.0, (i % 41) - 20);
    const std::size_t r = tricky.size() + static_cast<std::size_t>(i);
    ASSERT_TRUE(same_bits(t.column("value")[r], x)) << "row " << r;
    ASSERT_TRUE(same_bits(t.column(2)[r], -x / 7.0)) << "row " << r;
  }
  EXPECT_EQ(t.column("index")[5], 5.0);
  std::filesystem::remove(path);
}

TEST(Csv, ShortestTextAndHeaderLine) {
  EXPECT_EQ(tk::format_double(0.1), "0.1");
  EXPECT_EQ(tk::format_double(-2.0), "-2");
  EXPECT_EQ(tk::format_double(1e-300), "1e-300");
  EXPECT_EQ(tk::format_double(std::nan("")), "nan");
  const auto path = temp_file("text.csv");
  {
    tk::CsvWriter w(path, {"t", "tau_1"});
    w.row({0.5, -1.25});
  }
  EXPECT_EQ(slurp(path), "t,tau_1\n0.5,-1.25\n");
  std::filesystem::remove(path);
}

// Text columns (the daemon's cycles.csv: the mode's name): quoted only when they must be, and the
// reader takes the row back (the numbers exact, the text as NaN when asked).
TEST(Csv, RowsWithTextCellsAreQuotedOnlyWhenNeededAndReadBack) {
  const auto path = temp_file("cells.csv");
  {
    tk::CsvWriter w(path, {"t", "mode", "tau_1"});
    const std::vector<tk::CsvWriter::Cell> a = {0.1, "RUNNING", -1.25};
    const std::vector<tk::CsvWriter::Cell> b = {0.2, "hold, \"frozen\"", 2.5};
    w.row(a);
    w.row(b);
    const std::vector<tk::CsvWriter::Cell> short_row = {0.3, "RUNNING"};
    EXPECT_THROW(w.row(short_row), tk::CsvError);
  }
  EXPECT_EQ(slurp(path), "t,mode,tau_1\n0.1,RUNNING,-1.25\n0.2,\"hold, \"\"frozen\"\"\",2.5\n");
  const tk::CsvTable t = tk::CsvTable::read(path, {.text_as_nan = true});
  ASSERT_EQ(t.rows(), 2u);
  EXPECT_EQ(t.column("tau_1")[1], 2.5);
  EXPECT_EQ(t.column("t")[0], 0.1);
  EXPECT_TRUE(std::isnan(t.column("mode")[1]));
  std::filesystem::remove(path);
}

TEST(Csv, ColumnCountMismatchNamesTheCounts) {
  const auto path = temp_file("mismatch.csv");
  tk::CsvWriter w(path, {"a", "b", "c"});
  w.row({1, 2, 3});
  try {
    w.row({1, 2});
    FAIL() << "short row accepted";
  } catch (const tk::CsvError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("mismatch.csv"), std::string::npos) << m;
    EXPECT_NE(m.find("row 2 has 2 values but the header names 3 columns"), std::string::npos) << m;
  }
  EXPECT_THROW(w.row({1, 2, 3, 4}), tk::CsvError);
  w.close();
  // the rejected rows were not written
  EXPECT_EQ(tk::CsvTable::read(path).rows(), 1u);
  std::filesystem::remove(path);
}

TEST(Csv, BadHeaderNamesTheColumn) {
  const auto path = temp_file("header.csv");
  try {
    tk::CsvWriter w(path, {"a", "b,c"});
    FAIL() << "comma accepted";
  } catch (const tk::CsvError& e) {
    EXPECT_NE(std::string(e.what()).find("column 2 ('b,c')"), std::string::npos) << e.what();
  }
  try {
    tk::CsvWriter w(path, {"x", "y", "x"});
    FAIL() << "duplicate accepted";
  } catch (const tk::CsvError& e) {
    EXPECT_NE(std::string(e.what()).find("column 3 ('x') is named twice"), std::string::npos) << e.what();
  }
  EXPECT_THROW(tk::CsvWriter(path, {}), tk::CsvError);
  EXPECT_THROW(tk::CsvWriter("/proc/no/such/dir/x.csv", {"a"}), tk::CsvError);
}

TEST(CsvReader, ErrorsNameFileLineAndColumn) {
  const std::string bad_number = error_of("# comment\nt,x,y\n0,1,2\n1,oops,3\n", "rec.csv");
  EXPECT_NE(bad_number.find("rec.csv:4"), std::string::npos) << bad_number;
  EXPECT_NE(bad_number.find("column 2 ('x')"), std::string::npos) << bad_number;
  EXPECT_NE(bad_number.find("'oops'"), std::string::npos) << bad_number;

  const std::string short_row = error_of("t,x,y\n0,1,2\n\n1,2\n", "rec.csv");
  EXPECT_NE(short_row.find("rec.csv:4"), std::string::npos) << short_row;
  EXPECT_NE(short_row.find("2 fields but the header names 3 columns"), std::string::npos) << short_row;

  const std::string empty_field = error_of("t,x\n0,\n", "e.csv");
  EXPECT_NE(empty_field.find("e.csv:2: column 2 ('x')"), std::string::npos) << empty_field;

  EXPECT_NE(error_of("# only a comment\n\n", "n.csv").find("n.csv: no header"), std::string::npos);
  EXPECT_NE(error_of("a,b,a\n", "d.csv").find("d.csv:1: header column 3 ('a') is named twice"), std::string::npos);
  EXPECT_NE(error_of("a,b\n1,2x\n", "s.csv").find("'2x' is not a number"), std::string::npos);

  try {
    (void)tk::CsvTable::read("/nonexistent/pedalwave.csv");
    FAIL() << "missing file accepted";
  } catch (const tk::CsvError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/pedalwave.csv"), std::string::npos);
  }
}

TEST(CsvReader, UnknownColumnListsTheColumns) {
  const auto t = tk::CsvTable::parse("t,x\n0,1\n", "r.csv");
  EXPECT_TRUE(t.has("x"));
  EXPECT_FALSE(t.has("z"));
  try {
    (void)t.column("z");
    FAIL();
  } catch (const tk::CsvError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("r.csv: no column 'z' (columns: t, x)"), std::string::npos) << m;
  }
  EXPECT_THROW((void)t.column(std::size_t{2}), tk::CsvError);
}

TEST(CsvReader, ToleratesCrlfSpacesCommentsAndSpecialValues) {
  const auto t = tk::CsvTable::parse("# meta\r\n t , x \r\n0, +1.5\r\n\r\n# mid comment\r\n1,-inf\r\n2,nan\r\n3,1e400\r\n", "w.csv");
  EXPECT_EQ(t.names(), (std::vector<std::string>{"t", "x"}));
  ASSERT_EQ(t.rows(), 4u);
  EXPECT_EQ(t.column("x")[0], 1.5);
  EXPECT_TRUE(std::isinf(t.column("x")[1]) && t.column("x")[1] < 0);
  EXPECT_TRUE(std::isnan(t.column("x")[2]));
  EXPECT_TRUE(std::isinf(t.column("x")[3]));  // overflow reads as +inf, as strtod does
  EXPECT_EQ(t.comments().size(), 2u);
}

TEST(CsvReader, EmptyTableHasColumnsButNoRows) {
  const auto t = tk::CsvTable::parse("a,b\n", "h.csv");
  EXPECT_EQ(t.cols(), 2u);
  EXPECT_EQ(t.rows(), 0u);
  EXPECT_TRUE(t.column("a").empty());
}

// A recording of another program (pedalwave_monitor --record): quoted text with commas, text
// cells, a last line cut short while it was written.
TEST(CsvTable, ReadsARecordingLenientlyWhenAsked) {
  const std::string text =
      "seq,fault_names,x\n"
      "1,\"stale, nan\",0.5\n"
      "2,\"say \"\"hi\"\"\",1.5\n"
      "3,0.1\n";
  EXPECT_THROW((void)pedalwave::toolkit::CsvTable::parse(text, "rec.csv"), pedalwave::toolkit::CsvError);
  const auto t = pedalwave::toolkit::CsvTable::parse(text, "rec.csv", {.text_as_nan = true, .skip_ragged = true});
  ASSERT_EQ(t.rows(), 2u);
  EXPECT_EQ(t.column("x")[0], 0.5);  // the quoted comma did not split the row
  EXPECT_EQ(t.column("x")[1], 1.5);
  EXPECT_TRUE(std::isnan(t.column("fault_names")[0]));
  ASSERT_EQ(t.skipped().size(), 1u);
  EXPECT_EQ(t.skipped()[0], "rec.csv:4: row has 2 fields but the header names 3 columns: skipped");
  // Text alone is still an error naming the cell when only ragged rows are allowed.
  try {
    (void)pedalwave::toolkit::CsvTable::parse(text, "rec.csv", {.skip_ragged = true});
    FAIL() << "text accepted";
  } catch (const pedalwave::toolkit::CsvError& e) {
    EXPECT_NE(std::string(e.what()).find("rec.csv:2: column 2 ('fault_names'): 'stale, nan' is not a number"),
              std::string::npos) << e.what();
  }
}
