#include "experiments.hpp"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/dynamics.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/simloop/closed_loop.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::paper {

namespace {

// Whole control periods in `seconds`, or −1 when it is not a whole number.
long long periods_in(double seconds, double rate_hz) {
  const double x = seconds * rate_hz;
  const long long n = std::llround(x);
  return std::abs(x - static_cast<double>(n)) <= 1e-6 * std::max(1.0, x) ? n : -1;
}

}  // namespace

double gait_period(const model::Scene& s) { return 2.0 * std::numbers::pi / std::abs(s.gait.omega); }

// What a run measures, observed after every control period k (0 … n_periods) from the plant's
// state: the COM for the average speed, the head's crossing, the stair events (every 10 ms) and the
// trace samples. One per run, whether the run is stepped alone or in a lockstep group.
class Measures {
 public:
  Measures(const RunSpec& spec, const model::Plant& plant)
      : spec_(spec), m_(plant.model()), dd_(m_), tau_(m_.joints()) {
    const double rate = spec.rate_hz;
    if (!(rate > 0) || !std::isfinite(rate))
      throw std::invalid_argument("control rate = " + std::to_string(rate) + " Hz: expected > 0");
    n_periods_ = periods_in(spec.scene.duration, rate);
    if (n_periods_ < 1)
      throw std::invalid_argument("duration = " + std::to_string(spec.scene.duration) +
                                  " s: expected a positive multiple of the control period");
    if (spec.sample_every > 0) {
      per_sample_ = periods_in(spec.sample_every, rate);
      if (per_sample_ < 1)
        throw std::invalid_argument("sample period = " + std::to_string(spec.sample_every) +
                                    " s: expected a multiple of the control period");
    }
    const double t0 = std::isfinite(spec.avg_from) ? spec.avg_from : gait_period(spec.scene);
    k_avg_ = std::llround(t0 * rate);
    r_.resolved = plant.scene();
    r_.avg_from = t0;
    stair_.emplace(r_.resolved);
    // Events are checked every 10 ms (cheap against the plant's steps, fine against 1 cm/s).
    per_event_ = std::max<long long>(1, periods_in(0.01, rate));
  }

  long long periods() const { return n_periods_; }

  // After period k (k = 0: the start), at plant time t and state q; eta_head the head joint's η as
  // the controller will use it from this period on.
  void observe(long long k, double t, const Eigen::VectorXd& q, double eta_head) {
    const bool sample = per_sample_ > 0 && k % per_sample_ == 0;
    const bool event = k % per_event_ == 0 || k == n_periods_;
    if (!sample && !event && k != k_avg_) return;
    model::update_kinematics(m_, dd_, q, no_v_);
    const model::Vec2 com = model::center_of_mass(m_, dd_, q);
    if (k == k_avg_) com_x_from_ = com.x();
    r_.com_x_final = com.x();
    const model::Vec2 head = model::point_position(m_, dd_, q, m_.point_head());
    if (std::isfinite(spec_.cross_x) && std::isnan(r_.t_head_cross) && head.x() >= spec_.cross_x)
      r_.t_head_cross = t;
    stair_->observe(t, m_, dd_, q);
    if (!sample) return;
    const int P = m_.points(), head_joint = m_.joints() - 1;
    Trace& tr = r_.trace;
    const model::Vec2 tail = model::point_position(m_, dd_, q, m_.point_tail());
    tr.t.push_back(t);
    tr.com_x.push_back(com.x());
    tr.com_z.push_back(com.y());
    tr.head_x.push_back(head.x());
    tr.head_z.push_back(head.y());
    tr.tail_x.push_back(tail.x());
    tr.tail_z.push_back(tail.y());
    model::sea_torques(m_, q, tau_);
    tr.tau_head.push_back(tau_(head_joint));
    tr.eta_head.push_back(eta_head);
    std::vector<double> bx(static_cast<std::size_t>(P)), bz(static_cast<std::size_t>(P));
    for (int p = 0; p < P; ++p) {
      const model::Vec2 pt = model::point_position(m_, dd_, q, p);
      bx[static_cast<std::size_t>(p)] = pt.x();
      bz[static_cast<std::size_t>(p)] = pt.y();
    }
    tr.body_x.push_back(std::move(bx));
    tr.body_z.push_back(std::move(bz));
  }

  // The result of a run that reached plant time t_end with `status` in `steps` plant steps.
  RunResult finish(model::StepStatus status, double t_end, std::uint64_t steps) {
    r_.status = status;
    r_.t_end = t_end;
    const double t0 = r_.avg_from;
    if (std::isfinite(com_x_from_) && r_.t_end > t0 + 1e-9 && std::isfinite(r_.com_x_final))
      r_.avg_speed = (r_.com_x_final - com_x_from_) / (r_.t_end - t0);
    r_.stair = stair_->events();
    r_.steps = steps;
    return std::move(r_);
  }

 private:
  const RunSpec& spec_;
  const model::Model& m_;
  model::Data dd_;
  Eigen::VectorXd tau_;
  const Eigen::VectorXd no_v_;
  long long n_periods_ = 0, per_sample_ = 0, per_event_ = 1, k_avg_ = 0;
  double com_x_from_ = kNaN;
  RunResult r_;
  std::optional<simloop::StairWatch> stair_;
};

