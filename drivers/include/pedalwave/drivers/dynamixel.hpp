// DYNAMIXEL Protocol 2.0 packet codec and the register map of the pedalwave modules on a serial
// servo bus (drivers/PROTOCOL.md §3). Pure functions on caller-provided buffers: allocation-free,
// noexcept, no I/O.
//
// Packet: FF FF FD 00 | ID | LEN_L LEN_H | INST | [ERR] | PARAM… | CRC_L CRC_H
//   LEN = bytes after the length field (instruction, error, parameters after stuffing, CRC);
//   byte stuffing over INST…PARAM: every "FF FF FD" gets an extra FD ("FF FF FD FD");
//   CRC-16 (poly 0x8005, init 0, crc16_dxl) over everything from the header up to the CRC, as sent
//   (stuffed).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pedalwave::drivers::dxl {

// ---- Protocol constants -------------------------------------------------------------------------
inline constexpr std::uint8_t kBroadcastId = 0xFE;
inline constexpr std::uint8_t kInstPing = 0x01;
inline constexpr std::uint8_t kInstRead = 0x02;
inline constexpr std::uint8_t kInstWrite = 0x03;
inline constexpr std::uint8_t kInstRegWrite = 0x04;
inline constexpr std::uint8_t kInstAction = 0x05;
inline constexpr std::uint8_t kInstFactoryReset = 0x06;
inline constexpr std::uint8_t kInstReboot = 0x08;
inline constexpr std::uint8_t kInstClear = 0x10;
inline constexpr std::uint8_t kInstBackup = 0x20;
inline constexpr std::uint8_t kInstStatus = 0x55;
inline constexpr std::uint8_t kInstSyncRead = 0x82;
inline constexpr std::uint8_t kInstSyncWrite = 0x83;
inline constexpr std::uint8_t kInstFastSyncRead = 0x8A;
inline constexpr std::uint8_t kInstBulkRead = 0x92;
inline constexpr std::uint8_t kInstBulkWrite = 0x93;
inline constexpr std::uint8_t kInstFastBulkRead = 0x9A;
// Error field of a status packet: bit 7 alert, bits 0…6 error number.
inline constexpr std::uint8_t kErrAlert = 0x80;
inline constexpr std::uint8_t kErrResultFail = 0x01;
inline constexpr std::uint8_t kErrInstruction = 0x02;
inline constexpr std::uint8_t kErrCrc = 0x03;
inline constexpr std::uint8_t kErrDataRange = 0x04;
inline constexpr std::uint8_t kErrDataLength = 0x05;
inline constexpr std::uint8_t kErrDataLimit = 0x06;
inline constexpr std::uint8_t kErrAccess = 0x07;

inline constexpr std::size_t kHeaderSize = 7;   // FF FF FD 00 ID LEN_L LEN_H
inline constexpr std::size_t kMaxPacket = 1024; // largest packet we build or accept [bytes]
inline constexpr std::size_t kMaxParams = kMaxPacket - kHeaderSize - 3;

// ---- Register map of a pedalwave SEA module (little-endian; PROTOCOL.md §3.2) -------------------
inline constexpr std::uint16_t kRegModelNumber = 0;       // u16 R   0x5057 ("PW")
inline constexpr std::uint16_t kRegFirmware = 2;          // u8  R
inline constexpr std::uint16_t kRegId = 7;                // u8  RW  1…252
inline constexpr std::uint16_t kRegBaud = 8;              // u8  RW  index (PROTOCOL.md)
inline constexpr std::uint16_t kRegReturnDelay = 9;       // u8  RW  [2 µs]
inline constexpr std::uint16_t kRegCommandTimeout = 10;   // u16 RW  [ms], 0 = never
inline constexpr std::uint16_t kRegTorqueEnable = 64;     // u8  RW  0/1
inline constexpr std::uint16_t kRegStatusReturnLevel = 68;  // u8 RW  0 ping, 1 + reads, 2 all
inline constexpr std::uint16_t kRegHardwareError = 70;    // u8  R   bit 2 overheating, 3 encoder
inline constexpr std::uint16_t kRegSyncCounter = 96;      // u8  W   cycle counter c (broadcast)
inline constexpr std::uint16_t kRegCommand = 100;         // command block, kCommandBlockSize bytes
inline constexpr std::uint16_t kRegFeedback = 120;        // feedback block, kFeedbackBlockSize
inline constexpr std::uint16_t kModelNumber = 0x5057;
inline constexpr std::uint8_t kFirmwareVersion = 1;
// Hardware Error Status bits (the X-series' bit numbers): the module's over-temperature and encoder
// fault. Non-zero: the alert bit (kErrAlert) in every status packet of the module.
inline constexpr std::uint8_t kHwErrOverheating = 0x04;
inline constexpr std::uint8_t kHwErrEncoder = 0x08;
// Command block offsets: τ i16 [1e-3 N·m], β_ref i16 [1e-4 rad], β̇_ref i16 [1e-3 rad/s],
// kp u16 [1e-2 N·m/rad], kd u16 [1e-3 N·m·s/rad], flags u8 (bit 0 torque off), counter u8 (c).
inline constexpr std::size_t kCommandBlockSize = 12;
// Feedback block offsets: β i16 [1e-4 rad], β̇ i16 [1e-3 rad/s], deflection i16 [2e-5 rad],
// status u8 (bit 0 saturated, 1 over-temp, 2 encoder fault, 3 torque off), echo u8 (last c),
// then the timing record (wire::ModuleTiming): sample time u32 [µs, module clock], application
// age u16 [µs] (bit 15: no command), applied command counter u8 (its c).
inline constexpr std::size_t kFeedbackBlockSize = 15;

