#include "pedalwave/drivers/socketcan_driver.hpp"

#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>

#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/can_io.hpp"
#include "pedalwave/drivers/posix_util.hpp"

namespace pedalwave::drivers {
namespace {

[[noreturn]] void fail(int err, const std::string& ifname, const std::string& what) {
  std::string msg = "CAN interface '" + ifname + "': " + what;
  if (err == EAFNOSUPPORT)
    msg += ": this kernel has no PF_CAN; see the vcan VM test (ctest -L vcan inside the VM)";
  throw std::system_error(err, std::generic_category(), msg);
}

// Error classes we subscribe to with CAN_RAW_ERR_FILTER.
constexpr can_err_mask_t kErrMask = CAN_ERR_TX_TIMEOUT | CAN_ERR_CRTL | CAN_ERR_PROT |
                                    CAN_ERR_BUSOFF | CAN_ERR_BUSERROR | CAN_ERR_RESTARTED;

}  // namespace

bool can_sockets_available() noexcept {
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) return false;
  ::close(fd);
  return true;
}

int open_can_socket(const CanSocketOptions& opt) {
  if (opt.ifname.empty() || opt.ifname.size() >= IFNAMSIZ)
    throw std::invalid_argument("CAN interface name '" + opt.ifname + "': expected 1…" +
                                std::to_string(IFNAMSIZ - 1) + " characters");
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) fail(errno, opt.ifname, "socket(PF_CAN, SOCK_RAW, CAN_RAW) failed");
  try {
    ifreq ifr{};
    std::memcpy(ifr.ifr_name, opt.ifname.c_str(), opt.ifname.size() + 1);
    if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) fail(errno, opt.ifname, "no such interface");
    const int ifindex = ifr.ifr_ifindex;
    const int one = 1;
    if (opt.fd_frames) {
      if (::ioctl(fd, SIOCGIFMTU, &ifr) < 0) fail(errno, opt.ifname, "SIOCGIFMTU failed");
      if (ifr.ifr_mtu != CANFD_MTU)
        throw std::invalid_argument("CAN interface '" + opt.ifname + "': MTU " +
                                    std::to_string(ifr.ifr_mtu) + ", expected " +
                                    std::to_string(CANFD_MTU) +
                                    " for CAN FD (ip link set " + opt.ifname + " mtu 72)");
      if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &one, sizeof one) < 0)
        fail(errno, opt.ifname, "CAN_RAW_FD_FRAMES not supported");
    }
    if (!opt.filters.empty() &&
        ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, opt.filters.data(),
                     static_cast<socklen_t>(opt.filters.size_bytes())) < 0)
      fail(errno, opt.ifname, "CAN_RAW_FILTER failed");
    if (opt.error_frames && ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &kErrMask,
                                         sizeof kErrMask) < 0)
      fail(errno, opt.ifname, "CAN_RAW_ERR_FILTER failed");
    if (opt.timestamps) {
      if (::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one) < 0)
        fail(errno, opt.ifname, "SO_TIMESTAMPNS failed");
      if (::setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof one) < 0)
        fail(errno, opt.ifname, "SO_RXQ_OVFL failed");
    }
    if (opt.own_frames && ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &one, sizeof one) < 0)
      fail(errno, opt.ifname, "CAN_RAW_RECV_OWN_MSGS failed");
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifindex;
    if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0)
      fail(errno, opt.ifname, "bind failed");
  } catch (...) {
    ::close(fd);
    throw;
  }
  return fd;
}

std::unique_ptr<SocketCanDriver> SocketCanDriver::open(const SocketCanConfig& cfg) {
  // Budget and joint count first: a refused configuration never touches the bus.
  check_can_bus_budget({cfg.joints, cfg.period_s, cfg.bitrate, cfg.fd, cfg.data_bitrate,
                        cfg.max_load});
  std::array<can_filter, 2 * kMaxJoints> filters{};
  for (int j = 0; j < cfg.joints; ++j) {
    const auto node = static_cast<canid_t>(can::node_of_joint(j));
    filters[static_cast<std::size_t>(2 * j)] = {can::kFeedbackBase + node,
                                                CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG};
    filters[static_cast<std::size_t>(2 * j + 1)] = {can::kTimingBase + node,
                                                    CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG};
  }
  CanSocketOptions opt;
  opt.ifname = cfg.ifname;
  opt.fd_frames = cfg.fd;
  opt.filters = std::span<const can_filter>(filters.data(), static_cast<std::size_t>(2 * cfg.joints));
  return std::make_unique<SocketCanDriver>(open_can_socket(opt), cfg);
}

