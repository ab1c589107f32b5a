#include "pedalwave/drivers/serial_driver.hpp"

#include <fcntl.h>
#include <linux/serial.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <system_error>

#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/wire.hpp"
#include "pedalwave/drivers/xseries_driver.hpp"
#include "pedalwave/drivers/posix_util.hpp"

namespace pedalwave::drivers {
namespace {

// kSerialBauds → termios' constants; a rate of the list missing here does not compile (below).
constexpr speed_t speed_of(int baud) {
  switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 500000: return B500000;
    case 921600: return B921600;
    case 1000000: return B1000000;
    case 1500000: return B1500000;
    case 2000000: return B2000000;
    case 3000000: return B3000000;
    case 4000000: return B4000000;
    default:
      throw std::invalid_argument("serial baud = " + std::to_string(baud) + ", expected one of " +
                                  serial_bauds_text());
  }
}
static_assert([] {
  for (int b : kSerialBauds) (void)speed_of(b);  // the throw is not a constant expression
  return true;
}());

}  // namespace

std::string serial_bauds_text() {
  std::string s;
  for (int b : kSerialBauds) s += (s.empty() ? "" : ", ") + std::to_string(b);
  return s;
}

int open_serial_port(const std::string& path, int baud) {
  const speed_t speed = speed_of(baud);
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0)
    throw std::system_error(errno, std::generic_category(), "serial port '" + path + "': open");
  termios t{};
  if (::tcgetattr(fd, &t) != 0) {
    const int e = errno;
    ::close(fd);
    throw std::system_error(e, std::generic_category(),
                            "serial port '" + path + "': not a terminal (tcgetattr)");
  }
  ::cfmakeraw(&t);                 // 8 data bits, no parity, no echo, no line processing
  t.c_cflag &= ~static_cast<tcflag_t>(CSTOPB | CRTSCTS);  // 1 stop bit, no hardware flow control
  t.c_cflag |= CLOCAL | CREAD;
  t.c_iflag &= ~static_cast<tcflag_t>(IXON | IXOFF | IXANY);
  t.c_cc[VMIN] = 0;
  t.c_cc[VTIME] = 0;
  if (::cfsetispeed(&t, speed) != 0 || ::cfsetospeed(&t, speed) != 0 ||
      ::tcsetattr(fd, TCSANOW, &t) != 0) {
    const int e = errno;
    ::close(fd);
    throw std::system_error(e, std::generic_category(),
                            "serial port '" + path + "': baud " + std::to_string(baud));
  }
  // Ask a USB-serial driver for low latency (ignored where unsupported, e.g. a pty).
  serial_struct ss{};
  if (::ioctl(fd, TIOCGSERIAL, &ss) == 0) {
    ss.flags |= ASYNC_LOW_LATENCY;
    (void)::ioctl(fd, TIOCSSERIAL, &ss);
  }
  ::tcflush(fd, TCIOFLUSH);
  return fd;
}

std::unique_ptr<SerialDriver> SerialDriver::open(const SerialConfig& cfg) {
  SerialBusSpec spec{cfg.joints, cfg.period_s, cfg.baud, cfg.return_delay_s, cfg.turnaround_s,
                     cfg.max_load};
  spec.x_series = cfg.devices == SerialDevices::kXSeries;
  check_serial_bus_budget(spec);
  auto d = std::make_unique<SerialDriver>(open_serial_port(cfg.device, cfg.baud), cfg);
  d->configure_modules();
  return d;
}

