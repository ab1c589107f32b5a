// libFuzzer target: the YAML readers (a scene, a daemon configuration) on arbitrary text. The
// property: every input either loads or is refused with a config::ConfigError of ONE line — no
// other exception, no crash, no sanitizer report, no hang (a bounded document: the reader refuses
// more than 64 levels of nesting).
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "pedalwave/config/daemon.hpp"
#include "pedalwave/config/scene.hpp"

namespace {
void check_one_line(const pedalwave::config::ConfigError& e) {
  if (std::string(e.what()).find('\n') == std::string::npos) return;  // one line per error
  std::fprintf(stderr, "multi-line error:\n%s\n", e.what());
  std::abort();
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 4096) return 0;  // configuration files are small; keep the runs fast
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    (void)pedalwave::config::parse_scene(text, "fuzz.yaml");
  } catch (const pedalwave::config::ConfigError& e) {
    check_one_line(e);
  }
  try {
    // Relative scene paths resolve against the shipped configurations (a sim driver may name
    // ../scenes/flat_high_friction.yaml and load it).
    (void)pedalwave::config::parse_daemon_config(text, "fuzz.yaml", PEDALWAVE_CONFIG_DIR "/runtime");
  } catch (const pedalwave::config::ConfigError& e) {
    check_one_line(e);
  }
  return 0;
}
