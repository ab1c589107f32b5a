// The emulated pedalwave module as a DYNAMIXEL device (PROTOCOL.md §3.2, module_emulator.hpp):
// its control table over Read / Write / Sync / Bulk, the access rules, the status return level,
// Hardware Error Status, the unsupported instructions' errors and the inter-byte timeout. The
// test plays the host on the pty slave with raw instruction packets.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <optional>
#include <system_error>
#include <thread>
#include <vector>

#include "cycle_harness.hpp"
#include "pedalwave/drivers/dynamixel.hpp"
#include "pedalwave/drivers/module_emulator.hpp"
#include "pedalwave/drivers/serial_driver.hpp"
#include "pedalwave/drivers/wire.hpp"
#include "test_plant.hpp"

namespace pd = pedalwave::drivers;
namespace dxl = pedalwave::drivers::dxl;

namespace {

constexpr std::int64_t kMs = 1'000'000;

// A plant whose joint `hot` reports over-temperature (for Hardware Error Status).
class HotPlant final : public pd::ModulePlant {
 public:
  explicit HotPlant(int hot) : hot_(hot) {}
  void apply(const pd::Command& c) override { joints_ = c.joints; }
  void measure(pd::Feedback& out) override {
    out.joints = joints_;
    for (int j = 0; j < joints_; ++j) out.status[j] = j == hot_ ? pd::kStatusOverTemp : 0;
  }
  void advance_to(std::int64_t) override {}

 private:
  int hot_, joints_ = 0;
};

struct Bus {
  int master = -1, host = -1;
  std::string slave;
  HotPlant plant;
  std::unique_ptr<pd::SerialModuleEmulator> emu;
  std::atomic<bool> stop{false};
  std::thread th;
  explicit Bus(int joints, int hot = -1) : plant(hot) {
    master = ::posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || ::grantpt(master) != 0 || ::unlockpt(master) != 0)
      throw std::system_error(errno, std::generic_category(), "posix_openpt");
    slave = ::ptsname(master);
    host = pd::open_serial_port(slave, 4'000'000);
    pd::EmulatorConfig ec;
    ec.joints = joints;
    ec.command_timeout_ns = 50 * kMs;
    emu = std::make_unique<pd::SerialModuleEmulator>(master, ec, plant);
    th = std::thread([this] { emu->run(stop); });
  }
  ~Bus() {
    stop = true;
    th.join();
    ::close(host);
    ::close(master);
  }
  void send(std::uint8_t id, std::uint8_t inst, const std::vector<std::uint8_t>& params) {
    std::array<std::uint8_t, dxl::kMaxPacket> out{};
    std::size_t n = 0;
    ASSERT_EQ(dxl::build_instruction(id, inst, params, out, n), dxl::DxlStatus::kOk);
    put(out.data(), n);
  }
  void put(const std::uint8_t* p, std::size_t n) {
    ASSERT_EQ(::write(host, p, n), static_cast<ssize_t>(n));
  }
  // The next status packet, or none within `timeout_ns`.
  std::optional<dxl::Packet> recv(std::int64_t timeout_ns = 100 * kMs) {
    const std::int64_t give_up = pedalwave::test::now_ns() + timeout_ns;
    for (;;) {
      dxl::Packet p{};
      std::size_t used = 0;
      while (len > 0) {
        const dxl::DxlStatus s = dxl::parse_packet(std::span<const std::uint8_t>(rx.data(), len), p, used);
        if (s == dxl::DxlStatus::kNeedMore) break;
        std::memmove(rx.data(), rx.data() + used, len - used);
        len -= used;
        if (s == dxl::DxlStatus::kOk) return p;
      }
      const std::int64_t left = give_up - pedalwave::test::now_ns();
      if (left <= 0) return std::nullopt;
      pollfd pf{host, POLLIN, 0};
      ::poll(&pf, 1, static_cast<int>(left / kMs) + 1);
      const ssize_t r = ::read(host, rx.data() + len, rx.size() - len);
      if (r > 0) len += static_cast<std::size_t>(r);
    }
  }
  std::vector<std::uint8_t> addr_len(std::uint16_t a, std::uint16_t l) {
    return {static_cast<std::uint8_t>(a), static_cast<std::uint8_t>(a >> 8),
            static_cast<std::uint8_t>(l), static_cast<std::uint8_t>(l >> 8)};
  }
  std::optional<dxl::Packet> read(std::uint8_t id, std::uint16_t a, std::uint16_t l) {
    send(id, dxl::kInstRead, addr_len(a, l));
    return recv();
  }
  std::optional<dxl::Packet> write(std::uint8_t id, std::uint16_t a, std::vector<std::uint8_t> d) {
    std::vector<std::uint8_t> p = {static_cast<std::uint8_t>(a), static_cast<std::uint8_t>(a >> 8)};
    p.insert(p.end(), d.begin(), d.end());
    send(id, dxl::kInstWrite, p);
    return recv(id == dxl::kBroadcastId ? 20 * kMs : 100 * kMs);
  }
  std::array<std::uint8_t, 4096> rx{};
  std::size_t len = 0;
};

