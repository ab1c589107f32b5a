#include "soak.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "pedalwave/toolkit/cli.hpp"
#include "pedalwave/toolkit/table.hpp"

namespace pedalwave::soak {

static_assert(kExitPass == toolkit::cli::kExitOk && kExitFail == toolkit::cli::kExitInternal &&
              kExitUsage == toolkit::cli::kExitBadInput && kExitFault == toolkit::cli::kExitFault &&
              kExitEmergencyStop == toolkit::cli::kExitEmergencyStop);

namespace {

using toolkit::Table;

std::string fmt(double v, int sig = 4) { return Table::num(v, sig); }

// A JSON value as a cell: numbers compactly, strings as they are, null as "-".
std::string cell(const Json& v) {
  if (v.is_number()) {
    const double x = v.number();
    if (x == std::floor(x) && std::fabs(x) < 1e15) return std::to_string(static_cast<long long>(x));
    return fmt(x);
  }
  if (v.is_string()) return v.string().empty() ? "-" : v.string();
  if (v.is_bool()) return v.boolean() ? "yes" : "no";
  if (v.is_null()) return "-";
  return v.dump();
}

std::string mb(double kB) { return fmt(kB / 1024.0, 4); }

// The sample at or after `t_s` (the last one when none is).
const Json& sample_at(const Json& rows, double t_s) {
  for (const Json& r : rows.items())
    if (r["t_s"].number_or(0) >= t_s) return r;
  return rows[rows.size() - 1];
}

bool is_fault_event(const Json& e) { return e["kind"].string_or("") == "fault"; }

// The member `key` of the given type (the report's schema names "driver" twice: the driver's name,
// a string, and its counters, an object); a shared null when there is none.
const Json& member(const Json& o, const std::string& key, Json::Type type) {
  static const Json null;
  if (!o.is_object()) return null;
  for (const auto& [k, v] : o.members())
    if (k == key && v.type() == type) return v;
  return null;
}

}  // namespace

// ---- /proc/<pid>/status --------------------------------------------------------------------------

std::optional<MemorySample> parse_proc_status(const std::string& text) {
  MemorySample s;
  bool have_rss = false;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::string key = line.substr(0, colon);
    long value = 0;
    try {
      value = std::stol(line.substr(colon + 1));
    } catch (const std::exception&) {
      continue;
    }
    if (key == "VmRSS") {
      s.rss_kB = value;
      have_rss = true;
    } else if (key == "VmHWM") {
      s.hwm_kB = value;
    } else if (key == "VmSize") {
      s.size_kB = value;
    } else if (key == "Threads") {
      s.threads = static_cast<int>(value);
    }
  }
  if (!have_rss) return std::nullopt;
  return s;
}

std::optional<MemorySample> read_proc_status(pid_t pid, double t_s) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  if (!in) return std::nullopt;
  std::stringstream ss;
  ss << in.rdbuf();
  auto s = parse_proc_status(ss.str());
  if (s) s->t_s = t_s;
  return s;
}

Json to_json(const std::vector<MemorySample>& samples) {
  Json rows = Json::array();
  for (const MemorySample& s : samples)
    rows.push(Json::object()
                  .set("t_s", s.t_s)
                  .set("rss_kB", s.rss_kB)
                  .set("hwm_kB", s.hwm_kB)
                  .set("size_kB", s.size_kB)
                  .set("threads", s.threads));
  return rows;
}

// ---- the runtime configuration -------------------------------------------------------------------

