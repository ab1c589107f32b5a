#include "pedalwave/drivers/xseries_driver.hpp"

#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <system_error>

#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/wire.hpp"
#include "pedalwave/drivers/posix_util.hpp"

namespace pedalwave::drivers {

const char* xseries_model_name(std::uint16_t model) noexcept {
  switch (model) {
    case dxl::x::kModelXM430W350: return "XM430-W350";
    case dxl::x::kModelXM430W210: return "XM430-W210";
    default: return nullptr;
  }
}

double xseries_current_lsb(std::uint16_t model) noexcept {
  return xseries_model_name(model) ? dxl::x::kCurrentLsbXM430 : 0.0;
}

namespace {
std::string register_name(bool sensor, std::uint16_t addr) {
  const dxl::Register* r = dxl::register_at(
      sensor ? std::span<const dxl::Register>(dxl::x::kSensorRegisters)
             : std::span<const dxl::Register>(dxl::x::kRegisters),
      addr);
  return "register " + std::to_string(addr) + " (" + (r ? r->name : "?") + ")";
}
std::string hw_error_text(std::uint8_t hw) {
  std::string s;
  const char* names[8] = {"input voltage", "?", "overheating", "motor encoder", "electrical shock",
                          "overload", "?", "?"};
  for (int b = 0; b < 8; ++b)
    if (hw & (1u << b)) s += std::string(s.empty() ? " (" : ", ") + names[b];
  return s.empty() ? s : s + ")";
}
}  // namespace

// ---- Realtime Tick ----------------------------------------------------------------------------------
namespace {
std::int64_t wrap_tick(std::int64_t x) noexcept {  // into [−16.384 s, 16.384 s)
  constexpr std::int64_t w = XSeriesTickClock::kWrapNs;
  x %= w;
  if (x < 0) x += w;
  return x >= w / 2 ? x - w : x;
}
constexpr std::int64_t kNone = INT64_MAX;
}  // namespace

std::int64_t XSeriesTickClock::d(std::uint16_t tick, std::int64_t t_ns) const noexcept {
  return wrap_tick(std::int64_t{tick % dxl::x::kTickWrap} * kTickNs - t_ns % kWrapNs - ref_);
}

void XSeriesTickClock::learn(std::uint16_t tick, std::int64_t t_ns) noexcept {
  if (!seeded_) {
    seeded_ = true;
    ref_ = wrap_tick(std::int64_t{tick % dxl::x::kTickWrap} * kTickNs - t_ns % kWrapNs);
    cur_min_ = 0;
    prev_min_ = kNone;
    count_ = 1;
    return;
  }
  cur_min_ = std::min(cur_min_, d(tick, t_ns));
  if (++count_ < kBlock) return;
  // A new block: the kept minimum over the last two (the clocks drift apart by up to ~50 ppm,
  // 13 µs over a block at 500 Hz), and everything re-anchored on it (no wrap however long it runs).
  const std::int64_t kept = std::min(cur_min_, prev_min_);
  ref_ = wrap_tick(ref_ + kept);
  prev_min_ = cur_min_ - kept;
  cur_min_ = kNone;
  count_ = 0;
}

std::int64_t XSeriesTickClock::place(std::uint16_t tick, std::int64_t t_ns) const noexcept {
  return wrap_tick(d(tick, t_ns) - std::min(cur_min_, prev_min_));
}

XSeriesDriver::XSeriesDriver(int fd, const SerialConfig& cfg)
    : fd_(fd), joints_(cfg.joints), baud_(cfg.baud), sensor_offset_(cfg.sensor_id_offset),
      k_t_(cfg.torque_constant), set_mode_(cfg.set_operating_mode),
      stale_limit_(cfg.max_stale_cycles), write_timeout_ns_(cfg.write_timeout_ns) {
  link_.attach(fd);
  try {
    if (fd < 0)
      throw std::invalid_argument("X-series driver: fd = " + std::to_string(fd) +
                                  ", expected an open tty");
    if (joints_ < 1 || joints_ > kMaxJoints)
      throw std::invalid_argument("X-series driver: joints = " + std::to_string(joints_) +
                                  ", expected 1 … " + std::to_string(kMaxJoints));
    if (sensor_offset_ < joints_ || sensor_offset_ + joints_ > 252)
      throw std::invalid_argument(
          "X-series driver: sensor_id_offset = " + std::to_string(sensor_offset_) +
          ", expected the sensor IDs (servo ID + offset) clear of the servos' IDs 1 … " +
          std::to_string(joints_) + " and ≤ 252: " + std::to_string(joints_) + " … " +
          std::to_string(252 - joints_));
    if (!(k_t_ > 0) || !std::isfinite(k_t_))
      throw std::invalid_argument("X-series driver: torque_constant = " + std::to_string(k_t_) +
                                  " N·m/A, expected > 0 (XM430-W350 at 12 V: 1.78)");
    if (stale_limit_ < 1 || stale_limit_ > 1000)
      throw std::invalid_argument("X-series driver: max_stale_cycles = " + std::to_string(stale_limit_) +
                                  ", expected 1 … 1000 cycles (how old a sample the host's PD may "
                                  "act on)");
    const double steps = std::round(cfg.return_delay_s / 2e-6);
    if (!(steps >= 0 && steps <= 254))
      throw std::invalid_argument("X-series driver: return_delay = " +
                                  std::to_string(cfg.return_delay_s) +
                                  " s, expected 0 … 508e-6 s (register 9: 0 … 254 × 2 µs)");
    return_delay_steps_ = static_cast<std::uint8_t>(steps);
    const double wd = std::ceil(cfg.command_timeout_s / 0.02 - 1e-9);
    if (!(wd >= 1 && wd <= 127))
      throw std::invalid_argument("X-series driver: command_timeout = " +
                                  std::to_string(cfg.command_timeout_s) +
                                  " s, expected 0.02 … 2.54 s (the servos' Bus Watchdog, register "
                                  "98: 1 … 127 × 20 ms)");
    watchdog_steps_ = static_cast<std::uint8_t>(wd);
    SerialBusSpec spec{cfg.joints, cfg.period_s, cfg.baud, cfg.return_delay_s, cfg.turnaround_s,
                       cfg.max_load};
    spec.x_series = true;
    check_serial_bus_budget(spec);
    if (!detail::set_nonblocking(fd))
      throw std::system_error(errno, std::generic_category(), "X-series driver: O_NONBLOCK");
    // The Bulk Read never changes: per joint (servo, 126, 10), (sensor, 124, 2).
    std::array<std::uint8_t, 10 * kMaxJoints> prm{};
    for (int j = 0; j < joints_; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      ids_[ju] = static_cast<std::uint8_t>(j + 1);
      ids_[static_cast<std::size_t>(joints_) + ju] = static_cast<std::uint8_t>(j + 1 + sensor_offset_);
      std::uint8_t* p = prm.data() + 10 * ju;
      p[0] = ids_[ju];
      wire::put_u16(p + 1, dxl::x::kFeedbackAddress);
      wire::put_u16(p + 3, static_cast<std::uint16_t>(dxl::x::kFeedbackSize));
      p[5] = ids_[static_cast<std::size_t>(joints_) + ju];
      wire::put_u16(p + 6, dxl::x::kRegSensorDeflection);
      wire::put_u16(p + 8, 2);
      lsb_[ju] = dxl::x::kCurrentLsbXM430;
      identity_[ju].current_limit = 1193;
    }
    if (dxl::build_instruction(dxl::kBroadcastId, dxl::kInstBulkRead,
                               std::span<const std::uint8_t>(prm.data(), 10 * static_cast<std::size_t>(joints_)),
                               bulk_tx_, bulk_len_) != dxl::DxlStatus::kOk)
      throw std::invalid_argument("X-series driver: cannot build the Bulk Read packet");
    bulk_wire_ns_ = wire_ns(bulk_len_);
    min_reply_ns_ = wire_ns(dxl::kHeaderSize + 4 + 2);  // the shortest answer: the sensor's
  } catch (...) {
    if (fd >= 0) ::close(fd);
    fd_ = -1;
    throw;
  }
}

XSeriesDriver::~XSeriesDriver() {
  if (fd_ >= 0) ::close(fd_);
}

std::int64_t XSeriesDriver::wire_ns(std::size_t bytes) const noexcept {
  return std::llround(static_cast<double>(bytes) * 10.0 * 1e9 / baud_);
}

std::string XSeriesDriver::name(int j, bool sensor) const {
  return std::string("serial bus (X-series): ") +
         (sensor ? "deflection sensor ID " + std::to_string(j + 1 + sensor_offset_)
                 : "servo ID " + std::to_string(j + 1)) +
         " (joint " + std::to_string(j + 1) + ")";
}

// ---- Configuration -------------------------------------------------------------------------------
std::vector<std::uint8_t> XSeriesDriver::read_registers(int j, bool sensor, std::uint16_t addr,
                                                        std::uint16_t len, std::int64_t timeout_ns) {
  const auto id = static_cast<std::uint8_t>(j + 1 + (sensor ? sensor_offset_ : 0));
  std::size_t n = 0;
  dxl::build_read(id, addr, len, std::span<std::uint8_t>(tx_.data(), dxl::kMaxPacket), n);
  for (int attempt = 0; attempt < 3; ++attempt) {
    if (!link_.transact(tx_.data(), n, id, timeout_ns, len)) continue;
    const dxl::Packet& pkt_ = link_.packet();
    if ((pkt_.error & 0x7F) != 0)
      throw std::runtime_error(name(j, sensor) + ": Read of " + register_name(sensor, addr) + ", " +
                               std::to_string(len) + " bytes, answered error " +
                               std::to_string(pkt_.error & 0x7F) + " (" + dxl::error_name(pkt_.error) +
                               "), expected its value");
    if (pkt_.param_count != len)
      throw std::runtime_error(name(j, sensor) + ": Read of " + register_name(sensor, addr) +
                               " answered " + std::to_string(pkt_.param_count) +
                               " bytes, expected " + std::to_string(len));
    return {pkt_.params.begin(), pkt_.params.begin() + static_cast<std::ptrdiff_t>(len)};
  }
  throw std::runtime_error(name(j, sensor) + ": no answer to a Read of " +
                           register_name(sensor, addr) + " in 3 tries of " +
                           std::to_string(timeout_ns / 1'000'000) +
                           " ms, expected its status packet (is it powered, on this bus, at " +
                           std::to_string(baud_) + " baud, with ID " + std::to_string(id) +
                           " and status return level ≥ 1?)");
}

void XSeriesDriver::write_registers(int j, bool sensor, std::uint16_t addr,
                                    const std::vector<std::uint8_t>& data, std::int64_t timeout_ns) {
  const auto id = static_cast<std::uint8_t>(j + 1 + (sensor ? sensor_offset_ : 0));
  std::size_t n = 0;
  dxl::build_write(id, addr, data, std::span<std::uint8_t>(tx_.data(), dxl::kMaxPacket), n);
  const dxl::Packet& pkt_ = link_.packet();
  if (link_.transact(tx_.data(), n, id, timeout_ns, 0) && (pkt_.error & 0x7F) != 0)
    throw std::runtime_error(name(j, sensor) + ": Write of " + register_name(sensor, addr) +
                             " answered error " + std::to_string(pkt_.error & 0x7F) + " (" +
                             dxl::error_name(pkt_.error) + "), expected 0");
  const std::vector<std::uint8_t> back =
      read_registers(j, sensor, addr, static_cast<std::uint16_t>(data.size()), timeout_ns);
  for (std::size_t k = 0; k < data.size(); ++k) {
    if (back[k] == data[k]) continue;
    throw std::runtime_error(name(j, sensor) + ": " +
                             register_name(sensor, static_cast<std::uint16_t>(addr + k)) + " = " +
                             std::to_string(back[k]) + " after writing it, expected " +
                             std::to_string(data[k]));
  }
}

void XSeriesDriver::configure(std::int64_t reply_timeout_ns) {
  const int want_baud = dxl::baud_index(baud_);
  if (want_baud < 0)
    throw std::invalid_argument("serial bus (X-series): driver.baud = " + std::to_string(baud_) +
                                " has no value in the servos' register 8 (baud rate), expected "
                                "one of 9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000");
  auto check_id_baud = [&](int j, bool sensor, std::uint8_t id, std::uint8_t baud) {
    const int want_id = j + 1 + (sensor ? sensor_offset_ : 0);
    if (id != want_id)
      throw std::runtime_error(name(j, sensor) + ": " + register_name(sensor, dxl::x::kRegId) +
                               " = " + std::to_string(id) + ", expected " + std::to_string(want_id));
    if (baud != want_baud)
      throw std::runtime_error(name(j, sensor) + ": " + register_name(sensor, dxl::x::kRegBaud) +
                               " = " + std::to_string(baud) + " (" + dxl::baud_text(baud) +
                               "), expected " + std::to_string(want_baud) + " (" +
                               dxl::baud_text(want_baud) + ", driver.baud)");
  };
  auto check_hw = [&](int j, bool sensor) {
    const std::uint8_t hw =
        read_registers(j, sensor, dxl::x::kRegHardwareError, 1, reply_timeout_ns)[0];
    if (hw != 0)
      throw std::runtime_error(name(j, sensor) + ": " +
                               register_name(sensor, dxl::x::kRegHardwareError) + " = " +
                               std::to_string(hw) + hw_error_text(hw) +
                               ", expected 0 (a Reboot clears it once the cause is gone)");
  };
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    XSeriesIdentity& who = identity_[ju];
    // The servo: model, firmware, ID, baud, Operating Mode in one Read of 0 … 11.
    const std::vector<std::uint8_t> t = read_registers(j, false, 0, 12, reply_timeout_ns);
    who.model = wire::get_u16(t.data() + dxl::x::kRegModelNumber);
    who.firmware = t[dxl::x::kRegFirmware];
    who.operating_mode = t[dxl::x::kRegOperatingMode];
    if (xseries_model_name(who.model) == nullptr)
      throw std::runtime_error(name(j, false) + ": " + register_name(false, 0) + " = " +
                               std::to_string(who.model) + ", expected " +
                               std::to_string(dxl::x::kModelXM430W350) + " (XM430-W350) or " +
                               std::to_string(dxl::x::kModelXM430W210) +
                               " (XM430-W210): a servo whose current control and Goal Current "
                               "unit (2.69 mA) the driver knows");
    lsb_[ju] = xseries_current_lsb(who.model);
    check_id_baud(j, false, t[dxl::x::kRegId], t[dxl::x::kRegBaud]);
    check_hw(j, false);
    seed_tick(j, reply_timeout_ns);
  }
  // Every servo identified and its clock known before anything is written.
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    XSeriesIdentity& who = identity_[ju];
    // Torque off (the EEPROM area is written only so), then current control and return delay.
    write_registers(j, false, dxl::x::kRegTorqueEnable, {0}, reply_timeout_ns);
    torque_on_[ju] = false;
    if (who.operating_mode != dxl::x::kOperatingModeCurrent) {
      if (!set_mode_)
        throw std::runtime_error(
            name(j, false) + ": " + register_name(false, dxl::x::kRegOperatingMode) + " = " +
            std::to_string(who.operating_mode) + ", expected 0 (current control; " +
            "driver.set_operating_mode: false, so the driver does not change it)");
      write_registers(j, false, dxl::x::kRegOperatingMode, {dxl::x::kOperatingModeCurrent},
                      reply_timeout_ns);
    }
    write_registers(j, false, dxl::x::kRegReturnDelay, {return_delay_steps_}, reply_timeout_ns);
    const std::vector<std::uint8_t> lim =
        read_registers(j, false, dxl::x::kRegCurrentLimit, 2, reply_timeout_ns);
    who.current_limit = wire::get_u16(lim.data());
    if (who.current_limit == 0)
      throw std::runtime_error(name(j, false) + ": " +
                               register_name(false, dxl::x::kRegCurrentLimit) +
                               " = 0, expected > 0 (the servo could deliver no torque)");
    // Bus Watchdog (98): a servo that hears nothing for command_timeout stops by itself (a
    // stock servo otherwise holds its Goal Current when the host is gone). An expired one (−1) is
    // cleared first (0), which also makes its goal writable again.
    write_registers(j, false, dxl::x::kRegBusWatchdog, {0}, reply_timeout_ns);
    write_registers(j, false, dxl::x::kRegGoalCurrent, {0, 0}, reply_timeout_ns);
    write_registers(j, false, dxl::x::kRegBusWatchdog, {watchdog_steps_}, reply_timeout_ns);
    goal_[ju] = 0;
    // The sensor: model, firmware, ID, baud in one Read of 0 … 8; its errors; its return delay.
    const std::vector<std::uint8_t> s = read_registers(j, true, 0, 9, reply_timeout_ns);
    who.sensor_model = wire::get_u16(s.data());
    who.sensor_firmware = s[2];
    if (who.sensor_model != dxl::x::kSensorModelNumber)
      throw std::runtime_error(name(j, true) + ": " + register_name(true, 0) + " = " +
                               std::to_string(who.sensor_model) + ", expected " +
                               std::to_string(dxl::x::kSensorModelNumber) +
                               " (0x5053, a pedalwave deflection sensor)");
    check_id_baud(j, true, s[dxl::x::kRegId], s[dxl::x::kRegBaud]);
    check_hw(j, true);
    write_registers(j, true, dxl::x::kRegReturnDelay, {return_delay_steps_}, reply_timeout_ns);
  }
  link_.clear();
}

