#include "pedalwave/drivers/canopen_driver.hpp"

#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <system_error>

#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/can_io.hpp"
#include "pedalwave/drivers/posix_util.hpp"

namespace pedalwave::drivers {
namespace {

namespace co = canopen;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr canid_t kTpdo1 = 0x180, kTpdo2 = 0x280, kRpdo1 = 0x200, kRpdo2 = 0x300;

std::uint32_t mapping(std::uint16_t index, std::uint8_t sub, int bits) {
  return (std::uint32_t{index} << 16) | (std::uint32_t{sub} << 8) | static_cast<std::uint32_t>(bits);
}
std::uint16_t u16(const std::uint8_t* p) noexcept { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
std::uint32_t u32(const std::uint8_t* p) noexcept {
  return std::uint32_t{p[0]} | (std::uint32_t{p[1]} << 8) | (std::uint32_t{p[2]} << 16) | (std::uint32_t{p[3]} << 24);
}
void put16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
void put32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
std::int32_t to_i32(double v) noexcept {
  if (!std::isfinite(v)) return 0;
  return static_cast<std::int32_t>(std::clamp(std::llround(v), -2147483648LL, 2147483647LL));
}
std::int16_t to_i16(double v) noexcept {
  if (!std::isfinite(v)) return 0;
  return static_cast<std::int16_t>(std::clamp(std::llround(v), -32768LL, 32767LL));
}
std::string hex(std::uint32_t v, int w) {
  char b[16];
  std::snprintf(b, sizeof b, "%0*Xh", w, v);
  return b;
}

}  // namespace

CanBusSpec can_bus_spec(const SocketCanConfig& cfg) noexcept {
  CanBusSpec s{cfg.joints, cfg.period_s, cfg.bitrate, cfg.fd, cfg.data_bitrate, cfg.max_load};
  if (cfg.protocol == CanProtocol::kCanOpen) {
    s.canopen = true;
    s.canopen_csp = cfg.canopen.mode == CanOpenMode::kCsp;
    s.heartbeat_s = cfg.canopen.heartbeat_s;
  }
  return s;
}

std::unique_ptr<Driver> open_socketcan(const SocketCanConfig& cfg) {
  if (cfg.protocol == CanProtocol::kCanOpen) return CanOpenDriver::open(cfg);
  return SocketCanDriver::open(cfg);
}

std::unique_ptr<CanOpenDriver> CanOpenDriver::open(const SocketCanConfig& cfg) {
  check_can_bus_budget(can_bus_spec(cfg));
  CanSocketOptions opt;
  opt.ifname = cfg.ifname;
  // Everything the master consumes: EMCY 081h–0FFh, TPDOs 181h–2FFh, SDO answers 581h–5FFh,
  // heartbeats 701h–77Fh (filters by id range: id & mask == can_id & mask).
  static const can_filter filters[] = {
      {0x080, 0x780 | CAN_EFF_FLAG | CAN_RTR_FLAG},  // 080h–0FFh (the SYNC is ours, not received)
      {0x100, 0x700 | CAN_EFF_FLAG | CAN_RTR_FLAG},  // 100h–1FFh (TPDO 1)
      {0x200, 0x700 | CAN_EFF_FLAG | CAN_RTR_FLAG},  // 200h–2FFh (TPDO 2; RPDOs are ours)
      {0x580, 0x780 | CAN_EFF_FLAG | CAN_RTR_FLAG},  // 580h–5FFh
      {0x700, 0x780 | CAN_EFF_FLAG | CAN_RTR_FLAG},  // 700h–77Fh
  };
  opt.filters = filters;
  opt.own_frames = true;  // the SYNC's echo: when it was on the bus (read())
  return std::make_unique<CanOpenDriver>(open_can_socket(opt), cfg);
}

CanOpenDriver::CanOpenDriver(int fd, const SocketCanConfig& cfg) : fd_(fd), joints_(cfg.joints), cfg_(cfg) {
  try {
    if (fd < 0) throw std::invalid_argument("CanOpenDriver: fd = " + std::to_string(fd) + ", expected an open socket");
    check_can_bus_budget(can_bus_spec(cfg));
    if (!detail::set_nonblocking(fd)) throw std::system_error(errno, std::generic_category(), "CanOpenDriver: O_NONBLOCK");
    const int one = 1;
    (void)::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);
    int own = 0;
    socklen_t own_len = sizeof own;
    echo_ = ::getsockopt(fd, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &own, &own_len) == 0 && own != 0;
    sync_wire_ns_ = std::llround(can_classic_frame_bits(0) / cfg.bitrate * 1e9);
    for (int n = 0; n <= 8; ++n)
      frame_wire_ns_[static_cast<std::size_t>(n)] = std::llround(can_classic_frame_bits(n) / cfg.bitrate * 1e9);
    joint_of_node_.fill(-1);
    for (int j = 0; j < joints_; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      const std::uint8_t id = cfg.canopen.node[ju] == 0 ? static_cast<std::uint8_t>(j + 1) : cfg.canopen.node[ju];
      if (id < 1 || id > 127 || joint_of_node_[id] >= 0)
        throw std::invalid_argument("CANopen: node id " + std::to_string(id) + " of joint " + std::to_string(j + 1) +
                                    ": expected a unique node id in 1 … 127");
      node_[ju] = id;
      joint_of_node_[id] = static_cast<std::int8_t>(j);
    }
    if (!(cfg.canopen.heartbeat_s > 0) || cfg.canopen.heartbeat_s > 65.535 ||
        !(cfg.canopen.heartbeat_timeout_s > cfg.canopen.heartbeat_s))
      throw std::invalid_argument("CANopen: heartbeat " + std::to_string(cfg.canopen.heartbeat_s) +
                                  " s, heartbeat_timeout " + std::to_string(cfg.canopen.heartbeat_timeout_s) +
                                  " s; expected 0 < heartbeat ≤ 65.535 s < heartbeat_timeout");
    if (!(cfg.canopen.sync_window >= 0 && cfg.canopen.sync_window < 1))
      throw std::invalid_argument("CANopen: sync_window " + std::to_string(cfg.canopen.sync_window) +
                                  "; expected a share of the SYNC period in [0, 1) (0: no synchronous window)");
    hb_timeout_ns_ = std::llround(cfg.canopen.heartbeat_timeout_s * 1e9);
    // As the drives get them (1006h, 1007h in µs).
    const auto period_us = std::llround(cfg.period_s * 1e6);
    period_ns_ = period_us * 1000;
    window_ns_ = std::llround(static_cast<double>(period_us) * cfg.canopen.sync_window) * 1000;
    bring_up();
  } catch (...) {
    if (fd >= 0) ::close(fd);
    fd_ = -1;
    throw;
  }
}

CanOpenDriver::~CanOpenDriver() {
  if (fd_ >= 0) ::close(fd_);
}

std::string CanOpenDriver::who(int j) const {
  return "CANopen node " + std::to_string(node_[static_cast<std::size_t>(j)]) + " (joint " + std::to_string(j + 1) + ")";
}

cia402::State CanOpenDriver::drive_state(int j) const {
  return cia402::decode_statusword(statusword_[static_cast<std::size_t>(j)]);
}

// ---- Bring-up ---------------------------------------------------------------------------------------
void CanOpenDriver::send_blocking(const can_frame& f) {
  const std::int64_t give_up = detail::monotonic_ns() + 100'000'000;
  for (;;) {
    const Send s = send_frame(fd_, &f, CAN_MTU);
    if (s == Send::kSent) {
      ++counters_.frames_tx;
      return;
    }
    const int err = errno;
    if (s == Send::kFull && detail::monotonic_ns() < give_up) {
      pollfd p{fd_, POLLOUT, 0};
      const timespec ts = detail::to_timespec(1'000'000);
      ::ppoll(&p, 1, &ts, nullptr);
      continue;
    }
    throw std::system_error(err, std::generic_category(), "CANopen: sending a frame failed");
  }
}

// The next frame before deadline_ns (true), or none (false). Heartbeats and EMCYs seen meanwhile
// are noted.
bool CanOpenDriver::receive_until(std::int64_t deadline_ns, can_frame& f) {
  for (;;) {
    canfd_frame rec{};
    const ssize_t n = ::recv(fd_, &rec, sizeof rec, MSG_DONTWAIT);
    if (n == static_cast<ssize_t>(CAN_MTU)) {
      std::memcpy(&f, &rec, CAN_MTU);
      ++counters_.frames_rx;
      if (f.can_id & CAN_ERR_FLAG) continue;
      const canid_t id = f.can_id & CAN_SFF_MASK;
      if (id > co::kCobEmcy && id <= co::kCobEmcy + 127 && f.len == 8) {
        std::uint8_t node = 0;
        co::Emcy e;
        if (co::decode_emcy(f, node, e)) {
          ++emcy_count_;
          if (joint_of_node_[node] >= 0) emcy_[static_cast<std::size_t>(joint_of_node_[node])] = e.code;
        }
      }
      return true;
    }
    if (n > 0) continue;  // an FD record: not ours
    if (n == 0) throw std::runtime_error("CANopen: the bus peer closed the connection during bring-up");
    if (errno == EINTR) continue;
    const std::int64_t left = deadline_ns - detail::monotonic_ns();
    if (left <= 0) return false;
    pollfd p{fd_, POLLIN, 0};
    const timespec ts = detail::to_timespec(left);
    ::ppoll(&p, 1, &ts, nullptr);
  }
}

void CanOpenDriver::sdo_transfer(int j, can_frame req, std::uint16_t index, std::uint8_t sub, const char* what,
                                 const std::string& value_text) {
  const auto ju = static_cast<std::size_t>(j);
  const std::string obj = hex(index, 4) + ":" + hex(sub, 2).substr(0, 2) + " (" + what + ")";
  send_blocking(req);
  const std::int64_t timeout = std::llround(cfg_.canopen.sdo_timeout_s * 1e9);
  std::int64_t deadline = detail::monotonic_ns() + timeout;
  for (;;) {
    can_frame f{};
    if (!receive_until(deadline, f)) {
      can_frame abort{};
      sdo_.timeout(abort);
      send_blocking(abort);
      throw std::runtime_error(who(j) + ": no SDO answer for object " + obj + value_text + " within " +
                               std::to_string(cfg_.canopen.sdo_timeout_s) + " s");
    }
    can_frame next{};
    switch (sdo_.on_frame(f, next)) {
      case co::SdoStep::kIgnored: continue;
      case co::SdoStep::kSend:
        send_blocking(next);
        deadline = detail::monotonic_ns() + timeout;
        continue;
      case co::SdoStep::kDone: return;
      case co::SdoStep::kAbort:
        if ((next.can_id & CAN_SFF_MASK) == co::kCobSdoRx + node_[ju]) send_blocking(next);
        throw std::runtime_error(who(j) + ": SDO " + (value_text.empty() ? "upload of " : "download of ") + obj +
                                 value_text + " refused: abort " + hex(sdo_.abort_code(), 8) + " " +
                                 co::abort_text(sdo_.abort_code()));
    }
  }
}

std::uint32_t CanOpenDriver::sdo_upload(int j, std::uint16_t index, std::uint8_t sub, const char* what) {
  can_frame req{};
  sdo_.start_upload(node_[static_cast<std::size_t>(j)], index, sub, req);
  sdo_transfer(j, req, index, sub, what, "");
  const auto d = sdo_.data();
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < d.size() && i < 4; ++i) v |= std::uint32_t{d[i]} << (8 * i);
  return v;
}

