// rtbench: how well does the runtime loop keep its period on this machine?
//
// For each phase (idle: no background load; loaded: N load threads), it runs in the same time
// window:
//   - the real pedalwave::runtime loop (read → observe → control → write → publish) at --rate,
//     with a trivial in-memory driver and a controller that computes for --load-us per cycle,
//   - cyclictest with the same priority, interval and duration (one thread, histogram output),
// then prints wake-up latency p50/p99/p99.9/max of both side by side with the ratio, our
// overruns, and our per-stage compute time percentiles. A missing privilege or a missing
// cyclictest is reported loudly; our numbers are printed regardless.
#include <sys/utsname.h>
#include <unistd.h>

#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cyclictest.hpp"
#include "pedalwave/runtime/consumer.hpp"
#include "pedalwave/runtime/runtime.hpp"

namespace {

namespace prt = pedalwave::runtime;
namespace dr = pedalwave::drivers;
using pedalwave::rtbench::CyclictestHistogram;

// A driver with nothing behind it: feedback is a slow sine, writes go nowhere.
class NullDriver : public dr::Driver {
 public:
  explicit NullDriver(int joints) : joints_(joints) {}
  int joints() const override { return joints_; }
  dr::IoStatus read(std::int64_t now_ns, std::int64_t, dr::Feedback& out) override {
    out.joints = joints_;
    out.seq = seq_++;
    out.stamp_ns = now_ns;
    for (int j = 0; j < joints_; ++j) {
      const auto js = static_cast<std::size_t>(j);
      out.beta[js] = 0.1 * std::sin(1e-3 * static_cast<double>(seq_) + j);
      out.beta_dot[js] = 0.0;
      out.deflection[js] = 0.0;
      out.status[js] = dr::kStatusOk;
    }
    return dr::IoStatus::kOk;
  }
  dr::IoStatus write(const dr::Command& cmd) override {
    sink_ = sink_ + cmd.tau[0];
    return dr::IoStatus::kOk;
  }
  void safe_stop() override { ++safe_stops_; }
  const dr::DriverCounters& counters() const override { return counters_; }

 private:
  int joints_;
  std::uint64_t seq_ = 0, safe_stops_ = 0;
  volatile double sink_ = 0.0;
  dr::DriverCounters counters_{};
};

// A controller that computes for load_ns per cycle (busy arithmetic until the budget is spent),
// then writes a PD-like torque.
class LoadController : public prt::Controller {
 public:
  explicit LoadController(std::int64_t load_ns) : load_ns_(load_ns) {}
  void start(const dr::Feedback&) override {}
  void control(const prt::CycleIo& io) override {
    double acc = 0.0;
    if (load_ns_ > 0) {
      const std::int64_t t0 = prt::monotonic_ns();
      int i = 0;
      while (prt::monotonic_ns() - t0 < load_ns_) {
        for (int k = 0; k < 64; ++k) acc += std::sin(0.001 * (i + k));
        ++i;
      }
    }
    for (int j = 0; j < io.cmd.joints; ++j) {
      const auto js = static_cast<std::size_t>(j);
      io.cmd.tau[js] = -2.0 * io.fb.beta[js] + 1e-12 * acc;
    }
  }
  void hold(const prt::CycleIo& io) override { control(io); }

 private:
  std::int64_t load_ns_;
};

// Background load: threads doing floating-point work and walking a buffer larger than the
// caches, SCHED_OTHER, each bounded by its own deadline even if the phase is aborted.
class BackgroundLoad {
 public:
  BackgroundLoad(int threads, double seconds) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds + 2.0);
    for (int t = 0; t < threads; ++t) {
      threads_.emplace_back([this, until, t] {
        std::vector<std::uint64_t> buf(4u << 20, static_cast<std::uint64_t>(t));  // 32 MiB
        std::uint64_t x = 1;
        double y = 1.0;
        std::size_t i = 0;
        while (!stop_.load(std::memory_order_relaxed) && std::chrono::steady_clock::now() < until) {
          for (int k = 0; k < 4096; ++k) {
            i = (i + 4099) & (buf.size() - 1);
            buf[i] += x;
            x = x * 6364136223846793005ull + 1442695040888963407ull;
            y = std::sqrt(y + static_cast<double>(x & 1023));
          }
        }
        sink_.fetch_add(static_cast<std::uint64_t>(y) + buf[i], std::memory_order_relaxed);
      });
    }
  }
  ~BackgroundLoad() {
    stop_.store(true);
    for (auto& t : threads_) t.join();
  }

 private:
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> sink_{0};
  std::vector<std::thread> threads_;
};

struct Options {
  int seconds = 10;
  double rate = 1000.0;
  int priority = 80;
  int cpu = -1;
  bool lock_memory = true;
  double load_us = 0.0;
  int joints = 12;
  int bg_threads = 0;  // 0 = number of online CPUs
  std::vector<std::string> phases = {"idle", "loaded"};
  bool cyclictest = true;
  std::string cyclictest_exe = "cyclictest";
  int hist_us = 10000;
  bool sequential = false;
};