SocketCanDriver::SocketCanDriver(int fd, const SocketCanConfig& cfg)
    : fd_(fd), joints_(cfg.joints), fd_mode_(cfg.fd) {
  try {
    if (fd < 0) throw std::invalid_argument("SocketCanDriver: fd = " + std::to_string(fd) +
                                            ", expected an open socket");
    if (cfg.protocol != CanProtocol::kPedalwave)
      throw std::invalid_argument("SocketCanDriver: protocol canopen is CanOpenDriver's (open_socketcan)");
    check_can_bus_budget({cfg.joints, cfg.period_s, cfg.bitrate, cfg.fd, cfg.data_bitrate,
                          cfg.max_load});
    if (!detail::set_nonblocking(fd))
      throw std::system_error(errno, std::generic_category(), "SocketCanDriver: O_NONBLOCK");
    // Kernel receive timestamps also work on AF_UNIX sockets; harmless if refused.
    const int one = 1;
    (void)::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);
    sync_wire_ns_ = std::llround(can_classic_frame_bits(2) / cfg.bitrate * 1e9);
  } catch (...) {
    if (fd >= 0) ::close(fd);
    fd_ = -1;
    throw;
  }
}

SocketCanDriver::~SocketCanDriver() {
  if (fd_ >= 0) ::close(fd_);
}

// ---- Transmit -----------------------------------------------------------------------------------
SocketCanDriver::Tx SocketCanDriver::transmit(const void* f, std::size_t size) noexcept {
  const Send s = send_frame(fd_, f, size);
  if (s == Send::kSent) {
    ++counters_.frames_tx;
    return Tx::kOk;
  }
  ++counters_.tx_dropped;
  return s == Send::kFull ? Tx::kDropped : Tx::kDown;  // kDown: ENETDOWN, ENXIO, EPIPE, short write
}

SocketCanDriver::Tx SocketCanDriver::send_classic(const can_frame& f) noexcept { return transmit(&f, CAN_MTU); }

SocketCanDriver::Tx SocketCanDriver::send_fd(const canfd_frame& f) noexcept { return transmit(&f, CANFD_MTU); }

void SocketCanDriver::note_tx(Tx t, bool& dropped, bool& down) noexcept {
  if (t == Tx::kDropped) dropped = true;
  if (t == Tx::kDown) down = true;
}

// ---- Receive ------------------------------------------------------------------------------------
void SocketCanDriver::drain(std::int64_t rt_minus_mono_ns) noexcept {
  ReceivedFrame r;
  for (;;) {
    const Receive got = receive_frame(fd_, cmsg_buf_, rt_minus_mono_ns, r);
    if (got == Receive::kNone) return;  // nothing more; errors surface as missing frames
    if (got == Receive::kClosed) {
      peer_closed_ = true;
      return;
    }
    if (r.have_rxq_ovfl) {
      counters_.rx_dropped += static_cast<std::uint32_t>(r.rxq_ovfl - rxq_ovfl_);
      rxq_ovfl_ = r.rxq_ovfl;
    }
    const std::int64_t stamp = r.stamp_ns != 0 ? r.stamp_ns : detail::monotonic_ns();
    silence_.on_rx(stamp, counters_);
    if (r.truncated) {
      ++counters_.frames_rx;
      ++counters_.malformed;
      continue;
    }
    handle_frame(r.frame, r.bytes, stamp);
  }
}