std::uint32_t value(const dxl::Packet& p) {
  std::uint32_t v = 0;
  for (std::size_t k = 0; k < p.param_count && k < 4; ++k) v |= std::uint32_t{p.params[k]} << (8 * k);
  return v;
}

}  // namespace

// Every register PROTOCOL.md lists as readable answers with its value (old emulator: error 2 on
// every Read); a write-only register, a range past the table and length 0 are refused.
TEST(DxlModule, ReadsEveryDocumentedRegister) {
  Bus bus(3);
  for (const dxl::Register& r : dxl::kRegisters) {
    if (r.size == 0) continue;
    const auto p = bus.read(2, r.address, r.size);
    ASSERT_TRUE(p) << r.name;
    EXPECT_EQ(p->id, 2);
    if (r.access == dxl::Access::kW) {
      EXPECT_EQ(p->error, dxl::kErrAccess) << r.name;
      EXPECT_EQ(p->param_count, 0u);
    } else {
      EXPECT_EQ(p->error, 0) << r.name;
      EXPECT_EQ(p->param_count, r.size) << r.name;
    }
  }
  EXPECT_EQ(value(*bus.read(2, dxl::kRegModelNumber, 2)), dxl::kModelNumber);
  EXPECT_EQ(value(*bus.read(2, dxl::kRegFirmware, 1)), dxl::kFirmwareVersion);
  EXPECT_EQ(value(*bus.read(2, dxl::kRegId, 1)), 2u);
  EXPECT_EQ(value(*bus.read(2, dxl::kRegBaud, 1)), 6u);          // 4 Mbaud
  EXPECT_EQ(value(*bus.read(2, dxl::kRegReturnDelay, 1)), 10u);  // 20 µs
  EXPECT_EQ(value(*bus.read(2, dxl::kRegCommandTimeout, 2)), 50u);
  EXPECT_EQ(value(*bus.read(2, dxl::kRegTorqueEnable, 1)), 0u);
  EXPECT_EQ(value(*bus.read(2, dxl::kRegStatusReturnLevel, 1)), 2u);
  EXPECT_EQ(value(*bus.read(2, dxl::kRegHardwareError, 1)), 0u);
  // The EEPROM block in one read: gaps read as 0.
  const auto e = bus.read(3, 0, 12);
  ASSERT_TRUE(e);
  ASSERT_EQ(e->param_count, 12u);
  EXPECT_EQ(e->params[3], 0);
  EXPECT_EQ(e->params[7], 3);
  EXPECT_EQ(bus.read(2, 134, 2)->error, dxl::kErrAccess);   // past the table
  EXPECT_EQ(bus.read(2, 90, 10)->error, dxl::kErrAccess);   // covers the write-only 96
  EXPECT_EQ(bus.read(2, 0, 0)->error, dxl::kErrDataLength);
  EXPECT_FALSE(bus.read(9, 0, 2));  // no such module: silence
  bus.send(dxl::kBroadcastId, dxl::kInstRead, bus.addr_len(0, 2));
  EXPECT_FALSE(bus.recv(20 * kMs));  // a broadcast Read is never answered
}