// A servo's Realtime Tick against the host's clock, before any answer can be late: Reads of
// register 120, each taken as sampled when the Read had crossed the line (as a Bulk Read's
// sample); the kept minimum drops the ones the host or the link delayed. Spread over ≈ 5 ms so
// the tick's phase varies.
void XSeriesDriver::seed_tick(int j, std::int64_t reply_timeout_ns) {
  std::size_t n = 0;
  std::array<std::uint8_t, dxl::kMaxPacket> req{};
  const auto id = static_cast<std::uint8_t>(j + 1);
  dxl::build_read(id, dxl::x::kRegRealtimeTick, 2, std::span<std::uint8_t>(req.data(), req.size()), n);
  XSeriesTickClock& clock = tick_[static_cast<std::size_t>(j)];
  clock = XSeriesTickClock{};
  for (int round = 0; round < kTickSeedReads; ++round) {
    const std::int64_t sent = detail::monotonic_ns();
    if (link_.transact(req.data(), n, id, reply_timeout_ns, 2)) {
      const dxl::Packet& p = link_.packet();
      if ((p.error & 0x7F) == 0 && p.param_count == 2)
        clock.learn(wire::get_u16(p.params.data()), sent + wire_ns(n));
    }
    const timespec gap = detail::to_timespec(300'000);
    ::clock_nanosleep(CLOCK_MONOTONIC, 0, &gap, nullptr);
  }
  if (!clock.seeded())
    throw std::runtime_error(name(j, false) + ": no answer to " + std::to_string(kTickSeedReads) +
                             " Reads of " + register_name(false, dxl::x::kRegRealtimeTick) +
                             ", expected its millisecond counter (it tells which Bulk Read an "
                             "answer is)");
}

// ---- Cycle -----------------------------------------------------------------------------------------
XSeriesDriver::Dev XSeriesDriver::device_of(std::uint8_t id, int& j) const noexcept {
  if (id >= 1 && id <= joints_) {
    j = id - 1;
    return Dev::kServo;
  }
  if (id > sensor_offset_ && id <= sensor_offset_ + joints_) {
    j = id - 1 - sensor_offset_;
    return Dev::kSensor;
  }
  return Dev::kNone;
}

void XSeriesDriver::on_packet(dxl::DxlStatus s, const dxl::Packet& p, std::int64_t stamp_ns) noexcept {
  if (s == dxl::DxlStatus::kOk) {
    handle_status(p, stamp_ns, before_request_);
    return;
  }
  int j = 0;  // a CRC failure: flag its joint if the ID is one of ours
  if (device_of(p.id, j) != Dev::kNone) status_[static_cast<std::size_t>(j)] |= kStatusChecksum;
}

void XSeriesDriver::handle_status(const dxl::Packet& p, std::int64_t stamp_ns,
                                  bool before_request) noexcept {
  int j = 0;
  const Dev dev = p.instruction == dxl::kInstStatus ? device_of(p.id, j) : Dev::kNone;
  if (dev == Dev::kNone) {
    ++counters_.malformed;
    return;
  }
  const auto ju = static_cast<std::size_t>(j);
  const std::uint8_t err = p.error & 0x7F;
  if (err != 0) {
    if (err == dxl::kErrCrc) {
      ++counters_.checksum;
      status_[ju] |= kStatusChecksum;
    } else {
      ++counters_.malformed;
    }
    return;
  }
  // A status packet carries no cycle counter: what was waiting before the request answers an
  // older Bulk Read — taken as the previous one's (kept for a joint without a fresh answer) —, what
  // comes after the deadline is late (read at the next cycle's start is too late now: dropped);
  // a second answer of a device in one cycle means the first one was an older Bulk Read's
  // (late), and the newer one is kept.
  // An answer received before this request's last byte could have crossed the line and a status
  // packet come back is no answer to it either: an older one, delivered late (a loaded host).
  // Beyond those physical bounds the servo's Realtime Tick says which Bulk Read an answer is
  // (XSeriesTickClock): this one's (taken late by more than the tick's resolution: its values,
  // no time), the previous one's (a late answer), or older still (dropped). A sensor's answer
  // follows its servo's in the Bulk Read, so it is the Bulk Read of its servo's last answer.
  const bool servo = dev == Dev::kServo;
  if (p.param_count != (servo ? dxl::x::kFeedbackSize : 2u)) {
    ++counters_.malformed;
    return;
  }
  dxl::x::PresentValues sv{};
  if (servo) dxl::x::decode_present_values(p.params.data(), lsb_[ju], sv);
  const bool ticks = tick_[ju].seeded();
  bool older = before_request || stamp_ns < sample_ns_ + min_reply_ns_;
  bool untimed = false;
  if (ticks) {
    std::uint64_t req = 0;  // the Bulk Read it answers: cycle_ (this one), cycle_ − 1, 0 older
    if (servo) {
      const auto fits = [](std::int64_t e) { return e >= -kTickSlackNs && e < XSeriesTickClock::kTickNs + kTickSlackNs; };
      // Before this request, sample_ns_ is still the previous Bulk Read's time.
      const std::int64_t e = tick_[ju].place(sv.tick, sample_ns_);
      const std::int64_t e_prev = before_request ? e : tick_[ju].place(sv.tick, prev_sample_ns_);
      if (!before_request && fits(e)) {
        req = cycle_;
      } else if (!before_request && e >= XSeriesTickClock::kTickNs + kTickSlackNs) {
        req = cycle_;
        untimed = true;
      } else if (fits(e_prev)) {
        req = cycle_ - 1;
      }
      if (untimed) ++tick_delayed_;
      if (req == 0) ++tick_stale_;
      servo_req_[ju] = req;
    } else {
      req = servo_req_[ju];  // (its time, if its servo's had none, goes with the servo's flag)
    }
    if (req == 0) {  // an answer to a Bulk Read before the previous one: nothing to use
      ++counters_.late;
      status_[ju] |= kStatusLate;
      return;
    }
    older = older || req != cycle_;
  }
  if (older || stamp_ns > deadline_ns_) {
    ++counters_.late;
    status_[ju] |= kStatusLate;
    if (older && servo) {
      late_servo_[ju] = sv;
      late_servo_got_[ju] = true;
    } else if (older) {
      late_sensor_[ju] = wire::get_i16(p.params.data()) * wire::kDeflectionLsb;
      late_sensor_got_[ju] = true;
    }
    return;
  }
  bool& got = servo ? got_servo_[ju] : got_sensor_[ju];
  if (got) {
    ++counters_.late;
    status_[ju] |= kStatusLate;
  } else {
    ++fresh_packets_;
  }
  got = true;
  if (stamp_ns > stamp_ns_) stamp_ns_ = stamp_ns;
  if (servo) {
    servo_[ju] = sv;
    untimed_[ju] = untimed;
    // A servo answer taken when the host said: its tick joins the kept minimum.
    if (ticks && !untimed) tick_[ju].learn(sv.tick, sample_ns_);
    // The alert bit: a Hardware Error Status ≠ 0, and an X-series servo then holds torque off.
    alert_[ju] = static_cast<std::uint16_t>(
        (alert_[ju] & ~kStatusTorqueOff) | ((p.error & dxl::kErrAlert) ? kStatusTorqueOff : 0));
  } else {
    sensor_[ju] = wire::get_i16(p.params.data()) * wire::kDeflectionLsb;
    alert_[ju] = static_cast<std::uint16_t>(
        (alert_[ju] & ~kStatusEncoderFault) |
        ((p.error & dxl::kErrAlert) ? kStatusEncoderFault : 0));
  }
}

IoStatus XSeriesDriver::read(std::int64_t /*now_ns*/, std::int64_t deadline_ns, Feedback& out) {
  ++cycle_;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    status_[ju] = 0;
    got_servo_[ju] = got_sensor_[ju] = false;
    late_servo_got_[ju] = late_sensor_got_[ju] = false;
    untimed_[ju] = false;
  }
  fresh_packets_ = 0;
  stamp_ns_ = 0;
  deadline_ns_ = deadline_ns;

  // 1. What is already here answers older Bulk Reads. A packet still incomplete is a short read.
  before_request_ = true;
  link_.receive(detail::monotonic_ns(), counters_, *this);
  link_.drop_partial(counters_);
  before_request_ = false;

  // 2. The Bulk Read: every servo and sensor samples when it has arrived.
  const std::int64_t t0 = detail::monotonic_ns();
  prev_sample_ns_ = sample_ns_;
  prev_applied_seq_ = sample_applied_seq_;
  prev_applied_ns_ = sample_applied_ns_;
  sample_ns_ = t0 + bulk_wire_ns_;
  sample_applied_seq_ = applied_seq_;
  sample_applied_ns_ = applied_ns_;
  const bool sent = link_.write_all(bulk_tx_.data(), bulk_len_, deadline_ns);
  // Nothing samples before the request has been handed to the kernel: a host preempted between
  // its clock read and the write (a loaded machine: milliseconds) put the sample that much early,
  // and the observer's consistency check saw c ≈ that time × β̇ (0.013 rad over an overrun).
  sample_ns_ = std::max(sample_ns_, detail::monotonic_ns());
  if (sent) {
    ++counters_.frames_tx;
  } else {
    ++counters_.tx_dropped;
  }

  // 3. Gather the 2J status packets until the deadline.
  if (sent) link_.gather(deadline_ns, counters_, *this, fresh_packets_, 2 * joints_);

  out.joints = joints_;
  out.seq = cycle_;
  out.stamp_ns = fresh_packets_ > 0 ? stamp_ns_ : detail::monotonic_ns();
  out.timing = FeedbackTiming::kModule;
  int fresh = 0, late_used = 0;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    std::uint16_t st = status_[ju];
    out.late_applied_ns[ju] = 0;
    // Hand out a sample: the servo's and sensor's values, when they were sampled, and the command
    // in effect then (age: cycles since that Bulk Read).
    const auto hand_out = [&](const dxl::x::PresentValues& sv, double defl, std::int64_t at,
                              std::uint64_t seq, const std::array<std::int64_t, kMaxJoints>& when,
                              std::uint64_t age) {
      last_[ju] = JointSample{sv.position, sv.velocity, defl, 0};
      have_sample_[ju] = true;
      out.sample_ns[ju] = at;
      out.applied_seq[ju] = seq;
      out.applied_ns[ju] = seq == kNoCommandSeq ? 0 : when[ju];
      handed_ns_[ju] = at;
      age_[ju] = age;
    };
    if (got_servo_[ju] && got_sensor_[ju]) {
      hand_out(servo_[ju], sensor_[ju], sample_ns_, applied_seq_, applied_ns_, 0);
      if (untimed_[ju]) {
        // This Bulk Read's values, sampled later than the host can say (the request was
        // delivered late): the law uses them, the observer bridges them (no time).
        st |= kStatusNoTiming;
        out.sample_ns[ju] = 0;
        out.applied_ns[ju] = 0;
      }
      ++fresh;
    } else if (late_servo_got_[ju] && late_sensor_got_[ju] && prev_sample_ns_ > handed_ns_[ju]) {
      // No fresh answer, but the previous Bulk Read's came late: an older sample, at its time.
      hand_out(late_servo_[ju], late_sensor_[ju], prev_sample_ns_, prev_applied_seq_, prev_applied_ns_, 1);
      ++counters_.late_used;
      ++late_used;
    } else {
      st |= kStatusMissing;
      ++counters_.missing;
      out.sample_ns[ju] = 0;
    }
    // How old the values a host law acts on are: 0 fresh, 1 the previous Bulk Read's (late),
    // one more per cycle without either. Beyond stale_limit the law is blind: kStatusStaleFeedback,
    // and write() gives the servo no torque until a sample comes again.
    if (st & kStatusMissing) ++age_[ju];
    if (have_sample_[ju] && age_[ju] > 0) {
      ++counters_.held;
      if (age_[ju] > counters_.held_age_max) counters_.held_age_max = age_[ju];
    }
    if (have_sample_[ju] && age_[ju] > static_cast<std::uint64_t>(stale_limit_)) {
      st |= kStatusStaleFeedback;
      ++counters_.stale_feedback;
    }
    if (!torque_on_[ju]) st |= kStatusTorqueOff;
    if (goal_flags_[ju] & wire::kQuantClamped) st |= kStatusSaturated;
    JointSample sample = last_[ju];
    sample.status = static_cast<std::uint16_t>(st | alert_[ju]);
    out.set_joint(ju, sample);
  }
  if (!sent) return IoStatus::kBusError;
  if (fresh + late_used == 0) return IoStatus::kTimeout;
  if (fresh + late_used < joints_) return IoStatus::kPartial;
  return IoStatus::kOk;
}

