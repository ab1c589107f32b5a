#include "pedalwave/config/scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "pedalwave/drivers/fault_injector.hpp"
#include "pedalwave/model/plant.hpp"

namespace pedalwave::config {

using namespace pedalwave::model;

Params read_robot(const Reader& r, bool link_shape) {
  if (link_shape)
    r.allow_only({"N", "m_l", "link_length", "I_l", "m_r", "I_r", "n", "K", "g", "joints",
                  "rigid_variant", "link_shape", "link_radius", "link_height"});
  else
    r.allow_only({"N", "m_l", "link_length", "I_l", "m_r", "I_r", "n", "K", "g", "joints",
                  "rigid_variant"});
  // Ranges: what a snake robot of SEA modules can be (far outside them the integrators overflow
  // within the first steps, e.g. K = 1e308).
  Params p = paper_params(static_cast<int>(r.integer("N", 6, kMinLinks, kMaxLinks)));
  p.m_l = r.bounded("m_l", p.m_l, 0, 1e3, "kg", true);
  if (r.has("link_length")) p.l = 0.5 * r.bounded("link_length", 2 * p.l, 0, 10, "m", true);
  // I_l defaults to the uniform rod of the (possibly changed) mass and length.
  p.I_l = r.bounded("I_l", p.m_l * 4 * p.l * p.l / 12.0, 0, 1e3, "kg·m²", true);
  p.m_r = r.bounded("m_r", p.m_r, 0, 1e3, "kg");
  p.I_r = r.bounded("I_r", p.I_r, 0, 1, "kg·m²");
  p.n = r.bounded("n", p.n, 0, 1e5, "-", true);
  p.g = r.bounded("g", p.g, 0, 100, "m/s²");
  const std::vector<double> K = r.bounded_numbers("K", 0, 1e6, "N·m/rad", true);
  if (K.size() == 1) p.K_all = K[0];
  else if (!K.empty()) p.K = K;
  if (K.size() > 1 && static_cast<int>(K.size()) != p.N - 1)
    r["K"].fail("one stiffness for every joint or N-1 = " + std::to_string(p.N - 1) +
                " of them (one per joint), not " + std::to_string(K.size()));
  p.joints = r.choice("joints", "flexible", {"flexible", "rigid"}) == "rigid" ? JointModel::kRigid
                                                                               : JointModel::kFlexible;
  p.rigid_variant = r.choice("rigid_variant", "exact_limit", {"exact_limit", "paper"}) == "paper"
                        ? RigidVariant::kPaper
                        : RigidVariant::kExactLimit;
  // The variant picks the rigid model's equations: with flexible joints it would be ignored.
  if (r.has("rigid_variant") && p.joints == JointModel::kFlexible)
    r["rigid_variant"].fail("joints: rigid beside it (rigid_variant chooses between the rigid "
                            "model's equations; these joints are flexible)");
  if (!link_shape) return p;
  // The module's contact geometry (README "Link shapes"): its size is required with its shape and
  // refused with another one (it would be ignored).
  const std::string shape = r.choice("link_shape", "segment", {"segment", "capsule", "box"});
  p.link_shape = shape == "capsule" ? LinkShape::kCapsule : shape == "box" ? LinkShape::kBox : LinkShape::kSegment;
  if (p.link_shape == LinkShape::kCapsule)
    r.required("link_radius", "the capsule's radius [m] with link_shape: capsule");
  if (p.link_shape == LinkShape::kBox)
    r.required("link_height", "the module's height [m] with link_shape: box");
  p.link_radius = r.bounded("link_radius", 0.0, 0, 1, "m", true);
  p.link_height = r.bounded("link_height", 0.0, 0, 2, "m", true);
  if (r.has("link_radius") && p.link_shape != LinkShape::kCapsule)
    r["link_radius"].fail("link_shape: capsule beside it (the radius of a capsule link; the shape is " + shape + ")");
  if (r.has("link_height") && p.link_shape != LinkShape::kBox)
    r["link_height"].fail("link_shape: box beside it (the height of a box link; the shape is " + shape + ")");
  return p;
}

IntegratorOptions read_integrator(const Reader& r) {
  r.allow_only({"method", "h", "rtol", "atol", "h_min", "h_max"});
  IntegratorOptions o{.method = Method::kImplicitVelocity, .h = 1e-4};
  if (r.has("method")) {
    try {
      o.method = parse_method(r["method"].as_string());
    } catch (const std::invalid_argument& e) {
      r["method"].fail("one of euler, semi_implicit_euler, implicit_velocity, rk4, dopri45, implicit_contact");
    }
  }
  // h below 1e-7 s never ends a run (1e-15: 1e16 steps for 10 s); above 0.1 s it is no step.
  o.h = r.bounded("h", o.h, 1e-7, 0.1, "s");
  // The tolerances and step bounds belong to the adaptive method: with a fixed step they would
  // be ignored. Read first: a key with no value is that error, not this one.
  o.rtol = r.bounded("rtol", o.rtol, 0, 1, "-", true);
  o.atol = r.bounded("atol", o.atol, 0, 1, "-", true);
  o.h_min = r.bounded("h_min", o.h_min, 1e-12, 0.1, "s");
  o.h_max = r.bounded("h_max", o.h_max, 1e-7, 1, "s");
  for (const char* k : {"rtol", "atol", "h_min", "h_max"})
    if (r.has(k) && !is_adaptive(o.method))
      r[k].fail(std::string("integrator.method: dopri45 beside it (") + k +
                " is the adaptive method's; method is " + std::string(to_string(o.method)) + ")");
  if (r.has("h_min") && o.h_min > o.h_max) r["h_min"].fail("h_min <= h_max = " + std::to_string(o.h_max) + " s");
  return o;
}

GaitParams read_gait(const Reader& r, double A_p_min) {
  r.allow_only({"A_p", "omega", "eta"});
  GaitParams g;
  g.A_p = r.bounded("A_p", g.A_p, A_p_min, M_PI, "rad");
  g.omega = r.bounded("omega", g.omega, -100, 100, "rad/s");
  g.eta = r.bounded("eta", g.eta, -2 * M_PI, 2 * M_PI, "rad");
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

namespace {

// A start inside the ground or a box stores k·depth²/2 per body point and launches the robot (2 cm
// into k = 1e5 N/m threw it 8.9 m up): the normal force k·depth at the deepest point of the start
// pose (any pose, explicit q included; boxes use the ground's k) may be at most 10 × the robot's
// weight (the links and the modules at the joints). Blamed on initial.height, initial.q, or the
// obstacles, whichever put the robot there.
void check_start_depth(const Reader& r, const Scene& s) {
  if (!s.ground_on && s.boxes.empty()) return;
  const Params& p = s.robot;
  const double weight = (p.N * p.m_l + (p.N - 1) * p.m_r) * p.g;  // [N]
  const double depth_max = 10.0 * weight / s.ground.k;             // [m]
  model::Plant plant(s);
  Eigen::VectorXd q, v;
  plant.initial_state(q, v);
  model::ContactReport rep;
  plant.report(q, v, rep);
  if (rep.max_penetration <= depth_max) return;
  const bool explicit_q = s.initial.pose == InitialPose::kExplicit;
  const bool sunk = !explicit_q && s.initial.height < 0 && -s.initial.height >= rep.max_penetration - 1e-12;
  std::ostringstream os;
  os << "a start at most " << depth_max << " m inside the ground or a box (k·depth <= 10 × the robot's weight "
     << weight << " N at ground.k = " << s.ground.k << " N/m; deeper, the contact launches the robot); this start is "
     << rep.max_penetration << " m deep";
  if (explicit_q) r["initial"]["q"].fail(os.str());
  if (sunk || s.boxes.empty()) r["initial"]["height"].fail(os.str());
  r["obstacles"].fail(os.str() + ", inside an obstacle");
}

}  // namespace

Scene read_scene(const Reader& r) {
  r.allow_only({"name", "description", "robot", "ground", "obstacles", "joint_friction",
                "torque_limit", "sensor_noise", "initial", "gait", "duration", "integrator",
                "faults"});
  Scene s;
  s.source = r.file();
  s.name = r.string("name", r.file());
  // A given name names pedalwave_sim's output folder (sim_out/<name>) and workprec's report file.
  if (r.has("name") && (s.name.empty() || s.name.size() > 63 ||
                        std::any_of(s.name.begin(), s.name.end(), [](char c) {
                          return c == '/' || static_cast<unsigned char>(c) < 0x20 || c == 0x7f;
                        })))
    r["name"].fail("a name of 1 … 63 characters, no '/' or control characters");
  (void)r.string("description", "");  // a label: any text, but text
  if (r.has("robot")) s.robot = read_robot(r["robot"], true);
  s.ground_on = r.has("ground");
  if (s.ground_on) {
    const Reader g = r["ground"];
    g.allow_only({"z", "k", "d", "mu", "friction", "v_s", "k_t", "patches", "friction_at_com"});
    s.ground.z = g.bounded("z", 0.0, -1e3, 1e3, "m");
    s.ground.k = g.bounded("k", s.ground.k, 0, 1e7, "N/m", true);
    s.ground.d = g.bounded("d", s.ground.d, 0, 1e5, "N·s/m");
    s.ground.mu = g.bounded("mu", s.ground.mu, 0, 10, "-");
    s.ground.law = read_law(g);
    s.ground.v_s = g.bounded("v_s", s.ground.v_s, 0, 10, "m/s", true);
    s.ground.k_t = g.bounded("k_t", s.ground.k_t, 0, 1e8, "N/m", true);
    s.ground.friction_at_com = g.boolean("friction_at_com", false);
    // Thick links keep no stick-slip anchors, and a box link never touches at its COM.
    if (s.robot.link_shape != LinkShape::kSegment && s.ground.law == FrictionLaw::kStickSlip)
      g["friction"].fail(std::string("coulomb, regularized or tanh with robot.link_shape: ") +
                         to_string(s.robot.link_shape) + " (stick_slip's anchors are the segment's body points)");
    if (s.robot.link_shape == LinkShape::kBox && s.ground.friction_at_com)
      g["friction_at_com"].fail("false with robot.link_shape: box (a box link touches with its corners, never at its COM)");
    if (g.has("patches")) {
      const Reader ps = g["patches"];
      if (!ps.is_sequence()) ps.fail("a list of {x_begin, mu}");
      for (std::size_t i = 0; i < ps.size(); ++i) {
        const Reader p = ps.at(i);
        p.allow_only({"x_begin", "mu"});
        p.required("x_begin", "a number");
        s.ground.patches.push_back({p.bounded("x_begin", 0.0, -1e4, 1e4, "m"), p.bounded("mu", 0.4, 0, 10, "-")});
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
      box.x_near = b.bounded("x_near", std::numeric_limits<double>::quiet_NaN(), -1e4, 1e4, "m");
      box.ahead_of_head = b.bounded("ahead_of_head", std::numeric_limits<double>::quiet_NaN(), -1e4, 1e4, "m");
      box.width = b.bounded("width", box.width, 0, 1e3, "m", true);
      box.height = b.bounded("height", box.height, 0, 10, "m", true);
      box.mu = b.bounded("mu", box.mu, 0, 10, "-");
      box.corner_contact = b.boolean("corner_contact", true);
      if (b.has("edge_mu")) box.edge_mu = b.bounded("edge_mu", box.mu, 0, 10, "-");  // absent: mu
      s.boxes.push_back(box);
    }
  }
  if ((s.joint_friction_on = r.has("joint_friction"))) {
    const Reader j = r["joint_friction"];
    j.allow_only({"motor_viscous"});
    s.joint_friction.motor_viscous = j.bounded("motor_viscous", 0.0, 0, 1e3, "N·m·s/rad");
  }
  if ((s.torque_limit_on = r.has("torque_limit"))) {
    const Reader t = r["torque_limit"];
    t.allow_only({"u_max"});
    s.torque_limit.u_max = t.bounded("u_max", 1.2, 0, 1e4, "N·m", true);
  }
  if ((s.sensor_noise_on = r.has("sensor_noise"))) {
    const Reader n = r["sensor_noise"];
    n.allow_only({"beta_sigma", "beta_dot_sigma", "deflection_sigma", "encoder_resolution",
                  "deflection_resolution", "seed"});
    SensorNoise& sn = s.sensor_noise;
    sn.beta_sigma = n.bounded("beta_sigma", 0.0, 0, 10, "rad");
    sn.beta_dot_sigma = n.bounded("beta_dot_sigma", 0.0, 0, 1e3, "rad/s");
    sn.deflection_sigma = n.bounded("deflection_sigma", 0.0, 0, 10, "rad");
    sn.encoder_resolution = n.bounded("encoder_resolution", 0.0, 0, 1, "rad");
    sn.deflection_resolution = n.bounded("deflection_resolution", 0.0, 0, 1, "rad");
    sn.seed = static_cast<std::uint64_t>(n.integer("seed", 1, 0, (1LL << 53)));
  }
  if (r.has("initial")) {
    const Reader in = r["initial"];
    in.allow_only({"pose", "x", "height", "theta", "q", "v"});
    const std::string pose = in.choice("pose", "flat", {"flat", "gait_start", "air", "explicit"});
    s.initial.pose = pose == "gait_start" ? InitialPose::kGaitStart
                     : pose == "air"      ? InitialPose::kAir
                     : pose == "explicit" ? InitialPose::kExplicit
                                          : InitialPose::kFlat;
    s.initial.x = in.bounded("x", 0.0, -1e4, 1e4, "m");
    s.initial.height = in.bounded("height", 0.0, -0.1, 100, "m");
    if (in.has("theta")) {
      if (s.initial.pose == InitialPose::kExplicit)
        in["theta"].fail("no theta with pose: explicit (q gives θ_N)");
      s.initial.theta = in.bounded("theta", 0.0, -M_PI, M_PI, "rad");
    }
    s.initial.q = in.bounded_numbers("q", -1e4, 1e4, "rad or m");
    s.initial.v = in.bounded_numbers("v", -1e3, 1e3, "rad/s or m/s");
    if (s.initial.pose == InitialPose::kExplicit && !in.has("q"))
      in.fail_key("q", "the full q (2N+1 values flexible, N+2 rigid) with pose: explicit");
  }
  if (r.has("faults")) {
    // Injected faults (drivers::FaultInjector: by the FaultInjectingDriver and inside the virtual
    // robot's modules): {type, joint, t_start, value, duration}.
    const Reader fs = r["faults"];
    if (!fs.is_sequence()) fs.fail("a list of {type, joint, t_start, value, duration}");
    if (fs.size() > static_cast<std::size_t>(drivers::FaultInjector::kMaxFaults))
      fs.at(static_cast<std::size_t>(drivers::FaultInjector::kMaxFaults))
          .fail("at most " + std::to_string(drivers::FaultInjector::kMaxFaults) + " faults");
    std::string names;
    for (std::string_view n : kFaultTypeNames) names += (names.empty() ? "" : ", ") + std::string(n);
    for (std::size_t i = 0; i < fs.size(); ++i) {
      const Reader f = fs.at(i);
      f.allow_only({"type", "joint", "t_start", "value", "duration"});
      FaultSpec spec;
      const Reader type = f.required("type", "a fault type");
      if (!type.is_scalar() || !parse_fault_type(type.as_string(), spec.type)) type.fail("one of " + names);
      if (spec.type == FaultType::kSpringScale) f.required("value", "a stiffness factor > 0 (spring_scale)");
      const int joints = s.robot.N - 1;
      spec.joint = static_cast<int>(f.integer("joint", 0, 0, joints - 1));
      spec.t_start = f.bounded("t_start", 0.0, 0, 1e6, "s");
      spec.value = f.bounded("value", 0.0, -1e6, 1e6, "");
      // Each type's own range (drivers::FaultInjector::validate checks them again, without lines).
      switch (spec.type) {
        case FaultType::kStale:  // the values of `value` cycles ago, from the injector's history
          spec.value = static_cast<double>(
              f.integer("value", 1, 1, drivers::FaultInjector::kMaxStaleDelay));
          break;
        case FaultType::kTorqueGain:
        case FaultType::kMotorFriction:
        case FaultType::kEncoderNoise:
          spec.value = f.bounded("value", 0.0, 0, 1e6, "");
          break;
        case FaultType::kSpringScale:
          spec.value = f.bounded("value", 0.0, 0, 1e6, "-", true);
          break;
        default:
          break;
      }
      if (f.has("duration")) spec.duration = f.bounded("duration", spec.duration, 0, 1e6, "s", true);
      s.faults.push_back(spec);
    }
  }
  if (r.has("gait")) s.gait = read_gait(r["gait"]);
  s.duration = r.bounded("duration", s.duration, 0, 1e6, "s", true);
  if (r.has("integrator")) s.integrator = read_integrator(r["integrator"]);
  // Whatever the model layer still finds wrong, reported with the file name.
  try {
    validate(s);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());
  }
  check_start_depth(r, s);
  return s;
}

Scene load_scene(const std::string& path) { return read_scene(Reader::load_file(path)); }

Scene load_scene(const std::string& path, const SceneUse& use) {
  const Reader r = Reader::load_file(path);
  if (!use.faults && r.has("faults"))
    r["faults"].fail("no faults: list (" + use.consumer +
                     " does not inject them; run the scene with pedalwave_runtime's sim driver, "
                     "pedalwave_virtual_robot or pedalwave_faultbench)");
  return read_scene(r);
}

Scene parse_scene(const std::string& text, const std::string& name) {
  return read_scene(Reader::parse(text, name));
}

}  // namespace pedalwave::config
