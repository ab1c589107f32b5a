#include "pedalwave/config/scene.hpp"

#include <cmath>
#include <limits>

namespace pedalwave::config {

using namespace pedalwave::model;

Params read_robot(const Reader& r) {
  r.allow_only({"N", "m_l", "link_length", "I_l", "m_r", "I_r", "n", "K", "g", "joints",
                "rigid_variant"});
  Params p = paper_params(static_cast<int>(r.integer("N", 6, kMinLinks, kMaxLinks)));
  p.m_l = r.positive("m_l", p.m_l);
  if (r.has("link_length")) p.l = 0.5 * r.positive("link_length", 2 * p.l);
  // I_l defaults to the uniform rod of the (possibly changed) mass and length.
  p.I_l = r.positive("I_l", p.m_l * 4 * p.l * p.l / 12.0);
  p.m_r = r.non_negative("m_r", p.m_r);
  p.I_r = r.non_negative("I_r", p.I_r);
  p.n = r.positive("n", p.n);
  p.g = r.non_negative("g", p.g);
  const std::vector<double> K = r.numbers("K");
  if (K.size() == 1) p.K_all = K[0];
  else if (!K.empty()) p.K = K;
  p.joints = r.choice("joints", "flexible", {"flexible", "rigid"}) == "rigid" ? JointModel::kRigid
                                                                               : JointModel::kFlexible;
  p.rigid_variant = r.choice("rigid_variant", "exact_limit", {"exact_limit", "paper"}) == "paper"
                        ? RigidVariant::kPaper
                        : RigidVariant::kExactLimit;
  return p;
}

IntegratorOptions read_integrator(const Reader& r) {
  r.allow_only({"method", "h", "rtol", "atol", "h_min", "h_max"});
  IntegratorOptions o{.method = Method::kImplicitVelocity, .h = 1e-4};
  if (r.has("method")) {
    try {
      o.method = parse_method(r["method"].as_string());
    } catch (const std::invalid_argument& e) {
      r["method"].fail("one of euler, semi_implicit_euler, implicit_velocity, rk4, dopri45");
    }
  }
  o.h = r.positive("h", o.h);
  o.rtol = r.positive("rtol", o.rtol);
  o.atol = r.positive("atol", o.atol);
  o.h_min = r.positive("h_min", o.h_min);
  o.h_max = r.positive("h_max", o.h_max);
  return o;
}

GaitParams read_gait(const Reader& r) {
  r.allow_only({"A_p", "omega", "eta"});
  GaitParams g;
  g.A_p = r.number("A_p", g.A_p);
  g.omega = r.number("omega", g.omega);
  g.eta = r.number("eta", g.eta);
  return g;
}

namespace {
FrictionLaw read_law(const Reader& r) {
  const std::string law =
      r.choice("friction", "regularized", {"coulomb", "regularized", "tanh", "stick_slip"});
  if (law == "coulomb") return FrictionLaw::kCoulomb;
  if (law == "tanh") return FrictionLaw::kTanh;
  if (law == "stick_slip") return FrictionLaw::kStickSlip;
  return FrictionLaw::kRegularized;
}
}  // namespace

Scene read_scene(const Reader& r) {
  r.allow_only({"name", "description", "robot", "ground", "obstacles", "joint_friction",
                "torque_limit", "sensor_noise", "initial", "gait", "duration", "integrator",
                "faults"});
  Scene s;
  s.source = r.file();
  s.name = r.string("name", r.file());
  if (r.has("robot")) s.robot = read_robot(r["robot"]);
  s.ground_on = r.has("ground");
  if (s.ground_on) {
    const Reader g = r["ground"];
    g.allow_only({"z", "k", "d", "mu", "friction", "v_s", "k_t", "patches", "friction_at_com"});
    s.ground.z = g.number("z", 0.0);
    s.ground.k = g.positive("k", s.ground.k);
    s.ground.d = g.non_negative("d", s.ground.d);
    s.ground.mu = g.non_negative("mu", s.ground.mu);
    s.ground.law = read_law(g);
    s.ground.v_s = g.positive("v_s", s.ground.v_s);
    s.ground.k_t = g.positive("k_t", s.ground.k_t);
    s.ground.friction_at_com = g.boolean("friction_at_com", false);
    if (g.has("patches")) {
      const Reader ps = g["patches"];
      if (!ps.is_sequence()) ps.fail("a list of {x_begin, mu}");
      for (std::size_t i = 0; i < ps.size(); ++i) {
        const Reader p = ps.at(i);
        p.allow_only({"x_begin", "mu"});
        s.ground.patches.push_back({p.number("x_begin"), p.non_negative("mu", 0.4)});
        if (i > 0 && s.ground.patches[i].x_begin < s.ground.patches[i - 1].x_begin)
          p["x_begin"].fail("patches sorted by x_begin (this one starts before the previous)");
      }
    }
  }
  if (r.has("obstacles")) {
    const Reader os = r["obstacles"];
    if (!os.is_sequence()) os.fail("a list of boxes");
    for (std::size_t i = 0; i < os.size(); ++i) {
      const Reader b = os.at(i);
      b.allow_only({"type", "x_near", "ahead_of_head", "width", "height", "mu", "corner_contact", "edge_mu"});
      b.choice("type", "box", {"box"});
      Box box;
      if (b.has("x_near") == b.has("ahead_of_head"))
        b.fail("exactly one of x_near (absolute X [m]) or ahead_of_head (distance ahead of the head tip [m])");
      box.x_near = b.number("x_near", std::numeric_limits<double>::quiet_NaN());
      box.ahead_of_head = b.number("ahead_of_head", std::numeric_limits<double>::quiet_NaN());
      box.width = b.positive("width", box.width);
      box.height = b.positive("height", box.height);
      box.mu = b.non_negative("mu", box.mu);
      box.corner_contact = b.boolean("corner_contact", true);
      if (b.has("edge_mu")) box.edge_mu = b.non_negative("edge_mu", box.mu);  // absent: mu
      s.boxes.push_back(box);
    }
  }
  if ((s.joint_friction_on = r.has("joint_friction"))) {
    const Reader j = r["joint_friction"];
    j.allow_only({"motor_viscous"});
    s.joint_friction.motor_viscous = j.non_negative("motor_viscous", 0.0);
  }
  if ((s.torque_limit_on = r.has("torque_limit"))) {
    const Reader t = r["torque_limit"];
    t.allow_only({"u_max"});
    s.torque_limit.u_max = t.positive("u_max", 1.2);
  }
  if ((s.sensor_noise_on = r.has("sensor_noise"))) {
    const Reader n = r["sensor_noise"];
    n.allow_only({"beta_sigma", "beta_dot_sigma", "deflection_sigma", "encoder_resolution",
                  "deflection_resolution", "seed"});
    SensorNoise& sn = s.sensor_noise;
    sn.beta_sigma = n.non_negative("beta_sigma", 0.0);
    sn.beta_dot_sigma = n.non_negative("beta_dot_sigma", 0.0);
    sn.deflection_sigma = n.non_negative("deflection_sigma", 0.0);
    sn.encoder_resolution = n.non_negative("encoder_resolution", 0.0);
    sn.deflection_resolution = n.non_negative("deflection_resolution", 0.0);
    sn.seed = static_cast<std::uint64_t>(n.integer("seed", 1, 0, (1LL << 53)));
  }
  if (r.has("initial")) {
    const Reader in = r["initial"];
    in.allow_only({"pose", "x", "height", "q", "v"});
    const std::string pose = in.choice("pose", "flat", {"flat", "gait_start", "air", "explicit"});
    s.initial.pose = pose == "gait_start" ? InitialPose::kGaitStart
                     : pose == "air"      ? InitialPose::kAir
                     : pose == "explicit" ? InitialPose::kExplicit
                                          : InitialPose::kFlat;
    s.initial.x = in.number("x", 0.0);
    s.initial.height = in.number("height", 0.0);
    s.initial.q = in.numbers("q");
    s.initial.v = in.numbers("v");
    if (s.initial.pose == InitialPose::kExplicit && !in.has("q"))
      in.fail_key("q", "the full q (2N+1 values flexible, N+2 rigid) with pose: explicit");
  }
  if (r.has("faults")) {
    // Injected faults (drivers::FaultInjector: by the FaultInjectingDriver and inside the virtual
    // robot's modules): {type, joint, t_start, value, duration}.
    const Reader fs = r["faults"];
    if (!fs.is_sequence()) fs.fail("a list of {type, joint, t_start, value, duration}");
    std::string names;
    for (std::string_view n : kFaultTypeNames) names += (names.empty() ? "" : ", ") + std::string(n);
    for (std::size_t i = 0; i < fs.size(); ++i) {
      const Reader f = fs.at(i);
      f.allow_only({"type", "joint", "t_start", "value", "duration"});
      FaultSpec spec;
      if (!f.has("type")) f.fail_key("type", "a fault type");
      if (!parse_fault_type(f.string("type", ""), spec.type)) f["type"].fail("one of " + names);
      const int joints = s.robot.N - 1;
      spec.joint = static_cast<int>(f.integer("joint", 0, 0, joints - 1));
      spec.t_start = f.non_negative("t_start", 0.0);
      spec.value = f.number("value", 0.0);
      if (f.has("duration")) spec.duration = f.positive("duration", spec.duration);
      s.faults.push_back(spec);
    }
  }
  if (r.has("gait")) s.gait = read_gait(r["gait"]);
  s.duration = r.positive("duration", s.duration);
  if (r.has("integrator")) s.integrator = read_integrator(r["integrator"]);
  // Whatever the model layer still finds wrong, reported with the file name.
  try {
    validate(s);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());
  }
  return s;
}

Scene load_scene(const std::string& path) { return read_scene(Reader::load_file(path)); }

Scene parse_scene(const std::string& text, const std::string& name) {
  return read_scene(Reader::parse(text, name));
}

}  // namespace pedalwave::config