SerialDriver::SerialDriver(int fd, const SerialConfig& cfg)
    : fd_(fd), joints_(cfg.joints), write_timeout_ns_(cfg.write_timeout_ns) {
  link_.attach(fd);
  baud_ = cfg.baud;
  if (cfg.devices == SerialDevices::kXSeries) {  // stock servos + sensors: another driver
    fd_ = -1;
    x_ = std::make_unique<XSeriesDriver>(fd, cfg);
    return;
  }
  try {
    if (fd < 0)
      throw std::invalid_argument("SerialDriver: fd = " + std::to_string(fd) +
                                  ", expected an open tty");
    // What configure_modules() writes: in the registers' steps and ranges.
    const double steps = std::round(cfg.return_delay_s / 2e-6);
    if (!(steps >= 0 && steps <= 254))
      throw std::invalid_argument("serial driver: return_delay = " + std::to_string(cfg.return_delay_s) +
                                  " s, expected 0 … 508e-6 s (the modules' register 9: 0 … 254 × 2 µs)");
    return_delay_steps_ = static_cast<std::uint8_t>(steps);
    const double ms = std::round(cfg.command_timeout_s * 1e3);
    if (!(ms >= 1 && ms <= 65535))
      throw std::invalid_argument("serial driver: command_timeout = " + std::to_string(cfg.command_timeout_s) +
                                  " s, expected 0.001 … 65.535 s (the modules' register 10, 1 ms steps)");
    command_timeout_ms_ = static_cast<std::uint16_t>(ms);
    check_serial_bus_budget({cfg.joints, cfg.period_s, cfg.baud, cfg.return_delay_s,
                             cfg.turnaround_s, cfg.max_load});
    if (!detail::set_nonblocking(fd))
      throw std::system_error(errno, std::generic_category(), "SerialDriver: O_NONBLOCK");
    for (int j = 0; j < joints_; ++j) ids_[static_cast<std::size_t>(j)] = static_cast<std::uint8_t>(j + 1);
    // The Sync Read never changes: build it once, behind room for the sync-counter write.
    std::size_t n = 0;
    if (dxl::build_sync_read(dxl::kRegFeedback, dxl::kFeedbackBlockSize,
                             std::span<const std::uint8_t>(ids_.data(), static_cast<std::size_t>(joints_)),
                             std::span<std::uint8_t>(sync_tx_.data() + 16, sync_tx_.size() - 16),
                             n) != dxl::DxlStatus::kOk)
      throw std::invalid_argument("SerialDriver: cannot build the Sync Read packet");
    sync_read_len_ = n;
    sync_wire_ns_ = std::llround(13 * 10.0 * 1e9 / cfg.baud);  // the 13-byte sync-counter write
  } catch (...) {
    if (fd >= 0) ::close(fd);
    fd_ = -1;
    throw;
  }
}

// ---- Configuration -------------------------------------------------------------------------------
namespace {
std::string module_name(int j) {
  return "serial bus: module ID " + std::to_string(j + 1) + " (joint " + std::to_string(j + 1) + ")";
}
std::string register_name(std::uint16_t addr) {
  const dxl::Register* r = dxl::register_at(addr);
  return "register " + std::to_string(addr) + " (" + (r ? r->name : "?") + ")";
}
}  // namespace

std::vector<std::uint8_t> SerialDriver::read_registers(int j, std::uint16_t addr, std::uint16_t len,
                                                       std::int64_t timeout_ns) {
  const auto id = static_cast<std::uint8_t>(j + 1);
  std::size_t n = 0;
  dxl::build_read(id, addr, len, tx_, n);
  for (int attempt = 0; attempt < 3; ++attempt) {
    if (!link_.transact(tx_.data(), n, id, timeout_ns)) continue;
    const dxl::Packet& pkt_ = link_.packet();
    if ((pkt_.error & 0x7F) != 0)
      throw std::runtime_error(module_name(j) + ": Read of " + register_name(addr) + ", " +
                               std::to_string(len) + " bytes, answered error " +
                               std::to_string(pkt_.error & 0x7F) + " (" + dxl::error_name(pkt_.error) +
                               "), expected its value");
    if (pkt_.param_count != len)
      throw std::runtime_error(module_name(j) + ": Read of " + register_name(addr) + " answered " +
                               std::to_string(pkt_.param_count) + " bytes, expected " +
                               std::to_string(len));
    return {pkt_.params.begin(), pkt_.params.begin() + static_cast<std::ptrdiff_t>(len)};
  }
  throw std::runtime_error(module_name(j) + ": no answer to a Read of " + register_name(addr) +
                           " in 3 tries of " + std::to_string(timeout_ns / 1'000'000) +
                           " ms, expected its status packet (is it powered, on this bus, at " +
                           std::to_string(baud_) + " baud, with ID " + std::to_string(j + 1) +
                           " and status return level ≥ 1?)");
}

void SerialDriver::write_registers(int j, std::uint16_t addr, const std::vector<std::uint8_t>& data,
                                   std::int64_t timeout_ns) {
  const auto id = static_cast<std::uint8_t>(j + 1);
  std::size_t n = 0;
  dxl::build_write(id, addr, data, tx_, n);
  // At status return level 2 the Write is answered; below it, the read back below decides.
  const dxl::Packet& pkt_ = link_.packet();
  if (link_.transact(tx_.data(), n, id, timeout_ns) && (pkt_.error & 0x7F) != 0)
    throw std::runtime_error(module_name(j) + ": Write of " + register_name(addr) +
                             " answered error " + std::to_string(pkt_.error & 0x7F) + " (" +
                             dxl::error_name(pkt_.error) + "), expected 0");
  const std::vector<std::uint8_t> back =
      read_registers(j, addr, static_cast<std::uint16_t>(data.size()), timeout_ns);
  for (std::size_t k = 0; k < data.size(); ++k) {
    if (back[k] == data[k]) continue;
    const auto a = static_cast<std::uint16_t>(addr + k);
    throw std::runtime_error(module_name(j) + ": " + register_name(a) + " = " +
                             std::to_string(back[k]) + " after writing it, expected " +
                             std::to_string(data[k]));
  }
}

