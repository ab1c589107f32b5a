// A simple first-order plant for the driver tests: each joint is a motor with viscous damping b
// and no inertia, so under the module law u = τ + kp (β_ref − β) + kd (β̇_ref − β̇):
//   β̇ = u / b  ⇒  β̇ = (τ + kp (β_ref − β) + kd β̇_ref) / (b + kd)
// integrated with explicit Euler sub-steps of 0.1 ms; deflection = u / K (a spring of stiffness
// K in series). The emulator thread is the only caller while it runs.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "pedalwave/drivers/module_emulator.hpp"

namespace pedalwave::test {

class FirstOrderPlant final : public drivers::ModulePlant {
 public:
  explicit FirstOrderPlant(double b = 0.05, double k_spring = 3.0, double u_max = 1.2)
      : b_(b), k_(k_spring), u_max_(u_max) {}

  void apply(const drivers::Command& cmd) override {
    cmd_ = cmd;
    ++applies_;
  }
  void measure(drivers::Feedback& out) override {
    out.joints = cmd_.joints;
    for (int j = 0; j < cmd_.joints; ++j) {
      const double u = torque(j);
      out.beta[j] = beta_[j];
      out.beta_dot[j] = rate(j);
      out.deflection[j] = std::clamp(u, -u_max_, u_max_) / k_;
      out.status[j] = std::abs(u) > u_max_ ? drivers::kStatusSaturated : 0;
    }
    last_measured_ = out;
  }
  void advance_to(std::int64_t t_ns) override {
    if (t_ns_ == 0) t_ns_ = t_ns;
    while (t_ns_ < t_ns) {
      const std::int64_t step = std::min<std::int64_t>(100'000, t_ns - t_ns_);
      for (int j = 0; j < cmd_.joints; ++j) beta_[j] += rate(j) * 1e-9 * static_cast<double>(step);
      t_ns_ += step;
    }
  }

  void hold(std::int64_t ns) override {
    if (t_ns_ != 0) t_ns_ += ns;  // time passes, nothing integrated
    held_ns_ += ns;
  }

  const drivers::Command& last_command() const { return cmd_; }
  std::int64_t plant_ns() const { return t_ns_; }  // host time the plant has reached [ns]
  std::int64_t held_ns() const { return held_ns_; }
  const drivers::Feedback& last_measured() const { return last_measured_; }
  std::uint64_t applies() const { return applies_; }

 private:
  double rate(int j) const {
    const double u = std::clamp(cmd_.tau[j] + cmd_.kp[j] * cmd_.beta_ref[j] +
                                    cmd_.kd[j] * cmd_.beta_dot_ref[j] - cmd_.kp[j] * beta_[j],
                                -u_max_, u_max_);
    return u / (b_ + cmd_.kd[j]);
  }
  double torque(int j) const {
    return cmd_.tau[j] + cmd_.kp[j] * (cmd_.beta_ref[j] - beta_[j]) +
           cmd_.kd[j] * (cmd_.beta_dot_ref[j] - rate(j));
  }

  double b_, k_, u_max_;
  drivers::Command cmd_{};
  drivers::Feedback last_measured_{};
  std::array<double, drivers::kMaxJoints> beta_{};
  std::int64_t t_ns_ = 0, held_ns_ = 0;
  std::uint64_t applies_ = 0;
};

}  // namespace pedalwave::test
