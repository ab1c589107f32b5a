#include "pedalwave/drivers/module_emulator.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/can_io.hpp"
#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/drivers/wire.hpp"
#include "pedalwave/drivers/posix_util.hpp"

namespace pedalwave::drivers {
namespace {

constexpr std::int64_t kPollSliceNs = 1'000'000;  // stop flag checked at least every 1 ms

// Wait for input or until `until_ns`, at most one slice; with `blocked` (the last send found the
// transport full) also for room to send, and never less than a slice: a real-time thread that
// retried at once would spin and starve the kernel worker that drains the transport (a pty's).
// Returns poll's revents (0 on timeout).
short wait_input(int fd, std::int64_t now, std::int64_t until_ns, bool blocked = false) noexcept {
  std::int64_t wait = kPollSliceNs;
  if (!blocked && until_ns > 0 && until_ns - now < wait) wait = until_ns - now;
  if (wait < 0) wait = 0;
  pollfd p{fd, static_cast<short>(blocked ? POLLIN | POLLOUT : POLLIN), 0};
  const timespec ts = detail::to_timespec(wait);
  if (::ppoll(&p, 1, &ts, nullptr) <= 0) return 0;
  return p.revents;
}

void sleep_ns(std::int64_t ns) noexcept {
  const timespec ts = detail::to_timespec(ns);
  ::clock_nanosleep(CLOCK_MONOTONIC, 0, &ts, nullptr);
}

}  // namespace

// ---- Module clocks --------------------------------------------------------------------------------
void spread_module_clocks(EmulatorConfig& cfg, double drift_ppm, std::uint32_t seed) {
  std::mt19937 rng(seed);
  for (int j = 0; j < cfg.joints && j < kMaxJoints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    cfg.clock_offset_us[ju] = static_cast<std::uint32_t>(rng());
    cfg.clock_drift_ppm[ju] =
        cfg.joints > 1 ? drift_ppm * (1.0 - 2.0 * j / (cfg.joints - 1)) : drift_ppm;
  }
}

// ---- ModuleBank ---------------------------------------------------------------------------------
ModuleBank::ModuleBank(const EmulatorConfig& cfg, ModulePlant& plant)
    : cfg_(cfg), plant_(plant), rng_(cfg.faults.seed) {
  trace_.reserve(cfg.trace_syncs);
  if (cfg.joints < 1 || cfg.joints > kMaxJoints)
    throw std::invalid_argument("module emulator: joints = " + std::to_string(cfg.joints) +
                                ", expected 1…" + std::to_string(kMaxJoints));
  if (cfg.command_timeout_ns <= 0)
    throw std::invalid_argument("module emulator: command_timeout_ns = " +
                                std::to_string(cfg.command_timeout_ns) + ", expected > 0");
  if (!(cfg.faults.frame_loss >= 0 && cfg.faults.frame_loss <= 1) ||
      !(cfg.faults.bit_error >= 0 && cfg.faults.bit_error <= 1) || cfg.faults.reply_latency_ns < 0)
    throw std::invalid_argument(
        "module emulator: frame_loss = " + std::to_string(cfg.faults.frame_loss) +
        ", bit_error = " + std::to_string(cfg.faults.bit_error) + ", reply_latency_ns = " +
        std::to_string(cfg.faults.reply_latency_ns) + "; expected probabilities in [0, 1] and "
        "latency ≥ 0");
  latched_.joints = cfg.joints;
  sample_.joints = cfg.joints;
  timeout_ns_.fill(cfg.command_timeout_ns);
  off_.fill(true);  // torque off until the first command
  apply_now();
}

bool ModuleBank::silent(int j) const {
  return (faults_active() && cfg_.faults.module[static_cast<std::size_t>(j)].silent) ||
         !plant_.answering(j);
}

bool ModuleBank::lose() noexcept {
  if (!faults_active() || cfg_.faults.frame_loss <= 0) return false;
  return std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < cfg_.faults.frame_loss;
}

bool ModuleBank::corrupt() noexcept {
  if (!faults_active() || cfg_.faults.bit_error <= 0) return false;
  return std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < cfg_.faults.bit_error;
}

void ModuleBank::apply_now() noexcept {
  Command c = latched_;
  c.joints = cfg_.joints;
  bool all_off = true;
  for (int j = 0; j < cfg_.joints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (off_[ju]) {
      c.tau[ju] = 0.0;
      c.kp[ju] = 0.0;
      c.kd[ju] = 0.0;
    } else {
      all_off = false;
    }
  }
  c.torque_off = all_off;
  plant_.apply(c);
}

std::uint32_t ModuleBank::module_clock_us(int j, std::int64_t t_ns) const noexcept {
  const auto ju = static_cast<std::size_t>(j);
  const double elapsed_ns = static_cast<double>(t_ns - clock_origin_ns_);
  const double us = std::floor(elapsed_ns * (1.0 + cfg_.clock_drift_ppm[ju] * 1e-6) * 1e-3);
  // Modulo 2³²: the module's free-running counter wraps.
  return static_cast<std::uint32_t>(cfg_.clock_offset_us[ju] +
                                    static_cast<std::uint32_t>(static_cast<std::int64_t>(us) & 0xFFFFFFFFll));
}

void ModuleBank::start_clock(std::int64_t t_ns) noexcept {
  if (clock_started_) return;
  clock_started_ = true;
  clock_origin_ns_ = t_ns;
  applied_ns_.fill(t_ns);
  no_command_.fill(true);
}

namespace {
void keep_longest(std::atomic<std::int64_t>& longest, std::int64_t& last_ns, std::int64_t t_ns) {
  if (last_ns >= 0 && t_ns - last_ns > longest.load(std::memory_order_relaxed))
    longest.store(t_ns - last_ns, std::memory_order_relaxed);
  if (t_ns > last_ns) last_ns = t_ns;
}
}  // namespace

void ModuleBank::on_reply_sent(std::int64_t t_ns) noexcept {
  stats_.replies_sent.fetch_add(1, std::memory_order_relaxed);
  keep_longest(stats_.reply_gap_max_ns, last_reply_ns_, t_ns);
}

void ModuleBank::on_sync(std::uint8_t counter, std::int64_t t_ns) noexcept {
  ++syncs_;
  stats_.syncs.fetch_add(1, std::memory_order_relaxed);
  if (last_sync_ns_ >= 0 && t_ns > last_sync_ns_ && t_ns - last_sync_ns_ < 100'000'000)
    sync_interval_ns_ = t_ns - last_sync_ns_;
  if (last_sync_ns_ >= 0 && t_ns > last_sync_ns_) {
    recent_sync_ns_[recent_sync_next_] = t_ns - last_sync_ns_;
    recent_sync_next_ = (recent_sync_next_ + 1) % recent_sync_ns_.size();
    // The typical interval: the median of those recorded. Not the shortest: after an overrun
    // the next SYNC comes early (2 ms into a 10 ms period), and 10 × that held a 26 ms machine
    // stall the observer bridges (ModuleBank.ASyncThatCameEarlyAfterAnOverrun…).
    decltype(recent_sync_ns_) v{};
    std::size_t n = 0;
    for (std::int64_t x : recent_sync_ns_)
      if (x > 0) v[n++] = x;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(n / 2), v.begin() + static_cast<std::ptrdiff_t>(n));
    usual_sync_ns_ = v[n / 2];
  }
  keep_longest(stats_.sync_gap_max_ns, last_sync_ns_, t_ns);
  start_clock(t_ns);
  if (trace_.size() < trace_.capacity())
    trace_.push_back({syncs_, t_ns, detail::monotonic_ns(), front_ns_ > t_ns ? front_ns_ - t_ns : 0});
  // 1. Integrate up to the SYNC with the commands applied so far.
  advance_plant(t_ns);
  last_advance_ns_ = t_ns;
  // 2. Command lifetime: a module without a valid command for command_timeout turns its output
  //    off now (and says so: "no command").
  bool changed = false;
  for (int j = 0; j < cfg_.joints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (have_cmd_[ju] && timeout_ns_[ju] > 0 && t_ns - last_cmd_ns_[ju] > timeout_ns_[ju]) {
      have_cmd_[ju] = false;
      off_[ju] = true;
      no_command_[ju] = true;
      applied_ns_[ju] = t_ns;
      changed = true;
      stats_.lifetime_expired.fetch_add(1, std::memory_order_relaxed);
    }
  }
  if (changed) apply_now();
  // 3. Sample, stamp with each module's clock.
  plant_.measure(sample_);
  sample_.joints = cfg_.joints;
  sample_.seq = syncs_;
  sample_.stamp_ns = t_ns;
  for (int j = 0; j < cfg_.joints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    sample_.status[ju] = static_cast<std::uint16_t>(
        (sample_.status[ju] & wire::kModuleStatusMask & ~kStatusTorqueOff) |
        (off_[ju] ? kStatusTorqueOff : 0));
    wire::ModuleTiming& tm = timing_[ju];
    tm.sample_us = module_clock_us(j, t_ns);
    const std::uint32_t age = tm.sample_us - module_clock_us(j, applied_ns_[ju]);
    tm.applied_age_us = static_cast<std::uint16_t>(age > wire::kAgeMaxUs ? wire::kAgeMaxUs : age);
    tm.no_command = no_command_[ju];
    tm.applied_tag = applied_tag_[ju];
  }
  // 4. The counter each module echoes (rolling-counter faults).
  for (int j = 0; j < cfg_.joints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const CounterFault f = faults_active() ? cfg_.faults.module[ju].counter : CounterFault::kNone;
    if (f == CounterFault::kNone) echo_[ju] = counter;
    else if (f == CounterFault::kBackwards) echo_[ju] = static_cast<std::uint8_t>(echo_[ju] - 1);
    // kRepeat: keep the previous echo
  }
}

