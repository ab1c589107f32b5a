// pedalwave_plot_recording on a small recording in the monitor's format: body.csv and the figures written, a missing
// recording is one clear error with exit code 2, a line cut short is skipped (not fatal).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

namespace {
void write_recording(const fs::path& dir, bool cut_last_line) {
  const int J = 5;
  std::ofstream js(dir / "run.joint_state.csv"), os(dir / "run.observer_state.csv"),
      rd(dir / "run.robot_description.csv");
  js << "recv_ns,source_time_ns,seq,stamp_ns,t";
  for (const char* f : {"beta", "beta_dot", "alpha", "deflection", "tau_sea"})
    for (int j = 1; j <= J; ++j) js << "," << f << "_" << j;
  js << "\n";
  os << "recv_ns,source_time_ns,seq,stamp_ns";
  for (const char* f : {"residual", "tau_ext"})
    for (int j = 1; j <= J; ++j) os << "," << f << "_" << j;
  os << ",theta_N,p_x,p_z,theta_N_dot,p_x_dot,p_z_dot,fault_flags,fault_names,fault_joint,forward_speed\n";
  rd << "recv_ns,source_time_ns,links,link_length\n0,0,6,0.07\n";
  for (int k = 0; k < 300; ++k) {
    const double t = k * 0.01;
    js << 0 << "," << 0 << "," << k * 10 << "," << static_cast<long long>(t * 1e9) << "," << t;
    for (int f = 0; f < 5; ++f)
      for (int j = 0; j < J; ++j) js << "," << 0.7 * std::sin(M_PI * t - 1.2566 * j) * (f == 2 ? 1 : 0.1);
    js << "\n";
    os << 0 << "," << 0 << "," << k * 10 << "," << static_cast<long long>(t * 1e9);
    for (int j = 0; j < 2 * J; ++j) os << ",0.01";
    os << ",0," << 0.014 * t << ",0.03,0,0.014,0,0,\"\",-1,0.014\n";
  }
  if (cut_last_line) js << "0,0,3000,3000000000,3.0,0.1,0.2\n";
}
int run(const std::string& args) {
  const int rc = std::system((std::string(PLOTREC_EXE) + " " + args + " > /dev/null 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}
}  // namespace

TEST(PlotRecording, WritesThePlotsOfARecording) {
  const fs::path dir = fs::temp_directory_path() / ("plotrec_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  write_recording(dir, true);
  EXPECT_EQ(run((dir / "run.csv").string() + " --out " + (dir / "plots").string()), 0);
  EXPECT_TRUE(fs::exists(dir / "plots" / "body.csv"));  // the body placed by the observer's pose
  if (std::system("/usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null") == 0) {
    for (const char* f : {"joint_signals.png", "snake_shapes.png", "paths.png"})
      EXPECT_TRUE(fs::exists(dir / "plots" / f)) << f;
  } else {
    std::printf("SKIPPED the figures' part: /usr/bin/python3 has no matplotlib\n");
  }
  EXPECT_EQ(run((dir / "absent.csv").string() + " --out " + (dir / "p2").string()), 2);
  fs::remove_all(dir);
}