void SocketCanDriver::handle_frame(const canfd_frame& f, std::size_t nbytes,
                                   std::int64_t stamp_ns) noexcept {
  can_frame c{};
  if (nbytes == CAN_MTU) {
    std::memcpy(&c, &f, CAN_MTU);
    if (c.can_id & CAN_ERR_FLAG) {
      handle_error_frame(c);
      return;
    }
  } else if (nbytes == CANFD_MTU) {
    if (f.len == can::kFdFeedbackLen) {  // an FD bus's feedback frame (with the timing record)
      ++counters_.frames_rx;
      handle_feedback_fd(f, stamp_ns);
      return;
    }
    if (!can::fd_to_classic(f, c)) {
      ++counters_.frames_rx;
      ++counters_.malformed;
      return;
    }
  } else {
    ++counters_.frames_rx;
    ++counters_.malformed;
    return;
  }
  ++counters_.frames_rx;
  const canid_t id = c.can_id & CAN_SFF_MASK;
  if (id > can::kTimingBase && id <= can::kTimingBase + static_cast<canid_t>(can::kMaxNode))
    handle_timing(c, stamp_ns);
  else
    handle_feedback(c, stamp_ns);
}

void SocketCanDriver::handle_error_frame(const can_frame& f) noexcept {
  const canid_t e = f.can_id & CAN_ERR_MASK;
  if (e & CAN_ERR_RESTARTED) {
    bus_off_ = false;
    error_passive_ = false;
  }
  if (e & CAN_ERR_BUSOFF) bus_off_ = true;
  bool bad = (e & (CAN_ERR_TX_TIMEOUT | CAN_ERR_PROT | CAN_ERR_BUSOFF | CAN_ERR_BUSERROR)) != 0;
  if (e & CAN_ERR_CRTL) {
    const std::uint8_t d1 = f.data[1];
    if (d1 & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) error_passive_ = true;
    if (d1 & CAN_ERR_CRTL_ACTIVE) error_passive_ = false;
    if (d1 & static_cast<std::uint8_t>(~CAN_ERR_CRTL_ACTIVE)) bad = true;  // not just "recovered"
  }
  if (bad) {
    ++counters_.bus_errors;
    bus_error_cycle_ = true;
  }
}

void SocketCanDriver::handle_feedback(const can_frame& f, std::int64_t stamp_ns) noexcept {
  int node = 0;
  can::FeedbackFrame fb{};
  const can::CodecStatus s = can::decode_feedback(f, node, fb);
  const int j = can::joint_of_node(node);
  if (s == can::CodecStatus::kChecksum) {
    ++counters_.checksum;
    if (j >= 0 && j < joints_) status_[static_cast<std::size_t>(j)] |= kStatusChecksum;
    return;
  }
  if (s != can::CodecStatus::kOk || j < 0 || j >= joints_) {
    ++counters_.malformed;
    return;
  }
  take_feedback(j, fb, nullptr, stamp_ns);
}

void SocketCanDriver::handle_feedback_fd(const canfd_frame& f, std::int64_t stamp_ns) noexcept {
  int node = 0;
  can::FeedbackFrame fb{};
  wire::ModuleTiming t{};
  const can::CodecStatus s = can::decode_feedback_fd(f, node, fb, t);
  const int j = can::joint_of_node(node);
  if (s == can::CodecStatus::kChecksum) {
    ++counters_.checksum;
    if (j >= 0 && j < joints_) status_[static_cast<std::size_t>(j)] |= kStatusChecksum;
    return;
  }
  if (s != can::CodecStatus::kOk || j < 0 || j >= joints_) {
    ++counters_.malformed;
    return;
  }
  take_feedback(j, fb, &t, stamp_ns);
}

