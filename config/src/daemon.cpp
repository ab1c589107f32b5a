#include "pedalwave/config/daemon.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/canopen_driver.hpp"
#include "pedalwave/drivers/serial_driver.hpp"

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

// lo <= hi for a pair of keys of one section, either of them possibly its default: the one given
// is refused (lo_key when both are), at its line; the components would refuse it later, lineless.
void check_order(const Reader& r, const char* lo_key, double lo, const char* hi_key, double hi) {
  if (lo <= hi) return;
  std::ostringstream os;
  if (r.has(lo_key)) {
    os << "a number <= " << r.path() << "." << hi_key << " = " << hi;
    r[lo_key].fail(os.str());
  }
  os << "a number >= " << r.path() << "." << lo_key << " = " << lo;
  r[hi_key].fail(os.str());
}

void read_controller(const Reader& r, DaemonConfig& c) {
  r.allow_only({"k_c", "pd_placement", "K_p", "K_D", "tau_max", "tau_rate_max", "gait",
                "M_d", "D_d", "K_d", "eta_min", "eta_max"});
  control::GaitControllerParams& p = c.controller;
  p.admittance.k_c = r.bounded("k_c", 0.0, -1e3, 1e3, "-");
  p.admittance.M_d = r.bounded("M_d", p.admittance.M_d, 0, 1e6, "N·m·s²/rad", true);
  p.admittance.D_d = r.bounded("D_d", p.admittance.D_d, 0, 1e6, "N·m·s/rad", true);
  p.admittance.K_d = r.bounded("K_d", p.admittance.K_d, 0, 1e6, "N·m/rad", true);
  p.admittance.eta_min = r.bounded("eta_min", p.admittance.eta_min, -2 * M_PI, 2 * M_PI, "rad");
  p.admittance.eta_max = r.bounded("eta_max", p.admittance.eta_max, -2 * M_PI, 2 * M_PI, "rad");
  check_order(r, "eta_min", p.admittance.eta_min, "eta_max", p.admittance.eta_max);
  p.pd.placement = r.choice("pd_placement", "module", {"module", "host"}) == "host"
                       ? control::PdPlacement::kHost
                       : control::PdPlacement::kModule;
  if (r.has("K_p")) p.pd.K_p = r.bounded_numbers("K_p", 0, 1e6, "N·m/rad");
  if (r.has("K_D")) p.pd.K_D = r.bounded_numbers("K_D", 0, 1e6, "N·m·s/rad");
  if (r.has("tau_max")) p.limits.tau_max = r.bounded_numbers("tau_max", 0, 1e4, "N·m", true);
  if (r.has("tau_rate_max")) p.limits.tau_rate_max = r.bounded_numbers("tau_rate_max", 0, 1e9, "N·m/s", true);
  if (r.has("gait")) {
    // A_p ≥ 0: the controller refuses a negative amplitude, later and without a line.
    const model::GaitParams g = read_gait(r["gait"], 0.0);
    p.gait.A_p = g.A_p;
    p.gait.omega = g.omega;
    p.admittance.eta_n = {g.eta};
  }
}

// Which driver types each key of `driver:` belongs to (README "driver", its type column). A key
// of another type is refused, not ignored: `{type: sim, baud: 1}` is a file that says two things.
struct DriverKey {
  const char* key;
  const char* owner;  // for the message: "the serial driver's", "the socketcan and serial drivers'"
  bool sim, socketcan, serial;
};
constexpr DriverKey kDriverKeys[] = {
    {"scene", "the sim driver's", true, false, false},
    {"clock", "the sim driver's", true, false, false},
    {"command_timeout", "the sim and serial drivers'", true, false, true},
    {"ifname", "the socketcan driver's", false, true, false},
    {"fd", "the socketcan driver's", false, true, false},
    {"bitrate", "the socketcan driver's", false, true, false},
    {"data_bitrate", "the socketcan driver's", false, true, false},
    {"max_load", "the socketcan and serial drivers'", false, true, true},
    {"protocol", "the socketcan driver's", false, true, false},
    {"nodes", "the socketcan driver's", false, true, false},              // protocol: canopen only
    {"drive_mode", "the socketcan driver's", false, true, false},         // protocol: canopen only
    {"heartbeat", "the socketcan driver's", false, true, false},          // protocol: canopen only
    {"heartbeat_timeout", "the socketcan driver's", false, true, false},  // protocol: canopen only
    {"sync_window", "the socketcan driver's", false, true, false},        // protocol: canopen only
    {"device", "the serial driver's", false, false, true},
    {"baud", "the serial driver's", false, false, true},
    {"return_delay", "the serial driver's", false, false, true},
    {"turnaround", "the serial driver's", false, false, true},
    {"devices", "the serial driver's", false, false, true},
    {"torque_constant", "the serial driver's", false, false, true},     // devices: x_series only
    {"sensor_id_offset", "the serial driver's", false, false, true},    // devices: x_series only
    {"set_operating_mode", "the serial driver's", false, false, true},  // devices: x_series only
    {"max_stale_cycles", "the serial driver's", false, false, true},    // devices: x_series only
};