std::string soak_runtime_config(const std::filesystem::path& template_path, const std::string& device,
                                double rate_hz, bool telemetry) {
  const std::string where = "--config " + template_path.string();
  if (!std::filesystem::is_regular_file(template_path))
    throw UsageError(where + ": no such file (expected a runtime configuration, e.g. config/runtime/serial.yaml)");
  YAML::Node root;
  try {
    root = YAML::LoadFile(template_path.string());
  } catch (const YAML::Exception& e) {
    throw UsageError(where + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap()) throw UsageError(where + ": expected a mapping of the runtime's keys (name, rate_hz, driver, ...)");
  YAML::Node driver = root["driver"];
  if (!driver || !driver.IsMap())
    throw UsageError(where + ": no driver section; expected driver: {type: serial, ...} (the virtual robot serves a pty)");
  const std::string type = driver["type"] ? driver["type"].as<std::string>() : std::string("sim");
  if (type != "serial")
    throw UsageError(where + ": driver.type is '" + type +
                     "', expected 'serial' (the soak runs the runtime against the virtual robot's pty)");
  driver["device"] = device;
  if (rate_hz > 0) root["rate_hz"] = rate_hz;
  YAML::Node tel = root["telemetry"];
  if (!tel || !tel.IsMap()) {
    root["telemetry"] = YAML::Node(YAML::NodeType::Map);
    tel = root["telemetry"];
  }
  tel["enabled"] = telemetry;
  if (telemetry && !tel["interface"]) tel["interface"] = "lo";
  // The shipped hardware configurations wait in READY for an operator's start command
  // (DEPLOY.md "Service policy"); the soak stands for that operator and starts at once.
  YAML::Node rt = root["realtime"];
  if (!rt || !rt.IsMap()) {
    root["realtime"] = YAML::Node(YAML::NodeType::Map);
    rt = root["realtime"];
  }
  rt["auto_start"] = true;
  YAML::Emitter out;
  out << root;
  return std::string("# written by pedalwave_soak from ") + template_path.string() + "\n" + out.c_str() + "\n";
}

// ---- verdict --------------------------------------------------------------------------------------

Verdict judge(const Json& report, int runtime_exit, bool interrupted) {
  Verdict v;
  auto fail = [&](std::string why) {
    v.code = kExitFail;
    v.reasons.push_back(std::move(why));
  };
  // The most specific code (see soak.hpp) once the reasons are known.
  auto settle = [&](int faults) {
    if (v.reasons.empty()) return;
    const int ended = report.is_object()
                          ? toolkit::cli::exit_for_run_end(report["exit"]["reason"].string_or("none"))
                          : toolkit::cli::kExitInternal;
    if (ended == kExitFault || ended == kExitEmergencyStop) v.code = ended;
    else if (faults > 0) v.code = kExitFault;
    else if (runtime_exit == kExitUsage) v.code = kExitUsage;
    else v.code = kExitFail;
  };
  if (interrupted) fail("the soak was interrupted (SIGINT/SIGTERM) before the end");
  if (runtime_exit != 0)
    fail(runtime_exit < 0 ? "the runtime was killed by a signal"
                          : "the runtime exited with code " + std::to_string(runtime_exit));
  if (!report.is_object()) {
    fail("no report from the runtime (report.json missing or unreadable)");
    settle(0);
    return v;
  }
  const Json& exit = report["exit"];
  const std::string reason = exit["reason"].string_or("?");
  if (reason != "cycle_limit") fail("the runtime stopped with exit reason '" + reason + "', not at its duration (cycle_limit)");
  const std::string fault = exit["fault"].string_or("none");
  if (fault != "none" && !fault.empty()) fail("the runtime stopped on fault '" + fault + "'");
  std::size_t faults = 0;
  for (const Json& e : report["events"].is_array() ? report["events"].items() : Json::Array{})
    faults += is_fault_event(e) ? 1 : 0;
  if (faults > 0) fail(std::to_string(faults) + " fault event(s) in the report");
  settle(static_cast<int>(faults));
  return v;
}

// ---- histograms -----------------------------------------------------------------------------------

std::string histogram_table(const Json& stage, int bar_width, int max_rows) {
  const Json& bins = stage["bins"];
  if (!bins.is_array() || bins.size() == 0) return "";
  struct Bin {
    double lo, hi, count;
  };
  std::vector<Bin> all;
  for (const Json& b : bins.items()) all.push_back({b[0].number_or(NAN), b[1].number_or(NAN), b[2].number_or(0)});
  std::size_t first = all.size(), last = 0;
  for (std::size_t k = 0; k < all.size(); ++k) {
    if (all[k].count > 0) {
      first = std::min(first, k);
      last = k;
    }
  }
  if (first == all.size()) return "  (no samples)\n";
  // Merge equal groups of bins when there are too many rows.
  const std::size_t n = last - first + 1;
  const std::size_t group = (n + static_cast<std::size_t>(max_rows) - 1) / static_cast<std::size_t>(max_rows);
  std::vector<Bin> rows;
  for (std::size_t k = first; k <= last; k += group) {
    Bin b{all[k].lo, all[k].hi, 0};
    for (std::size_t m = k; m < std::min(k + group, last + 1); ++m) {
      b.hi = all[m].hi;
      b.count += all[m].count;
    }
    rows.push_back(b);
  }
  double peak = 0;
  for (const Bin& b : rows) peak = std::max(peak, b.count);
  Table t({"bin [µs]", "count", "log-scale bar"}, {toolkit::Align::right, toolkit::Align::right, toolkit::Align::left});
  for (const Bin& b : rows) {
    int len = 0;
    if (b.count > 0)
      len = std::max(1, static_cast<int>(std::lround(bar_width * std::log10(1 + b.count) / std::log10(1 + peak))));
    t.add_row({fmt(b.lo) + " … " + (std::isfinite(b.hi) ? fmt(b.hi) : std::string("∞")), cell(Json(b.count)),
               std::string(static_cast<std::size_t>(len), '#')});
  }
  std::string out = t.to_text();
  const double overflows = stage["overflows"].number_or(0);
  if (overflows > 0) out += "  + " + cell(Json(overflows)) + " above the last bin (max " + cell(stage["max"]) + " µs)\n";
  return out;
}

// ---- summary --------------------------------------------------------------------------------------

std::string summary(const Json& soak) {
  std::ostringstream o;
  const Json& set = soak["settings"];
  const Json& load = soak["load"];
  const Json& machine = soak["machine"];
  const Json& report = soak["report"];
  o << "\n== pedalwave soak: " << cell(set["duration_s"]) << " s, scene " << cell(set["scene"]) << " ==\n";
  o << "machine: " << cell(machine["nproc"]) << " CPUs, kernel " << cell(machine["kernel"]) << "; load: "
    << cell(load["children"]) << " busy process(es) at duty " << cell(load["duty"]) << ", "
    << fmt(load["cpu_s"].number_or(0), 3) << " s CPU; telemetry " << cell(set["telemetry"]) << "\n";

  if (!report.is_object()) {
    o << "\nno report from the runtime (" << cell(soak["report_error"]) << ")\n";
  } else {
    const Json& exit = report["exit"];
    o << "\nrun: " << cell(report["name"]) << ", driver " << cell(member(report, "driver", Json::Type::string)) << ", "
      << cell(report["rate_hz"]) << " Hz, " << cell(report["duration_s"]) << " s\n";
    o << "exit: " << cell(exit["reason"]) << " (final mode " << cell(exit["final_mode"]) << ", fault "
      << cell(exit["fault"]) << ", joint " << cell(exit["joint"]) << ", signal " << cell(exit["signal"])
      << "); runtime exit code " << cell(soak["runtime"]["exit_code"]) << "\n";

    // Events: every one the report lists.
    const Json& events = report["events"];
    std::size_t faults = 0, warnings = 0;
    if (events.is_array() && events.size() > 0) {
      Table t({"t [s]", "cycle", "kind", "class", "severity", "joint", "value", "threshold", "text", "reaction"});
      for (const Json& e : events.items()) {
        faults += is_fault_event(e) ? 1 : 0;
        warnings += e["kind"].string_or("") == "warning" ? 1 : 0;
        t.add_row({cell(e["t"]), cell(e["cycle"]), cell(e["kind"]), cell(e["class"]), cell(e["severity"]),
                   cell(e["joint"]), cell(e["value"]), cell(e["threshold"]), cell(e["text"]), cell(e["reaction"])});
      }
      o << "\nevents (" << events.size() << "):\n" << t.to_text();
    } else {
      o << "\nevents: none\n";
    }
    o << "fault events (false alarms on a healthy run): " << faults << ", warnings: " << warnings
      << ", events dropped: " << cell(report["events_dropped"]) << "\n";

    const Json& loop = report["loop"];
    o << "\nloop: " << cell(loop["cycles"]) << " cycles, overruns " << cell(loop["overruns"]) << ", skipped periods "
      << cell(loop["skipped_periods"]) << " (max " << cell(loop["max_skipped"]) << " in a row), cycle drops "
      << cell(loop["cycle_drops"]) << ", event drops " << cell(loop["event_drops"]) << "\n";
    const Json& drv = report["driver_counters"];
    if (drv.is_object()) {
      o << "bus:";
      for (const auto& [k, v] : drv.members()) o << ' ' << k << ' ' << cell(v);
      o << "\n";
    }
    const Json& settings = report["settings"];
    if (settings.is_object()) {
      o << "settings:";
      for (const auto& [k, v] : settings.members()) o << ' ' << k << ' ' << cell(v);
      o << "\n";
    }

    // Timing: percentiles of every stage, then the histograms of wake, read and compute.
    const Json& timing = report["timing_us"];
    if (timing.is_object() && timing.size() > 0) {
      Table t({"stage [µs]", "count", "min", "p50", "p90", "p99", "p99.9", "max", "overflows"});
      for (const auto& [name, s] : timing.members())
        t.add_row({name, cell(s["count"]), cell(s["min"]), cell(s["p50"]), cell(s["p90"]), cell(s["p99"]),
                   cell(s["p999"]), cell(s["max"]), cell(s["overflows"])});
      o << "\ntiming:\n" << t.to_text();
      for (const char* name : {"wake", "read", "observe", "control"}) {
        const std::string h = histogram_table(timing[name]);
        if (!h.empty()) o << "\n" << name << " [µs]:\n" << h;
      }
    }
  }

  // Memory at start and end of both processes.
  const Json& memory = soak["memory"];
  const double warmup = soak["memory_warmup_s"].number_or(0);
  Table m({"process", "samples", "RSS start [MB]", "RSS end [MB]", "Δ [MB]", "Δ after " + fmt(warmup, 3) + " s [MB]",
           "peak RSS [MB]", "VmSize end [MB]", "threads"});
  bool any = false;
  for (const char* proc : {"runtime", "virtual_robot"}) {
    const Json& rows = memory[proc];
    if (!rows.is_array() || rows.size() == 0) continue;
    any = true;
    const Json& a = rows[0];
    const Json& z = rows[rows.size() - 1];
    const Json& w = sample_at(rows, warmup);
    const double d = z["rss_kB"].number_or(0) - a["rss_kB"].number_or(0);
    const double dw = z["rss_kB"].number_or(0) - w["rss_kB"].number_or(0);
    m.add_row({proc, std::to_string(rows.size()), mb(a["rss_kB"].number_or(0)), mb(z["rss_kB"].number_or(0)),
               (d > 0 ? "+" : "") + mb(d), (dw > 0 ? "+" : "") + mb(dw), mb(z["hwm_kB"].number_or(0)),
               mb(z["size_kB"].number_or(0)), cell(z["threads"])});
  }
  if (any) o << "\nmemory (/proc/<pid>/status):\n" << m.to_text();

  const Json& vr = soak["virtual_robot"]["report"];
  if (vr.is_array() && vr.size() > 0) {
    o << "\nvirtual robot (exit code " << cell(soak["virtual_robot"]["exit_code"]) << "):\n";
    for (const Json& line : vr.items()) o << "  " << line.string_or("") << "\n";
  }

  const Json& verdict = soak["verdict"];
  if (verdict["code"].number_or(1) == kExitPass) {
    o << "\nverdict: PASS (duration reached, no fault event)\n";
  } else {
    o << "\nverdict: FAIL\n";
    for (const Json& r : verdict["reasons"].is_array() ? verdict["reasons"].items() : Json::Array{})
      o << "  - " << r.string_or("") << "\n";
  }
  return o.str();
}

}  // namespace pedalwave::soak
