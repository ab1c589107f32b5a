#include "pedalwave/vrobot/virtual_robot.hpp"

#include <fcntl.h>
#include <linux/can.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <pthread.h>
#include <sched.h>
#include <sstream>
#include <system_error>

#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/model/integrators.hpp"
#include "pedalwave/drivers/socketcan_driver.hpp"

namespace pedalwave::vrobot {

VirtualRobot::VirtualRobot(const model::Scene& scene, int fd, const VirtualRobotOptions& opt)
    : opt_(opt), fd_(fd) {
  try {
    model::Scene sc = scene;
    if (opt_.max_step > 0 && !model::is_adaptive(sc.integrator.method) && sc.integrator.h > opt_.max_step)
      sc.integrator.h = opt_.max_step;
    plant_ = std::make_unique<SimulationPlant>(sc, opt_.plant);
    opt_.emulator.joints = plant_->joints();
    if (opt_.bus == Bus::kCan)
      can_ = std::make_unique<drivers::CanModuleEmulator>(fd_, opt_.emulator, *plant_);
    else if (opt_.bus == Bus::kCanOpen)
      canopen_ = std::make_unique<drivers::canopen::CanOpenModuleEmulator>(fd_, opt_.emulator, opt_.canopen, *plant_);
    else
      serial_ = std::make_unique<drivers::SerialModuleEmulator>(fd_, opt_.emulator, *plant_);
  } catch (...) {
    if (fd_ >= 0) ::close(fd_);
    throw;
  }
}

VirtualRobot::~VirtualRobot() {
  stop();
  if (fd_ >= 0) ::close(fd_);
}

void VirtualRobot::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] {
    if (can_) can_->run(stop_);
    else if (canopen_) canopen_->run(stop_);
    else serial_->run(stop_);
  });
  // Real modules are microcontrollers of their own: give the emulating thread the CPU it needs.
  thread_note_.clear();
  if (opt_.thread_priority > 0) {
    sched_param sp{};
    sp.sched_priority = opt_.thread_priority;
    const int e = ::pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &sp);
    thread_note_ = e == 0 ? "modules' thread: SCHED_FIFO " + std::to_string(opt_.thread_priority)
                          : std::string("modules' thread: SCHED_FIFO refused (") + std::strerror(e) +
                                "): normal scheduling; under CPU load replies may come late";
  }
  if (opt_.thread_cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(opt_.thread_cpu, &set);
    const int e = ::pthread_setaffinity_np(thread_.native_handle(), sizeof set, &set);
    thread_note_ += (thread_note_.empty() ? "" : "; ") +
                    (e == 0 ? "pinned to CPU " + std::to_string(opt_.thread_cpu)
                            : std::string("pinning refused (") + std::strerror(e) + ")");
  }
}

void VirtualRobot::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

drivers::ModuleBank& VirtualRobot::bank() {
  return can_ ? can_->bank() : canopen_ ? canopen_->bank() : serial_->bank();
}

const drivers::EmulatorStats& VirtualRobot::stats() {
  return can_ ? can_->stats() : canopen_ ? canopen_->stats() : serial_->stats();
}

std::string VirtualRobot::report() {
  const drivers::EmulatorStats& s = stats();
  const PlantProgress p = plant_->progress();
  const drivers::FaultConfig& f = opt_.emulator.faults;
  std::ostringstream o;
  o << "virtual robot: " << joints() << " modules on "
    << (opt_.bus == Bus::kCan ? (opt_.emulator.fd ? "CAN FD" : "classic CAN")
        : opt_.bus == Bus::kCanOpen ? "CANopen (classic CAN)" : "serial (DYNAMIXEL 2.0)")
    << "\n";
  o << "  SYNCs " << s.syncs.load() << ", replies sent " << s.replies_sent.load()
    << ", commands latched " << s.commands.load() << " (torque-off " << s.torque_off_cmds.load()
    << "), malformed/CRC-failed frames received " << s.rx_errors.load() << "\n";
  o << "  longest gap between SYNCs received " << 1e-6 * static_cast<double>(s.sync_gap_max_ns.load())
    << " ms, between replies sent " << 1e-6 * static_cast<double>(s.reply_gap_max_ns.load())
    << " ms";
  if (s.keep_ups.load() > 0)
    o << "; the plant kept at wall time " << s.keep_ups.load() << " time(s) while a SYNC was overdue";
  if (s.self_stalls.load() > 0)
    o << "; the machine held the modules' thread " << s.self_stalls.load() << " time(s) ≥ 20 ms, "
      << 1e-6 * static_cast<double>(s.self_stall_ns.load()) << " ms in all (the plant held "
      << s.self_stall_holds.load() << " of them, longer than 10 SYNC intervals; integrated the rest)";
  if (s.stamped_behind.load() > 0)
    o << "; " << s.stamped_behind.load() << " SYNC(s) or command(s) stamped before the plant's time (up to "
      << 1e-6 * static_cast<double>(s.stamped_behind_max_ns.load()) << " ms)";
  if (canopen_)
    o << "; CANopen: " << canopen_->window_dropped.load() << " TPDO(s) not sent, their SYNC's window (1007h) closed";
  if (s.rx_lost.load() > 0)
    o << "; " << s.rx_lost.load() << " frame(s) LOST before the modules' thread read them (its receive queue full)";
  o << "\n";
  o << "  faults injected: replies dropped " << s.replies_dropped.load() << ", corrupted "
    << s.replies_corrupted.load() << ", command lifetime expired " << s.lifetime_expired.load();
  o << " (latency " << static_cast<double>(f.reply_latency_ns) * 1e-6 << " ms, loss " << f.frame_loss
    << ", bit errors " << f.bit_error;
  int n_silent = 0;
  for (int j = 0; j < joints(); ++j)
    if (f.module[static_cast<std::size_t>(j)].silent)
      o << (n_silent++ == 0 ? ", silent module(s) " : ",") << j + 1;
  o << ", from SYNC " << f.onset_sync << ")\n";
  char line[256];
  std::snprintf(line, sizeof line,
                "  plant: %.3f s simulated in %llu steps, COM x %.4f m, %s%s", p.t,
                static_cast<unsigned long long>(p.steps), p.com_x,
                p.all_off ? "outputs off" : "outputs on", p.failed ? ", PLANT FAILED" : "");
  o << line;
  if (p.gaps_skipped > 0) o << ", " << p.gaps_skipped << " idle or held gap(s) of " << p.gap_time_skipped << " s not integrated";
  o << "\n";
  // The scene's faults: each applied one and whether (when) it acted; the skipped ones.
  const std::vector<model::FaultSpec>& applied = plant_->faults();
  if (!applied.empty()) o << "  scene faults (inside the modules):\n";
  for (std::size_t i = 0; i < applied.size(); ++i) {
    const double t_on = plant_->fault_onset(i);
    o << "    " << describe(applied[i]) << ": ";
    if (std::isnan(t_on)) {
      o << "never active\n";
    } else {
      std::snprintf(line, sizeof line, "active from %.3f s of plant time\n", t_on);
      o << line;
    }
  }
  for (const model::FaultSpec& skipped : plant_->skipped_faults())
    o << "  scene fault not injected: " << describe(skipped) << "\n";
  return o.str();
}