std::string CanOpenDriver::sdo_upload_text(int j, std::uint16_t index, std::uint8_t sub, const char* what) {
  can_frame req{};
  sdo_.start_upload(node_[static_cast<std::size_t>(j)], index, sub, req);
  sdo_transfer(j, req, index, sub, what, "");
  const auto d = sdo_.data();
  return std::string(reinterpret_cast<const char*>(d.data()), d.size());
}

void CanOpenDriver::sdo_download(int j, std::uint16_t index, std::uint8_t sub, std::uint32_t value, int bytes,
                                 const char* what) {
  std::array<std::uint8_t, 4> b{};
  put32(b.data(), value);
  can_frame req{};
  sdo_.start_download(node_[static_cast<std::size_t>(j)], index, sub,
                      std::span<const std::uint8_t>(b.data(), static_cast<std::size_t>(bytes)), req);
  sdo_transfer(j, req, index, sub, what, " = " + hex(value, 2 * bytes));
}

void CanOpenDriver::bring_up() {
  const CanOpenOptions& o = cfg_.canopen;
  // 1. Every node back to its communication defaults; each announces itself (boot-up).
  can_frame f{};
  co::encode_nmt(co::NmtCommand::kResetCommunication, 0, f);
  send_blocking(f);
  std::array<bool, kMaxJoints> booted{};
  int pending = joints_;
  const std::int64_t boot_deadline = detail::monotonic_ns() + std::llround(o.boot_timeout_s * 1e9);
  while (pending > 0 && receive_until(boot_deadline, f)) {
    std::uint8_t node = 0;
    co::NmtState s{};
    if (!co::decode_heartbeat(f, node, s) || s != co::NmtState::kBootUp || joint_of_node_[node] < 0) continue;
    const auto ju = static_cast<std::size_t>(joint_of_node_[node]);
    if (!booted[ju]) --pending;
    booted[ju] = true;
  }
  if (pending > 0) {
    std::string missing;
    for (int j = 0; j < joints_; ++j)
      if (!booted[static_cast<std::size_t>(j)])
        missing += (missing.empty() ? "" : ", ") + std::to_string(node_[static_cast<std::size_t>(j)]) + " (joint " +
                   std::to_string(j + 1) + ")";
    throw std::runtime_error("CANopen: no boot-up message from node " + missing + " within " +
                             std::to_string(o.boot_timeout_s) + " s after NMT reset communication");
  }
  emcy_.fill(0);  // EMCYs from before the reset are history
  const bool csp = o.mode == CanOpenMode::kCsp;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const std::uint8_t n = node_[ju];
    // 2. What the node is, its units.
    const std::uint32_t type = sdo_upload(j, 0x1000, 0, "device type");
    if ((type & 0xFFFF) != 402)
      throw std::runtime_error(who(j) + ": device type 1000h = " + hex(type, 8) +
                               ", expected a CiA 402 drive (profile 402 = 0192h in the low 16 bits)");
    names_[ju] = sdo_upload_text(j, 0x1008, 0, "manufacturer device name");
    const std::uint32_t inc = sdo_upload(j, co::kObjEncoderResolution, 1, "encoder increments");
    const std::uint32_t revs = sdo_upload(j, co::kObjEncoderResolution, 2, "motor revolutions");
    const std::uint32_t dinc = sdo_upload(j, co::kObjDeflectionResolution, 0, "deflection measuring units per revolution");
    const std::uint32_t rated = sdo_upload(j, co::kObjRatedTorque, 0, "motor rated torque");
    if (inc == 0 || revs == 0 || dinc == 0 || rated == 0)
      throw std::runtime_error(who(j) + ": 608Fh:01 = " + std::to_string(inc) + ", 608Fh:02 = " + std::to_string(revs) +
                               ", 6001h = " + std::to_string(dinc) + ", 6076h = " + std::to_string(rated) +
                               "; expected every unit > 0");
    rad_per_inc_[ju] = kTwoPi * revs / inc;
    defl_rad_per_inc_[ju] = kTwoPi / dinc;
    nm_per_permille_[ju] = rated * 1e-6;
    // 3. PDOs: invalidate, map, synchronous, validate (CiA 301's order).
    auto tpdo = [&](int p, std::initializer_list<std::uint32_t> map) {
      const auto com = static_cast<std::uint16_t>(0x1800 + p), mp = static_cast<std::uint16_t>(0x1A00 + p);
      const std::uint32_t cob = (p == 0 ? kTpdo1 : kTpdo2) + n;
      sdo_download(j, com, 1, 0x80000000u | cob, 4, "TPDO COB-ID, invalid");
      sdo_download(j, mp, 0, 0, 1, "TPDO mapping count");
      std::uint8_t k = 0;
      for (std::uint32_t m : map) sdo_download(j, mp, ++k, m, 4, "TPDO mapped object");
      sdo_download(j, mp, 0, k, 1, "TPDO mapping count");
      sdo_download(j, com, 2, 1, 1, "TPDO transmission type: every SYNC");
      sdo_download(j, com, 1, cob, 4, "TPDO COB-ID, valid");
    };
    auto rpdo = [&](int p, std::initializer_list<std::uint32_t> map) {
      const auto com = static_cast<std::uint16_t>(0x1400 + p), mp = static_cast<std::uint16_t>(0x1600 + p);
      const std::uint32_t cob = (p == 0 ? kRpdo1 : kRpdo2) + n;
      sdo_download(j, com, 1, 0x80000000u | cob, 4, "RPDO COB-ID, invalid");
      if (map.size() == 0) return;  // stays invalid
      sdo_download(j, mp, 0, 0, 1, "RPDO mapping count");
      std::uint8_t k = 0;
      for (std::uint32_t m : map) sdo_download(j, mp, ++k, m, 4, "RPDO mapped object");
      sdo_download(j, mp, 0, k, 1, "RPDO mapping count");
      sdo_download(j, com, 2, 1, 1, "RPDO transmission type: synchronous");
      sdo_download(j, com, 1, cob, 4, "RPDO COB-ID, valid");
    };
    tpdo(0, {mapping(cia402::kObjStatusword, 0, 16), mapping(cia402::kObjPositionActual, 0, 32),
             mapping(cia402::kObjTorqueActual, 0, 16)});
    tpdo(1, {mapping(cia402::kObjVelocityActual, 0, 32), mapping(co::kObjDeflection, 0, 32)});
    if (csp) {
      rpdo(0, {mapping(cia402::kObjControlword, 0, 16), mapping(cia402::kObjTargetPosition, 0, 32),
               mapping(co::kObjTorqueOffset, 0, 16)});
      rpdo(1, {mapping(co::kObjVelocityOffset, 0, 32)});
      auto bits = [](double v) {
        const auto real = static_cast<float>(v);
        std::uint32_t b = 0;
        std::memcpy(&b, &real, 4);
        return b;
      };
      sdo_download(j, co::kObjCspKp, 0, bits(o.csp_kp[ju]), 4, "CSP position loop gain");
      sdo_download(j, co::kObjCspKd, 0, bits(o.csp_kd[ju]), 4, "CSP velocity loop gain");
      sent_kp_[ju] = want_kp_[ju] = o.csp_kp[ju];
      sent_kd_[ju] = want_kd_[ju] = o.csp_kd[ju];
      kp_sent_[ju] = kd_sent_[ju] = true;
    } else {
      rpdo(0, {mapping(cia402::kObjControlword, 0, 16), mapping(cia402::kObjTargetTorque, 0, 16)});
      rpdo(1, {});
    }
    // The SYNC period and the synchronous window (CiA 301 1006h, 1007h [µs]): no TPDO later than
    // the window after its SYNC, so the TPDOs before the next SYNC answer this one.
    const auto period_us = static_cast<std::uint32_t>(std::llround(cfg_.period_s * 1e6));
    sdo_download(j, co::kObjCyclePeriod, 0, period_us, 4, "communication cycle period");
    sdo_download(j, co::kObjSyncWindow, 0, static_cast<std::uint32_t>(std::llround(period_us * o.sync_window)), 4,
                 "synchronous window length");  // 0: none
    const auto hb_ms = static_cast<std::uint32_t>(std::llround(o.heartbeat_s * 1e3));
    sdo_download(j, 0x1017, 0, std::max<std::uint32_t>(hb_ms, 1), 2, "producer heartbeat time");
    sdo_download(j, cia402::kObjModesOfOperation, 0,
                 static_cast<std::uint8_t>(csp ? cia402::kModeCsp : cia402::kModeCst), 1, "modes of operation");
  }
  // 4. Operational, then each drive to Switched On (its output still off: the cycle's
  //    controlword enables operation once the runtime commands torque).
  co::encode_nmt(co::NmtCommand::kStart, 0, f);
  send_blocking(f);
  for (int j = 0; j < joints_; ++j) {
    std::uint16_t prev = 0;
    cia402::State s = cia402::State::kUnknown;
    for (int step = 0; step < 12; ++step) {
      const auto sw = static_cast<std::uint16_t>(sdo_upload(j, cia402::kObjStatusword, 0, "statusword"));
      s = cia402::decode_statusword(sw);
      statusword_[static_cast<std::size_t>(j)] = sw;
      if (s == cia402::State::kSwitchedOn) break;
      std::uint16_t cw = cia402::controlword_to_enable(s, prev);
      if (s == cia402::State::kOperationEnabled) cw = cia402::kCwSwitchOn;  // disable operation
      sdo_download(j, cia402::kObjControlword, 0, cw, 2, "controlword");
      prev = cw;
    }
    if (s != cia402::State::kSwitchedOn)
      throw std::runtime_error(who(j) + ": the CiA 402 drive did not reach Switched On (statusword " +
                               hex(statusword_[static_cast<std::size_t>(j)], 4) + ", state " + cia402::to_string(s) +
                               ", last EMCY " + hex(emcy_[static_cast<std::size_t>(j)], 4) + ")");
  }
  const std::int64_t now = detail::monotonic_ns();
  last_hb_ns_.fill(now);
  emcy_.fill(0);
}

