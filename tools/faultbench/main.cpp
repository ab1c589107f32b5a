// pedalwave_faultbench: see CMakeLists.txt. Modes:
//   (default)     injection campaign + nominal runs + compute time → Markdown tables on stdout
//   --calibrate   nominal residual/consistency/hold/saturation statistics per scene (thresholds)
#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"

#include <algorithm>
#include <time.h>

#include <chrono>
#include <cmath>
#include <string>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <vector>

#include "harness.hpp"
#include "pedalwave/campaign/campaign.hpp"
#include "pedalwave/campaign/cli.hpp"
#include "pedalwave/toolkit/format.hpp"
#include "pedalwave/toolkit/table.hpp"
#include "pedalwave/interface/clock.hpp"

using namespace pedalwave;
using faultbench::LoopOptions;
namespace campaign = pedalwave::campaign;
namespace tk = pedalwave::toolkit;

namespace {

// The tools' one thread pool (pedalwave::campaign), over int indices.
template <class F>
void parallel_for(int n, int jobs, F&& f) {
  campaign::parallel_for(static_cast<std::size_t>(std::max(n, 0)), jobs,
                         [&](std::size_t i) { f(static_cast<int>(i)); });
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
  tk::Table t({"scene", "k_c", "s", "max r [N·m]", "rms r", "max c [rad]", "max sat", "hold β", "hold def", "alarms",
              "first"});
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const auto& s = st[i];
    t.add_row({cases[i].scene, tk::sig(cases[i].k_c), tk::fixed(s.seconds, 0), tk::sig(s.max_residual, 4),
               tk::sig(s.rms_residual, 3), tk::sig(s.max_consistency, 3), tk::sig(s.max_saturation, 3),
               std::to_string(s.max_hold_beta), std::to_string(s.max_hold_defl), std::to_string(s.alarms),
               std::string(faultbench::class_name(s.first)) + " j" + std::to_string(s.first_joint) +
                   " t=" + tk::fixed(s.first_t, 2) + " v=" + tk::sig(s.first_value, 3)});
  }
  std::printf("%s", t.to_markdown().c_str());
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

// One injection trial as a campaign's line of text: the scene (a shipped one, built in code), the
// fault, the noise seed and the run's length; the result's every field, doubles exact.
std::string encode_trial(const std::string& scene, const model::FaultSpec& f, std::uint64_t seed, double duration) {
  campaign::Record r;
  r.put_text("kind", "faultbench.trial")
      .put_text("scene", scene)
      .put_int("type", static_cast<long long>(f.type))
      .put_int("joint", f.joint)
      .put("t_start", f.t_start)
      .put("value", f.value)
      .put("fault_duration", f.duration)
      .put_text("seed", std::to_string(seed))
      .put("duration", duration);
  return r.line();
}

std::string run_trial_line(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_faultbench trial");
  if (r.text("kind") != "faultbench.trial")
    throw std::invalid_argument("trial: kind = " + r.text("kind") + ": expected faultbench.trial");
  const long long type = r.integer("type");
  if (type < 0 || type >= static_cast<long long>(model::FaultType::kCount))
    throw std::invalid_argument("trial: type = " + std::to_string(type) + ": expected a fault type");
  model::FaultSpec f;
  f.type = static_cast<model::FaultType>(type);
  f.joint = static_cast<int>(r.integer("joint"));
  f.t_start = r.number("t_start");
  f.value = r.number("value");
  f.duration = r.number("fault_duration");
  LoopOptions o;
  o.seed = std::stoull(r.text("seed"));
  const faultbench::RunResult x = faultbench::run_fault(faultbench::shipped_scene(r.text("scene")), o, f,
                                                        r.number("duration"));
  campaign::Record out;
  out.put_int("detected", x.detected)
      .put_int("false_alarm", x.false_alarm)
      .put_int("fault", static_cast<long long>(x.fault))
      .put_int("joint", x.joint)
      .put("t_detect", x.t_detect)
      .put("latency", x.latency)
      .put("value", x.value)
      .put("threshold", x.threshold)
      .put("estimate", x.estimate)
      .put_int("status", static_cast<long long>(x.status));
  return out.line();
}

faultbench::RunResult decode_trial_result(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_faultbench trial result");
  faultbench::RunResult x;
  x.detected = r.integer("detected") != 0;
  x.false_alarm = r.integer("false_alarm") != 0;
  x.fault = static_cast<runtime::FaultClass>(r.integer("fault"));
  x.joint = static_cast<int>(r.integer("joint"));
  x.t_detect = r.number("t_detect");
  x.latency = r.number("latency");
  x.value = r.number("value");
  x.threshold = r.number("threshold");
  x.estimate = r.number("estimate");
  x.status = static_cast<model::StepStatus>(r.integer("status"));
  return x;
}

// The injection trials as one campaign (Options: threads or Slurm job arrays).
std::vector<Trial> injection_campaign(int trials, const campaign::Options& co, std::uint64_t seed, bool verbose,
                                      const std::string& only) {
  std::vector<Trial> all;
  std::mt19937_64 rng(seed);
  for (const char* scene : {"flat_high_friction", "stair"})
    for (int f = 0; f < static_cast<int>(model::FaultType::kCount); ++f)
      for (int i = 0; i < trials; ++i)
        all.push_back({scene, faultbench::random_fault(static_cast<model::FaultType>(f), 5, 2.0, 8.0, rng), {}});
  if (!only.empty())  // same draws, then keep one type (to rerun part of a campaign)
    std::erase_if(all, [&](const Trial& t) { return model::to_string(t.fault.type) != only; });
  std::vector<std::string> specs;
  for (std::size_t i = 0; i < all.size(); ++i)
    specs.push_back(encode_trial(all[i].scene, all[i].fault, seed + 1000 + static_cast<std::uint64_t>(i),
                                 all[i].fault.t_start + 5.0));
  const std::vector<std::string> res = campaign::run("faultbench", specs, run_trial_line, co);
  for (std::size_t i = 0; i < all.size(); ++i) {
    Trial& tr = all[i];
    tr.res = decode_trial_result(res[i]);
    if (verbose)
      std::fprintf(stderr, "%s %s j%d v=%.4g t0=%.3f -> %s j%d lat=%.3f est=%.3g\n", tr.scene.c_str(),
                   std::string(model::to_string(tr.fault.type)).c_str(), tr.fault.joint, tr.fault.value,
                   tr.fault.t_start, faultbench::class_name(tr.res.fault), tr.res.joint, tr.res.latency,
                   tr.res.estimate);
  }
  return all;
}

std::string threshold_of(model::FaultType f, const observer::ObserverParams& p) {
  using model::FaultType;
  char b[160];
  switch (f) {
    case FaultType::kTorqueGain:
    case FaultType::kMotorFriction:
    case FaultType::kSpringScale:
    case FaultType::kDeflectionBias:
    case FaultType::kDeflectionScale:
      std::snprintf(b, sizeof b, "|r| > %.3g N·m, then %.1f + %.1f s fit", p.r_threshold, p.t_transient, p.t_classify);
      break;
    case FaultType::kEncoderOffset:
      std::snprintf(b, sizeof b, "|c| > %.1e rad, alone in %d cycles", p.consistency_threshold, p.jump_window);
      break;
    case FaultType::kEncoderNoise:
      std::snprintf(b, sizeof b, "|c| > %.1e rad, %d more in %d cycles", p.consistency_threshold, p.noise_spikes, p.jump_window);
      break;
    case FaultType::kEncoderStuck:
      std::snprintf(b, sizeof b, "%d identical, β_ref moved > %.0e rad", p.hold_cycles, p.hold_motion);
      break;
    case FaultType::kDeflectionStuck:
      std::snprintf(b, sizeof b, "%d identical, β moved > %.0e rad", p.hold_cycles_deflection, p.hold_motion);
      break;
    case FaultType::kNaN:
    case FaultType::kImplausible:
      std::snprintf(b, sizeof b, "|β| > %.1f, |β̇| > %.0f, |def| > %.1f", p.beta_max, p.beta_dot_max, p.deflection_max);
      break;
    case FaultType::kModuleSilent: std::snprintf(b, sizeof b, "%d missing in a row", p.missing_cycles); break;
    case FaultType::kStale:
    case FaultType::kOutOfOrder:
    case FaultType::kRepeatedFrame:
      std::snprintf(b, sizeof b, "%d in %d cycles", p.stale_count, p.stale_window);
      break;
    case FaultType::kJointLoad:
      std::snprintf(b, sizeof b, "LP(τ=%.2f s) of |u| ≥ u_max > %.1f", p.saturation_tau, p.saturation_fraction);
      break;
    default: b[0] = 0;
  }
  return b;
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::min<double>(v.size() - 1, std::floor(q * static_cast<double>(v.size()))))];
}