TEST(DxlModule, WritesFollowAccessRangeAndEepromRules) {
  Bus bus(2);
  EXPECT_EQ(bus.write(1, dxl::kRegReturnDelay, {5})->error, 0);
  EXPECT_EQ(value(*bus.read(1, dxl::kRegReturnDelay, 1)), 5u);
  EXPECT_EQ(bus.write(1, dxl::kRegCommandTimeout, {0x2C, 0x01})->error, 0);  // 300 ms
  EXPECT_EQ(value(*bus.read(1, dxl::kRegCommandTimeout, 2)), 300u);
  EXPECT_EQ(bus.emu->bank().command_timeout_ns(0), 300 * kMs);
  EXPECT_EQ(bus.write(1, dxl::kRegModelNumber, {1, 2})->error, dxl::kErrAccess);  // read-only
  EXPECT_EQ(bus.write(1, 3, {1})->error, dxl::kErrAccess);                        // a gap
  EXPECT_EQ(bus.write(1, dxl::kRegId, {0})->error, dxl::kErrDataRange);
  EXPECT_EQ(bus.write(1, dxl::kRegBaud, {7})->error, dxl::kErrDataRange);
  EXPECT_EQ(bus.write(1, dxl::kRegCommandTimeout, {1})->error, dxl::kErrDataLength);  // half
  EXPECT_EQ(bus.write(1, dxl::kRegStatusReturnLevel, {3})->error, dxl::kErrDataRange);
  // A refused write changes nothing, also not its valid part.
  EXPECT_EQ(bus.write(1, dxl::kRegReturnDelay, {7, 1})->error, dxl::kErrDataLength);
  EXPECT_EQ(value(*bus.read(1, dxl::kRegReturnDelay, 1)), 5u);
  // Torque enable = 0 on a module that is off is no command (the host's configuration writes it).
  EXPECT_EQ(bus.write(1, dxl::kRegTorqueEnable, {0})->error, 0);
  EXPECT_EQ(bus.emu->stats().commands.load(), 0u);
  EXPECT_EQ(bus.emu->stats().replies_sent.load(), 0u);  // none of these answered a cycle's read
  EXPECT_GT(bus.emu->stats().other_replies.load(), 10u);
  // Torque on: the EEPROM area is locked (Access Error); off again: writable.
  EXPECT_EQ(bus.write(1, dxl::kRegTorqueEnable, {1})->error, 0);
  EXPECT_EQ(value(*bus.read(1, dxl::kRegTorqueEnable, 1)), 1u);
  EXPECT_FALSE(bus.emu->bank().torque_off(0));
  EXPECT_EQ(bus.write(1, dxl::kRegReturnDelay, {9})->error, dxl::kErrAccess);
  EXPECT_EQ(bus.write(1, dxl::kRegCommand, std::vector<std::uint8_t>(12, 0))->error, 0);  // RAM
  EXPECT_EQ(bus.write(1, dxl::kRegTorqueEnable, {0})->error, 0);
  EXPECT_TRUE(bus.emu->bank().torque_off(0));
  EXPECT_EQ(bus.write(1, dxl::kRegReturnDelay, {9})->error, 0);
  // A new ID: the module answers to it, not to the old one.
  EXPECT_EQ(bus.write(2, dxl::kRegId, {7})->error, 0);
  EXPECT_FALSE(bus.read(2, dxl::kRegId, 1));
  EXPECT_EQ(value(*bus.read(7, dxl::kRegId, 1)), 7u);
  // Broadcast write: every module, no status packet.
  EXPECT_FALSE(bus.write(dxl::kBroadcastId, dxl::kRegReturnDelay, {3}));
  EXPECT_EQ(value(*bus.read(1, dxl::kRegReturnDelay, 1)), 3u);
  EXPECT_EQ(value(*bus.read(7, dxl::kRegReturnDelay, 1)), 3u);
}