// ---- Cycle ------------------------------------------------------------------------------------------
CanOpenDriver::Tx CanOpenDriver::send(const can_frame& f) noexcept {
  const Send s = send_frame(fd_, &f, CAN_MTU);
  if (s == Send::kSent) {
    ++counters_.frames_tx;
    // The bus carries the frames one after the other (the transmit queue is FIFO).
    const std::int64_t t = detail::monotonic_ns();
    wire_busy_ns_ = (wire_busy_ns_ > t ? wire_busy_ns_ : t) + frame_wire_ns_[f.len > 8 ? 8 : f.len];
    return Tx::kOk;
  }
  ++counters_.tx_dropped;
  return s == Send::kFull ? Tx::kDropped : Tx::kDown;
}

void CanOpenDriver::note_fault(int j, const char* fmt, unsigned a, unsigned b, const char* text) noexcept {
  if (fault_joint_ >= 0) return;  // the first one is named
  fault_joint_ = j;
  const int n = std::snprintf(fault_text_.data(), fault_text_.size(), "CANopen node %u (joint %d): ",
                              static_cast<unsigned>(node_[static_cast<std::size_t>(j)]), j + 1);
  if (n > 0 && static_cast<std::size_t>(n) < fault_text_.size())
    std::snprintf(fault_text_.data() + n, fault_text_.size() - static_cast<std::size_t>(n), fmt, a, b, text);
}

