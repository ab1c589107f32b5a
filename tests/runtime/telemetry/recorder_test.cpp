// CsvRecorder: one file per topic, header from the first message, values round-trip exactly.
#include <gtest/gtest.h>

#include <algorithm>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "pedalwave/telemetry/recorder.hpp"

namespace pedalwave::telemetry {
namespace {

namespace fs = std::filesystem;

// Splits one CSV line ("" inside quotes is a quote).
std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        out.back() += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        out.back() += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      out.emplace_back();
    } else {
      out.back() += c;
    }
  }
  return out;
}

std::vector<std::vector<std::string>> read_csv(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::vector<std::string>> rows;
  for (std::string line; std::getline(in, line);) rows.push_back(split(line));
  return rows;
}

struct RecorderTest : ::testing::Test {
  fs::path dir = fs::temp_directory_path() / ("pedalwave_rec_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
};

TEST_F(RecorderTest, WritesOneFilePerTopicWithHeaderAndExactValues) {
  const std::string base = (dir / "run.csv").string();
  {
    CsvRecorder rec(base);
    EXPECT_EQ(rec.file_for("joint_state"), (dir / "run.joint_state.csv").string());
    JointStateMsg j{42, 123456789, 0.042, {0.1, -0.2}, {1.0 / 3.0, 2.0}, {3.0, 4.0},
                    {5e-5, 6.0}, {7.0, 1e300}};
    rec.on_joint_state(j, MessageInfo{11, 22, 1});
    j.seq = 43;
    rec.on_joint_state(j, MessageInfo{12, 23, 1});
    FaultEventMsg f{7, 99, 3, "encoder_stuck", 2, "degrade", 1, 0.25, 0.1, 5,
                    "stuck, says \"module\""};
    f.event_seq = 17;
    rec.on_fault_event(f, MessageInfo{13, 24, 2});
    EXPECT_EQ(rec.rows("joint_state"), 2u);
    EXPECT_EQ(rec.rows("fault_event"), 1u);
    EXPECT_EQ(rec.rows("loop_timing"), 0u);
  }
  const auto js = read_csv((dir / "run.joint_state.csv").string());
  ASSERT_EQ(js.size(), 3u);
  const std::vector<std::string> header = {
      "recv_ns", "source_time_ns", "seq", "stamp_ns", "t", "beta_0", "beta_1", "beta_dot_0",
      "beta_dot_1", "alpha_0", "alpha_1", "deflection_0", "deflection_1", "tau_sea_0",
      "tau_sea_1"};
  EXPECT_EQ(js[0], header);
  ASSERT_EQ(js[1].size(), header.size());
  EXPECT_EQ(js[1][0], "11");
  EXPECT_EQ(js[1][2], "42");
  EXPECT_EQ(js[1][3], "123456789");
  EXPECT_EQ(std::stod(js[1][4]), 0.042);
  EXPECT_EQ(std::stod(js[1][7]), 1.0 / 3.0) << "doubles must round-trip exactly";
  EXPECT_EQ(std::stod(js[1][11]), 5e-5);
  EXPECT_EQ(std::stod(js[1][14]), 1e300);
  EXPECT_EQ(js[2][2], "43");

  const auto fe = read_csv((dir / "run.fault_event.csv").string());
  ASSERT_EQ(fe.size(), 2u);
  const auto col = [&](const std::string& name) {
    const auto it = std::find(fe[0].begin(), fe[0].end(), name);
    EXPECT_NE(it, fe[0].end()) << name;
    return static_cast<std::size_t>(it - fe[0].begin());
  };
  EXPECT_EQ(fe[1][col("text")], "stuck, says \"module\"") << "text with comma and quotes survives";
  EXPECT_EQ(fe[1][col("event_seq")], "17");
  EXPECT_EQ(fe[1][5], "encoder_stuck");

  // Topics with no message: file exists, empty.
  EXPECT_TRUE(fs::exists(dir / "run.loop_timing.csv"));
  EXPECT_EQ(fs::file_size(dir / "run.loop_timing.csv"), 0u);
  EXPECT_TRUE(fs::exists(dir / "run.command_ack.csv"));
}

TEST_F(RecorderTest, LaterWidthChangeIsPaddedToTheHeaderAndCounted) {
  const std::string base = (dir / "w").string();
  {
    CsvRecorder rec(base);
    ObserverStateMsg o;
    o.residual = {1.0, 2.0, 3.0};
    o.tau_ext = {4.0, 5.0, 6.0};
    rec.on_observer_state(o, {});
    o.residual = {1.0};
    o.tau_ext = {4.0};
    rec.on_observer_state(o, {});
    EXPECT_EQ(rec.width_mismatches(), 1u);
  }
  const auto rows = read_csv((dir / "w.observer_state.csv").string());
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[1].size(), rows[0].size());
  EXPECT_EQ(rows[2].size(), rows[0].size()) << "a row must keep the header's column count";
  EXPECT_EQ(rows[2][5], "") << "missing joints are empty cells";
}

TEST_F(RecorderTest, UnwritablePathThrowsAtConstruction) {
  EXPECT_THROW(CsvRecorder((dir / "no/such/dir/run.csv").string()), std::runtime_error);
  EXPECT_THROW(CsvRecorder(".csv"), std::invalid_argument);
}

}  // namespace
}  // namespace pedalwave::telemetry
