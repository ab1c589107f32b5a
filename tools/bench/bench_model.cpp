// pedalwave_bench_model: what one evaluation of the plant model costs, and what each scene effect
// adds (Google Benchmark). Benchmarks:
//   forward_dynamics/<recursive|dense>/<flexible|rigid>/N:<n>
//                                             model::forward_dynamics with each solver,
//                                             N = 2, 6, 16, 32, 64
//   acceleration/<effects>                    Plant::acceleration with the shipped scenes' effects
//                                             switched on one at a time (N = 6, module PD input);
//                                             the link-shape rows (…/capsule, …/box_links) against
//                                             the segment row they replace ("over")
//   implicit_terms/<effects>                  Plant::implicit_terms (velocity-implicit Jacobians)
//   integrator_step/<method>                  one step of each integrator on the flat scene (and
//                                             implicit_contact_fresh: jacobian_age 0)
// After the runs it prints (stdout) the cost-versus-N table of both solvers with the exponent fitted
// to the N = 16 … 64 points, the effect table, and the checks of the targets: ≤ 2 µs for one flexible
// N = 6 forward-dynamics evaluation; the recursive solver (issue 19) at N = 64 ≤ 10 µs, cost(64) /
// cost(6) ≤ 15, and at N = 6 no slower than the dense one — ratios of one run. Usual Google Benchmark flags apply
// (--benchmark_filter=..., --benchmark_repetitions=..., --benchmark_min_time=...).
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/dynamics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/toolkit/cli.hpp"
#include "pedalwave/toolkit/table.hpp"

