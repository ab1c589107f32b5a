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
#include "pedalwave/model/lanes.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
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

std::string lockstep_refusal(const RunSpec& base) {
  if (model::LanePlant::machine_width() == 0) return "this machine has neither AVX-512 nor AVX2 with FMA";
  if (base.integ.method != model::Method::kImplicitContact)
    return std::string("the integrator is ") + std::string(model::to_string(base.integ.method)) +
           ", not implicit_contact";
  return model::LanePlant::unsupported(base.scene);
}

namespace {

// One member of a lockstep group: what simloop::ClosedLoop and drivers::SimDriver hold for one run
// (the controller and its state, the feedback and the command), its plant for the sensors, its
// measures.
struct Member {
  RunSpec spec;
  model::Plant plant;
  control::GaitController ctl;
  control::GaitControllerState state;
  control::ControlOutput out{};
  drivers::Feedback fb{};
  drivers::Command cmd{};
  model::Measurement meas;
  Eigen::VectorXd q, v;
  Measures measures;
  bool done = false;
  RunResult result;
  Member(const RunSpec& s)
      : spec(s), plant(s.scene), ctl(simloop::controller_params(s.scene, s.rate_hz, s.k_c)),
        measures(spec, plant) {
    state = ctl.make_state();
    ctl.reset(state, 0.0);
    const int J = plant.model().joints();
    cmd.joints = J;
    meas.beta = meas.beta_dot = meas.deflection = Eigen::VectorXd::Zero(J);
  }
};

// Members [first, first + count) of specs stepped together in lanes of `width`; the unused lanes
// carry copies of the last member.
void run_lanes(const RunSpec& base, std::vector<Member>& members, int width) {
  const double rate = base.rate_hz, period = 1.0 / rate, h = base.integ.h;
  model::Plant plant(base.scene);
  model::LanePlant lanes(plant, width);
  model::LaneStepper stepper(lanes, plant, base.integ);
  const int n = plant.nq(), J = plant.model().joints(), W = width;
  const int m = static_cast<int>(members.size());
  const auto lane = [&](int l) { return l < m ? l : m - 1; };
  std::vector<double> q(static_cast<size_t>(n * W)), v(q.size());
  {
    Eigen::VectorXd q0, v0;
    plant.initial_state(q0, v0);
    for (int l = 0; l < W; ++l)
      for (int i = 0; i < n; ++i) {
        q[static_cast<size_t>(i * W + l)] = q0(i);
        v[static_cast<size_t>(i * W + l)] = v0(i);
      }
    for (Member& mb : members) {
      mb.q = q0;
      mb.v = v0;
    }
  }
  model::LaneInputs in = lanes.make_inputs();
  std::vector<model::StepStatus> status(static_cast<size_t>(W), model::StepStatus::kOk);
  std::vector<double> t_fail(static_cast<size_t>(W), 0.0);
  const int head_joint = J - 1;
  double t = 0.0;
  for (Member& mb : members) mb.measures.observe(0, t, mb.q, mb.spec.scene.gait.eta);
  const long long n_periods = members.front().measures.periods();
  model::ActuatorInput input = plant.input();
  int running = m;
  for (long long k = 0; k < n_periods && running > 0; ++k) {
    // Each member's loop: the sensors (SimDriver::read), the controller, the command into the
    // plant's input (SimDriver::write), as simloop::ClosedLoop::step does.
    for (int l = 0; l < m; ++l) {
      Member& mb = members[static_cast<size_t>(l)];
      if (mb.done) continue;
      mb.plant.measure(mb.q, mb.v, mb.meas);
      drivers::to_feedback(mb.meas, mb.fb);
      mb.fb.seq = static_cast<std::uint64_t>(k + 1);
      mb.fb.stamp_ns = static_cast<std::int64_t>(std::llround(t * 1e9));
      mb.ctl.update(t, period, control::measurement_from(mb.fb), mb.state, mb.out);
      mb.ctl.fill_command(mb.out, mb.cmd);
      mb.cmd.seq = static_cast<std::uint64_t>(k + 1);
      mb.cmd.joints = J;
      drivers::to_actuator_input(mb.cmd, input);
      for (int j = 0; j < J; ++j) {
        const bool on = !input.torque_off;
        const size_t x = static_cast<size_t>(j * W + l);
        in.tau[x] = on ? input.tau(j) : 0.0;
        in.kp[x] = on ? input.kp(j) : 0.0;
        in.beta_ref[x] = on ? input.beta_ref(j) : 0.0;
        in.kd[x] = on ? input.kd(j) : 0.0;
        in.beta_dot_ref[x] = on ? input.beta_dot_ref(j) : 0.0;
      }
    }
    for (int l = m; l < W; ++l)
      for (int j = 0; j < J; ++j) {
        const size_t x = static_cast<size_t>(j * W + l), y = static_cast<size_t>(j * W + lane(l));
        in.tau[x] = in.tau[y];
        in.kp[x] = in.kp[y];
        in.beta_ref[x] = in.beta_ref[y];
        in.kd[x] = in.kd[y];
        in.beta_dot_ref[x] = in.beta_dot_ref[y];
      }
    // One control period of plant steps (model::Simulation::advance_to).
    const double t_end = t + period;
    while (t_end - t > 1e-12 * std::max(1.0, std::abs(t_end))) {
      const double step = std::min(h, t_end - t);
      for (int l = 0; l < W; ++l)
        if (status[static_cast<size_t>(l)] == model::StepStatus::kOk) t_fail[static_cast<size_t>(l)] = t;
      stepper.step(t, step, q.data(), v.data(), in, status.data());
      t += step;
    }
    t = t_end;
    for (int l = 0; l < m; ++l) {
      Member& mb = members[static_cast<size_t>(l)];
      if (mb.done) continue;
      for (int i = 0; i < n; ++i) {
        mb.q(i) = q[static_cast<size_t>(i * W + l)];
        mb.v(i) = v[static_cast<size_t>(i * W + l)];
      }
      if (status[static_cast<size_t>(l)] != model::StepStatus::kOk) {
        mb.result = mb.measures.finish(status[static_cast<size_t>(l)], t_fail[static_cast<size_t>(l)], stepper.stats(l).steps);
        mb.done = true;
        --running;
        continue;
      }
      mb.measures.observe(k + 1, t, mb.q, mb.out.eta[static_cast<std::size_t>(head_joint)]);
    }
  }
  for (int l = 0; l < m; ++l) {
    Member& mb = members[static_cast<size_t>(l)];
    if (!mb.done) mb.result = mb.measures.finish(model::StepStatus::kOk, t, stepper.stats(l).steps);
  }
}

}  // namespace

