// pedalwave_bench_mujoco — pedalwave and MuJoCo side by side on the same robot and gait (issue 19,
// item 3). Built only when libmujoco-dev is installed (find_package(mujoco)).
//
// The robot in MuJoCo, from the scene's parameters (model-spec.md §1, §4): link 1 the floating base
// (slide x, slide z, hinge about −Y, so the angle turns X toward Z as θ does), then per joint j a
// gearbox-output body on a hinge β_j (armature n² I_r: the reflected rotor inertia; the rotor mass m_r
// on it, at the joint) and link j+1 on a spring hinge s_j = α_j − β_j (stiffness K_j), I_r added to
// link j's rotation. Contact: a sphere of radius r at each of the 2N+1 body points of the model
// (tips, link COMs, joints) against a plane r below the ground, friction μ (condim 3), MuJoCo's
// soft contact (default solref/solimp). Differences from pedalwave's model that remain: the rotor's
// spin coupling to its link (the −n I_r θ̇_j β̇_j term of the kinetic energy) is not in MuJoCo's
// armature, and MuJoCo's contact is its soft constraint, not the spring–damper k δ + d δ̇ with
// regularized Coulomb friction. So each simulator's accuracy is measured against its own reference
// (pedalwave: dopri45 rtol 1e-9 as the work-precision study; MuJoCo: Euler at a 10× smaller step),
// and the difference between the two COM paths is printed for what it is, a model difference.
//
// The gait: the paper's module PD (model-spec.md §7), u_j = K_p (α^d_j − β_j) + K_D (α̇^d_j − β̇_j),
// α^d_j = A_p sin(ω t + η j): the references set at 1 kHz (zero-order hold) by one function for
// both, the PD evaluated with the current motor state at every step as the modules do (pedalwave:
// the plant's module-PD input; MuJoCo: a position actuator K_p and a velocity actuator K_D per motor).
// Real-time factor = simulated time / CPU time of the run (this thread).
//
// Usage: pedalwave_bench_mujoco [--scene FILE] [--seconds T] [--mj-contact-mass M] [--repeat R]
#include <mujoco/mujoco.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/toolkit/cli.hpp"
#include "pedalwave/toolkit/table.hpp"
#include "pedalwave/interface/clock.hpp"

