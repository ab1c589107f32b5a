#include "pedalwave/config/daemon.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/drivers/bus_budget.hpp"

namespace pedalwave::config {

const char* to_string(DriverKind k) {
  switch (k) {
    case DriverKind::kSim: return "sim";
    case DriverKind::kSocketCan: return "socketcan";
    case DriverKind::kSerial: return "serial";
  }
  return "?";
}

namespace {

// Wraps a component's own validation (std::invalid_argument) into a ConfigError naming the file
// and the section.
template <class F>
void checked(const Reader& r, const std::string& section, F&& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    throw ConfigError(r.file() + ": " + section + ": " + e.what());
  }
}

template <std::size_t N>
void copy_name(std::array<char, N>& dst, const std::string& s) {
  dst.fill('\0');
  std::memcpy(dst.data(), s.data(), std::min(s.size(), N - 1));
}

void read_controller(const Reader& r, DaemonConfig& c) {
  r.allow_only({"k_c", "pd_placement", "K_p", "K_D", "tau_max", "tau_rate_max", "gait",
                "M_d", "D_d", "K_d", "eta_min", "eta_max"});
  control::GaitControllerParams& p = c.controller;
  p.admittance.k_c = r.number("k_c", 0.0);
  p.admittance.M_d = r.positive("M_d", p.admittance.M_d);
  p.admittance.D_d = r.positive("D_d", p.admittance.D_d);
  p.admittance.K_d = r.positive("K_d", p.admittance.K_d);
  p.admittance.eta_min = r.number("eta_min", p.admittance.eta_min);
  p.admittance.eta_max = r.number("eta_max", p.admittance.eta_max);
  p.pd.placement = r.choice("pd_placement", "module", {"module", "host"}) == "host"
                       ? control::PdPlacement::kHost
                       : control::PdPlacement::kModule;
  if (r.has("K_p")) p.pd.K_p = r.numbers("K_p");
  if (r.has("K_D")) p.pd.K_D = r.numbers("K_D");
  if (r.has("tau_max")) p.limits.tau_max = r.numbers("tau_max");
  if (r.has("tau_rate_max")) p.limits.tau_rate_max = r.numbers("tau_rate_max");
  if (r.has("gait")) {
    const model::GaitParams g = read_gait(r["gait"]);
    p.gait.A_p = g.A_p;
    p.gait.omega = g.omega;
    p.admittance.Pi_n = {g.eta};
  }
}

void read_driver(const Reader& r, const std::string& base_dir, DaemonConfig& c) {
  r.allow_only({"type", "scene", "clock", "command_timeout", "ifname", "fd", "bitrate",
                "data_bitrate", "max_load", "device", "baud", "return_delay", "turnaround"});
  DriverSelection& d = c.driver;
  const std::string type = r.choice("type", "sim", {"sim", "socketcan", "serial"});
  d.kind = type == "socketcan" ? DriverKind::kSocketCan
           : type == "serial"  ? DriverKind::kSerial
                               : DriverKind::kSim;
  const double period = 1.0 / c.runtime.rt.rate_hz;
  const int joints = c.robot.N - 1;
  if (d.kind == DriverKind::kSim) {
    if (!r.has("scene")) r.fail_key("scene", "the scene file the simulated plant runs (driver.type: sim)");
    std::filesystem::path p = r.string("scene", "");
    if (p.is_relative()) p = std::filesystem::path(base_dir) / p;
    d.scene_path = p.lexically_normal().string();
    try {
      d.scene = load_scene(d.scene_path);
    } catch (const ConfigError& e) {
      throw ConfigError(r.file() + ": driver.scene: " + e.what());
    }
    d.sim.clock = r.choice("clock", "lockstep", {"lockstep", "free_running"}) == "free_running"
                      ? drivers::SimClock::kFreeRunning
                      : drivers::SimClock::kLockstep;
    d.sim.period = period;
    d.sim.command_timeout = r.positive("command_timeout", 0.05);
    c.robot = d.scene.robot;  // the controller is tuned for the simulated robot
  } else if (d.kind == DriverKind::kSocketCan) {
    d.can.ifname = r.string("ifname", "can0");
    d.can.joints = joints;
    d.can.fd = r.boolean("fd", false);
    d.can.bitrate = r.positive("bitrate", 1e6);
    d.can.data_bitrate = r.positive("data_bitrate", 5e6);
    d.can.max_load = r.positive("max_load", 0.8);
    d.can.period_s = period;
    checked(r, "driver", [&] {
      drivers::check_can_bus_budget({d.can.joints, d.can.period_s, d.can.bitrate, d.can.fd,
                                     d.can.data_bitrate, d.can.max_load});
    });
  } else {
    d.serial.device = r.string("device", "/dev/ttyUSB0");
    d.serial.baud = static_cast<int>(r.integer("baud", 4'000'000, 9600, 4'000'000));
    d.serial.joints = joints;
    d.serial.return_delay_s = r.non_negative("return_delay", 20e-6);
    d.serial.turnaround_s = r.non_negative("turnaround", 0.0);
    d.serial.max_load = r.positive("max_load", 0.8);
    d.serial.period_s = period;
    checked(r, "driver", [&] {
      drivers::check_serial_bus_budget({d.serial.joints, d.serial.period_s, d.serial.baud,
                                        d.serial.return_delay_s, d.serial.turnaround_s, d.serial.max_load});
    });
  }
}

void read_realtime(const Reader& r, DaemonConfig& c) {
  r.allow_only({"priority", "cpu", "lock_memory", "prefault_stack", "require", "clock",
                "read_budget", "stale_timeout", "overrun_fault_after", "auto_start"});
  runtime::RuntimeConfig& rc = c.runtime;
  rc.rt.priority = static_cast<int>(r.integer("priority", 0, 0, 99));
  rc.rt.cpu = static_cast<int>(r.integer("cpu", -1, -1, 1023));
  rc.rt.lock_memory = r.boolean("lock_memory", false);
  rc.rt.prefault_stack_bytes = static_cast<std::size_t>(r.integer("prefault_stack", 256 * 1024, 0, 4 << 20));
  rc.rt.require_rt = r.boolean("require", false);
  rc.clock = r.choice("clock", "realtime", {"realtime", "lockstep"}) == "lockstep"
                 ? runtime::ClockMode::kLockstep
                 : runtime::ClockMode::kRealtime;
  rc.read_budget = r.positive("read_budget", rc.read_budget);
  rc.stale_timeout = r.positive("stale_timeout", rc.stale_timeout);
  rc.overrun_fault_after = static_cast<std::uint32_t>(r.integer("overrun_fault_after", 0, 0, 1 << 30));
  rc.auto_start = r.boolean("auto_start", true);
}

void read_telemetry(const Reader& r, DaemonConfig& c) {
  r.allow_only({"enabled", "domain_id", "interface", "peers", "decimation_state",
                "decimation_timing", "commands", "amplitude_max", "omega_max", "eta_min", "eta_max"});
  TelemetrySection& t = c.telemetry;
  t.enabled = r.boolean("enabled", true);
  t.domain_id = static_cast<std::uint32_t>(r.integer("domain_id", 0, 0, 232));
  t.interface = r.string("interface", "lo");
  if (r.has("peers")) {
    const Reader p = r["peers"];
    if (!p.is_sequence()) p.fail("a list of addresses");
    for (std::size_t i = 0; i < p.size(); ++i) t.peers.push_back(p.at(i).as_string());
  }
  t.decimation_state = static_cast<int>(r.integer("decimation_state", 10, 1, 100000));
  t.decimation_timing = static_cast<int>(r.integer("decimation_timing", 10, 1, 100000));
  t.commands = r.boolean("commands", true);
  t.amplitude_max = r.positive("amplitude_max", t.amplitude_max);
  t.omega_max = r.positive("omega_max", t.omega_max);
  t.eta_min = r.number("eta_min", t.eta_min);
  t.eta_max = r.number("eta_max", t.eta_max);
}

// Timeouts from the rate and the bus unless the file gives them (README "Timeouts"):
//   read deadline  = wake + read_budget · period, read_budget ≥ the bus's reply window (derived:
//                    1.25 · window + 0.2 ms, within [0.5, 0.9] of the period);
//   stale_timeout  = max(0.25 s, 50 periods): above a loaded host's worst stall (the soak tool
//                    measured a 99 ms wake-up of the SCHED_FIFO loop on a shared 2-core machine),
//                    far below a walking robot's time to harm itself (its modules hold their PD);
//   module silent  = a bus: 0.2 s of missing replies in a row, by time (a late reply is
//                    a missing one), and at least 3 requests unanswered (one request left
//                    unanswered across a host stall is the host's silence); the in-process
//                    plant: 3 (it never drops a reply).
void derive_timeouts(const Reader& r, DaemonConfig& c) {
  runtime::RuntimeConfig& rc = c.runtime;
  const double period = 1.0 / rc.rt.rate_hz;
  const bool have_rt = r.has("realtime");
  const bool given_budget = have_rt && r["realtime"].has("read_budget");
  const bool given_stale = have_rt && r["realtime"].has("stale_timeout");
  double window = 0.0;
  const DriverSelection& d = c.driver;
  if (d.kind == DriverKind::kSocketCan)
    window = drivers::can_reply_window_s({d.can.joints, period, d.can.bitrate, d.can.fd,
                                          d.can.data_bitrate, d.can.max_load});
  else if (d.kind == DriverKind::kSerial)
    window = drivers::serial_reply_window_s({d.serial.joints, period, d.serial.baud,
                                             d.serial.return_delay_s, d.serial.turnaround_s,
                                             d.serial.max_load});
  char buf[256];
  std::string note;
  if (given_budget) {
    if (rc.read_budget * period < window) {
      std::snprintf(buf, sizeof buf,
                    "a fraction of the period that leaves the bus's replies their %.0f µs (≥ %.3f "
                    "at %g Hz)", window * 1e6, window / period, rc.rt.rate_hz);
      r["realtime"]["read_budget"].fail(buf);
    }
    std::snprintf(buf, sizeof buf, "read deadline %.2f of the period (given)", rc.read_budget);
  } else if (window > 0) {
    rc.read_budget = std::clamp((1.25 * window + 2e-4) / period, 0.5, 0.9);
    std::snprintf(buf, sizeof buf, "read deadline %.2f of the period (derived: the replies need %.0f µs)",
                  rc.read_budget, window * 1e6);
  } else {
    std::snprintf(buf, sizeof buf, "read deadline %.2f of the period", rc.read_budget);
  }
  note += buf;
  if (!given_stale) rc.stale_timeout = std::max(0.25, 50.0 * period);
  std::snprintf(buf, sizeof buf, ", stale_timeout %g s (%s)", rc.stale_timeout,
                given_stale ? "given" : "derived: max(0.25 s, 50 periods)");
  note += buf;
  c.observer_missing_cycles = 3;
  c.observer_missing_time = d.kind == DriverKind::kSim ? 0.0 : 0.2;
  if (c.observer_missing_time > 0)
    std::snprintf(buf, sizeof buf, ", module silent after %g s of missing replies (at least %d)",
                  c.observer_missing_time, c.observer_missing_cycles);
  else
    std::snprintf(buf, sizeof buf, ", module silent after %d missing replies", c.observer_missing_cycles);
  note += buf;
  if (window > 0) {
    std::snprintf(buf, sizeof buf, "; the modules' command lifetime should exceed %g s",
                  rc.stale_timeout);
    note += buf;
  }
  c.timing_note = note;
}

}  // namespace