namespace {

using pedalwave::model::Data;
using pedalwave::model::Integrator;
using pedalwave::model::IntegratorOptions;
using pedalwave::model::Method;
using pedalwave::model::Model;
using pedalwave::model::Params;
using pedalwave::model::Plant;
using pedalwave::model::Scene;
using pedalwave::model::VectorXd;
using pedalwave::toolkit::Table;

constexpr double kTargetNs = 2000.0;  // project target: one N = 6 flexible evaluation [ns]
constexpr double kTarget64Ns = 10000.0;  // issue 19: recursive N = 64 flexible [ns]
constexpr double kTargetRatio = 15.0;    // issue 19: recursive cost(64) / cost(6)
const std::vector<int> kSizes = {2, 6, 16, 32, 64};
using pedalwave::model::ForwardSolver;
constexpr ForwardSolver kSolvers[] = {ForwardSolver::kRecursive, ForwardSolver::kDense};

// A generic moving state: joints bent like the gait, every coordinate moving, springs deflected.
void moving_state(const Model& m, VectorXd& q, VectorXd& v) {
  q = VectorXd::Zero(m.nq());
  v = VectorXd::Zero(m.nq());
  for (int j = 0; j < m.joints(); ++j) {
    q(m.i_alpha(j)) = 0.7 * std::sin(-1.2566 * j);
    v(m.i_alpha(j)) = 0.5 * std::cos(0.9 * j);
    if (m.flexible()) {
      q(m.i_beta(j)) = q(m.i_alpha(j)) + 0.02 * std::sin(1.3 * j);
      v(m.i_beta(j)) = v(m.i_alpha(j)) + 0.1;
    }
  }
  q(m.i_theta_N()) = 0.1;
  q(m.i_pz()) = 0.05;
  v(m.i_theta_N()) = 0.3;
  v(m.i_px()) = 0.02;
  v(m.i_pz()) = -0.01;
}

// ---- forward dynamics ---------------------------------------------------------------------------

void bm_forward_dynamics(benchmark::State& st, int N, bool flexible, ForwardSolver solver) {
  Params p = pedalwave::model::paper_params(N);
  p.joints = flexible ? pedalwave::model::JointModel::kFlexible : pedalwave::model::JointModel::kRigid;
  const Model m(p);
  Data d(m);
  VectorXd q, v;
  moving_state(m, q, v);
  VectorXd u = VectorXd::Constant(m.joints(), 0.05);
  VectorXd Q;  // no external force
  VectorXd qdd = VectorXd::Zero(m.nq());
  for (auto _ : st) {
    benchmark::DoNotOptimize(q.data());
    const bool ok = pedalwave::model::forward_dynamics(m, d, q, v, u, Q, qdd, solver);
    benchmark::DoNotOptimize(ok);
    benchmark::DoNotOptimize(qdd.data());
    benchmark::ClobberMemory();
  }
  st.counters["nq"] = m.nq();
}

// ---- plant effects --------------------------------------------------------------------------------

Scene shipped(const char* name) {
  return pedalwave::config::load_scene(std::string(PEDALWAVE_CONFIG_DIR) + "/scenes/" + name +
                                       ".yaml");
}

// The effect stacks, cumulative from "ground" on, built from the shipped scenes.
struct EffectCase {
  std::string name;   // benchmark name suffix
  std::string what;   // table text
  std::string base;   // the case this one adds an effect to (empty: none)
  Scene scene;
};

std::vector<EffectCase> effect_cases() {
  std::vector<EffectCase> out;
  Scene flat = shipped("flat_high_friction");
  Scene none = flat;
  none.ground_on = false;
  out.push_back({"no_contact", "no contact (dynamics + motor law only)", "", none});
  out.push_back({"ground", "ground (flat_high_friction)", "no_contact", flat});
  out.push_back({"ground+patches", "ground + μ patch (friction_change)", "ground",
                 shipped("friction_change")});
  Scene stair = shipped("stair");
  out.push_back({"ground+box_far", "ground + box out of reach (stair, broad phase)", "ground", stair});
  // The box under the raised front of the gait-start shape: a body point inside it (top face)
  // and its corners tested against every link.
  Scene reach = stair;
  reach.boxes[0].ahead_of_head = std::numeric_limits<double>::quiet_NaN();
  reach.boxes[0].x_near = 0.0;
  out.push_back({"ground+box", "ground + box in reach (faces + corner segments)", "ground", reach});
  // Thick links (README "Link shapes"): the same contacts with the modules' surface, against the
  // segment rows they replace.
  auto shaped = [](Scene sc, pedalwave::model::LinkShape shape) {
    sc.robot.link_shape = shape;
    if (shape == pedalwave::model::LinkShape::kCapsule) sc.robot.link_radius = 0.015;
    else sc.robot.link_height = 0.03;
    return sc;
  };
  using pedalwave::model::LinkShape;
  out.push_back({"ground/capsule", "ground, capsule links r = 1.5 cm", "ground", shaped(flat, LinkShape::kCapsule)});
  out.push_back({"ground/box_links", "ground, box links h_m = 3 cm", "ground", shaped(flat, LinkShape::kBox)});
  out.push_back({"ground+box_far/capsule", "ground + box out of reach, capsule links", "ground+box_far",
                 shaped(stair, LinkShape::kCapsule)});
  out.push_back({"ground+box/capsule", "ground + box in reach, capsule links", "ground+box",
                 shaped(reach, LinkShape::kCapsule)});
  out.push_back({"ground+box/box_links", "ground + box in reach, box links", "ground+box",
                 shaped(reach, LinkShape::kBox)});
  Scene limits = reach;
  limits.joint_friction_on = true;
  limits.joint_friction.motor_viscous = 0.01;
  limits.torque_limit_on = true;
  limits.torque_limit.u_max = 1.0;
  out.push_back({"+joint_friction+torque_limit", "… + joint friction + torque limit", "ground+box",
                 limits});
  Scene stick = limits;
  stick.ground.law = pedalwave::model::FrictionLaw::kStickSlip;
  out.push_back({"+stick_slip", "… + stick-slip friction law", "+joint_friction+torque_limit",
                 stick});
  return out;
}

// Plant at its scene's initial state pressed 2 mm into the ground (contacts carry force), moving,
// with the module PD of the paper driving the motors toward the gait's first shape.
struct PlantFixture {
  explicit PlantFixture(const Scene& s) : plant(s) {
    plant.initial_state(q, v);
    const Model& m = plant.model();
    VectorXd qm, vm;
    moving_state(m, qm, vm);
    v = 0.2 * vm;
    q(m.i_pz()) -= 0.002;
    auto& in = plant.input();
    for (int j = 0; j < m.joints(); ++j) {
      in.kp(j) = 30.0;
      in.kd(j) = 15.0;
      in.beta_ref(j) = 0.7 * std::sin(0.3 + -1.2566 * j);
      in.beta_dot_ref(j) = 0.5;
    }
    plant.after_step(q, v);  // stick–slip anchors of the penetrating points
    plant.after_step(q, v);
    a = VectorXd::Zero(m.nq());
  }
  Plant plant;
  VectorXd q, v, a;
};

void bm_acceleration(benchmark::State& st, const Scene& scene) {
  PlantFixture f(scene);
  pedalwave::model::ContactReport rep;
  f.plant.report(f.q, f.v, rep);
  for (auto _ : st) {
    benchmark::DoNotOptimize(f.q.data());
    const bool ok = f.plant.acceleration(0.0, f.q, f.v, f.a);
    benchmark::DoNotOptimize(ok);
    benchmark::DoNotOptimize(f.a.data());
    benchmark::ClobberMemory();
  }
  st.counters["contacts"] = rep.active;
}

void bm_implicit_terms(benchmark::State& st, const Scene& scene) {
  PlantFixture f(scene);
  const int n = f.plant.nq();
  pedalwave::model::ImplicitTerms t{Eigen::MatrixXd::Zero(n, n), VectorXd::Zero(n),
                                    Eigen::MatrixXd::Zero(n, n), Eigen::MatrixXd::Zero(n, n)};
  for (auto _ : st) {
    benchmark::DoNotOptimize(f.q.data());
    const bool ok = f.plant.implicit_terms(0.0, f.q, f.v, t);
    benchmark::DoNotOptimize(ok);
    benchmark::DoNotOptimize(t.M.data());
    benchmark::ClobberMemory();
  }
}

// ---- integrators --------------------------------------------------------------------------------

void bm_integrator_step(benchmark::State& st, Method method, int jacobian_age) {
  PlantFixture f(shipped("flat_high_friction"));
  IntegratorOptions o;
  o.method = method;
  o.h = 1e-4;
  if (jacobian_age >= 0) o.jacobian_age = jacobian_age;
  Integrator integ(f.plant.nq(), o);
  VectorXd q = f.q, v = f.v;
  for (auto _ : st) {
    q = f.q;  // the same step every iteration (the state copy is 2 × nq doubles)
    v = f.v;
    const auto s = integ.step(f.plant, 0.0, o.h, q, v);
    benchmark::DoNotOptimize(s);
    benchmark::DoNotOptimize(q.data());
    benchmark::ClobberMemory();
  }
  st.counters["evals/step"] = static_cast<double>(integ.stats().evaluations) /
                              static_cast<double>(std::max<std::uint64_t>(integ.stats().steps, 1));
}

// ---- result collection and the summary tables ---------------------------------------------------

// Collects the mean time per iteration [ns] per benchmark name (the median aggregate when
// --benchmark_repetitions is used), while the console reporter prints as usual.
class Collector : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      if (r.error_occurred) continue;
      const double ns = r.GetAdjustedCPUTime() * to_ns(r.time_unit);
      if (r.run_type == Run::RT_Iteration) {
        if (!median_.count(r.run_name.str())) ns_[r.run_name.str()] = ns;
      } else if (r.aggregate_name == "median") {
        median_[r.run_name.str()] = true;
        ns_[r.run_name.str()] = ns;
      }
    }
    ConsoleReporter::ReportRuns(runs);
  }
  // NaN when the benchmark did not run (filtered out).
  double ns(const std::string& name) const {
    const auto it = ns_.find(name);
    return it == ns_.end() ? std::numeric_limits<double>::quiet_NaN() : it->second;
  }

 private:
  static double to_ns(benchmark::TimeUnit u) {
    switch (u) {
      case benchmark::kNanosecond: return 1.0;
      case benchmark::kMicrosecond: return 1e3;
      case benchmark::kMillisecond: return 1e6;
      case benchmark::kSecond: return 1e9;
    }
    return 1.0;
  }
  std::map<std::string, double> ns_;
  std::map<std::string, bool> median_;
};