// Sync Read / Write of ranges other than the cycle's (old: dropped silently), Bulk Read / Write
// (old: error 2).
TEST(DxlModule, SyncAndBulkOfAnyRange) {
  Bus bus(3);
  std::vector<std::uint8_t> sr = bus.addr_len(0, 3);
  sr.insert(sr.end(), {1, 2, 3});
  bus.send(dxl::kBroadcastId, dxl::kInstSyncRead, sr);
  for (std::uint8_t id = 1; id <= 3; ++id) {
    const auto p = bus.recv();
    ASSERT_TRUE(p) << int{id};
    EXPECT_EQ(p->id, id);
    ASSERT_EQ(p->param_count, 3u);
    EXPECT_EQ(pd::wire::get_u16(p->params.data()), dxl::kModelNumber);
  }
  // Sync Write of the return delay, one value per module.
  std::vector<std::uint8_t> sw = bus.addr_len(dxl::kRegReturnDelay, 1);
  sw.insert(sw.end(), {1, 11, 2, 12, 3, 13});
  bus.send(dxl::kBroadcastId, dxl::kInstSyncWrite, sw);
  for (std::uint8_t id = 1; id <= 3; ++id)
    EXPECT_EQ(value(*bus.read(id, dxl::kRegReturnDelay, 1)), 10u + id);
  // Bulk Write: module 1 its torque enable, module 3 its command timeout.
  bus.send(dxl::kBroadcastId, dxl::kInstBulkWrite,
           {1, dxl::kRegTorqueEnable, 0, 1, 0, 1, 3, dxl::kRegCommandTimeout, 0, 2, 0, 0x64, 0});
  EXPECT_FALSE(bus.recv(20 * kMs));
  EXPECT_EQ(value(*bus.read(1, dxl::kRegTorqueEnable, 1)), 1u);
  EXPECT_EQ(value(*bus.read(3, dxl::kRegCommandTimeout, 2)), 100u);
  // Bulk Read of three different ranges, answered in list order.
  bus.send(dxl::kBroadcastId, dxl::kInstBulkRead,
           {3, 0, 0, 2, 0, 1, dxl::kRegTorqueEnable, 0, 1, 0, 2, dxl::kRegFeedback, 0, 15, 0});
  const auto a = bus.recv(), b = bus.recv(), c = bus.recv();
  ASSERT_TRUE(a && b && c);
  EXPECT_EQ(a->id, 3);
  EXPECT_EQ(value(*a), dxl::kModelNumber);
  EXPECT_EQ(b->id, 1);
  EXPECT_EQ(value(*b), 1u);
  EXPECT_EQ(c->id, 2);
  EXPECT_EQ(c->param_count, dxl::kFeedbackBlockSize);
  // A Sync Read one module cannot serve: it says why, the others answer.
  std::vector<std::uint8_t> bad = bus.addr_len(dxl::kRegSyncCounter, 1);
  bad.insert(bad.end(), {1, 2});
  bus.send(dxl::kBroadcastId, dxl::kInstSyncRead, bad);
  EXPECT_EQ(bus.recv()->error, dxl::kErrAccess);
  EXPECT_EQ(bus.recv()->error, dxl::kErrAccess);
}

TEST(DxlModule, StatusReturnLevel) {
  Bus bus(1);
  EXPECT_FALSE(bus.write(1, dxl::kRegStatusReturnLevel, {1}));  // the new level applies at once
  EXPECT_FALSE(bus.write(1, dxl::kRegReturnDelay, {4}));                // level 1: no Write answer
  EXPECT_EQ(value(*bus.read(1, dxl::kRegReturnDelay, 1)), 4u);          // but the Read's
  EXPECT_FALSE(bus.write(1, dxl::kRegStatusReturnLevel, {0}));
  EXPECT_FALSE(bus.read(1, dxl::kRegReturnDelay, 1));  // level 0: Ping only
  bus.send(1, dxl::kInstPing, {});
  const auto p = bus.recv();
  ASSERT_TRUE(p);
  EXPECT_EQ(pd::wire::get_u16(p->params.data()), dxl::kModelNumber);
  // Reboot restores the RAM area (level 2 again), torque off.
  bus.send(1, dxl::kInstReboot, {});
  EXPECT_FALSE(bus.recv(20 * kMs));  // (sent at level 0)
  EXPECT_EQ(value(*bus.read(1, dxl::kRegStatusReturnLevel, 1)), 2u);
  EXPECT_EQ(value(*bus.read(1, dxl::kRegReturnDelay, 1)), 4u);  // EEPROM kept
}

