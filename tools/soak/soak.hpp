// The soak tool's pieces that do not start processes (tested in tests/tools/soak/): memory samples from
// /proc/<pid>/status, the runtime configuration written for a soak run, the reading of the
// runtime's report.json, the verdict and the printed summary.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "pedalwave/toolkit/json.hpp"

namespace pedalwave::soak {

using toolkit::Json;

// Exit codes of pedalwave_soak: those of every tool (toolkit/cli.hpp), the run's end mapped as
// pedalwave_runtime maps it (cli::exit_for_run_end).
inline constexpr int kExitPass = 0;           // the run reached its duration with no fault event
inline constexpr int kExitFail = 1;           // no verdict on a whole run: interrupted, no report,
                                              // the runtime crashed or stopped early by a signal
inline constexpr int kExitUsage = 2;          // bad option, file or configuration
inline constexpr int kExitFault = 4;          // a fault ended the run, or fault events in it
inline constexpr int kExitEmergencyStop = 5;  // an operator emergency stop ended the run

// Thrown for usage/configuration problems (exit 2); what() names the option or file, the value
// and what was expected.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One reading of /proc/<pid>/status.
struct MemorySample {
  double t_s = 0.0;        // time since the runtime started [s]
  long rss_kB = 0;         // VmRSS: resident set [kB]
  long hwm_kB = 0;         // VmHWM: peak resident set [kB]
  long size_kB = 0;        // VmSize: virtual size [kB]
  int threads = 0;         // Threads
};

// Parses the text of a /proc/<pid>/status file; nullopt when VmRSS is absent (a zombie or a
// kernel thread).
[[nodiscard]] std::optional<MemorySample> parse_proc_status(const std::string& text);
// Reads /proc/<pid>/status; nullopt when the process is gone.
[[nodiscard]] std::optional<MemorySample> read_proc_status(pid_t pid, double t_s);

// The runtime configuration of a soak run, from a template (config/runtime/serial.yaml or the
// user's): driver.device = `device`, rate_hz overridden when rate_hz > 0, telemetry.enabled (and
// telemetry.interface = lo when on and the template names none), realtime.auto_start = true (the
// soak is the operator who starts the walk). Returns the YAML text.
// Throws UsageError naming the template and the key when the template cannot be read, is not a
// mapping or its driver is not the serial bus (driver.type: serial) that the virtual robot's pty
// serves.
[[nodiscard]] std::string soak_runtime_config(const std::filesystem::path& template_path,
                                              const std::string& device, double rate_hz,
                                              bool telemetry);

// The verdict of a run: exit code and the reasons for a failure (empty when it passed).
struct Verdict {
  int code = kExitPass;
  std::vector<std::string> reasons;
};

// `report` is the parsed report.json (null when none), `runtime_exit` the runtime's exit status
// (−1 = killed by a signal), `interrupted` whether the soak was stopped by SIGINT/SIGTERM.
// Passes when the runtime exited 0 with exit.reason "cycle_limit" (its duration), exit.fault
// none/null, and no event of kind "fault". Otherwise the code says why: the run's end as the
// runtime maps it (exit.reason "fault" → kExitFault, "emergency_stop" → kExitEmergencyStop);
// fault events in a run that went on → kExitFault; the runtime refused its configuration (exit 2)
// → kExitUsage; anything else → kExitFail.
[[nodiscard]] Verdict judge(const Json& report, int runtime_exit, bool interrupted);

// A text table of one stage's histogram (report "timing_us".<stage>): rows from the first to the
// last non-empty bin, "lo … hi [µs]", the count, and a bar of '#' on a log scale (the longest bar
// `bar_width` characters is the largest bin; one '#' is one count). More than `max_rows` bins
// are merged in equal groups. Empty string when the stage has no bins.
[[nodiscard]] std::string histogram_table(const Json& stage, int bar_width = 40, int max_rows = 30);

// The summary printed at the end, from the content of soak.json (see main.cpp: "report",
// "memory", "virtual_robot", "load", "verdict", ...).
[[nodiscard]] std::string summary(const Json& soak);

// Memory samples of one process as JSON rows {t_s, rss_kB, hwm_kB, size_kB, threads}.
[[nodiscard]] Json to_json(const std::vector<MemorySample>& samples);

}  // namespace pedalwave::soak