void CanOpenDriver::drain(std::int64_t rt_minus_mono_ns, bool before_sync) noexcept {
  ReceivedFrame r;
  for (;;) {
    const Receive got = receive_frame(fd_, cmsg_buf_, rt_minus_mono_ns, r);
    if (got == Receive::kNone) return;
    if (got == Receive::kClosed) {
      peer_closed_ = true;
      return;
    }
    if (r.have_rxq_ovfl && r.rxq_ovfl != rxq_ovfl_) {  // frames the kernel dropped: the receive queue was full
      counters_.rx_dropped += static_cast<std::uint32_t>(r.rxq_ovfl - rxq_ovfl_);
      rxq_ovfl_ = r.rxq_ovfl;
    }
    const std::int64_t stamp = r.stamp_ns != 0 ? r.stamp_ns : detail::monotonic_ns();
    // This master is the bus's only SYNC producer (CiA 301): a SYNC received is its own, looped
    // back when it was sent. Its other frames (RPDOs, SDO requests) looped back are not news.
    const canid_t raw = r.frame.can_id;
    if (r.bytes == CAN_MTU && !r.truncated && (raw & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) == 0 &&
        (raw & CAN_SFF_MASK) == co::kCobSync) {
      if (echo_) on_sync_echo(stamp, r.stamp_ns != 0 && !r.stamped_at_read);
      continue;
    }
    if (r.own) continue;
    silence_.on_rx(stamp, counters_);
    if (stamp > wire_busy_ns_) wire_busy_ns_ = stamp;  // the bus was busy up to this frame's end
    ++counters_.frames_rx;
    if (r.bytes != CAN_MTU || r.truncated) {
      ++counters_.malformed;
      continue;
    }
    can_frame f{};
    std::memcpy(&f, &r.frame, CAN_MTU);
    handle(f, stamp, before_sync);
  }
}

