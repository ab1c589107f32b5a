// The runtime daemon in simulated-plant mode, in-process: lockstep loop clock and lockstep plant,
// so runs are deterministic; configuration errors are refused before anything starts.
#include <gtest/gtest.h>

#include "daemon.hpp"
#include "pedalwave/config/daemon.hpp"

using namespace pedalwave;

namespace {
config::DaemonConfig lockstep(double duration) {
  auto c = config::load_daemon_config(PEDALWAVE_CONFIG_DIR "/runtime/sim_lockstep.yaml");
  c.duration = duration;
  c.runtime.max_cycles = static_cast<std::uint64_t>(duration * c.runtime.rt.rate_hz);
  return c;
}
std::string config_error(const std::string& yaml) {
  try {
    config::parse_daemon_config(yaml, "bad.yaml", PEDALWAVE_CONFIG_DIR "/runtime");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Daemon, SimulatedPlantWalksAndStopsSafely) {
  const auto r = app::run_daemon(lockstep(6.0), {.plots_dir = "", .telemetry = false, .print = false});
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.run.final_mode, runtime::Mode::kSafeStop);
  EXPECT_EQ(r.run.cycles, 6000u);
  EXPECT_EQ(r.run.overruns, 0u) << "lockstep clock: no overruns";
  EXPECT_NEAR(r.sim_time, 6.0, 0.02);
  // The same gait offline (simloop) walks at ~1.4 cm/s; through the runtime it must too.
  EXPECT_GT(r.forward_speed, 0.010);
  EXPECT_LT(r.forward_speed, 0.020);
}

TEST(Daemon, LockstepRunsAreReproducible) {
  const auto a = app::run_daemon(lockstep(3.0), {.plots_dir = "", .telemetry = false, .print = false});
  const auto b = app::run_daemon(lockstep(3.0), {.plots_dir = "", .telemetry = false, .print = false});
  EXPECT_EQ(a.forward_speed, b.forward_speed);  // bit-identical
}

TEST(Daemon, ConfigurationErrorsNameFileKeyAndExpectation) {
  std::string e = config_error("rate_hz: 1000\ndriver: {type: sim}\n");
  EXPECT_NE(e.find("driver.scene"), std::string::npos) << e;
  e = config_error("rate_hz: fast\ndriver: {type: sim, scene: ../scenes/stair.yaml}\n");
  EXPECT_NE(e.find("rate_hz = \"fast\": expected a number"), std::string::npos) << e;
  e = config_error("driver: {type: carrier-pigeon}\n");
  EXPECT_NE(e.find("one of sim, socketcan, serial"), std::string::npos) << e;
  // A bus that cannot carry 5 joints at 1 kHz is refused with the numbers.
  e = config_error("rate_hz: 1000\nrobot: {N: 6}\ndriver: {type: socketcan, ifname: vcan0, fd: false, bitrate: 1.0e6}\n");
  EXPECT_NE(e.find("bits"), std::string::npos) << e;
  EXPECT_NE(e.find("CAN FD"), std::string::npos) << e;
  // A host-side PD that is unstable at the loop rate is refused with the fix.
  e = config_error("rate_hz: 1000\ndriver: {type: sim, scene: ../scenes/flat_high_friction.yaml}\ncontroller: {pd_placement: host}\n");
  EXPECT_NE(e.find("controller"), std::string::npos) << e;
  EXPECT_NE(e.find("module"), std::string::npos) << e;
  e = config_error("rate_hz: 1000\ndriver: {type: sim, scene: ../scenes/flat_high_friction.yaml}\nrealtime: {priority: 150}\n");
  EXPECT_NE(e.find("realtime.priority = \"150\""), std::string::npos) << e;
  e = config_error("rate_hz: 1000\ndriver: {type: sim, scene: nowhere.yaml}\n");
  EXPECT_NE(e.find("nowhere.yaml"), std::string::npos) << e;
}
