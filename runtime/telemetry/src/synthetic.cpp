#include "pedalwave/telemetry/synthetic.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace pedalwave::telemetry {
namespace {

template <std::size_t M>
void set_text(std::array<char, M>& dst, const char* s) {
  std::snprintf(dst.data(), M, "%s", s);
}

}  // namespace

SyntheticRobot::SyntheticRobot(int joints, double rate_hz) : joints_(joints), rate_hz_(rate_hz) {
  if (joints < 1 || joints > runtime::kMaxJoints) {
    throw std::invalid_argument("synthetic robot: joints = " + std::to_string(joints) +
                                ": expected 1.." + std::to_string(runtime::kMaxJoints));
  }
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) {
    throw std::invalid_argument("synthetic robot: rate_hz = " + std::to_string(rate_hz) +
                                ": expected a finite rate > 0");
  }
}

runtime::RobotDescription SyntheticRobot::description() const {
  runtime::RobotDescription d;
  d.links = joints_ + 1;
  d.link_length = 0.12;
  d.link_mass = 0.35;
  d.rotor_mass = 0.05;
  d.rotor_inertia = 2.5e-6;
  d.gear_ratio = 100.0;
  for (int j = 0; j < joints_; ++j) d.spring_stiffness[static_cast<std::size_t>(j)] = 8.0 + 0.25 * j;
  d.rate_hz = rate_hz_;
  set_text(d.name, "synthetic");
  set_text(d.driver, "synthetic");
  return d;
}

runtime::CycleSample SyntheticRobot::sample(std::uint64_t seq) const {
  runtime::CycleSample s;
  const double t = static_cast<double>(seq) / rate_hz_;
  const double omega = 2.0 * M_PI * 0.5;   // gait frequency [rad/s]
  const double eta = 0.6;                  // phase lag between joints [rad]
  s.seq = seq;
  s.t_ns = 1'000'000'000 + static_cast<std::int64_t>(std::llround(1e9 * t));
  s.t = t;
  // Mode: RUNNING, except a FAULT window every 20 s (cycles 10..12 s).
  s.mode = std::fmod(t, 20.0) >= 10.0 && std::fmod(t, 20.0) < 12.0 ? runtime::Mode::kFault
                                                                     : runtime::Mode::kRunning;
  s.joints = joints_;
  for (int j = 0; j < joints_; ++j) {
    const auto i = static_cast<std::size_t>(j);
    const double ph = omega * t - eta * j;
    s.beta[i] = 0.5 * std::sin(ph);
    s.beta_dot[i] = 0.5 * omega * std::cos(ph);
    s.deflection[i] = 0.01 * std::sin(ph + 0.3) + 1e-4 * j;
    s.alpha[i] = s.beta[i] - s.deflection[i];
    s.tau_sea[i] = (8.0 + 0.25 * j) * s.deflection[i];
    s.alpha_d[i] = 0.45 * std::sin(ph + 0.05);
    s.eta[i] = eta + 0.01 * std::sin(0.1 * t + j);
    s.u[i] = 0.2 * std::cos(ph) + 0.001 * j;
    s.residual[i] = 0.002 * std::sin(7.0 * t + j) + (j == 2 && s.mode == runtime::Mode::kFault ? 0.3 : 0.0);
    s.tau_ext[i] = 0.05 * std::cos(3.0 * t + 0.5 * j);
  }
  for (std::size_t k = 0; k < s.body.size(); ++k) s.body[k] = 0.01 * (k + 1) * std::sin(t + k);
  s.fault_flags = s.mode == runtime::Mode::kFault
                      ? (1u << static_cast<unsigned>(runtime::FaultClass::kActuatorTorque))
                      : 0u;
  s.fault_joint = static_cast<std::int16_t>(s.mode == runtime::Mode::kFault ? 2 : -1);
  s.forward_speed = 0.05 + 0.01 * std::sin(omega * t);
  s.wake_latency_ns = static_cast<std::int32_t>(5000 + seq % 997);
  s.t_read_ns = static_cast<std::int32_t>(3000 + seq % 101);
  s.t_observe_ns = static_cast<std::int32_t>(20000 + seq % 503);
  s.t_control_ns = static_cast<std::int32_t>(4000 + seq % 211);
  s.t_write_ns = static_cast<std::int32_t>(2000 + seq % 53);
  s.overruns = static_cast<std::uint32_t>(seq / 100000);
  s.ring_drops = seq / 250000;
  return s;
}

runtime::EventSample SyntheticRobot::fault_event(std::uint64_t k, std::uint64_t seq) const {
  runtime::EventSample e;
  e.seq = seq;
  e.t_ns = sample(seq).t_ns;
  const auto classes = static_cast<std::uint64_t>(runtime::FaultClass::kCount) - 1;
  e.fault = static_cast<runtime::FaultClass>(1 + k % classes);
  e.severity = static_cast<runtime::Severity>(k % 4);
  // Only a kStop fault changes the mode (RUNNING → FAULT); the others are reported while running.
  e.from = runtime::Mode::kRunning;
  e.to = e.severity == runtime::Severity::kStop ? runtime::Mode::kFault : runtime::Mode::kRunning;
  e.joint = static_cast<std::int16_t>(k % static_cast<std::uint64_t>(joints_));
  e.value = 0.1 + 0.001 * static_cast<double>(k);
  e.threshold = 0.05;
  std::snprintf(e.text.data(), e.text.size(), "synthetic fault #%llu",
                static_cast<unsigned long long>(k));
  return e;
}

runtime::EventSample SyntheticRobot::mode_event(runtime::Mode from, runtime::Mode to,
                                                std::uint64_t seq) const {
  runtime::EventSample e;
  e.seq = seq;
  e.t_ns = sample(seq).t_ns;
  e.from = from;
  e.to = to;
  std::snprintf(e.text.data(), e.text.size(), "synthetic mode change at cycle %llu",
                static_cast<unsigned long long>(seq));
  return e;
}

}  // namespace pedalwave::telemetry