DaemonConfig parse_daemon_config(const std::string& text, const std::string& name,
                                 const std::string& base_dir) {
  const Reader r = Reader::parse(text, name);
  r.allow_only({"name", "description", "rate_hz", "duration", "robot", "driver", "controller",
                "realtime", "observer", "telemetry", "log_file"});
  DaemonConfig c;
  c.source = name;
  c.name = r.string("name", "pedalwave");
  c.duration = r.non_negative("duration", 0.0);
  c.runtime.rt.rate_hz = r.positive("rate_hz", 1000.0);
  if (c.runtime.rt.rate_hz > runtime::kMaxRateHz) r["rate_hz"].fail("a rate in (0, 20000] Hz");
  if (r.has("robot")) c.robot = read_robot(r["robot"]);
  if (r.has("realtime")) read_realtime(r["realtime"], c);
  else c.runtime.auto_start = true;
  if (!r.has("driver")) r.fail_key("driver", "a driver section (type: sim | socketcan | serial)");
  read_driver(r["driver"], base_dir, c);
  // Controller: matched to the robot (K, n² I_r), at the loop rate.
  control::GaitControllerParams& p = c.controller;
  p.joints = c.robot.N - 1;
  p.period = 1.0 / c.runtime.rt.rate_hz;
  p.actuator.K.clear();
  for (int j = 0; j < p.joints; ++j)
    p.actuator.K.push_back(c.robot.joints == model::JointModel::kFlexible ? c.robot.stiffness(j) : 1e6);
  p.actuator.reflected_inertia = {std::max(c.robot.n * c.robot.n * c.robot.I_r, 1e-12)};
  if (c.driver.kind == DriverKind::kSim) {
    p.gait.A_p = c.driver.scene.gait.A_p;
    p.gait.omega = c.driver.scene.gait.omega;
    p.admittance.Pi_n = {c.driver.scene.gait.eta};
  }
  if (r.has("controller")) read_controller(r["controller"], c);
  checked(r, "controller", [&] { control::GaitController probe(p); });
  if (r.has("observer")) {
    const Reader o = r["observer"];
    o.allow_only({"enabled"});
    c.observer = o.boolean("enabled", true);
  }
  if (r.has("telemetry")) read_telemetry(r["telemetry"], c);
  c.log_file = r.string("log_file", "");
  derive_timeouts(r, c);
  // The loop.
  runtime::RuntimeConfig& rc = c.runtime;
  if (c.duration > 0) rc.max_cycles = static_cast<std::uint64_t>(std::llround(c.duration * rc.rt.rate_hz));
  runtime::RobotDescription& d = rc.description;
  d.links = c.robot.N;
  d.link_length = 2 * c.robot.l;
  d.link_mass = c.robot.m_l;
  d.rotor_mass = c.robot.m_r;
  d.rotor_inertia = c.robot.I_r;
  d.gear_ratio = c.robot.n;
  for (int j = 0; j < c.robot.N - 1; ++j) d.spring_stiffness[static_cast<std::size_t>(j)] = c.robot.stiffness(j);
  d.rate_hz = rc.rt.rate_hz;
  copy_name(d.name, c.name);
  copy_name(d.driver, to_string(c.driver.kind));
  checked(r, "realtime", [&] { runtime::validate(rc); });
  return c;
}

DaemonConfig load_daemon_config(const std::string& path) {
  const Reader r = Reader::load_file(path);  // for the I/O error message
  (void)r;
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_daemon_config(ss.str(), path, std::filesystem::path(path).parent_path().string());
}

}  // namespace pedalwave::config