struct PhaseResult {
  std::string name;
  prt::RunResult run;
  std::unique_ptr<prt::LoopMetrics> metrics;
  CyclictestHistogram ct;
  bool ct_ran = false;
  std::string ct_command;
};

std::string machine_line() {
  utsname u{};
  uname(&u);
  std::ostringstream os;
  os << u.sysname << " " << u.release << " " << u.version << ", " << sysconf(_SC_NPROCESSORS_ONLN)
     << " online CPUs";
  std::ifstream rt("/sys/kernel/realtime");
  int is_rt = 0;
  if (rt >> is_rt && is_rt == 1) os << ", PREEMPT_RT";
  std::ifstream cmd("/proc/cmdline");
  std::string c;
  std::getline(cmd, c);
  if (c.find("isolcpus") == std::string::npos) os << ", no isolcpus";
  std::ifstream hv("/sys/hypervisor/type");
  std::string h;
  if (hv >> h) os << ", hypervisor " << h;
  std::ifstream cpu("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpu, line)) {
    if (line.find("hypervisor") != std::string::npos && line.rfind("flags", 0) == 0) {
      os << ", virtual machine (cpu flag 'hypervisor')";
      break;
    }
  }
  return os.str();
}

PhaseResult run_phase(const Options& o, const std::string& phase) {
  PhaseResult pr;
  pr.name = phase;
  const int threads = o.bg_threads > 0 ? o.bg_threads : static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN));
  const double total_s = o.sequential ? 2.0 * o.seconds + 1.0 : o.seconds + 1.0;
  std::unique_ptr<BackgroundLoad> load;
  if (phase == "loaded") load = std::make_unique<BackgroundLoad>(threads, total_s);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // let the load ramp up

  const int interval_us = static_cast<int>(std::lround(1e6 / o.rate));
  pedalwave::rtbench::CyclictestRun ct;
  auto launch_ct = [&] {
    ct = pedalwave::rtbench::start_cyclictest(o.cyclictest_exe, o.priority, interval_us, o.seconds,
                                              o.hist_us, o.cpu, o.lock_memory);
    pr.ct_ran = true;
    pr.ct_command = ct.command;
  };
  if (o.cyclictest && !o.sequential) launch_ct();

  prt::RuntimeConfig cfg;
  cfg.rt.rate_hz = o.rate;
  cfg.rt.priority = o.priority;
  cfg.rt.cpu = o.cpu;
  cfg.rt.lock_memory = o.lock_memory;
  cfg.rt.prefault_stack_bytes = 256 * 1024;
  cfg.clock = prt::ClockMode::kRealtime;
  cfg.auto_start = true;
  cfg.stale_timeout = 1.0;
  cfg.max_cycles = static_cast<std::uint64_t>(std::llround(o.seconds * o.rate));
  cfg.description.rate_hz = o.rate;
  NullDriver driver(o.joints);
  LoadController controller(static_cast<std::int64_t>(std::llround(o.load_us * 1e3)));
  auto runtime = std::make_unique<prt::Runtime>(cfg, driver, controller);
  prt::ConsumerConfig ccfg;
  ccfg.log_events = false;
  prt::TelemetryConsumer consumer(*runtime, {}, ccfg);
  consumer.start();
  std::thread loop([&] { pr.run = runtime->run(); });
  loop.join();
  consumer.stop();
  pr.metrics = std::make_unique<prt::LoopMetrics>(runtime->metrics());

  if (o.cyclictest && o.sequential) launch_ct();
  if (o.cyclictest) pr.ct = pedalwave::rtbench::finish_cyclictest(ct);
  return pr;
}