// `type` and every key above: what `driver:` may hold.
constexpr auto kDriverSectionKeys = [] {
  std::array<const char*, std::size(kDriverKeys) + 1> a{"type"};
  for (std::size_t i = 0; i < std::size(kDriverKeys); ++i) a[i + 1] = kDriverKeys[i].key;
  return a;
}();

void read_driver(const Reader& r, const std::string& base_dir, DaemonConfig& c) {
  r.allow_only(kDriverSectionKeys);
  DriverSelection& d = c.driver;
  const std::string type = r.choice("type", "sim", {"sim", "socketcan", "serial"});
  d.kind = type == "socketcan" ? DriverKind::kSocketCan
           : type == "serial"  ? DriverKind::kSerial
                               : DriverKind::kSim;
  for (const DriverKey& k : kDriverKeys) {
    const bool applies = d.kind == DriverKind::kSim         ? k.sim
                         : d.kind == DriverKind::kSocketCan ? k.socketcan
                                                            : k.serial;
    if (!applies && r.has(k.key))
      r[k.key].fail(std::string("no ") + k.key + " with type: " + type + " (" + k.key + " is " + k.owner +
                    (r.has("type") ? "" : "; type: sim is the default") + ")");
  }
  const double period = 1.0 / c.runtime.rt.rate_hz;
  const int joints = c.robot.N - 1;
  if (d.kind == DriverKind::kSim) {
    const Reader scene = r.required("scene", "the scene file the simulated plant runs (driver.type: sim)");
    std::filesystem::path p = scene.as_string();
    if (p.is_relative()) p = std::filesystem::path(base_dir) / p;
    d.scene_path = p.lexically_normal().string();
    // A scene that is not there is this key's error (what is wrong inside one is the scene's).
    if (std::error_code ec; !std::filesystem::exists(d.scene_path, ec))
      scene.fail("an existing scene file (there is no " + d.scene_path + "; a relative path starts at this file's folder)");
    try {
      d.scene = load_scene(d.scene_path);
    } catch (const ConfigError& e) {
      throw ConfigError(r.file() + ": driver.scene: " + e.what());
    }
    d.sim.clock = r.choice("clock", "lockstep", {"lockstep", "free_running"}) == "free_running"
                      ? drivers::SimClock::kFreeRunning
                      : drivers::SimClock::kLockstep;
    d.sim.period = period;
    d.sim.command_timeout = r.bounded("command_timeout", 0.05, 0, 10, "s", true);
    c.robot = d.scene.robot;  // the controller is tuned for the simulated robot
  } else if (d.kind == DriverKind::kSocketCan) {
    d.can.ifname = r.string("ifname", "can0");
    if (d.can.ifname.empty() || d.can.ifname.size() > 15 ||
        d.can.ifname.find_first_of("/ \t") != std::string::npos)
      r["ifname"].fail("a network interface name (1 … 15 characters, no '/' or blanks)");
    d.can.joints = joints;
    d.can.fd = r.boolean("fd", false);
    d.can.bitrate = r.bounded("bitrate", 1e6, 0, 1e6, "bit/s", true);
    d.can.data_bitrate = r.bounded("data_bitrate", 5e6, 0, 1.2e7, "bit/s", true);
    if (!d.can.fd && r.has("data_bitrate"))  // only an FD bus has a data phase: not ignored
      r["data_bitrate"].fail("no data_bitrate without fd: true (the data phase is CAN FD's)");
    d.can.max_load = r.bounded("max_load", 0.8, 0, 1, "-", true);
    d.can.period_s = period;
    // What the bus speaks: the pedalwave modules' protocol, or CANopen drives (CiA 301/402,
    // drivers/PROTOCOL.md §7).
    const bool canopen = r.choice("protocol", "pedalwave", {"pedalwave", "canopen"}) == "canopen";
    d.can.protocol = canopen ? drivers::CanProtocol::kCanOpen : drivers::CanProtocol::kPedalwave;
    for (const char* key : {"nodes", "drive_mode", "heartbeat", "heartbeat_timeout", "sync_window"})
      if (!canopen && r.has(key))
        r[key].fail(std::string("no ") + key + " without protocol: canopen (" + key + " is the CANopen master's)");
    if (canopen) {
      if (d.can.fd) r["fd"].fail("fd: false with protocol: canopen (the CANopen master sends classic frames)");
      drivers::CanOpenOptions& o = d.can.canopen;
      if (r.has("nodes")) {
        const Reader n = r["nodes"];
        const std::string what = "a list of " + std::to_string(joints) +
                                 " distinct CANopen node ids in 1 … 127, one per joint (robot.N − 1)";
        if (!n.is_sequence() || static_cast<int>(n.size()) != joints) n.fail(what);
        std::array<bool, 128> used{};
        for (std::size_t i = 0; i < n.size(); ++i) {
          const Reader e = n.at(i);
          if (!e.is_scalar()) e.fail("a node id, an integer in 1 … 127");
          const double v = e.as_number();
          if (!(v >= 1 && v <= 127) || v != std::floor(v)) e.fail("a node id, an integer in 1 … 127");
          if (used[static_cast<std::size_t>(v)]) e.fail("a node id not given to another joint");
          used[static_cast<std::size_t>(v)] = true;
          o.node[i] = static_cast<std::uint8_t>(v);
        }
      }
      o.mode = r.choice("drive_mode", "cst", {"cst", "csp"}) == "csp" ? drivers::CanOpenMode::kCsp
                                                                      : drivers::CanOpenMode::kCst;
      // 1017h holds whole milliseconds (1 … 65535).
      o.heartbeat_s = r.bounded("heartbeat", 0.05, 0.001, 65.535, "s");
      o.heartbeat_timeout_s = r.bounded("heartbeat_timeout", 3 * o.heartbeat_s, 0, 100, "s", true);
      // 1007h: the drives' synchronous window as a share of the SYNC period; 0 = none.
      o.sync_window = r.bounded("sync_window", 0.9, 0, 0.95, "of the SYNC period");
      if (!(o.heartbeat_timeout_s > o.heartbeat_s)) {
        std::ostringstream os;
        os << "a number > driver.heartbeat = " << o.heartbeat_s << " (the consumer waits longer than the producer's period)";
        r[r.has("heartbeat_timeout") ? "heartbeat_timeout" : "heartbeat"].fail(os.str());
      }
    }
    checked(r, "driver", [&] { drivers::check_can_bus_budget(drivers::can_bus_spec(d.can)); });
  } else {
    d.serial.device = r.string("device", "/dev/ttyUSB0");
    // Absolute: a relative one would be opened from wherever the daemon was started.
    if (d.serial.device.empty() || d.serial.device[0] != '/')
      r["device"].fail("an absolute device path (e.g. /dev/ttyUSB0)");
    // Only the rates the port opens at: 3500000 would load and fail at start.
    if (r.has("baud")) {
      const Reader b = r["baud"];
      const std::string rates = "one of the standard rates " + drivers::serial_bauds_text() + " [bit/s]";
      if (!b.is_scalar()) b.fail(rates);
      const double v = b.as_number();
      if (std::find(drivers::kSerialBauds.begin(), drivers::kSerialBauds.end(), v) == drivers::kSerialBauds.end())
        b.fail(rates);
      d.serial.baud = static_cast<int>(v);
    } else {
      d.serial.baud = 4'000'000;
    }
    d.serial.joints = joints;
    // What sits on the bus: pedalwave modules, or stock X-series servos in current control with a
    // deflection sensor each (drivers/PROTOCOL.md §3.6).
    const bool x = r.choice("devices", "pedalwave", {"pedalwave", "x_series"}) == "x_series";
    d.serial.devices = x ? drivers::SerialDevices::kXSeries : drivers::SerialDevices::kPedalwave;
    for (const char* key : {"torque_constant", "sensor_id_offset", "set_operating_mode", "max_stale_cycles"})
      if (!x && r.has(key))
        r[key].fail(std::string("no ") + key + " without devices: x_series (" + key +
                    " is the stock X-series servos')");
    d.serial.return_delay_s = r.bounded("return_delay", 20e-6, 0, 0.1, "s");
    d.serial.turnaround_s = r.bounded("turnaround", 0.0, 0, 0.1, "s");
    // X-series: the servos' Bus Watchdog (98), 1 … 127 × 20 ms.
    d.serial.command_timeout_s =
        x ? r.bounded("command_timeout", 0.5, 0.02, 2.54, "s") : r.bounded("command_timeout", 0.5, 0, 10, "s", true);
    d.serial.max_load = r.bounded("max_load", 0.8, 0, 1, "-", true);
    d.serial.period_s = period;
    if (x) {
      d.serial.torque_constant = r.bounded("torque_constant", 1.78, 0, 100, "N·m/A", true);
      d.serial.sensor_id_offset = static_cast<int>(
          r.integer("sensor_id_offset", 100, std::max(joints, 1), std::max(252 - joints, 1)));
      d.serial.set_operating_mode = r.boolean("set_operating_mode", true);
      d.serial.max_stale_cycles = static_cast<int>(r.integer("max_stale_cycles", 8, 1, 1000));
    }
    checked(r, "driver", [&] {
      drivers::SerialBusSpec spec{d.serial.joints, d.serial.period_s, d.serial.baud,
                                  d.serial.return_delay_s, d.serial.turnaround_s, d.serial.max_load};
      spec.x_series = x;
      drivers::check_serial_bus_budget(spec);
    });
  }
}