void print_campaign(const std::vector<Trial>& all) {
  const auto p = faultbench::campaign_params(faultbench::shipped_scene("flat_high_friction"));
  tk::Table tab({"fault (injected)", "named class", "residual / check", "threshold", "detected", "latency median [ms]",
              "latency max [ms]", "isolation (class + joint)"});
  for (int f = 0; f < static_cast<int>(model::FaultType::kCount); ++f) {
    const auto type = static_cast<model::FaultType>(f);
    std::vector<double> lat;
    int n = 0, det = 0, iso = 0;
    for (const Trial& t : all) {
      if (t.fault.type != type) continue;
      ++n;
      if (t.res.detected && !t.res.false_alarm) {
        ++det;
        lat.push_back(t.res.latency * 1e3);
        if (t.res.fault == faultbench::expected_class(type) && t.res.joint == faultbench::expected_joint(t.fault)) ++iso;
      }
    }
    if (n == 0) continue;
    tab.add_row({std::string(model::to_string(type)), faultbench::class_name(faultbench::expected_class(type)),
               check_of(type), threshold_of(type, p), std::to_string(det) + "/" + std::to_string(n),
               tk::fixed(quantile(lat, 0.5), 0), tk::fixed(quantile(lat, 1.0), 0),
               std::to_string(iso) + "/" + std::to_string(n) + " (" + tk::fixed(100.0 * iso / std::max(1, n), 0) + " %)"});
  }
  std::printf("%s", tab.to_markdown().c_str());
}

