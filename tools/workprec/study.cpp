#include "study.hpp"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/simloop/closed_loop.hpp"

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

double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

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

}  // namespace pedalwave::workprec
