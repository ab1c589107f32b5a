// The figure scripts (tools/figures/*.py) as the tools run them, through toolkit::draw_figures:
// one test per family on data in the tools' formats written here (a short synthetic run), checking
// that every figure appears as a PNG of plausible size; bad data (a missing column, a ragged row,
// a JSON without its key) fail with the file and the column named; without matplotlib (an
// interpreter that cannot import it, or none) the outcome is "skipped" with the reason, not a
// crash. The drawing tests SKIP loudly where /usr/bin/python3 has no matplotlib (deps.sh installs it).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figures.hpp"

namespace {

namespace fs = std::filesystem;
namespace tk = pedalwave::toolkit;
using Status = tk::FigureOutcome::Status;

constexpr int kLinks = 6;                // N
constexpr int kPoints = 2 * kLinks + 1;  // 2N+1 body points
constexpr double kPi = std::numbers::pi;

bool have_matplotlib() { return std::system("/usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null") == 0; }

#define REQUIRE_MATPLOTLIB()                                                                       \
  if (!have_matplotlib()) GTEST_SKIP() << "SKIPPED: /usr/bin/python3 has no matplotlib/numpy "     \
                                          "(apt-get install python3-matplotlib python3-numpy)"

struct Png {
  std::uint32_t width = 0, height = 0;
  std::uintmax_t bytes = 0;
};

// Width and height from the PNG's IHDR chunk (bytes 16..23, big endian); zeros if not a PNG.
Png read_png(const fs::path& p) {
  Png png;
  std::ifstream f(p, std::ios::binary);
  unsigned char h[24] = {};
  if (!f.read(reinterpret_cast<char*>(h), sizeof h)) return png;
  if (h[1] != 'P' || h[2] != 'N' || h[3] != 'G') return png;
  auto be32 = [&](int i) {
    return (std::uint32_t{h[i]} << 24) | (std::uint32_t{h[i + 1]} << 16) | (std::uint32_t{h[i + 2]} << 8) | h[i + 3];
  };
  png.width = be32(16);
  png.height = be32(20);
  png.bytes = fs::file_size(p);
  return png;
}

// A figure with content: about 1000 px wide (10 in at 100 dpi, legends outside may widen it), not
// a sliver, and more bytes than an empty frame with labels (≈ 15 kB) would take.
void expect_figure(const fs::path& p, std::uintmax_t min_bytes = 20000) {
  ASSERT_TRUE(fs::is_regular_file(p)) << p;
  const Png png = read_png(p);
  EXPECT_GE(png.width, 700u) << p;
  EXPECT_LE(png.width, 2000u) << p;
  EXPECT_GE(png.height, 150u) << p;  // a true-aspect snake on flat ground is a wide strip
  EXPECT_LE(png.height, 1600u) << p;
  EXPECT_GE(png.bytes, min_bytes) << p;
}

void write(const fs::path& p, const std::string& text) {
  std::ofstream f(p);
  f << text;
}

// A snake lying along x with a travelling wave in z, moving forward at 1 cm/s: body.csv.
void write_body(const fs::path& file, double duration, double dt) {
  std::vector<std::string> h{"t", "com_x", "com_z", "head_x", "head_z"};
  for (const char* a : {"x_", "z_"})
    for (int k = 0; k < kPoints; ++k) h.push_back(a + std::to_string(k));
  tk::CsvWriter csv(file, h);
  csv.comment("synthetic body for the figures' test");
  for (double t = 0; t <= duration + 1e-9; t += dt) {
    std::vector<double> r{t, 0.01 * t, 0.02, 0.0, 0.0};
    for (int k = 0; k < kPoints; ++k) r.push_back(-0.2 + 0.035 * k + 0.01 * t);
    for (int k = 0; k < kPoints; ++k) r.push_back(0.02 + 0.02 * std::sin(kPi * t - 0.6 * k));
    r[3] = r[5 + kPoints - 1];
    r[4] = r[5 + 2 * kPoints - 1];
    csv.row(r);
  }
}

const char* kScene =
    R"({"ground_z": 0.0, "boxes": [{"x0": 0.3, "x1": 0.41, "z0": 0.0, "z1": 0.06}],)"
    R"( "patches": [{"x_begin": 0.1, "mu": 0.4}]})";

class Figures : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("pedalwave_figures_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    unsetenv("PEDALWAVE_PYTHON");
  }
  void TearDown() override {
    unsetenv("PEDALWAVE_PYTHON");
    if (!HasFailure()) fs::remove_all(dir_);
  }