TEST(DxlModule, HardwareErrorStatusBehindTheAlertBit) {
  Bus bus(2, /*hot=*/1);
  // The SYNC samples the plant (module 2 over-temperature).
  EXPECT_FALSE(bus.write(dxl::kBroadcastId, dxl::kRegSyncCounter, {1}));
  const auto hot = bus.read(2, dxl::kRegHardwareError, 1);
  ASSERT_TRUE(hot);
  EXPECT_EQ(value(*hot), dxl::kHwErrOverheating);
  EXPECT_EQ(hot->error, dxl::kErrAlert);
  EXPECT_EQ(bus.read(2, dxl::kRegModelNumber, 2)->error, dxl::kErrAlert);  // every status packet
  EXPECT_EQ(bus.write(2, dxl::kRegId, {0})->error, dxl::kErrAlert | dxl::kErrDataRange);
  const auto cool = bus.read(1, dxl::kRegHardwareError, 1);
  EXPECT_EQ(value(*cool), 0u);
  EXPECT_EQ(cool->error, 0);
}

TEST(DxlModule, UnsupportedInstructionsSayInstructionError) {
  Bus bus(2);
  for (std::uint8_t inst : {dxl::kInstFactoryReset, dxl::kInstRegWrite, dxl::kInstAction,
                            dxl::kInstClear, dxl::kInstBackup, std::uint8_t{0x7E}}) {
    bus.send(2, inst, {0xFF});
    const auto p = bus.recv();
    ASSERT_TRUE(p) << int{inst};
    EXPECT_EQ(p->id, 2);
    EXPECT_EQ(p->error, dxl::kErrInstruction) << int{inst};
  }
  std::vector<std::uint8_t> fsr = bus.addr_len(0, 2);
  fsr.insert(fsr.end(), {2, 1});
  bus.send(dxl::kBroadcastId, dxl::kInstFastSyncRead, fsr);
  const auto f = bus.recv();
  ASSERT_TRUE(f);
  EXPECT_EQ(f->id, 2);  // the first listed
  EXPECT_EQ(f->error, dxl::kErrInstruction);
  EXPECT_FALSE(bus.recv(20 * kMs));
}

// A packet whose LEN is too long does not swallow the next one (old: it did, until LEN was
// filled): a later packet is answered after the inter-byte timeout, one in the same write at
// once after it.
TEST(DxlModule, InterByteTimeoutKeepsATooLongPacketFromSwallowingTheNext) {
  Bus bus(1);
  std::array<std::uint8_t, 64> bad{};
  std::size_t n = 0;
  ASSERT_EQ(dxl::build_read(1, 0, 2, bad, n), dxl::DxlStatus::kOk);
  bad[5] = static_cast<std::uint8_t>(bad[5] + 40);  // LEN 40 bytes too long
  bus.put(bad.data(), n);
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const auto p = bus.read(1, dxl::kRegModelNumber, 2);
  ASSERT_TRUE(p);
  EXPECT_EQ(value(*p), dxl::kModelNumber);
  // The broken packet and a good one in one write.
  std::array<std::uint8_t, 128> both{};
  std::memcpy(both.data(), bad.data(), n);
  std::size_t m = 0;
  ASSERT_EQ(dxl::build_read(1, dxl::kRegId, 1, std::span<std::uint8_t>(both.data() + n, 64), m),
            dxl::DxlStatus::kOk);
  bus.put(both.data(), n + m);
  const auto q = bus.recv();
  ASSERT_TRUE(q);
  EXPECT_EQ(value(*q), 1u);
  EXPECT_GE(bus.emu->stats().rx_errors.load(), 2u);
}

