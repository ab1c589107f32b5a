// pedalwave_soak — the deployment path as a user runs it, for a long time, under CPU load:
// the virtual robot on a pty (a process), the runtime daemon on the serial bus (a process), N busy
// processes beside them; memory of both sampled from /proc while it runs; at the end the runtime's
// report.json (exit, events, loop counters, timing histograms), the virtual robot's report and
// the memory at start and end, printed and written to <out>/soak.json, <out>/memory.csv and a plot.
//
//   pedalwave_soak --duration 3600 --load 2 --out out/soak
//
// Exit codes (soak.hpp, toolkit/cli.hpp): 0 the run reached its duration with no fault event; 4 a
// fault ended the run or fault events in it; 5 an operator emergency stop ended it (the runtime's
// own mapping of how its run ended); 2 bad option, file or configuration (the message names it);
// 1 no verdict on a whole run (interrupted, no report, the runtime crashed or stopped early).
#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"
#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/utsname.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdint>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/config/shipped.hpp"
#include "pedalwave/toolkit/cpu_load.hpp"
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figures.hpp"
#include "pedalwave/toolkit/json.hpp"
#include "soak.hpp"
#include "pedalwave/interface/clock.hpp"

namespace fs = std::filesystem;
namespace sk = pedalwave::soak;
namespace tk = pedalwave::toolkit;
using sk::Json;

