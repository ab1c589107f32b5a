// pedalwave_mcap_demo: writes an MCAP recording (ros2 profile: ros2msg schemas, CDR messages) of
// synthetic snake data with pedalwave::mcap, to open in Foxglove or `ros2 bag`, and to test the
// writer against independent readers (tests/runtime/telemetry/mcap/interop).
//
//   pedalwave_mcap_demo --out demo.mcap [--compression zstd|lz4|none] [--chunk-size BYTES]
//                       [--duration S] [--start-ns NS] [--qos-style names|integers] [--expect FILE.jsonl]
//
// Topics (log times from the wall clock at start, CLOCK_REALTIME, or from --start-ns [ns since the
// Unix epoch] for a file that is the same byte for byte on every run; 100 Hz base rate):
//   /pedalwave/joint_states      sensor_msgs/msg/JointState       100 Hz, 5 joints (α, α̇, SEA torque)
//   /pedalwave/status            std_msgs/msg/String              1 Hz
//   /pedalwave/module_health     pedalwave_mcap_demo/msg/ModuleHealth  10 Hz (a custom message that
//                                uses every CDR shape: 1/2/4/8-byte fields, bool, fixed array, sequences)
//   /pedalwave/robot_description std_msgs/msg/String              once, transient-local QoS
// The data are made up (a travelling wave); they only exercise the format. --qos-style: how the
// channels' offered_qos_profiles spell the QoS — names for ROS 2 Jazzy and later (default),
// integers for Humble and Iron (ros2msg.hpp, QosYamlStyle).
//
// --expect writes one JSON line per message (topic, sequence, log_time, publish_time as strings of
// integers, and the message's fields as published; int64 as strings, doubles to 17 digits) so a
// reader can compare what it decodes with what was written.
//
// Exit status (toolkit/cli.hpp): 0 written, 2 bad command line, 1 a file cannot be written.
#include <CLI/CLI.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/mcap/cdr.hpp"
#include "pedalwave/mcap/ros2msg.hpp"
#include "pedalwave/mcap/writer.hpp"
#include "pedalwave/toolkit/cli.hpp"
#include "pedalwave/toolkit/format.hpp"
#include "pedalwave/toolkit/json.hpp"
#include "pedalwave/interface/clock.hpp"

namespace mcap = pedalwave::mcap;
namespace tk = pedalwave::toolkit;

namespace {

constexpr std::string_view kTool = "pedalwave_mcap_demo";
constexpr int kJoints = 5;

// The ROS 2 interface definitions the demo's schemas are made of (public definitions, comments
// left out; the custom message is the demo's own).
mcap::MsgMapLookup definitions() {
  mcap::MsgMapLookup l;
  l.add("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n");
  l.add("std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id\n");
  l.add("std_msgs/msg/String", "string data\n");
  l.add("sensor_msgs/msg/JointState",
        "std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n");
  l.add("pedalwave_mcap_demo/msg/ModuleHealth",
        "# One module's health (pedalwave_mcap_demo's own message).\n"
        "uint8 MODE_RUN=1\n"
        "builtin_interfaces/Time stamp\n"
        "uint8 module_id\n"
        "bool ok\n"
        "int16 temperature_cdeg   # [0.01 degC]\n"
        "float32 voltage          # [V]\n"
        "float64[3] accel         # [m/s^2]\n"
        "string[] faults\n"
        "uint32[] counters\n"
        "int64 cycle\n"
        "byte[] raw\n"
        "char mode\n");
  return l;
}

std::string num(double v) { return pedalwave::toolkit::sig(v, 17); }
std::string time_json(std::int64_t ns) {
  const std::int64_t sec = ns >= 0 ? ns / 1'000'000'000 : -((-ns + 999'999'999) / 1'000'000'000);
  const std::int64_t nsec = ns - sec * 1'000'000'000;
  return "{\"sec\":" + std::to_string(sec) + ",\"nanosec\":" + std::to_string(nsec) + "}";
}
template <class T, class F>
std::string array_json(const std::vector<T>& v, F&& f) {
  std::string s = "[";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? "," : "") + f(v[i]);
  return s + "]";
}

struct Recorder {
  mcap::Writer& out;
  std::ofstream* expect;
  mcap::CdrWriter cdr;
  void write(mcap::ChannelId ch, std::string_view topic, std::uint32_t seq, std::uint64_t log_time,
             const std::string& fields_json) {
    const std::uint64_t publish_time = log_time - 20'000;  // published 20 µs before it was logged
    out.write(mcap::Message{ch, seq, log_time, publish_time, cdr.bytes()});
    if (expect != nullptr)
      *expect << "{\"topic\":" << tk::json_quote(topic) << ",\"sequence\":" << seq << ",\"log_time\":\""
              << log_time << "\",\"publish_time\":\"" << publish_time << "\",\"msg\":" << fields_json << "}\n";
  }
};