// The cycle (sync counter, Sync Read 120/15, Sync Write 100/12) bytes as before: a command block
// sent by Sync Write reads back by Read, byte for byte.
TEST(DxlModule, CommandBlockWrittenBySyncWriteReadsBack) {
  Bus bus(2);
  std::uint8_t blocks[2][dxl::kCommandBlockSize];
  dxl::encode_command_block({0.5, -0.25, 1.0, 30.0, 15.0, false, 7}, blocks[0]);
  dxl::encode_command_block({-0.5, 0.25, -1.0, 3.0, 1.5, true, 7}, blocks[1]);
  const std::uint8_t ids[2] = {1, 2};
  std::array<std::uint8_t, 128> out{};
  std::size_t n = 0;
  ASSERT_EQ(dxl::build_sync_write(dxl::kRegCommand, dxl::kCommandBlockSize, ids,
                                  std::span<const std::uint8_t>(&blocks[0][0], 24), out, n),
            dxl::DxlStatus::kOk);
  bus.put(out.data(), n);
  for (int j = 0; j < 2; ++j) {
    const auto p = bus.read(static_cast<std::uint8_t>(j + 1), dxl::kRegCommand, dxl::kCommandBlockSize);
    ASSERT_TRUE(p);
    ASSERT_EQ(p->param_count, dxl::kCommandBlockSize);
    EXPECT_EQ(std::memcmp(p->params.data(), blocks[j], dxl::kCommandBlockSize), 0) << j;
  }
  EXPECT_FALSE(bus.emu->bank().torque_off(0));
  EXPECT_TRUE(bus.emu->bank().torque_off(1));
  EXPECT_EQ(bus.emu->stats().commands.load(), 2u);
}