std::vector<RunResult> run_group(const RunSpec& base, const std::vector<double>& k_c, bool lanes) {
  std::vector<RunResult> out;
  out.reserve(k_c.size());
  const int width = model::LanePlant::machine_width();
  if (!lanes || !lockstep_refusal(base).empty()) {
    for (double k : k_c) {
      RunSpec s = base;
      s.k_c = k;
      out.push_back(run(s));
    }
    return out;
  }
  for (size_t first = 0; first < k_c.size(); first += static_cast<size_t>(width)) {
    const auto wall0 = std::chrono::steady_clock::now();
    const double cpu0 = thread_cpu_s();
    std::vector<Member> members;
    const size_t count = std::min(k_c.size() - first, static_cast<size_t>(width));
    members.reserve(count);
    for (size_t i = 0; i < count; ++i) {
      RunSpec s = base;
      s.k_c = k_c[first + i];
      members.emplace_back(s);
    }
    run_lanes(base, members, width);
    const double cpu = (thread_cpu_s() - cpu0) / static_cast<double>(count);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count() /
                        static_cast<double>(count);
    for (Member& mb : members) {
      mb.result.cpu_s = cpu;
      mb.result.wall_s = wall;
      out.push_back(std::move(mb.result));
    }
  }
  return out;
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

std::string encode_group(const RunSpec& base, const std::vector<double>& k_c, bool lanes,
                         const std::string& scene_name, const std::string& scene_text) {
  std::string gains;
  for (double k : k_c) gains += (gains.empty() ? "" : ",") + campaign::hex(k);
  campaign::Record r;
  r.put_text("kind", "paper.group")
      .put_text("base", encode_spec(base, scene_name, scene_text))
      .put_text("k_c", gains)
      .put_int("lanes", lanes ? 1 : 0);
  return r.line();
}

namespace {
std::string run_group_line(const campaign::Record& r) {
  const RunSpec base = decode_spec(r.text("base"));
  std::vector<double> k_c;
  const std::string gains = r.text("k_c");
  for (size_t b = 0; b < gains.size();) {
    size_t e = gains.find(',', b);
    if (e == std::string::npos) e = gains.size();
    const std::string one = gains.substr(b, e - b);
    char* end = nullptr;
    const double k = std::strtod(one.c_str(), &end);
    if (one.empty() || end != one.c_str() + one.size())
      throw std::invalid_argument("run group: k_c = " + gains + ": expected a comma-separated list of numbers");
    k_c.push_back(k);
    b = e + 1;
  }
  if (k_c.empty()) throw std::invalid_argument("run group: k_c is empty: expected at least one gain");
  const std::vector<RunResult> res = run_group(base, k_c, r.integer("lanes") != 0);
  campaign::Record o;
  o.put_int("members", static_cast<long long>(res.size()));
  for (size_t i = 0; i < res.size(); ++i) o.put_text("r" + std::to_string(i), encode_result(res[i]));
  return o.line();
}
}  // namespace

std::vector<RunResult> decode_group_result(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_paper group result");
  const long long n = r.integer("members");
  if (n < 1) throw std::invalid_argument("group result: members = " + std::to_string(n) + ": expected ≥ 1");
  std::vector<RunResult> out;
  for (long long i = 0; i < n; ++i) out.push_back(decode_result(r.text("r" + std::to_string(i))));
  return out;
}

std::string run_line(const std::string& line) {
  const campaign::Record r = campaign::Record::parse(line, "pedalwave_paper run specification");
  if (r.text("kind") == "paper.group") return run_group_line(r);
  return encode_result(run(decode_spec(line)));
}

}  // namespace pedalwave::paper
