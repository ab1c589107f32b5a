// The body points of a run as CSV (the snake's shapes over time), one row per sample: the
// caller's leading columns (t, COM, head tip, …), then x_0 … x_{P-1} and z_0 … z_{P-1}, the body
// points in the model's order (the 2N+1 points, tail tip first) [m]. Written by pedalwave_sim
// (body.csv), pedalwave_paper (the traces), pedalwave_plot_recording and the daemon's --plots
// (body.csv); drawn by tools/figures (pwfig.Body). Numbers as CsvWriter writes them.
#pragma once

#include <cstddef>
#include <filesystem>
#include <initializer_list>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "pedalwave/toolkit/csv.hpp"

namespace pedalwave::toolkit {

class BodyPointsCsv {
 public:
  // Creates `path` (and its folder) with the header `leading` + x_0 … x_{points-1} + z_0 …;
  // points may be 0 (a trace without shapes). Throws CsvError as CsvWriter does.
  BodyPointsCsv(const std::filesystem::path& path, std::vector<std::string> leading, std::size_t points);

  void comment(std::string_view text) { csv_.comment(text); }
  // One sample: as many leading values as leading columns, then the points' x and z (`points`
  // each). Throws CsvError naming the file and the counts when a count differs.
  void row(std::span<const double> leading, std::span<const double> x, std::span<const double> z);
  void row(std::initializer_list<double> leading, std::span<const double> x, std::span<const double> z) {
    row(std::span<const double>(leading.begin(), leading.size()), x, z);
  }
  void close() { csv_.close(); }

  [[nodiscard]] std::size_t points() const { return points_; }
  [[nodiscard]] std::size_t rows_written() const { return csv_.rows_written(); }

 private:
  CsvWriter csv_;
  std::size_t leading_, points_;
  std::vector<double> row_;  // reused
};

}  // namespace pedalwave::toolkit
