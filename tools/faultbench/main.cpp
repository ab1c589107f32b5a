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

struct Trial {
  std::string scene;
  model::FaultSpec fault;
  faultbench::RunResult res;
};

const char* check_of(model::FaultType f) {
  using model::FaultType;
  switch (f) {
    case FaultType::kTorqueGain:
    case FaultType::kMotorFriction:
    case FaultType::kSpringScale:
    case FaultType::kDeflectionBias:
    case FaultType::kDeflectionScale: return "momentum residual |r| + LS signature";
    case FaultType::kEncoderOffset:
    case FaultType::kEncoderNoise: return "consistency c = Δβ − T·mean(β̇)";
    case FaultType::kEncoderStuck:
    case FaultType::kDeflectionStuck: return "hold (bit-identical) while moving";
    case FaultType::kNaN:
    case FaultType::kImplausible: return "finite / range";
    case FaultType::kModuleSilent: return "kStatusMissing run";
    case FaultType::kStale:
    case FaultType::kOutOfOrder: return "stale/out-of-order flags in window";
    case FaultType::kRepeatedFrame: return "seq not increasing in window";
    case FaultType::kJointLoad: return "demand beyond u_max, low-passed";
    default: return "?";
  }
}

std::vector<Trial> campaign(int trials, int jobs, std::uint64_t seed, bool verbose) {
  std::vector<Trial> all;
  std::mt19937_64 rng(seed);
  for (const char* scene : {"flat_high_friction", "stair"})
    for (int f = 0; f < static_cast<int>(model::FaultType::kCount); ++f)
      for (int i = 0; i < trials; ++i)
        all.push_back({scene, faultbench::random_fault(static_cast<model::FaultType>(f), 5, 2.0, 8.0, rng), {}});
  std::mutex mu;
  parallel_for(static_cast<int>(all.size()), jobs, [&](int i) {
    Trial& tr = all[static_cast<std::size_t>(i)];
    LoopOptions o;
    o.seed = seed + 1000 + static_cast<std::uint64_t>(i);
    tr.res = faultbench::run_fault(faultbench::shipped_scene(tr.scene), o, tr.fault,
                                   tr.fault.t_start + 5.0);
    if (verbose) {
      std::lock_guard<std::mutex> lock(mu);
      std::fprintf(stderr, "%s %s j%d v=%.4g t0=%.3f -> %s j%d lat=%.3f est=%.3g\n", tr.scene.c_str(),
                   std::string(model::to_string(tr.fault.type)).c_str(), tr.fault.joint, tr.fault.value,
                   tr.fault.t_start, faultbench::class_name(tr.res.fault), tr.res.joint, tr.res.latency,
                   tr.res.estimate);
    }
  });
  return all;
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
  int trials = 0;
  std::uint64_t seed = 7;
  bool verbose = false;
  app.add_option("--trials", trials, "random injections per fault type and scene");
  app.add_option("--seed", seed, "campaign seed");
  app.add_flag("-v,--verbose", verbose, "one line per trial on stderr");
  bool no_noise = false;
  app.add_option("--trace", trace_s, "print a trace of the flat scene for this long [s]");
  app.add_flag("--no-noise", no_noise, "sensor noise off");
  CLI11_PARSE(app, argc, argv);
  if (trace_s > 0) return trace(trace_s, !no_noise);
  if (calib) return calibrate(minutes, jobs);
  if (trials > 0) {
    auto all = campaign(trials, jobs, seed, verbose);
    (void)all;
  }
  return 0;
}