// ---- The host's configuration (SerialDriver::configure_modules) ----------------------------------
namespace {
pd::SerialConfig host_config(int joints) {
  pd::SerialConfig cfg;
  cfg.joints = joints;
  cfg.baud = 4'000'000;
  cfg.period_s = 2e-3;
  cfg.return_delay_s = 30e-6;
  cfg.command_timeout_s = 0.2;
  return cfg;
}
std::string configure_error(Bus& bus, int joints) {
  pd::SerialDriver drv(pd::open_serial_port(bus.slave, 4'000'000), host_config(joints));
  try {
    drv.configure_modules(20 * kMs);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(SerialConfigure, IdentifiesEveryModuleAndSetsDelayAndTimeout) {
  Bus bus(3);
  EXPECT_EQ(bus.write(2, dxl::kRegTorqueEnable, {1})->error, 0);  // left on: turned off first
  pd::SerialDriver drv(pd::open_serial_port(bus.slave, 4'000'000), host_config(3));
  drv.configure_modules();
  for (int j = 0; j < 3; ++j) {
    EXPECT_EQ(drv.identity(j).model, dxl::kModelNumber);
    EXPECT_EQ(drv.identity(j).firmware, dxl::kFirmwareVersion);
    EXPECT_EQ(bus.emu->bank().command_timeout_ns(j), 200 * kMs);
    EXPECT_TRUE(bus.emu->bank().torque_off(j));
  }
  EXPECT_EQ(value(*bus.read(3, dxl::kRegReturnDelay, 1)), 15u);  // 30 µs
  // The cycle runs after it, every module fresh.
  const pedalwave::test::CycleLog log = pedalwave::test::run_cycles(drv, 50, 2 * kMs, 20 * kMs);
  int ok = 0;
  for (pd::IoStatus s : log.io) ok += s == pd::IoStatus::kOk;
  EXPECT_GE(ok, 45);
  EXPECT_EQ(drv.counters().malformed + drv.counters().checksum, 0u);
}

TEST(SerialConfigure, RefusesTheModuleThatDisagreesNamingRegisterAndValues) {
  {
    Bus bus(3);
    EXPECT_EQ(bus.write(2, dxl::kRegBaud, {3})->error, 0);  // 1 Mbaud (a pty keeps its rate)
    const std::string e = configure_error(bus, 3);
    EXPECT_NE(e.find("module ID 2 (joint 2)"), std::string::npos) << e;
    EXPECT_NE(e.find("register 8 (baud rate) = 3 (1000000 baud), expected 6 (4000000 baud"),
              std::string::npos) << e;
  }
  {
    Bus bus(2);
    const std::string e = configure_error(bus, 3);  // joint 3 has no module
    EXPECT_NE(e.find("module ID 3 (joint 3): no answer to a Read of register 0 (model number)"),
              std::string::npos) << e;
  }
  {
    Bus bus(3, /*hot=*/0);
    EXPECT_FALSE(bus.write(dxl::kBroadcastId, dxl::kRegSyncCounter, {1}));  // sample: it is hot
    const std::string e = configure_error(bus, 3);
    EXPECT_NE(e.find("module ID 1 (joint 1): register 70 (hardware error status) = 4 (overheating), "
                     "expected 0"), std::string::npos) << e;
  }
  {
    Bus bus(2);
    EXPECT_EQ(bus.write(1, dxl::kRegId, {2})->error, 0);  // two modules answer to ID 2 now
    const std::string e = configure_error(bus, 2);
    EXPECT_NE(e.find("module ID 1 (joint 1): no answer"), std::string::npos) << e;
  }
}

// The X-series bus (PROTOCOL.md §3.6): a stock servo per joint and its deflection sensor.
TEST(DxlXSeriesBus, ServoInCurrentModeAndSensorAnswer) {
  int master = ::posix_openpt(O_RDWR | O_NOCTTY);
  ASSERT_TRUE(master >= 0 && ::grantpt(master) == 0 && ::unlockpt(master) == 0);
  Bus host(1);  // (only its helpers; the X bus below gets its own pty)
  ::close(host.host);
  host.host = pd::open_serial_port(::ptsname(master), 4'000'000);
  pedalwave::test::FirstOrderPlant plant;
  pd::EmulatorConfig ec;
  ec.joints = 2;
  ec.serial_devices = pd::SerialDevices::kXSeries;
  pd::SerialModuleEmulator emu(master, ec, plant);
  std::atomic<bool> stop{false};
  std::thread th([&] { emu.run(stop); });
  EXPECT_EQ(value(*host.read(1, dxl::x::kRegModelNumber, 2)), dxl::x::kModelXM430W350);
  EXPECT_EQ(value(*host.read(101, dxl::x::kRegModelNumber, 2)), dxl::x::kSensorModelNumber);
  EXPECT_EQ(value(*host.read(1, dxl::x::kRegOperatingMode, 1)), 3u);  // as shipped
  EXPECT_EQ(host.write(1, dxl::x::kRegOperatingMode, {0})->error, 0);
  EXPECT_EQ(host.write(1, dxl::x::kRegTorqueEnable, {1})->error, 0);
  EXPECT_EQ(host.write(1, dxl::x::kRegOperatingMode, {3})->error, dxl::kErrAccess);  // EEPROM, on
  EXPECT_EQ(host.write(1, dxl::x::kRegGoalCurrent, {100, 0})->error, 0);
  EXPECT_NEAR(plant.last_command().tau[0], 100 * 2.69e-3 * 1.78, 1e-9);
  EXPECT_FALSE(emu.bank().torque_off(0));
  host.send(dxl::kBroadcastId, dxl::kInstBulkRead,
            {1, dxl::x::kFeedbackAddress, 0, dxl::x::kFeedbackSize, 0, 101, 124, 0, 2, 0});
  const auto a = host.recv(), b = host.recv();
  ASSERT_TRUE(a && b);
  EXPECT_EQ(a->id, 1);
  ASSERT_EQ(a->param_count, dxl::x::kFeedbackSize);
  EXPECT_EQ(pd::wire::get_i16(a->params.data() + (dxl::x::kRegPresentCurrent - dxl::x::kFeedbackAddress)),
            100);  // present current = goal
  EXPECT_EQ(b->id, 101);
  EXPECT_EQ(b->param_count, 2u);
  // The Realtime Tick (120: 1 ms, mod 32768) runs with the clock from power-on, in a Read and in
  // the Bulk Read's answer (its sample's): a Read after it, and one 20 ms later.
  const std::uint32_t bulk_tick = pd::wire::get_u16(a->params.data());
  const std::uint32_t t1 = value(*host.read(1, dxl::x::kRegRealtimeTick, 2));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const std::uint32_t t2 = value(*host.read(1, dxl::x::kRegRealtimeTick, 2));
  EXPECT_LT((t1 + 32768 - bulk_tick) % 32768, 100u) << bulk_tick << " then " << t1;
  EXPECT_GE((t2 + 32768 - t1) % 32768, 20u) << t1 << " then " << t2;
  EXPECT_LT((t2 + 32768 - t1) % 32768, 200u) << t1 << " then " << t2;
  stop = true;
  th.join();
  ::close(master);
}