// ---- The control table (PROTOCOL.md §3.2): one source for the emulator, the host and the docs --
enum class Access : std::uint8_t { kR = 1, kW = 2, kRW = 3 };
struct Register {
  std::uint16_t address = 0;  // first byte [-]
  std::uint8_t size = 0;      // bytes [-]
  Access access = Access::kR;
  bool eeprom = false;        // written only while torque enable = 0 (else kErrAccess)
  std::uint32_t min = 0, max = 0;  // accepted raw values of a write (else kErrDataRange) [-]
  const char* name = "";
};
inline constexpr std::uint16_t kTableSize = 135;  // addresses 0 … 134 [bytes]
inline constexpr std::array<Register, 33> kRegisters = {{
    {0, 2, Access::kR, true, 0, 0xFFFF, "model number"},
    {2, 1, Access::kR, true, 0, 0xFF, "firmware version"},
    {7, 1, Access::kRW, true, 1, 252, "ID"},
    {8, 1, Access::kRW, true, 0, 6, "baud rate"},
    {9, 1, Access::kRW, true, 0, 254, "return delay time"},
    {10, 2, Access::kRW, true, 0, 0xFFFF, "command timeout"},
    {64, 1, Access::kRW, false, 0, 1, "torque enable"},
    {68, 1, Access::kRW, false, 0, 2, "status return level"},
    {70, 1, Access::kR, false, 0, 0xFF, "hardware error status"},
    {96, 1, Access::kW, false, 0, 0xFF, "sync counter"},
    {100, 2, Access::kRW, false, 0, 0xFFFF, "tau"},
    {102, 2, Access::kRW, false, 0, 0xFFFF, "beta_ref"},
    {104, 2, Access::kRW, false, 0, 0xFFFF, "beta_dot_ref"},
    {106, 2, Access::kRW, false, 0, 0xFFFF, "kp"},
    {108, 2, Access::kRW, false, 0, 0xFFFF, "kd"},
    {110, 1, Access::kRW, false, 0, 1, "command flags"},
    {111, 1, Access::kRW, false, 0, 0xFF, "command counter"},
    {120, 2, Access::kR, false, 0, 0xFFFF, "beta"},
    {122, 2, Access::kR, false, 0, 0xFFFF, "beta_dot"},
    {124, 2, Access::kR, false, 0, 0xFFFF, "deflection"},
    {126, 1, Access::kR, false, 0, 0xFF, "status"},
    {127, 1, Access::kR, false, 0, 0xFF, "echo"},
    {128, 4, Access::kR, false, 0, 0xFFFFFFFF, "sample time"},
    {132, 2, Access::kR, false, 0, 0xFFFF, "application age"},
    {134, 1, Access::kR, false, 0, 0xFF, "applied counter"},
    // (the rows below keep the array's size fixed; a zero-size row is no register)
    {}, {}, {}, {}, {}, {}, {}, {},
}};
// The register containing `address`, or nullptr (a gap: reads as 0, never written).
const Register* register_at(std::uint16_t address) noexcept;
// Baud-rate register index ↔ bit/s (1 = 57600 … 6 = 4 M, as the X-series); -1 / 0 when none.
int baud_index(int baud) noexcept;
int baud_of_index(int index) noexcept;
// For messages: a status packet's error number (its low 7 bits) by name ("CRC Error", …), and a
// baud-rate index as its rate ("4000000 baud" or "no rate of the index").
const char* error_name(std::uint8_t error) noexcept;
std::string baud_text(int index);
// What a control-table access of `length` bytes at `address` may do, by the table alone (no
// module state): 0 = allowed; kErrAccess (outside the table; a write touching a gap or a
// read-only register; a read touching a write-only register), kErrDataLength (length 0; a write
// entering or leaving a register in its middle), kErrDataRange (a written value outside the
// register's range). `eeprom` is set when a write touches the EEPROM area.
std::uint8_t check_read(std::uint16_t address, std::uint16_t length) noexcept;
std::uint8_t check_write(std::uint16_t address, std::span<const std::uint8_t> data,
                         bool& eeprom) noexcept;
