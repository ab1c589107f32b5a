#include "experiments.hpp"

#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <mutex>
#include <numbers>
#include <stdexcept>
#include <string>
#include <thread>

#include "pedalwave/model/dynamics.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/simloop/closed_loop.hpp"

namespace pedalwave::paper {

namespace {

double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Whole control periods in `seconds`, or −1 when it is not a whole number.
long long periods_in(double seconds, double rate_hz) {
  const double x = seconds * rate_hz;
  const long long n = std::llround(x);
  return std::abs(x - static_cast<double>(n)) <= 1e-6 * std::max(1.0, x) ? n : -1;
}

}  // namespace

double gait_period(const model::Scene& s) { return 2.0 * std::numbers::pi / std::abs(s.gait.omega); }

RunResult run(const RunSpec& spec) {
  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = thread_cpu_s();
  const double rate = spec.rate_hz;
  if (!(rate > 0) || !std::isfinite(rate))
    throw std::invalid_argument("control rate = " + std::to_string(rate) + " Hz: expected > 0");
  const long long n_periods = periods_in(spec.scene.duration, rate);
  if (n_periods < 1)
    throw std::invalid_argument("duration = " + std::to_string(spec.scene.duration) +
                                " s: expected a positive multiple of the control period");
  long long per_sample = 0;
  if (spec.sample_every > 0) {
    per_sample = periods_in(spec.sample_every, rate);
    if (per_sample < 1)
      throw std::invalid_argument("sample period = " + std::to_string(spec.sample_every) +
                                  " s: expected a multiple of the control period");
  }
  const double t0 = std::isfinite(spec.avg_from) ? spec.avg_from : gait_period(spec.scene);
  const long long k_avg = std::llround(t0 * rate);

  simloop::ClosedLoop loop(spec.scene, simloop::Options{.rate_hz = rate, .controller = true, .k_c = spec.k_c},
                           spec.integ);
  model::Simulation& sim = loop.sim();
  const model::Model& m = sim.plant().model();
  const int P = m.points(), head_joint = m.joints() - 1;
  model::Data dd(m);
  const Eigen::VectorXd no_v;
  Eigen::VectorXd tau(m.joints());

  RunResult r;
  r.resolved = sim.plant().scene();
  r.avg_from = t0;
  const bool has_box = r.resolved.ground_on && !r.resolved.boxes.empty();
  if (has_box) {
    const model::Box& b = r.resolved.boxes.front();
    r.stair.x_near = b.x_near;
    r.stair.x_far = b.x_near + b.width;
    r.stair.top = r.resolved.ground.z + b.height;
    r.stair.max_head_z = -std::numeric_limits<double>::infinity();
  }
  // Events are checked every 10 ms (cheap against the plant's steps, fine against 1 cm/s).
  const long long per_event = std::max<long long>(1, periods_in(0.01, rate));
  double com_x_from = kNaN;

  auto observe = [&](long long k) {
    const Eigen::VectorXd& q = sim.q();
    const double t = sim.t();
    const bool sample = per_sample > 0 && k % per_sample == 0;
    const bool event = k % per_event == 0 || k == n_periods;
    if (!sample && !event && k != k_avg) return;
    model::update_kinematics(m, dd, q, no_v);
    const model::Vec2 com = model::center_of_mass(m, dd, q);
    if (k == k_avg) com_x_from = com.x();
    r.com_x_final = com.x();
    const model::Vec2 head = model::point_position(m, dd, q, m.point_head());
    if (std::isfinite(spec.cross_x) && std::isnan(r.t_head_cross) && head.x() >= spec.cross_x)
      r.t_head_cross = t;
    if (has_box) {
      StairEvents& e = r.stair;
      e.max_head_z = std::max(e.max_head_z, head.y());
      if (std::isnan(e.t_head_on_top) && head.x() >= e.x_near && head.x() <= e.x_far &&
          head.y() >= e.top - kOnTopBelow && head.y() <= e.top + kOnTopAbove)
        e.t_head_on_top = t;
      if (std::isnan(e.t_com_past) && com.x() > e.x_far) e.t_com_past = t;
      if (std::isnan(e.t_body_past)) {
        bool past = true;
        for (int p = 0; p < P && past; ++p) past = model::point_position(m, dd, q, p).x() > e.x_far;
        if (past) e.t_body_past = t;
      }
    }
    if (sample) {
      Trace& tr = r.trace;
      const model::Vec2 tail = model::point_position(m, dd, q, m.point_tail());
      tr.t.push_back(t);
      tr.com_x.push_back(com.x());
      tr.com_z.push_back(com.y());
      tr.head_x.push_back(head.x());
      tr.head_z.push_back(head.y());
      tr.tail_x.push_back(tail.x());
      tr.tail_z.push_back(tail.y());
      model::sea_torques(m, q, tau);
      tr.tau_head.push_back(tau(head_joint));
      // η of the head joint as the controller will use it from this period on (before the first
      // update: the nominal η).
      tr.eta_head.push_back(k == 0 ? spec.scene.gait.eta
                                   : loop.control().Pi[static_cast<std::size_t>(head_joint)]);
      std::vector<double> bx(static_cast<std::size_t>(P)), bz(static_cast<std::size_t>(P));
      for (int p = 0; p < P; ++p) {
        const model::Vec2 pt = model::point_position(m, dd, q, p);
        bx[static_cast<std::size_t>(p)] = pt.x();
        bz[static_cast<std::size_t>(p)] = pt.y();
      }
      tr.body_x.push_back(std::move(bx));
      tr.body_z.push_back(std::move(bz));
    }
  };

  long long k = 0;
  observe(0);
  for (; k < n_periods; ++k) {
    r.status = loop.step();
    if (r.status != model::StepStatus::kOk) break;
    observe(k + 1);
  }
  r.t_end = sim.t();
  if (std::isfinite(com_x_from) && r.t_end > t0 + 1e-9 && std::isfinite(r.com_x_final))
    r.avg_speed = (r.com_x_final - com_x_from) / (r.t_end - t0);
  if (has_box && !std::isfinite(r.stair.max_head_z)) r.stair.max_head_z = kNaN;
  r.steps = sim.integrator().stats().steps;
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

void parallel_for(std::size_t n, int jobs, const std::function<void(std::size_t)>& f,
                  const std::function<void()>& done) {
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  std::atomic<bool> stop{false};
  auto worker = [&]() {
    for (;;) {
      if (stop.load()) return;
      const std::size_t i = next.fetch_add(1);
      if (i >= n) return;
      try {
        f(i);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        stop = true;
        return;
      }
      if (done) done();
    }
  };
  const int threads = std::max(1, std::min<int>(jobs, static_cast<int>(std::max<std::size_t>(n, 1))));
  if (threads == 1) {
    worker();
  } else {
    std::vector<std::thread> pool;
    pool.reserve(static_cast<std::size_t>(threads));
    for (int i = 0; i < threads; ++i) pool.emplace_back(worker);
    for (std::thread& th : pool) th.join();
  }
  if (error) std::rethrow_exception(error);
}

int default_jobs() { return static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

}  // namespace pedalwave::paper
