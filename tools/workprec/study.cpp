#include "study.hpp"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <stdexcept>

#include "pedalwave/campaign/campaign.hpp"
#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/simloop/closed_loop.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::workprec {

const char* to_string(RunStatus s) {
  switch (s) {
    case RunStatus::kOk: return "ok";
    case RunStatus::kUnstable: return "unstable";
    case RunStatus::kFailed: return "failed";
  }
  return "?";
}

namespace {

void sample(model::Simulation& sim, double t, Trajectory& tr) {
  const model::Model& m = sim.plant().model();
  model::Data& d = sim.plant().data();
  model::update_kinematics(m, d, sim.q(), model::VectorXd());
  const model::Vec2 c = model::center_of_mass(m, d, sim.q());
  tr.t.push_back(t);
  tr.com_x.push_back(c.x());
  tr.com_z.push_back(c.y());
  for (int j = 0; j < m.joints(); ++j) tr.alpha.push_back(sim.q()(m.i_alpha(j)));
}

}  // namespace

RunResult run_once(const RunSpec& spec, bool record) {
  RunResult r;
  std::unique_ptr<simloop::ClosedLoop> loop;
  std::unique_ptr<model::Simulation> open;
  if (spec.closed_loop)
    loop = std::make_unique<simloop::ClosedLoop>(spec.scene, simloop::Options{.rate_hz = spec.rate_hz},
                                                 spec.integ);
  else
    open = std::make_unique<model::Simulation>(spec.scene, spec.integ);
  model::Simulation& sim = loop ? loop->sim() : *open;
  const double period = 1.0 / spec.rate_hz;
  const auto n = static_cast<long>(std::llround(spec.duration / period));
  if (record) {
    r.traj.joints = sim.plant().model().joints();
    r.traj.t.reserve(static_cast<size_t>(n + 1));
    sample(sim, 0.0, r.traj);
  }
  const auto w0 = std::chrono::steady_clock::now();
  const double c0 = thread_cpu_s();
  for (long k = 1; k <= n; ++k) {
    const model::StepStatus st =
        loop ? loop->step() : sim.advance_to(static_cast<double>(k) * period);
    if (st != model::StepStatus::kOk) {
      // NaN/Inf is an instability; a step below h_min or a failed evaluation is a failure.
      r.status = st == model::StepStatus::kNonFinite ? RunStatus::kUnstable : RunStatus::kFailed;
      r.why = std::string(model::to_string(st));
      break;
    }
    if (spec.max_evaluations > 0 && sim.integrator().stats().evaluations > spec.max_evaluations) {
      r.status = RunStatus::kFailed;
      r.why = "too costly: over " + std::to_string(spec.max_evaluations) + " evaluations";
      break;
    }
    if (sim.v().lpNorm<Eigen::Infinity>() > 1e3 || !sim.q().allFinite()) {
      r.status = RunStatus::kUnstable;
      r.why = "blow-up: |q̇| > 1e3";
      break;
    }
    r.t_fail = static_cast<double>(k) * period;
    if (record) sample(sim, r.t_fail, r.traj);
  }
  r.cpu_s = thread_cpu_s() - c0;
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  const model::IntegratorStats& s = sim.integrator().stats();
  r.evaluations = s.evaluations;
  r.steps = s.steps;
  r.rejected = s.rejected;
  return r;
}

Errors compare(const Trajectory& run, const Trajectory& ref) {
  Errors e;
  const size_t n = std::min(run.t.size(), ref.t.size());
  const auto J = static_cast<size_t>(ref.joints);
  for (size_t i = 0; i < n; ++i) {
    const double d = std::hypot(run.com_x[i] - ref.com_x[i], run.com_z[i] - ref.com_z[i]);
    e.com_max = std::max(e.com_max, d);
    for (size_t j = 0; j < J; ++j)
      e.alpha_max = std::max(e.alpha_max, std::abs(run.alpha[i * J + j] - ref.alpha[i * J + j]));
  }
  if (n > 0)
    e.com_final = std::hypot(run.com_x[n - 1] - ref.com_x[n - 1], run.com_z[n - 1] - ref.com_z[n - 1]);
  return e;
}

const std::vector<Variant>& fidelity_variants() {
  static const std::vector<Variant> v = {
      {"flexible, regularized v_s = 1e-3 (shipped)", [](model::Scene&) {}},
      {"rigid joints (exact limit)", [](model::Scene& s) { s.robot.joints = model::JointModel::kRigid; }},
      {"Coulomb (exact sign)", [](model::Scene& s) { s.ground.law = model::FrictionLaw::kCoulomb; }},
      {"regularized v_s = 1e-4", [](model::Scene& s) { s.ground.v_s = 1e-4; }},
      {"regularized v_s = 1e-2", [](model::Scene& s) { s.ground.v_s = 1e-2; }},
      {"tanh v_s = 1e-3", [](model::Scene& s) { s.ground.law = model::FrictionLaw::kTanh; }},
      {"stick-slip k_t = 2000 N/m", [](model::Scene& s) { s.ground.law = model::FrictionLaw::kStickSlip; }},
  };
  return v;
}

namespace {

std::string hex_list(const std::vector<double>& v) {
  std::string out;
  out.reserve(v.size() * 24);
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (i) out += ',';
    out += campaign::hex(v[i]);
  }
  return out;
}