void ModuleBank::advance_plant(std::int64_t t_ns) noexcept {
  if (front_ns_ >= 0 && t_ns < front_ns_) {
    stats_.stamped_behind.fetch_add(1, std::memory_order_relaxed);
    if (front_ns_ - t_ns > stats_.stamped_behind_max_ns.load(std::memory_order_relaxed))
      stats_.stamped_behind_max_ns.store(front_ns_ - t_ns, std::memory_order_relaxed);
  }
  plant_.advance_to(t_ns);
  if (t_ns > front_ns_) front_ns_ = t_ns;
}

void ModuleBank::keep_up(std::int64_t now_ns) noexcept {
  if (!clock_started_ || last_sync_ns_ < 0 || sync_interval_ns_ <= 0) return;
  if (now_ns - last_sync_ns_ > cfg_.command_timeout_ns) return;  // the host is away: the plant waits
  if (now_ns - last_advance_ns_ < 2 * sync_interval_ns_) return;
  bool any_on = false;  // after a safe stop (every output off) the plant waits for the host
  for (int j = 0; j < cfg_.joints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    any_on = any_on || (have_cmd_[ju] && !off_[ju]);
  }
  if (!any_on) return;
  advance_plant(now_ns);
  last_advance_ns_ = now_ns;
  stats_.keep_ups.fetch_add(1, std::memory_order_relaxed);
}

void ModuleBank::on_turn(std::int64_t now_ns) noexcept {
  constexpr std::int64_t kSelfStallNs = 20'000'000;
  constexpr std::int64_t kHoldIntervals = 10;
  if (last_turn_ns_ >= 0 && clock_started_ && now_ns - last_turn_ns_ > kSelfStallNs) {
    const std::int64_t held = now_ns - std::max(last_turn_ns_, last_advance_ns_);
    // Only a span no host integrates across is held (see the header); a shorter one is
    // integrated at the next SYNC or keep_up, as a real robot's world would have moved.
    if (held > 0 && (usual_sync_ns_ <= 0 || held > kHoldIntervals * usual_sync_ns_)) {
      plant_.hold(held);
      last_advance_ns_ += held;
      if (front_ns_ >= 0) front_ns_ += held;
      stats_.self_stall_holds.fetch_add(1, std::memory_order_relaxed);
    }
    stats_.self_stalls.fetch_add(1, std::memory_order_relaxed);
    stats_.self_stall_ns.fetch_add(now_ns - last_turn_ns_, std::memory_order_relaxed);
  }
  last_turn_ns_ = now_ns;
}

