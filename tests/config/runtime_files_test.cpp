// The shipped daemon configurations (config/runtime/*.yaml): every one loads, and only those on
// the simulated plant may start walking on their own. A configuration for a robot on a bus
// (socketcan, serial) waits in READY for an operator's start command, so a service restart can
// never walk the robot unasked (DEPLOY.md "Service policy").
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "pedalwave/config/daemon.hpp"
#include "pedalwave/config/shipped.hpp"

using namespace pedalwave;

TEST(RuntimeFiles, HardwareConfigurationsDoNotStartWalkingOnTheirOwn) {
  int hardware = 0, sim = 0;
  for (const auto& f : std::filesystem::directory_iterator(PEDALWAVE_CONFIG_DIR "/runtime")) {
    if (f.path().extension() != ".yaml") continue;
    SCOPED_TRACE(f.path().string());
    const config::DaemonConfig c = config::load_daemon_config(f.path().string());
    if (c.driver.kind == config::DriverKind::kSim) {
      ++sim;
      continue;
    }
    ++hardware;
    EXPECT_FALSE(c.runtime.auto_start)
        << f.path().filename().string() << " drives a real bus (" << config::to_string(c.driver.kind)
        << ") and must say realtime: {auto_start: false}";
  }
  EXPECT_GE(hardware, 2) << "socketcan.yaml and serial.yaml";
  EXPECT_GE(sim, 1) << "demo.yaml";
}

// Installed programs find the shipped files in the installed examples once the source tree is gone.
TEST(RuntimeFiles, ShippedFilesComeFromTheSourceTreeElseTheInstalledExamples) {
  EXPECT_EQ(config::pick_shipped_dir(PEDALWAVE_CONFIG_DIR, "/usr/share/pedalwave/examples"),
            PEDALWAVE_CONFIG_DIR);
  EXPECT_EQ(config::pick_shipped_dir("/nonexistent/pedalwave/config", "/usr/share/pedalwave/examples"),
            "/usr/share/pedalwave/examples");
  EXPECT_EQ(config::shipped_dir(), PEDALWAVE_CONFIG_DIR) << "a build tree uses its sources";
}