void read_realtime(const Reader& r, DaemonConfig& c) {
  r.allow_only({"priority", "cpu", "lock_memory", "prefault_stack", "require", "clock",
                "read_budget", "stale_timeout", "overrun_fault_after", "auto_start"});
  runtime::RuntimeConfig& rc = c.runtime;
  rc.rt.priority = static_cast<int>(r.integer("priority", 0, 0, 99));
  // The robot's machine's CPU: whether this machine has it is --check's and the start's question
  // (a packaging machine with 1 CPU loads a robot's cpu: 1).
  rc.rt.cpu = static_cast<int>(r.integer("cpu", -1, -1, runtime::kMaxCpu));
  rc.rt.lock_memory = r.boolean("lock_memory", false);
  rc.rt.prefault_stack_bytes = static_cast<std::size_t>(r.integer("prefault_stack", 256 * 1024, 0, 4 << 20));
  rc.rt.require_rt = r.boolean("require", false);
  rc.clock = r.choice("clock", "realtime", {"realtime", "lockstep"}) == "lockstep"
                 ? runtime::ClockMode::kLockstep
                 : runtime::ClockMode::kRealtime;
  rc.read_budget = r.bounded("read_budget", rc.read_budget, 0, 1, "of the period", true);
  rc.stale_timeout = r.bounded("stale_timeout", rc.stale_timeout, 0, 10, "s", true);
  rc.overrun_fault_after = static_cast<std::uint32_t>(r.integer("overrun_fault_after", 0, 0, 1 << 30));
  rc.auto_start = r.boolean("auto_start", true);
}