struct NominalCase { const char* scene; double k_c; };

void nominal(double minutes, int jobs) {
  const std::vector<NominalCase> cases = {{"flat_high_friction", 0}, {"flat_low_friction", 0},
                                          {"friction_change", 0},    {"stair", 0},
                                          {"stair", 15},             {"friction_change", 15},
                                          {"flat_high_friction", 15}, {"flat_low_friction", 15},
                                          {"stair_grip", 0},          {"stair_grip", 15}};
  std::vector<faultbench::NominalStats> st(cases.size());
  parallel_for(static_cast<int>(cases.size()), jobs, [&](int i) {
    const auto& c = cases[static_cast<std::size_t>(i)];
    model::Scene s = faultbench::shipped_scene(c.scene);
    s.torque_limit_on = true;
    s.torque_limit.u_max = 0.8;
    LoopOptions o;
    o.k_c = c.k_c;
    o.seed = 9000 + static_cast<std::uint64_t>(i);
    st[static_cast<std::size_t>(i)] = faultbench::run_nominal(s, o, minutes * 60.0);
  });
  double total = 0.0;
  int alarms = 0;
  tk::Table t({"nominal run (noise on, u_max = 0.8 N·m)", "k_c", "simulated [min]", "false alarms", "max |r| [N·m]",
              "max |c| [rad]", "longest hold β / def [cycles]", "max saturation LP"});
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const auto& s = st[i];
    total += s.seconds;
    alarms += s.alarms;
    t.add_row({cases[i].scene, tk::sig(cases[i].k_c), tk::fixed(s.seconds / 60.0, 1),
               std::to_string(s.alarms) + (s.alarms ? std::string(" first: ") + faultbench::class_name(s.first) : ""),
               tk::fixed(s.max_residual, 4), tk::sci(s.max_consistency, 1),
               std::to_string(s.max_hold_beta) + " / " + std::to_string(s.max_hold_defl), tk::fixed(s.max_saturation, 3)});
  }
  std::printf("%s", t.to_markdown().c_str());
  std::printf("\n**False alarms: %d over %.2f nominal hours simulated.**\n", alarms, total / 3600.0);
}

void timing(int cycles) {
  tk::Table t({"N", "joints", "observe() median [µs]", "p99 [µs]", "max [µs]", "without body model median [µs]"});
  for (int N : {6, 24}) {
    model::Scene s = faultbench::shipped_scene("flat_high_friction");
    s.robot = model::paper_params(N);
    double med[2] = {0, 0}, p99 = 0, mx = 0;
    for (int body = 1; body >= 0; --body) {
      LoopOptions o;
      auto op = faultbench::campaign_params(s);
      op.body_model = body == 1;
      faultbench::FaultLoop loop(s, o, op);
      for (int i = 0; i < 500; ++i) loop.step();
      // Re-run observe on the live feedback of each cycle on a twin observer (the loop's own one
      // keeps running), timed alone.
      observer::RuntimeObserver twin(op);
      runtime::CycleSample sample{};
      std::vector<double> us;
      us.reserve(static_cast<std::size_t>(cycles));
      drivers::Command last = loop.command();
      for (int i = 0; i < cycles; ++i) {
        loop.step();
        // Thread CPU time: what observe() costs, without the preemptions of a shared machine.
        const std::int64_t a = clock_ns(CLOCK_THREAD_CPUTIME_ID);
        (void)twin.observe(loop.feedback(), last, loop.t(), 1e-3, sample);
        const std::int64_t b = clock_ns(CLOCK_THREAD_CPUTIME_ID);
        last = loop.command();
        us.push_back(static_cast<double>(b - a) * 1e-3);
      }
      med[body] = quantile(us, 0.5);
      if (body == 1) p99 = quantile(us, 0.99), mx = quantile(us, 1.0);
    }
    t.add_row({std::to_string(N), std::to_string(N - 1), tk::fixed(med[1], 1), tk::fixed(p99, 1), tk::fixed(mx, 1),
               tk::fixed(med[0], 1)});
  }
  std::printf("%s", t.to_markdown().c_str());
}

