#include "pedalwave/toolkit/body_csv.hpp"

#include <algorithm>

namespace pedalwave::toolkit {

namespace {
std::vector<std::string> header_of(std::vector<std::string> leading, std::size_t points) {
  for (const char* axis : {"x_", "z_"})
    for (std::size_t k = 0; k < points; ++k) leading.push_back(axis + std::to_string(k));
  return leading;
}
}  // namespace

BodyPointsCsv::BodyPointsCsv(const std::filesystem::path& path, std::vector<std::string> leading,
                             std::size_t points)
    : csv_(path, header_of(leading, points)), leading_(leading.size()), points_(points),
      row_(leading_ + 2 * points) {}

void BodyPointsCsv::row(std::span<const double> leading, std::span<const double> x, std::span<const double> z) {
  if (leading.size() != leading_ || x.size() != points_ || z.size() != points_) {
    throw CsvError("CSV '" + csv_.path().string() + "': body points row " + std::to_string(csv_.rows_written() + 1) +
                   " has " + std::to_string(leading.size()) + " leading values and " + std::to_string(x.size()) +
                   " x / " + std::to_string(z.size()) + " z points, expected " + std::to_string(leading_) + " and " +
                   std::to_string(points_));
  }
  std::copy(leading.begin(), leading.end(), row_.begin());
  std::copy(x.begin(), x.end(), row_.begin() + static_cast<std::ptrdiff_t>(leading_));
  std::copy(z.begin(), z.end(), row_.begin() + static_cast<std::ptrdiff_t>(leading_ + points_));
  csv_.row(row_);
}

}  // namespace pedalwave::toolkit