bool XSeriesDriver::send(const Command* cmd, std::int64_t until_ns) noexcept {
  const auto count = static_cast<std::size_t>(joints_);
  std::array<bool, kMaxJoints> on{};
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    std::uint8_t flags = 0;
    std::int16_t g = 0;
    on[ju] = cmd != nullptr && !cmd->torque_off && j < cmd->joints;
    if (on[ju]) {
      // The module law, on the host, from the sample handed out last (PROTOCOL.md §3.6).
      double u = cmd->tau[ju];
      if (cmd->kp[ju] != 0.0 || cmd->kd[ju] != 0.0) {
        u = module_law(cmd->tau[ju], cmd->kp[ju], cmd->beta_ref[ju], cmd->kd[ju], cmd->beta_dot_ref[ju],
                       last_[ju].beta, last_[ju].beta_dot);
        if (!have_sample_[ju]) u = std::nan("");  // no sample yet: no law to evaluate
      }
      // The controller's host-side PD (pd_placement: host) is in τ: on a sample older than
      // stale_limit cycles it is blind, and the servo gets no torque (it stays enabled).
      if (have_sample_[ju] && age_[ju] > static_cast<std::uint64_t>(stale_limit_)) u = 0.0;
      g = dxl::x::goal_current(u, k_t_, lsb_[ju], identity_[ju].current_limit, flags);
      if (flags & wire::kQuantNotFinite) on[ju] = false;  // NaN/Inf: torque off, as a module
    }
    goal_flags_[ju] = flags;
    wire::put_i16(data_.data() + 2 * ju, on[ju] ? g : std::int16_t{0});
  }
  // Goal Current to every servo, then Torque Enable where it changes.
  std::size_t n = 0, first = 0;
  if (dxl::build_sync_write(dxl::x::kRegGoalCurrent, 2, std::span<const std::uint8_t>(ids_.data(), count),
                            std::span<const std::uint8_t>(data_.data(), 2 * count),
                            std::span<std::uint8_t>(tx_.data(), dxl::kMaxPacket), first) != dxl::DxlStatus::kOk)
    return false;
  n = first;
  for (int value = 0; value <= 1; ++value) {
    std::size_t k = 0;
    for (int j = 0; j < joints_; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      if (on[ju] == (value == 1) && (torque_on_[ju] != on[ju] || cmd == nullptr))
        sel_ids_[k++] = ids_[ju];  // safe_stop(): Torque Enable 0 to every servo, whatever it was
    }
    if (k == 0) continue;
    std::array<std::uint8_t, kMaxJoints> v{};
    v.fill(static_cast<std::uint8_t>(value));
    std::size_t m = 0;
    if (dxl::build_sync_write(dxl::x::kRegTorqueEnable, 1,
                              std::span<const std::uint8_t>(sel_ids_.data(), k),
                              std::span<const std::uint8_t>(v.data(), k),
                              std::span<std::uint8_t>(tx_.data() + n, tx_.size() - n), m) != dxl::DxlStatus::kOk)
      return false;
    n += m;
  }
  const std::int64_t t0 = detail::monotonic_ns();
  if (!link_.write_all(tx_.data(), n, until_ns)) {
    ++counters_.tx_dropped;
    return false;
  }
  const std::int64_t written = detail::monotonic_ns();  // no servo acts before this
  counters_.frames_tx += n > first ? 2 : 1;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    // A goal acts when its Sync Write has arrived; a torque switch when the whole buffer has.
    applied_ns_[ju] = std::max(written, t0 + wire_ns(torque_on_[ju] != on[ju] ? n : first));
    torque_on_[ju] = on[ju];
    goal_[ju] = on[ju] ? wire::get_i16(data_.data() + 2 * ju) : std::int16_t{0};
  }
  return true;
}