  // pedalwave_runtime --plots: cycles.csv (5 joints, 50 Hz over 10 s) and runtime.json.
  void write_runtime_data(bool drop_u1 = false) {
    std::vector<std::string> h{"t_s", "t_controller_s", "mode", "fault_flags", "wake_latency_us", "read_us"};
    const char* names[] = {"beta", "beta_dot", "deflection", "alpha", "tau_sea", "u", "residual"};
    for (int j = 1; j <= 5; ++j)
      for (const char* n : names)
        if (!(drop_u1 && j == 1 && std::string(n) == "u")) h.push_back(std::string(n) + "_" + std::to_string(j));
    std::ofstream f(dir_ / "cycles.csv");
    for (std::size_t i = 0; i < h.size(); ++i) f << (i ? "," : "") << h[i];
    f << "\n";
    for (int i = 0; i < 500; ++i) {
      const double t = 0.02 * i;
      f << t << "," << t << ",RUNNING,0," << 80 + (i % 37) << "," << 1 + (i % 5);
      for (int j = 1; j <= 5; ++j)
        for (int q = 0; q < 7; ++q)
          if (!(drop_u1 && j == 1 && q == 5)) f << "," << 0.1 * (q + 1) * std::sin(kPi * t - 1.2 * j);
      f << "\n";
    }
    write(dir_ / "runtime.json", R"({"residual_threshold": 0.8, "marks": [{"t": 4.0, "label": "stale j2"}]})");
  }

  fs::path dir_;
};

// ---- one test per family --------------------------------------------------------------------

TEST_F(Figures, RuntimeDrawsTheSignalsObserverAndPlantFigures) {
  REQUIRE_MATPLOTLIB();
  write_runtime_data();
  write_body(dir_ / "body.csv", 10.0, 0.01);
  write(dir_ / "plant.json", std::string(R"({"name": "test", "scene": )") + kScene + "}");
  const tk::FigureOutcome r = tk::draw_figures("runtime.py", {dir_.string()});
  ASSERT_EQ(r.status, Status::drawn) << r.message;
  for (const char* f : {"runtime_signals.png", "observer.png", "snake_shapes.png", "paths.png", "speed.png"}) {
    expect_figure(dir_ / f);
    EXPECT_NE(r.message.find(f), std::string::npos) << r.message;  // the tool passes the list on
  }
  // Without the plant's data (a bus driver): only the runtime's two figures.
  fs::remove_all(dir_ / "x");
  fs::create_directories(dir_ / "x");
  fs::copy_file(dir_ / "cycles.csv", dir_ / "x" / "cycles.csv");
  fs::copy_file(dir_ / "runtime.json", dir_ / "x" / "runtime.json");
  ASSERT_EQ(tk::draw_figures("runtime.py", {(dir_ / "x").string()}).status, Status::drawn);
  EXPECT_TRUE(fs::exists(dir_ / "x" / "observer.png"));
  EXPECT_FALSE(fs::exists(dir_ / "x" / "snake_shapes.png"));
}

