// Bus budget checks, run once at configuration (drivers/PROTOCOL.md §5): does one cycle's frame
// set fit in one period? A configuration that does not fit is refused with std::invalid_argument
// naming the numbers (needed, available, load %) and the options (lower rate, CAN FD, second bus,
// higher baud rate).
//
// Classic CAN 2.0A data frame with n data bytes, worst-case bit stuffing (Davis et al., 2007):
//   bits(n) = 8n + 47 + ⌊(34 + 8n − 1) / 4⌋          (47 = 34 stuffable + 13 fixed incl. 3-bit IFS)
// CAN FD frame (11-bit id, BRS set), conservative bound:
//   nominal-rate bits = 17 (SOF…BRS) + 4 (stuff) + 13 (CRC delim, ACK, EOF, IFS)      = 34
//   data-rate bits    = 5 (ESI, DLC) + 8n + ⌊(5 + 8n − 1)/4⌋ (dynamic stuff)
//                       + 4 (stuff count) + CRC (17 if n ≤ 16 else 21) + fixed stuff bits
//                       (⌈(4 + CRC)/4⌉)
//   time = nominal bits / bitrate + data bits / data_bitrate
// Per cycle the CAN frame set is (PROTOCOL.md §2): 1 SYNC (2 bytes, classic) + J feedback frames
// (classic: 8 bytes + J timing frames of 8 bytes; FD: 16-byte frames with BRS carrying the timing
// record) + commands: classic J command frames + 1 gains frame; FD ⌈J/6⌉ command-group frames.
// Serial (DYNAMIXEL 2.0, 8N1 = 10 bits per byte): sync-counter Write (13 bytes) + Sync Read
// (14 + J) + J status packets (worst-case stuffing) + Sync Write (worst-case stuffing), plus J
// module return delays and one host turnaround per exchange.
#pragma once

#include <cstdint>
#include <string>

namespace pedalwave::drivers {

// Worst-case bits of a classic CAN frame (11-bit id) with n data bytes, interframe space included.
int can_classic_frame_bits(int n) noexcept;
// Worst-case bits of a CAN FD frame (11-bit id, BRS) with payload n (a valid FD length).
struct CanFdFrameBits {
  int nominal = 0;  // bits at the arbitration (nominal) bit rate [-]
  int data = 0;     // bits at the data bit rate [-]
};
CanFdFrameBits canfd_frame_bits(int n) noexcept;

struct CanBusSpec {
  int joints = 0;             // joints (modules) on this bus, 1…63 [-]
  double period_s = 1e-3;     // cycle period [s]
  double bitrate = 1e6;       // nominal (arbitration) bit rate [bit/s]
  bool fd = false;            // CAN FD frame set (command groups, FD feedback with BRS)
  double data_bitrate = 5e6;  // CAN FD data-phase bit rate [bit/s] (ignored for classic)
  double max_load = 0.8;      // fraction of the period the frame set may occupy [-]
  // CANopen instead of the pedalwave frame set (PROTOCOL.md §7.4; classic frames only): per cycle
  // SYNC (0 bytes) + J RPDO 1 (CST: 4 bytes, CSP: 8) [+ J RPDO 2 of 4 bytes in CSP] + J TPDO 1 and
  // J TPDO 2 (8 bytes each), plus the heartbeats (J frames of 1 byte every heartbeat_s) spread
  // over the cycles.
  bool canopen = false;
  bool canopen_csp = false;
  double heartbeat_s = 0.0;   // 0: no heartbeat counted [s]
};

struct BusBudget {
  int frames = 0;                  // frames (packets) per cycle [-]
  double bits_needed = 0.0;        // nominal-bit-time equivalents per cycle [bit]
  double bits_available = 0.0;     // bitrate × period × max_load [bit]
  double time_needed_s = 0.0;      // bus time per cycle [s]
  double time_available_s = 0.0;   // period × max_load [s]
  double load = 0.0;               // time_needed / period [-] (1 = 100 % of the bus)
  bool fits = false;               // time_needed ≤ time_available
};

// Computes the budget (no throw). Invalid specs (joints ≤ 0, rates ≤ 0) give fits = false.
BusBudget can_bus_budget(const CanBusSpec& spec) noexcept;
// Throws std::invalid_argument with the numbers and the options if the frame set does not fit
// (or the spec is invalid). Returns the budget otherwise.
BusBudget check_can_bus_budget(const CanBusSpec& spec);

struct SerialBusSpec {
  int joints = 0;                 // modules on the bus [-]
  double period_s = 1e-3;         // cycle period [s]
  int baud = 1'000'000;           // [bit/s], 8N1
  double return_delay_s = 20e-6;  // per module: status-packet return delay [s]
  double turnaround_s = 0.0;      // host: per exchange (write→read), e.g. USB latency [s]
  double max_load = 0.8;          // fraction of the period the exchange may occupy [-]
  // Stock X-series servos + deflection sensors (PROTOCOL.md §3.6): per cycle one Bulk Read
  // (servo 10 bytes at 126, sensor 2 bytes at 124), 2 status packets and 2 return delays per
  // joint, one Sync Write of Goal Current; instead of the pedalwave modules' packets.
  bool x_series = false;
};
// Worst-case bytes per cycle on the serial bus for J joints.
int serial_bytes_per_cycle(int joints) noexcept;
int xseries_bytes_per_cycle(int joints) noexcept;  // the same on an X-series bus
BusBudget serial_bus_budget(const SerialBusSpec& spec) noexcept;
BusBudget check_serial_bus_budget(const SerialBusSpec& spec);

// Time from the start of the SYNC to the end of the last module's answer on an idle bus, worst
// case [s]: the least a read deadline must leave (the runtime's read_budget · period).
double can_reply_window_s(const CanBusSpec& spec) noexcept;
double serial_reply_window_s(const SerialBusSpec& spec) noexcept;

}  // namespace pedalwave::drivers