// CALIBRATING before READY: the deflection sensors zeroed at rest (runtime.hpp CalibrationConfig).
void read_calibration(const Reader& r, DaemonConfig& c) {
  r.allow_only({"duration", "timeout", "max_offset", "max_rate", "max_spread"});
  runtime::CalibrationConfig& k = c.runtime.calibration;
  const double period = 1.0 / c.runtime.rt.rate_hz;
  k.duration = r.bounded("duration", 0.5, 0, 60, "s");
  if (k.duration > 0 && k.duration * c.runtime.rt.rate_hz < 1.0 - 1e-9) {
    std::ostringstream os;
    os << "0 (no calibration) or at least one control period 1/rate_hz = " << period << " s";
    r["duration"].fail(os.str());
  }
  k.timeout = r.bounded("timeout", std::max(k.timeout, k.duration), 0, 600, "s");
  if (k.timeout < k.duration) r["timeout"].fail("a time in [calibration.duration, 600] s");
  k.max_offset = r.bounded("max_offset", k.max_offset, 0, 1, "rad", true);
  k.max_rate = r.bounded("max_rate", k.max_rate, 0, 10, "rad/s", true);
  k.max_spread = r.bounded("max_spread", k.max_spread, 0, 1, "rad", true);
}

// A ROS 2 namespace: "/" then names [A-Za-z_][A-Za-z0-9_]* separated by "/", no trailing "/",
// at most 63 characters. (The telemetry checks it again when it starts; this layer does not
// link the telemetry, which a build without DDS leaves out.)
bool ros_namespace_ok(const std::string& ns) {
  if (ns.size() > 63 || ns.front() != '/' || ns.back() == '/') return false;
  bool token_start = true;
  for (std::size_t i = 1; i < ns.size(); ++i) {
    const char ch = ns[i];
    if (ch == '/') {
      if (token_start) return false;
      token_start = true;
      continue;
    }
    const bool alpha = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || ch == '_';
    const bool digit = ch >= '0' && ch <= '9';
    if (!alpha && !(digit && !token_start)) return false;
    token_start = false;
  }
  return true;
}

