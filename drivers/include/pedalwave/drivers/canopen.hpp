// CANopen (CiA 301) codecs: NMT, SYNC, heartbeat / boot-up, EMCY, and an SDO client and server
// (expedited and segmented transfers) as pure state machines on can_frame — no I/O, no
// allocation, noexcept. Used by the SocketCAN driver's CANopen master (canopen_driver.hpp,
// driver.protocol: canopen) and the emulator's CANopen personality (canopen_emulator.hpp).
//
// Predefined connection set (11-bit COB-IDs, node 1 … 127):
//   0x000 NMT command        host → nodes   2 bytes: [0] command specifier, [1] node (0 = all)
//   0x080 SYNC               host → all     0 bytes, or 1 byte counter 1 … 240
//   0x080 + node  EMCY       node → host    8 bytes: [0-1] error code, [2] error register (1001h),
//                                            [3-7] manufacturer-specific
//   0x580 + node  SDO tx     server → client 8 bytes
//   0x600 + node  SDO rx     client → server 8 bytes
//   0x700 + node  heartbeat  node → host    1 byte: NMT state (0x00 = boot-up)
// SDO byte 0 (command specifier, bits 7-5):
//   initiate download request  001 0 n(3-2) e(1) s(0)   e.g. 0x23/0x27/0x2B/0x2F: 4/3/2/1 bytes
//   initiate download response 011 00000 (0x60)
//   download segment request   000 t(4) n(3-1) c(0)     c = 1: last segment
//   download segment response  001 t(4) 0000 (0x20 | t)
//   initiate upload request    010 00000 (0x40)
//   initiate upload response   010 0 n e s              e.g. 0x43/0x47/0x4B/0x4F; 0x41: segmented
//   upload segment request     011 t 0000 (0x60 | t)
//   upload segment response    000 t n(3-1) c(0)
//   abort                      100 00000 (0x80), [4-7] abort code (u32)
// then [1-2] index (little-endian), [3] subindex in the initiate and abort frames.
#pragma once

#include <linux/can.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace pedalwave::drivers::canopen {

inline constexpr canid_t kCobNmt = 0x000;
inline constexpr canid_t kCobSync = 0x080;
inline constexpr canid_t kCobEmcy = 0x080;       // + node
inline constexpr canid_t kCobSdoTx = 0x580;      // + node: server → client
inline constexpr canid_t kCobSdoRx = 0x600;      // + node: client → server
inline constexpr canid_t kCobHeartbeat = 0x700;  // + node

enum class NmtCommand : std::uint8_t {
  kStart = 0x01,               // → operational
  kStop = 0x02,                // → stopped
  kEnterPreOperational = 0x80,
  kResetNode = 0x81,
  kResetCommunication = 0x82,
};
enum class NmtState : std::uint8_t {
  kBootUp = 0x00,
  kStopped = 0x04,
  kOperational = 0x05,
  kPreOperational = 0x7F,
};
const char* to_string(NmtState s) noexcept;

// SDO abort codes (CiA 301 §7.2.4.3.17), the ones this code produces or names.
enum AbortCode : std::uint32_t {
  kAbortToggle = 0x05030000,            // toggle bit not alternated
  kAbortTimeout = 0x05040000,           // SDO protocol timed out
  kAbortCommand = 0x05040001,           // client/server command specifier not valid or unknown
  kAbortOutOfMemory = 0x05040005,       // out of memory
  kAbortUnsupportedAccess = 0x06010000, // unsupported access to an object
  kAbortWriteOnly = 0x06010001,         // attempt to read a write only object
  kAbortReadOnly = 0x06010002,          // attempt to write a read only object
  kAbortNoObject = 0x06020000,          // object does not exist in the object dictionary
  kAbortLength = 0x06070010,            // data type does not match, length of service parameter does not match
  kAbortLengthHigh = 0x06070012,        // data type does not match, length too high
  kAbortLengthLow = 0x06070013,         // data type does not match, length too low
  kAbortNoSubindex = 0x06090011,        // sub-index does not exist
  kAbortValueRange = 0x06090030,        // invalid value for parameter (download only)
  kAbortGeneral = 0x08000000,           // general error
  kAbortDeviceState = 0x08000022,       // data cannot be transferred because of the present device state
};
// The code's name ("toggle bit not alternated", …; "unknown abort code" otherwise).
const char* abort_text(std::uint32_t code) noexcept;

