#include "pedalwave/observer/input_log.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "pedalwave/csv/csv.hpp"

namespace pedalwave::observer {

namespace {

// The depth of the command history the runtime hands the observer (Runtime::kCommandHistory;
// tests/runtime/observer/input_log_test.cpp checks they agree).
constexpr int kHistory = 16;

constexpr const char* kCycleColumns[] = {"cycle",   "t",          "dt",    "fb_seq", "stamp_ns", "timing",
                                         "cmd_seq", "torque_off", "fault", "flags",  "fault_joint"};
constexpr const char* kJointColumns[] = {"beta",        "beta_dot",   "deflection",       "status",
                                         "sample_ns",   "applied_seq", "applied_ns",      "late_applied_seq",
                                         "late_applied_ns", "tau",    "beta_ref",         "beta_dot_ref",
                                         "kp",          "kd",         "residual"};
// The integer columns of a joint (the rest are doubles).
constexpr bool kJointInteger[] = {false, false, false, true,  true,  true,  true, true,
                                  true,  false, false, false, false, false, false};
constexpr bool kCycleInteger[] = {true, false, false, true, true, true, true, true, true, true, true};
static_assert(std::size(kJointColumns) == std::size(kJointInteger));
static_assert(std::size(kCycleColumns) == std::size(kCycleInteger));

std::string joint_column(const char* q, int j) { return std::string(q) + "_" + std::to_string(j + 1); }

}  // namespace

InputLog::InputLog(int joints, std::size_t capacity) : joints_(joints) {
  if (joints < 1 || joints > drivers::kMaxJoints)
    throw std::invalid_argument("observer input log: joints = " + std::to_string(joints) + ": expected 1 … " +
                                std::to_string(drivers::kMaxJoints));
  if (capacity == 0) throw std::invalid_argument("observer input log: capacity 0: expected at least one cycle");
  cycles_.resize(capacity);
  joints_data_.resize(capacity * static_cast<std::size_t>(joints));
}

std::size_t InputLog::size() const noexcept {
  return static_cast<std::size_t>(std::min<std::uint64_t>(recorded_, cycles_.size()));
}

std::size_t InputLog::slot(std::size_t i) const noexcept {
  const std::uint64_t first = recorded_ > cycles_.size() ? recorded_ - cycles_.size() : 0;
  return static_cast<std::size_t>((first + i) % cycles_.size());
}

void InputLog::record(const drivers::Feedback& fb, const drivers::CommandHistory& cmds, double t, double dt,
                      const runtime::Verdict& v, const runtime::CycleSample& sample) noexcept {
  const std::size_t s = static_cast<std::size_t>(recorded_ % cycles_.size());
  const drivers::Command& c = cmds.last();
  cycles_[s] = Cycle{.cycle = recorded_, .t = t, .dt = dt, .fb_seq = fb.seq, .stamp_ns = fb.stamp_ns,
                     .timing = fb.timing, .cmd_seq = c.seq, .torque_off = c.torque_off, .fault = v.fault,
                     .flags = v.flags, .fault_joint = v.joint};
  Joint* out = &joints_data_[s * static_cast<std::size_t>(joints_)];
  for (int j = 0; j < joints_; ++j) {
    const auto k = static_cast<std::size_t>(j);
    out[k] = Joint{.fb = fb.joint(k), .sample_ns = fb.sample_ns[k], .applied_seq = fb.applied_seq[k],
                   .applied_ns = fb.applied_ns[k], .late_applied_seq = fb.late_applied_seq[k],
                   .late_applied_ns = fb.late_applied_ns[k], .tau = c.tau[k], .beta_ref = c.beta_ref[k],
                   .beta_dot_ref = c.beta_dot_ref[k], .kp = c.kp[k], .kd = c.kd[k],
                   .residual = sample.residual[k]};
  }
  ++recorded_;
}

void InputLog::feedback(std::size_t i, drivers::Feedback& fb) const noexcept {
  const Cycle& c = cycle(i);
  fb = drivers::Feedback{};
  fb.joints = joints_;
  fb.seq = c.fb_seq;
  fb.stamp_ns = c.stamp_ns;
  fb.timing = c.timing;
  for (int j = 0; j < joints_; ++j) {
    const auto k = static_cast<std::size_t>(j);
    const Joint& x = joint(i, j);
    fb.set_joint(k, x.fb);
    fb.sample_ns[k] = x.sample_ns;
    fb.applied_seq[k] = x.applied_seq;
    fb.applied_ns[k] = x.applied_ns;
    fb.late_applied_seq[k] = x.late_applied_seq;
    fb.late_applied_ns[k] = x.late_applied_ns;
  }
}

void InputLog::command(std::size_t i, drivers::Command& cmd) const noexcept {
  const Cycle& c = cycle(i);
  cmd = drivers::Command{};
  cmd.joints = joints_;
  cmd.seq = c.cmd_seq;
  cmd.torque_off = c.torque_off;
  for (int j = 0; j < joints_; ++j) {
    const auto k = static_cast<std::size_t>(j);
    const Joint& x = joint(i, j);
    cmd.tau[k] = x.tau, cmd.beta_ref[k] = x.beta_ref, cmd.beta_dot_ref[k] = x.beta_dot_ref;
    cmd.kp[k] = x.kp, cmd.kd[k] = x.kd;
  }
}

void InputLog::write_csv(const std::filesystem::path& path, const drivers::FeedbackSpec& spec) const {
  std::vector<std::string> header(std::begin(kCycleColumns), std::end(kCycleColumns));
  for (int j = 0; j < joints_; ++j)
    for (const char* q : kJointColumns) header.push_back(joint_column(q, j));
  csv::Writer w = csv::Writer::header_later(path, {});
  std::ostringstream spec_line;
  spec_line.precision(17);
  spec_line << "feedback_spec beta_lsb=" << spec.beta_lsb << " beta_dot_lsb=" << spec.beta_dot_lsb
            << " deflection_lsb=" << spec.deflection_lsb << " torque_lsb=" << spec.torque_lsb
            << " sample_time_uncertainty=" << spec.sample_time_uncertainty << " stale_limit=" << spec.stale_limit;
  w.comment("pedalwave observer inputs (runtime/observer/include/pedalwave/observer/input_log.hpp): " +
            std::to_string(joints_) + " joints, " + std::to_string(size()) + " of " + std::to_string(recorded_) +
            " cycles kept (the last ones)");
  w.comment(spec_line.str());
  w.header(std::move(header));
  const auto seq = [](std::uint64_t s) { return static_cast<std::int64_t>(s); };  // ~0 → −1
  for (std::size_t i = 0; i < size(); ++i) {
    const Cycle& c = cycle(i);
    w.integer(c.cycle).number(c.t).number(c.dt).integer(seq(c.fb_seq)).integer(c.stamp_ns)
        .integer(static_cast<int>(c.timing)).integer(seq(c.cmd_seq)).integer(c.torque_off ? 1 : 0)
        .integer(static_cast<int>(c.fault)).integer(c.flags).integer(c.fault_joint);
    for (int j = 0; j < joints_; ++j) {
      const Joint& x = joint(i, j);
      w.number(x.fb.beta).number(x.fb.beta_dot).number(x.fb.deflection).integer(x.fb.status)
          .integer(x.sample_ns).integer(seq(x.applied_seq)).integer(x.applied_ns)
          .integer(seq(x.late_applied_seq)).integer(x.late_applied_ns).number(x.tau).number(x.beta_ref)
          .number(x.beta_dot_ref).number(x.kp).number(x.kd).number(x.residual);
    }
    w.end_row();
  }
  w.close();
}

InputLog InputLog::read_csv(const std::filesystem::path& path, drivers::FeedbackSpec* spec) {
  const std::string where = path.string();
  // The joints from the header line (deflection_1 … deflection_J), then the file with its integer
  // columns named.
  int joints = 0;
  {
    std::ifstream in(path);
    if (!in) throw csv::Error(where + ": cannot open the observer input log");
    std::string line;
    while (std::getline(in, line) && !line.empty() && line[0] == '#') {
    }
    std::size_t pos = 0;
    while ((pos = line.find("deflection_", pos)) != std::string::npos) ++joints, ++pos;
  }
  if (joints < 1 || joints > drivers::kMaxJoints)
    throw std::invalid_argument(where + ": " + std::to_string(joints) +
                                " joints (deflection_<j> columns): expected an observer input log (input_log.hpp) "
                                "with 1 … " + std::to_string(drivers::kMaxJoints));
  csv::Table::ReadOptions opt;
  for (std::size_t c = 0; c < std::size(kCycleColumns); ++c)
    if (kCycleInteger[c]) opt.integer_columns.emplace_back(kCycleColumns[c]);
  for (int j = 0; j < joints; ++j)
    for (std::size_t q = 0; q < std::size(kJointColumns); ++q)
      if (kJointInteger[q]) opt.integer_columns.push_back(joint_column(kJointColumns[q], j));
  const csv::Table t = csv::Table::read(path, opt);
  const std::size_t n = t.rows();
  if (n == 0) throw std::invalid_argument(where + ": no cycles: expected at least one row");
  InputLog log(joints, n);
  const auto& cycle = t.integers("cycle");
  const auto& tt = t.column("t");
  const auto& dt = t.column("dt");
  const auto& fb_seq = t.integers("fb_seq");
  const auto& stamp = t.integers("stamp_ns");
  const auto& timing = t.integers("timing");
  const auto& cmd_seq = t.integers("cmd_seq");
  const auto& off = t.integers("torque_off");
  const auto& fault = t.integers("fault");
  const auto& flags = t.integers("flags");
  const auto& fj = t.integers("fault_joint");
  for (std::size_t i = 0; i < n; ++i) {
    if (timing[i] < 0 || timing[i] > 1 || fault[i] < 0 ||
        fault[i] >= static_cast<std::int64_t>(runtime::FaultClass::kCount))
      throw std::invalid_argument(where + ": row " + std::to_string(i + 1) + ": timing " + std::to_string(timing[i]) +
                                  " / fault " + std::to_string(fault[i]) + ": expected 0 … 1 / 0 … " +
                                  std::to_string(static_cast<int>(runtime::FaultClass::kCount) - 1));
    log.cycles_[i] = Cycle{.cycle = static_cast<std::uint64_t>(cycle[i]), .t = tt[i], .dt = dt[i],
                           .fb_seq = static_cast<std::uint64_t>(fb_seq[i]), .stamp_ns = stamp[i],
                           .timing = static_cast<drivers::FeedbackTiming>(timing[i]),
                           .cmd_seq = static_cast<std::uint64_t>(cmd_seq[i]), .torque_off = off[i] != 0,
                           .fault = static_cast<runtime::FaultClass>(fault[i]),
                           .flags = static_cast<std::uint32_t>(flags[i]),
                           .fault_joint = static_cast<std::int16_t>(fj[i])};
  }
  for (int j = 0; j < joints; ++j) {
    const auto d = [&](const char* q) -> const std::vector<double>& { return t.column(joint_column(q, j)); };
    const auto z = [&](const char* q) -> const std::vector<std::int64_t>& { return t.integers(joint_column(q, j)); };
    const auto &beta = d("beta"), &beta_dot = d("beta_dot"), &defl = d("deflection"), &tau = d("tau"),
               &beta_ref = d("beta_ref"), &beta_dot_ref = d("beta_dot_ref"), &kp = d("kp"), &kd = d("kd"),
               &res = d("residual");
    const auto &status = z("status"), &sample = z("sample_ns"), &applied_seq = z("applied_seq"),
               &applied_ns = z("applied_ns"), &late_seq = z("late_applied_seq"), &late_ns = z("late_applied_ns");
    for (std::size_t i = 0; i < n; ++i)
      log.joints_data_[i * static_cast<std::size_t>(joints) + static_cast<std::size_t>(j)] = Joint{
          .fb = {beta[i], beta_dot[i], defl[i], static_cast<std::uint16_t>(status[i])},
          .sample_ns = sample[i], .applied_seq = static_cast<std::uint64_t>(applied_seq[i]),
          .applied_ns = applied_ns[i], .late_applied_seq = static_cast<std::uint64_t>(late_seq[i]),
          .late_applied_ns = late_ns[i], .tau = tau[i], .beta_ref = beta_ref[i], .beta_dot_ref = beta_dot_ref[i],
          .kp = kp[i], .kd = kd[i], .residual = res[i]};
  }
  log.recorded_ = n;
  if (spec) {
    *spec = drivers::FeedbackSpec{};
    bool found = false;
    for (const std::string& c : t.comments()) {
      if (c.rfind("feedback_spec ", 0) != 0) continue;
      std::istringstream in(c.substr(14));
      std::string kv;
      while (in >> kv) {
        const std::size_t eq = kv.find('=');
        if (eq == std::string::npos) continue;
        const std::string key = kv.substr(0, eq), value = kv.substr(eq + 1);
        try {
          if (key == "beta_lsb") spec->beta_lsb = std::stod(value);
          else if (key == "beta_dot_lsb") spec->beta_dot_lsb = std::stod(value);
          else if (key == "deflection_lsb") spec->deflection_lsb = std::stod(value);
          else if (key == "torque_lsb") spec->torque_lsb = std::stod(value);
          else if (key == "sample_time_uncertainty") spec->sample_time_uncertainty = std::stod(value);
          else if (key == "stale_limit") spec->stale_limit = std::stoi(value);
        } catch (const std::exception&) {
          throw std::invalid_argument(where + ": feedback_spec " + key + " = \"" + value + "\": expected a number");
        }
      }
      found = true;
    }
    if (!found)
      throw std::invalid_argument(where + ": no \"# feedback_spec …\" comment line: expected an observer input log "
                                  "written by InputLog::write_csv");
  }
  return log;
}

ReplayResult replay(const InputLog& log, runtime::Observer& observer) {
  ReplayResult r;
  r.cycles = log.size();
  const auto J = static_cast<std::size_t>(log.joints());
  r.residual.assign(r.cycles * J, 0.0);
  std::array<drivers::Command, kHistory> ring{};
  drivers::Feedback fb;
  drivers::Command cmd;
  runtime::CycleSample sample;
  observer.reset();
  for (std::size_t i = 0; i < r.cycles; ++i) {
    log.feedback(i, fb);
    log.command(i, cmd);
    ring[static_cast<std::size_t>(cmd.seq % kHistory)] = cmd;
    const drivers::CommandHistory cmds(ring.data(), kHistory, cmd.seq);
    const InputLog::Cycle& c = log.cycle(i);
    const runtime::Verdict v = observer.observe(fb, cmds, c.t, c.dt, sample);
    for (std::size_t j = 0; j < J; ++j) {
      r.residual[i * J + j] = sample.residual[j];
      r.max_residual_difference =
          std::max(r.max_residual_difference, std::abs(sample.residual[j] - log.joint(i, static_cast<int>(j)).residual));
    }
    if (v.fault != c.fault || v.flags != c.flags) ++r.verdicts_differing;
    if (c.fault != runtime::FaultClass::kNone && r.live_fault_at == SIZE_MAX) {
      r.live_fault_at = i;
      r.live_fault = c.fault;
      r.live_joint = c.fault_joint;
    }
    if (v.fault != runtime::FaultClass::kNone && r.replay_fault_at == SIZE_MAX) {
      r.replay_fault_at = i;
      r.replay_fault = v.fault;
      r.replay_joint = v.joint;
      r.replay_value = v.value;
      r.replay_threshold = v.threshold;
    }
  }
  return r;
}

}  // namespace pedalwave::observer