std::vector<double> parse_list(const std::string& text, const std::string& key) {
  std::vector<double> out;
  if (text.empty()) return out;
  const char* p = text.c_str();
  while (true) {
    char* end = nullptr;
    const double v = std::strtod(p, &end);
    if (end == p) throw std::invalid_argument("workprec run result: " + key + " holds a field that is not a number");
    out.push_back(v);
    if (*end == '\0') break;
    if (*end != ',') throw std::invalid_argument("workprec run result: " + key + ": expected numbers separated by ','");
    p = end + 1;
  }
  return out;
}

}  // namespace

std::string encode_spec(const RunSpec& spec, const std::string& scene_name, const std::string& scene_text,
                        int variant, bool record, int repeats) {
  campaign::Record r;
  r.put_text("kind", "workprec.run")
      .put_text("scene", scene_name)
      .put_text("scene_yaml", scene_text)
      .put_int("variant", variant)
      .put_int("closed_loop", spec.closed_loop ? 1 : 0)
      .put("rate_hz", spec.rate_hz)
      .put("duration", spec.duration)
      .put_text("method", model::to_string(spec.integ.method))
      .put("h", spec.integ.h)
      .put("rtol", spec.integ.rtol)
      .put("atol", spec.integ.atol)
      .put("h_min", spec.integ.h_min)
      .put("h_max", spec.integ.h_max)
      .put_int("jacobian_age", spec.integ.jacobian_age)
      .put_int("max_evaluations", static_cast<long long>(spec.max_evaluations))
      .put_int("record", record ? 1 : 0)
      .put_int("repeats", repeats);
  return r.line();
}

std::string run_line(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_workprec run specification");
  if (r.text("kind") != "workprec.run")
    throw std::invalid_argument("run specification: kind = " + r.text("kind") + ": expected workprec.run");
  RunSpec s;
  s.scene = config::parse_scene(r.text("scene_yaml"), r.text("scene"));
  const long long v = r.integer("variant");
  if (v < 0 || v >= static_cast<long long>(fidelity_variants().size()))
    throw std::invalid_argument("run specification: variant = " + std::to_string(v) + ": expected 0 … " +
                                std::to_string(fidelity_variants().size() - 1));
  fidelity_variants()[static_cast<std::size_t>(v)].apply(s.scene);
  s.closed_loop = r.integer("closed_loop") != 0;
  s.rate_hz = r.number("rate_hz");
  s.duration = r.number("duration");
  s.integ.method = model::parse_method(r.text("method"));
  s.integ.h = r.number("h");
  s.integ.rtol = r.number("rtol");
  s.integ.atol = r.number("atol");
  s.integ.h_min = r.number("h_min");
  s.integ.h_max = r.number("h_max");
  const long long age = r.integer("jacobian_age");
  if (age < 0 || age > 1000)
    throw std::invalid_argument("run specification: jacobian_age = " + std::to_string(age) + ": expected 0 … 1000");
  s.integ.jacobian_age = static_cast<int>(age);
  s.max_evaluations = static_cast<std::uint64_t>(r.integer("max_evaluations"));
  const bool record = r.integer("record") != 0;
  const long long repeats = r.integer("repeats");
  RunResult res = run_once(s, record);
  // Short runs: repeat and take the median time (the first run's results are kept).
  if (res.status == RunStatus::kOk && repeats > 1 && res.cpu_s < 1.0) {
    std::vector<double> wall{res.wall_s}, cpu{res.cpu_s};
    for (long long k = 1; k < repeats; ++k) {
      const RunResult x = run_once(s, false);
      wall.push_back(x.wall_s);
      cpu.push_back(x.cpu_s);
    }
    std::sort(wall.begin(), wall.end());
    std::sort(cpu.begin(), cpu.end());
    res.wall_s = wall[wall.size() / 2];
    res.cpu_s = cpu[cpu.size() / 2];
  }
  return encode_result(res);
}

std::string encode_result(const RunResult& x) {
  campaign::Record r;
  r.put_int("status", static_cast<long long>(x.status))
      .put_text("why", x.why)
      .put("t_fail", x.t_fail)
      .put("wall_s", x.wall_s)
      .put("cpu_s", x.cpu_s)
      .put_int("evaluations", static_cast<long long>(x.evaluations))
      .put_int("steps", static_cast<long long>(x.steps))
      .put_int("rejected", static_cast<long long>(x.rejected))
      .put_int("joints", x.traj.joints)
      .put_text("t", hex_list(x.traj.t))
      .put_text("com_x", hex_list(x.traj.com_x))
      .put_text("com_z", hex_list(x.traj.com_z))
      .put_text("alpha", hex_list(x.traj.alpha));
  return r.line();
}

RunResult decode_result(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_workprec run result");
  RunResult x;
  const long long st = r.integer("status");
  if (st < 0 || st > static_cast<long long>(RunStatus::kFailed))
    throw std::invalid_argument("run result: status = " + std::to_string(st) + ": expected 0 … 2");
  x.status = static_cast<RunStatus>(st);
  x.why = r.text("why");
  x.t_fail = r.number("t_fail");
  x.wall_s = r.number("wall_s");
  x.cpu_s = r.number("cpu_s");
  x.evaluations = static_cast<std::uint64_t>(r.integer("evaluations"));
  x.steps = static_cast<std::uint64_t>(r.integer("steps"));
  x.rejected = static_cast<std::uint64_t>(r.integer("rejected"));
  x.traj.joints = static_cast<int>(r.integer("joints"));
  x.traj.t = parse_list(r.text("t"), "t");
  x.traj.com_x = parse_list(r.text("com_x"), "com_x");
  x.traj.com_z = parse_list(r.text("com_z"), "com_z");
  x.traj.alpha = parse_list(r.text("alpha"), "alpha");
  return x;
}

}  // namespace pedalwave::workprec
