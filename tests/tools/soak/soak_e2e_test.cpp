// pedalwave_soak end to end: the built tool runs the built virtual robot and runtime as processes
// under one busy process for 8 s; exit code, soak.json (memory samples of both processes, the
// parsed report) and no process left behind (load, runtime, virtual robot). A second run puts a
// stand-in in front of the real runtime that writes a report.json of the runtime's schema, so the
// whole path is checked also while the runtime on this branch has no --report-json; SIGINT stops
// everything in order (exit 1); bad input exits 2 with a message that names it.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "pedalwave/toolkit/cpu_load.hpp"
#include "pedalwave/toolkit/json.hpp"

namespace fs = std::filesystem;
namespace tk = pedalwave::toolkit;
using tk::Json;

namespace {

struct SoakRun {
  int code = -1;
  std::string text;  // stdout + stderr
};

SoakRun run_soak_cmd(const std::string& command) {
  SoakRun r;
  const std::string cmd = command + " 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) r.text.append(buf, n);
  const int st = ::pclose(p);
  r.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

SoakRun run_soak(const std::string& args) { return run_soak_cmd(std::string(PEDALWAVE_SOAK_EXE) + " " + args); }

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("pedalwave_soak_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

// Every process the soak started is gone.
void expect_no_process_left(const Json& soak) {
  ASSERT_TRUE(soak["load"]["pids"].is_array());
  EXPECT_EQ(soak["load"]["pids"].size(), 1u);
  for (const Json& p : soak["load"]["pids"].items())
    EXPECT_FALSE(tk::process_alive(static_cast<pid_t>(p.number()))) << "load process " << p.number() << " left";
  for (const char* who : {"runtime", "virtual_robot"}) {
    const Json& pid = soak[who]["pid"];
    ASSERT_TRUE(pid.is_number()) << who;
    EXPECT_FALSE(tk::process_alive(static_cast<pid_t>(pid.number()))) << who << " left";
  }
}

void expect_memory_samples(const Json& soak) {
  for (const char* who : {"runtime", "virtual_robot"}) {
    const Json& rows = soak["memory"][who];
    ASSERT_TRUE(rows.is_array()) << who;
    EXPECT_GE(rows.size(), 2u) << who << ": a sample at the start and one near the end";
    for (const Json& r : rows.items()) {
      EXPECT_GT(r["rss_kB"].number(), 0) << who;
      EXPECT_GE(r["threads"].number(), 1) << who;
    }
  }
}

// The stand-in runtime: writes a report.json (the runtime's schema) where --report-json says, then
// becomes the real runtime (exec) with the other arguments, so the sampled pid is the runtime's.
fs::path write_standin(const fs::path& out) {
  const fs::path script = out / "runtime_standin.sh";
  {
    std::ofstream f(script);
    f << "#!/bin/bash\n"
         "args=(); report=\n"
         "while [ $# -gt 0 ]; do\n"
         "  if [ \"$1\" = --report-json ]; then report=$2; shift 2; else args+=(\"$1\"); shift; fi\n"
         "done\n"
         "[ -n \"$report\" ] && cat > \"$report\" <<'JSON'\n"
         "{\"name\": \"serial-robot\", \"driver\": \"serial\", \"rate_hz\": 500, \"duration_s\": 8,\n"
         " \"exit\": {\"reason\": \"cycle_limit\", \"final_mode\": \"SAFE_STOP\", \"fault\": \"none\", \"joint\": null, \"signal\": null},\n"
         " \"events\": [], \"events_dropped\": 0,\n"
         " \"loop\": {\"cycles\": 4000, \"overruns\": 0, \"skipped_periods\": 0, \"max_skipped\": 0, \"cycle_drops\": 0, \"event_drops\": 0},\n"
         " \"timing_us\": {\"wake\": {\"count\": 4000, \"min\": 2, \"p50\": 10, \"p90\": 15, \"p99\": 30, \"p999\": 80, \"max\": 120,\n"
         "   \"overflows\": 0, \"bins\": [[0, 10, 2000], [10, 50, 1990], [50, 200, 10]]}},\n"
         " \"driver_counters\": {\"frames_tx\": 12005, \"missing\": 0}, \"settings\": {\"observer\": true}}\n"
         "JSON\n"
         "exec " PEDALWAVE_RUNTIME_EXE " \"${args[@]}\"\n";
  }
  fs::permissions(script, fs::perms::owner_all);
  return script;
}

// The runtime as configured for the robot on the serial bus (config/runtime/serial.yaml: observer
// on, SCHED_FIFO, derived timeouts).
const std::string kArgs = " --config " PEDALWAVE_SOAK_TEST_CONFIG
                          " --duration 8 --load 1 --no-plot --telemetry off --sample-period 2 --out ";

}  // namespace

TEST(SoakCli, RealRuntimeAndVirtualRobotUnderLoad) {
  const fs::path out = fresh_dir("real");
  const SoakRun r = run_soak(kArgs + out.string());
  std::printf("%s", r.text.c_str());
  ASSERT_TRUE(fs::exists(out / "soak.json")) << r.text;
  const Json soak = Json::parse_file(out / "soak.json");
  expect_no_process_left(soak);
  EXPECT_EQ(r.code, 0) << r.text;
  expect_memory_samples(soak);
  ASSERT_TRUE(soak["report"].is_object()) << r.text;
  EXPECT_EQ(soak["report"]["exit"]["reason"].string(), "cycle_limit");
  EXPECT_TRUE(soak["report"]["settings"]["observer"].boolean()) << "the observer ran";
  EXPECT_GT(soak["report"]["loop"]["cycles"].number(), 0);
  EXPECT_NE(r.text.find("verdict: PASS"), std::string::npos);
  fs::remove_all(out);
}

TEST(SoakCli, StandInReportInFrontOfTheRealRuntime) {
  const fs::path out = fresh_dir("standin");
  const fs::path script = write_standin(out);
  const SoakRun r = run_soak(kArgs + out.string() + " --runtime " + script.string());
  std::printf("%s", r.text.c_str());
  EXPECT_EQ(r.code, 0) << r.text;
  ASSERT_TRUE(fs::exists(out / "soak.json")) << r.text;
  ASSERT_TRUE(fs::exists(out / "memory.csv")) << r.text;
  const Json soak = Json::parse_file(out / "soak.json");
  expect_no_process_left(soak);
  expect_memory_samples(soak);
  EXPECT_EQ(soak["runtime"]["exit_code"].number(), 0);
  EXPECT_EQ(soak["report"]["loop"]["cycles"].number(), 4000);
  EXPECT_EQ(soak["load"]["children"].number(), 1);
  EXPECT_GT(soak["load"]["cpu_s"].number(), 1.0) << "one busy process for ≥ 8 s";
  EXPECT_GE(soak["machine"]["nproc"].number(), 1);
  EXPECT_NE(soak["machine"]["kernel"].string().find("Linux"), std::string::npos);
  EXPECT_GT(soak["virtual_robot"]["report"].size(), 0u) << "the virtual robot's report lines";
  // The virtual robot answered the real runtime: it counted its SYNCs.
  EXPECT_NE(r.text.find("SYNCs"), std::string::npos) << r.text;
  EXPECT_NE(r.text.find("wake [µs]:"), std::string::npos);
  EXPECT_NE(r.text.find("verdict: PASS"), std::string::npos);
  fs::remove_all(out);
}

TEST(SoakCli, BadInputExitsWith2AndNamesIt) {
  const fs::path out = fresh_dir("bad");
  const std::string broken = (out / "broken.yaml").string(), sim = (out / "sim.yaml").string();
  std::ofstream(broken) << "driver: [\n";
  std::ofstream(sim) << "driver: {type: sim, scene: x.yaml}\n";
  struct Case {
    std::string args, want;
  };
  const std::vector<Case> cases = {
      {"--scene /nonexistent/scene.yaml", "--scene /nonexistent/scene.yaml: no such file"},
      {"--config " + broken, "--config " + broken + ": not valid YAML"},
      {"--config " + sim, "driver.type is 'sim', expected 'serial'"},
      {"--runtime /nonexistent/pedalwave_runtime", "--runtime /nonexistent/pedalwave_runtime: not an executable"},
      {"--load-duty 0", "--load-duty 0: expected a fraction in (0, 1]"},
      {"--telemetry maybe", "--telemetry"},
      {"--duration -1", "--duration"},
  };
  for (const Case& c : cases) {
    const SoakRun r = run_soak(c.args + " --no-plot --out " + out.string());
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.text;
    EXPECT_NE(r.text.find(c.want), std::string::npos) << c.args << "\n" << r.text;
  }
  fs::remove_all(out);
}

TEST(SoakCli, SigintStopsEverythingInOrder) {
  const fs::path out = fresh_dir("sigint");
  const fs::path script = write_standin(out);
  // SIGINT 4 s into a 30 s soak: the runtime, the virtual robot and the load are stopped, the
  // files are written, the verdict says why, exit 1.
  const SoakRun r = run_soak_cmd("timeout --preserve-status -s INT 4 " + std::string(PEDALWAVE_SOAK_EXE) +
                                 " --config " PEDALWAVE_SOAK_TEST_CONFIG
                                 " --duration 30 --load 1 --no-plot --telemetry off --sample-period 1 --out " +
                                 out.string() + " --runtime " + script.string());
  std::printf("%s", r.text.c_str());
  EXPECT_EQ(r.code, 1) << r.text;
  ASSERT_TRUE(fs::exists(out / "soak.json")) << r.text;
  const Json soak = Json::parse_file(out / "soak.json");
  expect_no_process_left(soak);
  EXPECT_TRUE(soak["interrupted"].boolean());
  EXPECT_NE(r.text.find("interrupted"), std::string::npos) << r.text;
  EXPECT_LT(soak["runtime"]["wall_s"].number(), 20.0);
  fs::remove_all(out);
}
