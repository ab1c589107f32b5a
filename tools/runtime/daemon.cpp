#include "daemon.hpp"

#include <fcntl.h>
#include <net/if.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <algorithm>
#include <cstdlib>
#include <ctime>
#include <cmath>
#include <exception>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <vector>

#include "gait_stage.hpp"
#include "run_marker.hpp"
#include "run_report.hpp"
#include "pedalwave/drivers/fault_injecting_driver.hpp"
#include "pedalwave/drivers/serial_driver.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/drivers/canopen_driver.hpp"
#include "pedalwave/drivers/socketcan_driver.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/runtime/consumer.hpp"
#include "pedalwave/simloop/plant_checks.hpp"
#include "pedalwave/toolkit/cli.hpp"
#include "pedalwave/toolkit/body_csv.hpp"
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figures.hpp"
#include "pedalwave/toolkit/json.hpp"
#include "pedalwave/toolkit/toolkit.hpp"
#if PEDALWAVE_HAS_DDS
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/mcap_recorder.hpp"
#endif
#include "pedalwave/observer/input_log.hpp"
#include "pedalwave/observer/runtime_observer.hpp"

namespace pedalwave::app {

namespace {

// Keeps a compact, decimated copy of the cycle samples for the plots and cycles.csv (on the
// telemetry consumer's thread, never the loop's): every `every`-th cycle, at most kMaxRows rows.
class SampleRecorder final : public runtime::TelemetrySink {
 public:
  static constexpr std::size_t kMaxRows = 1'000'000;  // 5.5 h at 500 Hz / 10 (≈ 30 B per joint)
  static constexpr int kPerJoint = 7;  // β, β̇, deflection, α, τ_s, u, residual
  struct Row {
    std::int64_t t_ns = 0;
    double t = 0;  // controller time [s]
    runtime::Mode mode = runtime::Mode::kUnconfigured;
    std::uint32_t fault_flags = 0;
    float wake_us = 0, read_us = 0;
  };
  explicit SampleRecorder(int every) : every_(every) {}
  void on_description(const runtime::RobotDescription&) override {}
  void on_cycle(const runtime::CycleSample& s) override {
    if (s.seq % static_cast<std::uint64_t>(every_) != 0) return;
    if (rows.size() >= kMaxRows) {
      truncated = true;
      return;
    }
    if (joints == 0) joints = s.joints;
    rows.push_back({s.t_ns, s.t, s.mode, s.fault_flags, 1e-3f * static_cast<float>(s.wake_latency_ns),
                    1e-3f * static_cast<float>(s.t_read_ns)});
    for (int j = 0; j < joints; ++j) {
      const auto k = static_cast<std::size_t>(j);
      for (double v : {s.beta[k], s.beta_dot[k], s.deflection[k], s.alpha[k], s.tau_sea[k], s.u[k],
                       s.residual[k]})
        values.push_back(static_cast<float>(v));
    }
  }
  void on_event(const runtime::EventSample&) override {}
  // Joint j's quantity q (0 … kPerJoint−1) in row i.
  float at(std::size_t i, int j, int q) const {
    return values[(i * static_cast<std::size_t>(joints) + static_cast<std::size_t>(j)) * kPerJoint +
                  static_cast<std::size_t>(q)];
  }
  std::vector<Row> rows;
  std::vector<float> values;  // rows × joints × kPerJoint
  int joints = 0;
  bool truncated = false;

