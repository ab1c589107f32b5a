#include "pedalwave/drivers/bus_budget.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/drivers/dynamixel.hpp"
#include "pedalwave/interface/io.hpp"

namespace pedalwave::drivers {
namespace {

std::string fmt(const char* f, double a) {
  char b[64];
  std::snprintf(b, sizeof b, f, a);
  return b;
}

std::string rate_str(double bps) {
  if (bps >= 1e6) return fmt("%g Mbit/s", bps / 1e6);
  return fmt("%g kbit/s", bps / 1e3);
}

// Nominal-bit-time equivalents and bus time of one cycle's CAN frame set.
struct CanCycle {
  int frames = 0;
  double time_s = 0.0;
};

CanCycle can_cycle(int joints, bool fd, double bitrate, double data_bitrate) noexcept {
  CanCycle c;
  const double sync = can_classic_frame_bits(2) / bitrate;
  c.frames = 1;
  c.time_s = sync;
  if (!fd) {
    // J feedback + J timing frames (PROTOCOL.md §1.1) + J commands + 1 gains frame.
    const double f8 = can_classic_frame_bits(8) / bitrate;
    c.frames += 3 * joints + 1;
    c.time_s += (3.0 * joints + 1.0) * f8;
  } else {
    // J feedback frames carrying their timing record (16 bytes) + the command groups.
    const CanFdFrameBits fb = canfd_frame_bits(can::kFdFeedbackLen);
    c.frames += joints;
    c.time_s += joints * (fb.nominal / bitrate + fb.data / data_bitrate);
    for (int left = joints; left > 0; left -= can::kFdJointsPerFrame) {
      const int count = left < can::kFdJointsPerFrame ? left : can::kFdJointsPerFrame;
      const CanFdFrameBits cb = canfd_frame_bits(can::fd_command_len(count));
      c.frames += 1;
      c.time_s += cb.nominal / bitrate + cb.data / data_bitrate;
    }
  }
  return c;
}

BusBudget finish(int frames, double time_s, double period_s, double max_load, double bitrate) {
  BusBudget b;
  b.frames = frames;
  b.time_needed_s = time_s;
  b.time_available_s = period_s * max_load;
  b.bits_needed = time_s * bitrate;
  b.bits_available = b.time_available_s * bitrate;
  b.load = time_s / period_s;
  b.fits = time_s <= b.time_available_s;
  return b;
}

}  // namespace

int can_classic_frame_bits(int n) noexcept { return 8 * n + 47 + (34 + 8 * n - 1) / 4; }

CanFdFrameBits canfd_frame_bits(int n) noexcept {
  CanFdFrameBits b;
  b.nominal = 17 + 4 + 13;
  const int crc = n <= 16 ? 17 : 21;
  const int fixed_stuff = (4 + crc + 3) / 4;
  b.data = 5 + 8 * n + (5 + 8 * n - 1) / 4 + 4 + crc + fixed_stuff;
  return b;
}

BusBudget can_bus_budget(const CanBusSpec& s) noexcept {
  if (s.joints <= 0 || s.joints > kMaxJoints || !(s.period_s > 0) || !(s.bitrate > 0) ||
      (s.fd && !(s.data_bitrate > 0)) || !(s.max_load > 0))
    return BusBudget{};
  if (s.canopen) {
    if (s.fd) return BusBudget{};  // CANopen here: classic frames only
    const int j = s.joints;
    int frames = 1 + j + 2 * j;
    double bits = can_classic_frame_bits(0) + j * can_classic_frame_bits(s.canopen_csp ? 8 : 4) +
                  2.0 * j * can_classic_frame_bits(8);
    if (s.canopen_csp) {
      frames += j;
      bits += j * can_classic_frame_bits(4);
    }
    if (s.heartbeat_s > 0) bits += j * can_classic_frame_bits(1) * s.period_s / s.heartbeat_s;
    return finish(frames, bits / s.bitrate, s.period_s, s.max_load, s.bitrate);
  }
  const CanCycle c = can_cycle(s.joints, s.fd, s.bitrate, s.data_bitrate);
  return finish(c.frames, c.time_s, s.period_s, s.max_load, s.bitrate);
}

BusBudget check_can_bus_budget(const CanBusSpec& s) {
  if (s.joints <= 0 || s.joints > kMaxJoints)
    throw std::invalid_argument("CAN bus: joints = " + std::to_string(s.joints) +
                                ", expected 1…" + std::to_string(kMaxJoints));
  if (!(s.period_s > 0) || !(s.bitrate > 0) || (s.fd && !(s.data_bitrate > 0)) ||
      !(s.max_load > 0) || s.max_load > 1)
    throw std::invalid_argument(
        "CAN bus: period_s = " + fmt("%g", s.period_s) + ", bitrate = " + fmt("%g", s.bitrate) +
        ", data_bitrate = " + fmt("%g", s.data_bitrate) + ", max_load = " + fmt("%g", s.max_load) +
        "; expected period > 0, bit rates > 0, 0 < max_load ≤ 1");
  if (s.canopen && s.fd)
    throw std::invalid_argument("CAN bus: protocol canopen with fd: true; expected a classic CAN bus "
                                "(this CANopen master sends classic frames only)");
  const BusBudget b = can_bus_budget(s);
  if (b.fits) return b;
  if (s.canopen) {
    int per_bus = 0;
    for (int j = s.joints - 1; j >= 1 && per_bus == 0; --j) {
      CanBusSpec t = s;
      t.joints = j;
      if (can_bus_budget(t).fits) per_bus = j;
    }
    throw std::invalid_argument(
        "CAN bus budget exceeded: CANopen (" + std::string(s.canopen_csp ? "CSP" : "CST") + ") with " +
        std::to_string(s.joints) + " nodes at " + fmt("%g", 1.0 / s.period_s) + " Hz on classic CAN at " +
        rate_str(s.bitrate) + " needs " + fmt("%.0f", b.time_needed_s * 1e6) + " µs per cycle (SYNC + " +
        std::to_string(b.frames - 1) + " PDOs" + (s.heartbeat_s > 0 ? " + heartbeats" : "") + "), load " +
        fmt("%.0f", b.load * 100) + " %, but max_load allows " + fmt("%.0f", b.time_available_s * 1e6) +
        " µs; options: a rate of at most " + fmt("%.0f", s.max_load / b.time_needed_s) + " Hz, " +
        (per_bus > 0 ? "at most " + std::to_string(per_bus) + (per_bus == 1 ? " node" : " nodes") + " per bus"
                     : std::string("a second bus")) +
        ", or a higher bit rate");
  }

  // Options: the highest rate that fits, CAN FD, joints per bus at this rate.
  const double max_rate = s.max_load / b.time_needed_s;
  std::string fd_option;
  if (!s.fd) {
    CanBusSpec f = s;
    f.fd = true;
    f.data_bitrate = 5e6;
    const BusBudget fb = can_bus_budget(f);
    fd_option = "use CAN FD (at " + rate_str(s.bitrate) + " / 5 Mbit/s data phase the cycle needs " +
                fmt("%.0f", fb.time_needed_s * 1e6) + " µs, load " + fmt("%.0f", fb.load * 100) +
                " %" + (fb.fits ? ", fits" : ", does not fit either") + ")";
  } else {
    fd_option = "raise the CAN FD data bit rate (now " + rate_str(s.data_bitrate) + ")";
  }
  int per_bus = 0;
  for (int j = s.joints - 1; j >= 1; --j) {
    CanBusSpec t = s;
    t.joints = j;
    if (can_bus_budget(t).fits) {
      per_bus = j;
      break;
    }
  }
  std::string msg = "CAN bus budget exceeded: " + std::to_string(s.joints) + " joints at " +
                    fmt("%g", 1.0 / s.period_s) + " Hz on " + (s.fd ? "CAN FD" : "classic CAN") +
                    " at " + rate_str(s.bitrate) +
                    (s.fd ? " (data phase " + rate_str(s.data_bitrate) + ")" : std::string()) +
                    " need " + fmt("%.0f", b.bits_needed) + " bits per cycle (" +
                    std::to_string(b.frames) + " frames, worst-case stuffing), " +
                    fmt("%.0f", b.bits_available) + " bits available (" +
                    fmt("%.0f", s.bitrate * s.period_s) + " per period × max load " +
                    fmt("%.0f", s.max_load * 100) + " %): load " + fmt("%.0f", b.load * 100) +
                    " %. Options: lower the cycle rate to ≤ " + fmt("%.0f", std::floor(max_rate)) +
                    " Hz; " + fd_option + "; or a second bus (" +
                    (per_bus > 0 ? "≤ " + std::to_string(per_bus) + " joints per bus fit"
                                 : std::string("not even one joint fits at this rate")) +
                    ").";
  throw std::invalid_argument(msg);
}

int serial_bytes_per_cycle(int j) noexcept {
  const int sync_counter = static_cast<int>(dxl::worst_packet_size(1 + 3)) - 1;  // no FF in it
  const int sync_read = 14 + j;
  const int status = static_cast<int>(dxl::worst_packet_size(2 + dxl::kFeedbackBlockSize));
  const int sync_write =
      static_cast<int>(dxl::worst_packet_size(1 + 4 + j * (1 + dxl::kCommandBlockSize)));
  return sync_counter + sync_read + j * status + sync_write;
}

int xseries_bytes_per_cycle(int j) noexcept {
  const int bulk_read = static_cast<int>(dxl::worst_packet_size(1 + 2 * j * 5));
  const int servo = static_cast<int>(dxl::worst_packet_size(2 + dxl::x::kFeedbackSize));
  const int sensor = static_cast<int>(dxl::worst_packet_size(2 + 2));
  const int sync_write = static_cast<int>(dxl::worst_packet_size(1 + 4 + j * (1 + 2)));
  return bulk_read + j * (servo + sensor) + sync_write;
}

namespace {
int bytes_per_cycle(const SerialBusSpec& s) noexcept {
  return s.x_series ? xseries_bytes_per_cycle(s.joints) : serial_bytes_per_cycle(s.joints);
}
int devices(const SerialBusSpec& s) noexcept { return s.x_series ? 2 * s.joints : s.joints; }
}  // namespace

BusBudget serial_bus_budget(const SerialBusSpec& s) noexcept {
  if (s.joints <= 0 || s.joints > kMaxJoints || !(s.period_s > 0) || s.baud <= 0 ||
      !(s.max_load > 0))
    return BusBudget{};
  const int bytes = bytes_per_cycle(s);
  const double t = bytes * 10.0 / s.baud + devices(s) * s.return_delay_s + 2.0 * s.turnaround_s;
  return finish(s.x_series ? 2 + 2 * s.joints : 3 + s.joints, t, s.period_s, s.max_load, s.baud);
}

double can_reply_window_s(const CanBusSpec& s) noexcept {
  if (s.joints <= 0 || !(s.bitrate > 0)) return 0.0;
  if (s.canopen)
    return (can_classic_frame_bits(0) + 2.0 * s.joints * can_classic_frame_bits(8)) / s.bitrate;
  const double sync = can_classic_frame_bits(2) / s.bitrate;
  if (!s.fd) return sync + 2.0 * s.joints * can_classic_frame_bits(8) / s.bitrate;
  const CanFdFrameBits fb = canfd_frame_bits(can::kFdFeedbackLen);
  return sync + s.joints * (fb.nominal / s.bitrate + fb.data / s.data_bitrate);
}

double serial_reply_window_s(const SerialBusSpec& s) noexcept {
  if (s.joints <= 0 || s.baud <= 0) return 0.0;
  if (s.x_series)
    return (static_cast<double>(dxl::worst_packet_size(1 + 2 * s.joints * 5)) +
            s.joints * static_cast<double>(dxl::worst_packet_size(2 + dxl::x::kFeedbackSize) +
                                           dxl::worst_packet_size(2 + 2))) *
               10.0 / s.baud +
           2 * s.joints * s.return_delay_s + s.turnaround_s;
  const double bytes = static_cast<double>(dxl::worst_packet_size(1 + 3)) - 1 + 14 + s.joints +
                       s.joints * static_cast<double>(dxl::worst_packet_size(2 + dxl::kFeedbackBlockSize));
  return bytes * 10.0 / s.baud + s.joints * s.return_delay_s + s.turnaround_s;
}

BusBudget check_serial_bus_budget(const SerialBusSpec& s) {
  if (s.joints <= 0 || s.joints > kMaxJoints)
    throw std::invalid_argument("serial bus: joints = " + std::to_string(s.joints) +
                                ", expected 1…" + std::to_string(kMaxJoints));
  if (!(s.period_s > 0) || s.baud <= 0 || !(s.max_load > 0) || s.max_load > 1 ||
      s.return_delay_s < 0 || s.turnaround_s < 0)
    throw std::invalid_argument("serial bus: period_s = " + fmt("%g", s.period_s) +
                                ", baud = " + std::to_string(s.baud) + ", max_load = " +
                                fmt("%g", s.max_load) +
                                "; expected period > 0, baud > 0, 0 < max_load ≤ 1, delays ≥ 0");
  const BusBudget b = serial_bus_budget(s);
  if (b.fits) return b;
  const double max_rate = s.max_load / b.time_needed_s;
  int per_bus = 0;
  for (int j = s.joints - 1; j >= 1; --j) {
    SerialBusSpec t = s;
    t.joints = j;
    if (serial_bus_budget(t).fits) {
      per_bus = j;
      break;
    }
  }
  const int bytes = bytes_per_cycle(s);
  const double wire_time = b.time_available_s - devices(s) * s.return_delay_s - 2 * s.turnaround_s;
  const std::string baud_option =
      wire_time > 0
          ? "raise the baud rate (≥ " + fmt("%.0f", std::ceil(bytes * 10.0 / wire_time)) +
                " baud needed)"
          : std::string("shorten the return delays / turnaround (they alone exceed the period)");
  throw std::invalid_argument(
      std::string(s.x_series ? "serial bus (X-series servos + sensors) budget exceeded: "
                             : "serial bus budget exceeded: ") +
      std::to_string(s.joints) + " joints at " +
      fmt("%g", 1.0 / s.period_s) + " Hz, " + std::to_string(s.baud) + " baud need " +
      std::to_string(bytes) + " bytes per cycle (" + std::to_string(bytes * 10) +
      " bits, worst-case stuffing) + " + fmt("%.0f", devices(s) * s.return_delay_s * 1e6) +
      " µs return delays + " + fmt("%.0f", 2 * s.turnaround_s * 1e6) + " µs turnaround = " +
      fmt("%.0f", b.time_needed_s * 1e6) + " µs, " + fmt("%.0f", b.time_available_s * 1e6) +
      " µs available (max load " + fmt("%.0f", s.max_load * 100) + " %): load " +
      fmt("%.0f", b.load * 100) + " %. Options: lower the cycle rate to ≤ " +
      fmt("%.0f", std::floor(max_rate)) + " Hz; " + baud_option + "; or a second bus (" +
      (per_bus > 0 ? "≤ " + std::to_string(per_bus) + " joints per bus fit"
                   : std::string("not even one joint fits")) +
      ").");
}

}  // namespace pedalwave::drivers