TEST_F(Figures, SimulateDrawsShapesGaitCyclePathsTorquesAndSpeed) {
  REQUIRE_MATPLOTLIB();
  write_body(dir_ / "body.csv", 6.0, 0.01);
  {
    tk::CsvWriter csv(dir_ / "trajectory.csv", {"t", "v_forward", "tau_sea_1", "tau_sea_2", "u_1", "u_2", "com_x"});
    for (int i = 0; i <= 600; ++i) {
      const double t = 0.01 * i;
      csv.row({t, 0.01 + 0.02 * std::sin(kPi * t), 0.2 * std::sin(kPi * t), 0.2 * std::cos(kPi * t),
               0.25 * std::sin(kPi * t - 0.3), 0.25 * std::cos(kPi * t - 0.3), 0.01 * t});
    }
  }
  write(dir_ / "figures.json", std::string(R"({"title": "test, gait k_c = 0", "gait_period_s": 2.0,)") +
                                   R"( "average_speed_m_s": 0.01, "scene": )" + kScene + "}");
  const tk::FigureOutcome r = tk::draw_figures("simulate.py", {dir_.string()});
  ASSERT_EQ(r.status, Status::drawn) << r.message;
  for (const char* f : {"shapes.png", "gait_cycle.png", "paths.png", "torques.png", "speed.png"}) expect_figure(dir_ / f);
}

TEST_F(Figures, RecordingDrawsJointSignalsLoopTimingShapesAndPath) {
  REQUIRE_MATPLOTLIB();
  {
    std::ofstream js(dir_ / "run.joint_state.csv"), lt(dir_ / "run.loop_timing.csv");
    js << "seq,stamp_ns,alpha_1,alpha_2,tau_sea_1,tau_sea_2\n";
    lt << "seq,stamp_ns,wake_latency_ns\n";
    for (int k = 0; k < 300; ++k) {
      const double t = 0.01 * k;
      js << k << "," << static_cast<long long>(1e9 + t * 1e9) << "," << std::sin(kPi * t) << "," << std::cos(kPi * t)
         << "," << 0.1 * std::sin(kPi * t) << "," << 0.1 * std::cos(kPi * t) << "\n";
      lt << k << "," << static_cast<long long>(1e9 + t * 1e9) << "," << 80000 + 1000 * (k % 7) << "\n";
    }
    js << "300,4000000000,0.1\n";  // a line cut short (still being written): skipped, not fatal
  }
  const fs::path out = dir_ / "plots";
  fs::create_directories(out);
  write_body(out / "body.csv", 3.0, 0.01);
  const tk::FigureOutcome r = tk::draw_figures("recording.py", {(dir_ / "run").string(), out.string()});
  ASSERT_EQ(r.status, Status::drawn) << r.message;
  EXPECT_NE(r.message.find("run.joint_state.csv: data row 301 has 3 values"), std::string::npos) << r.message;
  for (const char* f : {"joint_signals.png", "loop_timing.png", "snake_shapes.png", "paths.png"}) expect_figure(out / f);
}

TEST_F(Figures, WorkprecDrawsErrorAgainstCostPerScene) {
  REQUIRE_MATPLOTLIB();
  {
    tk::CsvWriter csv(dir_ / "work_precision.csv", {"scene", "method", "status", "cpu_s", "com_err_max_m", "alpha_err_max_rad"});
    csv.comment("pedalwave_workprec: duration 2 s, reference dopri45 rtol 1e-09\nscene ids: 0=flat 1=stair\n"
                "method ids: 0=euler 3=rk4\nstatus: 0 ok");
    for (int s = 0; s < 2; ++s)
      for (int m : {0, 3})
        for (int k = 0; k < 4; ++k) {
          const double cost = 0.01 * std::pow(2.0, k) * (m + 1);
          csv.row({double(s), double(m), k == 0 && m == 0 ? 1.0 : 0.0, cost, 1e-3 * std::pow(cost, -(m + 1.0)) * 1e-4,
                   1e-2 * std::pow(cost, -(m + 1.0)) * 1e-4});
        }
  }
  const tk::FigureOutcome r = tk::draw_figures("workprec.py", {dir_.string()});
  ASSERT_EQ(r.status, Status::drawn) << r.message;
  for (const char* f : {"flat_com.png", "flat_alpha.png", "stair_com.png", "stair_alpha.png"}) expect_figure(dir_ / f);
}