void SocketCanDriver::take_feedback(int j, const can::FeedbackFrame& fb,
                                    const wire::ModuleTiming* t, std::int64_t stamp_ns) noexcept {
  const auto ju = static_cast<std::size_t>(j);
  // The echo is 4 bits on both CAN frame sets (the FD feedback keeps the classic layout's byte 6).
  const std::uint64_t answered = track_[ju].take(fb.counter, 16, cycle_);
  FrameAge age = classify_frame(rc_[ju], fb.counter, sync_counter_, cycle_, 16);
  if (age == FrameAge::kFresh && stamp_ns > deadline_ns_) {
    // The answer to this SYNC, but received after the cycle's deadline: not used.
    rc_[ju].fresh = false;
    age = FrameAge::kLate;
  }
  switch (age) {
    case FrameAge::kFresh:
      last_[ju] = fb.sample;
      ++fresh_count_;
      if (stamp_ns > stamp_ns_) stamp_ns_ = stamp_ns;
      fresh_answered_[ju] = answered;
      fresh_sure_[ju] = track_[ju].sure() && answered == cycle_;
      if (t) {
        timing_[ju] = *t;
        have_timing_[ju] = true;
      }
      break;
    case FrameAge::kDuplicate:
      ++counters_.duplicate;
      status_[ju] |= kStatusStale;
      break;
    case FrameAge::kLate:
      ++counters_.late;
      status_[ju] |= kStatusLate;
      late_[ju].offer_values(fb.counter, answered, track_[ju].sure() && answered != 0, fb.sample);
      if (t) late_[ju].offer_timing(fb.counter, *t);
      break;
    case FrameAge::kOutOfOrder:
      ++counters_.out_of_order;
      status_[ju] |= kStatusOutOfOrder;
      break;
  }
}

// Classic bus: the timing record of this cycle's sample comes in its own frame (same echo).
void SocketCanDriver::handle_timing(const can_frame& f, std::int64_t stamp_ns) noexcept {
  int node = 0;
  wire::ModuleTiming t{};
  std::uint8_t echo = 0;
  const can::CodecStatus s = can::decode_timing(f, node, t, echo);
  const int j = can::joint_of_node(node);
  if (s == can::CodecStatus::kChecksum) {
    ++counters_.checksum;
    return;
  }
  if (s != can::CodecStatus::kOk || j < 0 || j >= joints_) {
    ++counters_.malformed;
    return;
  }
  const auto ju = static_cast<std::size_t>(j);
  if (echo != (sync_counter_ & can::kClassicCounterMask) || stamp_ns > deadline_ns_) {
    // An older SYNC's or a late record: not this cycle's timing, but it still says when the
    // module applied its command then (the observer bridges the lost sample with it).
    late_[ju].offer_timing(echo, t);
    return;
  }
  if (have_timing_[ju]) return;  // a repeated record
  timing_[ju] = t;
  have_timing_[ju] = true;
}