// ---- NMT, SYNC, heartbeat, EMCY --------------------------------------------------------------------
// Node ids are 1 … 127; an encoder given another returns false (NMT: 0 = every node).
bool encode_nmt(NmtCommand cmd, std::uint8_t node, can_frame& f) noexcept;
bool decode_nmt(const can_frame& f, NmtCommand& cmd, std::uint8_t& node) noexcept;
// SYNC without counter (counter = 0) or with one (1 … 240).
bool encode_sync(std::uint8_t counter, can_frame& f) noexcept;
bool encode_heartbeat(std::uint8_t node, NmtState s, can_frame& f) noexcept;
// A heartbeat or boot-up frame (0x701 … 0x77F, 1 byte, a known state; toggle bit 7 ignored).
bool decode_heartbeat(const can_frame& f, std::uint8_t& node, NmtState& s) noexcept;
struct Emcy {
  std::uint16_t code = 0;                  // emergency error code (0x0000 = error reset)
  std::uint8_t error_register = 0;         // object 1001h
  std::array<std::uint8_t, 5> vendor{};    // manufacturer-specific
};
bool encode_emcy(std::uint8_t node, const Emcy& e, can_frame& f) noexcept;
// An EMCY frame (0x081 … 0x0FF, 8 bytes). A SYNC (0x080) is none.
bool decode_emcy(const can_frame& f, std::uint8_t& node, Emcy& e) noexcept;

// ---- SDO client --------------------------------------------------------------------------------
// One transfer at a time with one node. start_*() builds the first request; on_frame() takes every
// received frame and says what to do: send `next` (kSend), the transfer is over (kDone: a download
// was confirmed, an upload's data is in data()), or it failed (kAbort: abort_code(); when the
// client aborts it, `next` holds the abort frame to send), or the frame is not this transfer's
// (kIgnored). timeout() ends a transfer whose answer did not come (returns the abort frame to send).
enum class SdoStep : std::uint8_t { kIgnored, kSend, kDone, kAbort };

class SdoClient {
 public:
  static constexpr std::size_t kMaxData = 256;  // largest transfer [bytes]

  // Download (write) `data` to node's object index:sub: expedited up to 4 bytes, else segmented
  // (the size indicated). False: a bad node, empty or too long data.
  bool start_download(std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                      std::span<const std::uint8_t> data, can_frame& request) noexcept;
  // Upload (read) node's object index:sub.
  bool start_upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                    can_frame& request) noexcept;
  SdoStep on_frame(const can_frame& f, can_frame& next) noexcept;
  void timeout(can_frame& abort) noexcept;

  bool busy() const noexcept { return state_ != State::kIdle; }
  std::uint32_t abort_code() const noexcept { return abort_; }
  std::span<const std::uint8_t> data() const noexcept { return {buf_.data(), len_}; }

 private:
  enum class State : std::uint8_t { kIdle, kInitDownload, kSegDownload, kInitUpload, kSegUpload };
  SdoStep fail(std::uint32_t code, bool send, can_frame& next) noexcept;
  void next_segment(can_frame& f) noexcept;

  State state_ = State::kIdle;
  std::uint8_t node_ = 0;
  std::uint16_t index_ = 0;
  std::uint8_t sub_ = 0;
  bool toggle_ = false;
  std::uint32_t abort_ = 0;
  std::size_t len_ = 0, pos_ = 0;
  std::size_t expected_ = 0;   // upload: the size the server indicated (0 = not indicated)
  std::array<std::uint8_t, kMaxData> buf_{};
};