int run(const std::string& out_path, const std::string& compression, std::uint64_t chunk_size, double duration,
        std::uint64_t start_ns, const std::string& qos_style, const std::string& expect_path) {
  mcap::WriterOptions options;
  options.compression = mcap::compression_from_string(compression);
  options.chunk_size = chunk_size;
  options.library = "pedalwave_mcap_demo";
  std::ofstream expect;
  if (!expect_path.empty()) {
    expect.open(expect_path);
    if (!expect) throw std::runtime_error(expect_path + ": cannot create the expectation file");
  }
  mcap::Writer out(out_path, options);
  const auto defs = definitions();
  const auto style = qos_style == "integers" ? mcap::QosYamlStyle::integers : mcap::QosYamlStyle::names;
  const auto qos = mcap::offered_qos_profiles_yaml({.reliable = true, .transient_local = false, .depth = 10}, style);
  const auto latched = mcap::offered_qos_profiles_yaml({.reliable = true, .transient_local = true, .depth = 1}, style);
  auto channel = [&](std::string_view topic, std::string_view type, const std::string& q) {
    return out.add_ros2_channel(topic, type, mcap::concatenate_msg_definitions(type, defs), q);
  };
  const auto description = channel("/pedalwave/robot_description", "std_msgs/msg/String", latched);
  const auto joints = channel("/pedalwave/joint_states", "sensor_msgs/msg/JointState", qos);
  const auto status = channel("/pedalwave/status", "std_msgs/msg/String", qos);
  const auto health = channel("/pedalwave/module_health", "pedalwave_mcap_demo/msg/ModuleHealth", qos);
  Recorder rec{out, expect_path.empty() ? nullptr : &expect, {}};

  std::uint64_t t0 = start_ns;
  if (t0 == 0) {
    t0 = static_cast<std::uint64_t>(pedalwave::clock_ns(CLOCK_REALTIME));
  }

  // The robot description, once (a tiny URDF-like text with characters JSON must escape).
  {
    const std::string urdf = "<robot name=\"snake\">\n  <!-- 5 joints, \"demo\" -->\n</robot>\n";
    rec.cdr.reset();
    rec.cdr.write_string(urdf);
    rec.write(description, "/pedalwave/robot_description", 0, t0, "{\"data\":" + tk::json_quote(urdf) + "}");
  }

  const int cycles = static_cast<int>(std::lround(duration * 100.0));
  std::vector<std::string> names;
  for (int j = 0; j < kJoints; ++j) names.push_back("joint_" + std::to_string(j + 1));
  for (int k = 0; k < cycles; ++k) {
    const double t = k * 0.01;
    const std::uint64_t log_time = t0 + static_cast<std::uint64_t>(k) * 10'000'000ull + 1;
    const std::int64_t stamp = static_cast<std::int64_t>(log_time) - 150'000;  // sampled 150 µs earlier

    // sensor_msgs/JointState: a travelling wave α_j = A sin(ω t − j φ), its rate, a spring torque.
    std::vector<double> pos, vel, eff;
    for (int j = 0; j < kJoints; ++j) {
      const double phase = 2.0 * std::numbers::pi * 0.5 * t - j * 0.8;
      pos.push_back(0.6 * std::sin(phase));
      vel.push_back(0.6 * std::numbers::pi * std::cos(phase));
      eff.push_back(-0.35 * std::sin(phase + 0.1) + 0.01 * j);
    }
    rec.cdr.reset();
    rec.cdr.write_time(stamp);
    rec.cdr.write_string("snake_base");
    rec.cdr.write_sequence(names);
    rec.cdr.write_sequence(pos);
    rec.cdr.write_sequence(k % 50 == 7 ? std::vector<double>{} : vel);  // sometimes no velocities
    rec.cdr.write_sequence(eff);
    const auto q = [](const std::string& s) { return tk::json_quote(s); };
    rec.write(joints, "/pedalwave/joint_states", static_cast<std::uint32_t>(k), log_time,
              "{\"header\":{\"stamp\":" + time_json(stamp) + ",\"frame_id\":\"snake_base\"},\"name\":" +
                  array_json(names, q) + ",\"position\":" + array_json(pos, num) + ",\"velocity\":" +
                  array_json(k % 50 == 7 ? std::vector<double>{} : vel, num) + ",\"effort\":" +
                  array_json(eff, num) + "}");

    // pedalwave_mcap_demo/ModuleHealth at 10 Hz, the modules in turn.
    if (k % 10 == 3) {
      const int n = k / 10;
      const auto module = static_cast<std::uint8_t>(1 + n % kJoints);
      const bool ok = n % 7 != 4;
      const auto temp = static_cast<std::int16_t>(2500 + 37 * (n % 11) - (n % 3 == 0 ? 3000 : 0));
      const float voltage = 11.1f + 0.013f * static_cast<float>(n % 9);
      const std::array<double, 3> accel = {0.01 * n, -9.81 + 0.001 * n, 1e-300 * n};
      std::vector<std::string> faults;
      if (!ok) faults = {"over_temperature", "encoder \"jump\""};
      const std::vector<std::uint32_t> counters = {static_cast<std::uint32_t>(n), 4000000000u, 0u};
      const std::int64_t cycle = -5'000'000'000'000ll + 1'000'003ll * k;  // beyond 2^32, negative
      const std::vector<std::uint8_t> raw(static_cast<std::size_t>(n % 4), static_cast<std::uint8_t>(0xF0 + n % 16));
      rec.cdr.reset();
      rec.cdr.write_time(stamp);
      rec.cdr.write_u8(module);
      rec.cdr.write_bool(ok);
      rec.cdr.write_i16(temp);
      rec.cdr.write_f32(voltage);
      rec.cdr.write_array(std::span<const double>(accel));
      rec.cdr.write_sequence(faults);
      rec.cdr.write_sequence(counters);
      rec.cdr.write_i64(cycle);
      rec.cdr.write_sequence(raw);
      rec.cdr.write_u8('R');
      const auto u = [](auto x) { return std::to_string(x); };
      rec.write(health, "/pedalwave/module_health", static_cast<std::uint32_t>(n), log_time + 2,
                "{\"stamp\":" + time_json(stamp) + ",\"module_id\":" + u(module) + ",\"ok\":" +
                    (ok ? "true" : "false") + ",\"temperature_cdeg\":" + u(temp) + ",\"voltage\":" +
                    num(static_cast<double>(voltage)) + ",\"accel\":" +
                    array_json(std::vector<double>(accel.begin(), accel.end()), num) + ",\"faults\":" +
                    array_json(faults, q) + ",\"counters\":" + array_json(counters, u) + ",\"cycle\":\"" +
                    std::to_string(cycle) + "\",\"raw\":" + array_json(raw, u) + ",\"mode\":" + u(int{'R'}) +
                    "}");
    }

    // std_msgs/String at 1 Hz.
    if (k % 100 == 50) {
      const std::string text = "mode running, cycle " + std::to_string(k) + (k % 200 == 50 ? ", α ok" : "");
      rec.cdr.reset();
      rec.cdr.write_string(text);
      rec.write(status, "/pedalwave/status", static_cast<std::uint32_t>(k / 100), log_time + 1,
                "{\"data\":" + tk::json_quote(text) + "}");
    }
  }
  out.close();
  const auto& s = out.stats();
  std::printf("%s: %llu messages in %u chunks (%s), %llu bytes (records %llu → %llu)\n", out_path.c_str(),
              static_cast<unsigned long long>(s.message_count), s.chunk_count,
              compression.c_str(), static_cast<unsigned long long>(s.bytes_written),
              static_cast<unsigned long long>(s.uncompressed_bytes),
              static_cast<unsigned long long>(s.compressed_bytes));
  if (!expect_path.empty()) {
    expect.close();
    if (!expect) throw std::runtime_error(expect_path + ": cannot write the expectation file");
  }
  return tk::cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Writes an MCAP recording (ros2 profile) of synthetic snake data with pedalwave::mcap."};
  std::string out_path, compression = "zstd", qos_style = "names", expect_path;
  std::uint64_t chunk_size = 256 * 1024;
  std::uint64_t start_ns = 0;
  double duration = 10.0;
  app.add_option("--out", out_path, "the MCAP file to write")->required();
  app.add_option("--compression", compression, "chunk compression")
      ->check(CLI::IsMember({"zstd", "lz4", "none"}));
  app.add_option("--chunk-size", chunk_size, "uncompressed bytes per chunk")->check(CLI::Range(1ull, 1ull << 32));
  app.add_option("--duration", duration, "recorded time [s] (100 Hz)")->check(tk::cli::finite_in(0.01, 3600));
  app.add_option("--start-ns", start_ns, "first log time [ns since the Unix epoch] (default: now)")
      ->check(CLI::Range(1ull, 1ull << 62));
  app.add_option("--qos-style", qos_style, "offered_qos_profiles spelling: names (ROS 2 Jazzy+) or integers (Humble, Iron)")
      ->check(CLI::IsMember({"names", "integers"}));
  app.add_option("--expect", expect_path, "also write every message's published values here (JSON lines)");
  if (const auto code = tk::cli::parse(app, argc, argv, kTool)) return *code;
  return tk::cli::run(kTool, [&] { return run(out_path, compression, chunk_size, duration, start_ns, qos_style, expect_path); });
}