FeedbackSpec XSeriesDriver::feedback_spec() const {
  FeedbackSpec f;
  f.beta_lsb = dxl::x::kPositionLsb;         // Present Position: 4096 per revolution
  f.beta_dot_lsb = dxl::x::kVelocityLsb;     // Present Velocity: 0.229 rev/min
  f.deflection_lsb = wire::kDeflectionLsb;   // the sensor's deflection (124)
  for (int j = 0; j < joints_; ++j)          // Goal Current: the servo's current LSB × k_t
    f.torque_lsb = std::max(f.torque_lsb, lsb_[static_cast<std::size_t>(j)] * k_t_);
  // A servo samples when the Bulk Read reaches it; the host stamps that as its send time + wire
  // time. The request's delivery varies by the adapter's (USB-serial: 1 ms latency timer) or the
  // kernel's (a pty's flip buffer on a loaded host) jitter.
  f.sample_time_uncertainty = 1e-3;
  f.stale_limit = stale_limit_;
  return f;
}

IoStatus XSeriesDriver::write(const Command& cmd) {
  if (!send(&cmd, detail::monotonic_ns() + write_timeout_ns_)) return IoStatus::kBusError;
  applied_seq_ = cmd.seq;
  return IoStatus::kOk;
}

void XSeriesDriver::safe_stop() {
  if (send(nullptr, detail::monotonic_ns() + 20'000'000)) applied_seq_ = kNoCommandSeq;
}

}  // namespace pedalwave::drivers