TEST_F(Figures, PaperDrawsFromItsDataFolder) {
  REQUIRE_MATPLOTLIB();
  const fs::path data = dir_ / "data";
  fs::create_directories(data);
  for (const char* name : {"a", "b"}) {
    tk::CsvWriter csv(data / (std::string(name) + ".csv"), {"t", "com_x"});
    for (int i = 0; i <= 200; ++i) csv.row({0.05 * i, (name[0] == 'a' ? 0.02 : 0.015) * 0.05 * i});
  }
  write(data / "flat_com.json", R"({"kind": "flat_com", "avg_from": 2.0, "runs": [{"label": "μ = 0.82", "csv": "a.csv"},)"
                                R"( {"label": "μ = 0.40", "csv": "b.csv"}]})");
  {
    tk::CsvWriter csv(dir_ / "sweep.csv", {"k_c", "speed_m_s", "t_body_past_s"});
    for (int i = 0; i <= 30; ++i) csv.row({0.5 * i, 0.005 + 0.001 * std::sin(0.3 * i), i > 20 ? 40.0 : NAN});
  }
  write(data / "sweep_speed.json", R"({"kind": "sweep_speed", "csv": "../sweep.csv", "duration": 60, "v0": 0.005,)"
                                   R"( "paper_best_k_c": 10.1, "best": {"k_c": 5, "speed": 0.006, "gain_label": "+20.0 %"}})");
  const tk::FigureOutcome r = tk::draw_figures("paper.py", {dir_.string(), "flat_com", "sweep_speed"});
  ASSERT_EQ(r.status, Status::drawn) << r.message;
  expect_figure(dir_ / "flat_com.png");
  expect_figure(dir_ / "sweep_speed.png");
}

TEST_F(Figures, SoakDrawsTheTimingHistogramsAndTheMemory) {
  REQUIRE_MATPLOTLIB();
  std::string bins;
  for (int i = 0; i < 12; ++i)
    bins += "[" + std::to_string(10 * std::pow(1.5, i)) + "," + std::to_string(10 * std::pow(1.5, i + 1)) + "," +
            std::to_string(1000 / (1 + i * i)) + "],";
  bins += "[5000,100000,3]";
  const std::string stage = R"({"bins": [)" + bins + R"(], "p50": 30, "p99": 200, "max": 90000})";
  std::string memory;
  for (int t = 0; t < 60; t += 10)
    memory += std::string(t ? "," : "") + R"({"t_s": )" + std::to_string(t) + R"(, "rss_kB": 10000, "hwm_kB": 11000})";
  write(dir_ / "soak.json", R"({"report": {"rate_hz": 1000, "timing_us": {"wake": )" + stage + R"(, "read": )" + stage +
                                R"(}}, "memory": {"runtime": [)" + memory + R"(]}, "settings": {"duration_s": 60}})");
  const tk::FigureOutcome r =
      tk::draw_figures("soak.py", {(dir_ / "soak.json").string(), (dir_ / "soak.png").string()});
  ASSERT_EQ(r.status, Status::drawn) << r.message;
  expect_figure(dir_ / "soak.png");
}

// ---- bad data: the file and the column named ----------------------------------------------------

