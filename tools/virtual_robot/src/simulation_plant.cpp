#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/vrobot/virtual_robot.hpp"

namespace pedalwave::vrobot {

namespace {
constexpr auto kRelaxed = std::memory_order_relaxed;
}

SimulationPlant::SimulationPlant(const model::Scene& scene, const PlantOptions& opt)
    : opt_(opt),
      sim_(std::make_unique<model::Simulation>(scene, scene.integrator)),
      data_(sim_->plant().model()),
      injector_(sim_->plant().model().joints(), /*physical=*/true, opt.fault_seed) {
  if (!(opt_.max_gap > 0) || !std::isfinite(opt_.max_gap))
    throw std::invalid_argument("virtual robot: max_gap = " + std::to_string(opt_.max_gap) +
                                " s: expected a finite value > 0");
  if (!(opt_.record_period >= 0) || !std::isfinite(opt_.record_period))
    throw std::invalid_argument("virtual robot: record_period = " +
                                std::to_string(opt_.record_period) + " s: expected ≥ 0");
  joints_ = sim_->plant().model().joints();
  if (joints_ < 1 || joints_ > drivers::kMaxJoints)
    throw std::invalid_argument("virtual robot: the scene's robot has " + std::to_string(joints_) +
                                " joints, expected 1…" + std::to_string(drivers::kMaxJoints));
  fixed_step_ = !model::is_adaptive(scene.integrator.method);
  h_ = scene.integrator.h;
  const auto J = static_cast<Eigen::Index>(joints_);
  meas_.beta = Eigen::VectorXd::Zero(J);
  meas_.beta_dot = Eigen::VectorXd::Zero(J);
  meas_.deflection = Eigen::VectorXd::Zero(J);
  u_ = Eigen::VectorXd::Zero(J);
  // Modules start with their output off (the emulator applies its torque-off command first).
  model::ActuatorInput& in = sim_->plant().input();
  in.tau.setZero();
  in.kp.setZero();
  in.kd.setZero();
  in.torque_off = true;
  if (opt_.record_period > 0 && opt_.record_capacity > 0) {
    rec_t_.reserve(opt_.record_capacity);
    rec_x_.reserve(opt_.record_capacity);
  }
  const double x = com_x_now();
  com_x_.store(x, kRelaxed);
  com_x0_.store(x, kRelaxed);

  // The scene's faults, inside the modules (validated now, applied in the cycle).
  for (auto& t : onset_t_) t.store(std::numeric_limits<double>::quiet_NaN(), kRelaxed);
  for (std::size_t i = 0; i < scene.faults.size(); ++i) {
    const model::FaultSpec& f = scene.faults[i];
    const std::string where = "virtual robot: scene '" + scene.name + "' faults[" +
                              std::to_string(i) + "]: ";
    if (!opt_.apply_scene_faults) {
      skipped_.push_back(f);
      continue;
    }
    if (drivers::is_host_side(f.type)) {
      if (opt_.ignore_host_side_faults) {
        skipped_.push_back(f);
        continue;
      }
      throw std::invalid_argument(
          where + std::string(model::to_string(f.type)) + " (joint: " + std::to_string(f.joint) +
          ") is a fault of the host's reception (old, reordered or repeated frames), not of a "
          "module: the virtual robot cannot inject it inside the modules. Use the module "
          "emulator's counter faults instead (FaultConfig::module[j].counter = kRepeat or "
          "kBackwards; pedalwave_virtual_robot --counter-fault J:repeat|backwards), or skip the "
          "host-side faults (PlantOptions::ignore_host_side_faults; pedalwave_virtual_robot "
          "--ignore-host-faults)");
    }
    try {
      injector_.add(f, "scene");
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(where + e.what());
    }
  }
}

double SimulationPlant::com_x_now() {
  const model::Model& m = sim_->plant().model();
  model::update_kinematics(m, data_, sim_->q(), sim_->v());
  return model::center_of_mass(m, data_, sim_->q()).x();
}

void SimulationPlant::record() {
  const double t = sim_->t();
  const double x = com_x_now();
  com_x_.store(x, kRelaxed);
  t_.store(t, kRelaxed);
  if (opt_.record_period <= 0) return;
  if (t + 1e-12 >= next_record_t_ && rec_t_.size() < rec_t_.capacity()) {
    rec_t_.push_back(t);  // within the reserved capacity: no allocation
    rec_x_.push_back(x);
  }
  while (next_record_t_ <= t + 1e-12) next_record_t_ += opt_.record_period;
}

void SimulationPlant::apply(const drivers::Command& cmd) {
  drivers::to_actuator_input(cmd, sim_->plant().input());
  // A joint is off when the module says so for all (torque_off) or zeroed its law (ModuleBank
  // sends tau = kp = kd = 0 for a torque-off module).
  const bool off = cmd.torque_off;
  if (off && was_on_) off_applies_.fetch_add(1, kRelaxed);
  was_on_ = !off;
  all_off_.store(off, kRelaxed);
}

void SimulationPlant::measure(drivers::Feedback& out) {
  model::Simulation& s = *sim_;
  s.plant().measure(s.q(), s.v(), meas_);
  drivers::to_feedback(meas_, out);
  const model::Scene& sc = s.plant().scene();
  if (sc.torque_limit_on && sc.torque_limit.u_max > 0) {
    s.plant().motor_torques(s.q(), s.v(), u_);
    for (int j = 0; j < joints_; ++j)
      if (std::abs(u_(j)) >= sc.torque_limit.u_max * (1.0 - 1e-9))
        out.status[static_cast<std::size_t>(j)] |= drivers::kStatusSaturated;
  }
  if (status_.load(kRelaxed) != 0)
    for (int j = 0; j < joints_; ++j)
      out.status[static_cast<std::size_t>(j)] |= drivers::kStatusEncoderFault;
  // Sensor faults on what the modules report (their PD law above used the true signals).
  if (!injector_.faults().empty()) {
    injector_.apply_sensors(s.t(), out);
    note_active(s.t(), /*physical=*/false);
  }
}

bool SimulationPlant::answering(int j) const { return !injector_.silent(j, sim_->t()); }

void SimulationPlant::note_active(double t, bool physical) {
  const std::vector<model::FaultSpec>& faults = injector_.faults();
  for (std::size_t i = 0; i < faults.size(); ++i)
    if (model::is_physical(faults[i].type) == physical &&
        drivers::FaultInjector::active(faults[i], t) && std::isnan(onset_t_[i].load(kRelaxed))) {
      onset_ns_[i].store(origin_ns_ + std::llround(t * 1e9), kRelaxed);
      onset_t_[i].store(t, kRelaxed);
    }
}

void SimulationPlant::advance_to(std::int64_t t_ns) {
  model::Simulation& s = *sim_;
  if (!started_) {  // the first SYNC: plant time 0
    started_ = true;
    origin_ns_ = t_ns;
    record();
    return;
  }
  if (status_.load(kRelaxed) != 0) return;  // failed: frozen
  double target = static_cast<double>(t_ns - origin_ns_) * 1e-9;
  if (target - s.t() > opt_.max_gap) {
    // The host was away: do not integrate the gap, move the origin so that now = plant time.
    gaps_.fetch_add(1, kRelaxed);
    gap_time_.store(gap_time_.load(kRelaxed) + (target - s.t()), kRelaxed);
    origin_ns_ = t_ns - static_cast<std::int64_t>(std::llround(s.t() * 1e9));
    return;
  }
  if (target <= s.t() + 1e-12) return;
  // Plant steps of h up to the SYNC, the last one shortened so the sample is taken at the SYNC.
  const std::uint64_t steps = fixed_step_
      ? static_cast<std::uint64_t>(std::ceil((target - s.t()) / h_ - 1e-9)) : 1u;
  // Physical faults active at the start of this advance (healed once they have ended).
  if (injector_.apply_physical(s.t(), s.plant().faults())) note_active(s.t(), /*physical=*/true);
  const model::StepStatus st = s.advance_to(target);
  steps_.fetch_add(steps, kRelaxed);
  if (st != model::StepStatus::kOk) status_.store(static_cast<int>(st));
  record();
}

void SimulationPlant::hold(std::int64_t ns) {
  if (!started_ || ns <= 0) return;
  origin_ns_ += ns;
  gaps_.fetch_add(1, kRelaxed);
  gap_time_.store(gap_time_.load(kRelaxed) + 1e-9 * static_cast<double>(ns), kRelaxed);
}

PlantProgress SimulationPlant::progress() const {
  PlantProgress p;
  p.t = t_.load(kRelaxed);
  p.com_x = com_x_.load(kRelaxed);
  p.com_x0 = com_x0_.load(kRelaxed);
  p.steps = steps_.load(kRelaxed);
  p.gaps_skipped = gaps_.load(kRelaxed);
  p.gap_time_skipped = gap_time_.load(kRelaxed);
  p.torque_off_applies = off_applies_.load(kRelaxed);
  p.all_off = all_off_.load(kRelaxed);
  p.failed = status_.load(kRelaxed) != 0;
  return p;
}

double SimulationPlant::forward_speed(double t_from) const {
  std::size_t i0 = 0;
  while (i0 < rec_t_.size() && rec_t_[i0] < t_from) ++i0;
  if (i0 + 1 >= rec_t_.size()) return std::numeric_limits<double>::quiet_NaN();
  const std::size_t i1 = rec_t_.size() - 1;
  return (rec_x_[i1] - rec_x_[i0]) / (rec_t_[i1] - rec_t_[i0]);
}

namespace {
// 4 → "4.0", 0.25 → "0.25" (seconds and values as a scene file would give them).
std::string number(double x) {
  char b[32];
  const bool one_decimal = std::abs(x * 10 - std::round(x * 10)) < 1e-9 && std::abs(x) < 1e9;
  std::snprintf(b, sizeof b, one_decimal ? "%.1f" : "%g", x);
  return b;
}
bool has_value(model::FaultType t) {
  using model::FaultType;
  switch (t) {
    case FaultType::kEncoderStuck:
    case FaultType::kDeflectionStuck:
    case FaultType::kNaN:
    case FaultType::kModuleSilent:
    case FaultType::kOutOfOrder:
    case FaultType::kRepeatedFrame:
      return false;
    default:
      return true;
  }
}
}  // namespace

std::string describe(const model::FaultSpec& f) {
  std::string s(model::to_string(f.type));
  if (has_value(f.type)) s.append(" ").append(number(f.value));
  if (f.type == model::FaultType::kRepeatedFrame) s.append(" on every joint");
  else s.append(" on joint ").append(std::to_string(f.joint + 1));
  s.append(" from ").append(number(f.t_start)).append(" s");
  if (std::isfinite(f.duration)) s.append(" for ").append(number(f.duration)).append(" s");
  return s;
}

}  // namespace pedalwave::vrobot
