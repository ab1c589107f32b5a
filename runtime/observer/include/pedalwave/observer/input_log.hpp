// The observer's flight recorder. Observer::observe() is a function of its inputs alone (the
// cycle's feedback, the commands written, t and dt): the log keeps those inputs of the last
// `capacity` cycles — with what the live observer concluded (each joint's residual, the verdict)
// — in memory allocated up front, and writes them as CSV after the run. replay() runs a fresh
// observer over a log, cycle by cycle, and says where it differs from the live one; a log that
// holds a run from its first cycle replays it bit for bit. What it is for: a false alarm (or a
// missed fault) on the robot is examined, and a changed observer tried, on the data of that run.
//
// RecordingObserver puts the log in front of any observer: on the real-time thread it copies the
// inputs into the ring (no allocation, no lock, no I/O); the ring is read only after the loop has
// stopped.
//
// File (InputLog::write_csv, pedalwave::csv): comment lines (the driver's FeedbackSpec, the
// joints, how many cycles were recorded and kept), then one row per cycle:
//   cycle, t, dt, fb_seq, stamp_ns, timing, cmd_seq, torque_off, fault, flags, fault_joint,
//   then per joint j = 1 … N-1: beta_j, beta_dot_j, deflection_j, status_j, sample_ns_j,
//   applied_seq_j, applied_ns_j, late_applied_seq_j, late_applied_ns_j (the feedback), tau_j,
//   beta_ref_j, beta_dot_ref_j, kp_j, kd_j (the newest command written), residual_j (live).
// Sequence numbers are written as signed 64-bit integers (kNoCommandSeq = −1, kUnknownSeq = −2);
// numbers are shortest round-trip text, so a read log is the written one exactly.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "pedalwave/interface/stages.hpp"

namespace pedalwave::observer {

class InputLog {
 public:
  // One cycle's scalar inputs and the live verdict.
  struct Cycle {
    std::uint64_t cycle = 0;  // the how-many-th observe() call of the run (0 = first) [-]
    double t = 0.0, dt = 0.0;  // observe()'s t and dt [s]
    std::uint64_t fb_seq = 0;
    std::int64_t stamp_ns = 0;
    drivers::FeedbackTiming timing = drivers::FeedbackTiming::kNominal;
    std::uint64_t cmd_seq = 0;  // the newest command's Command::seq
    bool torque_off = false;
    runtime::FaultClass fault = runtime::FaultClass::kNone;  // live verdict
    std::uint32_t flags = 0;
    std::int16_t fault_joint = -1;
  };
  // One joint's feedback, its share of the newest command, and its live residual.
  struct Joint {
    drivers::JointSample fb{};
    std::int64_t sample_ns = 0;
    std::uint64_t applied_seq = 0;
    std::int64_t applied_ns = 0;
    std::uint64_t late_applied_seq = 0;
    std::int64_t late_applied_ns = 0;
    double tau = 0, beta_ref = 0, beta_dot_ref = 0, kp = 0, kd = 0;
    double residual = 0;
  };

  // Allocates everything: `capacity` cycles of `joints` joints. Throws std::invalid_argument for
  // joints outside 1 … kMaxJoints or capacity 0.
  InputLog(int joints, std::size_t capacity);

  // Real-time: copies one cycle (overwriting the oldest when full). Never allocates or throws.
  void record(const drivers::Feedback& fb, const drivers::CommandHistory& cmds, double t, double dt,
              const runtime::Verdict& v, const runtime::CycleSample& sample) noexcept;

  int joints() const noexcept { return joints_; }
  std::size_t capacity() const noexcept { return cycles_.size(); }
  std::uint64_t recorded() const noexcept { return recorded_; }  // cycles seen
  std::size_t size() const noexcept;                               // cycles kept
  // The i-th kept cycle, oldest first (i < size()).
  const Cycle& cycle(std::size_t i) const noexcept { return cycles_[slot(i)]; }
  const Joint& joint(std::size_t i, int j) const noexcept {
    return joints_data_[slot(i) * static_cast<std::size_t>(joints_) + static_cast<std::size_t>(j)];
  }
  // The i-th kept cycle's inputs as observe() got them (the newest command only).
  void feedback(std::size_t i, drivers::Feedback& fb) const noexcept;
  void command(std::size_t i, drivers::Command& cmd) const noexcept;

  // Writes the kept cycles (csv::Error naming the file on failure); `spec` is the driver's, which
  // the observer's thresholds were derived from.
  void write_csv(const std::filesystem::path& path, const drivers::FeedbackSpec& spec) const;
  // Reads a written log (csv::Error / std::invalid_argument naming the file and what is wrong);
  // the FeedbackSpec of its comment lines into *spec when given.
  static InputLog read_csv(const std::filesystem::path& path, drivers::FeedbackSpec* spec = nullptr);

 private:
  std::size_t slot(std::size_t i) const noexcept;
  int joints_;
  std::uint64_t recorded_ = 0;
  std::vector<Cycle> cycles_;
  std::vector<Joint> joints_data_;
};

// An observer that records its inputs into a log and then asks the wrapped observer.
class RecordingObserver final : public runtime::Observer {
 public:
  RecordingObserver(runtime::Observer& inner, InputLog& log) noexcept : inner_(inner), log_(log) {}
  void reset() override { inner_.reset(); }
  runtime::Verdict observe(const drivers::Feedback& fb, const drivers::CommandHistory& cmds, double t,
                           double dt, runtime::CycleSample& sample) override {
    const runtime::Verdict v = inner_.observe(fb, cmds, t, dt, sample);
    log_.record(fb, cmds, t, dt, v, sample);
    return v;
  }

 private:
  runtime::Observer& inner_;
  InputLog& log_;
};

// What a replay found.
struct ReplayResult {
  std::size_t cycles = 0;
  // The first kept cycle whose live / replayed verdict is a fault (SIZE_MAX: none), its class
  // and joint (0-based).
  std::size_t live_fault_at = SIZE_MAX, replay_fault_at = SIZE_MAX;
  runtime::FaultClass live_fault = runtime::FaultClass::kNone, replay_fault = runtime::FaultClass::kNone;
  int live_joint = -1, replay_joint = -1;
  double replay_value = 0.0, replay_threshold = 0.0;
  // Largest |replayed − live residual| over every cycle and joint [N·m], and the cycles whose
  // verdict (class and flags) differs.
  double max_residual_difference = 0.0;
  std::size_t verdicts_differing = 0;
  std::vector<double> residual;  // replayed residuals, cycles × joints
};

// Runs `observer` (reset first) over the log's cycles. The command history it gets is rebuilt
// from the logged newest commands (Runtime::kCommandHistory = 16 deep): commands written before
// the log's first cycle are not in it, so a log that does not start at the run's first cycle
// starts the observer fresh mid-run (its first seconds are not the live ones).
ReplayResult replay(const InputLog& log, runtime::Observer& observer);

}  // namespace pedalwave::observer
