// pedalwave::csv: the two number spellings (kFixed is fmt's "{}", checked against fmt itself),
// rows cell by cell, a header written after the file is created, the writer's errors, and the
// reader's exact integer and text columns.
#include <gtest/gtest.h>

#include <fmt/format.h>
#include <unistd.h>

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/csv/csv.hpp"

namespace csv = pedalwave::csv;
namespace fs = std::filesystem;

namespace {

struct CsvFiles : ::testing::Test {
  fs::path dir = fs::temp_directory_path() / ("pedalwave_common_csv_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
  static std::string slurp(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    std::ostringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }
};

// The double a text reads back as (from_chars: denormals too, where std::stod throws).
double read_back(const std::string& s) {
  double v = 0.0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  EXPECT_TRUE(r.ec == std::errc() && r.ptr == s.data() + s.size()) << s;
  return v;
}

std::string spelled(double v, csv::Numbers n) {
  std::string s;
  csv::append_number(s, v, n);
  return s;
}

TEST(CsvNumbers, TheTwoSpellings) {
  EXPECT_EQ(spelled(100000.0, csv::Numbers::kShortest), "1e+05");
  EXPECT_EQ(spelled(100000.0, csv::Numbers::kFixed), "100000");
  EXPECT_EQ(spelled(0.0001, csv::Numbers::kShortest), "1e-04");
  EXPECT_EQ(spelled(0.0001, csv::Numbers::kFixed), "0.0001");
  EXPECT_EQ(spelled(5e-5, csv::Numbers::kFixed), "5e-05");
  EXPECT_EQ(spelled(1e16, csv::Numbers::kFixed), "1e+16");
  EXPECT_EQ(spelled(1e15, csv::Numbers::kFixed), "1000000000000000");
  EXPECT_EQ(spelled(-0.0, csv::Numbers::kFixed), "-0");
  EXPECT_EQ(spelled(-std::numeric_limits<double>::quiet_NaN(), csv::Numbers::kShortest), "nan");
  EXPECT_EQ(spelled(-std::numeric_limits<double>::infinity(), csv::Numbers::kShortest), "-inf");
  EXPECT_EQ(spelled(std::numeric_limits<double>::infinity(), csv::Numbers::kFixed), "inf");
}

// kFixed is documented as fmt's "{}": compared with fmt on special values, on powers of ten
// around both thresholds, and on 200000 random bit patterns; every text reads back exactly.
TEST(CsvNumbers, FixedIsFmtsSpellingAndRoundTrips) {
  std::vector<double> values = {0.0, -0.0, 1.0, 0.1, 1.0 / 3.0, 123456.5, 1e300, -1e-300,
                                std::numeric_limits<double>::denorm_min(),
                                std::numeric_limits<double>::max(),
                                std::numeric_limits<double>::lowest(),
                                std::numeric_limits<double>::quiet_NaN(),
                                -std::numeric_limits<double>::quiet_NaN(),
                                std::numeric_limits<double>::infinity(),
                                -std::numeric_limits<double>::infinity()};
  for (int e = -8; e <= 20; ++e) {
    for (const double m : {1.0, 1.5, 9.999999999999999, 9.9999999999999999}) {
      values.push_back(m * std::pow(10.0, e));
      values.push_back(-m * std::pow(10.0, e));
    }
  }
  std::mt19937_64 rng(20261206);
  for (int i = 0; i < 200000; ++i) values.push_back(std::bit_cast<double>(rng()));
  std::uniform_real_distribution<double> exponent(-6.0, 18.0);
  for (int i = 0; i < 200000; ++i) values.push_back(std::pow(10.0, exponent(rng)));
  int differ = 0;
  for (const double v : values) {
    const std::string mine = spelled(v, csv::Numbers::kFixed);
    if (mine != fmt::format("{}", v) && ++differ <= 5) {
      ADD_FAILURE() << "kFixed " << mine << " but fmt " << fmt::format("{}", v);
    }
    if (!std::isnan(v)) {
      EXPECT_EQ(read_back(mine), v) << mine;
      EXPECT_EQ(read_back(spelled(v, csv::Numbers::kShortest)), v);
    }
  }
  EXPECT_EQ(differ, 0);
}

TEST_F(CsvFiles, RowCellByCellWithALateHeader) {
  const fs::path p = dir / "late.csv";
  {
    csv::Writer w = csv::Writer::header_later(p, {csv::Numbers::kFixed, false});
    EXPECT_TRUE(fs::exists(p)) << "the file exists before its header";
    EXPECT_FALSE(w.has_header());
    EXPECT_THROW(w.number(1.0).end_row(), csv::Error) << "a row before the header";
    w.header({"a", "b", "c", "d", "e", "f"});
    EXPECT_THROW(w.header({"x"}), csv::Error);
    w.integer(std::int64_t{-9223372036854775807LL}).integer(std::uint64_t{18446744073709551615ULL})
        .integer(std::uint8_t{200}).text("a, b").quoted("plain").empty();
    w.end_row();
    w.number(100000.0).integer(std::int16_t{-1}).text("x").quoted("say \"hi\"").empty().number(0.5);
    w.end_row();
    EXPECT_THROW(w.number(1.0).end_row(), csv::Error) << "1 cell, 6 columns";
    w.number(1).number(2).number(3).number(4).number(5).number(6);
    w.end_row();  // the refused row left nothing behind
    EXPECT_EQ(w.rows_written(), 3u);
  }
  EXPECT_EQ(slurp(p),
            "a,b,c,d,e,f\n"
            "-9223372036854775807,18446744073709551615,200,\"a, b\",\"plain\",\n"
            "100000,-1,x,\"say \"\"hi\"\"\",,0.5\n"
            "1,2,3,4,5,6\n");
  const auto t = csv::Table::parse(slurp(p), "late.csv", {.text_as_nan = true, .skip_ragged = false});
  EXPECT_EQ(t.rows(), 3u);
  EXPECT_EQ(t.column("a")[1], 100000.0);
}

TEST_F(CsvFiles, FoldersAreCreatedOnlyWhenAsked) {
  EXPECT_NO_THROW(csv::Writer(dir / "new" / "x.csv", {"a"}));
  EXPECT_TRUE(fs::exists(dir / "new" / "x.csv"));
  try {
    csv::Writer w(dir / "none" / "x.csv", {"a"}, {csv::Numbers::kShortest, false});
    ADD_FAILURE() << "no error for a missing folder";
  } catch (const csv::Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find((dir / "none" / "x.csv").string()), std::string::npos) << what;
    EXPECT_NE(what.find("cannot open for writing: No such file or directory"), std::string::npos) << what;
  }
}

// Integer columns are exact where a double is not (a nanosecond stamp: beyond 2^53), text columns
// keep their text, and a bad integer is an error naming the file, the line and the column.
TEST(CsvTable, IntegerColumnsAreExactAndTextColumnsKeepTheirText) {
  const std::string text =
      "# a recording\n"
      "seq,stamp_ns,mode_name,x\n"
      "1,9007199254740993,RUNNING,0.5\n"         // 2^53 + 1: no double holds it
      "2,9223372036854775807,\"a, b\",1.5\n"     // the largest int64
      "3,-9223372036854775808,,2.5\n"            // the smallest
      "4,+17,IDLE,nan\n";
  const csv::Table::ReadOptions exact{.integer_columns = {"seq", "stamp_ns"}, .text_columns = {"mode_name", "absent"}};
  const auto t = csv::Table::parse(text, "run.joint_state.csv", exact);
  ASSERT_EQ(t.rows(), 4u);
  EXPECT_EQ(t.integers("stamp_ns"),
            (std::vector<std::int64_t>{9007199254740993LL, std::numeric_limits<std::int64_t>::max(),
                                       std::numeric_limits<std::int64_t>::min(), 17}));
  EXPECT_EQ(t.integers("seq"), (std::vector<std::int64_t>{1, 2, 3, 4}));
  // column() of an integer column: the nearest doubles (2^53 + 1 is not one of them).
  EXPECT_EQ(t.column("stamp_ns")[0], 9007199254740992.0);
  EXPECT_NE(static_cast<std::int64_t>(t.column("stamp_ns")[0]), t.integers("stamp_ns")[0]);
  EXPECT_EQ(t.texts("mode_name"), (std::vector<std::string>{"RUNNING", "a, b", "", "IDLE"}));
  EXPECT_TRUE(std::isnan(t.column("mode_name")[0]));
  EXPECT_EQ(t.column("x")[2], 2.5);
  EXPECT_TRUE(std::isnan(t.column("x")[3]));
  // Without the options the same text is an error at the text cell, and the accessors say why.
  EXPECT_THROW((void)csv::Table::parse(text, "run.joint_state.csv"), csv::Error);
  const auto lenient = csv::Table::parse(text, "r.csv", {.text_as_nan = true});
  auto error_of = [](auto&& f) -> std::string {
    try {
      f();
    } catch (const csv::Error& e) {
      return e.what();
    }
    return "no error";
  };
  EXPECT_EQ(error_of([&] { (void)lenient.integers("stamp_ns"); }),
            "r.csv: column 'stamp_ns' was not read as integers (expected it in Table::ReadOptions::integer_columns)");
  EXPECT_EQ(error_of([&] { (void)lenient.texts("mode_name"); }),
            "r.csv: column 'mode_name' was not read as text (expected it in Table::ReadOptions::text_columns)");
  EXPECT_EQ(error_of([&] { (void)t.integers("t"); }), "run.joint_state.csv: no column 't' (columns: seq, stamp_ns, mode_name, x)");

  // Bad integers name the file, the line and the column, whatever text_as_nan says.
  const auto bad = [&](const std::string& cell) {
    return error_of([&] {
      (void)csv::Table::parse("# c\nseq,stamp_ns\n1,2\n2," + cell + "\n", "run.csv",
                              {.text_as_nan = true, .integer_columns = {"stamp_ns"}});
    });
  };
  const std::string range = ": expected a whole number in [-9223372036854775808, 9223372036854775807]";
  EXPECT_EQ(bad("1.5"), "run.csv:4: column 2 ('stamp_ns'): '1.5' is not an integer" + range);
  EXPECT_EQ(bad("1e9"), "run.csv:4: column 2 ('stamp_ns'): '1e9' is not an integer" + range);
  EXPECT_EQ(bad(""), "run.csv:4: column 2 ('stamp_ns'): '' is not an integer" + range);
  EXPECT_EQ(bad("12abc"), "run.csv:4: column 2 ('stamp_ns'): '12abc' is not an integer" + range);
  EXPECT_EQ(bad("9223372036854775808"),
            "run.csv:4: column 2 ('stamp_ns'): '9223372036854775808' is beyond the 64-bit integers" + range);
  EXPECT_EQ(bad("-9223372036854775809"),
            "run.csv:4: column 2 ('stamp_ns'): '-9223372036854775809' is beyond the 64-bit integers" + range);
  // An integer column the header lacks.
  EXPECT_EQ(error_of([&] { (void)csv::Table::parse("a,b\n1,2\n", "h.csv", {.integer_columns = {"seq"}}); }),
            "h.csv:1: no column 'seq' (columns: a, b): expected it, as integers");
}

}  // namespace
