// Where the shipped YAML files (runtime/, scenes/) are for a program that was built here or
// installed: the source tree's config/ (PEDALWAVE_CONFIG_DIR) while it exists — a build tree —
// else the installed examples, <prefix>/share/pedalwave/examples (runtime/deploy/CMakeLists.txt
// installs them there). Tools use it for their defaults; tests keep PEDALWAVE_CONFIG_DIR.
#pragma once

#include <string>

namespace pedalwave::config {

// `source` when it is a folder, else `installed`.
std::string pick_shipped_dir(const std::string& source, const std::string& installed);

// pick_shipped_dir(PEDALWAVE_CONFIG_DIR, the installed examples folder).
std::string shipped_dir();

}  // namespace pedalwave::config
