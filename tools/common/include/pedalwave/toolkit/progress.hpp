// A progress bar for long offline runs (sweeps, studies), safe to advance from many threads.
//
// On a terminal it redraws one line in place (bar, done/total, rate, ETA) at most every
// `redraw_interval_s`; elsewhere (CI logs, files) it prints one line each time another 10 % is
// done. finish() prints the total time and rate. Output goes to std::cerr unless told otherwise.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <iosfwd>
#include <mutex>
#include <string>

namespace pedalwave::toolkit {

// A duration for people: "350 ms", "12.3 s", "2 min 05 s", "1 h 02 min"; "--" when not finite.
[[nodiscard]] std::string format_duration(double seconds);

class Progress {
 public:
  enum class Style {
    automatic,  // tty when the stream is std::cerr and stderr is a terminal, else lines
    tty,        // redraw in place with '\r'
    lines,      // a line per 10 %
    silent,     // count only
  };
  struct Options {
    Style style = Style::automatic;
    std::ostream* out = nullptr;     // nullptr = std::cerr
    double redraw_interval_s = 0.1;  // minimum time between tty redraws [s]
    int bar_width = 30;              // bar length [characters]
  };

  // total = number of work items; 0 = unknown (no bar, percentage or ETA).
  Progress(std::string label, std::uint64_t total);
  Progress(std::string label, std::uint64_t total, Options options);
  // Calls finish() if it was not called.
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Adds n finished items (thread-safe, lock-free unless this call prints).
  void advance(std::uint64_t n = 1);
  // Items done so far.
  [[nodiscard]] std::uint64_t done() const { return done_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t total() const { return total_; }
  // Elapsed time since construction [s].
  [[nodiscard]] double elapsed_s() const;
  // Prints the final line "<label>: <done>/<total> done in <time> (<rate>/s)" once; later calls
  // do nothing. Thread-safe.
  void finish();

 private:
  void print_tty(bool final_line);                    // caller holds print_mutex_
  void print_line(std::uint64_t done, int percent);  // caller holds print_mutex_

  std::string label_;
  std::uint64_t total_;
  Options opt_;
  Style style_;
  std::ostream* out_;
  std::chrono::steady_clock::time_point start_;
  std::atomic<std::uint64_t> done_{0};
  std::atomic<int> next_decile_{1};          // next 10 % step to report in lines style
  std::atomic<std::int64_t> next_redraw_ns_{0};  // earliest next tty redraw (since start)
  std::atomic<bool> finished_{false};
  std::mutex print_mutex_;                   // one printer at a time
  std::size_t last_width_ = 0;               // characters of the last tty line
};

}  // namespace pedalwave::toolkit