// The motor rows' neglected coupling n I_r θ̈_j (θ_j = the stator link's absolute angle), from the
// plant's true state differenced at the cycle rate: max and rms over a run.
std::vector<std::string> coupling(const char* scene, double seconds) {
  LoopOptions o;
  o.noise = false;
  faultbench::FaultLoop loop(faultbench::shipped_scene(scene), o);
  const auto& m = loop.sim().sim().plant().model();
  const int J = m.joints();
  std::vector<double> th0(static_cast<std::size_t>(J)), th1(th0), th2(th0);
  double mx = 0, s2 = 0;
  long n = 0;
  const double nIr = m.params().n * m.params().I_r;
  for (int i = 0; i < static_cast<int>(seconds / o.period); ++i) {
    loop.step();
    const auto& q = loop.sim().sim().q();
    th0 = th1;
    th1 = th2;
    for (int j = 0; j < J; ++j) {
      double th = q(m.i_theta_N());
      for (int k = j; k < J; ++k) th += q(m.i_alpha(k));
      th2[static_cast<std::size_t>(j)] = th;
    }
    if (loop.t() < 1.0) continue;
    for (int j = 0; j < J; ++j) {
      const auto k = static_cast<std::size_t>(j);
      const double acc = (th2[k] - 2 * th1[k] + th0[k]) / (o.period * o.period);
      mx = std::max(mx, std::abs(nIr * acc));
      s2 += nIr * acc * nIr * acc;
      ++n;
    }
  }
  return {scene, tk::sci(mx, 2), tk::sci(std::sqrt(s2 / static_cast<double>(n)), 2)};
}

int main(int argc, char** argv) {
  if (campaign::cli::is_worker(argc, argv))
    return campaign::worker_main(argc - 1, argv + 1, run_trial_line, "pedalwave_faultbench");
  CLI::App app{"pedalwave_faultbench: observer fault-injection campaign"};
  campaign::cli::CliOptions camp;
  campaign::cli::add_options(&app, camp, "out/faultbench-campaign");  // the injection trials' backend
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
  double nominal_minutes = 0;
  double coupling_s = 0;
  app.add_option("--coupling", coupling_s, "measure the neglected coupling n I_r θ̈ over this long [s]");
  int timing_cycles = 0;
  app.add_option("--nominal-minutes", nominal_minutes, "simulated minutes per nominal run (8 runs)");
  app.add_option("--timing-cycles", timing_cycles, "cycles timed per N for the compute-time table");
  app.add_option("--seed", seed, "campaign seed");
  app.add_flag("-v,--verbose", verbose, "one line per trial on stderr");
  std::string only;
  app.add_option("--only", only, "campaign: only this fault type (same random draws)");
  bool no_noise = false;
  app.add_option("--trace", trace_s, "print a trace of the flat scene for this long [s]");
  app.add_flag("--no-noise", no_noise, "sensor noise off");
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_faultbench")) return *rc;
  // What escapes (a shipped scene the reader refuses, a refused value: 2; else 1) is one line, not
  // std::terminate.
  return pedalwave::toolkit::cli::run("pedalwave_faultbench", [&]() -> int {
    if (trace_s > 0) return trace(trace_s, !no_noise);
    if (calib) return calibrate(minutes, jobs);
    if (coupling_s > 0) {
      pedalwave::toolkit::Table t({"scene", "max |n I_r θ̈_j| [N·m]", "rms [N·m]"});
      for (const char* sc : {"flat_high_friction", "stair"}) t.add_row(coupling(sc, coupling_s));
      std::printf("%s", t.to_markdown().c_str());
      return 0;
    }
    if (trials <= 0 && nominal_minutes <= 0 && timing_cycles <= 0) {
      std::fprintf(stderr, "nothing to do: give --trials, --nominal-minutes or --timing-cycles\n");
      return 2;
    }
    if (trials > 0) {
      const campaign::Options co = campaign::cli::options(camp, jobs, false);  // a refused file: before any output
      std::printf("## Fault-injection campaign: %d random injections per fault and scene (flat_high_friction, stair), onset uniform in 2…8 s, joint uniform, sensor noise on\n\n", trials);
      print_campaign(injection_campaign(trials, co, seed, verbose, only));
      std::printf("\n");
    }
    if (nominal_minutes > 0) {
      std::printf("## Nominal runs (false alarms)\n\n");
      nominal(nominal_minutes, jobs);
      std::printf("\n");
    }
    if (timing_cycles > 0) {
      std::printf("## Observer compute time per cycle (one run, %d cycles each, thread CPU time, this machine)\n\n", timing_cycles);
      timing(timing_cycles);
    }
    return 0;
  });
}