void CanOpenDriver::handle(const can_frame& f, std::int64_t stamp, bool before_sync) noexcept {
  if (f.can_id & CAN_ERR_FLAG) {
    const canid_t e = f.can_id & CAN_ERR_MASK;
    if (e & CAN_ERR_RESTARTED) bus_off_ = false;
    if (e & CAN_ERR_BUSOFF) bus_off_ = true;
    if (e & (CAN_ERR_TX_TIMEOUT | CAN_ERR_PROT | CAN_ERR_BUSOFF | CAN_ERR_BUSERROR | CAN_ERR_CRTL)) {
      ++counters_.bus_errors;
      bus_error_cycle_ = true;
    }
    return;
  }
  if (f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG)) {
    ++counters_.malformed;
    return;
  }
  const canid_t id = f.can_id & CAN_SFF_MASK;
  const auto node = static_cast<std::uint8_t>(id & 0x7F);
  const int j = joint_of_node_[node];
  const canid_t fn = id & 0x780;
  if (j < 0 || node == 0) {
    ++counters_.malformed;  // a node this master does not know
    return;
  }
  const auto ju = static_cast<std::size_t>(j);
  if (fn == co::kCobHeartbeat) {
    std::uint8_t nd = 0;
    co::NmtState s{};
    if (!co::decode_heartbeat(f, nd, s)) {
      ++counters_.malformed;
      return;
    }
    last_hb_ns_[ju] = stamp;
    if (s != co::NmtState::kOperational && !faulted_[ju]) {
      faulted_[ju] = true;
      note_fault(j, "reports NMT state %02Xh%.0u (%s), expected operational", static_cast<unsigned>(s), 0,
                 co::to_string(s));
    }
    return;
  }
  if (fn == co::kCobEmcy) {
    std::uint8_t nd = 0;
    co::Emcy e;
    if (!co::decode_emcy(f, nd, e)) {
      ++counters_.malformed;
      return;
    }
    ++emcy_count_;
    emcy_[ju] = e.code;
    if (e.code != 0 && !faulted_[ju]) {
      faulted_[ju] = true;
      note_fault(j, "EMCY %04Xh, error register %02Xh: %s", e.code, e.error_register, co::emcy_text(e.code));
    }
    return;
  }
  if (fn == co::kCobSdoTx) {
    if (sdo_joint_ != j) {
      ++counters_.malformed;
      return;
    }
    can_frame next{};
    const co::SdoStep st = sdo_.on_frame(f, next);
    if (st == co::SdoStep::kSend) {
      (void)send(next);
    } else if (st == co::SdoStep::kDone) {
      if (sdo_kp_) {
        sent_kp_[ju] = sdo_value_;
        kp_sent_[ju] = true;
      } else {
        sent_kd_[ju] = sdo_value_;
        kd_sent_[ju] = true;
      }
      sdo_joint_ = -1;
    } else if (st == co::SdoStep::kAbort) {
      if (!faulted_[ju]) {
        faulted_[ju] = true;
        note_fault(j, "SDO download of the CSP gain %04Xh refused: abort %08Xh%s", sdo_kp_ ? 0x2010u : 0x2011u,
                   sdo_.abort_code(), "");
      }
      sdo_joint_ = -1;
    }
    return;
  }
  const bool t1 = fn == kTpdo1, t2 = fn == kTpdo2;
  if (!t1 && !t2) {
    ++counters_.malformed;
    return;
  }
  if (f.len != 8) {
    ++counters_.malformed;
    return;
  }
  if (before_sync || echo_pending_ || stamp < t_sync_ns_) {
    // Queued before this read's SYNC went out (with the SYNC's echo: received before the echo,
    // the receive queue keeps the bus's order): within the drive's synchronous window of the
    // previous SYNC (1007h), so its answer, late. Kept as that SYNC's sample (read()).
    ++counters_.late;
    status_[ju] |= kStatusLate;
    if (prev_sync_.cycle == 0) return;  // no SYNC before this one: nothing it answers
    bool& got = t1 ? late1_[ju] : late2_[ju];
    if (got) {
      ++counters_.duplicate;
      return;
    }
    got = true;
    decode_tpdo(t1, f, ju, late_[ju]);
    return;
  }
  // This SYNC's answer; one that came after the deadline (drained in this read's last poll) is
  // still this SYNC's sample, flagged.
  if (stamp > deadline_ns_) {
    ++counters_.late;
    status_[ju] |= kStatusLate;
  }
  bool& got = t1 ? got1_[ju] : got2_[ju];
  if (got) {
    ++counters_.duplicate;
    status_[ju] |= kStatusStale;
    return;
  }
  got = true;
  DriveValues v{statusword_[ju], beta_[ju], beta_dot_[ju], defl_[ju], torque_[ju]};
  decode_tpdo(t1, f, ju, v);
  statusword_[ju] = v.statusword, beta_[ju] = v.beta, beta_dot_[ju] = v.beta_dot, defl_[ju] = v.defl,
  torque_[ju] = v.torque;
}

