#include "cyclictest.hpp"

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

extern char** environ;

namespace pedalwave::rtbench {

std::int64_t CyclictestHistogram::percentile_us(double q) const {
  if (total == 0) return -1;
  auto rank = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(total)));
  rank = std::clamp<std::uint64_t>(rank, 1, total);
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < bins.size(); ++i) {
    seen += bins[i];
    if (seen >= rank) return static_cast<std::int64_t>(i);
  }
  return max_us;
}

CyclictestHistogram parse_cyclictest(const std::string& text) {
  CyclictestHistogram h;
  std::istringstream in(text);
  std::string line;
  bool in_hist = false;
  auto field = [](const std::string& l) -> std::int64_t {
    const auto c = l.find(':');
    if (c == std::string::npos) return -1;
    std::istringstream v(l.substr(c + 1));
    std::int64_t x = -1;
    v >> x;
    return x;
  };
  while (std::getline(in, line)) {
    if (line.rfind("# Histogram", 0) == 0 && line.find("Overflow") == std::string::npos) {
      in_hist = true;
      continue;
    }
    if (line.rfind("# Min Latencies", 0) == 0) h.min_us = field(line);
    else if (line.rfind("# Avg Latencies", 0) == 0) h.avg_us = field(line);
    else if (line.rfind("# Max Latencies", 0) == 0) h.max_us = field(line);
    else if (line.rfind("# Histogram Overflows", 0) == 0) h.overflows = static_cast<std::uint64_t>(std::max<std::int64_t>(0, field(line)));
    else if (in_hist && !line.empty() && line[0] != '#') {
      std::istringstream v(line);
      std::uint64_t bin = 0, count = 0;
      if (v >> bin >> count) {
        if (bin >= h.bins.size()) h.bins.resize(bin + 1, 0);
        h.bins[bin] = count;
      }
    }
  }
  std::uint64_t in_bins = 0;
  for (auto c : h.bins) in_bins += c;
  h.total = in_bins + h.overflows;
  h.ok = !h.bins.empty() && h.max_us >= 0 && h.total > 0;
  if (!h.ok) h.error = "no histogram / summary lines in cyclictest output";
  return h;
}

CyclictestRun start_cyclictest(const std::string& exe, int priority, int interval_us, int seconds,
                               int hist_us, int cpu, bool mlock) {
  CyclictestRun run;
  char out_tmpl[] = "/tmp/rtbench-cyclictest-XXXXXX";
  char err_tmpl[] = "/tmp/rtbench-cyclictest-err-XXXXXX";
  const int out_fd = mkstemp(out_tmpl);
  const int err_fd = mkstemp(err_tmpl);
  if (out_fd < 0 || err_fd < 0) {
    run.start_error = std::string("mkstemp: ") + std::strerror(errno);
    return run;
  }
  run.out_path = out_tmpl;
  run.err_path = err_tmpl;

  std::vector<std::string> args = {exe,
                                   "-q",
                                   "-t", "1",
                                   "-p", std::to_string(priority),
                                   "-i", std::to_string(interval_us),
                                   "-h", std::to_string(hist_us),
                                   "-D", std::to_string(seconds)};
  // cyclictest -p 0 alone still runs its measurement thread at SCHED_FIFO 2: ask for
  // SCHED_OTHER explicitly so that both sides run under the same policy.
  args.push_back(priority > 0 ? "--policy=fifo" : "--policy=other");
  if (cpu >= 0) args.push_back("-a" + std::to_string(cpu));
  if (mlock) args.push_back("-m");
  for (const auto& a : args) run.command += (run.command.empty() ? "" : " ") + a;

  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, out_fd, STDOUT_FILENO);
  posix_spawn_file_actions_adddup2(&fa, err_fd, STDERR_FILENO);
  const int rc = posix_spawnp(&run.pid, exe.c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  close(out_fd);
  close(err_fd);
  if (rc != 0) {
    run.pid = -1;
    run.start_error = "cannot start '" + exe + "': " + std::strerror(rc) +
                      " (install rt-tests: apt-get install rt-tests)";
  }
  return run;
}

CyclictestHistogram finish_cyclictest(CyclictestRun& run) {
  CyclictestHistogram h;
  if (run.pid < 0) {
    h.error = run.start_error;
    return h;
  }
  int status = 0;
  while (waitpid(run.pid, &status, 0) < 0 && errno == EINTR) {
  }
  run.pid = -1;
  auto slurp = [](const std::string& p) {
    std::ifstream f(p);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  };
  const std::string out = slurp(run.out_path), err = slurp(run.err_path);
  std::remove(run.out_path.c_str());
  std::remove(run.err_path.c_str());
  h = parse_cyclictest(out);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    h.ok = false;
    h.error = "cyclictest exited with status " + std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) +
              (err.empty() ? std::string() : ": " + err);
  } else if (!h.ok && !err.empty()) {
    h.error += ": " + err;
  }
  return h;
}

}  // namespace pedalwave::rtbench