TEST_F(Figures, AMissingColumnNamesTheFileAndTheColumn) {
  REQUIRE_MATPLOTLIB();
  write_runtime_data(/*drop_u1=*/true);
  const tk::FigureOutcome r = tk::draw_figures("runtime.py", {dir_.string()});
  EXPECT_EQ(r.status, Status::failed) << r.message;
  EXPECT_NE(r.message.find((dir_ / "cycles.csv").string() + ": no column 'u_1'"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(dir_ / "runtime_signals.png"));
}

TEST_F(Figures, ARaggedRowOrAMissingKeyIsAClearError) {
  REQUIRE_MATPLOTLIB();
  write(dir_ / "work_precision.csv", "scene,method,status,cpu_s,com_err_max_m,alpha_err_max_rad\n0,0,0,1,2,3\n0,0,0\n");
  tk::FigureOutcome r = tk::draw_figures("workprec.py", {dir_.string()});
  EXPECT_EQ(r.status, Status::failed) << r.message;
  EXPECT_NE(r.message.find("work_precision.csv: data row 2 has 3 values but the header names 6 columns"),
            std::string::npos) << r.message;
  fs::create_directories(dir_ / "data");
  write(dir_ / "data" / "x.json", R"({"kind": "flat_com"})");
  r = tk::draw_figures("paper.py", {dir_.string(), "x"});
  EXPECT_EQ(r.status, Status::failed) << r.message;
  EXPECT_NE(r.message.find("x.json: no key 'runs'"), std::string::npos) << r.message;
}

// ---- no matplotlib: skipped, with the reason -----------------------------------------------------

TEST_F(Figures, WithoutMatplotlibTheFiguresAreSkippedWithTheReason) {
  write_runtime_data();
  // An interpreter that runs but cannot import matplotlib: Debian's python3 without its site
  // packages (-S leaves /usr/lib/python3/dist-packages out of sys.path).
  const fs::path wrapper = dir_ / "python-without-matplotlib";
  write(wrapper, "#!/bin/sh\nexec /usr/bin/python3 -S \"$@\"\n");
  fs::permissions(wrapper, fs::perms::owner_all);
  setenv("PEDALWAVE_PYTHON", wrapper.c_str(), 1);
  tk::FigureOutcome r = tk::draw_figures("runtime.py", {dir_.string()});
  EXPECT_EQ(r.status, Status::skipped) << r.message;
  EXPECT_EQ(r.message.rfind("figures skipped: ", 0), 0u) << r.message;
  EXPECT_NE(r.message.find("cannot import"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("python3-matplotlib"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(dir_ / "runtime_signals.png"));
  // No interpreter at all.
  setenv("PEDALWAVE_PYTHON", (dir_ / "no-such-python").c_str(), 1);
  r = tk::draw_figures("runtime.py", {dir_.string()});
  EXPECT_EQ(r.status, Status::skipped) << r.message;
  EXPECT_NE(r.message.find("figures skipped: cannot run the interpreter " + (dir_ / "no-such-python").string()),
            std::string::npos) << r.message;
  // No such script.
  unsetenv("PEDALWAVE_PYTHON");
  r = tk::draw_figures("no_such_family.py", {dir_.string()});
  EXPECT_EQ(r.status, Status::skipped) << r.message;
  EXPECT_NE(r.message.find("no_such_family.py is not there"), std::string::npos) << r.message;
}

TEST_F(Figures, TheScriptsAreFoundInTheSourceTreeAndTheInterpreterIsDebians) {
  EXPECT_TRUE(fs::is_regular_file(tk::figures_dir() / "pwfig.py")) << tk::figures_dir();
  // Installed (the source tree gone): <prefix>/share/pedalwave/figures.
  EXPECT_EQ(tk::pick_figures_dir("/nonexistent/pedalwave/tools/figures", "/usr/share/pedalwave/figures"),
            fs::path("/usr/share/pedalwave/figures"));
  EXPECT_EQ(tk::pick_figures_dir(dir_, "/usr/share/pedalwave/figures"), dir_);
  EXPECT_EQ(tk::figure_python(), "/usr/bin/python3");
  setenv("PEDALWAVE_PYTHON", "/opt/py/bin/python3", 1);
  EXPECT_EQ(tk::figure_python(), "/opt/py/bin/python3");
}

}  // namespace