void CanOpenDriver::on_sync_echo(std::int64_t stamp, bool stamp_known) noexcept {
  if (!echo_pending_) return;  // safe_stop()'s, or one whose SYNC was given up on
  echo_pending_ = false;
  if (!stamp_known) {
    // Stamped when this thread read it (or not at all): when the SYNC was on the bus is not
    // known. The drives sampled then, and the command this SYNC put in force acts from then: both
    // go out without a time (an interval the observer bridges), not with this thread's.
    ++echoes_stamped_at_read_;
    sync_known_ = false;
    if (prev_sync_.cycle == last_sync_.cycle) prev_sync_.known = false;
    last_sync_.known = false;
    return;
  }
  const std::int64_t t = (wire_before_sync_ns_ > stamp ? wire_before_sync_ns_ : stamp) + sync_wire_ns_;
  if (wire_before_sync_ns_ > stamp) {
    // Queued behind this master's own frames (an overrun's RPDOs, then at once the next SYNC):
    // its time is the end of those frames on the wire as this thread counted them from its send
    // calls, and the drives, counting from their receive stamps, put it up to a frame time (0.12 ms
    // at 1 Mbit/s) elsewhere — in the loaded VM 3–5 % of the SYNCs, and the false faults of issue
    // 14 sat on them (a sample 0.1 ms off is a residual kick of the threshold's size). The window
    // and the stamp rules use this estimate; the samples and the command it put in force go out
    // without a time (the observer bridges them).
    ++syncs_after_frames_;
    if (wire_before_sync_ns_ - stamp > after_frames_max_ns_) after_frames_max_ns_ = wire_before_sync_ns_ - stamp;
    sync_known_ = false;
    if (prev_sync_.cycle == last_sync_.cycle) prev_sync_.known = false;
    last_sync_.known = false;
  }
  const std::int64_t delay = stamp - t_sync_ns_;
  if (delay > sync_delay_max_ns_) sync_delay_max_ns_ = delay;
  if (delay > 1'000'000) ++syncs_delayed_;
  // The SYNC record's time: this read's (in its polls), or the previous read's when its echo came
  // only in this read's first drain (then prev_sync_ is that record).
  if (prev_sync_.cycle == last_sync_.cycle) prev_sync_.lower_ns = t;
  last_sync_.lower_ns = t;
  sync_lower_ns_ = t;
  t_sync_ns_ = stamp;
}

void CanOpenDriver::decode_tpdo(bool t1, const can_frame& f, std::size_t j, DriveValues& v) const noexcept {
  if (t1) {  // 6041h statusword, 6064h position actual, 6077h torque actual
    v.statusword = u16(f.data);
    v.beta = static_cast<std::int32_t>(u32(f.data + 2)) * rad_per_inc_[j];
    v.torque = static_cast<std::int16_t>(u16(f.data + 6)) * nm_per_permille_[j];
  } else {  // 606Ch velocity actual, 6004h deflection
    v.beta_dot = static_cast<std::int32_t>(u32(f.data)) * rad_per_inc_[j];
    v.defl = static_cast<std::int32_t>(u32(f.data + 4)) * defl_rad_per_inc_[j];
  }
}

IoStatus CanOpenDriver::read(std::int64_t /*now_ns*/, std::int64_t deadline_ns, Feedback& out) {
  ++cycle_;
  got1_.fill(false);
  got2_.fill(false);
  late1_.fill(false);
  late2_.fill(false);
  status_.fill(0);
  deadline_ns_ = deadline_ns;
  bus_error_cycle_ = false;
  prev_sync_ = last_sync_;  // the SYNC whose late answers this read's first drain gathers
  const std::int64_t rt_off = rt_offset_.get();
  drain(rt_off, true);
  // No SYNC while the previous one's synchronous window is open: a drive may still answer it, and
  // an answer sent after a newer SYNC would be taken for that one's (a PDO names no SYNC). After
  // an overrun the loop's next cycle comes early — 2 ms after the late SYNC in a 10 ms period —
  // and the vcan VM's drives, answering 3 ms after a SYNC, answered the old one after the new:
  // samples a SYNC off, which the observer read as a torque it could not explain. A window that
  // closes before this read's deadline is waited out (the loop's wake-up jitter, a previous SYNC
  // sent late); otherwise this cycle sends no SYNC and gathers the previous one's answers, used
  // as late samples.
  bool hold = false;
  if (window_ns_ > 0 && last_sync_.cycle != 0) {
    const std::int64_t closes = last_sync_.lower_ns + window_ns_;
    const std::int64_t now = detail::monotonic_ns();
    if (now < closes) {
      if (closes < deadline_ns) {
        const timespec until = detail::to_timespec(closes);
        while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &until, nullptr) == EINTR) {
        }
        drain(rt_off, true);
      } else {
        hold = true;
        ++syncs_held_;
      }
    }
  }
  // Receives until every joint has both TPDOs in `t1`, `t2` (or the deadline); `before_sync`: all
  // of it answers the previous SYNC.
  auto gather = [&](const std::array<bool, kMaxJoints>& t1, const std::array<bool, kMaxJoints>& t2,
                    bool before_sync) noexcept {
    auto all_in = [&] {
      for (int j = 0; j < joints_; ++j)
        if (!t1[static_cast<std::size_t>(j)] || !t2[static_cast<std::size_t>(j)]) return false;
      return true;
    };
    detail::poll_until(fd_, deadline_ns, [&] { return peer_closed_ || all_in(); },
                       [&] { drain(rt_off, before_sync); });
  };
  if (hold) {
    gather(late1_, late2_, true);  // everything answers the previous SYNC (or an older one)
    return finish_read(out, Tx::kOk);
  }
  // The RPDOs written last cycle act from this SYNC on; the sample this SYNC takes is the end of
  // the interval over which the previous SYNC's command acted (reported: applied then).
  prev_acting_seq_ = acting_seq_;
  prev_sync_ns_ = sync_lower_ns_;
  prev_sync_known_ = sync_known_;
  sync_known_ = true;
  if (written_) acting_seq_ = written_seq_;
  written_ = false;
  can_frame sync{};
  co::encode_sync(0, sync);
  // The drives sample when the SYNC has crossed the bus: after what is still queued or on the
  // wire before it (last cycle's RPDOs of a late write, answers still coming), then its own bits.
  const std::int64_t t_sync = detail::monotonic_ns();
  sync_lower_ns_ = (wire_busy_ns_ > t_sync ? wire_busy_ns_ : t_sync) + sync_wire_ns_;
  wire_before_sync_ns_ = wire_busy_ns_;
  t_sync_ns_ = t_sync;
  last_sync_ = SyncRecord{cycle_, sync_lower_ns_, prev_acting_seq_, prev_sync_known_ ? prev_sync_ns_ : 0};
  if (echo_pending_) ++echo_lost_;  // the previous SYNC's echo never came
  const std::uint64_t rx_dropped_before = counters_.rx_dropped;
  const Tx tx = send(sync);
  // With the echo, the sample time is when the SYNC was on the bus, not when this thread asked
  // for it: on a loaded machine the send itself took up to 20 ms (the vcan VM beside a compiler),
  // and the drives sampled that much later than the lower bound above.
  echo_pending_ = echo_ && tx == Tx::kOk;
  gather(got1_, got2_, false);
  if (echo_pending_ && counters_.rx_dropped != rx_dropped_before) {
    // The echo may be among the frames the full receive queue lost: which SYNC the answers
    // received answer is then unknown; none is used.
    late1_.fill(false);
    late2_.fill(false);
  }
  return finish_read(out, tx);
}