IoStatus SocketCanDriver::read(std::int64_t /*now_ns*/, std::int64_t deadline_ns, Feedback& out) {
  ++cycle_;
  sync_counter_ = static_cast<std::uint8_t>(sync_counter_ + 1);
  for (int j = 0; j < joints_; ++j) {
    drivers::begin_cycle(rc_[static_cast<std::size_t>(j)]);
    status_[static_cast<std::size_t>(j)] = 0;
    have_timing_[static_cast<std::size_t>(j)] = false;
    late_[static_cast<std::size_t>(j)].clear();
  }
  fresh_count_ = 0;
  stamp_ns_ = 0;
  deadline_ns_ = deadline_ns;
  bus_error_cycle_ = false;
  // Kernel stamps are CLOCK_REALTIME; Feedback wants CLOCK_MONOTONIC.
  const std::int64_t rt_off = rt_offset_.get();

  // Frames already queued are answers to older SYNCs: classify them against the new counter.
  drain(rt_off);
  can_frame sync{};
  can::encode_sync(sync_counter_, sync);
  bool dropped = false, down = false;
  sync_lower_ns_ = detail::monotonic_ns() + sync_wire_ns_;
  log_.sync(cycle_, sync_lower_ns_);
  note_tx(send_classic(sync), dropped, down);

  // Until every joint has its fresh feedback (and, on a classic bus, its timing frame).
  auto complete = [&]() noexcept {
    if (fresh_count_ < joints_) return false;
    for (int j = 0; j < joints_; ++j)
      if (!have_timing_[static_cast<std::size_t>(j)]) return false;
    return true;
  };
  detail::poll_until(fd_, deadline_ns, [&] { return peer_closed_ || complete(); }, [&] { drain(rt_off); });

  out.joints = joints_;
  out.seq = cycle_;
  out.stamp_ns = fresh_count_ > 0 ? stamp_ns_ : detail::monotonic_ns();
  out.timing = FeedbackTiming::kModule;
  int late_used = 0;  // joints whose sample is a late answer (PROTOCOL.md §4)
  const bool bus_bad = down || bus_off_ || error_passive_ || bus_error_cycle_;
  for (int j = 0; j < joints_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    std::uint16_t st = status_[ju];
    out.sample_ns[ju] = 0;
    out.late_applied_ns[ju] = 0;
    const unsigned modulus = fd_mode_ ? 256u : 16u;  // of the applied tag (the echo: 16 on both)
    ModuleClock& clk = clocks_[ju];
    const LateSample& late = late_[ju];
    // A late record (its values not used) tells when the module applied which command; only
    // with its values (the SYNC it answered, placed) and placed for sure.
    if (late.complete() && late.sure && clk.started() && !late.timing.no_command) {
      out.late_applied_ns[ju] = applied_host_ns(late.timing, clk);
      out.late_applied_seq[ju] = log_.applied(late.answered, late.timing.applied_tag, modulus);
      if (out.late_applied_seq[ju] == kUnknownSeq) out.late_applied_ns[ju] = 0;
    }
    if (rc_[ju].fresh && !have_timing_[ju]) {
      st |= kStatusNoTiming;
    } else if (rc_[ju].fresh) {
      hand_out(timing_[ju], log_, fresh_answered_[ju], fresh_sure_[ju], modulus, clk, handed_[ju],
               out, ju);
    } else if (late.complete() && handed_[ju].newer(late.timing.sample_us)) {
      // No fresh answer, but a late one (values and record of the same SYNC): an older sample at
      // its own module time. It updates the clock with the lower bound of the SYNC it answered.
      const wire::ModuleTiming& t = late.timing;
      last_[ju] = late.values;
      hand_out(t, log_, late.answered, late.sure, modulus, clk, handed_[ju], out, ju);
      out.late_applied_ns[ju] = 0;
      ++counters_.late_used;
      ++late_used;
    } else {
      st |= kStatusMissing;
      ++counters_.missing;
    }
    if (bus_bad) st |= kStatusBusError;
    track_[ju].end_cycle(cycle_, rc_[ju].fresh);
    JointSample sample = last_[ju];
    sample.status = static_cast<std::uint16_t>(st | sample.status);
    out.set_joint(ju, sample);
  }
  if (bus_bad) return IoStatus::kBusError;
  if (fresh_count_ + late_used == 0) return IoStatus::kTimeout;
  if (fresh_count_ + late_used < joints_) return IoStatus::kPartial;
  return IoStatus::kOk;
}

// ---- Commands -----------------------------------------------------------------------------------
int SocketCanDriver::pick_gains_joint(const Command& cmd) noexcept {
  const int n = cmd.joints < joints_ ? cmd.joints : joints_;
  if (n <= 0) return -1;
  // Changed gains first (round robin from the cursor), else refresh the joint at the cursor.
  for (int k = 0; k < n; ++k) {
    const int j = (gains_cursor_ + k) % n;
    const auto ju = static_cast<std::size_t>(j);
    if (!gains_sent_[ju] || sent_kp_[ju] != cmd.kp[ju] || sent_kd_[ju] != cmd.kd[ju]) {
      gains_cursor_ = (j + 1) % n;
      return j;
    }
  }
  const int j = gains_cursor_ % n;
  gains_cursor_ = (j + 1) % n;
  return j;
}

