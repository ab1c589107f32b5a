#include "recording.hpp"

#include <nlopt.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>
#include <stdexcept>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/simloop/closed_loop.hpp"
#include "pedalwave/toolkit/csv.hpp"

namespace pedalwave::identify {

namespace fs = std::filesystem;

Recording read_recording_csv(const fs::path& file) {
  const toolkit::CsvTable c = toolkit::CsvTable::read(file);
  Recording r;
  r.source = file.string();
  auto col = [&](const std::string& name) -> const std::vector<double>& {
    if (!c.has(name))
      throw std::runtime_error(file.string() + ": column " + name +
                               " missing: expected pedalwave_sim's trajectory.csv columns t, alpha_j, beta_j, "
                               "beta_j_dot, u_j (j = 1 … N−1)");
    return c.column(name);
  };
  r.t = col("t");
  while (c.has("alpha_" + std::to_string(r.joints + 1))) ++r.joints;
  if (r.joints < 1) throw std::runtime_error(file.string() + ": no column alpha_1: expected joint columns alpha_j");
  for (int j = 1; j <= r.joints; ++j) {
    const std::string s = std::to_string(j);
    r.alpha.push_back(col("alpha_" + s));
    r.beta.push_back(col("beta_" + s));
    r.beta_dot.push_back(col("beta_" + s + "_dot"));
    r.u.push_back(col("u_" + s));
  }
  if (c.has("theta_N_dot")) {
    std::vector<std::vector<double>> ad;
    for (int j = 1; j <= r.joints; ++j) {
      if (!c.has("alpha_" + std::to_string(j) + "_dot")) { ad.clear(); break; }
      ad.push_back(c.column("alpha_" + std::to_string(j) + "_dot"));
    }
    if (!ad.empty()) {
      r.alpha_dot = ad;
      r.theta_N_dot = c.column("theta_N_dot");
    }
  }
  if (r.t.size() < 3) throw std::runtime_error(file.string() + ": " + std::to_string(r.t.size()) + " rows: expected a walk (≥ 3)");
  const double h = r.t[1] - r.t[0];
  for (std::size_t k = 1; k < r.t.size(); ++k)
    if (!(std::abs(r.t[k] - r.t[k - 1] - h) <= 1e-6 * h + 1e-12))
      throw std::runtime_error(file.string() + ": t at row " + std::to_string(k + 1) + " = " + std::to_string(r.t[k]) +
                               ": expected samples every control period (" + std::to_string(h) +
                               " s; pedalwave_sim --every equal to the control period)");
  return r;
}

void write_recording_csv(const Recording& r, const fs::path& file) {
  std::vector<std::string> names{"t"};
  const int J = r.joints;
  for (int j = 1; j <= J; ++j) names.push_back("alpha_" + std::to_string(j));
  for (int j = 1; j <= J; ++j) names.push_back("beta_" + std::to_string(j));
  for (int j = 1; j <= J; ++j) names.push_back("beta_" + std::to_string(j) + "_dot");
  for (int j = 1; j <= J; ++j) names.push_back("u_" + std::to_string(j));
  const bool rates = !r.theta_N_dot.empty();
  if (rates) {
    for (int j = 1; j <= J; ++j) names.push_back("alpha_" + std::to_string(j) + "_dot");
    names.push_back("theta_N_dot");
  }
  toolkit::CsvWriter w(file, names);
  std::vector<double> row;
  for (std::size_t k = 0; k < r.t.size(); ++k) {
    row.assign(1, r.t[k]);
    for (const auto* v : {&r.alpha, &r.beta, &r.beta_dot, &r.u})
      for (int j = 0; j < J; ++j) row.push_back((*v)[static_cast<std::size_t>(j)][k]);
    if (rates) {
      for (int j = 0; j < J; ++j) row.push_back(r.alpha_dot[static_cast<std::size_t>(j)][k]);
      row.push_back(r.theta_N_dot[k]);
    }
    w.row(row);
  }
  w.close();
}

double sample_period(const Recording& r) {
  if (r.t.size() < 2) throw std::invalid_argument("recording " + r.source + ": fewer than 2 samples");
  return (r.t.back() - r.t.front()) / static_cast<double>(cycle_of(r, r.t.size() - 1) - cycle_of(r, 0));
}

long long cycle_of(const Recording& r, std::size_t k) {
  return r.cycle.empty() ? static_cast<long long>(k) : r.cycle[k];
}

MotorFit fit_motor(const Recording& r, const MotorFitOptions& o) {
  const int J = r.joints;
  const double h = sample_period(r);
  const auto per = static_cast<std::size_t>(std::max<long>(1, std::lround(o.window / h)));
  std::size_t first = 0;
  while (first < r.t.size() && r.t[first] - r.t.front() < o.skip - 0.5 * h) ++first;
  MotorFit f;
  f.theta_term = !r.theta_N_dot.empty() && static_cast<int>(r.alpha_dot.size()) == J;
  // θ̇_j = θ̇_N + Σ_{k≥j} α̇_k (model-spec.md §1).
  std::vector<std::vector<double>> theta_dot;
  if (f.theta_term) {
    theta_dot.assign(static_cast<std::size_t>(J), std::vector<double>(r.t.size()));
    for (std::size_t k = 0; k < r.t.size(); ++k) {
      double acc = r.theta_N_dot[k];
      for (int j = J - 1; j >= 0; --j) {
        acc += r.alpha_dot[static_cast<std::size_t>(j)][k];
        theta_dot[static_cast<std::size_t>(j)][k] = acc;
      }
    }
  }
  // Windows of `per` consecutive cycles (a lost sample ends a run of them).
  std::vector<std::size_t> starts;
  for (std::size_t a = first; a + per < r.t.size();) {
    if (cycle_of(r, a + per) - cycle_of(r, a) == static_cast<long long>(per)) {
      starts.push_back(a);
      a += per;
    } else {
      ++a;
    }
  }
  const std::size_t windows = starts.size();
  if (windows < 4) throw std::invalid_argument("recording " + r.source + ": too short for windows of " + std::to_string(o.window) + " s");
  const auto rows = static_cast<Eigen::Index>(windows * static_cast<std::size_t>(J));
  const Eigen::Index P = J + 2;  // K_1 … K_J, b, I_r
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(rows, P);
  Eigen::VectorXd y(rows);
  // Columns scaled for conditioning (I_r ~ 1e-8): I_r is solved as I_r · s.
  const double s_ir = o.n * o.n;
  Eigen::Index row = 0;
  for (std::size_t w = 0; w < windows; ++w) {
    const std::size_t a = starts[w], b = a + per;
    for (int j = 0; j < J; ++j) {
      const auto& al = r.alpha[static_cast<std::size_t>(j)];
      const auto& be = r.beta[static_cast<std::size_t>(j)];
      const auto& bd = r.beta_dot[static_cast<std::size_t>(j)];
      const auto& u = r.u[static_cast<std::size_t>(j)];
      double iu = 0, idef = 0;
      for (std::size_t k = a; k < b; ++k) {
        idef += 0.5 * h * ((be[k] - al[k]) + (be[k + 1] - al[k + 1]));
        // The torque applied over period k: the command, plus the module PD's change along it,
        // −K_p ∫(β − β_k) − K_D ∫(β̇ − β̇_k) = −K_p (∫β − h β_k) − K_D (β_{k+1} − β_k − h β̇_k):
        // the β̇ integral exactly from the encoder (the motor's fast dynamics, n² I_r / K_D below
        // a period, make β̇ far from linear within one).
        double uk = u[k] * h;
        if (o.module_pd)
          uk -= o.K_p * (0.5 * h * (be[k] + be[k + 1]) - be[k] * h) + o.K_D * ((be[k + 1] - be[k]) - bd[k] * h);
        iu += uk;
      }
      double ir = s_ir * (bd[b] - bd[a]);
      if (f.theta_term) ir -= o.n * (theta_dot[static_cast<std::size_t>(j)][b] - theta_dot[static_cast<std::size_t>(j)][a]);
      A(row, j) = idef;
      A(row, J) = be[b] - be[a];
      A(row, J + 1) = ir / s_ir;
      y(row) = iu;
      ++row;
    }
  }
  // Column scaling, then least squares.
  Eigen::VectorXd scale(P);
  for (Eigen::Index c = 0; c < P; ++c) scale(c) = std::max(A.col(c).norm(), 1e-300);
  const Eigen::MatrixXd As = A * scale.cwiseInverse().asDiagonal();
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(As);
  const Eigen::VectorXd xs = qr.solve(y);
  const Eigen::VectorXd x = xs.cwiseQuotient(scale);
  const Eigen::VectorXd res = y - A * x;
  const double dof = static_cast<double>(rows - P);
  const double s2 = res.squaredNorm() / std::max(dof, 1.0);
  const Eigen::MatrixXd cov_s = (As.transpose() * As).inverse() * s2;
  f.K.resize(static_cast<std::size_t>(J));
  f.K_se.resize(static_cast<std::size_t>(J));
  for (int j = 0; j < J; ++j) {
    f.K[static_cast<std::size_t>(j)] = x(j);
    f.K_se[static_cast<std::size_t>(j)] = std::sqrt(cov_s(j, j)) / scale(j);
  }
  f.b = x(J);
  f.b_se = std::sqrt(cov_s(J, J)) / scale(J);
  f.I_r = x(J + 1) / s_ir;
  f.I_r_se = std::sqrt(cov_s(J + 1, J + 1)) / scale(J + 1) / s_ir;
  f.residual_rms = std::sqrt(res.squaredNorm() / static_cast<double>(rows));
  f.rows = static_cast<int>(rows);
  f.windows = static_cast<int>(windows);
  return f;
}

// ---- stage 2 ----------------------------------------------------------------------------------------
namespace {

const Recording& cached_recording(const std::string& path) {
  static std::mutex mu;
  static std::map<std::string, Recording> cache;
  std::lock_guard<std::mutex> lock(mu);
  auto it = cache.find(path);
  if (it == cache.end()) it = cache.emplace(path, read_recording(path)).first;
  return it->second;
}

model::Scene scene_for(const campaign::Record& in) {
  model::Scene sc = config::parse_scene(in.text("scene_yaml"), "recording scene");
  const long long J = in.integer("joints");
  sc.robot.K.clear();
  for (long long j = 0; j < J; ++j) sc.robot.K.push_back(in.number("K" + std::to_string(j)));
  sc.robot.I_r = in.number("I_r");
  const double b = in.number("b");
  sc.joint_friction_on = b > 0;
  sc.joint_friction.motor_viscous = std::max(b, 0.0);
  const double mu = in.number("mu"), base = sc.ground.mu;
  sc.ground.mu = mu;
  for (auto& p : sc.ground.patches) p.mu *= mu / base;
  return sc;
}

}  // namespace

std::string ground_run_line(const std::string& line) {
  const campaign::Record in = campaign::Record::parse(line, "pedalwave_identify ground run");
  const Recording& r = cached_recording(in.text("recording"));
  model::Scene sc = scene_for(in);
  const double rate = in.number("rate_hz");
  sc.duration = r.t.back() - r.t.front();
  simloop::ClosedLoop loop(sc, simloop::Options{.rate_hz = rate});
  const model::Model& m = loop.sim().plant().model();
  if (m.joints() != r.joints)
    throw std::invalid_argument("recording " + r.source + " has " + std::to_string(r.joints) +
                                " joints, the scene " + std::to_string(m.joints()));
  double sse = 0;
  long long n = 0;
  int status = 0;
  for (std::size_t k = 0; k < r.t.size(); ++k) {
    if (k > 0) {  // one step a cycle; compared where the recording has the cycle
      model::StepStatus st = model::StepStatus::kOk;
      for (long long c = cycle_of(r, k - 1); c < cycle_of(r, k) && st == model::StepStatus::kOk; ++c) st = loop.step();
      if (st != model::StepStatus::kOk) { status = static_cast<int>(st); break; }
    }
    const Eigen::VectorXd& q = loop.sim().q();
    for (int j = 0; j < r.joints; ++j) {
      const double a = q(m.i_alpha(j)), b = q(m.i_beta(j));
      const double ra = r.alpha[static_cast<std::size_t>(j)][k], rb = r.beta[static_cast<std::size_t>(j)][k];
      const double e1 = (b - a) - (rb - ra), e2 = a - ra;
      sse += e1 * e1 + e2 * e2;
      n += 2;
    }
  }
  campaign::Record out;
  out.put_int("status", status).put("sse", status == 0 ? sse : NAN).put_int("n", n);
  return out.line();
}

namespace {
struct GroundCtx {
  std::function<double(double)> f;
  std::string error;
};
double ground_objective(unsigned, const double* x, double*, void* d) {
  auto* c = static_cast<GroundCtx*>(d);
  try {
    return c->f(x[0]);
  } catch (const std::exception& e) {
    c->error = e.what();
    return HUGE_VAL;
  }
}
}  // namespace

GroundFit fit_ground_mu(const fs::path& recording, const std::string& scene_yaml, const MotorFit& motor,
                        const GroundFitOptions& o) {
  const Recording& r = cached_recording(recording.string());
  const double rate = o.rate_hz > 0 ? o.rate_hz : 1.0 / sample_period(r);
  GroundFit g;
  std::map<std::string, std::pair<double, long long>> cache;
  int batch = 0;
  auto spec = [&](double mu) {
    campaign::Record s;
    s.put_text("kind", "identify.ground").put_text("recording", fs::absolute(recording).string())
        .put_text("scene_yaml", scene_yaml).put("rate_hz", rate).put_int("joints", r.joints);
    for (int j = 0; j < r.joints; ++j) s.put("K" + std::to_string(j), motor.K[static_cast<std::size_t>(j)]);
    s.put("I_r", motor.I_r).put("b", motor.b).put("mu", mu);
    return s.line();
  };
  auto eval = [&](const std::vector<double>& mus) {
    std::vector<std::string> todo;
    for (double mu : mus)
      if (!cache.count(spec(mu))) todo.push_back(spec(mu));
    if (!todo.empty()) {
      campaign::Options co = o.campaign;
      const auto res = campaign::run("ground-" + std::to_string(batch++), todo, ground_run_line, co);
      for (std::size_t i = 0; i < todo.size(); ++i) {
        const campaign::Record x = campaign::Record::parse(res[i], "ground result");
        cache[todo[i]] = {x.number("sse"), x.integer("n")};
      }
      g.simulations += static_cast<int>(todo.size());
    }
    std::vector<double> out;
    for (double mu : mus) {
      const double sse = cache.at(spec(mu)).first;
      out.push_back(std::isfinite(sse) ? sse : HUGE_VAL);
    }
    return out;
  };
  // Grid (one batch), then a bounded local search from the best.
  std::vector<double> grid;
  for (int i = 0; i < o.grid; ++i) grid.push_back(o.lo + (o.hi - o.lo) * (i + 0.5) / o.grid);
  const std::vector<double> gv = eval(grid);
  const std::size_t bi = static_cast<std::size_t>(std::min_element(gv.begin(), gv.end()) - gv.begin());
  GroundCtx ctx{[&](double mu) { return eval({mu}).front(); }, ""};
  nlopt_opt opt = nlopt_create(NLOPT_LN_SBPLX, 1);
  const double lb = o.lo, ub = o.hi, step = 0.5 * (o.hi - o.lo) / o.grid;
  nlopt_set_lower_bounds(opt, &lb);
  nlopt_set_upper_bounds(opt, &ub);
  nlopt_set_min_objective(opt, ground_objective, &ctx);
  nlopt_set_maxeval(opt, o.max_evals);
  nlopt_set_xtol_abs1(opt, 1e-5);
  nlopt_set_initial_step(opt, &step);
  double x = grid[bi], fx = 0;
  nlopt_optimize(opt, &x, &fx);
  nlopt_destroy(opt);
  if (!ctx.error.empty()) throw std::runtime_error(ctx.error);
  g.mu = x;
  // σ_μ: Gauss–Newton, σ² = SSE / (n − 1), Σ (∂e/∂μ)² from the SSE's curvature (central differences).
  const double d = std::max(1e-3, 1e-2 * x);
  const double xl = std::max(o.lo, x - d), xh = std::min(o.hi, x + d);
  const std::vector<double> v = eval({xl, x, xh});
  const long long n = cache.at(spec(x)).second;
  if (!(xh > x && x > xl)) {  // at a bound: no curvature from one side
    g.mu_sigma = NAN;
    g.rms = std::sqrt(v[1] / static_cast<double>(std::max<long long>(n, 1)));
    return g;
  }
  const double curv = 2 * ((v[2] - v[1]) / (xh - x) - (v[1] - v[0]) / (x - xl)) / (xh - xl);  // d²SSE/dμ² = 2 Σ(∂e/∂μ)²
  const double s2 = v[1] / static_cast<double>(std::max<long long>(n - 1, 1));
  g.mu_sigma = curv > 0 ? std::sqrt(s2 / (0.5 * curv)) : NAN;
  g.rms = std::sqrt(v[1] / static_cast<double>(std::max<long long>(n, 1)));
  return g;
}

}  // namespace pedalwave::identify