IoStatus CanOpenDriver::finish_read(Feedback& out, Tx tx) noexcept {
  const std::int64_t now = detail::monotonic_ns();
  out.joints = joints_;
  out.seq = cycle_;
  out.stamp_ns = sync_lower_ns_;
  out.timing = FeedbackTiming::kModule;
  const bool bus_bad = tx == Tx::kDown || bus_off_ || bus_error_cycle_;
  int fresh = 0;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    std::uint16_t st = status_[ju];
    // Heartbeat consumer.
    if (!lost_[ju] && now - last_hb_ns_[ju] > hb_timeout_ns_) {
      lost_[ju] = true;
      note_fault(j, "heartbeat lost: none for %u ms (consumer time %u ms)%s",
                 static_cast<unsigned>((now - last_hb_ns_[ju]) / 1'000'000),
                 static_cast<unsigned>(hb_timeout_ns_ / 1'000'000), "");
    }
    const bool have = got1_[ju] && got2_[ju];
    const bool have_late = late1_[ju] && late2_[ju] && prev_sync_.cycle != 0;
    const bool use_late = !have && have_late && handed_cycle_[ju] < prev_sync_.cycle;
    if (use_late) statusword_[ju] = late_[ju].statusword;
    const cia402::State ds = cia402::decode_statusword(statusword_[ju]);
    if (ds == cia402::State::kFault && !faulted_[ju]) {
      faulted_[ju] = true;
      note_fault(j, "drive in Fault (statusword %04Xh, error code %04Xh)%s", statusword_[ju], emcy_[ju], "");
    }
    out.sample_ns[ju] = 0;
    out.applied_ns[ju] = 0;
    out.late_applied_ns[ju] = 0;
    if (lost_[ju]) {
      st |= kStatusMissing;
      ++counters_.missing;
    } else if (have) {
      ++fresh;
      out.sample_ns[ju] = sync_known_ ? sync_lower_ns_ : 0;
      if (!sync_known_) st |= kStatusNoTiming;
      // The command applied last before this sample: the one the previous SYNC put in force (this
      // SYNC's takes effect as the sample is taken, and acts over the next interval).
      out.applied_seq[ju] = prev_acting_seq_;
      out.applied_ns[ju] = prev_sync_known_ ? prev_sync_ns_ : 0;
      handed_cycle_[ju] = cycle_;
      if (have_late && prev_sync_.applied_ns != 0) {
        // The previous SYNC's answer came late as well: when its command took effect (the
        // observer places a lost sample's command with it).
        out.late_applied_seq[ju] = prev_sync_.applied_seq;
        out.late_applied_ns[ju] = prev_sync_.applied_ns;
      }
    } else if (use_late) {
      // No fresh pair, but the previous SYNC's came after that read's deadline: an older sample,
      // at that SYNC's time, with the command that SYNC's sample had applied.
      ++fresh;
      ++counters_.late_used;
      st |= kStatusLate;
      beta_[ju] = late_[ju].beta;
      beta_dot_[ju] = late_[ju].beta_dot;
      defl_[ju] = late_[ju].defl;
      torque_[ju] = late_[ju].torque;
      out.sample_ns[ju] = prev_sync_.known ? prev_sync_.lower_ns : 0;
      if (!prev_sync_.known) st |= kStatusNoTiming;
      out.applied_seq[ju] = prev_sync_.applied_seq;
      out.applied_ns[ju] = prev_sync_.applied_ns;
      handed_cycle_[ju] = prev_sync_.cycle;
    } else {
      st |= kStatusMissing;
      ++counters_.missing;
    }
    if (faulted_[ju]) st |= kStatusStale | kStatusTorqueOff;
    else if (ds != cia402::State::kOperationEnabled) st |= kStatusTorqueOff;
    if (bus_bad) st |= kStatusBusError;
    out.beta[ju] = beta_[ju];
    out.beta_dot[ju] = beta_dot_[ju];
    out.deflection[ju] = defl_[ju];
    out.status[ju] = st;
  }
  if (bus_bad) return IoStatus::kBusError;
  if (fresh == 0) return IoStatus::kTimeout;
  for (int j = 0; j < joints_; ++j)
    if (out.status[static_cast<std::size_t>(j)] & (kStatusMissing | kStatusStale)) return IoStatus::kPartial;
  return fresh < joints_ ? IoStatus::kPartial : IoStatus::kOk;
}