Pty open_pty() {
  Pty p;
  p.master = ::posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (p.master < 0) throw std::system_error(errno, std::generic_category(), "posix_openpt");
  std::array<char, 128> name{};
  if (::grantpt(p.master) != 0 || ::unlockpt(p.master) != 0 ||
      ::ptsname_r(p.master, name.data(), name.size()) != 0) {
    const int e = errno;
    ::close(p.master);
    throw std::system_error(e, std::generic_category(), "pty: grantpt/unlockpt/ptsname");
  }
  p.slave_path = name.data();
  p.slave_keep = ::open(p.slave_path.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC | O_NONBLOCK);
  termios tio{};
  if (p.slave_keep < 0 || ::tcgetattr(p.slave_keep, &tio) != 0) {
    const int e = errno;
    if (p.slave_keep >= 0) ::close(p.slave_keep);
    ::close(p.master);
    throw std::system_error(e, std::generic_category(), "pty: open " + p.slave_path);
  }
  ::cfmakeraw(&tio);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  if (::tcsetattr(p.slave_keep, TCSANOW, &tio) != 0) {
    const int e = errno;
    ::close(p.slave_keep);
    ::close(p.master);
    throw std::system_error(e, std::generic_category(), "pty: raw mode on " + p.slave_path);
  }
  return p;
}

int open_module_can_socket(const std::string& ifname, bool fd_frames) {
  namespace can = drivers::can;
  // SYNC exactly; 0x200…0x2FF (commands 0x201… and FD command groups 0x280…); 0x300…0x33F (gains).
  static const std::array<can_filter, 3> filters{{
      {can::kSyncId, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG},
      {can::kCommandBase, 0x700u | CAN_EFF_FLAG | CAN_RTR_FLAG},
      {can::kGainsBase, 0x7C0u | CAN_EFF_FLAG | CAN_RTR_FLAG},
  }};
  drivers::CanSocketOptions o;
  o.ifname = ifname;
  o.fd_frames = fd_frames;
  o.filters = filters;
  o.error_frames = false;
  o.timestamps = false;
  const int fd = drivers::open_can_socket(o);
  // A large receive queue: when the modules' thread is not scheduled for a while (a loaded or
  // emulated machine) the host's frames wait instead of being dropped (root may exceed rmem_max).
  const int bytes = 4 << 20;
  if (::setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &bytes, sizeof bytes) != 0)
    (void)::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
  return fd;
}

int open_canopen_module_socket(const std::string& ifname) {
  static const std::array<can_filter, 4> filters{{
      {0x000, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG},   // NMT
      {0x080, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG},   // SYNC
      {0x200, 0x600u | CAN_EFF_FLAG | CAN_RTR_FLAG},         // 200h–3FFh: RPDO 1, RPDO 2
      {0x600, 0x780u | CAN_EFF_FLAG | CAN_RTR_FLAG},         // 600h–67Fh: SDO requests
  }};
  drivers::CanSocketOptions o;
  o.ifname = ifname;
  o.filters = filters;
  o.error_frames = false;
  o.timestamps = false;
  const int fd = drivers::open_can_socket(o);
  const int bytes = 4 << 20;
  if (::setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &bytes, sizeof bytes) != 0)
    (void)::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
  return fd;
}

}  // namespace pedalwave::vrobot