void read_telemetry(const Reader& r, DaemonConfig& c) {
  r.allow_only({"enabled", "domain_id", "interface", "localhost_only", "peers", "namespace",
                "stamp_clock", "standard_topics", "decimation_state", "decimation_timing",
                "commands", "amplitude_max", "omega_max", "eta_min", "eta_max", "record"});
  TelemetrySection& t = c.telemetry;
  t.enabled = r.boolean("enabled", true);
  t.has_domain_id = r.has("domain_id");
  t.domain_id = static_cast<std::uint32_t>(r.integer("domain_id", 0, 0, 232));
  t.has_interface = r.has("interface");
  t.interface = r.string("interface", "");
  if (t.has_interface && (t.interface.empty() || t.interface.size() > 15 ||
                          t.interface.find_first_of("/ \t") != std::string::npos))
    r["interface"].fail("a network interface name (1 … 15 characters, no '/' or blanks)");
  t.localhost_only = r.boolean("localhost_only", false);
  if (t.localhost_only && t.has_interface && t.interface != "lo")
    r["interface"].fail("no interface besides localhost_only: true (or \"lo\"): localhost_only "
                        "binds to lo");
  t.ros_namespace = r.string("namespace", "");
  if (!t.ros_namespace.empty() && !ros_namespace_ok(t.ros_namespace))
    r["namespace"].fail("a ROS 2 namespace: \"/\" then names [A-Za-z_][A-Za-z0-9_]* separated by "
                        "\"/\", no trailing \"/\", at most 63 characters (e.g. \"/snake1\")");
  t.realtime_stamps = r.choice("stamp_clock", "realtime", {"realtime", "monotonic"}) == "realtime";
  t.standard_topics = r.boolean("standard_topics", true);
  if (r.has("peers")) {
    const Reader p = r["peers"];
    if (!p.is_sequence()) p.fail("a list of addresses");
    for (std::size_t i = 0; i < p.size(); ++i) {
      const Reader a = p.at(i);
      t.peers.push_back(a.as_string());
      // What the telemetry would refuse only when it starts (it writes them into an XML file).
      if (t.peers.back().empty() || t.peers.back().find_first_of(" \t<>&\"'") != std::string::npos)
        a.fail("an IPv4 address or host name (no blanks or <>&\"')");
    }
  }
  t.decimation_state = static_cast<int>(r.integer("decimation_state", 10, 1, 100000));
  t.decimation_timing = static_cast<int>(r.integer("decimation_timing", 10, 1, 100000));
  t.commands = r.boolean("commands", true);
  t.amplitude_max = r.bounded("amplitude_max", t.amplitude_max, 0, M_PI, "rad", true);
  t.omega_max = r.bounded("omega_max", t.omega_max, 0, 100, "rad/s", true);
  t.eta_min = r.bounded("eta_min", t.eta_min, -2 * M_PI, 2 * M_PI, "rad");
  t.eta_max = r.bounded("eta_max", t.eta_max, -2 * M_PI, 2 * M_PI, "rad");
  check_order(r, "eta_min", t.eta_min, "eta_max", t.eta_max);
  t.record = r.string("record", "");
  if (r.has("record")) {
    const std::string& f = t.record;
    const bool mcap = f.size() > 5 && f.compare(f.size() - 5, 5, ".mcap") == 0;
    if (!mcap || f.find_first_of("\n\r") != std::string::npos)
      r["record"].fail("a file name ending in .mcap (e.g. /var/lib/pedalwave/run-{time}.mcap)");
  }
}

