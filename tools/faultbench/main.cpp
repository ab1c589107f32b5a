// pedalwave_faultbench: see CMakeLists.txt. Modes:
//   (default)     injection campaign + nominal runs + compute time → Markdown tables on stdout
//   --calibrate   nominal residual/consistency/hold/saturation statistics per scene (thresholds)
#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "harness.hpp"

using namespace pedalwave;
using faultbench::LoopOptions;

namespace {

template <class F>
void parallel_for(int n, int jobs, F&& f) {
  std::atomic<int> next{0};
  std::vector<std::thread> ts;
  for (int w = 0; w < std::max(1, jobs); ++w)
    ts.emplace_back([&] {
      for (int i; (i = next.fetch_add(1)) < n;) f(i);
    });
  for (auto& t : ts) t.join();
}

int calibrate(double minutes, int jobs) {
  struct Case { const char* scene; double k_c; };
  const std::vector<Case> cases = {{"flat_high_friction", 0}, {"flat_low_friction", 0},
                                   {"friction_change", 0},    {"stair", 0},
                                   {"stair", 15},             {"flat_high_friction", 15}};
  std::vector<faultbench::NominalStats> st(cases.size());
  parallel_for(static_cast<int>(cases.size()), jobs, [&](int i) {
    LoopOptions o;
    o.k_c = cases[static_cast<std::size_t>(i)].k_c;
    o.seed = 100 + static_cast<std::uint64_t>(i);
    st[static_cast<std::size_t>(i)] =
        faultbench::run_nominal(faultbench::shipped_scene(cases[static_cast<std::size_t>(i)].scene), o, minutes * 60.0);
  });
  std::printf("| scene | k_c | s | max r [N·m] | rms r | max c [rad] | max sat | hold β | hold def | alarms | first |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const auto& s = st[i];
    std::printf("| %s | %g | %.0f | %.4g | %.3g | %.3g | %.3g | %d | %d | %d | %s j%d t=%.2f v=%.3g |\n", cases[i].scene,
                cases[i].k_c, s.seconds, s.max_residual, s.rms_residual, s.max_consistency,
                s.max_saturation, s.max_hold_beta, s.max_hold_defl, s.alarms,
                faultbench::class_name(s.first), s.first_joint, s.first_t, s.first_value);
  }
  return 0;
}

}  // namespace


int trace(double seconds, bool noise) {
  LoopOptions o;
  o.noise = noise;
  faultbench::FaultLoop loop(faultbench::shipped_scene("flat_high_friction"), o);
  const auto n = static_cast<int>(seconds / o.period);
  for (int i = 0; i < n; ++i) {
    loop.step();
    const auto& c = loop.observer().core();
    std::printf("%.3f %.5f %.5f %.6f %.5f %.5f %.5f %.5f %.4f %.4f\n", loop.t(), c.residual()[0],
                c.residual()[2], c.consistency()[0], loop.control().u[0], loop.feedback().deflection[0] * 3,
                c.tau_ext()[0], c.tau_ext()[2], c.body()[1], c.body()[2]);
  }
  return 0;
}

int main(int argc, char** argv) {
  CLI::App app{"pedalwave_faultbench: observer fault-injection campaign"};
  bool calib = false;
  double minutes = 1.0;
  int jobs = 2;
  app.add_flag("--calibrate", calib, "nominal statistics per scene");
  app.add_option("--minutes", minutes, "simulated minutes per nominal run");
  app.add_option("--jobs", jobs, "worker threads");
  double trace_s = 0;
  bool no_noise = false;
  app.add_option("--trace", trace_s, "print a trace of the flat scene for this long [s]");
  app.add_flag("--no-noise", no_noise, "sensor noise off");
  CLI11_PARSE(app, argc, argv);
  if (trace_s > 0) return trace(trace_s, !no_noise);
  if (calib) return calibrate(minutes, jobs);
  return 0;
}