IoStatus SocketCanDriver::write(const Command& cmd) {
  bool dropped = false, down = false;
  const std::uint8_t ctr = sync_counter_;
  // The modules will name this command by its tag: classic frames carry c mod 16, FD groups c.
  log_.command(cycle_, cmd.seq);
  if (!fd_mode_) {
    for (int j = 0; j < joints_; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      can::JointCommand jc{};
      jc.counter = static_cast<std::uint8_t>(ctr & can::kClassicCounterMask);
      // Joints the command does not cover get torque off.
      jc.torque_off = cmd.torque_off || j >= cmd.joints;
      if (!jc.torque_off) {
        jc.tau = cmd.tau[ju];
        jc.beta_ref = cmd.beta_ref[ju];
        jc.beta_dot_ref = cmd.beta_dot_ref[ju];
      }
      can_frame f{};
      can::encode_command(can::node_of_joint(j), jc, f);
      note_tx(send_classic(f), dropped, down);
    }
    const int gj = pick_gains_joint(cmd);
    if (gj >= 0) {
      const auto gu = static_cast<std::size_t>(gj);
      can_frame f{};
      can::encode_gains(can::node_of_joint(gj),
                        {cmd.kp[gu], cmd.kd[gu],
                         static_cast<std::uint8_t>(ctr & can::kClassicCounterMask)},
                        f);
      const Tx t = send_classic(f);
      note_tx(t, dropped, down);
      if (t == Tx::kOk) {
        gains_sent_[gu] = true;
        sent_kp_[gu] = cmd.kp[gu];
        sent_kd_[gu] = cmd.kd[gu];
      }
    }
  } else {
    for (int g = 0; g * can::kFdJointsPerFrame < joints_; ++g) {
      can::FdCommandGroup grp{};
      grp.group = g;
      grp.counter = ctr;
      const int first = g * can::kFdJointsPerFrame;
      grp.count = joints_ - first < can::kFdJointsPerFrame ? joints_ - first
                                                           : can::kFdJointsPerFrame;
      // A group frame has one torque-off flag: any uncovered joint turns the group off.
      grp.torque_off = cmd.torque_off || first + grp.count > cmd.joints;
      if (!grp.torque_off) {
        for (int k = 0; k < grp.count; ++k) {
          const auto ju = static_cast<std::size_t>(first + k);
          grp.joint[static_cast<std::size_t>(k)] = {cmd.tau[ju], cmd.beta_ref[ju],
                                                    cmd.beta_dot_ref[ju], cmd.kp[ju], cmd.kd[ju]};
        }
      }
      canfd_frame f{};
      can::encode_fd_command(grp, f);
      note_tx(send_fd(f), dropped, down);
    }
  }
  if (down) return IoStatus::kBusError;
  return dropped ? IoStatus::kPartial : IoStatus::kOk;
}

void SocketCanDriver::safe_stop() {
  // Torque-off to every module; a full transmit queue is waited out for at most 20 ms in total.
  const std::int64_t give_up = detail::monotonic_ns() + 20'000'000;
  auto wait_writable = [&]() noexcept {
    const std::int64_t remaining = give_up - detail::monotonic_ns();
    if (remaining <= 0) return false;
    pollfd p{fd_, POLLOUT, 0};
    const timespec ts = detail::to_timespec(remaining);
    return ::ppoll(&p, 1, &ts, nullptr) > 0;
  };
  if (!fd_mode_) {
    for (int j = 0; j < joints_; ++j) {
      can::JointCommand jc{};
      jc.torque_off = true;
      jc.counter = static_cast<std::uint8_t>(sync_counter_ & can::kClassicCounterMask);
      can_frame f{};
      can::encode_command(can::node_of_joint(j), jc, f);
      Tx t;
      while ((t = send_classic(f)) == Tx::kDropped && wait_writable()) {
      }
    }
  } else {
    for (int g = 0; g * can::kFdJointsPerFrame < joints_; ++g) {
      can::FdCommandGroup grp{};
      grp.group = g;
      grp.counter = sync_counter_;
      const int first = g * can::kFdJointsPerFrame;
      grp.count = joints_ - first < can::kFdJointsPerFrame ? joints_ - first
                                                           : can::kFdJointsPerFrame;
      grp.torque_off = true;
      canfd_frame f{};
      can::encode_fd_command(grp, f);
      Tx t;
      while ((t = send_fd(f)) == Tx::kDropped && wait_writable()) {
      }
    }
  }
}

}  // namespace pedalwave::drivers