void CanOpenDriver::send_gains() noexcept {
  const std::int64_t now = detail::monotonic_ns();
  if (sdo_joint_ >= 0) {
    if (now - sdo_started_ns_ < std::llround(cfg_.canopen.sdo_timeout_s * 1e9)) return;
    can_frame abort{};
    sdo_.timeout(abort);
    (void)send(abort);
    sdo_joint_ = -1;
  }
  for (int k = 0; k < joints_; ++k) {
    const int j = (gains_cursor_ + k) % joints_;
    const auto ju = static_cast<std::size_t>(j);
    const bool kp = !kp_sent_[ju] || sent_kp_[ju] != want_kp_[ju];
    const bool kd = !kd_sent_[ju] || sent_kd_[ju] != want_kd_[ju];
    if (!kp && !kd) continue;
    sdo_kp_ = kp;
    sdo_value_ = kp ? want_kp_[ju] : want_kd_[ju];
    const auto v = static_cast<float>(sdo_value_);
    std::array<std::uint8_t, 4> b{};
    std::memcpy(b.data(), &v, 4);
    can_frame req{};
    if (!sdo_.start_download(node_[ju], kp ? co::kObjCspKp : co::kObjCspKd, 0, b, req)) return;
    if (send(req) != Tx::kOk) return;
    sdo_joint_ = j;
    sdo_started_ns_ = now;
    gains_cursor_ = (j + 1) % joints_;
    return;
  }
}

IoStatus CanOpenDriver::write(const Command& cmd) {
  bool dropped = false, down = false;
  const bool csp = cfg_.canopen.mode == CanOpenMode::kCsp;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const bool off = cmd.torque_off || j >= cmd.joints;
    const std::uint16_t cw = off ? cia402::kCwSwitchOn : cia402::kCwEnableOperation;
    const double pm = nm_per_permille_[ju];
    can_frame f{};
    f.can_id = kRpdo1 + node_[ju];
    put16(f.data, cw);
    if (csp) {
      f.len = 8;
      put32(f.data + 2, static_cast<std::uint32_t>(to_i32(off ? beta_[ju] / rad_per_inc_[ju]
                                                              : cmd.beta_ref[ju] / rad_per_inc_[ju])));
      put16(f.data + 6, static_cast<std::uint16_t>(to_i16(off ? 0.0 : cmd.tau[ju] / pm)));
    } else {
      f.len = 4;
      put16(f.data + 2, static_cast<std::uint16_t>(to_i16(off ? 0.0 : cmd.tau[ju] / pm)));
    }
    Tx t = send(f);
    dropped |= t == Tx::kDropped;
    down |= t == Tx::kDown;
    if (csp) {
      can_frame g{};
      g.can_id = kRpdo2 + node_[ju];
      g.len = 4;
      put32(g.data, static_cast<std::uint32_t>(to_i32(off ? 0.0 : cmd.beta_dot_ref[ju] / rad_per_inc_[ju])));
      t = send(g);
      dropped |= t == Tx::kDropped;
      down |= t == Tx::kDown;
      want_kp_[ju] = off ? sent_kp_[ju] : cmd.kp[ju];
      want_kd_[ju] = off ? sent_kd_[ju] : cmd.kd[ju];
    }
  }
  if (csp) send_gains();
  written_seq_ = cmd.seq;
  written_ = !dropped && !down;
  if (down) return IoStatus::kBusError;
  return dropped ? IoStatus::kPartial : IoStatus::kOk;
}

void CanOpenDriver::safe_stop() {
  // Disable operation (output off) with zero targets to every drive, then a SYNC so the
  // synchronous RPDOs act; a full transmit queue is waited out for at most 20 ms in total.
  const std::int64_t give_up = detail::monotonic_ns() + 20'000'000;
  auto put = [&](const can_frame& f) {
    Tx t;
    while ((t = send(f)) == Tx::kDropped) {
      const std::int64_t remaining = give_up - detail::monotonic_ns();
      if (remaining <= 0) return;
      pollfd p{fd_, POLLOUT, 0};
      const timespec ts = detail::to_timespec(remaining);
      if (::ppoll(&p, 1, &ts, nullptr) <= 0) return;
    }
  };
  const bool csp = cfg_.canopen.mode == CanOpenMode::kCsp;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    can_frame f{};
    f.can_id = kRpdo1 + node_[ju];
    put16(f.data, cia402::kCwSwitchOn);
    if (csp) {
      f.len = 8;
      put32(f.data + 2, static_cast<std::uint32_t>(to_i32(beta_[ju] / rad_per_inc_[ju])));
    } else {
      f.len = 4;
    }
    put(f);
  }
  can_frame sync{};
  co::encode_sync(0, sync);
  put(sync);
}

FeedbackSpec CanOpenDriver::feedback_spec() const {
  FeedbackSpec f;
  for (int j = 0; j < joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    f.beta_lsb = std::max(f.beta_lsb, rad_per_inc_[ju]);
    f.beta_dot_lsb = std::max(f.beta_dot_lsb, rad_per_inc_[ju]);  // 606Ch: increments/s
    f.deflection_lsb = std::max(f.deflection_lsb, defl_rad_per_inc_[ju]);
    f.torque_lsb = std::max(f.torque_lsb, nm_per_permille_[ju]);
  }
  f.sample_time_uncertainty = 1e-3;
  return f;
}

}  // namespace pedalwave::drivers