std::string fd_name(bool flexible, int N, ForwardSolver s = ForwardSolver::kRecursive) {
  return std::string("forward_dynamics/") + (s == ForwardSolver::kRecursive ? "recursive/" : "dense/") +
         (flexible ? "flexible" : "rigid") + "/N:" + std::to_string(N);
}

// Least-squares slope of log(cost) against log(N) over the points with N in [16, 64].
double fitted_exponent(const Collector& c, bool flexible, ForwardSolver s) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (int N : kSizes) {
    if (N < 16) continue;
    const double t = c.ns(fd_name(flexible, N, s));
    if (!std::isfinite(t)) continue;
    const double x = std::log(N), y = std::log(t);
    sx += x, sy += y, sxx += x * x, sxy += x * y, ++n;
  }
  if (n < 2) return std::numeric_limits<double>::quiet_NaN();
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

std::string us(double ns) { return std::isfinite(ns) ? Table::num(ns / 1e3, 3) : "-"; }

void print_summary(const Collector& c, const std::vector<EffectCase>& effects) {
  using S = ForwardSolver;
  std::cout << "\n== forward_dynamics cost versus N (CPU time per evaluation), both solvers ==\n";
  Table scale({"N", "nq flexible", "recursive flexible [µs]", "dense flexible [µs]", "dense / recursive",
               "recursive rigid [µs]", "dense rigid [µs]", "dense / recursive"});
  auto ratio = [](double a, double b) { return std::isfinite(a / b) ? Table::num(a / b, 3) : "-"; };
  for (int N : kSizes) {
    const double rf = c.ns(fd_name(true, N, S::kRecursive)), df = c.ns(fd_name(true, N, S::kDense));
    const double rr = c.ns(fd_name(false, N, S::kRecursive)), dr = c.ns(fd_name(false, N, S::kDense));
    scale.add_row({std::to_string(N), std::to_string(2 * N + 1), us(rf), us(df), ratio(df, rf), us(rr),
                   us(dr), ratio(dr, rr)});
  }
  std::cout << scale.to_text();
  std::cout << "fitted exponent (cost ∝ N^p, N = 16 … 64): recursive flexible p = "
            << Table::num(fitted_exponent(c, true, S::kRecursive), 3)
            << ", rigid p = " << Table::num(fitted_exponent(c, false, S::kRecursive), 3)
            << "; dense flexible p = " << Table::num(fitted_exponent(c, true, S::kDense), 3)
            << ", rigid p = " << Table::num(fitted_exponent(c, false, S::kDense), 3) << '\n';
  for (bool flexible : {true, false}) {
    const char* what = flexible ? "flexible" : "rigid";
    const double r6 = c.ns(fd_name(flexible, 6, S::kRecursive)), r64 = c.ns(fd_name(flexible, 64, S::kRecursive));
    const double d6 = c.ns(fd_name(flexible, 6, S::kDense)), d64 = c.ns(fd_name(flexible, 64, S::kDense));
    std::cout << what << ": cost(64) / cost(6) recursive " << ratio(r64, r6) << " (target ≤ "
              << Table::num(kTargetRatio, 3) << ": " << (r64 / r6 <= kTargetRatio ? "MET" : "NOT MET")
              << "), dense " << ratio(d64, d6) << "; N = 64 recursive " << us(r64) << " µs (target ≤ "
              << us(kTarget64Ns) << " µs: " << (r64 <= kTarget64Ns ? "MET" : "NOT MET")
              << "); N = 6 recursive / dense " << ratio(r6, d6) << " (target ≤ 1: "
              << (r6 <= d6 ? "MET" : "NOT MET") << ")\n";
  }
  const double t6 = c.ns(fd_name(true, 6));
  if (std::isfinite(t6))
    std::cout << "target: N = 6 flexible ≤ " << us(kTargetNs) << " µs → measured " << us(t6)
              << " µs: " << (t6 <= kTargetNs ? "MET" : "NOT MET") << " (" << Table::num(t6 / kTargetNs, 3)
              << " × target)\n";

  std::cout << "\n== Plant::acceleration, N = 6, effects added one at a time ==\n";
  Table eff({"effects", "acceleration [µs]", "added [µs]", "over", "implicit_terms [µs]"});
  for (const EffectCase& e : effects) {
    const double a = c.ns("acceleration/" + e.name), it = c.ns("implicit_terms/" + e.name);
    const double base = e.base.empty() ? std::numeric_limits<double>::quiet_NaN()
                                       : c.ns("acceleration/" + e.base);
    eff.add_row({e.what, us(a), us(a - base), e.base.empty() ? "-" : e.base, us(it)});
  }
  std::cout << eff.to_text();

  std::cout << "\n== one integrator step, flat_high_friction (N = 6), h = 1e-4 s ==\n";
  Table integ({"method", "step [µs]"});
  for (Method m : {Method::kExplicitEuler, Method::kSemiImplicitEuler, Method::kImplicitVelocity,
                   Method::kRK4, Method::kDormandPrince45, Method::kImplicitContact}) {
    const std::string name(pedalwave::model::to_string(m));
    integ.add_row({name, us(c.ns("integrator_step/" + name))});
  }
  integ.add_row({"implicit_contact_fresh (jacobian_age 0)", us(c.ns("integrator_step/implicit_contact_fresh"))});
  std::cout << integ.to_text();
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  // An option Google Benchmark does not take (it printed "<argv0>: error: unrecognized
  // command-line flag: …" for each) is a bad command line: exit 2, as in every tool.
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return pedalwave::toolkit::cli::kExitBadInput;

  for (bool flexible : {true, false})
    for (int N : kSizes)
      for (ForwardSolver s : kSolvers)
        benchmark::RegisterBenchmark(fd_name(flexible, N, s).c_str(), bm_forward_dynamics, N, flexible, s)
            ->Unit(benchmark::kNanosecond);

  std::vector<EffectCase> effects;
  try {
    effects = effect_cases();
  } catch (const std::exception& e) {
    std::cerr << "pedalwave_bench_model: cannot load the shipped scenes: " << e.what() << '\n';
    return 2;
  }
  for (const EffectCase& e : effects)
    benchmark::RegisterBenchmark(("acceleration/" + e.name).c_str(), bm_acceleration, e.scene)
        ->Unit(benchmark::kNanosecond);
  for (const EffectCase& e : effects)
    benchmark::RegisterBenchmark(("implicit_terms/" + e.name).c_str(), bm_implicit_terms, e.scene)
        ->Unit(benchmark::kNanosecond);
  for (Method m : {Method::kExplicitEuler, Method::kSemiImplicitEuler, Method::kImplicitVelocity,
                   Method::kRK4, Method::kDormandPrince45, Method::kImplicitContact})
    benchmark::RegisterBenchmark(
        ("integrator_step/" + std::string(pedalwave::model::to_string(m))).c_str(),
        bm_integrator_step, m, -1)
        ->Unit(benchmark::kNanosecond);
  // implicit_contact with a fresh Jacobian at every evaluation (the scheme before jacobian_age).
  benchmark::RegisterBenchmark("integrator_step/implicit_contact_fresh", bm_integrator_step,
                               Method::kImplicitContact, 0)
      ->Unit(benchmark::kNanosecond);

  Collector collector;
  benchmark::RunSpecifiedBenchmarks(&collector);
  print_summary(collector, effects);
  benchmark::Shutdown();
  return 0;
}
