#include "pedalwave/config/shipped.hpp"

#include <filesystem>
#include <system_error>

namespace pedalwave::config {

std::string pick_shipped_dir(const std::string& source, const std::string& installed) {
  std::error_code ec;
  return std::filesystem::is_directory(source, ec) ? source : installed;
}

std::string shipped_dir() { return pick_shipped_dir(PEDALWAVE_CONFIG_DIR, PEDALWAVE_INSTALLED_CONFIG_DIR); }

}  // namespace pedalwave::config
