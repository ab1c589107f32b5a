// toolkit::BodyPointsCsv: the body-points CSV of pedalwave_sim, pedalwave_paper, the daemon's
// --plots and pedalwave_plot_recording: header, rows, and counts checked.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/toolkit/body_csv.hpp"

namespace tk = pedalwave::toolkit;
namespace fs = std::filesystem;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("pedalwave_body_csv_" + std::to_string(::getpid()));
  fs::remove_all(d);
  return d;
}

TEST(BodyPointsCsv, LeadingColumnsThenXsThenZs) {
  const fs::path d = temp_dir();
  {
    tk::BodyPointsCsv csv(d / "sub" / "body.csv", {"t", "com_x"}, 3);
    csv.comment("three points");
    const std::vector<double> x{0.0, 0.5, 1.0}, z{-1.0, 0.25, 1e-5};
    csv.row({0.01, 0.5}, x, z);
    EXPECT_EQ(csv.rows_written(), 1u);
    csv.close();
  }
  EXPECT_EQ(slurp(d / "sub" / "body.csv"),
            "t,com_x,x_0,x_1,x_2,z_0,z_1,z_2\n# three points\n0.01,0.5,0,0.5,1,-1,0.25,1e-05\n");
  fs::remove_all(d);
}

TEST(BodyPointsCsv, NoPointsIsATraceAndWrongCountsAreErrors) {
  const fs::path d = temp_dir();
  {
    tk::BodyPointsCsv csv(d / "trace.csv", {"t", "tau"}, 0);
    csv.row({1.0, 2.0}, {}, {});
  }
  EXPECT_EQ(slurp(d / "trace.csv"), "t,tau\n1,2\n");
  tk::BodyPointsCsv csv(d / "bad.csv", {"t"}, 2);
  const std::vector<double> two{1.0, 2.0}, three{1.0, 2.0, 3.0};
  try {
    csv.row({0.0}, two, three);
    ADD_FAILURE() << "3 z points for 2 accepted";
  } catch (const tk::CsvError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("bad.csv"), std::string::npos) << what;
    EXPECT_NE(what.find("2 x / 3 z points, expected 1 and 2"), std::string::npos) << what;
  }
  EXPECT_THROW(csv.row({0.0, 1.0}, two, two), tk::CsvError);
  EXPECT_EQ(csv.rows_written(), 0u);
  fs::remove_all(d);
}

}  // namespace