void read_security(const Reader& r, const std::string& base_dir, DaemonConfig& c) {
  r.allow_only({"enable", "keystore", "enclave", "strategy"});
  SecuritySection& s = c.security;
  s.present = true;
  s.enable = r.boolean("enable", true);
  s.keystore = r.string("keystore", "");
  if (r.has("keystore")) {
    if (s.keystore.empty()) r["keystore"].fail("an SROS2 keystore folder (tools/scripts/keystore.sh init)");
    std::filesystem::path p(s.keystore);
    if (p.is_relative()) p = std::filesystem::path(base_dir) / p;
    s.keystore = p.lexically_normal().string();
  }
  s.enclave = r.string("enclave", "");
  if (r.has("enclave")) {
    // An enclave is a path of names, e.g. /pedalwave/snake1 (keystore.sh's rule).
    bool ok = s.enclave.size() > 1 && s.enclave.front() == '/' && s.enclave.back() != '/';
    for (std::size_t i = 0; ok && i < s.enclave.size(); ++i) {
      const char ch = s.enclave[i];
      ok = ch == '/' ? (i == 0 || s.enclave[i - 1] != '/')
                     : ((ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') ||
                        (ch >= '0' && ch <= '9') || ch == '_');
    }
    if (!ok) r["enclave"].fail("an enclave path: \"/\" then names [A-Za-z0-9_] separated by \"/\" "
                               "(e.g. \"/pedalwave/snake1\")");
  }
  if (r.has("strategy")) s.strategy = r.choice("strategy", "enforce", {"enforce", "permissive"});
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
    window = drivers::can_reply_window_s(drivers::can_bus_spec(d.can));
  else if (d.kind == DriverKind::kSerial) {
    drivers::SerialBusSpec spec{d.serial.joints, period, d.serial.baud, d.serial.return_delay_s,
                                d.serial.turnaround_s, d.serial.max_load};
    spec.x_series = d.serial.devices == drivers::SerialDevices::kXSeries;
    window = drivers::serial_reply_window_s(spec);
  }
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

// The daemon's `robot:` beside a simulated plant must describe the scene's robot: the controller
// is tuned for the robot it drives (the scene's), and a robot: {N: 12} beside a 6-link scene would
// otherwise run 5 joints while saying 11. Every key the section gives is compared.
void check_robot_matches_scene(const Reader& r, const model::Params& scene, const std::string& scene_path) {
  const model::Params given = read_robot(r);
  auto differ = [](double a, double b) { return std::abs(a - b) > 1e-12 * std::max(std::abs(a), std::abs(b)); };
  auto refuse = [&](const char* key, const std::string& scene_value) {
    r[key].fail("the simulated robot's value " + scene_value + " (driver.scene: " + scene_path +
                "); the robot section is optional beside a sim driver");
  };
  auto num = [](double v) {
    std::ostringstream os;
    os << v;
    return os.str();
  };
  if (r.has("N") && given.N != scene.N) refuse("N", std::to_string(scene.N));
  if (r.has("m_l") && differ(given.m_l, scene.m_l)) refuse("m_l", num(scene.m_l));
  if (r.has("link_length") && differ(given.l, scene.l)) refuse("link_length", num(2 * scene.l));
  if (r.has("I_l") && differ(given.I_l, scene.I_l)) refuse("I_l", num(scene.I_l));
  if (r.has("m_r") && differ(given.m_r, scene.m_r)) refuse("m_r", num(scene.m_r));
  if (r.has("I_r") && differ(given.I_r, scene.I_r)) refuse("I_r", num(scene.I_r));
  if (r.has("n") && differ(given.n, scene.n)) refuse("n", num(scene.n));
  if (r.has("g") && differ(given.g, scene.g)) refuse("g", num(scene.g));
  if (r.has("joints") && given.joints != scene.joints)
    refuse("joints", scene.joints == model::JointModel::kRigid ? "rigid" : "flexible");
  if (r.has("K"))
    for (int j = 0; j < scene.N - 1; ++j)
      if (j >= given.N - 1 || differ(given.stiffness(j), scene.stiffness(j)))
        refuse("K", "K[" + std::to_string(j) + "] = " + num(scene.stiffness(j)));
}

}  // namespace

std::string duration_problem(double duration, double rate_hz) {
  if (!std::isfinite(duration) || duration < 0 || duration > kMaxDuration) {
    std::ostringstream os;
    os << "a run time in [0, " << kMaxDuration << "] s (0 = until a signal)";
    return os.str();
  }
  // At least one period, as the message says (and README.md says of --duration), within float
  // rounding of it (0.0019 s at 1/0.0019 Hz is 0.9999999999999999 periods); half a period, which
  // rounded to one cycle, passed.
  if (duration > 0 && duration * rate_hz < 1.0 - 1e-9) {
    std::ostringstream os;
    os << "0 (until a signal) or at least one control period 1/rate_hz = " << 1.0 / rate_hz << " s";
    return os.str();
  }
  return "";
}

DaemonConfig parse_daemon_config(const std::string& text, const std::string& name,
                                 const std::string& base_dir) {
  const Reader r = Reader::parse(text, name);
  r.allow_only({"name", "description", "rate_hz", "duration", "robot", "driver", "controller",
                "realtime", "calibration", "observer", "telemetry", "security", "log_file"});
  DaemonConfig c;
  c.source = name;
  c.name = r.string("name", "pedalwave");
  // The name fills the 64-byte robot name the telemetry publishes: longer would be cut.
  if (c.name.empty() || c.name.size() > 63 ||
      std::any_of(c.name.begin(), c.name.end(), [](char ch) {
        return static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f;
      }))
    r["name"].fail("a name of 1 … 63 characters, no control characters");
  (void)r.string("description", "");  // a label: any text, but text
  c.runtime.rt.rate_hz = r.positive("rate_hz", 1000.0);
  if (c.runtime.rt.rate_hz > runtime::kMaxRateHz) r["rate_hz"].fail("a rate in (0, 20000] Hz");
  c.duration = r.bounded("duration", 0.0, 0, kMaxDuration, "s");
  if (const std::string why = duration_problem(c.duration, c.runtime.rt.rate_hz); !why.empty())
    r["duration"].fail(why);
  if (r.has("robot")) c.robot = read_robot(r["robot"]);
  if (r.has("realtime")) read_realtime(r["realtime"], c);
  else c.runtime.auto_start = true;
  if (r.has("calibration")) read_calibration(r["calibration"], c);
  read_driver(r.required("driver", "a driver section (type: sim | socketcan | serial)"), base_dir, c);
  if (c.driver.kind == DriverKind::kSim && r.has("robot"))
    check_robot_matches_scene(r["robot"], c.driver.scene.robot, c.driver.scene_path);
  // Controller: matched to the robot (K, n² I_r), at the loop rate.
  control::GaitControllerParams& p = c.controller;
  p.joints = c.robot.N - 1;
  p.period = 1.0 / c.runtime.rt.rate_hz;
  p.actuator.K.clear();
  for (int j = 0; j < p.joints; ++j)
    p.actuator.K.push_back(c.robot.joints == model::JointModel::kFlexible ? c.robot.stiffness(j) : 1e6);
  p.actuator.reflected_inertia = {std::max(c.robot.n * c.robot.n * c.robot.I_r, 1e-12)};
  if (c.driver.kind == DriverKind::kSim) {
    // The scene's gait drives the runtime's unless the controller gives its own (a
    // controller.gait map replaces it whole). The controller takes amplitudes ≥ 0, the model any
    // sign: a negative one is refused here at the scene's own line (it was the controller's
    // error, naming no line and the wrong file).
    const bool own_gait = r.has("controller") && r["controller"].has("gait");
    if (!own_gait && c.driver.scene.gait.A_p < 0)
      Reader::load_file(c.driver.scene_path)["gait"]["A_p"].fail(
          "a number in [0, 3.14159] [rad]: this scene's gait drives the runtime's controller, which "
          "takes amplitudes >= 0 (or give controller.gait in " + (c.source.empty() ? c.name : c.source) + ")");
    p.gait.A_p = c.driver.scene.gait.A_p;
    p.gait.omega = c.driver.scene.gait.omega;
    p.admittance.eta_n = {c.driver.scene.gait.eta};
  }
  if (r.has("controller")) read_controller(r["controller"], c);
  // Stock X-series servos run no module law: the host evaluates the PD and sends a current, so
  // the controller must place it there — and then its stability check applies (the rate and
  // K_D must make the sampled PD stable; the paper's K_D = 15 needs > 2307 Hz).
  if (c.driver.kind == DriverKind::kSerial && c.driver.serial.devices == drivers::SerialDevices::kXSeries &&
      p.pd.placement != control::PdPlacement::kHost) {
    const std::string why =
        "pd_placement: host with driver.devices: x_series (a stock servo in current control runs "
        "no module PD: the host evaluates it and sends Goal Current; choose rate_hz and K_D the "
        "host-PD stability check accepts, e.g. config/runtime/xseries.yaml)";
    if (r.has("controller") && r["controller"].has("pd_placement")) r["controller"]["pd_placement"].fail(why);
    r["driver"]["devices"].fail(why);
  }
  // CANopen drives in cyclic synchronous torque apply the target torque only: the host evaluates
  // the PD (in CSP the drive's position loop is the module PD).
  if (c.driver.kind == DriverKind::kSocketCan && c.driver.can.protocol == drivers::CanProtocol::kCanOpen &&
      c.driver.can.canopen.mode == drivers::CanOpenMode::kCst && p.pd.placement != control::PdPlacement::kHost) {
    const std::string why =
        "pd_placement: host with driver.drive_mode: cst (a CiA 402 drive in cyclic synchronous torque applies "
        "the target torque only: the host evaluates the PD; or drive_mode: csp, whose position loop is the "
        "module PD)";
    if (r.has("controller") && r["controller"].has("pd_placement")) r["controller"]["pd_placement"].fail(why);
    if (r["driver"].has("drive_mode")) r["driver"]["drive_mode"].fail(why);
    r["driver"]["protocol"].fail(why);
  }
  checked(r, "controller", [&] { control::GaitController probe(p); });
  // CSP drives start with the controller's module PD gains (their position loop, 2010h / 2011h).
  // (pd_placement: host sends k_p = k_d = 0: the drives start with them.)
  if (c.driver.kind == DriverKind::kSocketCan && c.driver.can.protocol == drivers::CanProtocol::kCanOpen &&
      p.pd.placement == control::PdPlacement::kModule) {
    for (int j = 0; j < c.driver.can.joints; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      c.driver.can.canopen.csp_kp[ju] = p.pd.K_p.size() == 1 ? p.pd.K_p[0] : p.pd.K_p.at(ju);
      c.driver.can.canopen.csp_kd[ju] = p.pd.K_D.size() == 1 ? p.pd.K_D[0] : p.pd.K_D.at(ju);
    }
  }
  if (r.has("observer")) {
    const Reader o = r["observer"];
    o.allow_only({"enabled"});
    c.observer = o.boolean("enabled", true);
  }
  if (r.has("telemetry")) read_telemetry(r["telemetry"], c);
  if (r.has("security")) read_security(r["security"], base_dir, c);
  c.log_file = r.string("log_file", "");
  // Empty: stderr. A folder cannot be the log (it would be found only when the loop starts).
  if (std::error_code ec; !c.log_file.empty() &&
                          (c.log_file.back() == '/' || std::filesystem::is_directory(c.log_file, ec)))
    r["log_file"].fail("a file path (not a folder; \"\" or no key: stderr)");
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
  checked(r, "realtime", [&] { runtime::validate(rc, runtime::ValidateScope::kValues); });
  return c;
}

DaemonConfig load_daemon_config(const std::string& path) {
  // load_file refuses what is not a small regular file (a directory, /dev/zero) and an empty one.
  const Reader r = Reader::load_file(path);
  (void)r;
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_daemon_config(ss.str(), path, std::filesystem::path(path).parent_path().string());
}

}  // namespace pedalwave::config