// ---- SDO server --------------------------------------------------------------------------------
// The object dictionary behind a server: read() fills `out` (at most out.size() bytes) and returns
// its length, or sets an abort code; write() stores `data` or returns an abort code (0 = done).
class ObjectDictionary {
 public:
  virtual ~ObjectDictionary() = default;
  virtual std::size_t read(std::uint16_t index, std::uint8_t sub, std::span<std::uint8_t> out,
                           std::uint32_t& abort) noexcept = 0;
  virtual std::uint32_t write(std::uint16_t index, std::uint8_t sub,
                              std::span<const std::uint8_t> data) noexcept = 0;
};

class SdoServer {
 public:
  static constexpr std::size_t kMaxData = 256;  // largest transfer [bytes]
  SdoServer(std::uint8_t node, ObjectDictionary& od) noexcept : node_(node), od_(od) {}
  // A frame on 0x600 + node: true and `response` to send; false: not for this server.
  bool on_frame(const can_frame& f, can_frame& response) noexcept;

 private:
  enum class State : std::uint8_t { kIdle, kDownload, kUpload };
  void abort(std::uint32_t code, can_frame& r) noexcept;

  std::uint8_t node_;
  ObjectDictionary& od_;
  State state_ = State::kIdle;
  std::uint16_t index_ = 0;
  std::uint8_t sub_ = 0;
  bool toggle_ = false;
  std::size_t len_ = 0, pos_ = 0, size_ = 0;  // download: indicated size (0 = not indicated)
  std::array<std::uint8_t, kMaxData> buf_{};
};

// ---- The pedalwave drive's objects beyond cia402.hpp's (the master configures them, the
// emulated drive serves them; drivers/PROTOCOL.md §7) ----
// Further SDO abort codes the PDO mapping procedure uses (CiA 301).
inline constexpr std::uint32_t kAbortNotMappable = 0x06040041;  // object cannot be mapped to the PDO
inline constexpr std::uint32_t kAbortPdoLength = 0x06040042;    // mapped objects exceed the PDO length

// Communication objects of CiA 301 the master sets at bring-up.
inline constexpr std::uint16_t kObjCyclePeriod = 0x1006;  // uint32 [µs], the SYNC period
inline constexpr std::uint16_t kObjSyncWindow = 0x1007;   // uint32 [µs], synchronous window length
// Manufacturer objects: the CSP position loop's gains (REAL32).
inline constexpr std::uint16_t kObjCspKp = 0x2010;  // [N·m/rad]
inline constexpr std::uint16_t kObjCspKd = 0x2011;  // [N·m·s/rad]
// Profile objects beyond cia402.hpp's.
inline constexpr std::uint16_t kObjErrorCode = 0x603F;        // uint16, last EMCY code
inline constexpr std::uint16_t kObjRatedTorque = 0x6076;      // uint32 [mN·m]
inline constexpr std::uint16_t kObjEncoderResolution = 0x608F;  // :01 increments, :02 revolutions
inline constexpr std::uint16_t kObjVelocityOffset = 0x60B1;   // int32 [inc/s]
inline constexpr std::uint16_t kObjTorqueOffset = 0x60B2;     // int16 [‰]
inline constexpr std::uint16_t kObjDeflectionResolution = 0x6001;  // CiA 406 measuring units / rev
inline constexpr std::uint16_t kObjDeflection = 0x6004;       // CiA 406 position value
inline constexpr std::uint32_t kDeviceType = 0x00020192;      // CiA 402, servo drive

// EMCY codes the emulated drives send.
inline constexpr std::uint16_t kEmcyOverTemperature = 0x4210;  // excess temperature device
inline constexpr std::uint16_t kEmcyEncoder = 0x7305;          // incremental sensor 1 fault
const char* emcy_text(std::uint16_t code) noexcept;  // "excess temperature (device)", …

}  // namespace pedalwave::drivers::canopen