void print_phase(const Options& o, const PhaseResult& pr) {
  const auto& m = *pr.metrics;
  auto us = [](std::int64_t ns) { return static_cast<double>(ns) * 1e-3; };
  std::printf("\n=== phase: %s%s ===\n", pr.name.c_str(),
              pr.name == "loaded" ? " (background CPU+memory load threads, SCHED_OTHER)" : "");
  std::printf("wake-up latency [us]      p50       p99     p99.9       max   samples\n");
  const double o50 = us(m.wake.percentile(0.5)), o99 = us(m.wake.percentile(0.99)),
               o999 = us(m.wake.percentile(0.999)), omax = us(m.wake.max());
  std::printf("  pedalwave loop     %9.1f %9.1f %9.1f %9.1f %9llu\n", o50, o99, o999, omax,
              static_cast<unsigned long long>(m.wake.count()));
  if (!o.cyclictest) {
    std::printf("  cyclictest         (disabled with --no-cyclictest)\n");
  } else if (!pr.ct.ok) {
    std::printf("  cyclictest         *** NOT AVAILABLE: %s\n", pr.ct.error.c_str());
  } else {
    const auto& h = pr.ct;
    const double c50 = static_cast<double>(h.percentile_us(0.5)), c99 = static_cast<double>(h.percentile_us(0.99)),
                 c999 = static_cast<double>(h.percentile_us(0.999)), cmax = static_cast<double>(h.max_us);
    std::printf("  cyclictest         %9.0f %9.0f %9.0f %9.0f %9llu\n", c50, c99, c999, cmax,
                static_cast<unsigned long long>(h.total));
    auto ratio = [](double a, double b) { return b > 0 ? a / b : NAN; };
    std::printf("  ratio ours/ct      %9.2f %9.2f %9.2f %9.2f\n", ratio(o50, c50), ratio(o99, c99),
                ratio(o999, c999), ratio(omax, cmax));
    if (h.overflows > 0)
      std::printf("  (cyclictest: %llu samples above the %d us histogram; a percentile there is its max)\n",
                  static_cast<unsigned long long>(h.overflows), o.hist_us);
    std::printf("  cyclictest command: %s\n", pr.ct_command.c_str());
  }
  std::printf("overruns: %llu of %llu cycles (%llu periods skipped, at most %u at once)\n",
              static_cast<unsigned long long>(m.overruns), static_cast<unsigned long long>(m.cycles),
              static_cast<unsigned long long>(m.skipped_periods), m.max_skipped);
  std::printf("ring drops: cycle %llu, event %llu\n", static_cast<unsigned long long>(pr.run.cycle_drops),
              static_cast<unsigned long long>(pr.run.event_drops));
  std::printf("compute time per stage:\n%s", prt::format_table(m).c_str());
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"rtbench: the pedalwave loop's wake-up latency next to cyclictest's"};
  app.add_option("-s,--seconds", o.seconds, "duration of each phase [s]")->check(CLI::Range(1, 3600));
  app.add_option("-r,--rate", o.rate, "loop rate [Hz]")->check(CLI::Range(1.0, 20000.0));
  app.add_option("-p,--priority", o.priority, "SCHED_FIFO priority, 0 = SCHED_OTHER")->check(CLI::Range(0, 99));
  app.add_option("-c,--cpu", o.cpu, "pin the loop (and cyclictest) to this CPU, -1 = no pinning");
  app.add_flag("!--no-mlock", o.lock_memory, "do not mlockall");
  app.add_option("-l,--load-us", o.load_us, "controller compute per cycle [us]")->check(CLI::Range(0.0, 1e6));
  app.add_option("-j,--joints", o.joints, "joints of the fake robot")->check(CLI::Range(1, 63));
  app.add_option("-b,--bg-threads", o.bg_threads, "background load threads in the 'loaded' phase (0 = one per CPU)")
      ->check(CLI::Range(0, 256));
  app.add_option("--phases", o.phases, "phases to run: idle, loaded")
      ->check(CLI::IsMember({"idle", "loaded"}))->delimiter(',');
  app.add_flag("!--no-cyclictest", o.cyclictest, "do not run cyclictest");
  app.add_option("--cyclictest", o.cyclictest_exe, "cyclictest executable");
  app.add_option("--hist-us", o.hist_us, "cyclictest histogram range [us]")->check(CLI::Range(100, 1000000));
  app.add_flag("--sequential", o.sequential,
               "run cyclictest after our loop instead of at the same time (no mutual interference, "
               "but a different time window)");
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_rtbench")) return *rc;

  std::printf("rtbench: %d s per phase at %.0f Hz, %s, cpu %d, mlockall %s, compute load %.1f us/cycle, %d joints\n",
              o.seconds, o.rate, o.priority > 0 ? ("SCHED_FIFO " + std::to_string(o.priority)).c_str() : "SCHED_OTHER",
              o.cpu, o.lock_memory ? "on" : "off", o.load_us, o.joints);
  std::printf("machine: %s\n", machine_line().c_str());
  std::printf("cyclictest runs %s, one thread, same priority and interval\n",
              o.sequential ? "right after our loop" : "at the same time as our loop");

  try {
    prt::RtConfig probe;
    probe.rate_hz = o.rate;
    probe.priority = o.priority;
    probe.cpu = o.cpu;
    prt::validate(probe);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rtbench: %s\n", e.what());
    return 2;
  }

  bool any_refused = false;
  for (const auto& phase : o.phases) {
    PhaseResult pr = run_phase(o, phase);
    if (!pr.run.rt.warnings.empty() && !any_refused) {
      any_refused = true;
      std::printf("\n*** REAL-TIME SETUP PARTLY REFUSED — numbers below are NOT real-time numbers ***\n");
      for (const auto& w : pr.run.rt.warnings) std::printf("*** %s\n", w.c_str());
    }
    std::printf("rt setup: %s\n", pr.run.rt.describe().c_str());
    print_phase(o, pr);
  }
  return 0;
}
