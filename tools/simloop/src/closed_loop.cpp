#include "pedalwave/simloop/closed_loop.hpp"

#include <cmath>
#include <stdexcept>

namespace pedalwave::simloop {

control::GaitControllerParams controller_params(const model::Scene& scene, double rate_hz,
                                                double k_c) {
  if (!(rate_hz > 0) || !std::isfinite(rate_hz))
    throw std::invalid_argument("control rate = " + std::to_string(rate_hz) + " Hz: expected > 0");
  const model::Params& p = scene.robot;
  control::GaitControllerParams c;
  c.joints = p.N - 1;
  c.period = 1.0 / rate_hz;
  c.gait.A_p = scene.gait.A_p;
  c.gait.omega = scene.gait.omega;
  c.admittance.eta_n = {scene.gait.eta};
  c.admittance.k_c = k_c;
  c.actuator.K.clear();
  for (int j = 0; j < p.N - 1; ++j)
    c.actuator.K.push_back(p.joints == model::JointModel::kFlexible ? p.stiffness(j) : 1e6);
  c.actuator.reflected_inertia = {std::max(p.n * p.n * p.I_r, 1e-12)};
  if (scene.torque_limit_on) c.limits.tau_max = {scene.torque_limit.u_max};
  return c;
}

ClosedLoop::ClosedLoop(const model::Scene& scene, const Options& opt)
    : ClosedLoop(scene, opt, scene.integrator) {}

ClosedLoop::ClosedLoop(const model::Scene& scene, const Options& opt,
                       const model::IntegratorOptions& integ)
    : ClosedLoop(scene, opt, integ, controller_params(scene, opt.rate_hz, opt.k_c)) {}

ClosedLoop::ClosedLoop(const model::Scene& scene, const Options& opt,
                       const model::IntegratorOptions& integ,
                       const control::GaitControllerParams& ctl)
    : opt_(opt),
      period_(1.0 / opt.rate_hz),
      driver_(scene, drivers::SimDriverOptions{.clock = drivers::SimClock::kLockstep,
                                               .period = 1.0 / opt.rate_hz,
                                               .command_timeout = 1e9},
              integ) {
  if (opt_.controller) {
    ctl_.emplace(ctl);
    state_ = ctl_->make_state();
    ctl_->reset(state_, 0.0);
  }
  cmd_.joints = driver_.joints();
}

model::StepStatus ClosedLoop::step() {
  const double t = driver_.sim().t();
  driver_.read(0, 0, fb_);
  if (ctl_) {
    ctl_->update(t, period_, control::measurement_from(fb_), state_, out_);
    ctl_->fill_command(out_, cmd_);
  }
  cmd_.seq = ++cycle_;
  driver_.write(cmd_);
  return driver_.plant_status();
}

}  // namespace pedalwave::simloop