 private:
  int every_;
};

// The configured driver; on the simulated plant with a scene `faults:` list, the SimDriver wrapped
// in a FaultInjectingDriver that applies them.
struct OwnedDriver {
  std::unique_ptr<drivers::Driver> base;
  std::unique_ptr<drivers::FaultInjectingDriver> faults;
  drivers::Driver* top() const { return faults ? faults.get() : base.get(); }
};

OwnedDriver make_driver(const config::DaemonConfig& cfg, double duration) {
  const config::DriverSelection& d = cfg.driver;
  OwnedDriver o;
  switch (d.kind) {
    case config::DriverKind::kSim: {
      drivers::SimDriverOptions so = d.sim;
      const double rate = cfg.runtime.rt.rate_hz;
      so.record_every = std::max(1, static_cast<int>(std::lround(rate / 100.0)));  // 100 Hz
      so.record_capacity = static_cast<std::size_t>((duration > 0 ? duration : 600.0) * 100.0) + 16;
      auto sim = std::make_unique<drivers::SimDriver>(d.scene, so);
      if (!d.scene.faults.empty()) o.faults = std::make_unique<drivers::FaultInjectingDriver>(*sim);
      sim->start();  // free-running plants start their own thread; lockstep: no-op
      o.base = std::move(sim);
      break;
    }
    case config::DriverKind::kSocketCan: o.base = drivers::open_socketcan(d.can); break;
    case config::DriverKind::kSerial: o.base = drivers::SerialDriver::open(d.serial); break;
  }
  return o;
}

double com_x(const model::Model& m, model::Data& data, const double* q) {
  const Eigen::Map<const Eigen::VectorXd> qv(q, m.nq());
  model::update_kinematics(m, data, qv, Eigen::VectorXd());
  return model::center_of_mass(m, data, qv).x();
}

// The simulated plant's data for the figures (tools/figures/runtime.py): body.csv (per recorded
// sample t, the COM, the head tip and the 2N+1 body points) and plant.json (the scene: ground,
// boxes, friction patches).
void write_plant_data(const std::string& dir, drivers::SimDriver& sim, const config::DaemonConfig& cfg) {
  namespace tk = toolkit;
  std::filesystem::create_directories(dir);
  const model::Model& m = sim.sim().plant().model();
  model::Data data(m);
  const drivers::SimRecording& r = sim.recording();
  const auto nq = static_cast<std::size_t>(r.nq);
  const auto P = static_cast<std::size_t>(m.points());
  tk::BodyPointsCsv csv(dir + "/body.csv", {"t", "com_x", "com_z", "head_x", "head_z"}, P);
  csv.comment("the simulated plant of " + cfg.name + ": COM, head tip and the 2N+1 body points (tail tip first) [m]");
  std::vector<double> x(P), z(P);
  for (std::size_t i = 0; i < r.count; ++i) {
    const Eigen::Map<const Eigen::VectorXd> q(&r.q[i * nq], r.nq);
    model::update_kinematics(m, data, q, Eigen::VectorXd());
    const model::Vec2 c = model::center_of_mass(m, data, q);
    const model::Vec2 h = model::point_position(m, data, q, m.point_head());
    for (std::size_t k = 0; k < P; ++k) {
      const model::Vec2 p = model::point_position(m, data, q, static_cast<int>(k));
      x[k] = p.x();
      z[k] = p.y();
    }
    csv.row({r.t[i], c.x(), c.y(), h.x(), h.y()}, x, z);
  }
  csv.close();
  const model::Scene& scene = sim.sim().plant().scene();
  tk::Json boxes = tk::Json::array(), patches = tk::Json::array();
  for (const model::Box& b : scene.boxes)
    boxes.push(tk::Json::object()
                   .set("x0", b.x_near).set("x1", b.x_near + b.width)
                   .set("z0", scene.ground.z).set("z1", scene.ground.z + b.height));
  for (const auto& p : scene.ground.patches) patches.push(tk::Json::object().set("x_begin", p.x_begin).set("mu", p.mu));
  tk::Json plant = tk::Json::object();
  plant.set("name", cfg.name);
  plant.set("scene", tk::Json::object()
                         .set("ground_z", scene.ground_on ? tk::Json(scene.ground.z) : tk::Json())
                         .set("boxes", std::move(boxes))
                         .set("patches", std::move(patches)));
  std::ofstream(dir + "/plant.json") << plant.dump(2) << "\n";
}

// What the runtime itself measured, commanded and concluded, on any driver (a bus or the
// simulated plant): cycles.csv (every recorded row) and runtime.json (the events to mark, the
// residual threshold) for the figures runtime_signals.png and observer.png.
void write_runtime_data(const std::string& dir, const SampleRecorder& rec,
                        const runtime::EventLog& log, const std::vector<runtime::RunEvent>& events,
                        double r_threshold, std::ostream& out) {
  namespace tk = toolkit;
  std::filesystem::create_directories(dir);
  std::filesystem::remove(dir + "/body.csv");  // an earlier run's plant: written again below if simulated
  std::filesystem::remove(dir + "/plant.json");
  const int J = rec.joints;
  const std::size_t n = rec.rows.size();
  const std::string csv_path = dir + "/cycles.csv";
  try {
    static const char* kNames[SampleRecorder::kPerJoint] = {"beta", "beta_dot", "deflection", "alpha",
                                                           "tau_sea", "u", "residual"};
    std::vector<std::string> header = {"t_s", "t_controller_s", "mode", "fault_flags", "wake_latency_us", "read_us"};
    for (int j = 0; j < J; ++j)
      for (const char* q : kNames) header.push_back(std::string(q) + "_" + std::to_string(j + 1));
    tk::CsvWriter csv(csv_path, std::move(header));
    std::vector<tk::CsvWriter::Cell> cells;
    for (std::size_t i = 0; i < n; ++i) {
      const SampleRecorder::Row& r = rec.rows[i];
      cells.clear();
      cells.insert(cells.end(), {static_cast<double>(r.t_ns - log.t0_ns()) * 1e-9, r.t,
                                 std::string_view(runtime::to_string(r.mode)), static_cast<double>(r.fault_flags),
                                 static_cast<double>(r.wake_us), static_cast<double>(r.read_us)});
      for (int j = 0; j < J; ++j)
        for (int q = 0; q < SampleRecorder::kPerJoint; ++q) cells.emplace_back(rec.at(i, j, q));
      csv.row(cells);
    }
    csv.close();
  } catch (const tk::CsvError& e) {
    throw std::runtime_error("--plots " + dir + ": " + e.what());
  }
  tk::Json marks = tk::Json::array();
  for (const runtime::RunEvent& e : events)
    if (e.listed && e.sample.fault != runtime::FaultClass::kNone)
      marks.push(tk::Json::object()
                     .set("t", log.seconds(e.sample))
                     .set("label", std::string(runtime::to_string(e.sample.fault)) + " j" +
                                       std::to_string(e.sample.joint + 1)));
  tk::Json info = tk::Json::object();
  info.set("residual_threshold", std::isfinite(r_threshold) ? tk::Json(r_threshold) : tk::Json());
  info.set("marks", std::move(marks));
  std::ofstream(dir + "/runtime.json") << info.dump(2) << "\n";
  out << "plot data: " << csv_path << " (" << n << " rows" << (rec.truncated ? ", truncated" : "") << ")\n";
}

// Draws the figures of the folder's data (tools/figures/runtime.py) and says what it wrote, or
// why it wrote nothing.
void draw_run_figures(const std::string& dir, std::ostream& out) {
  const toolkit::FigureOutcome r = toolkit::draw_figures("runtime.py", {dir});
  if (r.status == toolkit::FigureOutcome::Status::drawn)
    out << "plots: " << r.message << "\n";
  else  // loudly, also when the run prints nothing: the data are there, the figures are not
    std::cerr << "pedalwave_runtime: --plots " << dir << ": " << r.message << "\n";
}

}  // namespace

// The residual threshold the daemon's observer uses (NaN: no observer).
double observer_threshold(const config::DaemonConfig& cfg) {
  return cfg.observer ? observer::ObserverParams{}.r_threshold : NAN;
}

// The daemon's observer parameters for a driver that declares `spec`.
observer::ObserverParams observer_params(const config::DaemonConfig& cfg, const drivers::FeedbackSpec& spec) {
  observer::ObserverParams op;
  // The driver's declared sensor resolution and host-law stale limit: the observer's thresholds
  // are at least what that quantization produces (runtime/observer/README.md §1.3).
  op.feedback = spec;
  op.robot = cfg.robot;
  if (op.robot.K.empty())  // one stiffness per joint, explicitly
    op.robot.K.assign(static_cast<std::size_t>(op.robot.N - 1), op.robot.K_all);
  op.period = 1.0 / cfg.runtime.rt.rate_hz;
  op.missing_cycles = cfg.observer_missing_cycles;
  op.missing_time = cfg.observer_missing_time;
  if (cfg.driver.kind == config::DriverKind::kSim) {
    const model::Scene& sc = cfg.driver.scene;
    if (sc.ground_on) op.ground = sc.ground;  // nominal terrain of the onboard body model
    if (sc.joint_friction_on) op.motor_viscous = sc.joint_friction.motor_viscous;
    if (sc.torque_limit_on) op.u_max = sc.torque_limit.u_max;
  }
  return op;
}

std::unique_ptr<observer::RuntimeObserver> make_observer(const config::DaemonConfig& cfg,
                                                         const drivers::Driver* driver) {
  if (!cfg.observer) return nullptr;
  return std::make_unique<observer::RuntimeObserver>(
      observer_params(cfg, driver ? driver->feedback_spec() : drivers::FeedbackSpec{}));
}

int exit_code(const runtime::RunResult& r) noexcept {
  // One mapping for the daemon and the tools that read its report (pedalwave_soak): by the
  // reason's name, as the report writes it.
  return toolkit::cli::exit_for_run_end(runtime::to_string(r.reason));
}

int exit_code(const DaemonResult& r) noexcept {
  return r.plant_failed() ? kExitNumerical : exit_code(r.run);
}

namespace {
// The PD gains the plant's integrator sees (model::check): the module's when it applies the PD
// law (the largest of each), none when the host does (the plant gets a torque held per period).
model::ControlGains plant_gains(const control::PdParams& pd) {
  if (pd.placement != control::PdPlacement::kModule) return {0.0, 0.0};
  model::ControlGains g{0.0, 0.0};
  for (double k : pd.K_p) g.K_p = std::max(g.K_p, k);
  for (double k : pd.K_D) g.K_D = std::max(g.K_D, k);
  return g;
}
}  // namespace

std::string config_problem(const config::DaemonConfig& cfg) {
  if (cfg.driver.kind != config::DriverKind::kSim) return "";
  const model::IntegratorOptions& integ = cfg.driver.scene.integrator;
  const std::string why = simloop::step_problem(integ, cfg.runtime.rt.rate_hz, "1/rate_hz");
  if (why.empty()) return "";
  std::ostringstream os;
  os << cfg.driver.scene_path << ": integrator.h = " << integ.h << ": " << why << " (rate_hz "
     << cfg.runtime.rt.rate_hz << " in " << (cfg.source.empty() ? cfg.name : cfg.source) << ")";
  return os.str();
}

std::string folder_problem(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return "cannot create the folder (" + ec.message() + ")";
  if (!std::filesystem::is_directory(dir, ec)) return "cannot create the folder (not a directory)";
  const std::filesystem::path probe =
      std::filesystem::path(dir) / (".pedalwave_write_probe_" + std::to_string(::getpid()));
  {
    std::ofstream f(probe);
    f << "probe\n";
    f.flush();
    if (!f) {
      std::filesystem::remove(probe, ec);
      return "cannot write files in the folder (" + std::string(std::strerror(errno)) + ")";
    }
  }
  std::filesystem::remove(probe, ec);
  return "";
}

std::string file_problem(const std::string& path) {
  std::error_code ec;
  const std::filesystem::path p = std::filesystem::absolute(path, ec);
  if (ec) return "cannot resolve the path (" + ec.message() + ")";
  if (std::filesystem::is_directory(p, ec)) return "is a directory";
  if (const std::string why = folder_problem(p.parent_path().string()); !why.empty()) return why;
  if (std::filesystem::exists(p, ec) && ::access(p.c_str(), W_OK) != 0)
    return "cannot write the file (" + std::string(std::strerror(errno)) + ")";
  return "";
}

std::vector<CheckItem> preflight(const config::DaemonConfig& cfg, const DaemonOptions& opt) {
  std::vector<CheckItem> items;
  auto add = [&](bool ok, std::string what, std::string why) {
    items.push_back({ok, std::move(what), ok ? std::string() : std::move(why)});
  };
  add(true, "configuration " + cfg.source + " (driver " + config::to_string(cfg.driver.kind) + ", " +
                std::to_string(cfg.robot.N - 1) + " joints)", "");
  const config::DriverSelection& d = cfg.driver;
  if (d.kind == config::DriverKind::kSim) {
    add(true, "simulated plant: scene " + d.scene_path + " loads", "");
  } else if (d.kind == config::DriverKind::kSerial) {
    // Opening the tty sends nothing; the driver's own open() configures it and talks to the bus.
    const std::string what = "serial device " + d.serial.device + " exists and opens";
    struct stat st {};
    if (::stat(d.serial.device.c_str(), &st) != 0) {
      add(false, what, std::strerror(errno));
    } else if (!S_ISCHR(st.st_mode)) {
      add(false, what, "not a character device");
    } else {
      const int fd = ::open(d.serial.device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
      add(fd >= 0, what, fd >= 0 ? "" : std::strerror(errno));
      if (fd >= 0) ::close(fd);
    }
  } else {
    const std::string what = "CAN interface " + d.can.ifname + " exists";
    add(::if_nametoindex(d.can.ifname.c_str()) != 0, what, "no such network interface");
  }
  if (const int cpu = cfg.runtime.rt.cpu; cpu >= 0) {  // the file is the robot's: is its CPU here?
    const int n = runtime::online_cpus();
    add(runtime::cpu_problem(cpu).empty(),
        "CPU " + std::to_string(cpu) + " exists (this machine has " + std::to_string(n) + " online CPUs)",
        "no such CPU (realtime.cpu: 0 … " + std::to_string(n - 1) + ", or -1 for no pinning)");
  }
  if (cfg.telemetry.enabled && opt.telemetry && cfg.telemetry.has_interface)
    add(::if_nametoindex(cfg.telemetry.interface.c_str()) != 0,
        "DDS network interface " + cfg.telemetry.interface + " exists", "no such network interface");
  if (!opt.plots_dir.empty()) {
    const std::string why = folder_problem(opt.plots_dir);
    add(why.empty(), "--plots " + opt.plots_dir + " is a writable folder", why);
  }
  if (!opt.report_json.empty()) {
    const std::filesystem::path parent = std::filesystem::absolute(opt.report_json).parent_path();
    const bool ok = ::access(parent.c_str(), W_OK) == 0 &&
                    (!std::filesystem::exists(opt.report_json) || ::access(opt.report_json.c_str(), W_OK) == 0);
    add(ok, "--report-json " + opt.report_json + " can be written", std::strerror(errno));
  }
  if (!opt.state_dir.empty()) {
    const std::string why = folder_problem(opt.state_dir);
    add(why.empty(), "--state-dir " + opt.state_dir + " is a writable folder", why);
  }
  if (!cfg.log_file.empty()) {  // the events log (spdlog appends to it, creating its folder)
    const std::string why = file_problem(cfg.log_file);
    add(why.empty(), "log_file " + cfg.log_file + " can be written", why);
  }
  return items;
}

DaemonResult run_daemon(const config::DaemonConfig& cfg, const DaemonOptions& opt) {
  DaemonResult res;
  std::ostringstream log;
  std::ostream& out = opt.print ? std::cout : log;

  if (const std::string why = config_problem(cfg); !why.empty()) throw BadInput(why);
  // The file names the robot's CPU (it loads on any machine): this one must have it, or nothing
  // starts — not the driver either.
  if (const std::string why = runtime::cpu_problem(cfg.runtime.rt.cpu); !why.empty())
    throw BadInput((cfg.source.empty() ? cfg.name : cfg.source) + ": realtime.cpu = " +
                   std::to_string(cfg.runtime.rt.cpu) + ": expected " + why);
  // The events log is opened by the telemetry consumer once the driver is up: a log_file that
  // cannot be written is refused now, before anything starts, not by the logger later.
  if (!cfg.log_file.empty())
    if (const std::string why = file_problem(cfg.log_file); !why.empty())
      throw BadInput((cfg.source.empty() ? cfg.name : cfg.source) + ": log_file = \"" + cfg.log_file + "\": " + why +
                     ": expected a file that can be written");

  // The report file is opened before anything starts: a path that cannot be written is refused
  // now, not discovered after a long run.
  std::ofstream report;
  if (!opt.report_json.empty()) {
    report.open(opt.report_json);
    if (!report) throw BadInput("--report-json " + opt.report_json + ": cannot open the file for writing");
  }
  if (!opt.plots_dir.empty())  // likewise the plots' folder: created and written to now
    if (const std::string why = folder_problem(opt.plots_dir); !why.empty())
      throw BadInput("--plots " + opt.plots_dir + ": " + why);
  if (!opt.observer_log.empty()) {
    if (!cfg.observer)
      throw BadInput("--observer-log " + opt.observer_log + ": " + (cfg.source.empty() ? cfg.name : cfg.source) +
                     " has observer: false: expected a configuration whose observer runs");
    if (const std::string why = file_problem(opt.observer_log); !why.empty())
      throw BadInput("--observer-log " + opt.observer_log + ": " + why + ": expected a file that can be written");
    if (!(opt.observer_log_seconds > 0) || opt.observer_log_seconds > 300)
      throw BadInput("--observer-log-seconds " + (std::ostringstream() << opt.observer_log_seconds).str() +
                     ": expected a time in (0, 300] s (the log is kept in memory: ≈ rate × seconds × "
                     "joints × 120 B)");
  }

  // The walking marker (run_marker.hpp): an earlier run's marker means it did not end in order;
  // this run then does not auto-start — it waits in READY for an operator's start command.
  std::unique_ptr<RunMarker> marker;
  runtime::RuntimeConfig rc = cfg.runtime;
  if (!opt.state_dir.empty()) {
    try {
      marker = std::make_unique<RunMarker>(opt.state_dir, cfg.source.empty() ? cfg.name : cfg.source);
    } catch (const std::runtime_error& e) {
      throw BadInput(e.what());
    }
    if (marker->found()) {
      res.previous_run_crashed = true;
      res.start_note =
          "*** the previous run did not end in order (" + marker->path().string() + ": " +
          marker->previous() + "): a crash, a kill or a power loss while walking. " +
          (rc.auto_start ? "auto_start is OFF for this run: " : "") +
          "the robot stays READY (torque off) until an operator starts it (DDS command start, "
          "e.g. pedalwave_monitor --command start); systemctl stop / restart ends this run in "
          "order and clears the marker";
      rc.auto_start = false;
      out << res.start_note << "\n";
    }
  }
  const OwnedDriver owned = opt.driver ? OwnedDriver{} : make_driver(cfg, cfg.duration);
  drivers::Driver* driver = opt.driver ? opt.driver : owned.top();
  auto* sim = dynamic_cast<drivers::SimDriver*>(opt.driver ? opt.driver : owned.base.get());
  GaitStage stage(cfg.controller);
  const std::unique_ptr<observer::RuntimeObserver> observer = make_observer(cfg, driver);
  // --observer-log: the observer's inputs of the run's last observer_log_seconds, recorded in
  // the cycle (allocated here) and written after it.
  std::unique_ptr<observer::InputLog> observer_log;
  std::unique_ptr<observer::RecordingObserver> recording_observer;
  if (observer && !opt.observer_log.empty()) {
    const double rate = cfg.runtime.rt.rate_hz;
    const double seconds = cfg.duration > 0 ? std::min(opt.observer_log_seconds, cfg.duration + 1.0)
                                            : opt.observer_log_seconds;
    observer_log = std::make_unique<observer::InputLog>(
        cfg.robot.N - 1, static_cast<std::size_t>(std::ceil(seconds * rate)) + 16);
    recording_observer = std::make_unique<observer::RecordingObserver>(*observer, *observer_log);
  }
  runtime::Observer* const stage_observer =
      recording_observer ? static_cast<runtime::Observer*>(recording_observer.get()) : observer.get();
  auto rt = std::make_unique<runtime::Runtime>(rc, *driver, stage, stage_observer);

  std::vector<runtime::TelemetrySink*> sinks;
  if (marker) sinks.push_back(marker.get());
  SampleRecorder recorder(std::max(1, static_cast<int>(std::lround(cfg.runtime.rt.rate_hz / 50.0))));
  if (!opt.plots_dir.empty()) sinks.push_back(&recorder);
#if PEDALWAVE_HAS_DDS
  std::unique_ptr<telemetry::DdsTelemetry> dds;
  std::unique_ptr<telemetry::RecordingThread> recording;  // telemetry.record (MCAP)
  std::string telemetry_line = "off";
  if (cfg.telemetry.enabled && opt.telemetry) {
    // Domain and discovery: --domain, then the file, then the ROS 2 environment, then defaults.
    telemetry::DomainRequest req;
    const std::uint32_t cli_domain = opt.domain.value_or(0);
    if (opt.domain) req.cli_domain = &cli_domain;
    if (cfg.telemetry.has_domain_id) req.config_domain = &cfg.telemetry.domain_id;
    if (cfg.telemetry.has_interface) req.config_interface = &cfg.telemetry.interface;
    req.config_localhost_only = cfg.telemetry.localhost_only;
    req.config_peers = cfg.telemetry.peers;
    telemetry::DomainChoice choice;
    try {
      choice = telemetry::resolve_domain(req, [](const char* v) { return std::getenv(v); });
    } catch (const std::invalid_argument& e) {
      throw BadInput(e.what());
    }
    telemetry::TelemetryConfig tc;
    tc.domain_id = choice.domain.domain_id;
    tc.interface = choice.domain.interface;
    tc.peers = choice.domain.peers;
    tc.robot_name = cfg.name;
    tc.ros_namespace = cfg.telemetry.ros_namespace;
    tc.stamp_clock = cfg.telemetry.realtime_stamps ? telemetry::StampClock::kRealtime
                                                   : telemetry::StampClock::kMonotonic;
    tc.standard_topics = cfg.telemetry.standard_topics;
    tc.decimation = {cfg.telemetry.decimation_state, cfg.telemetry.decimation_state,
                     cfg.telemetry.decimation_state, cfg.telemetry.decimation_timing};
    tc.enable_commands = cfg.telemetry.commands;
    tc.command_bounds.amplitude_max = cfg.telemetry.amplitude_max;
    tc.command_bounds.omega_max = cfg.telemetry.omega_max;
    tc.command_bounds.eta_min = cfg.telemetry.eta_min;
    tc.command_bounds.eta_max = cfg.telemetry.eta_max;
    // DDS Security: the file's security: section, then the ROS 2 environment (README "Securing
    // a robot"). A bad keystore is refused here, naming the file and what is wrong.
    telemetry::SecurityRequest sreq;
    sreq.config_present = cfg.security.present;
    sreq.config_enable = cfg.security.enable;
    sreq.config_keystore = cfg.security.keystore;
    sreq.config_enclave = cfg.security.enclave;
    sreq.config_strategy = cfg.security.strategy;
    sreq.default_enclave = "/pedalwave/" + telemetry::ros_namespace_for(cfg.name).substr(1);
    telemetry::SecurityChoice schoice;
    try {
      schoice = telemetry::resolve_security(sreq, [](const char* v) { return std::getenv(v); });
    } catch (const std::invalid_argument& e) {
      throw BadInput(e.what());
    }
    if (!schoice.warning.empty()) out << "WARNING: " << schoice.warning << "\n";
    tc.security = schoice.security;
    runtime::Runtime* rtp = rt.get();
    try {
      dds = std::make_unique<telemetry::DdsTelemetry>(
          tc, [rtp](const runtime::OperatorCommand& c) { return rtp->post(c); });
    } catch (const std::invalid_argument& e) {
      throw BadInput(e.what());
    } catch (const std::runtime_error& e) {
      if (tc.security.enabled) throw BadInput(e.what());
      throw;
    }
    sinks.push_back(dds.get());
    res.telemetry_active = true;
    telemetry_line = "DDS domain " + std::to_string(tc.domain_id) + " (" + choice.domain_source +
                     "), namespace " + tc.effective_namespace() + ", discovery " +
                     (tc.interface.empty() ? std::string("Cyclone's choice of interface")
                                           : "on " + tc.interface) +
                     " (" + choice.discovery_source + "), " +
                     telemetry::describe_security(tc.security) +
                     (tc.security.enabled ? " (" + schoice.source + ")" : "");
    if (!cfg.telemetry.record.empty() && tc.security.enabled)
      throw BadInput((cfg.source.empty() ? cfg.name : cfg.source) + ": telemetry.record = \"" +
                     cfg.telemetry.record + "\": the daemon's own recorder does not run with DDS "
                     "Security yet (its subscriber would need the robot's identity to read its own "
                     "topics); record with a monitor identity instead: pedalwave_monitor "
                     "--security-keystore … --record run.mcap");
    if (!cfg.telemetry.record.empty()) {
      // Every topic as published, through a subscriber of the daemon's own on its own thread.
      telemetry::SubscriberConfig sc;
      sc.domain_id = tc.domain_id;
      sc.interface = tc.interface;
      sc.peers = tc.peers;
      sc.robot = cfg.name;
      sc.ros_namespace = cfg.telemetry.ros_namespace;
      sc.standard_topics = tc.standard_topics;
      sc.sender = "pedalwave_runtime recorder";
      const std::string path = telemetry::expand_time(cfg.telemetry.record, static_cast<std::int64_t>(::time(nullptr)));
      try {
        recording = std::make_unique<telemetry::RecordingThread>(sc, path);
      } catch (const std::runtime_error& e) {
        throw BadInput((cfg.source.empty() ? cfg.name : cfg.source) + ": telemetry.record = \"" +
                       cfg.telemetry.record + "\": " + e.what());
      }
      telemetry_line += ", recording to " + path;
    }
  }
#else
  const std::string telemetry_line = "off";
#endif
  out << "pedalwave runtime '" << cfg.name << "': driver " << config::to_string(cfg.driver.kind)
      << (cfg.driver.kind == config::DriverKind::kSim ? " (scene " + cfg.driver.scene.name + ")" : "")
      << (owned.faults ? ", " + std::to_string(owned.faults->faults().size()) + " injected fault(s)" : "")
      << ", " << cfg.runtime.rt.rate_hz << " Hz, "
      << (cfg.duration > 0 ? std::to_string(cfg.duration) + " s" : std::string("until SIGINT/SIGTERM/SIGHUP/SIGQUIT"))
      << ", PD " << (cfg.controller.pd.placement == control::PdPlacement::kModule ? "module-side" : "host-side")
      << ", k_c = " << cfg.controller.admittance.k_c << ", observer "
      << (observer ? "on" : "off") << ", telemetry "
      << telemetry_line
      << "\n";
  out << "timeouts: " << cfg.timing_note << "\n" << std::flush;

  runtime::ConsumerConfig cc;
  cc.log_file = cfg.log_file;
  runtime::TelemetryConsumer consumer(*rt, sinks, cc);
  consumer.start();
  runtime::install_stop_signal_handlers();
  std::exception_ptr loop_error;  // run() throws only before the loop (require_rt refused)
  std::thread loop([&] {
    try {
      res.run = rt->run();
    } catch (...) {
      loop_error = std::current_exception();
      rt->request_stop();
    }
  });
  std::thread console;
  if (opt.operator_console) console = std::thread([&] { opt.operator_console(*rt); });
  loop.join();
  if (console.joinable()) console.join();
  res.summary = consumer.stop(&res.run);
#if PEDALWAVE_HAS_DDS
  if (recording) {  // everything published has reached it (locally): close the file
    const std::string err = recording->stop();
    out << "recording: " << recording->path() << ": " << recording->messages() << " messages on "
        << recording->topics() << " topics" << (err.empty() ? "" : ": *** " + err) << "\n";
  }
  dds.reset();
#endif
  if (loop_error) std::rethrow_exception(loop_error);  // not an orderly end: the marker stays

  // Every RunResult with a reason is an orderly end (the safe command was sent): clear the marker.
  if (marker) {
    res.marked_running = marker->marked();
    if (!marker->write_error().empty())
      out << "*** state: the walking marker could not be written: " << marker->write_error() << "\n";
    if (res.run.reason != runtime::ExitReason::kNone) {
      const std::string err = marker->clear();
      if (!err.empty()) out << "*** state: " << err << " (the next run will start in READY)\n";
    }
  }

  // Report: the summary (events, loop timing; the consumer logged it unless there is a log file),
  // the exit line, the JSON report, and (sim) what the robot did.
  res.exit_line = runtime::format_exit_line(res.run, consumer.events());
  res.event_log = consumer.events();
  res.events = res.event_log.events();
  out << (cfg.log_file.empty() ? res.exit_line : res.summary) << "\n";  // the summary ends with it
  // A CANopen bus names what its master saw (a lost node, a drive's EMCY): the runtime's fault
  // names the joint, this the drive and its error.
  if (const auto* co = dynamic_cast<const drivers::CanOpenDriver*>(driver); co != nullptr && co->fault_text()[0] != '\0')
    out << "driver: " << co->fault_text() << "\n";
  if (report.is_open()) {
    write_run_report(report, {.cfg = cfg, .run = res.run, .metrics = rt->metrics(),
                              .events = consumer.events(), .counters = driver->counters(),
                              .observer = observer != nullptr, .telemetry = res.telemetry_active});
    report.close();
    if (!report) throw std::runtime_error("--report-json " + opt.report_json + ": write failed");
    out << "report: " << opt.report_json << "\n";
  }
  if (!opt.plots_dir.empty())
    write_runtime_data(opt.plots_dir, recorder, res.event_log, res.events, observer_threshold(cfg), out);
  if (observer_log) {
    try {
      observer_log->write_csv(opt.observer_log, observer->core().params().feedback);
      out << "observer log: " << opt.observer_log << " (" << observer_log->size() << " of "
          << observer_log->recorded() << " cycles; pedalwave_runtime --config … --replay-observer "
          << opt.observer_log << ")\n";
    } catch (const std::exception& e) {  // the run is over: say it loudly, lose nothing else
      std::cerr << "pedalwave_runtime: --observer-log " << opt.observer_log << ": " << e.what() << "\n";
    }
  }
  if (sim) {
    sim->stop();
    const drivers::SimRecording& rec = sim->recording();
    const model::Model& m = sim->sim().plant().model();
    model::Data data(m);
    res.plant_status = sim->plant_status();
    if (res.plant_status == model::StepStatus::kOk && res.run.fault == runtime::FaultClass::kImplausible) {
      try {
        const double duration = cfg.duration > 0 ? cfg.duration : cfg.driver.scene.duration;
        res.plant_unstable = model::check(cfg.driver.scene, plant_gains(cfg.controller.pd),
                                          cfg.driver.scene.integrator, duration)
                                 .level == model::CheckLevel::kError;
      } catch (const std::exception&) {  // no prediction: the fault stands as the runtime saw it
      }
    }
    if (res.plant_failed()) {
      // The plant went numerically wrong: the fault the runtime saw is the simulation's, its
      // states before the failure are already wrong (no speed from them), and the step to use is
      // what pedalwave_sim says after such a run.
      res.plant_t = sim->sim().t();
      res.plant_advice = simloop::stability_advice(cfg.driver.scene, plant_gains(cfg.controller.pd),
                                                   cfg.driver.scene.integrator,
                                                   cfg.duration > 0 ? cfg.duration : cfg.driver.scene.duration);
      std::ostringstream os;
      os << "plant: "
         << (res.plant_unstable ? std::string("diverging (its step is beyond the stability limit; the "
                                              "implausible measurements are the integrator's)")
                                : std::string(model::to_string(res.plant_status)))
         << " at t = " << res.plant_t
         << " s of simulated plant: the simulation went numerically wrong (no speed); stability: "
         << res.plant_advice << "\n";
      out << os.str();
    } else if (rec.count > 2) {
      const auto nq = static_cast<std::size_t>(rec.nq);
      std::size_t i0 = 0;
      while (i0 + 1 < rec.count && rec.t[i0] < 2.0) ++i0;
      const std::size_t i1 = rec.count - 1;
      res.sim_time = rec.t[i1];
      if (rec.t[i1] > rec.t[i0])
        res.forward_speed = (com_x(m, data, &rec.q[i1 * nq]) - com_x(m, data, &rec.q[i0 * nq])) /
                            (rec.t[i1] - rec.t[i0]);
      char line[160];
      std::snprintf(line, sizeof line,
                    "forward speed: %.3f cm/s (COM, t = %.1f … %.1f s of simulated plant; the paper's "
                    "simulation: 2.18 cm/s, experiment 2.40 cm/s on μ = 0.82)\n",
                    100 * res.forward_speed, rec.t[i0], rec.t[i1]);
      out << line;
    }
    if (!opt.plots_dir.empty()) write_plant_data(opt.plots_dir, *sim, cfg);
  }
  if (!opt.plots_dir.empty()) draw_run_figures(opt.plots_dir, out);
  return res;
}

namespace {

// A joint's status bits, short ("ok" when none).
std::string status_text(std::uint16_t st) {
  static constexpr std::pair<std::uint16_t, const char*> kBits[] = {
      {drivers::kStatusMissing, "missing"}, {drivers::kStatusStale, "stale"},
      {drivers::kStatusOutOfOrder, "out_of_order"}, {drivers::kStatusChecksum, "checksum"},
      {drivers::kStatusSaturated, "saturated"}, {drivers::kStatusOverTemp, "over_temp"},
      {drivers::kStatusEncoderFault, "encoder_fault"}, {drivers::kStatusBusError, "bus_error"},
      {drivers::kStatusTorqueOff, "torque_off"}, {drivers::kStatusLate, "late"},
      {drivers::kStatusNoTiming, "no_timing"}, {drivers::kStatusStaleFeedback, "stale_feedback"}};
  std::string s;
  for (const auto& [bit, name] : kBits)
    if (st & bit) s += (s.empty() ? "" : "+") + std::string(name);
  return s.empty() ? "ok" : s;
}

// "<class> joint j at t = … s (cycle i)" of a verdict in the log.
std::string fault_text(const observer::InputLog& log, std::size_t at, runtime::FaultClass f, int joint) {
  if (at == SIZE_MAX) return "no fault";
  char buf[160];
  std::snprintf(buf, sizeof buf, "%s%s at t = %.3f s (cycle %llu of the run)", runtime::to_string(f),
                joint >= 0 ? (" joint " + std::to_string(joint + 1)).c_str() : "", log.cycle(at).t,
                static_cast<unsigned long long>(log.cycle(at).cycle));
  return buf;
}

}  // namespace

int replay_observer(const config::DaemonConfig& cfg, const std::string& log_path, std::ostream& out) {
  drivers::FeedbackSpec spec;
  observer::InputLog log(1, 1);
  try {
    log = observer::InputLog::read_csv(log_path, &spec);
  } catch (const std::exception& e) {
    throw BadInput("--replay-observer: " + std::string(e.what()));
  }
  if (log.joints() != cfg.robot.N - 1)
    throw BadInput("--replay-observer " + log_path + ": " + std::to_string(log.joints()) + " joints, but " +
                   (cfg.source.empty() ? cfg.name : cfg.source) + " has " + std::to_string(cfg.robot.N - 1) +
                   ": expected the configuration the log was recorded with");
  observer::RuntimeObserver obs(observer_params(cfg, spec));
  const observer::ReplayResult r = observer::replay(log, obs);
  const std::size_t n = r.cycles;
  char line[256];
  std::snprintf(line, sizeof line, "replay: %zu cycles (t = %.3f … %.3f s, cycles %llu … %llu of the run), %d joints, observer of %s\n",
                n, log.cycle(0).t, log.cycle(n - 1).t, static_cast<unsigned long long>(log.cycle(0).cycle),
                static_cast<unsigned long long>(log.cycle(n - 1).cycle), log.joints(),
                (cfg.source.empty() ? cfg.name : cfg.source).c_str());
  out << line;
  if (log.cycle(0).cycle != 0)
    out << "  (the log starts mid-run: the replayed observer starts fresh there, its first seconds are not the live ones)\n";
  out << "live:   " << fault_text(log, r.live_fault_at, r.live_fault, r.live_joint) << "\n";
  out << "replay: " << fault_text(log, r.replay_fault_at, r.replay_fault, r.replay_joint);
  if (r.replay_fault_at != SIZE_MAX) {
    std::snprintf(line, sizeof line, ", evidence %.4g against %.4g", r.replay_value, r.replay_threshold);
    out << line;
  }
  std::snprintf(line, sizeof line, "\nresiduals: max |replay - live| = %.3g N·m; verdicts differ in %zu of %zu cycles\n",
                r.max_residual_difference, r.verdicts_differing, n);
  out << line;
  // The cycles before the replayed fault, at its joint: what the observer was given.
  if (r.replay_fault_at != SIZE_MAX && r.replay_joint >= 0) {
    const int j = r.replay_joint;
    const std::size_t last = r.replay_fault_at, first = last >= 40 ? last - 40 : 0;
    out << "the 40 cycles before it, joint " << j + 1
        << " (sample age = the cycle's stamp − the joint's sample time; applied = cycles between the command it "
           "applied and the newest):\n";
    out << "       t [s]   dt [ms]  sample age [ms]  applied  residual [N·m]  status\n";
    const auto J = static_cast<std::size_t>(log.joints());
    for (std::size_t i = first; i <= last; ++i) {
      const observer::InputLog::Cycle& c = log.cycle(i);
      const observer::InputLog::Joint& x = log.joint(i, j);
      const double age = x.sample_ns != 0 ? 1e-6 * static_cast<double>(c.stamp_ns - x.sample_ns) : NAN;
      const long long applied = x.applied_seq >= drivers::kUnknownSeq
                                    ? -1
                                    : static_cast<long long>(c.cmd_seq) - static_cast<long long>(x.applied_seq);
      std::snprintf(line, sizeof line, "  %10.3f  %8.2f  %15.2f  %7lld  %14.5f  %s\n", c.t, 1e3 * c.dt, age, applied,
                    r.residual[i * J + static_cast<std::size_t>(j)], status_text(x.fb.status).c_str());
      out << line;
    }
  }
  return r.replay_fault_at != SIZE_MAX ? kExitFault : kExitNormal;
}

}  // namespace pedalwave::app