// The same for another device's table (`regs`, `size` bytes): the X-series servo, the sensor.
const Register* register_at(std::span<const Register> regs, std::uint16_t address) noexcept;
std::uint8_t check_read(std::span<const Register> regs, std::uint16_t size, std::uint16_t address,
                        std::uint16_t length) noexcept;
std::uint8_t check_write(std::span<const Register> regs, std::uint16_t size, std::uint16_t address,
                         std::span<const std::uint8_t> data, bool& eeprom) noexcept;

// ---- Results --------------------------------------------------------------------------------------
enum class DxlStatus : std::uint8_t {
  kOk = 0,
  kNeedMore,      // (parser) the buffer holds the start of a packet, wait for more bytes
  kGarbage,       // (parser) bytes before the next header: `consumed` of them can be dropped
  kMalformed,     // (parser) header found but length impossible / bad stuffing / wrong layout
  kChecksum,      // (parser) CRC mismatch
  kOverflow,      // (builder/unstuff) output buffer too small
  kBadArgument,   // (builder) invalid id/length
};

// A parsed packet. `params` holds the unstuffed parameters (after the error byte for status).
struct Packet {
  std::uint8_t id = 0;                          // packet ID [-]
  std::uint8_t instruction = 0;                 // instruction (0x55 for a status packet) [-]
  std::uint8_t error = 0;                       // error field (status packets only) [-]
  std::size_t param_count = 0;                  // number of valid bytes in params [-]
  std::array<std::uint8_t, kMaxParams> params{};
};

// Byte stuffing of `in` into `out` ("FF FF FD" → "FF FF FD FD").
DxlStatus stuff(std::span<const std::uint8_t> in, std::span<std::uint8_t> out,
                std::size_t& out_len) noexcept;
// Inverse: removes the FD that follows every "FF FF FD". A "FF FF FD" followed by anything but FD
// (or by the end of the data) is malformed.
DxlStatus unstuff(std::span<const std::uint8_t> in, std::span<std::uint8_t> out,
                  std::size_t& out_len) noexcept;

// Instruction packet: header, id, instruction, `params` (stuffed here), CRC.
DxlStatus build_instruction(std::uint8_t id, std::uint8_t instruction,
                            std::span<const std::uint8_t> params, std::span<std::uint8_t> out,
                            std::size_t& out_len) noexcept;
// Status packet (what a module sends): instruction 0x55, error, params.
DxlStatus build_status(std::uint8_t id, std::uint8_t error, std::span<const std::uint8_t> params,
                       std::span<std::uint8_t> out, std::size_t& out_len) noexcept;
// Sync Read (0x82, broadcast) of `length` bytes at `address` from `ids`.
DxlStatus build_sync_read(std::uint16_t address, std::uint16_t length,
                          std::span<const std::uint8_t> ids, std::span<std::uint8_t> out,
                          std::size_t& out_len) noexcept;
// Sync Write (0x83, broadcast): `data` holds ids.size() blocks of `length` bytes, in id order.
DxlStatus build_sync_write(std::uint16_t address, std::uint16_t length,
                           std::span<const std::uint8_t> ids, std::span<const std::uint8_t> data,
                           std::span<std::uint8_t> out, std::size_t& out_len) noexcept;

// Read (0x02) of `length` bytes at `address`; Write (0x03) of `data` at `address`.
DxlStatus build_read(std::uint8_t id, std::uint16_t address, std::uint16_t length,
                     std::span<std::uint8_t> out, std::size_t& out_len) noexcept;
DxlStatus build_write(std::uint8_t id, std::uint16_t address, std::span<const std::uint8_t> data,
                      std::span<std::uint8_t> out, std::size_t& out_len) noexcept;

// Parse the packet at the start of `in`. kOk/kChecksum/kMalformed/kGarbage set `consumed` to the
// bytes to drop; kNeedMore sets it to 0. On kChecksum `pkt.id` holds the (unverified) id byte.
DxlStatus parse_packet(std::span<const std::uint8_t> in, Packet& pkt,
                       std::size_t& consumed) noexcept;

