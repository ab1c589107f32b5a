#include "pedalwave/toolkit/progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "pedalwave/toolkit/format.hpp"

namespace pedalwave::toolkit {

std::string format_duration(double seconds) {
  if (!std::isfinite(seconds)) return "--";
  if (seconds < 0.0) seconds = 0.0;
  if (seconds < 1.0) return fixed(seconds * 1e3, 0) + " ms";
  if (seconds < 60.0) return fixed(seconds, 1) + " s";
  char buf[64];
  if (seconds < 3600.0) {
    const auto total = static_cast<long>(std::lround(seconds));
    std::snprintf(buf, sizeof buf, "%ld min %02ld s", total / 60, total % 60);
  } else {
    const auto total_min = static_cast<long>(std::lround(seconds / 60.0));
    std::snprintf(buf, sizeof buf, "%ld h %02ld min", total_min / 60, total_min % 60);
  }
  return buf;
}

namespace {
std::string rate_text(double per_s) {
  if (!(per_s > 0.0) || !std::isfinite(per_s)) return "-/s";
  if (per_s >= 100.0) return fixed(per_s, 0) + "/s";
  if (per_s >= 1.0) return fixed(per_s, 1) + "/s";
  return sig(per_s, 3) + "/s";
}
}  // namespace

Progress::Progress(std::string label, std::uint64_t total) : Progress(std::move(label), total, Options{}) {}

Progress::Progress(std::string label, std::uint64_t total, Options options)
    : label_(std::move(label)),
      total_(total),
      opt_(options),
      style_(options.style),
      out_(options.out ? options.out : &std::cerr),
      start_(std::chrono::steady_clock::now()) {
  if (style_ == Style::automatic) {
    style_ = (out_ == &std::cerr && ::isatty(STDERR_FILENO) == 1) ? Style::tty : Style::lines;
  }
  opt_.bar_width = std::clamp(opt_.bar_width, 5, 200);
}

Progress::~Progress() {
  try {
    finish();
  } catch (...) {  // NOLINT(bugprone-empty-catch): a failing stream must not end the program
  }
}

double Progress::elapsed_s() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::advance(std::uint64_t n) {
  const std::uint64_t done = done_.fetch_add(n, std::memory_order_relaxed) + n;
  if (finished_.load(std::memory_order_relaxed)) return;
  switch (style_) {
    case Style::silent:
    case Style::automatic:
      return;
    case Style::lines: {
      if (total_ == 0) return;
      // Each 10 % step is printed once overall, in order: claim it under the print lock (taken
      // only when a step was crossed, i.e. at most 10 times per run).
      const int reached = static_cast<int>(std::min<std::uint64_t>(10, done * 10 / total_));
      if (reached < next_decile_.load(std::memory_order_relaxed)) return;
      std::lock_guard lock(print_mutex_);
      if (reached < next_decile_.load(std::memory_order_relaxed) || finished_.load(std::memory_order_relaxed)) return;
      next_decile_.store(reached + 1, std::memory_order_relaxed);
      print_line(done, reached * 10);
      return;
    }
    case Style::tty: {
      const auto now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                              std::chrono::steady_clock::now() - start_).count();
      std::int64_t due = next_redraw_ns_.load(std::memory_order_relaxed);
      if (now_ns < due) return;
      const auto interval = static_cast<std::int64_t>(opt_.redraw_interval_s * 1e9);
      if (!next_redraw_ns_.compare_exchange_strong(due, now_ns + interval, std::memory_order_relaxed)) return;
      std::unique_lock lock(print_mutex_, std::try_to_lock);
      if (!lock.owns_lock() || finished_.load(std::memory_order_relaxed)) return;
      print_tty(false);
      return;
    }
  }
}

void Progress::print_line(std::uint64_t done, int percent) {
  const double t = elapsed_s();
  const double rate = t > 0.0 ? static_cast<double>(done) / t : 0.0;
  std::string line = label_ + ": " + std::to_string(percent) + "% (" + std::to_string(std::min(done, total_)) + "/" +
                     std::to_string(total_) + ", " + rate_text(rate);
  if (done < total_ && rate > 0.0) line += ", ETA " + format_duration(static_cast<double>(total_ - done) / rate);
  line += ")\n";
  *out_ << line << std::flush;
}

void Progress::print_tty(bool final_line) {
  const std::uint64_t done = done_.load(std::memory_order_relaxed);
  const double t = elapsed_s();
  const double rate = t > 0.0 ? static_cast<double>(done) / t : 0.0;
  std::string line(1, '\r');
  line.append(label_);
  line.push_back(' ');
  if (total_ > 0) {
    const double f = std::min(1.0, static_cast<double>(done) / static_cast<double>(total_));
    const int filled = static_cast<int>(f * opt_.bar_width);
    line += "[" + std::string(static_cast<std::size_t>(filled), '#') +
            std::string(static_cast<std::size_t>(opt_.bar_width - filled), '.') + "] ";
    char pct[16];
    std::snprintf(pct, sizeof pct, "%3.0f%% ", f * 100.0);
    line += pct;
    line += std::to_string(done) + "/" + std::to_string(total_) + "  " + rate_text(rate);
    if (!final_line && done < total_ && rate > 0.0) {
      line += "  ETA " + format_duration(static_cast<double>(total_ - done) / rate);
    }
  } else {
    line += std::to_string(done) + " done  " + rate_text(rate);
  }
  // pad over a longer previous line instead of relying on terminal escape codes
  const std::size_t width = line.size();
  if (width < last_width_) line += std::string(last_width_ - width, ' ');
  last_width_ = width;
  *out_ << line << std::flush;
}

void Progress::finish() {
  std::lock_guard lock(print_mutex_);
  if (finished_.exchange(true)) return;
  if (style_ == Style::silent || style_ == Style::automatic) return;
  const std::uint64_t done = done_.load(std::memory_order_relaxed);
  const double t = elapsed_s();
  const double rate = t > 0.0 ? static_cast<double>(done) / t : 0.0;
  if (style_ == Style::tty) {
    print_tty(true);
    *out_ << '\n';
  }
  std::string line = label_ + ": " + std::to_string(done);
  if (total_ > 0) line += "/" + std::to_string(total_);
  line.append(" done in ").append(format_duration(t)).append(" (").append(rate_text(rate)).append(")\n");
  *out_ << line << std::flush;
}

}  // namespace pedalwave::toolkit