std::int64_t ModuleBank::take_thread_stall() noexcept {
  const FaultConfig& f = cfg_.faults;
  if (f.thread_stall_ns <= 0 || f.stall_first_sync == 0) return 0;
  if (next_stall_sync_ == 0) next_stall_sync_ = f.stall_first_sync;
  if (syncs_ < next_stall_sync_) return 0;
  next_stall_sync_ = f.stall_every_syncs > 0 ? syncs_ + f.stall_every_syncs : ~std::uint64_t{0};
  return f.thread_stall_ns;
}

void ModuleBank::latch(int j, double tau, double beta_ref, double beta_dot_ref, bool has_gains,
                       double kp, double kd, bool torque_off, std::uint8_t tag,
                       std::int64_t t_ns) noexcept {
  if (j < 0 || j >= cfg_.joints) return;
  const auto ju = static_cast<std::size_t>(j);
  // Up to the arrival the previous command acts; from it on this one.
  if (clock_started_) {
    advance_plant(t_ns);
    last_advance_ns_ = t_ns;
  }
  start_clock(t_ns);
  latched_.tau[ju] = tau;
  latched_.beta_ref[ju] = beta_ref;
  latched_.beta_dot_ref[ju] = beta_dot_ref;
  if (has_gains) {
    latched_.kp[ju] = kp;
    latched_.kd[ju] = kd;
  }
  last_cmd_ns_[ju] = t_ns;
  have_cmd_[ju] = true;
  cmd_off_[ju] = torque_off;
  applied_ns_[ju] = t_ns;
  applied_tag_[ju] = tag;
  no_command_[ju] = false;
  stats_.commands.fetch_add(1, std::memory_order_relaxed);
  if (torque_off) {
    stats_.torque_off_cmds.fetch_add(1, std::memory_order_relaxed);
    std::uint64_t none = 0;
    if (!off_[ju]) stats_.first_off_sync.compare_exchange_strong(none, syncs_, std::memory_order_relaxed);
  }
  off_[ju] = torque_off;
  apply_now();
}

void ModuleBank::set_command_timeout(int j, std::int64_t ns) noexcept {
  if (j >= 0 && j < cfg_.joints) timeout_ns_[static_cast<std::size_t>(j)] = ns < 0 ? 0 : ns;
}

void ModuleBank::latch_gains(int j, double kp, double kd) noexcept {
  if (j < 0 || j >= cfg_.joints) return;
  latched_.kp[static_cast<std::size_t>(j)] = kp;
  latched_.kd[static_cast<std::size_t>(j)] = kd;
}

// ---- CAN front end ------------------------------------------------------------------------------
CanModuleEmulator::CanModuleEmulator(int fd, const EmulatorConfig& cfg, ModulePlant& plant)
    : fd_(fd), bank_(cfg, plant), wire_(cfg.bus.wire) {
  if (fd < 0 || !detail::set_nonblocking(fd))
    throw std::invalid_argument("CAN module emulator: fd = " + std::to_string(fd) +
                                ", expected an open socket");
}

void CanModuleEmulator::run(const std::atomic<bool>& stop) {
  while (!stop.load(std::memory_order_acquire)) {
    std::int64_t now = detail::monotonic_ns();
    const std::int64_t due = head_ != tail_ ? queue_[head_].due_ns : 0;
    const short ev = wait_input(fd_, now, due, blocked_ && head_ != tail_);
    if (const std::int64_t held = bank_.take_thread_stall(); held > 0) sleep_ns(held);
    bank_.on_turn(detail::monotonic_ns());
    bool got = false;
    for (;;) {
      canfd_frame f{};
      const ssize_t n = ::recv(fd_, &f, sizeof f, MSG_DONTWAIT);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      got = true;
      handle(f, static_cast<std::size_t>(n), detail::monotonic_ns());
    }
    if (!got && (ev & (POLLHUP | POLLERR))) sleep_ns(kPollSliceNs);  // peer gone: don't spin
    now = detail::monotonic_ns();
    flush(now);
    bank_.keep_up(now);
    bank_.end_turn(detail::monotonic_ns());
  }
}

std::int64_t CanModuleEmulator::wire_ns(std::size_t mtu, int len) const noexcept {
  const BusTimingConfig& b = bank_.config().bus;
  double s = 0.0;
  if (mtu == CANFD_MTU && bank_.config().fd) {
    const CanFdFrameBits bits = canfd_frame_bits(len);
    s = bits.nominal / b.bitrate + bits.data / b.data_bitrate;
  } else {
    s = can_classic_frame_bits(len) / b.bitrate;
  }
  return static_cast<std::int64_t>(std::llround(s * 1e9));
}

