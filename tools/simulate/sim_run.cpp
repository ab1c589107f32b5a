#include "sim_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "pedalwave/model/dynamics.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/format.hpp"
#include "pedalwave/toolkit/progress.hpp"

namespace pedalwave::simulate {

namespace {

// Number of whole control periods in `seconds`, or −1 when it is not a whole number.
long long periods_in(double seconds, double rate_hz) {
  const double x = seconds * rate_hz;
  const long long n = std::llround(x);
  return std::abs(x - static_cast<double>(n)) <= 1e-6 * std::max(1.0, x) ? n : -1;
}

std::string num(double v) { return toolkit::sig(v); }

}  // namespace

void validate(const RunConfig& c) {
  const double rate = c.loop.rate_hz;
  if (!(rate > 0) || !std::isfinite(rate))
    throw std::invalid_argument("--rate " + num(rate) + ": expected a control rate > 0 [Hz]");
  const std::string period = num(1.0 / rate);
  if (!(c.every > 0) || periods_in(c.every, rate) < 1)
    throw std::invalid_argument("--every " + num(c.every) +
                                ": expected a multiple of the control period 1/rate = " + period +
                                " s");
  if (!(c.scene.duration > 0) || periods_in(c.scene.duration, rate) < 1)
    throw std::invalid_argument("--duration " + num(c.scene.duration) +
                                ": expected a positive multiple of the control period 1/rate = " +
                                period + " s");
}

std::vector<std::string> trajectory_columns(const model::Model& m) {
  const int J = m.joints(), P = m.points();
  std::vector<std::string> q_names;
  for (int j = 1; j <= J; ++j) q_names.push_back("alpha_" + std::to_string(j));
  q_names.insert(q_names.end(), {"theta_N", "p_x", "p_z"});
  if (m.flexible())
    for (int j = 1; j <= J; ++j) q_names.push_back("beta_" + std::to_string(j));

  std::vector<std::string> cols{"t"};
  cols.insert(cols.end(), q_names.begin(), q_names.end());
  for (const std::string& n : q_names) cols.push_back(n + "_dot");
  for (int k = 0; k < P; ++k) cols.push_back("fn_" + std::to_string(k));
  for (int k = 0; k < P; ++k) cols.push_back("ft_" + std::to_string(k));
  cols.push_back("v_forward");
  if (m.flexible())
    for (int j = 1; j <= J; ++j) cols.push_back("tau_sea_" + std::to_string(j));
  for (int j = 1; j <= J; ++j) cols.push_back("u_" + std::to_string(j));
  cols.insert(cols.end(), {"com_x", "com_z", "head_x", "head_z"});
  return cols;
}

RunResult run(const RunConfig& c) {
  validate(c);
  const auto wall_start = std::chrono::steady_clock::now();
  simloop::ClosedLoop loop(c.scene, c.loop, c.integ);
  model::Simulation& sim = loop.sim();
  model::Plant& plant = sim.plant();
  const model::Model& m = plant.model();
  const int J = m.joints(), P = m.points(), nq = m.nq();
  const double period = loop.period();
  const long long n_periods = periods_in(c.scene.duration, c.loop.rate_hz);
  const long long per_sample = periods_in(c.every, c.loop.rate_hz);
  const long long k_avg = c.scene.duration > 1.0 ? periods_in(1.0, c.loop.rate_hz) : 0;

  RunResult r;
  r.scene = plant.scene();
  r.avg_from = c.scene.duration > 1.0 ? 1.0 : 0.0;
  r.tau_sea.assign(m.flexible() ? static_cast<std::size_t>(J) : 0, {});
  r.u.assign(static_cast<std::size_t>(J), {});
  r.csv = c.out_dir / "trajectory.csv";
  toolkit::CsvWriter csv(r.csv, trajectory_columns(m));
  csv.comment("pedalwave_sim trajectory of scene '" + c.scene.name + "' (" + c.scene.source + ")");
  csv.comment("robot: " + model::describe(c.scene.robot));
  csv.comment("controller: " + std::string(c.loop.controller ? "gait" : "none") +
              ", k_c = " + num(c.loop.k_c) + ", rate = " + num(c.loop.rate_hz) +
              " Hz; integrator: " + std::string(model::to_string(c.integ.method)) +
              ", h = " + num(c.integ.h) + " s; sample period " + num(c.every) + " s");
  csv.comment("units: SI (rad, m, s, N, N·m); u_j at row t is the command applied from t on "
              "(last row: the one applied over the last control period)");

  model::Data dd(m);  // our own workspace: the plant's is the integrator's scratch
  model::ContactReport rep;
  Eigen::VectorXd tau(J), ua(J), q0(nq), v0(nq);
  std::vector<double> row;
  row.reserve(trajectory_columns(m).size());
  std::size_t u_at = 0;  // index of u_1 in the row

  const int first = m.flexible() ? m.i_beta(0) : m.i_alpha(0);  // motor-rate coordinates
  const double b = c.scene.joint_friction_on ? c.scene.joint_friction.motor_viscous : 0.0;
  // Actuator power Σ u_act,j ṙ_j (u_act: the module's torque before bearing friction) and the
  // friction power b Σ ṙ_j² at (q, v) with the plant's current input.
  auto powers = [&](const Eigen::VectorXd& q, const Eigen::VectorXd& v, double& p_act,
                    double& p_fric) {
    plant.motor_torques(q, v, ua);
    p_act = 0.0, p_fric = 0.0;
    for (int j = 0; j < J; ++j) {
      const double rate = v(first + j);
      p_act += (ua(j) + b * rate) * rate;
      p_fric += b * rate * rate;
    }
  };

  // The row of the state at the current time, all but u (filled after the controller ran).
  auto state_row = [&]() {
    const Eigen::VectorXd& q = sim.q();
    const Eigen::VectorXd& v = sim.v();
    row.clear();
    row.push_back(sim.t());
    for (int i = 0; i < nq; ++i) row.push_back(q(i));
    for (int i = 0; i < nq; ++i) row.push_back(v(i));
    plant.report(q, v, rep);
    for (int k = 0; k < P; ++k) row.push_back(rep.f_normal(k));
    for (int k = 0; k < P; ++k) row.push_back(rep.f_tangent(k));
    model::update_kinematics(m, dd, q, v);
    const model::Vec2 com = model::center_of_mass(m, dd, q);
    const double vx = model::linear_momentum(m, dd, v).x() / m.total_mass();
    const model::Vec2 head = model::point_position(m, dd, q, m.point_head());
    row.push_back(vx);
    model::sea_torques(m, q, tau);
    if (m.flexible())
      for (int j = 0; j < J; ++j) row.push_back(tau(j));
    u_at = row.size();
    for (int j = 0; j < J; ++j) row.push_back(0.0);
    row.insert(row.end(), {com.x(), com.y(), head.x(), head.y()});
    // In-memory series for the plots and the summary.
    r.t.push_back(sim.t());
    r.com_x.push_back(com.x());
    r.com_z.push_back(com.y());
    r.head_x.push_back(head.x());
    r.head_z.push_back(head.y());
    r.v_forward.push_back(vx);
    for (std::size_t j = 0; j < r.tau_sea.size(); ++j) r.tau_sea[j].push_back(tau(static_cast<int>(j)));
    std::vector<double> bx(static_cast<std::size_t>(P)), bz(static_cast<std::size_t>(P));
    for (int k = 0; k < P; ++k) {
      const model::Vec2 p = model::point_position(m, dd, q, k);
      bx[static_cast<std::size_t>(k)] = p.x();
      bz[static_cast<std::size_t>(k)] = p.y();
    }
    r.body_x.push_back(std::move(bx));
    r.body_z.push_back(std::move(bz));
  };
  auto finish_row = [&]() {
    const control::ControlOutput& out = loop.control();
    for (int j = 0; j < J; ++j) {
      const double uj = c.loop.controller ? out.u[static_cast<std::size_t>(j)] : 0.0;
      row[u_at + static_cast<std::size_t>(j)] = uj;
      r.u[static_cast<std::size_t>(j)].push_back(uj);
    }
    csv.row(row);
  };

  r.e_initial = r.e_min = r.e_max = r.e_final = plant.energy(sim.q(), sim.v());
  if (c.scene.ground_on) {
    model::update_kinematics(m, dd, sim.q(), sim.v());
    for (int k = 0; k < P; ++k) {
      const double depth = c.scene.ground.z - model::point_position(m, dd, sim.q(), k).y();
      if (depth > 0) r.e_ground_initial += 0.5 * c.scene.ground.k * depth * depth;
    }
  }
  plant.report(sim.q(), sim.v(), rep);
  r.max_penetration = r.max_penetration_initial = rep.max_penetration;
  double com_x_from = 0.0;
  // Stair events, as pedalwave_paper checks them: every 10 ms of simulated time.
  simloop::StairWatch stair(plant.scene());
  r.has_box = stair.active();
  const long long per_event = std::max<long long>(1, periods_in(0.01, c.loop.rate_hz));
  auto watch = [&] {
    model::update_kinematics(m, dd, sim.q(), sim.v());
    stair.observe(sim.t(), m, dd, sim.q());
  };
  if (r.has_box) watch();

  toolkit::Progress progress(
      "simulating " + c.scene.name, static_cast<std::uint64_t>(n_periods),
      toolkit::Progress::Options{.style = c.progress ? toolkit::Progress::Style::automatic
                                                     : toolkit::Progress::Style::silent});
  for (long long k = 0; k < n_periods; ++k) {
    const bool sample = k % per_sample == 0;
    if (k == k_avg) {
      model::update_kinematics(m, dd, sim.q(), sim.v());
      com_x_from = model::center_of_mass(m, dd, sim.q()).x();
    }
    if (sample) state_row();
    q0 = sim.q();
    v0 = sim.v();
    r.status = loop.step();  // read → control → write → the plant advances one period
    if (sample) finish_row();
    if (r.status != model::StepStatus::kOk) break;
    // Work over the period (trapezoid; the plant's input is this period's command at both ends).
    double pa0, pf0, pa1, pf1;
    powers(q0, v0, pa0, pf0);
    powers(sim.q(), sim.v(), pa1, pf1);
    r.w_motor += 0.5 * period * (pa0 + pa1);
    r.w_joint_friction += 0.5 * period * (pf0 + pf1);
    const double e = plant.energy(sim.q(), sim.v());
    r.e_min = std::min(r.e_min, e);
    r.e_max = std::max(r.e_max, e);
    r.e_final = e;
    plant.report(sim.q(), sim.v(), rep);
    r.max_penetration = std::max(r.max_penetration, rep.max_penetration);
    if (r.has_box && ((k + 1) % per_event == 0 || k + 1 == n_periods)) watch();
    progress.advance();
  }
  if (r.status == model::StepStatus::kOk && n_periods % per_sample == 0) {
    state_row();  // the final time; u is the command of the last period
    finish_row();
  }
  progress.finish();
  csv.close();
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  r.t_end = loop.t();
  r.rows = csv.rows_written();
  r.stats = sim.integrator().stats();
  r.stair = stair.events();
  if (r.status == model::StepStatus::kOk) {
    model::update_kinematics(m, dd, sim.q(), sim.v());
    const double x_end = model::center_of_mass(m, dd, sim.q()).x();
    r.avg_speed = (x_end - com_x_from) / (r.t_end - r.avg_from);
  } else if (r.t.size() >= 2) {  // from the rows that were written
    r.avg_from = r.t.front();
    r.avg_speed = (r.com_x.back() - r.com_x.front()) / (r.t.back() - r.t.front());
  }
  return r;
}

std::string summary_text(const RunConfig& c, const RunResult& r) {
  const model::Params& p = c.scene.robot;
  const bool ok = r.status == model::StepStatus::kOk;
  std::ostringstream os;
  os << std::setprecision(4);
  os << "scene:            " << c.scene.name << " (" << c.scene.source << ")\n";
  os << "robot:            N = " << p.N << ", "
     << (p.joints == model::JointModel::kFlexible ? "flexible (SEA) joints" : "rigid joints")
     << ", K = " << p.stiffness(0) << " N·m/rad";
  if (p.link_shape == model::LinkShape::kCapsule) os << ", capsule links r = " << p.link_radius << " m";
  if (p.link_shape == model::LinkShape::kBox) os << ", box links h_m = " << p.link_height << " m";
  os << "\n";
  os << "controller:       ";
  if (c.loop.controller)
    os << "gait (A_p = " << c.scene.gait.A_p << " rad, ω = " << c.scene.gait.omega
       << " rad/s, η = " << c.scene.gait.eta << " rad), k_c = " << c.loop.k_c << ", module PD, "
       << c.loop.rate_hz << " Hz\n";
  else
    os << "none (passive robot, zero motor commands)\n";
  os << "integrator:       " << model::to_string(c.integ.method) << ", h = " << c.integ.h << " s";
  if (model::is_adaptive(c.integ.method)) os << ", rtol = " << c.integ.rtol;
  os << '\n';
  os << "run:              " << (ok ? "completed" : "STOPPED") << " at t = " << r.t_end << " s of "
     << c.scene.duration << " s (" << model::to_string(r.status) << ")";
  if (!ok) os << "; the last good step ended at t = " << r.t_end << " s";
  os << "\n";
  if (ok)
    os << "forward speed:    " << r.avg_speed * 100.0 << " cm/s average (COM x, t = " << r.avg_from
       << " … " << r.t_end << " s)\n";
  else  // the state before a blow-up is already wrong: a speed from it would be meaningless
    os << "forward speed:    none (the run went numerically wrong)\n";
  // After a numerical failure only what the start decided is shown: the states before the
  // failure already diverge, so their energy, work and penetration (nan, inf, 1e143 mm) mean
  // nothing.
  os << "energy [J]:       initial " << r.e_initial;
  if (ok) os << ", final " << r.e_final << ", min " << r.e_min << ", max " << r.e_max;
  os << " (kinetic + gravity + spring)";
  if (r.e_ground_initial > 0)
    os << "; " << r.e_ground_initial << " J more stored in the ground at t = 0 (the start is "
       << r.max_penetration_initial * 1000.0 << " mm inside it)";
  if (!ok) os << "; later values not shown (the run went numerically wrong)";
  os << "\n";
  if (ok) {
    os << "work [J]:         motors " << r.w_motor << ", dissipated " << r.w_motor - (r.e_final - r.e_initial)
       << " (= motor work − ΔE: contact damping, friction";
    if (c.scene.joint_friction_on) os << ", joint friction " << r.w_joint_friction;
    os << "; trapezoid per control period)\n";
    os << "max penetration:  " << r.max_penetration * 1000.0 << " mm\n";
    if (r.has_box) os << "stair:            " << simloop::describe(r.stair) << "\n";
  } else {
    os << "work, penetration: not shown (the run went numerically wrong)\n";
  }
  os << "integrator cost:  " << r.stats.steps << " steps, " << r.stats.rejected << " rejected, "
     << r.stats.evaluations << " evaluations, wall " << r.wall_s << " s, real-time factor "
     << (r.wall_s > 0 ? r.t_end / r.wall_s : 0.0) << " (simulated s per wall s)\n";
  os << "trajectory:       " << r.csv.string() << " (" << r.rows << " rows)\n";
  return os.str();
}

}  // namespace pedalwave::simulate