const ModuleIdentity& SerialDriver::identity(int j) const {
  return identity_[static_cast<std::size_t>(j)];
}

const DriverCounters& SerialDriver::counters() const { return x_ ? x_->counters() : counters_; }

FeedbackSpec SerialDriver::feedback_spec() const {
  if (x_) return x_->feedback_spec();
  FeedbackSpec f;
  f.beta_lsb = wire::kBetaLsb;
  f.beta_dot_lsb = wire::kBetaDotLsb;
  f.deflection_lsb = wire::kDeflectionLsb;
  f.torque_lsb = wire::kTauLsb;
  return f;
}

void SerialDriver::configure_modules(std::int64_t reply_timeout_ns) {
  if (x_) {
    x_->configure(reply_timeout_ns);
    return;
  }
  const int want_baud = dxl::baud_index(baud_);
  if (want_baud < 0)
    throw std::invalid_argument("serial bus: driver.baud = " + std::to_string(baud_) +
                                " has no value in the modules' register 8 (baud rate), expected "
                                "one of 9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000");
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    // 1. Who is it: model number and firmware (registers 0 … 2).
    const std::vector<std::uint8_t> who = read_registers(j, dxl::kRegModelNumber, 3, reply_timeout_ns);
    identity_[ju].model = wire::get_u16(who.data());
    identity_[ju].firmware = who[2];
    if (identity_[ju].model != dxl::kModelNumber)
      throw std::runtime_error(module_name(j) + ": " + register_name(dxl::kRegModelNumber) + " = " +
                               std::to_string(identity_[ju].model) + ", expected " +
                               std::to_string(dxl::kModelNumber) + " (0x5057, a pedalwave module)");
    // 2. ID and baud rate (registers 7, 8) as configured.
    const std::vector<std::uint8_t> eeprom = read_registers(j, dxl::kRegId, 2, reply_timeout_ns);
    if (eeprom[0] != j + 1)
      throw std::runtime_error(module_name(j) + ": " + register_name(dxl::kRegId) + " = " +
                               std::to_string(eeprom[0]) + ", expected " + std::to_string(j + 1));
    if (eeprom[1] != want_baud)
      throw std::runtime_error(module_name(j) + ": " + register_name(dxl::kRegBaud) + " = " +
                               std::to_string(eeprom[1]) + " (" + dxl::baud_text(eeprom[1]) +
                               "), expected " + std::to_string(want_baud) + " (" +
                               dxl::baud_text(want_baud) + ", driver.baud)");
    // 3. No hardware error (register 70).
    const std::uint8_t hw = read_registers(j, dxl::kRegHardwareError, 1, reply_timeout_ns)[0];
    if (hw != 0)
      throw std::runtime_error(module_name(j) + ": " + register_name(dxl::kRegHardwareError) +
                               " = " + std::to_string(hw) +
                               ((hw & dxl::kHwErrOverheating) ? " (overheating)" : "") +
                               ((hw & dxl::kHwErrEncoder) ? " (encoder fault)" : "") +
                               ", expected 0");
    // 4. Torque off (the EEPROM area is written only so), then return delay and command timeout
    //    (registers 9, 10), read back.
    write_registers(j, dxl::kRegTorqueEnable, {0}, reply_timeout_ns);
    write_registers(j, dxl::kRegReturnDelay,
                    {return_delay_steps_, static_cast<std::uint8_t>(command_timeout_ms_ & 0xFF),
                     static_cast<std::uint8_t>(command_timeout_ms_ >> 8)},
                    reply_timeout_ns);
  }
  link_.clear();
}

SerialDriver::~SerialDriver() {
  if (fd_ >= 0) ::close(fd_);
}

void SerialDriver::on_packet(dxl::DxlStatus s, const dxl::Packet& p, std::int64_t stamp_ns) noexcept {
  if (s == dxl::DxlStatus::kOk) {
    handle_status(p, stamp_ns);
    return;
  }
  const int j = p.id - 1;  // a CRC failure: flag its joint if the ID is one of ours
  if (j >= 0 && j < joints_) status_[static_cast<std::size_t>(j)] |= kStatusChecksum;
}

