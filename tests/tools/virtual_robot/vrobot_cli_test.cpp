// pedalwave_virtual_robot end to end: started with --pty it prints the slave path, the runtime's
// serial driver opens that path and the daemon walks against it; on SIGINT the tool stops and
// reports what it did (its counts must match what the runtime did). Bad input: exit 2, one line.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>

#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "vrobot_tool.hpp"
#include "walk_rig.hpp"

using namespace pedalwave;

namespace {

using test::Tool;

// The test scene with `faults_yaml` (a `faults:` list) appended, as a file; returns its path.
std::string scene_with_faults(const std::string& file, const std::string& faults_yaml) {
  std::ifstream in(test::kScenePath);
  std::stringstream text;
  text << in.rdbuf() << "\n" << faults_yaml;
  const std::string path = ::testing::TempDir() + file;
  std::ofstream(path) << text.str();
  return path;
}

std::uint64_t number_after(const std::string& text, const std::string& label) {
  std::smatch m;
  const std::regex re(label + " ([0-9]+)");
  return std::regex_search(text, m, re) ? std::stoull(m[1]) : ~0ull;
}

}  // namespace

TEST(VirtualRobotCli, PtyServesTheRuntimeAndReportsAtSigint) {
  Tool tool({"--scene", test::kScenePath, "--pty"});
  ASSERT_TRUE(tool.read_until("waiting for the host", 30.0)) << tool.text;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(tool.text, m, std::regex("pty: (/dev/pts/[0-9]+)"))) << tool.text;
  const std::string path = m[1];

  const model::Scene scene = config::load_scene(test::kScenePath);
  test::WalkSetup s{.transport = test::Transport::kSerial, .rate_hz = 500, .duration = 4};
  config::DaemonConfig cfg = test::daemon_config(s, scene);
  cfg.driver.serial.device = path;
  auto drv = drivers::SerialDriver::open(cfg.driver.serial);  // the real open() of the device
  // With --plots: the runtime's own signals and the observer's residuals, over the bus too.
  const std::filesystem::path plots = std::filesystem::temp_directory_path() / "pw_vrobot_cli_plots";
  std::filesystem::remove_all(plots);
  app::DaemonOptions opt = test::quiet(drv.get());
  opt.plots_dir = plots.string();
  const app::DaemonResult r = app::run_daemon(cfg, opt);
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.run.fault, runtime::FaultClass::kNone) << runtime::to_string(r.run.fault);
  EXPECT_EQ(r.run.cycles, 2000u);
  const drivers::DriverCounters c = drv->counters();
  drv.reset();

  tool.signal(SIGINT);
  EXPECT_EQ(tool.wait(), 0) << tool.text;
  std::printf("%s", tool.text.c_str());
  // The tool's account matches the runtime's: every cycle's SYNC, J commands per cycle plus the
  // safe stop's torque-off to each module, every reply the host counted.
  EXPECT_EQ(number_after(tool.text, "SYNCs"), r.run.cycles);
  EXPECT_EQ(number_after(tool.text, "commands latched"), 5 * r.run.cycles + 5);
  EXPECT_EQ(number_after(tool.text, "torque-off"), 5u);
  EXPECT_EQ(number_after(tool.text, "replies sent"), 5 * r.run.cycles);
  EXPECT_GE(c.frames_rx + c.missing, 5 * r.run.cycles - 5);
  EXPECT_NE(tool.text.find("outputs off"), std::string::npos) << "the safe stop reached the plant";
  EXPECT_NE(tool.text.find("cm/s on average"), std::string::npos);
  EXPECT_NE(tool.text.find("longest gap between SYNCs received"), std::string::npos);

  EXPECT_TRUE(std::filesystem::is_regular_file(plots / "runtime.json"));
  if (std::system("/usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null") == 0) {  // tools/figures
    EXPECT_TRUE(std::filesystem::is_regular_file(plots / "runtime_signals.png"));
    EXPECT_TRUE(std::filesystem::is_regular_file(plots / "observer.png"));
  }
  std::ifstream csv(plots / "cycles.csv");
  std::string header, line;
  ASSERT_TRUE(std::getline(csv, header));
  EXPECT_EQ(header.rfind("t_s,t_controller_s,mode,fault_flags,wake_latency_us,read_us,beta_1,", 0), 0u)
      << header;
  EXPECT_NE(header.find(",residual_5"), std::string::npos) << header;
  std::size_t rows = 0;
  double worst = 0;
  while (std::getline(csv, line)) {
    ++rows;
    const double r5 = std::stod(line.substr(line.rfind(',') + 1));  // residual_5: the last column
    ASSERT_TRUE(std::isfinite(r5)) << line;
    worst = std::max(worst, std::abs(r5));
  }
  EXPECT_EQ(rows, r.run.cycles / 10);  // every 10th cycle at 500 Hz
  EXPECT_GT(worst, 0.0) << "the residual column carries the observer's residual";
  std::filesystem::remove_all(plots);
}