// Register blocks ↔ plain values (same scalings as CAN, wire.hpp).
struct CommandBlock {
  double tau = 0.0;           // feed-forward torque [N·m]
  double beta_ref = 0.0;      // motor angle set-point [rad]
  double beta_dot_ref = 0.0;  // motor rate set-point [rad/s]
  double kp = 0.0;            // stiffness gain [N·m/rad]
  double kd = 0.0;            // damping gain [N·m·s/rad]
  bool torque_off = false;    // safe torque off
  std::uint8_t counter = 0;   // cycle counter c the command was computed in [-]
};
// The feedback block: the module's measurement, the sync counter it latched and its timing record.
struct FeedbackBlock {
  JointSample sample{};       // β, β̇, deflection, module StatusBits
  std::uint8_t echo = 0;      // last sync counter c the module latched [-]
  wire::ModuleTiming timing{};  // when it sampled, which command it applied last and when
};
// Encoders return wire::QuantFlag bits (0 = exact range). A NaN command encodes torque-off.
std::uint8_t encode_command_block(const CommandBlock& c, std::uint8_t* out12) noexcept;
void decode_command_block(const std::uint8_t* in12, CommandBlock& c) noexcept;
std::uint8_t encode_feedback_block(const FeedbackBlock& f, std::uint8_t* out15) noexcept;
void decode_feedback_block(const std::uint8_t* in15, FeedbackBlock& f) noexcept;

// Worst-case size of a packet whose unstuffed instruction+error+parameter region has n bytes:
// header 7 + n + ⌊n/3⌋ stuffing + CRC 2.
inline constexpr std::size_t worst_packet_size(std::size_t n) noexcept {
  return kHeaderSize + n + n / 3 + 2;
}