namespace {

// ---- signals: the first SIGINT/SIGTERM asks for an orderly stop; another one at least 1 s later
// (not the copy that `timeout` or a terminal sends to the process group at the same moment) kills
// the children and exits ----

volatile sig_atomic_t g_stop = 0;
volatile std::int64_t g_first_signal_ns = 0;
volatile pid_t g_children[2] = {-1, -1};  // the runtime and the virtual robot
tk::CpuLoad* g_load = nullptr;            // its pids are read by the handler (kill only)

extern "C" void on_signal(int) {
  const std::int64_t now = pedalwave::monotonic_ns();
  if (!g_stop) {
    g_first_signal_ns = now;
    g_stop = 1;
    return;
  }
  if (now - g_first_signal_ns < 1'000'000'000) return;
  // No more waiting. kill() and _exit() are async-signal-safe.
  for (const pid_t p : g_children)
    if (p > 0) ::kill(p, SIGKILL);
  if (g_load)
    for (const pid_t p : g_load->pids()) ::kill(p, SIGKILL);
  ::_exit(sk::kExitFail);
}

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// ---- child processes -----------------------------------------------------------------------------

// Starts `argv` with stdout and stderr into `log`, stdin from /dev/null, in its own process group
// (a terminal's Ctrl-C reaches the soak only, which then stops everything in order), and with
// SIGINT from the kernel if the soak dies (the runtime then still ends with its safe stop).
// fifo_priority > 0: under SCHED_FIFO at that priority (its threads inherit it); when that is not
// granted the child says so in its log (kFifoRefused) and runs at normal priority.
constexpr const char* kFifoRefused = "pedalwave_soak: SCHED_FIFO not granted";
pid_t spawn(const std::vector<std::string>& args, const fs::path& log, int fifo_priority = 0) {
  std::vector<std::string> a = args;
  std::vector<char*> argv;
  for (auto& s : a) argv.push_back(s.data());
  argv.push_back(nullptr);
  const std::string log_path = log.string();
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed for " + args[0]);
  if (pid == 0) {
    ::setpgid(0, 0);
    if (::prctl(PR_SET_PDEATHSIG, SIGINT) != 0 || ::getppid() != parent) ::_exit(126);
    const int out = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    const int in = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    if (out < 0 || in < 0) ::_exit(126);
    ::dup2(in, STDIN_FILENO);
    ::dup2(out, STDOUT_FILENO);
    ::dup2(out, STDERR_FILENO);
    if (fifo_priority > 0) {
      sched_param sp{};
      sp.sched_priority = fifo_priority;
      if (::sched_setscheduler(0, SCHED_FIFO, &sp) != 0) {
        const char* msg = kFifoRefused;
        (void)!::write(STDERR_FILENO, msg, std::strlen(msg));
        (void)!::write(STDERR_FILENO, "\n", 1);
      }
    }
    ::signal(SIGINT, SIG_DFL);
    ::signal(SIGTERM, SIG_DFL);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

// Exit status as a number: the exit code, or −1 when killed by a signal.
int exit_code(int status) { return WIFEXITED(status) ? WEXITSTATUS(status) : -1; }

// Waits up to timeout_s for the child; nullopt if it is still running. Stops waiting early when a
// stop was requested and `stop_early` is set.
std::optional<int> wait_for(pid_t pid, double timeout_s, bool stop_early = false) {
  const auto t0 = Clock::now();
  for (;;) {
    int status = 0;
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) return exit_code(status);
    if (r < 0 && errno != EINTR) return -1;
    if (seconds_since(t0) >= timeout_s || (stop_early && g_stop)) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

// SIGINT, then SIGKILL after `grace_s`; returns the exit status.
int stop_child(pid_t pid, double grace_s) {
  ::kill(pid, SIGINT);
  if (auto c = wait_for(pid, grace_s)) return *c;
  std::fprintf(stderr, "pedalwave_soak: pid %d did not stop %g s after SIGINT: SIGKILL\n", static_cast<int>(pid), grace_s);
  ::kill(pid, SIGKILL);
  return wait_for(pid, 10.0).value_or(-1);
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

// The last `n` lines of a log, indented, for an error message.
std::string tail(const fs::path& p, std::size_t n = 15) {
  const auto lines = lines_of(read_text(p));
  std::string out;
  for (std::size_t k = lines.size() > n ? lines.size() - n : 0; k < lines.size(); ++k) out += "    " + lines[k] + "\n";
  return out;
}

// The executable: the user's path, or the first of the candidates that exists. Throws
// UsageError listing every path tried.
fs::path find_executable(const std::string& option, const std::string& given, const std::vector<fs::path>& candidates,
                         const std::string& name) {
  auto ok = [](const fs::path& p) { return fs::is_regular_file(p) && ::access(p.c_str(), X_OK) == 0; };
  if (!given.empty()) {
    if (ok(given)) return fs::absolute(given);
    throw sk::UsageError(option + " " + given + ": not an executable file (expected the path of " + name + ")");
  }
  std::string tried;
  for (const fs::path& c : candidates) {
    if (ok(c)) return fs::absolute(c).lexically_normal();
    tried += "\n  " + c.lexically_normal().string();
  }
  if (const char* path = std::getenv("PATH")) {
    std::istringstream dirs(path);
    for (std::string d; std::getline(dirs, d, ':');) {
      if (!d.empty() && ok(fs::path(d) / name)) return fs::path(d) / name;
    }
    tried += "\n  " + name + " on PATH";
  }
  throw sk::UsageError(name + " not found; tried:" + tried + "\nbuild it (cmake --build build --target " +
                       (name == "pedalwave_runtime" ? std::string("pedalwave_runtime_daemon") : name) +
                       ") or give its path with " + option);
}

fs::path self_dir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::current_path() : exe.parent_path();
}

std::string now_iso() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

struct Options {
  std::string scene = pedalwave::config::shipped_dir() + "/scenes/flat_high_friction.yaml";
  std::string config = pedalwave::config::shipped_dir() + "/runtime/serial.yaml";
  double duration = 60.0;
  double rate = 0.0;
  int load = static_cast<int>(std::thread::hardware_concurrency());
  double duty = 1.0;
  std::string out = "out/soak";
  std::string runtime, vrobot;
  std::string telemetry = "on";
  double sample_period = 10.0;
  int robot_priority = 70;
  bool no_plot = false;
};

int run(const Options& opt) {
  // ---- everything checked before anything starts ----
  if (!fs::is_regular_file(opt.scene))
    throw sk::UsageError("--scene " + opt.scene + ": no such file (expected a scene YAML, e.g. config/scenes/flat_high_friction.yaml)");
  const fs::path here = self_dir();
  const fs::path runtime_exe = find_executable(
      "--runtime", opt.runtime, {here / "../runtime/pedalwave_runtime", here / "pedalwave_runtime"}, "pedalwave_runtime");
  const fs::path vrobot_exe =
      find_executable("--virtual-robot", opt.vrobot,
                      {here / "../virtual_robot/pedalwave_virtual_robot", here / "pedalwave_virtual_robot"},
                      "pedalwave_virtual_robot");
  const fs::path out = fs::absolute(opt.out);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) throw sk::UsageError("--out " + opt.out + ": cannot create the folder (" + ec.message() + ")");
  const fs::path link = out / "tty", report_path = out / "report.json", cfg_path = out / "runtime.yaml";
  const fs::path rt_log = out / "runtime.log", vr_log = out / "virtual_robot.log";
  fs::remove(report_path, ec);
  fs::remove(link, ec);
  {
    std::ofstream cfg(cfg_path);
    cfg << sk::soak_runtime_config(opt.config, link.string(), opt.rate, opt.telemetry == "on");
    if (!cfg) throw sk::UsageError("--out " + opt.out + ": cannot write " + cfg_path.string());
  }
  // The runtime's own validation of the written configuration (bus budget, rate, realtime...).
  {
    // --check-config: the file alone (the pty link does not exist until the virtual robot starts).
    const pid_t check = spawn({runtime_exe.string(), "-c", cfg_path.string(), "--check-config"}, out / "runtime_check.log");
    const int rc = wait_for(check, 60.0).value_or(-1);
    if (rc != 0)
      throw sk::UsageError("the runtime refused the configuration written from --config " + opt.config + " (" +
                           cfg_path.string() + "):\n" + tail(out / "runtime_check.log"));
  }

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::printf("pedalwave_soak: %g s, load %d × duty %g, telemetry %s, output %s\n  runtime       %s\n"
              "  virtual robot %s (%s)\n",
              opt.duration, opt.load, opt.duty, opt.telemetry.c_str(), out.c_str(), runtime_exe.c_str(), vrobot_exe.c_str(),
              opt.robot_priority > 0 ? ("SCHED_FIFO " + std::to_string(opt.robot_priority)).c_str() : "normal priority");
  std::fflush(stdout);

  // ---- the virtual robot, then its pty link ----
  const pid_t vr =
      spawn({vrobot_exe.string(), "--scene", opt.scene, "--pty", "--link", link.string()}, vr_log, opt.robot_priority);
  g_children[1] = vr;
  for (const auto t0 = Clock::now(); !fs::exists(link);) {
    if (auto c = wait_for(vr, 0.05)) {
      std::fprintf(stderr, "pedalwave_soak: error: the virtual robot exited (code %d) before making %s:\n%s", *c,
                   link.c_str(), tail(vr_log).c_str());
      return *c == 2 ? sk::kExitUsage : sk::kExitFail;
    }
    if (seconds_since(t0) > 20.0 || g_stop) {
      std::fprintf(stderr, "pedalwave_soak: error: %s did not appear within 20 s\n", link.c_str());
      stop_child(vr, 5.0);
      return sk::kExitFail;
    }
  }

  if (read_text(vr_log).find(kFifoRefused) != std::string::npos)
    std::printf("warning: the virtual robot runs at normal priority (SCHED_FIFO %d not granted: run as root or "
                "with CAP_SYS_NICE, or --robot-priority 0)\n", opt.robot_priority);

  // ---- the load, then the runtime ----
  tk::CpuLoad load;
  g_load = &load;
  load.start(opt.load, opt.duty);
  Json load_pids = Json::array();
  for (const pid_t p : load.pids()) load_pids.push(static_cast<int>(p));
  const auto t_start = Clock::now();
  const pid_t rt = spawn({runtime_exe.string(), "-c", cfg_path.string(), "--duration", tk::format_double(opt.duration),
                          "--report-json", report_path.string()},
                         rt_log);
  g_children[0] = rt;

  // ---- while it runs: memory of both, a progress line per sample ----
  std::vector<sk::MemorySample> mem_rt, mem_vr;
  std::vector<double> schedule;
  const double warmup = std::min(10.0, opt.duration / 4);
  // The first sample 1 s in (the runtime has started: locked its memory, started its threads).
  for (double t = std::min(1.0, opt.duration / 4); t < opt.duration; t += opt.sample_period) schedule.push_back(t);
  schedule.push_back(warmup);
  if (opt.duration > 1.0) schedule.push_back(opt.duration - 0.5);
  std::sort(schedule.begin(), schedule.end());
  std::size_t next = 0;
  std::optional<int> rt_exit;
  const double deadline = opt.duration + 60.0;
  bool timed_out = false;
  while (!rt_exit && !g_stop) {
    const double t = seconds_since(t_start);
    if (next < schedule.size() && t >= schedule[next]) {
      while (next < schedule.size() && schedule[next] <= t) ++next;
      const auto a = sk::read_proc_status(rt, t), b = sk::read_proc_status(vr, t);
      if (a) mem_rt.push_back(*a);
      if (b) mem_vr.push_back(*b);
      std::printf("[%7.1f / %g s] runtime RSS %.1f MB (%d threads) | virtual robot RSS %.1f MB (%d threads)\n", t,
                  opt.duration, a ? a->rss_kB / 1024.0 : 0.0, a ? a->threads : 0, b ? b->rss_kB / 1024.0 : 0.0,
                  b ? b->threads : 0);
      std::fflush(stdout);
    }
    if (t > deadline) {
      timed_out = true;
      break;
    }
    rt_exit = wait_for(rt, 0.1);
  }
  const double rt_wall = seconds_since(t_start);
  bool interrupted = g_stop != 0;
  if (!rt_exit) {
    if (timed_out)
      std::fprintf(stderr, "pedalwave_soak: the runtime is still running %g s after its duration: SIGINT\n", deadline - opt.duration);
    rt_exit = stop_child(rt, 10.0);
  }
  g_children[0] = -1;

  // ---- the virtual robot's last sample and its report; the load ----
  if (auto b = sk::read_proc_status(vr, seconds_since(t_start))) mem_vr.push_back(*b);
  const int vr_exit = stop_child(vr, 10.0);
  g_children[1] = -1;
  fs::remove(link, ec);
  load.stop();
  g_load = nullptr;
  std::vector<std::string> vr_report;
  {
    bool after = false;
    for (const std::string& l : lines_of(read_text(vr_log))) {
      if (after) vr_report.push_back(l);
      if (l.rfind("waiting for the host", 0) == 0) after = true;
    }
  }

  // ---- the runtime's report ----
  // A runtime without --report-json refuses the option at once (CLI11: "... not expected").
  const std::string rt_text = read_text(rt_log);
  const bool no_report_option = *rt_exit != 0 && rt_wall < 30.0 && rt_text.find("report-json") != std::string::npos &&
                                rt_text.find("not expected") != std::string::npos;
  Json report;
  std::string report_error;
  if (!no_report_option) {
    try {
      report = Json::parse_file(report_path);
    } catch (const tk::JsonError& e) {
      report_error = e.what();
    }
  }
  if (*rt_exit != 0)
    std::fprintf(stderr, "pedalwave_soak: the runtime exited with code %d; the end of %s:\n%s", *rt_exit, rt_log.c_str(),
                 tail(rt_log).c_str());
  sk::Verdict verdict = sk::judge(report, *rt_exit, interrupted);
  if (no_report_option) {
    report_error = "--report-json not available: " + runtime_exe.string() + " refused the option";
    verdict = {sk::kExitUsage, {report_error + "; the soak reads the runtime's report.json: build a runtime that has it"}};
    std::fprintf(stderr, "pedalwave_soak: error: %s\n", verdict.reasons[0].c_str());
  }

  // ---- soak.json, memory.csv, summary, plot ----
  utsname u{};
  ::uname(&u);
  Json reasons = Json::array();
  for (const std::string& r : verdict.reasons) reasons.push(r);
  Json vr_lines = Json::array();
  for (const std::string& l : vr_report) vr_lines.push(l);
  Json soak = Json::object();
  soak.set("tool", "pedalwave_soak").set("started", now_iso());
  soak.set("machine", Json::object()
                          .set("nproc", static_cast<int>(std::thread::hardware_concurrency()))
                          .set("kernel", std::string(u.sysname) + " " + u.release)
                          .set("kernel_version", u.version)
                          .set("arch", u.machine));
  soak.set("settings", Json::object()
                           .set("duration_s", opt.duration)
                           .set("rate_hz", opt.rate > 0 ? Json(opt.rate) : Json())
                           .set("scene", opt.scene)
                           .set("config", opt.config)
                           .set("runtime_config", cfg_path.string())
                           .set("runtime", runtime_exe.string())
                           .set("virtual_robot", vrobot_exe.string())
                           .set("telemetry", opt.telemetry)
                           .set("robot_priority", opt.robot_priority)
                           .set("sample_period_s", opt.sample_period));
  soak.set("load", Json::object()
                       .set("children", opt.load)
                       .set("duty", opt.duty)
                       .set("cpu_s", load.cpu_seconds())
                       .set("pids", load_pids));
  soak.set("memory_warmup_s", warmup);
  soak.set("memory", Json::object().set("runtime", sk::to_json(mem_rt)).set("virtual_robot", sk::to_json(mem_vr)));
  soak.set("runtime", Json::object().set("pid", static_cast<int>(rt)).set("exit_code", *rt_exit).set("wall_s", rt_wall).set("log", rt_log.string()));
  soak.set("virtual_robot", Json::object().set("pid", static_cast<int>(vr)).set("exit_code", vr_exit).set("report", vr_lines).set("log", vr_log.string()));
  soak.set("report", report);
  if (!report_error.empty()) soak.set("report_error", report_error);
  soak.set("interrupted", interrupted);
  soak.set("verdict", Json::object().set("code", verdict.code).set("reasons", reasons));
  {
    std::ofstream f(out / "soak.json");
    f << soak.dump(2) << "\n";
  }
  {
    tk::CsvWriter csv(out / "memory.csv", {"t_s", "process", "rss_kB", "hwm_kB", "size_kB", "threads"});
    csv.comment("process: 0 = runtime, 1 = virtual robot (/proc/<pid>/status)");
    for (int p = 0; p < 2; ++p)
      for (const sk::MemorySample& s : p == 0 ? mem_rt : mem_vr)
        csv.row({s.t_s, static_cast<double>(p), static_cast<double>(s.rss_kB), static_cast<double>(s.hwm_kB),
                 static_cast<double>(s.size_kB), static_cast<double>(s.threads)});
    csv.close();
  }
  std::printf("%s", sk::summary(soak).c_str());
  std::printf("\nwritten: %s, %s, %s, %s\n", (out / "soak.json").c_str(), (out / "memory.csv").c_str(), rt_log.c_str(),
              vr_log.c_str());
  std::fflush(stdout);  // before the script's output
  if (!opt.no_plot) {  // tools/figures/soak.py: the timing histograms and the memory over time
    const tk::FigureOutcome r = tk::draw_figures("soak.py", {(out / "soak.json").string(), (out / "soak.png").string()});
    std::fprintf(r.status == tk::FigureOutcome::Status::drawn ? stdout : stderr, "%s\n", r.message.c_str());
  }
  std::fflush(stdout);
  return verdict.code;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pedalwave_soak: the virtual robot (pty) and the runtime daemon as processes, under CPU load, for a "
               "long run; memory, events, overruns and timing histograms at the end"};
  Options opt;
  app.add_option("--scene", opt.scene, "scene of the virtual robot (YAML)")->capture_default_str();
  app.add_option("--config", opt.config, "runtime configuration template (driver.type: serial)")->capture_default_str();
  app.add_option("--duration", opt.duration, "run time of the runtime [s]")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--rate", opt.rate, "override the template's rate_hz [Hz]")->check(CLI::PositiveNumber);
  app.add_option("--load", opt.load, "busy-loop processes beside the runtime (default: number of CPUs)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--load-duty", opt.duty, "busy fraction of each load process, of every 10 ms (0, 1]")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--out", opt.out, "output folder")->capture_default_str();
  app.add_option("--runtime", opt.runtime,
                 "pedalwave_runtime executable (default: ../runtime/pedalwave_runtime next to this tool, then PATH)");
  app.add_option("--virtual-robot", opt.vrobot,
                 "pedalwave_virtual_robot executable (default: ../virtual_robot/pedalwave_virtual_robot, then PATH)");
  app.add_option("--telemetry", opt.telemetry, "the runtime's DDS telemetry (interface lo)")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  app.add_option("--sample-period", opt.sample_period, "memory sample and progress period [s]")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--robot-priority", opt.robot_priority,
                 "SCHED_FIFO priority of the virtual robot (it stands for the modules' own hardware, which the "
                 "load does not share; below the runtime's); 0 = normal scheduling")
      ->check(CLI::Range(0, 99))
      ->capture_default_str();
  app.add_flag("--no-plot", opt.no_plot, "do not draw soak.png");
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_soak")) return *rc;
  if (opt.duty <= 0.0) {
    std::cerr << "pedalwave_soak: error: --load-duty " << opt.duty << ": expected a fraction in (0, 1]\n";
    return sk::kExitUsage;
  }
  try {
    return run(opt);
  } catch (const sk::UsageError& e) {
    std::cerr << "pedalwave_soak: error: " << e.what() << '\n';
    return sk::kExitUsage;
  } catch (...) {
    return pedalwave::toolkit::cli::exit_for_current_exception("pedalwave_soak");
  }
}