void SerialDriver::handle_status(const dxl::Packet& p, std::int64_t stamp_ns) noexcept {
  const int j = p.id - 1;
  if (p.instruction != dxl::kInstStatus || j < 0 || j >= joints_) {
    ++counters_.malformed;
    return;
  }
  const auto ju = static_cast<std::size_t>(j);
  const std::uint8_t err = p.error & 0x7F;
  if (err != 0) {  // the module could not process our packet: no valid data
    if (err == dxl::kErrCrc) {
      ++counters_.checksum;
      status_[ju] |= kStatusChecksum;
    } else {
      ++counters_.malformed;
    }
    return;
  }
  if (p.param_count != dxl::kFeedbackBlockSize) {
    ++counters_.malformed;
    return;
  }
  dxl::FeedbackBlock fb{};
  dxl::decode_feedback_block(p.params.data(), fb);
  const std::uint64_t answered = track_[ju].take(fb.echo, 256, cycle_);
  FrameAge age = classify_frame(rc_[ju], fb.echo, counter_, cycle_, 256);
  if (age == FrameAge::kFresh && stamp_ns > deadline_ns_) {
    rc_[ju].fresh = false;
    age = FrameAge::kLate;
  }
  switch (age) {
    case FrameAge::kFresh:
      last_[ju] = fb;
      ++fresh_count_;
      if (stamp_ns > stamp_ns_) stamp_ns_ = stamp_ns;
      fresh_answered_[ju] = answered;
      fresh_sure_[ju] = track_[ju].sure() && answered == cycle_;
      break;
    case FrameAge::kDuplicate:
      ++counters_.duplicate;
      status_[ju] |= kStatusStale;
      break;
    case FrameAge::kLate:
      ++counters_.late;
      status_[ju] |= kStatusLate;
      late_[ju].offer_values(fb.echo, answered, track_[ju].sure() && answered != 0, fb.sample);
      late_[ju].offer_timing(fb.echo, fb.timing);
      break;
    case FrameAge::kOutOfOrder:
      ++counters_.out_of_order;
      status_[ju] |= kStatusOutOfOrder;
      break;
  }
}

void SerialDriver::poll_overruns() noexcept {
  if (!icount_ok_) return;
  serial_icounter_struct ic{};
  if (::ioctl(fd_, TIOCGICOUNT, &ic) != 0) {
    icount_ok_ = false;  // not a UART (pty, some USB adapters)
    return;
  }
  const auto total = static_cast<std::uint64_t>(ic.overrun) + static_cast<std::uint64_t>(ic.buf_overrun);
  if (total > overruns_) counters_.rx_dropped += total - overruns_;
  overruns_ = total;
}

