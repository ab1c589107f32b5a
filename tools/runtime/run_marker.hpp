// The walking marker: how a restarted daemon knows that the previous run did not end in order.
//
// <state_dir>/running exists from the moment the loop is seen RUNNING until the run ends in order
// (cycle limit, operator stop, SIGINT/SIGTERM, fault, e-stop: every RunResult with a reason). A
// marker found at start therefore means a crash, a kill or a power loss while the robot walked:
// the daemon then runs without auto_start and stays READY until an operator starts it (a DDS
// start command) — it never restarts into walking (DEPLOY.md "Service policy").
//
// Never on the loop thread: the marker is written by the telemetry consumer's thread (this is a
// TelemetrySink: it sees the RUNNING mode in the event and cycle samples) and checked and removed
// by run_daemon before and after the loop. The write is durable (write a temporary file, fsync,
// rename, fsync the folder), so a power loss while walking leaves the marker too.
#pragma once

#include <filesystem>
#include <string>

#include "pedalwave/interface/telemetry_sink.hpp"

namespace pedalwave::app {

class RunMarker final : public runtime::TelemetrySink {
 public:
  // Creates `dir` if needed and reads a marker an earlier run left there. `what` goes into the
  // marker (the configuration's path, for the next run's message). Throws std::runtime_error
  // naming the folder when it cannot be created or written.
  RunMarker(std::filesystem::path dir, std::string what);

  const std::filesystem::path& path() const noexcept { return path_; }
  // An earlier run's marker was there at construction; previous() is its content ("pid …").
  bool found() const noexcept { return found_; }
  const std::string& previous() const noexcept { return previous_; }
  // This run wrote the marker (it was seen RUNNING); write_error() says why a write failed.
  bool marked() const noexcept { return marked_; }
  const std::string& write_error() const noexcept { return write_error_; }

  // The run ended in order: remove the marker (ours or the earlier run's). Returns what failed
  // (empty = removed); a marker that stays only makes the next run start in READY (the safe side).
  std::string clear();

  void on_description(const runtime::RobotDescription&) override {}
  void on_cycle(const runtime::CycleSample& s) override {
    if (s.mode == runtime::Mode::kRunning) mark();
  }
  void on_event(const runtime::EventSample& e) override {
    if (e.to == runtime::Mode::kRunning) mark();
  }

 private:
  void mark();  // once per run; failures are kept in write_error_ (the consumer must go on)

  std::filesystem::path dir_, path_;
  std::string what_;
  bool found_ = false;
  std::string previous_;
  bool marked_ = false;
  bool tried_ = false;
  std::string write_error_;
};

}  // namespace pedalwave::app
