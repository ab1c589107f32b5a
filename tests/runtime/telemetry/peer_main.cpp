// Test peer: a second process on the DDS domain, so the tests exercise the real loopback network
// path (two Cyclone domain instances), robot restarts and reader deaths.
//   peer publish --domain D [--joints N] [--rate HZ] [--cycles C] [--start-seq S] [--events K]
//                [--decimate-timing k] [--wait-reader-s T] [--linger-s L]
//       DdsTelemetry publishing SyntheticRobot: description, a mode event, K fault events, then
//       (after a joint_state reader matched, if T > 0) C cycles at HZ from seq S; then lingers.
//       Prints "events-published", "reader-matched <n>", "done <written joint_state>".
//   peer subscribe --domain D
//   Both: [--interface IF] ("lo" default; "default" = Cyclone's own choice, as a default ROS 2
//   node) [--robot NAME] (the robot name / namespace, default "pedalwave").
//       TelemetrySubscriber polling until killed; prints "subscribed", then "received <n>" lines.
#include <time.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>

#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/subscriber.hpp"
#include "pedalwave/telemetry/synthetic.hpp"
#include "pedalwave/interface/clock.hpp"

namespace {

using namespace pedalwave;

struct Args {
  std::string mode;
  std::uint32_t domain = 0;
  int joints = 6;
  double rate = 1000.0;
  long cycles = 0;
  std::uint64_t start_seq = 0;
  int events = 0;
  int decimate_timing = 1;
  double wait_reader_s = 0.0;
  double linger_s = 0.5;
  std::string interface = "lo";
  std::string robot = "pedalwave";
};

Args parse(int argc, char** argv) {
  Args a;
  if (argc < 2) throw std::runtime_error("usage: peer publish|subscribe --domain D ...");
  a.mode = argv[1];
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    const char* v = argv[i + 1];
    if (k == "--domain") a.domain = static_cast<std::uint32_t>(std::stoul(v));
    else if (k == "--joints") a.joints = std::stoi(v);
    else if (k == "--rate") a.rate = std::stod(v);
    else if (k == "--cycles") a.cycles = std::stol(v);
    else if (k == "--start-seq") a.start_seq = std::stoull(v);
    else if (k == "--events") a.events = std::stoi(v);
    else if (k == "--decimate-timing") a.decimate_timing = std::stoi(v);
    else if (k == "--wait-reader-s") a.wait_reader_s = std::stod(v);
    else if (k == "--linger-s") a.linger_s = std::stod(v);
    else if (k == "--interface") a.interface = std::string(v) == "default" ? "" : v;
    else if (k == "--robot") a.robot = v;
    else throw std::runtime_error("peer: unknown option " + k);
  }
  return a;
}

void say(const std::string& s) {
  std::printf("%s\n", s.c_str());
  std::fflush(stdout);
}

int publish(const Args& a) {
  telemetry::TelemetryConfig cfg;
  cfg.domain_id = a.domain;
  cfg.interface = a.interface;
  cfg.robot_name = a.robot;
  cfg.decimation.loop_timing = a.decimate_timing;
  telemetry::DdsTelemetry tel(cfg, [](const runtime::OperatorCommand&) { return true; });
  const telemetry::SyntheticRobot robot(a.joints, a.rate);
  tel.on_description(robot.description());
  tel.on_event(robot.mode_event(runtime::Mode::kReady, runtime::Mode::kRunning, a.start_seq));
  for (int k = 0; k < a.events; ++k) {
    tel.on_event(robot.fault_event(static_cast<std::uint64_t>(k), a.start_seq));
  }
  say("events-published");
  if (a.wait_reader_s > 0.0) {
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::duration<double>(a.wait_reader_s);
    while (tel.joint_state_readers() == 0 && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    say("reader-matched " + std::to_string(tel.joint_state_readers()));
    // Matching is not simultaneous on both sides: give the reader's side a moment.
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  const auto period_ns = static_cast<std::int64_t>(1e9 / a.rate);
  timespec next = pedalwave::to_timespec(pedalwave::monotonic_ns());
  for (long i = 0; i < a.cycles; ++i) {
    tel.on_cycle(robot.sample(a.start_seq + static_cast<std::uint64_t>(i)));
    next.tv_nsec += period_ns;
    while (next.tv_nsec >= 1'000'000'000) {
      next.tv_nsec -= 1'000'000'000;
      ++next.tv_sec;
    }
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
  }
  const auto st = tel.stats();
  say("done " + std::to_string(st.joint_state) + " errors " + std::to_string(st.write_errors));
  std::this_thread::sleep_for(std::chrono::duration<double>(a.linger_s));
  return 0;
}

struct Counting : telemetry::TelemetryListener {
  std::uint64_t n = 0;
  void on_joint_state(const telemetry::JointStateMsg&, const telemetry::MessageInfo&) override {
    ++n;
  }
};

int subscribe(const Args& a) {
  telemetry::SubscriberConfig cfg;
  cfg.domain_id = a.domain;
  cfg.interface = a.interface;
  cfg.robot = a.robot;
  telemetry::TelemetrySubscriber sub(cfg);
  Counting c;
  sub.add_listener(c);
  say("subscribed");
  std::uint64_t last = 0;
  for (;;) {
    sub.poll(std::chrono::milliseconds(100));
    if (c.n / 100 != last / 100) say("received " + std::to_string(c.n));
    last = c.n;
  }
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Args a = parse(argc, argv);
    if (a.mode == "publish") return publish(a);
    if (a.mode == "subscribe") return subscribe(a);
    std::fprintf(stderr, "peer: unknown mode %s\n", a.mode.c_str());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "peer: %s\n", e.what());
    return 1;
  }
}
