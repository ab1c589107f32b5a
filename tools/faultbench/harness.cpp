#include "harness.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "pedalwave/simloop/closed_loop.hpp"

namespace pedalwave::faultbench {

using model::FaultType;
using runtime::FaultClass;

model::SensorNoise module_noise(std::uint64_t seed) {
  model::SensorNoise n;
  const double two_pi = 2.0 * std::numbers::pi;
  n.encoder_resolution = two_pi / 4096.0 / 255.0;  // 12-bit motor encoder through n = 255 [rad]
  n.beta_sigma = 1e-5;                             // [rad]
  n.beta_dot_sigma = 5e-3;                         // module's rate estimate [rad/s]
  n.deflection_resolution = two_pi / 16384.0;      // 14-bit deflection encoder [rad]
  n.deflection_sigma = 1e-4;                       // [rad]
  n.seed = seed;
  return n;
}

model::Scene shipped_scene(const std::string& name) {
  model::Scene s;
  s.name = name;
  s.robot = model::paper_params(6);
  s.ground_on = true;
  s.ground.k = 350;
  s.ground.d = 15;
  s.ground.mu = 0.82;
  s.ground.law = model::FrictionLaw::kRegularized;
  s.ground.v_s = 1e-3;
  s.initial.pose = model::InitialPose::kGaitStart;
  s.initial.theta = 0;  // link N flat: the shipped scenes' start, the README's campaign numbers
  s.integrator.method = model::Method::kImplicitVelocity;
  s.integrator.h = 5e-4;
  s.duration = 20;
  if (name == "flat_high_friction") {
  } else if (name == "flat_low_friction") {
    s.ground.mu = 0.40;
  } else if (name == "friction_change") {
    s.ground.patches.push_back({0.30, 0.40});
    s.duration = 30;
  } else if (name == "stair" || name == "stair_grip") {
    model::Box b;
    b.ahead_of_head = 0.05;
    b.width = 0.11;
    b.height = 0.06;
    b.mu = 0.82;
    if (name == "stair_grip") b.edge_mu = 1.5;  // the calibrated edge: the robot climbs
    s.boxes.push_back(b);
    s.duration = 60;
  } else {
    throw std::invalid_argument("faultbench: scene '" + name +
                                "': expected flat_high_friction, flat_low_friction, "
                                "friction_change, stair or stair_grip");
  }
  model::validate(s);
  return s;
}

observer::ObserverParams campaign_params(const model::Scene& scene, double period) {
  return observer::observer_params(scene, period);
}

namespace {
model::Scene with_noise(model::Scene s, const LoopOptions& opt) {
  if (opt.plant_h > 0) s.integrator.h = opt.plant_h;
  s.sensor_noise_on = opt.noise;
  if (opt.noise) s.sensor_noise = module_noise(opt.seed);
  return s;
}
}  // namespace

FaultLoop::FaultLoop(const model::Scene& scene, const LoopOptions& opt,
                     const observer::ObserverParams& op)
    : scene_(with_noise(scene, opt)),
      opt_(opt),
      sim_(scene_, drivers::SimDriverOptions{.clock = drivers::SimClock::kLockstep,
                                             .period = opt.period,
                                             .command_timeout = 1e9}),
      inj_(sim_, &sim_, {}, opt.seed ^ 0x5eedULL),
      ctl_(simloop::controller_params(scene_, 1.0 / opt.period, opt.k_c)),
      state_(ctl_.make_state()),
      obs_(op) {
  ctl_.reset(state_, 0.0);
  cmd_.joints = sim_.joints();
  cmd_.torque_off = true;  // the "last command" before the first write (as the runtime)
  obs_.reset();
}

model::StepStatus FaultLoop::step() {
  t_ = static_cast<double>(cycle_) * opt_.period;
  inj_.read(0, 0, fb_);
  sample_.joints = fb_.joints;
  verdict_ = stage_->observe(fb_, cmd_, t_, opt_.period, sample_);
  ctl_.update(t_, opt_.period, control::measurement_from(fb_), state_, out_);
  ctl_.fill_command(out_, cmd_);
  cmd_.torque_off = false;
  cmd_.seq = ++cycle_;
  inj_.write(cmd_);
  return sim_.plant_status();
}

const char* class_name(FaultClass f) {
  static const char* names[] = {"none", "actuator_torque", "motor_friction", "encoder_stuck",
                                "encoder_jump", "encoder_noise", "deflection_stuck",
                                "deflection_bias", "deflection_scale", "spring_broken",
                                "module_silent", "stale_data", "implausible", "saturation",
                                "overrun", "exception", "stale_feedback"};
  const auto i = static_cast<std::size_t>(f);
  return i < std::size(names) ? names[i] : "?";
}

FaultClass expected_class(FaultType f) {
  switch (f) {
    case FaultType::kTorqueGain: return FaultClass::kActuatorTorque;
    case FaultType::kMotorFriction: return FaultClass::kMotorFriction;
    case FaultType::kSpringScale: return FaultClass::kSpringBroken;
    case FaultType::kJointLoad: return FaultClass::kSaturation;
    case FaultType::kEncoderStuck: return FaultClass::kEncoderStuck;
    case FaultType::kEncoderOffset: return FaultClass::kEncoderJump;
    case FaultType::kEncoderNoise: return FaultClass::kEncoderNoise;
    case FaultType::kDeflectionStuck: return FaultClass::kDeflectionStuck;
    case FaultType::kDeflectionBias: return FaultClass::kDeflectionBias;
    case FaultType::kDeflectionScale: return FaultClass::kDeflectionScale;
    case FaultType::kNaN:
    case FaultType::kImplausible: return FaultClass::kImplausible;
    case FaultType::kModuleSilent: return FaultClass::kModuleSilent;
    case FaultType::kStale:
    case FaultType::kOutOfOrder:
    case FaultType::kRepeatedFrame: return FaultClass::kStaleData;
    default: return FaultClass::kNone;
  }
}

int expected_joint(const model::FaultSpec& f) {
  return f.type == FaultType::kRepeatedFrame ? -1 : f.joint;
}

model::FaultSpec random_fault(FaultType type, int joints, double t_min, double t_max,
                              std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  auto uni = [&](double a, double b) { return a + (b - a) * u01(rng); };
  auto sign = [&] { return u01(rng) < 0.5 ? -1.0 : 1.0; };
  model::FaultSpec f;
  f.type = type;
  f.joint = std::min(joints - 1, static_cast<int>(u01(rng) * joints));
  f.t_start = uni(t_min, t_max);
  switch (type) {
    case FaultType::kTorqueGain: f.value = uni(0.0, 0.6); break;          // loss 40…100 %
    case FaultType::kMotorFriction: f.value = uni(0.03, 0.1); break;      // [N·m·s/rad]
    case FaultType::kSpringScale: f.value = uni(0.1, 0.4); break;         // stiffness −60…−90 %
    case FaultType::kJointLoad: f.value = sign() * uni(1.0, 1.5); break;  // [N·m] vs u_max
    case FaultType::kEncoderStuck: break;
    case FaultType::kEncoderOffset: f.value = sign() * uni(0.005, 0.1); break;  // [rad]
    case FaultType::kEncoderNoise:
      f.value = uni(0.003, 0.02);  // σ [rad]
      f.duration = uni(0.2, 1.0);
      break;
    case FaultType::kDeflectionStuck: break;
    case FaultType::kDeflectionBias: f.value = sign() * uni(0.03, 0.1); break;  // [rad]
    case FaultType::kDeflectionScale:
      f.value = u01(rng) < 0.5 ? uni(0.5, 0.75) : uni(1.35, 1.8);
      break;
    case FaultType::kNaN: break;
    case FaultType::kImplausible: f.value = sign() * uni(4.0, 100.0); break;  // [rad]
    case FaultType::kModuleSilent: break;
    case FaultType::kStale: f.value = std::round(uni(1.0, 5.0)); break;
    case FaultType::kOutOfOrder: break;
    case FaultType::kRepeatedFrame: f.joint = 0; break;
    default: break;
  }
  return f;
}

RunResult run_fault(const model::Scene& scene, const LoopOptions& opt,
                    const std::optional<model::FaultSpec>& fault, double duration, double linger) {
  model::Scene s = scene;
  if (fault && fault->type == FaultType::kJointLoad && !s.torque_limit_on) {
    s.torque_limit_on = true;  // saturation needs the modules' torque limit
    s.torque_limit.u_max = 0.8;
  }
  FaultLoop loop(s, opt);
  if (fault) loop.injector().add(*fault);
  RunResult res;
  const auto cycles = static_cast<std::int64_t>(std::llround(duration / opt.period));
  double stop_at = 1e300;
  for (std::int64_t i = 0; i < cycles; ++i) {
    res.status = loop.step();
    if (res.status != model::StepStatus::kOk) break;
    const runtime::Verdict& v = loop.verdict();
    if (!res.detected && v.fault != FaultClass::kNone) {
      res.detected = true;
      res.fault = v.fault;
      res.joint = v.joint;
      res.t_detect = loop.t();
      res.value = v.value;
      res.threshold = v.threshold;
      if (const observer::FaultRecord* f = loop.observer().core().primary()) res.estimate = f->estimate;
      res.false_alarm = !fault || loop.t() < fault->t_start;
      res.latency = fault ? loop.t() - fault->t_start : 0.0;
      stop_at = loop.t() + linger;
    }
    if (loop.t() >= stop_at) break;
  }
  return res;
}

NominalStats run_nominal(const model::Scene& scene, const LoopOptions& opt, double duration,
                         double t_skip) {
  FaultLoop loop(scene, opt);
  NominalStats st;
  const auto cycles = static_cast<std::int64_t>(std::llround(duration / opt.period));
  const int J = loop.sim().joints();
  std::vector<int> hb(static_cast<std::size_t>(J), 0), hd(static_cast<std::size_t>(J), 0);
  std::vector<double> pb(static_cast<std::size_t>(J), 0), pd(static_cast<std::size_t>(J), 0);
  double sum2 = 0.0;
  std::int64_t n = 0;
  for (std::int64_t i = 0; i < cycles; ++i) {
    st.status = loop.step();
    if (st.status != model::StepStatus::kOk) break;
    st.seconds = loop.t();
    const auto& core = loop.observer().core();
    if (loop.verdict().fault != FaultClass::kNone && st.first == FaultClass::kNone) {
      st.first = loop.verdict().fault;
      st.first_joint = loop.verdict().joint;
      st.first_t = loop.t();
      st.first_value = loop.verdict().value;
    }
    for (int j = 0; j < J; ++j) {
      const auto k = static_cast<std::size_t>(j);
      const double b = loop.feedback().beta[k], d = loop.feedback().deflection[k];
      hb[k] = (i > 0 && b == pb[k]) ? hb[k] + 1 : 0;
      hd[k] = (i > 0 && d == pd[k]) ? hd[k] + 1 : 0;
      pb[k] = b;
      pd[k] = d;
      if (loop.t() < t_skip) continue;
      st.max_hold_beta = std::max(st.max_hold_beta, hb[k]);
      st.max_hold_defl = std::max(st.max_hold_defl, hd[k]);
      const double r = core.residual()[k];
      st.max_residual = std::max(st.max_residual, std::abs(r));
      sum2 += r * r;
      ++n;
      st.max_consistency = std::max(st.max_consistency, std::abs(core.consistency()[k]));
      st.max_saturation = std::max(st.max_saturation, core.saturation()[k]);
    }
  }
  st.rms_residual = n > 0 ? std::sqrt(sum2 / static_cast<double>(n)) : 0.0;
  st.alarms = loop.observer().core().fault_count();
  return st;
}

}  // namespace pedalwave::faultbench