// ---- Stock DYNAMIXEL X-series servos (PROTOCOL.md §3.6) ------------------------------------------
// The addresses ROBOTIS publishes for the XM430 / XH430 family (e-Manual control table, e.g.
// ROBOTIS-GIT/emanual docs/en/dxl/x/xm430-w350.md). Only what a current-controlled SEA joint uses.
namespace x {
inline constexpr std::uint16_t kRegModelNumber = 0;        // u16 R  (XM430-W350: 1020)
inline constexpr std::uint16_t kRegFirmware = 6;           // u8  R
inline constexpr std::uint16_t kRegId = 7;                 // u8  RW EEPROM
inline constexpr std::uint16_t kRegBaud = 8;               // u8  RW EEPROM (index as above)
inline constexpr std::uint16_t kRegReturnDelay = 9;        // u8  RW EEPROM [2 µs]
inline constexpr std::uint16_t kRegOperatingMode = 11;     // u8  RW EEPROM (0 = current control)
inline constexpr std::uint16_t kRegCurrentLimit = 38;      // u16 RW EEPROM [current LSB]
inline constexpr std::uint16_t kRegTorqueEnable = 64;      // u8  RW
inline constexpr std::uint16_t kRegStatusReturnLevel = 68; // u8  RW
inline constexpr std::uint16_t kRegHardwareError = 70;     // u8  R
inline constexpr std::uint16_t kRegBusWatchdog = 98;       // i8  RW [20 ms], 0 off, −1 = expired
inline constexpr std::uint16_t kRegGoalCurrent = 102;      // i16 RW [current LSB]
inline constexpr std::uint16_t kRegRealtimeTick = 120;     // u16 R  [1 ms], wraps at 32767
inline constexpr std::uint16_t kRegPresentCurrent = 126;   // i16 R  [current LSB]
inline constexpr std::uint16_t kRegPresentVelocity = 128;  // i32 R  [0.229 rev/min]
inline constexpr std::uint16_t kRegPresentPosition = 132;  // i32 R  [4096 per rev]
inline constexpr std::uint8_t kOperatingModeCurrent = 0;
inline constexpr std::uint16_t kModelXM430W350 = 1020;
inline constexpr std::uint16_t kModelXM430W210 = 1030;
// Realtime Tick … Present Position in one read: 120 … 135 (122 … 125, Moving, Moving Status and
// Present PWM, come along unused: one contiguous range).
inline constexpr std::uint16_t kFeedbackAddress = kRegRealtimeTick;
inline constexpr std::size_t kFeedbackSize = 16;
inline constexpr std::uint16_t kTickWrap = 32768;  // Realtime Tick counts 0 … 32767 [ms]
inline constexpr double kCurrentLsbXM430 = 2.69e-3;               // [A] (XM430 e-Manual)
inline constexpr double kVelocityLsb = 0.229 * 2.0 * 3.14159265358979323846 / 60.0;  // [rad/s]
inline constexpr double kPositionLsb = 2.0 * 3.14159265358979323846 / 4096.0;       // [rad]

// The servo's control table as far as the emulator keeps it (PROTOCOL.md §3.6); other addresses
// are gaps here.
inline constexpr std::uint16_t kTableSize = 136;
inline constexpr std::int64_t kBusWatchdogUnitNs = 20'000'000;  // Bus Watchdog LSB [ns]
inline constexpr std::array<Register, 16> kRegisters = {{
    {0, 2, Access::kR, true, 0, 0xFFFF, "model number"},
    {6, 1, Access::kR, true, 0, 0xFF, "firmware version"},
    {7, 1, Access::kRW, true, 0, 252, "ID"},
    {8, 1, Access::kRW, true, 0, 7, "baud rate"},
    {9, 1, Access::kRW, true, 0, 254, "return delay time"},
    {11, 1, Access::kRW, true, 0, 16, "operating mode"},
    {38, 2, Access::kRW, true, 0, 0xFFFF, "current limit"},
    {64, 1, Access::kRW, false, 0, 1, "torque enable"},
    {68, 1, Access::kRW, false, 0, 2, "status return level"},
    {70, 1, Access::kR, false, 0, 0xFF, "hardware error status"},
    {98, 1, Access::kRW, false, 0, 127, "bus watchdog"},
    {102, 2, Access::kRW, false, 0, 0xFFFF, "goal current"},
    {120, 2, Access::kR, false, 0, 0xFFFF, "realtime tick"},
    {126, 2, Access::kR, false, 0, 0xFFFF, "present current"},
    {128, 4, Access::kR, false, 0, 0xFFFFFFFF, "present velocity"},
    {132, 4, Access::kR, false, 0, 0xFFFFFFFF, "present position"},
}};
// The SEA deflection sensor beside each stock servo (pedalwave's own device, ID = servo ID +
// sensor offset): the deflection at 124 as a pedalwave module's (int16, 2e-5 rad).
inline constexpr std::uint16_t kSensorModelNumber = 0x5053;  // "PS"
inline constexpr std::uint16_t kRegSensorDeflection = 124;
inline constexpr std::uint16_t kSensorTableSize = 126;
inline constexpr std::array<Register, 8> kSensorRegisters = {{
    {0, 2, Access::kR, true, 0, 0xFFFF, "model number"},
    {2, 1, Access::kR, true, 0, 0xFF, "firmware version"},
    {7, 1, Access::kRW, true, 1, 252, "ID"},
    {8, 1, Access::kRW, true, 0, 6, "baud rate"},
    {9, 1, Access::kRW, true, 0, 254, "return delay time"},
    {68, 1, Access::kRW, false, 0, 2, "status return level"},
    {70, 1, Access::kR, false, 0, 0xFF, "hardware error status"},
    {124, 2, Access::kR, false, 0, 0xFFFF, "deflection"},
}};

// The servo's present-value registers (Present Current, Velocity, Position) in SI: what the stock
// servo says about its motor, not a joint measurement — the X-series driver makes the joint's
// JointSample from the position and velocity and the deflection sensor's reading.
struct PresentValues {
  double current = 0.0;   // present current [A]
  double velocity = 0.0;  // present velocity, output shaft [rad/s]
  double position = 0.0;  // present position, output shaft, 0 at count 0 [rad]
  std::uint16_t tick = 0; // Realtime Tick when the servo sampled them [ms, mod 32768]
};
// The 16 bytes at 120 (Realtime Tick u16, 4 unused, Present Current i16, Velocity i32, Position
// i32) → SI, with the servo's current LSB [A].
void decode_present_values(const std::uint8_t* in16, double current_lsb, PresentValues& f) noexcept;
// Goal Current for output torque tau [N·m] through torque constant k_t [N·m/A]: rounded to the
// LSB and saturated at ±limit LSB (the servo's Current Limit, register 38); NaN → 0. Returns
// wire::kQuantClamped / kQuantNotFinite bits as the other encoders.
std::int16_t goal_current(double tau, double k_t, double current_lsb, std::uint16_t limit,
                          std::uint8_t& flags) noexcept;
}  // namespace x

}  // namespace pedalwave::drivers::dxl

namespace pedalwave::drivers {
// What sits on the serial bus: pedalwave modules (PROTOCOL.md §3.2), or per joint a stock
// X-series servo in current control (ID j + 1, §3.6) and a deflection sensor (ID j + 1 + offset).
enum class SerialDevices : std::uint8_t { kPedalwave = 0, kXSeries };
}  // namespace pedalwave::drivers