namespace {

namespace pm = pedalwave::model;
using pedalwave::toolkit::Table;
using pm::VectorXd;

constexpr char kTool[] = "pedalwave_bench_mujoco";
constexpr double kPeriod = 1e-3;  // control period [s]
constexpr double kKp = 30.0, kKd = 15.0;
constexpr double kSphere = 1e-3;  // MuJoCo contact sphere radius [m]

// The gait's reference for joint j at t: α^d_j and α̇^d_j.
void gait_ref(const pm::Scene& s, int j, double t, double& ref, double& ref_dot) {
  const pm::GaitParams& g = s.gait;
  const double ph = g.omega * t + g.eta * j;
  ref = g.A_p * std::sin(ph);
  ref_dot = g.A_p * g.omega * std::cos(ph);
}

struct Run {
  std::string sim, method;
  double h = 0.0;
  double cpu = 0.0;
  std::vector<double> com_x, com_z;  // COM at every control period [m]
  bool ok = true;
};

// ---- pedalwave ----------------------------------------------------------------------------------

Run run_pedalwave(const pm::Scene& scene, const pm::IntegratorOptions& integ, double T) {
  Run r{"pedalwave", std::string(pm::to_string(integ.method)), integ.h, 0.0, {}, {}, true};
  pm::Simulation sim(scene, integ);
  pm::Plant& p = sim.plant();
  const pm::Model& m = p.model();
  pm::Data d(m);
  auto& in = p.input();
  in.tau.setZero();
  in.kp.setConstant(kKp);
  in.kd.setConstant(kKd);
  const int steps = static_cast<int>(std::lround(T / kPeriod));
  r.com_x.reserve(static_cast<std::size_t>(steps) + 1);
  r.com_z.reserve(static_cast<std::size_t>(steps) + 1);
  auto record = [&] {
    pm::update_kinematics(m, d, sim.q(), VectorXd());
    const pm::Vec2 c = pm::center_of_mass(m, d, sim.q());
    r.com_x.push_back(c.x());
    r.com_z.push_back(c.y());
  };
  record();
  const double t0 = pedalwave::thread_cpu_s();
  for (int k = 0; k < steps; ++k) {
    const double t = k * kPeriod;
    for (int j = 0; j < m.joints(); ++j) gait_ref(scene, j, t, in.beta_ref(j), in.beta_dot_ref(j));
    if (sim.advance_to((k + 1) * kPeriod) != pm::StepStatus::kOk) {
      r.ok = false;
      break;
    }
    record();
  }
  r.cpu = pedalwave::thread_cpu_s() - t0;  // (includes the COM recording, as the MuJoCo run does)
  return r;
}

// ---- MuJoCo -------------------------------------------------------------------------------------

// contact_mass > 0: the ground's k, d as MuJoCo's direct stiffness and damping (solref
// "−k/m −d/m", impedance 0.99), scaled by the mass m one contact carries; 0: MuJoCo's default.
std::string mjcf(const pm::Scene& s, double contact_mass) {
  const pm::Params& p = s.robot;
  const int N = p.N;
  const double l = p.l;
  std::ostringstream x;
  x.precision(17);
  x << "<mujoco model='pedalwave_snake'>\n"
    << "  <compiler angle='radian' inertiafromgeom='false'/>\n"
    << "  <option gravity='0 0 " << -p.g << "' integrator='Euler'/>\n"
    << "  <default><geom";
  if (contact_mass > 0)
    x << " solref='" << -s.ground.k / contact_mass << ' ' << -s.ground.d / contact_mass
      << "' solimp='0.99 0.99 0.001'";
  x << "/></default>\n"
    << "  <worldbody>\n"
    << "    <geom name='ground' type='plane' size='0 0 1' pos='0 0 " << s.ground.z - kSphere
    << "' contype='0' conaffinity='1' friction='" << s.ground.mu << " 0.005 0.0001'/>\n";
  auto sphere = [&](double px) {
    x << "<geom type='sphere' size='" << kSphere << "' pos='" << px
      << " 0 0' contype='1' conaffinity='0' friction='" << s.ground.mu << " 0.005 0.0001'/>";
  };
  std::string close;
  for (int i = 0; i < N; ++i) {
    const double I = p.I_l + (i < N - 1 ? p.I_r : 0.0);
    x << "<body name='link" << i << "'" << (i == 0 ? " pos='0 0 0'" : "") << ">";
    if (i == 0)
      x << "<joint name='px' type='slide' axis='1 0 0'/><joint name='pz' type='slide' axis='0 0 1'/>"
        << "<joint name='th' type='hinge' axis='0 -1 0'/>";
    else
      x << "<joint name='s" << i - 1 << "' type='hinge' axis='0 1 0' stiffness='"
        << p.stiffness(i - 1) << "'/>";
    x << "<inertial pos='" << l << " 0 0' mass='" << p.m_l << "' diaginertia='" << I << ' ' << I << ' '
      << I << "'/>";
    if (i == 0) sphere(0.0);
    sphere(l);
    sphere(2 * l);
    if (i < N - 1) {
      x << "<body name='out" << i << "' pos='" << 2 * l << " 0 0'><joint name='b" << i
        << "' type='hinge' axis='0 1 0' armature='" << p.n * p.n * p.I_r << "'/>"
        << "<inertial pos='0 0 0' mass='" << p.m_r << "' diaginertia='1e-12 1e-12 1e-12'/>\n";
      close += "</body></body>";
    } else {
      close += "</body>";
    }
  }
  x << close << "\n  </worldbody>\n  <actuator>\n";
  for (int j = 0; j < N - 1; ++j)
    x << "    <position joint='b" << j << "' kp='" << kKp << "'/><velocity joint='b" << j << "' kv='"
      << kKd << "'/>\n";
  x << "  </actuator>\n</mujoco>\n";
  return x.str();
}

struct MjRobot {
  mjModel* m = nullptr;
  int N = 0;
  std::vector<int> qb, qs, vb, vs;  // qpos/qvel addresses of β_j and s_j
  int qroot = 0, vroot = 0;
  ~MjRobot() {
    if (m) mj_deleteModel(m);
  }
};

bool load_mujoco(const pm::Scene& s, double contact_mass, MjRobot& r, std::string& error) {
  const std::string path = "/tmp/pedalwave_bench_mujoco_" + std::to_string(::getpid()) + ".xml";
  {
    std::ofstream f(path);
    f << mjcf(s, contact_mass);
    if (!f) {
      error = "cannot write " + path;
      return false;
    }
  }
  char err[1000] = "";
  r.m = mj_loadXML(path.c_str(), nullptr, err, sizeof err);
  std::remove(path.c_str());
  if (!r.m) {
    error = std::string("MuJoCo refused the generated model: ") + err;
    return false;
  }
  r.N = s.robot.N;
  r.qroot = r.m->jnt_qposadr[mj_name2id(r.m, mjOBJ_JOINT, "px")];
  r.vroot = r.m->jnt_dofadr[mj_name2id(r.m, mjOBJ_JOINT, "px")];
  for (int j = 0; j < r.N - 1; ++j) {
    const int b = mj_name2id(r.m, mjOBJ_JOINT, ("b" + std::to_string(j)).c_str());
    const int sj = mj_name2id(r.m, mjOBJ_JOINT, ("s" + std::to_string(j)).c_str());
    r.qb.push_back(r.m->jnt_qposadr[b]);
    r.vb.push_back(r.m->jnt_dofadr[b]);
    r.qs.push_back(r.m->jnt_qposadr[sj]);
    r.vs.push_back(r.m->jnt_dofadr[sj]);
  }
  return true;
}

// pedalwave's initial state → MuJoCo's: the tail tip's position and velocity, θ_1, β, α − β.
void initial_mujoco(const pm::Scene& s, const MjRobot& r, mjData* d) {
  pm::Plant p(s);
  const pm::Model& m = p.model();
  VectorXd q, v;
  p.initial_state(q, v);
  pm::Data pd(m);
  pm::update_kinematics(m, pd, q, v);
  const pm::Vec2 tip = pm::point_position(m, pd, q, pm::Model::point_tail());
  const pm::Vec2 tipv = pm::point_velocity(m, pd, v, pm::Model::point_tail());
  d->qpos[r.qroot] = tip.x();
  d->qpos[r.qroot + 1] = tip.y();
  d->qpos[r.qroot + 2] = pd.theta(0);
  d->qvel[r.vroot] = tipv.x();
  d->qvel[r.vroot + 1] = tipv.y();
  d->qvel[r.vroot + 2] = pd.theta_dot(0);
  for (int j = 0; j < m.joints(); ++j) {
    const auto J = static_cast<std::size_t>(j);
    d->qpos[r.qb[J]] = q(m.i_beta(j));
    d->qpos[r.qs[J]] = q(m.i_alpha(j)) - q(m.i_beta(j));
    d->qvel[r.vb[J]] = v(m.i_beta(j));
    d->qvel[r.vs[J]] = v(m.i_alpha(j)) - v(m.i_beta(j));
  }
}

Run run_mujoco(const pm::Scene& s, const MjRobot& r, double h, double T) {
  Run out{"MuJoCo " + std::to_string(mj_version() / 100) + "." + std::to_string(mj_version() / 10 % 10) +
              "." + std::to_string(mj_version() % 10),
          "euler", h, 0.0, {}, {}, true};
  r.m->opt.timestep = h;
  mjData* d = mj_makeData(r.m);
  initial_mujoco(s, r, d);
  mj_forward(r.m, d);
  const int steps = static_cast<int>(std::lround(T / kPeriod));
  const int sub = static_cast<int>(std::lround(kPeriod / h));
  double mass = 0.0;
  for (int b = 1; b < r.m->nbody; ++b) mass += r.m->body_mass[b];
  auto record = [&] {
    double cx = 0.0, cz = 0.0;
    for (int b = 1; b < r.m->nbody; ++b) {
      cx += r.m->body_mass[b] * d->xipos[3 * b];
      cz += r.m->body_mass[b] * d->xipos[3 * b + 2];
    }
    out.com_x.push_back(cx / mass);
    out.com_z.push_back(cz / mass);
  };
  record();
  const double t0 = pedalwave::thread_cpu_s();
  for (int k = 0; k < steps && out.ok; ++k) {
    const double t = k * kPeriod;
    for (int j = 0; j < r.N - 1; ++j) {
      gait_ref(s, j, t, d->ctrl[2 * j], d->ctrl[2 * j + 1]);
    }
    for (int i = 0; i < sub; ++i) mj_step(r.m, d);
    mj_kinematics(r.m, d);  // xipos at the new state
    // MuJoCo resets the state when it diverges (and warns): that is a failed run.
    if (d->warning[mjWARN_BADQACC].number > 0) out.ok = false;
    for (int i = 0; i < r.m->nq; ++i)
      if (!std::isfinite(d->qpos[i])) out.ok = false;
    record();
  }
  out.cpu = pedalwave::thread_cpu_s() - t0;
  mj_deleteData(d);
  return out;
}

// Max distance between two COM paths sampled alike [m].
double max_diff(const Run& a, const Run& b) {
  double e = 0.0;
  const std::size_t n = std::min(a.com_x.size(), b.com_x.size());
  for (std::size_t i = 0; i < n; ++i)
    e = std::max(e, std::hypot(a.com_x[i] - b.com_x[i], a.com_z[i] - b.com_z[i]));
  return n == a.com_x.size() && n == b.com_x.size() ? e : std::nan("");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pedalwave and MuJoCo side by side on the same robot and gait: real-time factors, "
               "their ratio, each one's COM accuracy against its own reference, the COM paths' "
               "difference"};
  std::string scene_file = std::string(PEDALWAVE_CONFIG_DIR) + "/scenes/flat_high_friction.yaml";
  double T = 10.0;
  double contact_mass = 0.0;
  int repeat = 3;
  app.add_option("--scene", scene_file, "scene YAML (flexible joints, ground only)")->check(CLI::ExistingFile);
  app.add_option("--seconds", T, "simulated time per run [s]")->check(pedalwave::toolkit::cli::finite_in(0.01, 600));
  app.add_option("--mj-contact-mass", contact_mass,
                 "MuJoCo contact as the scene's spring-damper: k/m, d/m for a contact carrying m [kg] "
                 "(0: MuJoCo's default soft contact)")
      ->check(pedalwave::toolkit::cli::finite_in(0.0, 100.0));
  app.add_option("--repeat", repeat, "runs of each compared setting; the least CPU time is kept")
      ->check(CLI::Range(1, 100));
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, kTool)) return *rc;

  return pedalwave::toolkit::cli::run(kTool, [&]() -> int {
    const pm::Scene scene = pedalwave::config::load_scene(scene_file);
    if (scene.robot.joints != pm::JointModel::kFlexible)
      return pedalwave::toolkit::cli::bad_input(
          kTool, scene_file + ": robot.joints = rigid: the MuJoCo model here is the flexible (SEA) robot");
    if (!scene.boxes.empty() || !scene.ground.patches.empty() || !scene.ground_on)
      return pedalwave::toolkit::cli::bad_input(
          kTool, scene_file + ": boxes, friction patches or no ground: only a flat ground is modelled in MuJoCo");
    MjRobot robot;
    std::string error;
    if (!load_mujoco(scene, contact_mass, robot, error)) {
      std::cerr << kTool << ": error: " << error << '\n';
      return pedalwave::toolkit::cli::kExitInternal;
    }

    std::vector<Run> runs;
    // pedalwave: the reference, the scene's shipped integrator, semi-implicit Euler at the
    // work-precision study's choice and at the paper's step.
    const pm::IntegratorOptions ref{.method = pm::Method::kDormandPrince45, .h = 1e-5, .rtol = 1e-9,
                                    .atol = 1e-11, .h_min = 1e-15, .h_max = 1e-3};
    // Each compared run `repeat` times, the least CPU time kept (the paths are identical).
    auto best_of = [&](const std::function<Run()>& f) {
      Run best = f();
      for (int i = 1; i < repeat; ++i) {
        Run r = f();
        if (r.cpu < best.cpu) best = std::move(r);
      }
      return best;
    };
    runs.push_back(run_pedalwave(scene, ref, T));
    for (const pm::IntegratorOptions& o :
         {scene.integrator, pm::IntegratorOptions{.method = pm::Method::kSemiImplicitEuler, .h = 2.5e-4},
          pm::IntegratorOptions{.method = pm::Method::kSemiImplicitEuler, .h = 1e-4}})
      runs.push_back(best_of([&] { return run_pedalwave(scene, o, T); }));
    const std::size_t mj0 = runs.size();
    // MuJoCo: its reference (Euler at 1e-5 s), the paper's step, and 2e-4 s.
    runs.push_back(run_mujoco(scene, robot, 1e-5, T));
    for (const double h : {1e-4, 2e-4}) runs.push_back(best_of([&] { return run_mujoco(scene, robot, h, T); }));
    const Run& pw_ref = runs[0];
    const Run& mj_ref = runs[mj0];
    const Run& mj_paper = runs[mj0 + 1];
    const double rtf_mj = T / mj_paper.cpu;

    std::cout << "scene " << scene.name << " (" << scene_file << "), N = " << scene.robot.N << ", "
              << T << " s simulated, gait PD at 1 kHz, CPU time the least of " << repeat
              << " runs (references: 1)\n";
    Table t({"simulator", "method", "h [s]", "CPU [s]", "real-time factor", "× MuJoCo at 1e-4 s",
             "max COM error vs own reference [mm]", "final COM x [m]"});
    for (std::size_t i = 0; i < runs.size(); ++i) {
      const Run& r = runs[i];
      const bool is_ref = i == 0 || i == mj0;
      const double rtf = T / r.cpu;
      const double err = is_ref ? std::nan("") : max_diff(r, i < mj0 ? pw_ref : mj_ref);
      t.add_row({r.sim, r.method + (is_ref ? " (reference)" : ""),
                 i == 0 ? "rtol 1e-9" : Table::num(r.h, 2), Table::num(r.cpu, 3),
                 r.ok ? Table::num(rtf, 3) : "failed", Table::num(rtf / rtf_mj, 3),
                 is_ref ? "-" : (r.ok ? Table::num(1e3 * err, 3) : "-"),
                 r.ok ? Table::num(r.com_x.back(), 4) : "-"});
    }
    std::cout << t.to_text();
    std::cout << "COM paths, pedalwave reference vs MuJoCo reference (a model difference: contact law "
                 "and the rotor's spin coupling): max "
              << Table::num(1e3 * max_diff(pw_ref, mj_ref), 3) << " mm\n";
    return 0;
  });
}