RunResult run(const RunSpec& spec) {
  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = thread_cpu_s();
  const double rate = spec.rate_hz;
  if (!(rate > 0) || !std::isfinite(rate))
    throw std::invalid_argument("control rate = " + std::to_string(rate) + " Hz: expected > 0");
  simloop::ClosedLoop loop(spec.scene, simloop::Options{.rate_hz = rate, .controller = true, .k_c = spec.k_c},
                           spec.integ);
  model::Simulation& sim = loop.sim();
  Measures meas(spec, sim.plant());
  const int head_joint = sim.plant().model().joints() - 1;
  const long long n_periods = meas.periods();
  meas.observe(0, sim.t(), sim.q(), spec.scene.gait.eta);
  model::StepStatus status = model::StepStatus::kOk;
  for (long long k = 0; k < n_periods; ++k) {
    status = loop.step();
    if (status != model::StepStatus::kOk) break;
    meas.observe(k + 1, sim.t(), sim.q(), loop.control().eta[static_cast<std::size_t>(head_joint)]);
  }
  RunResult r = meas.finish(status, sim.t(), sim.integrator().stats().steps);
  r.cpu_s = thread_cpu_s() - cpu0;
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  return r;
}

std::vector<std::size_t> negative_peaks(const std::vector<double>& t, const std::vector<double>& y,
                                        double window) {
  if (t.size() != y.size())
    throw std::invalid_argument("negative_peaks: t has " + std::to_string(t.size()) +
                                " samples but y has " + std::to_string(y.size()));
  std::vector<std::size_t> out;
  const double half = 0.5 * window;
  std::size_t lo = 0, hi = 0;  // window [lo, hi) around i
  for (std::size_t i = 0; i < y.size(); ++i) {
    while (t[lo] < t[i] - half) ++lo;
    while (hi < y.size() && t[hi] <= t[i] + half) ++hi;
    if (!(y[i] < 0.0)) continue;
    // Only a full window: a peak near either end could be the edge of a larger one outside.
    if (t[i] - half < t.front() || t[i] + half > t.back()) continue;
    bool is_min = true;
    for (std::size_t j = lo; j < hi && is_min; ++j)
      is_min = y[j] > y[i] || (y[j] == y[i] && j >= i);  // ties: the first one
    if (is_min) out.push_back(i);
  }
  return out;
}

std::string encode_spec(const RunSpec& spec, const std::string& scene_name, const std::string& scene_text) {
  campaign::Record r;
  r.put_text("kind", "paper.run")
      .put_text("scene", scene_name)
      .put_text("scene_yaml", scene_text)
      .put("duration", spec.scene.duration)
      .put("k_c", spec.k_c)
      .put_text("method", model::to_string(spec.integ.method))
      .put("h", spec.integ.h)
      .put("rtol", spec.integ.rtol)
      .put("atol", spec.integ.atol)
      .put("h_min", spec.integ.h_min)
      .put("h_max", spec.integ.h_max)
      .put("rate_hz", spec.rate_hz)
      .put("sample_every", spec.sample_every)
      .put("cross_x", spec.cross_x)
      .put("avg_from", spec.avg_from);
  return r.line();
}

RunSpec decode_spec(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_paper run specification");
  if (r.text("kind") != "paper.run")
    throw std::invalid_argument("run specification: kind = " + r.text("kind") + ": expected paper.run");
  RunSpec s;
  s.scene = config::parse_scene(r.text("scene_yaml"), r.text("scene"));
  s.scene.duration = r.number("duration");
  s.k_c = r.number("k_c");
  s.integ.method = model::parse_method(r.text("method"));
  s.integ.h = r.number("h");
  s.integ.rtol = r.number("rtol");
  s.integ.atol = r.number("atol");
  s.integ.h_min = r.number("h_min");
  s.integ.h_max = r.number("h_max");
  s.rate_hz = r.number("rate_hz");
  s.sample_every = r.number("sample_every");
  s.cross_x = r.number("cross_x");
  s.avg_from = r.number("avg_from");
  return s;
}

std::string encode_result(const RunResult& x) {
  campaign::Record r;
  r.put_int("status", static_cast<long long>(x.status))
      .put("t_end", x.t_end)
      .put("avg_from", x.avg_from)
      .put("avg_speed", x.avg_speed)
      .put("com_x_final", x.com_x_final)
      .put("t_head_cross", x.t_head_cross)
      .put("x_near", x.stair.x_near)
      .put("x_far", x.stair.x_far)
      .put("top", x.stair.top)
      .put("t_head_on_top", x.stair.t_head_on_top)
      .put("t_com_past", x.stair.t_com_past)
      .put("t_body_past", x.stair.t_body_past)
      .put("max_head_z", x.stair.max_head_z)
      .put("cpu_s", x.cpu_s)
      .put("wall_s", x.wall_s)
      .put_int("steps", static_cast<long long>(x.steps));
  return r.line();
}

RunResult decode_result(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_paper run result");
  RunResult x;
  const long long st = r.integer("status");
  if (st < 0 || st > static_cast<long long>(model::StepStatus::kStepTooSmall))
    throw std::invalid_argument("run result: status = " + std::to_string(st) + ": expected 0 … 3");
  x.status = static_cast<model::StepStatus>(st);
  x.t_end = r.number("t_end");
  x.avg_from = r.number("avg_from");
  x.avg_speed = r.number("avg_speed");
  x.com_x_final = r.number("com_x_final");
  x.t_head_cross = r.number("t_head_cross");
  x.stair.x_near = r.number("x_near");
  x.stair.x_far = r.number("x_far");
  x.stair.top = r.number("top");
  x.stair.t_head_on_top = r.number("t_head_on_top");
  x.stair.t_com_past = r.number("t_com_past");
  x.stair.t_body_past = r.number("t_body_past");
  x.stair.max_head_z = r.number("max_head_z");
  x.cpu_s = r.number("cpu_s");
  x.wall_s = r.number("wall_s");
  x.steps = static_cast<std::uint64_t>(r.integer("steps"));
  return x;
}

std::string run_line(const std::string& line) { return encode_result(run(decode_spec(line))); }

}  // namespace pedalwave::paper