void CanModuleEmulator::handle(const canfd_frame& rec, std::size_t n, std::int64_t now) noexcept {
  can_frame c{};
  if (n != CAN_MTU && n != CANFD_MTU) {
    bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  // The frame has reached the modules when its last bit has crossed the bus.
  const std::int64_t arrival = wire_.occupy(now, wire_ns(n, rec.len));
  if (n == CAN_MTU) {
    std::memcpy(&c, &rec, CAN_MTU);
    handle_classic(c, arrival);
    return;
  }
  if (can::fd_to_classic(rec, c)) {
    handle_classic(c, arrival);
    return;
  }
  can::FdCommandGroup grp{};
  const canid_t id = rec.can_id & CAN_SFF_MASK;
  if (id < can::kFdCommandBase || id >= can::kFdCommandBase + can::kMaxFdGroups) return;
  if (can::decode_fd_command(rec, grp) != can::CodecStatus::kOk) {
    bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  for (int k = 0; k < grp.count; ++k) {
    const can::FdJointCommand& jc = grp.joint[static_cast<std::size_t>(k)];
    bank_.latch(grp.group * can::kFdJointsPerFrame + k, jc.tau, jc.beta_ref, jc.beta_dot_ref, true,
                jc.kp, jc.kd, grp.torque_off, grp.counter, arrival);
  }
}

void CanModuleEmulator::handle_classic(const can_frame& f, std::int64_t now) noexcept {
  if (f.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG | CAN_EFF_FLAG)) return;
  const canid_t id = f.can_id & CAN_SFF_MASK;
  int node = 0;
  if (id == can::kSyncId) {
    std::uint8_t ctr = 0;
    if (can::decode_sync(f, ctr) == can::CodecStatus::kOk) on_sync(ctr, now);
    else bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
  } else if (id > can::kCommandBase && id <= can::kCommandBase + can::kMaxNode) {
    can::JointCommand jc{};
    if (can::decode_command(f, node, jc) == can::CodecStatus::kOk)
      bank_.latch(can::joint_of_node(node), jc.tau, jc.beta_ref, jc.beta_dot_ref, false, 0.0, 0.0,
                  jc.torque_off, jc.counter, now);
    else bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
  } else if (id > can::kGainsBase && id <= can::kGainsBase + can::kMaxNode) {
    can::JointGains g{};
    if (can::decode_gains(f, node, g) == can::CodecStatus::kOk)
      bank_.latch_gains(can::joint_of_node(node), g.kp, g.kd);
    else bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
  }
  // Other ids (e.g. other modules' feedback on a real bus) are not ours.
}

void CanModuleEmulator::enqueue(std::int64_t due, const canfd_frame& f, std::size_t size) noexcept {
  const std::size_t next = (tail_ + 1) % queue_.size();
  if (next == head_) {  // queue full: the answer is lost
    bank_.stats().replies_dropped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  Pending& p = queue_[tail_];
  p.due_ns = due;
  p.frame = f;
  p.size = size;
  tail_ = next;
}

void CanModuleEmulator::on_sync(std::uint8_t counter, std::int64_t now) noexcept {
  bank_.on_sync(counter, now);
  const Feedback& s = bank_.sample();
  const std::int64_t latency = bank_.latency_ns();
  const bool fd = bank_.config().fd;
  EmulatorStats& st = bank_.stats();
  // Which modules answer this SYNC (loss, silence, corruption drawn once per module).
  std::array<bool, kMaxJoints> answer{};
  std::array<bool, kMaxJoints> corrupt{};
  for (int j = 0; j < bank_.joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    answer[ju] = !(bank_.silent(j) || bank_.lose());
    if (!answer[ju]) st.replies_dropped.fetch_add(1, std::memory_order_relaxed);
    corrupt[ju] = answer[ju] && bank_.corrupt();
    if (corrupt[ju]) st.replies_corrupted.fetch_add(1, std::memory_order_relaxed);
  }
  auto flip = [&](std::uint8_t* data, int len) {
    const std::uint32_t r = bank_.random();
    data[r % static_cast<std::uint32_t>(len)] ^= static_cast<std::uint8_t>(1u << ((r >> 8) % 8));
  };
  // Feedback frames in arbitration order (0x181, 0x182, …), then on a classic bus the timing
  // frames (0x381, …); each leaves the wire after the one before.
  for (int j = 0; j < bank_.joints(); ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (!answer[ju]) continue;
    const can::FeedbackFrame fb{s.joint(ju), bank_.echo(j)};
    canfd_frame out{};
    std::size_t size = CAN_MTU;
    if (fd) {
      can::encode_feedback_fd(can::node_of_joint(j), fb, bank_.timing(j), out);
      size = CANFD_MTU;
    } else {
      can_frame f{};
      can::encode_feedback(can::node_of_joint(j), fb, f);
      std::memcpy(&out, &f, CAN_MTU);
    }
    if (corrupt[ju]) flip(out.data, out.len);
    enqueue(wire_.occupy(now, wire_ns(size, out.len)) + latency, out, size);
  }
  if (!fd) {
    for (int j = 0; j < bank_.joints(); ++j) {
      const auto ju = static_cast<std::size_t>(j);
      if (!answer[ju]) continue;
      can_frame f{};
      can::encode_timing(can::node_of_joint(j), bank_.timing(j), bank_.echo(j), f);
      canfd_frame out{};
      std::memcpy(&out, &f, CAN_MTU);
      enqueue(wire_.occupy(now, wire_ns(CAN_MTU, 8)) + latency, out, CAN_MTU);
    }
  }
  flush(detail::monotonic_ns());
}

void CanModuleEmulator::flush(std::int64_t now) noexcept {
  blocked_ = false;
  while (head_ != tail_ && queue_[head_].due_ns <= now) {
    const Pending& p = queue_[head_];
    const Send s = send_frame(fd_, &p.frame, p.size);
    if (s == Send::kFull) {
      blocked_ = true;
      return;
    }
    if (s == Send::kSent) bank_.on_reply_sent(now);
    head_ = (head_ + 1) % queue_.size();
  }
}

// ---- Serial front end ---------------------------------------------------------------------------
SerialModuleEmulator::SerialModuleEmulator(int fd, const EmulatorConfig& cfg, ModulePlant& plant)
    : fd_(fd), bank_(cfg, plant), wire_(cfg.bus.wire), power_on_ns_(detail::monotonic_ns()) {
  if (fd < 0 || !detail::set_nonblocking(fd))
    throw std::invalid_argument("serial module emulator: fd = " + std::to_string(fd) +
                                ", expected an open tty/pty");
  // Each module's control table at power-on (PROTOCOL.md §3.2; X-series bus: §3.6).
  x_ = cfg.serial_devices == SerialDevices::kXSeries;
  const double delay_steps = std::clamp(std::round(cfg.bus.return_delay_s / 2e-6), 0.0, 254.0);
  const int baud_ix = dxl::baud_index(cfg.bus.baud);
  const auto baud_reg = static_cast<std::uint8_t>(baud_ix < 0 ? 0xFF : baud_ix);  // 0xFF: a rate
                                                                                   // outside the index
  const std::int64_t timeout_ms = (cfg.command_timeout_ns + 999'999) / 1'000'000;
  if (x_ && (cfg.x.sensor_id_offset < bank_.joints() ||
             cfg.x.sensor_id_offset + bank_.joints() > 252 || !(cfg.x.torque_constant > 0) ||
             !(cfg.x.current_lsb > 0)))
    throw std::invalid_argument("serial module emulator: X-series sensor_id_offset = " +
                                std::to_string(cfg.x.sensor_id_offset) + ", torque_constant = " +
                                std::to_string(cfg.x.torque_constant) + ", current_lsb = " +
                                std::to_string(cfg.x.current_lsb) +
                                "; expected the sensor IDs clear of the servos' and ≤ 252, both > 0");
  for (int j = 0; j < bank_.joints(); ++j) {
    auto& t = table_[static_cast<std::size_t>(j)];
    t[dxl::kRegId] = static_cast<std::uint8_t>(j + 1);
    t[dxl::kRegBaud] = baud_reg;
    t[dxl::kRegReturnDelay] = static_cast<std::uint8_t>(delay_steps);
    if (!x_) {
      wire::put_u16(t.data() + dxl::kRegModelNumber, dxl::kModelNumber);
      t[dxl::kRegFirmware] = dxl::kFirmwareVersion;
      wire::put_u16(t.data() + dxl::kRegCommandTimeout,
                    static_cast<std::uint16_t>(std::min<std::int64_t>(timeout_ms, 0xFFFF)));
    } else {
      wire::put_u16(t.data() + dxl::x::kRegModelNumber, cfg.x.model);
      t[dxl::x::kRegFirmware] = 45;
      t[dxl::x::kRegOperatingMode] = 3;  // position control, as shipped: the host must set 0
      wire::put_u16(t.data() + dxl::x::kRegCurrentLimit, cfg.x.current_limit);
      bank_.set_command_timeout(j, 0);  // a stock servo keeps its goal (no bus watchdog set)
      auto& st = table_[static_cast<std::size_t>(kSensor + j)];
      wire::put_u16(st.data(), dxl::x::kSensorModelNumber);
      st[2] = 1;
      st[dxl::kRegId] = static_cast<std::uint8_t>(j + 1 + cfg.x.sensor_id_offset);
      st[dxl::kRegBaud] = baud_reg;
      st[dxl::kRegReturnDelay] = static_cast<std::uint8_t>(delay_steps);
      reset_ram(kSensor + j);
    }
    reset_ram(j);
  }
}

std::span<const dxl::Register> SerialModuleEmulator::registers(int d) const noexcept {
  if (!x_) return dxl::kRegisters;
  return d >= kSensor ? std::span<const dxl::Register>(dxl::x::kSensorRegisters)
                      : std::span<const dxl::Register>(dxl::x::kRegisters);
}

std::uint16_t SerialModuleEmulator::table_size(int d) const noexcept {
  if (!x_) return dxl::kTableSize;
  return d >= kSensor ? dxl::x::kSensorTableSize : dxl::x::kTableSize;
}

void SerialModuleEmulator::reset_ram(int d) noexcept {
  auto& t = table_[static_cast<std::size_t>(d)];
  std::fill(t.begin() + dxl::kRegTorqueEnable, t.end(), std::uint8_t{0});
  t[dxl::kRegStatusReturnLevel] = 2;
}

void SerialModuleEmulator::run(const std::atomic<bool>& stop) {
  const std::int64_t inter_byte_ns = bank_.config().bus.inter_byte_timeout_ns;
  while (!stop.load(std::memory_order_acquire)) {
    std::int64_t now = detail::monotonic_ns();
    const std::int64_t due = head_ != tail_ ? queue_[head_].due_ns : 0;
    const short ev = wait_input(fd_, now, due, blocked_ && head_ != tail_);
    if (const std::int64_t held = bank_.take_thread_stall(); held > 0) sleep_ns(held);
    bank_.on_turn(detail::monotonic_ns());
    bool got = false;
    for (;;) {
      if (rx_len_ == rx_.size()) rx_len_ = 0;  // overrun: drop everything (a resync follows)
      const ssize_t n = ::read(fd_, rx_.data() + rx_len_, rx_.size() - rx_len_);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      rx_len_ += static_cast<std::size_t>(n);
      got = true;
    }
    now = detail::monotonic_ns();
    if (got) {
      last_rx_ns_ = now;
      process(now);
    } else if (rx_len_ > 0 && inter_byte_ns > 0 && now - last_rx_ns_ > inter_byte_ns) {
      // Inter-byte timeout: the packet at the front is no packet (a LEN too long, a line cut
      // mid-packet); without it, it would swallow the packets that follow. Its header is
      // dropped and the bytes after it are parsed again (a whole packet among them is handled).
      bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
      std::memmove(rx_.data(), rx_.data() + 1, rx_len_ - 1);
      --rx_len_;
      resync_ = true;
      last_rx_ns_ = now;  // what is left gets its own timeout
      process(now);
    }
    if (!got && (ev & (POLLHUP | POLLERR))) sleep_ns(kPollSliceNs);  // no peer yet / any more
    now = detail::monotonic_ns();
    flush(now);
    bank_.keep_up(now);
    bank_.end_turn(detail::monotonic_ns());
  }
}

void SerialModuleEmulator::process(std::int64_t now) noexcept {
  std::size_t pos = 0;
  while (pos < rx_len_) {
    std::size_t used = 0;
    const dxl::DxlStatus s = dxl::parse_packet(
        std::span<const std::uint8_t>(rx_.data() + pos, rx_len_ - pos), pkt_, used);
    if (s == dxl::DxlStatus::kNeedMore) break;
    packet_bytes_ = used;
    if (s == dxl::DxlStatus::kOk) {
      resync_ = false;
      handle(now);
    } else if (s == dxl::DxlStatus::kChecksum) {
      // Resynchronize on the next byte: a LEN corrupted too long would otherwise take the
      // packets inside it along (byte stuffing keeps a header out of a packet's body).
      used = 1;
      resync_ = true;
      bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
    } else if (!(s == dxl::DxlStatus::kGarbage && resync_)) {
      bank_.stats().rx_errors.fetch_add(1, std::memory_order_relaxed);
    }
    pos += used;
  }
  if (pos > 0) {
    std::memmove(rx_.data(), rx_.data() + pos, rx_len_ - pos);
    rx_len_ -= pos;
  }
}

void SerialModuleEmulator::enqueue(std::int64_t due, const std::uint8_t* p, std::size_t n,
                                   bool feedback) noexcept {
  const std::size_t next = (tail_ + 1) % queue_.size();
  if (next == head_ || n > queue_[tail_].bytes.size()) {
    bank_.stats().replies_dropped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  Pending& q = queue_[tail_];
  q.due_ns = due;
  q.len = n;
  q.off = 0;
  q.feedback = feedback;
  std::memcpy(q.bytes.data(), p, n);
  tail_ = next;
}

std::int64_t SerialModuleEmulator::bytes_ns(std::size_t n) const noexcept {
  return static_cast<std::int64_t>(std::llround(static_cast<double>(n) * 10.0 * 1e9 /
                                                static_cast<double>(bank_.config().bus.baud)));
}

int SerialModuleEmulator::joint_of(std::uint8_t id) const noexcept {
  for (int j = 0; j < bank_.joints(); ++j)
    if (table_[static_cast<std::size_t>(j)][dxl::kRegId] == id) return j;
  if (x_)
    for (int j = 0; j < bank_.joints(); ++j)
      if (table_[static_cast<std::size_t>(kSensor + j)][dxl::kRegId] == id) return kSensor + j;
  return -1;
}

void SerialModuleEmulator::sample_now(std::int64_t now) noexcept {
  bank_.on_sync(++x_syncs_, now);
}

void SerialModuleEmulator::refresh(int d) noexcept {
  const int j = d >= kSensor ? d - kSensor : d;
  const auto ju = static_cast<std::size_t>(j);
  auto& t = table_[static_cast<std::size_t>(d)];
  const Feedback& s = bank_.sample();
  t[dxl::kRegHardwareError] = static_cast<std::uint8_t>(
      ((s.status[ju] & kStatusOverTemp) ? dxl::kHwErrOverheating : 0) |
      ((s.status[ju] & kStatusEncoderFault) ? dxl::kHwErrEncoder : 0));
  if (!x_) {
    t[dxl::kRegTorqueEnable] = bank_.torque_off(j) ? 0 : 1;
    const dxl::FeedbackBlock fb{s.joint(ju), bank_.echo(j), bank_.timing(j)};
    dxl::encode_feedback_block(fb, t.data() + dxl::kRegFeedback);
    return;
  }
  std::uint8_t f = 0;
  if (d >= kSensor) {
    wire::put_i16(t.data() + dxl::x::kRegSensorDeflection,
                  wire::to_i16(s.deflection[ju], wire::kDeflectionLsb, f));
    return;
  }
  // The servo: what its current controller delivers (the goal, with torque on in current mode),
  // the output shaft's rate and angle in its units.
  // The Bus Watchdog expired (the bank's lifetime turned the output off): it reads −1.
  if (t[dxl::x::kRegBusWatchdog] != 0 && t[dxl::x::kRegTorqueEnable] != 0 && bank_.timing(j).no_command &&
      bank_.torque_off(j))
    t[dxl::x::kRegBusWatchdog] = 0xFF;
  const bool driving = t[dxl::x::kRegTorqueEnable] != 0 &&
                       t[dxl::x::kRegOperatingMode] == dxl::x::kOperatingModeCurrent &&
                       t[dxl::x::kRegBusWatchdog] != 0xFF;
  wire::put_u16(t.data() + dxl::x::kRegPresentCurrent,
                driving ? wire::get_u16(t.data() + dxl::x::kRegGoalCurrent) : 0);
  wire::put_u32(t.data() + dxl::x::kRegPresentVelocity,
                static_cast<std::uint32_t>(static_cast<std::int32_t>(
                    std::lround(s.beta_dot[ju] / dxl::x::kVelocityLsb))));
  wire::put_u32(t.data() + dxl::x::kRegPresentPosition,
                static_cast<std::uint32_t>(static_cast<std::int32_t>(
                    std::lround(s.beta[ju] / dxl::x::kPositionLsb))));
  // Realtime Tick: the servo's millisecond clock when the request it answers arrived (a Bulk
  // Read's sample time, a Read's own).
  wire::put_u16(t.data() + dxl::x::kRegRealtimeTick,
                realtime_tick(j, request_ns_));
}

// The servo's millisecond counter, running from power-on (the emulator's start) at its clock's
// rate (EmulatorConfig::clock_drift_ppm, clock_offset_us), at host time t_ns.
std::uint16_t SerialModuleEmulator::realtime_tick(int j, std::int64_t t_ns) const noexcept {
  const auto ju = static_cast<std::size_t>(j);
  const EmulatorConfig& c = bank_.config();
  const double ms = static_cast<double>(t_ns - power_on_ns_) * (1.0 + c.clock_drift_ppm[ju] * 1e-6) * 1e-6 +
                    c.clock_offset_us[ju] * 1e-3;
  return static_cast<std::uint16_t>(static_cast<std::uint64_t>(std::floor(std::max(ms, 0.0))) % dxl::x::kTickWrap);
}

std::uint8_t SerialModuleEmulator::read_table(int d, std::uint16_t addr, std::uint16_t len) noexcept {
  const std::uint8_t err = dxl::check_read(registers(d), table_size(d), addr, len);
  if (err != 0) return err;
  refresh(d);
  std::memcpy(reply_.data(), table_[static_cast<std::size_t>(d)].data() + addr, len);
  return 0;
}

void SerialModuleEmulator::latch_servo(int j, std::int64_t now) noexcept {
  const auto& t = table_[static_cast<std::size_t>(j)];
  const XSeriesConfig& x = bank_.config().x;
  const bool on = t[dxl::x::kRegTorqueEnable] != 0;
  const bool current_mode = t[dxl::x::kRegOperatingMode] == dxl::x::kOperatingModeCurrent;
  const double tau = on && current_mode ? wire::get_i16(t.data() + dxl::x::kRegGoalCurrent) *
                                              x.current_lsb * x.torque_constant
                                        : 0.0;
  bank_.latch(j, tau, 0.0, 0.0, true, 0.0, 0.0, !on, 0, now);
}

void SerialModuleEmulator::latch_block(int j, bool off, std::int64_t now) noexcept {
  dxl::CommandBlock c{};
  dxl::decode_command_block(table_[static_cast<std::size_t>(j)].data() + dxl::kRegCommand, c);
  bank_.latch(j, c.tau, c.beta_ref, c.beta_dot_ref, true, c.kp, c.kd, off || c.torque_off,
              c.counter, now);
}

std::uint8_t SerialModuleEmulator::write_table(int d, std::uint16_t addr,
                                               std::span<const std::uint8_t> data,
                                               std::int64_t now) noexcept {
  bool eeprom = false;
  const std::uint8_t err = dxl::check_write(registers(d), table_size(d), addr, data, eeprom);
  if (err != 0) return err;
  auto& t = table_[static_cast<std::size_t>(d)];
  const bool torque_on = x_ ? d < kSensor && t[dxl::x::kRegTorqueEnable] != 0 : !bank_.torque_off(d);
  if (eeprom && torque_on) return dxl::kErrAccess;  // EEPROM: torque off only
  // After a Bus Watchdog error the goal values are read-only until 98 is written 0 (e-Manual).
  if (x_ && d < kSensor && t[dxl::x::kRegBusWatchdog] == 0xFF &&
      addr < dxl::x::kRegGoalCurrent + 2 && std::size_t{addr} + data.size() > dxl::x::kRegGoalCurrent)
    return dxl::kErrAccess;
  const bool was_on = t[dxl::kRegTorqueEnable] != 0;
  std::memcpy(t.data() + addr, data.data(), data.size());
  const std::size_t end = std::size_t{addr} + data.size();
  auto touches = [&](std::uint16_t first, std::size_t n) { return addr < first + n && end > first; };
  if (x_) {
    // A servo's Bus Watchdog (98, 20 ms steps, 0 = off): the bank's command lifetime — a servo
    // that got no Goal Current / Torque Enable for that long turns its output off (PROTOCOL.md §3.6).
    if (d < kSensor && touches(dxl::x::kRegBusWatchdog, 1))
      bank_.set_command_timeout(d, std::int64_t{t[dxl::x::kRegBusWatchdog]} * dxl::x::kBusWatchdogUnitNs);
    // A servo: a new goal current or torque enable acts at once (a sensor has nothing to act).
    if (d < kSensor && (touches(dxl::x::kRegGoalCurrent, 2) ||
                        (touches(dxl::x::kRegTorqueEnable, 1) &&
                         was_on != (t[dxl::x::kRegTorqueEnable] != 0))))
      latch_servo(d, now);
    return 0;
  }
  if (touches(dxl::kRegCommandTimeout, 2))
    bank_.set_command_timeout(d, std::int64_t{wire::get_u16(t.data() + dxl::kRegCommandTimeout)} *
                                     1'000'000);
  // Torque enable = 0 on a module already off changes nothing (no command is latched).
  const bool enable = touches(dxl::kRegTorqueEnable, 1) &&
                      !(t[dxl::kRegTorqueEnable] == 0 && bank_.torque_off(d));
  if (touches(dxl::kRegCommand, dxl::kCommandBlockSize) || enable)
    latch_block(d, touches(dxl::kRegTorqueEnable, 1) && t[dxl::kRegTorqueEnable] == 0, now);
  return 0;
}

void SerialModuleEmulator::answer(int d, std::uint8_t err, std::span<const std::uint8_t> params,
                                  Kind kind, std::int64_t now, bool cycle) noexcept {
  const int j = d >= kSensor ? d - kSensor : d;
  const auto ju = static_cast<std::size_t>(d);
  const std::uint8_t level = table_[ju][dxl::kRegStatusReturnLevel];
  if ((kind == Kind::kRead && level < 1) || (kind == Kind::kOther && level < 2)) return;
  EmulatorStats& st = bank_.stats();
  if (bank_.silent(j) || (cycle && bank_.lose())) {
    st.replies_dropped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  refresh(d);
  if (table_[ju][dxl::kRegHardwareError] != 0) err |= dxl::kErrAlert;
  std::array<std::uint8_t, 256> out{};
  std::size_t n = 0;
  if (dxl::build_status(table_[ju][dxl::kRegId], err, params, out, n) != dxl::DxlStatus::kOk) return;
  if (cycle && bank_.corrupt()) {
    // Flip one bit of a parameter byte (after the header and length), so the CRC fails.
    const std::uint32_t r = bank_.random();
    const std::size_t first = dxl::kHeaderSize + 2, span = n - 2 - first;
    out[first + r % span] ^= static_cast<std::uint8_t>(1u << ((r >> 8) % 8));
    st.replies_corrupted.fetch_add(1, std::memory_order_relaxed);
  }
  // Each module answers its return delay (register 9, 2 µs) after the line went quiet.
  const std::int64_t end =
      wire_.occupy(now, bytes_ns(n), std::int64_t{table_[ju][dxl::kRegReturnDelay]} * 2000);
  enqueue(end + (cycle ? bank_.latency_ns() : 0), out.data(), n, cycle && kind == Kind::kRead);
}

void SerialModuleEmulator::handle(std::int64_t read_ns) noexcept {
  const dxl::Packet& p = pkt_;
  // The packet has reached the modules when its last byte has crossed the line.
  const std::int64_t now = wire_.occupy(read_ns, bytes_ns(packet_bytes_));
  request_ns_ = now;
  EmulatorStats& st = bank_.stats();
  const int joints = bank_.joints();
  const bool broadcast = p.id == dxl::kBroadcastId;
  const int target = broadcast ? -1 : joint_of(p.id);
  const std::uint8_t* prm = p.params.data();
  const std::size_t np = p.param_count;
  const std::span<const std::uint8_t> none{};

  switch (p.instruction) {
    case dxl::kInstPing:
      for (int d = 0; d < kSensor + joints; ++d) {
        if (d == joints) d = x_ ? kSensor : kSensor + joints;  // the sensors, on an X-series bus
        if (d >= kSensor + joints || (!broadcast && d != target)) continue;
        const auto& t = table_[static_cast<std::size_t>(d)];
        const bool servo = x_ && d < kSensor;
        const std::uint8_t info[3] = {t[0], t[1], t[servo ? dxl::x::kRegFirmware : dxl::kRegFirmware]};
        answer(d, 0, info, Kind::kPing, now, false);
      }
      break;
    case dxl::kInstRead:
      if (target < 0) break;  // broadcast Read: no status packet; another ID: not ours
      if (np != 4) {
        answer(target, dxl::kErrDataLength, none, Kind::kRead, now, false);
        break;
      }
      {
        const std::uint16_t len = wire::get_u16(prm + 2);
        const std::uint8_t err = read_table(target, wire::get_u16(prm), len);
        answer(target, err, err ? none : std::span<const std::uint8_t>(reply_.data(), len),
               Kind::kRead, now, false);
      }
      break;
    case dxl::kInstWrite: {
      if (!broadcast && target < 0) break;
      if (np < 3) {
        if (target >= 0) answer(target, dxl::kErrDataLength, none, Kind::kOther, now, false);
        break;
      }
      const std::uint16_t addr = wire::get_u16(prm);
      const std::span<const std::uint8_t> data(prm + 2, np - 2);
      bool eeprom = false;
      // The serial bus's SYNC: a write of the sync counter, for the whole bank, once.
      if (!x_ && dxl::check_write(addr, data, eeprom) == 0 && addr <= dxl::kRegSyncCounter &&
          std::size_t{addr} + data.size() > dxl::kRegSyncCounter)
        bank_.on_sync(data[dxl::kRegSyncCounter - addr], now);
      if (!broadcast) {
        answer(target, write_table(target, addr, data, now), none, Kind::kOther, now, false);
        break;
      }
      for (int j = 0; j < joints; ++j) {
        (void)write_table(j, addr, data, now);
        if (x_) (void)write_table(kSensor + j, addr, data, now);
      }
      break;
    }
    case dxl::kInstSyncRead:
    case dxl::kInstBulkRead: {
      if (!broadcast) break;
      const bool bulk = p.instruction == dxl::kInstBulkRead;
      if (bulk ? np % 5 != 0 || np == 0 : np < 5) {
        st.rx_errors.fetch_add(1, std::memory_order_relaxed);
        break;
      }
      // Sync: addr, len, then IDs; Bulk: (ID, addr, len) per module. Answers in list order.
      // A stock servo samples when the read arrives (it has no sync counter).
      if (x_) sample_now(now);
      for (std::size_t k = bulk ? 0 : 4; k < np; k += bulk ? 5 : 1) {
        const int j = joint_of(prm[k]);
        if (j < 0) continue;  // another device on the bus answers for itself
        const std::uint8_t* al = bulk ? prm + k + 1 : prm;
        const std::uint16_t len = wire::get_u16(al + 2);
        const std::uint8_t err = read_table(j, wire::get_u16(al), len);
        answer(j, err, err ? none : std::span<const std::uint8_t>(reply_.data(), len), Kind::kRead,
               now, true);
      }
      flush(detail::monotonic_ns());
      return;
    }
    case dxl::kInstSyncWrite:
    case dxl::kInstBulkWrite: {
      if (!broadcast) break;
      const bool bulk = p.instruction == dxl::kInstBulkWrite;
      if (!bulk && (np < 4 || wire::get_u16(prm + 2) == 0 ||
                    (np - 4) % (1u + wire::get_u16(prm + 2)) != 0)) {
        st.rx_errors.fetch_add(1, std::memory_order_relaxed);
        break;
      }
      // Sync: addr, len, then (ID, data) per module; Bulk: (ID, addr, len, data) per module.
      std::size_t k = bulk ? 0 : 4;
      while (k < np) {
        const std::size_t head = bulk ? 5 : 1;
        if (k + head > np) break;
        const std::uint8_t* al = bulk ? prm + k + 1 : prm;
        const std::uint16_t addr = wire::get_u16(al), len = wire::get_u16(al + 2);
        if (len == 0 || k + head + len > np) {
          st.rx_errors.fetch_add(1, std::memory_order_relaxed);
          break;
        }
        const int j = joint_of(prm[k]);
        const std::span<const std::uint8_t> data(prm + k + head, len);
        bool eeprom = false;
        if (j >= 0) {
          if (!x_ && dxl::check_write(addr, data, eeprom) == 0 && addr <= dxl::kRegSyncCounter &&
              std::size_t{addr} + len > dxl::kRegSyncCounter)
            bank_.on_sync(data[dxl::kRegSyncCounter - addr], now);
          (void)write_table(j, addr, data, now);  // broadcast: no status packet
        }
        k += head + len;
      }
      break;
    }
    case dxl::kInstReboot:
      if (target < 0) break;
      answer(target, 0, none, Kind::kOther, now, false);
      reset_ram(target);
      if (!x_) latch_block(target, true, now);
      else if (target < kSensor) latch_servo(target, now);
      break;
    case dxl::kInstFastSyncRead:
    case dxl::kInstFastBulkRead:
      // Deliberately unsupported: the first listed module of ours says so.
      for (std::size_t k = p.instruction == dxl::kInstFastSyncRead ? 4 : 0; k < np;
           k += p.instruction == dxl::kInstFastSyncRead ? 1 : 5) {
        const int j = joint_of(prm[k]);
        if (j < 0) continue;
        answer(j, dxl::kErrInstruction, none, Kind::kRead, now, false);
        break;
      }
      break;
    default:  // Factory Reset, Reg Write, Action, Clear, Backup, unknown: deliberately unsupported
      if (target >= 0) answer(target, dxl::kErrInstruction, none, Kind::kOther, now, false);
      break;
  }
  flush(now);
}
void SerialModuleEmulator::flush(std::int64_t now) noexcept {
  blocked_ = false;
  while (head_ != tail_ && queue_[head_].due_ns <= now) {
    Pending& q = queue_[head_];
    const ssize_t r = ::write(fd_, q.bytes.data() + q.off, q.len - q.off);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) {  // EAGAIN: the line is full; wait for room (run())
      blocked_ = true;
      return;
    }
    q.off += static_cast<std::size_t>(r);
    if (q.off < q.len) return;
    if (q.feedback) bank_.on_reply_sent(now);
    else bank_.stats().other_replies.fetch_add(1, std::memory_order_relaxed);
    head_ = (head_ + 1) % queue_.size();
  }
}

}  // namespace pedalwave::drivers