IoStatus SerialDriver::read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) {
  if (x_) return x_->read(now_ns, deadline_ns, out);
  ++cycle_;
  counter_ = static_cast<std::uint8_t>(counter_ + 1);
  for (int j = 0; j < joints_; ++j) {
    drivers::begin_cycle(rc_[static_cast<std::size_t>(j)]);
    status_[static_cast<std::size_t>(j)] = 0;
    late_[static_cast<std::size_t>(j)].clear();
  }
  fresh_count_ = 0;
  stamp_ns_ = 0;
  deadline_ns_ = deadline_ns;
  poll_overruns();

  // 1. What is already here answers older cycles. A packet still incomplete is a short read.
  link_.receive(detail::monotonic_ns(), counters_, *this);
  link_.drop_partial(counters_);

  // 2. SYNC (broadcast write of c to the sync-counter register) + Sync Read, in one write.
  const std::uint8_t reg[3] = {static_cast<std::uint8_t>(dxl::kRegSyncCounter & 0xFF),
                               static_cast<std::uint8_t>(dxl::kRegSyncCounter >> 8), counter_};
  std::size_t n = 0;
  dxl::build_instruction(dxl::kBroadcastId, dxl::kInstWrite, reg,
                         std::span<std::uint8_t>(sync_tx_.data(), 16), n);
  // Close the gap between the two packets (the Sync Read was built at offset 16).
  std::memmove(sync_tx_.data() + n, sync_tx_.data() + 16, sync_read_len_);
  sync_lower_ns_ = detail::monotonic_ns() + sync_wire_ns_;
  log_.sync(cycle_, sync_lower_ns_);
  const bool sent = link_.write_all(sync_tx_.data(), n + sync_read_len_, deadline_ns);
  std::memmove(sync_tx_.data() + 16, sync_tx_.data() + n, sync_read_len_);
  if (sent) {
    counters_.frames_tx += 2;
  } else {
    ++counters_.tx_dropped;
  }

  // 3. Gather the status packets until all are fresh or the deadline passes.
  if (sent) link_.gather(deadline_ns, counters_, *this, fresh_count_, joints_);

  out.joints = joints_;
  out.seq = cycle_;
  out.stamp_ns = fresh_count_ > 0 ? stamp_ns_ : detail::monotonic_ns();
  out.timing = FeedbackTiming::kModule;
  int late_used = 0;  // joints whose sample is a late answer (PROTOCOL.md §4)
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    std::uint16_t st = status_[ju];
    out.sample_ns[ju] = 0;
    out.late_applied_ns[ju] = 0;
    ModuleClock& clk = clocks_[ju];
    const LateSample& late = late_[ju];
    // A late record (its values not used) tells when the module applied which command (placed
    // for sure among the host's cycles).
    if (late.complete() && late.sure && clk.started() && !late.timing.no_command) {
      out.late_applied_ns[ju] = applied_host_ns(late.timing, clk);
      out.late_applied_seq[ju] = log_.applied(late.answered, late.timing.applied_tag, 256);
      if (out.late_applied_seq[ju] == kUnknownSeq) out.late_applied_ns[ju] = 0;
    }
    if (rc_[ju].fresh) {
      hand_out(last_[ju].timing, log_, fresh_answered_[ju], fresh_sure_[ju], 256, clk, handed_[ju],
               out, ju);
    } else if (late.complete() && handed_[ju].newer(late.timing.sample_us)) {
      // No fresh answer, but a late one: an older sample at its own (module) time. It updates the
      // clock with the lower bound of the SYNC it answered.
      const wire::ModuleTiming& t = late.timing;
      last_[ju] = dxl::FeedbackBlock{late.values, late.values_echo, t};
      hand_out(t, log_, late.answered, late.sure, 256, clk, handed_[ju], out, ju);
      out.late_applied_ns[ju] = 0;
      ++counters_.late_used;
      ++late_used;
    } else {
      st |= kStatusMissing;
      ++counters_.missing;
    }
    track_[ju].end_cycle(cycle_, rc_[ju].fresh);
    JointSample sample = last_[ju].sample;
    sample.status = static_cast<std::uint16_t>(st | sample.status);
    out.set_joint(ju, sample);
  }
  if (!sent) return IoStatus::kBusError;
  if (fresh_count_ + late_used == 0) return IoStatus::kTimeout;
  if (fresh_count_ + late_used < joints_) return IoStatus::kPartial;
  return IoStatus::kOk;
}

bool SerialDriver::send_commands(const Command* cmd, bool all_off, std::int64_t until_ns) noexcept {
  if (cmd) log_.command(cycle_, cmd->seq);
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    dxl::CommandBlock b{};
    b.counter = counter_;
    b.torque_off = all_off || cmd == nullptr || cmd->torque_off || j >= cmd->joints;
    if (!b.torque_off) {
      b.tau = cmd->tau[ju];
      b.beta_ref = cmd->beta_ref[ju];
      b.beta_dot_ref = cmd->beta_dot_ref[ju];
      b.kp = cmd->kp[ju];
      b.kd = cmd->kd[ju];
    }
    dxl::encode_command_block(b, blocks_.data() + ju * dxl::kCommandBlockSize);
  }
  std::size_t n = 0;
  const auto count = static_cast<std::size_t>(joints_);
  if (dxl::build_sync_write(dxl::kRegCommand, dxl::kCommandBlockSize,
                            std::span<const std::uint8_t>(ids_.data(), count),
                            std::span<const std::uint8_t>(blocks_.data(), count * dxl::kCommandBlockSize),
                            tx_, n) != dxl::DxlStatus::kOk)
    return false;
  if (!link_.write_all(tx_.data(), n, until_ns)) {
    ++counters_.tx_dropped;
    return false;
  }
  ++counters_.frames_tx;
  return true;
}

IoStatus SerialDriver::write(const Command& cmd) {
  if (x_) return x_->write(cmd);
  return send_commands(&cmd, false, detail::monotonic_ns() + write_timeout_ns_)
             ? IoStatus::kOk
             : IoStatus::kBusError;
}

void SerialDriver::safe_stop() {
  if (x_) return x_->safe_stop();
  send_commands(nullptr, true, detail::monotonic_ns() + 20'000'000);
}

}  // namespace pedalwave::drivers