TEST(VirtualRobotCli, BadInputExitsWithCode2AndOneLine) {
  {
    Tool t({"--scene", test::kScenePath});
    EXPECT_EQ(t.wait(), 2);
    EXPECT_NE(t.text.find("--can IFNAME"), std::string::npos) << t.text;
  }
  {
    Tool t({"--scene", "/nonexistent/scene.yaml", "--pty"});
    EXPECT_EQ(t.wait(), 2);
    EXPECT_NE(t.text.find("/nonexistent/scene.yaml"), std::string::npos) << t.text;
  }
  {
    Tool t({"--scene", test::kScenePath, "--pty", "--silent", "9"});
    EXPECT_EQ(t.wait(), 2);
    EXPECT_NE(t.text.find("--silent 9: expected a joint 1…5"), std::string::npos) << t.text;
  }
  {
    Tool t({"--scene", test::kScenePath, "--pty", "--loss", "1.5"});
    EXPECT_EQ(t.wait(), 2) << t.text;
  }
}

TEST(VirtualRobotCli, PrintsTheScenesFaultsAndWhetherTheyActed) {
  const std::string path = scene_with_faults(
      "vrobot_cli_faults.yaml", "faults:\n  - {type: encoder_stuck, joint: 2, t_start: 4}\n");
  {
    Tool t({"--scene", path, "--pty", "--duration", "0.3"});
    EXPECT_EQ(t.wait(), 0) << t.text;
    EXPECT_NE(t.text.find("faults (inside the modules): encoder_stuck on joint 3 from 4.0 s\n"),
              std::string::npos) << t.text;
    // No host talked: plant time never reached the onset.
    EXPECT_NE(t.text.find("encoder_stuck on joint 3 from 4.0 s: never active"), std::string::npos)
        << t.text;
  }
  {
    Tool t({"--scene", path, "--pty", "--duration", "0.3", "--no-faults"});
    EXPECT_EQ(t.wait(), 0) << t.text;
    EXPECT_EQ(t.text.find("faults (inside the modules)"), std::string::npos) << t.text;
    EXPECT_NE(t.text.find("faults not injected (--no-faults): encoder_stuck on joint 3 from 4.0 s"),
              std::string::npos) << t.text;
  }
}

TEST(VirtualRobotCli, HostSideFaultInTheSceneIsBadInputNamingIt) {
  const std::string path = scene_with_faults(
      "vrobot_cli_stale.yaml",
      "faults:\n  - {type: encoder_offset, joint: 0, t_start: 1, value: 0.1}\n"
      "  - {type: stale, joint: 1, t_start: 2, value: 3}\n");
  {
    Tool t({"--scene", path, "--pty"});
    EXPECT_EQ(t.wait(), 2) << t.text;
    EXPECT_NE(t.text.find("faults[1]: stale"), std::string::npos) << t.text;
    EXPECT_NE(t.text.find("--counter-fault"), std::string::npos) << t.text;
  }
  {
    Tool t({"--scene", path, "--pty", "--duration", "0.3", "--ignore-host-faults"});
    EXPECT_EQ(t.wait(), 0) << t.text;
    EXPECT_NE(t.text.find("faults (inside the modules): encoder_offset 0.1 on joint 1 from 1.0 s\n"),
              std::string::npos) << t.text;
    EXPECT_NE(t.text.find("faults not injected (host-side, --ignore-host-faults): stale 3.0 on "
                          "joint 2 from 2.0 s"), std::string::npos) << t.text;
  }
}
