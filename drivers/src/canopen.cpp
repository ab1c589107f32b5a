#include "pedalwave/drivers/canopen.hpp"

#include <algorithm>
#include <cstring>

namespace pedalwave::drivers::canopen {
namespace {

constexpr canid_t kFlags = CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG;

bool plain(const can_frame& f) noexcept { return (f.can_id & kFlags) == 0; }
bool valid_node(std::uint8_t node) noexcept { return node >= 1 && node <= 127; }

void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
std::uint16_t get_u16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
std::uint32_t get_u32(const std::uint8_t* p) noexcept {
  return std::uint32_t{p[0]} | (std::uint32_t{p[1]} << 8) | (std::uint32_t{p[2]} << 16) |
         (std::uint32_t{p[3]} << 24);
}

// An 8-byte SDO frame on `id` with command byte `cs` and the multiplexer index:sub.
void sdo_frame(canid_t id, std::uint8_t cs, std::uint16_t index, std::uint8_t sub,
               can_frame& f) noexcept {
  f = can_frame{};
  f.can_id = id;
  f.len = 8;
  f.data[0] = cs;
  put_u16(f.data + 1, index);
  f.data[3] = sub;
}
void abort_frame(canid_t id, std::uint16_t index, std::uint8_t sub, std::uint32_t code,
                 can_frame& f) noexcept {
  sdo_frame(id, 0x80, index, sub, f);
  put_u32(f.data + 4, code);
}
bool is_nmt_command(std::uint8_t c) noexcept {
  return c == 0x01 || c == 0x02 || c == 0x80 || c == 0x81 || c == 0x82;
}
bool is_state(std::uint8_t s) noexcept { return s == 0x00 || s == 0x04 || s == 0x05 || s == 0x7F; }

}  // namespace

const char* to_string(NmtState s) noexcept {
  switch (s) {
    case NmtState::kBootUp: return "boot-up";
    case NmtState::kStopped: return "stopped";
    case NmtState::kOperational: return "operational";
    case NmtState::kPreOperational: return "pre-operational";
  }
  return "?";
}

const char* abort_text(std::uint32_t code) noexcept {
  switch (code) {
    case kAbortToggle: return "toggle bit not alternated";
    case kAbortTimeout: return "SDO protocol timed out";
    case kAbortCommand: return "command specifier not valid or unknown";
    case kAbortOutOfMemory: return "out of memory";
    case kAbortUnsupportedAccess: return "unsupported access to an object";
    case kAbortWriteOnly: return "attempt to read a write only object";
    case kAbortReadOnly: return "attempt to write a read only object";
    case kAbortNoObject: return "object does not exist in the object dictionary";
    case kAbortLength: return "data type does not match, length of service parameter does not match";
    case kAbortLengthHigh: return "data type does not match, length of service parameter too high";
    case kAbortLengthLow: return "data type does not match, length of service parameter too low";
    case kAbortNoSubindex: return "sub-index does not exist";
    case kAbortValueRange: return "invalid value for parameter";
    case kAbortGeneral: return "general error";
    case kAbortDeviceState: return "data cannot be transferred because of the present device state";
    default: return "unknown abort code";
  }
}

// ---- NMT, SYNC, heartbeat, EMCY --------------------------------------------------------------------
bool encode_nmt(NmtCommand cmd, std::uint8_t node, can_frame& f) noexcept {
  if (node > 127 || !is_nmt_command(static_cast<std::uint8_t>(cmd))) return false;
  f = can_frame{};
  f.can_id = kCobNmt;
  f.len = 2;
  f.data[0] = static_cast<std::uint8_t>(cmd);
  f.data[1] = node;
  return true;
}

bool decode_nmt(const can_frame& f, NmtCommand& cmd, std::uint8_t& node) noexcept {
  if (!plain(f) || f.can_id != kCobNmt || f.len != 2 || !is_nmt_command(f.data[0]) || f.data[1] > 127)
    return false;
  cmd = static_cast<NmtCommand>(f.data[0]);
  node = f.data[1];
  return true;
}

bool encode_sync(std::uint8_t counter, can_frame& f) noexcept {
  if (counter > 240) return false;
  f = can_frame{};
  f.can_id = kCobSync;
  f.len = counter == 0 ? 0 : 1;
  f.data[0] = counter;
  return true;
}

bool encode_heartbeat(std::uint8_t node, NmtState s, can_frame& f) noexcept {
  if (!valid_node(node) || !is_state(static_cast<std::uint8_t>(s))) return false;
  f = can_frame{};
  f.can_id = kCobHeartbeat + node;
  f.len = 1;
  f.data[0] = static_cast<std::uint8_t>(s);
  return true;
}

bool decode_heartbeat(const can_frame& f, std::uint8_t& node, NmtState& s) noexcept {
  if (!plain(f) || f.can_id <= kCobHeartbeat || f.can_id > kCobHeartbeat + 127 || f.len != 1)
    return false;
  const auto st = static_cast<std::uint8_t>(f.data[0] & 0x7F);  // bit 7: node guarding's toggle
  if (!is_state(st)) return false;
  node = static_cast<std::uint8_t>(f.can_id - kCobHeartbeat);
  s = static_cast<NmtState>(st);
  return true;
}

bool encode_emcy(std::uint8_t node, const Emcy& e, can_frame& f) noexcept {
  if (!valid_node(node)) return false;
  f = can_frame{};
  f.can_id = kCobEmcy + node;
  f.len = 8;
  put_u16(f.data, e.code);
  f.data[2] = e.error_register;
  std::memcpy(f.data + 3, e.vendor.data(), 5);
  return true;
}

bool decode_emcy(const can_frame& f, std::uint8_t& node, Emcy& e) noexcept {
  if (!plain(f) || f.can_id <= kCobEmcy || f.can_id > kCobEmcy + 127 || f.len != 8) return false;
  node = static_cast<std::uint8_t>(f.can_id - kCobEmcy);
  e.code = get_u16(f.data);
  e.error_register = f.data[2];
  std::memcpy(e.vendor.data(), f.data + 3, 5);
  return true;
}

// ---- SDO client --------------------------------------------------------------------------------
bool SdoClient::start_download(std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                               std::span<const std::uint8_t> data, can_frame& request) noexcept {
  if (!valid_node(node) || data.empty() || data.size() > kMaxData) return false;
  node_ = node;
  index_ = index;
  sub_ = sub;
  abort_ = 0;
  len_ = data.size();
  pos_ = 0;
  std::copy(data.begin(), data.end(), buf_.begin());
  if (len_ <= 4) {  // expedited, size indicated: n = bytes without data
    sdo_frame(kCobSdoRx + node, static_cast<std::uint8_t>(0x23 | ((4 - len_) << 2)), index, sub, request);
    std::memcpy(request.data + 4, buf_.data(), len_);
  } else {  // segmented, size indicated
    sdo_frame(kCobSdoRx + node, 0x21, index, sub, request);
    put_u32(request.data + 4, static_cast<std::uint32_t>(len_));
  }
  state_ = State::kInitDownload;
  return true;
}

bool SdoClient::start_upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                             can_frame& request) noexcept {
  if (!valid_node(node)) return false;
  node_ = node;
  index_ = index;
  sub_ = sub;
  abort_ = 0;
  len_ = 0;
  expected_ = 0;
  sdo_frame(kCobSdoRx + node, 0x40, index, sub, request);
  state_ = State::kInitUpload;
  return true;
}

SdoStep SdoClient::fail(std::uint32_t code, bool send, can_frame& next) noexcept {
  if (send) abort_frame(kCobSdoRx + node_, index_, sub_, code, next);
  abort_ = code;
  state_ = State::kIdle;
  return SdoStep::kAbort;
}

void SdoClient::timeout(can_frame& abort) noexcept {
  if (state_ == State::kIdle) return;
  (void)fail(kAbortTimeout, true, abort);
}

void SdoClient::next_segment(can_frame& f) noexcept {
  const std::size_t n = std::min<std::size_t>(7, len_ - pos_);
  f = can_frame{};
  f.can_id = kCobSdoRx + node_;
  f.len = 8;
  f.data[0] = static_cast<std::uint8_t>((toggle_ ? 0x10 : 0) | ((7 - n) << 1) | (pos_ + n == len_ ? 1 : 0));
  std::memcpy(f.data + 1, buf_.data() + pos_, n);
  pos_ += n;
}

SdoStep SdoClient::on_frame(const can_frame& f, can_frame& next) noexcept {
  if (state_ == State::kIdle || !plain(f) || f.can_id != kCobSdoTx + node_) return SdoStep::kIgnored;
  if (f.len != 8) return fail(kAbortGeneral, true, next);
  const std::uint8_t cs = f.data[0];
  const bool same_object = get_u16(f.data + 1) == index_ && f.data[3] == sub_;
  if ((cs & 0xE0) == 0x80) {  // the server aborted
    abort_ = get_u32(f.data + 4);
    state_ = State::kIdle;
    return SdoStep::kAbort;
  }
  switch (state_) {
    case State::kInitDownload:
      if ((cs & 0xE0) != 0x60) return fail(kAbortCommand, true, next);
      if (!same_object) return fail(kAbortGeneral, true, next);
      if (len_ <= 4) {
        state_ = State::kIdle;
        return SdoStep::kDone;
      }
      state_ = State::kSegDownload;
      toggle_ = false;
      next_segment(next);
      return SdoStep::kSend;
    case State::kSegDownload:
      if ((cs & 0xE0) != 0x20) return fail(kAbortCommand, true, next);
      if (((cs & 0x10) != 0) != toggle_) return fail(kAbortToggle, true, next);
      if (pos_ == len_) {
        state_ = State::kIdle;
        return SdoStep::kDone;
      }
      toggle_ = !toggle_;
      next_segment(next);
      return SdoStep::kSend;
    case State::kInitUpload:
      if ((cs & 0xE0) != 0x40) return fail(kAbortCommand, true, next);
      if (!same_object) return fail(kAbortGeneral, true, next);
      if (cs & 0x02) {  // expedited: 4 − n bytes (n valid with s), else 4 unspecified
        len_ = (cs & 0x01) ? 4 - ((cs >> 2) & 3) : 4;
        std::memcpy(buf_.data(), f.data + 4, len_);
        state_ = State::kIdle;
        return SdoStep::kDone;
      }
      expected_ = (cs & 0x01) ? get_u32(f.data + 4) : 0;
      if (expected_ > kMaxData) return fail(kAbortOutOfMemory, true, next);
      state_ = State::kSegUpload;
      toggle_ = false;
      sdo_frame(kCobSdoRx + node_, 0x60, 0, 0, next);  // upload segment request, t = 0
      return SdoStep::kSend;
    case State::kSegUpload: {
      if ((cs & 0xE0) != 0x00) return fail(kAbortCommand, true, next);
      if (((cs & 0x10) != 0) != toggle_) return fail(kAbortToggle, true, next);
      const std::size_t n = 7 - ((cs >> 1) & 7);
      if (len_ + n > kMaxData) return fail(kAbortOutOfMemory, true, next);
      std::memcpy(buf_.data() + len_, f.data + 1, n);
      len_ += n;
      if (cs & 0x01) {  // the last segment
        if (expected_ != 0 && len_ != expected_)
          return fail(len_ > expected_ ? kAbortLengthHigh : kAbortLengthLow, true, next);
        state_ = State::kIdle;
        return SdoStep::kDone;
      }
      toggle_ = !toggle_;
      sdo_frame(kCobSdoRx + node_, static_cast<std::uint8_t>(0x60 | (toggle_ ? 0x10 : 0)), 0, 0, next);
      return SdoStep::kSend;
    }
    case State::kIdle: break;
  }
  return SdoStep::kIgnored;
}

// ---- SDO server --------------------------------------------------------------------------------
void SdoServer::abort(std::uint32_t code, can_frame& r) noexcept {
  abort_frame(kCobSdoTx + node_, index_, sub_, code, r);
  state_ = State::kIdle;
}

bool SdoServer::on_frame(const can_frame& f, can_frame& r) noexcept {
  if (!plain(f) || f.can_id != kCobSdoRx + node_) return false;
  const std::uint8_t cs = f.data[0];
  if (f.len != 8) {
    abort(kAbortGeneral, r);
    return true;
  }
  const canid_t tx = kCobSdoTx + node_;
  switch (cs >> 5) {
    case 1: {  // initiate download
      index_ = get_u16(f.data + 1);
      sub_ = f.data[3];
      if (cs & 0x02) {  // expedited
        const std::size_t n = (cs & 0x01) ? 4 - ((cs >> 2) & 3) : 4;
        const std::uint32_t code = od_.write(index_, sub_, std::span<const std::uint8_t>(f.data + 4, n));
        if (code != 0) abort(code, r);
        else sdo_frame(tx, 0x60, index_, sub_, r);
        state_ = State::kIdle;
        return true;
      }
      size_ = (cs & 0x01) ? get_u32(f.data + 4) : 0;
      if (size_ > kMaxData) {
        abort(kAbortOutOfMemory, r);
        return true;
      }
      state_ = State::kDownload;
      toggle_ = false;
      len_ = 0;
      sdo_frame(tx, 0x60, index_, sub_, r);
      return true;
    }
    case 0: {  // download segment
      if (state_ != State::kDownload) {
        abort(kAbortCommand, r);
        return true;
      }
      if (((cs & 0x10) != 0) != toggle_) {
        abort(kAbortToggle, r);
        return true;
      }
      const std::size_t n = 7 - ((cs >> 1) & 7);
      if (len_ + n > kMaxData) {
        abort(kAbortOutOfMemory, r);
        return true;
      }
      std::memcpy(buf_.data() + len_, f.data + 1, n);
      len_ += n;
      if (cs & 0x01) {  // the last segment: the object gets the whole value
        if (size_ != 0 && len_ != size_) {
          abort(len_ > size_ ? kAbortLengthHigh : kAbortLengthLow, r);
          return true;
        }
        const std::uint32_t code = od_.write(index_, sub_, std::span<const std::uint8_t>(buf_.data(), len_));
        if (code != 0) {
          abort(code, r);
          return true;
        }
        state_ = State::kIdle;
      }
      r = can_frame{};
      r.can_id = tx;
      r.len = 8;
      r.data[0] = static_cast<std::uint8_t>(0x20 | (toggle_ ? 0x10 : 0));
      toggle_ = !toggle_;
      return true;
    }
    case 2: {  // initiate upload
      index_ = get_u16(f.data + 1);
      sub_ = f.data[3];
      std::uint32_t code = 0;
      len_ = od_.read(index_, sub_, buf_, code);
      if (code != 0) {
        abort(code, r);
        return true;
      }
      if (len_ <= 4) {
        sdo_frame(tx, static_cast<std::uint8_t>(0x43 | ((4 - len_) << 2)), index_, sub_, r);
        std::memcpy(r.data + 4, buf_.data(), len_);
        state_ = State::kIdle;
        return true;
      }
      sdo_frame(tx, 0x41, index_, sub_, r);
      put_u32(r.data + 4, static_cast<std::uint32_t>(len_));
      state_ = State::kUpload;
      toggle_ = false;
      pos_ = 0;
      return true;
    }
    case 3: {  // upload segment
      if (state_ != State::kUpload) {
        abort(kAbortCommand, r);
        return true;
      }
      if (((cs & 0x10) != 0) != toggle_) {
        abort(kAbortToggle, r);
        return true;
      }
      const std::size_t n = std::min<std::size_t>(7, len_ - pos_);
      const bool last = pos_ + n == len_;
      r = can_frame{};
      r.can_id = tx;
      r.len = 8;
      r.data[0] = static_cast<std::uint8_t>((toggle_ ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0));
      std::memcpy(r.data + 1, buf_.data() + pos_, n);
      pos_ += n;
      toggle_ = !toggle_;
      if (last) state_ = State::kIdle;
      return true;
    }
    case 4:  // the client aborted: no answer
      state_ = State::kIdle;
      return false;
    default:
      abort(kAbortCommand, r);
      return true;
  }
}

const char* emcy_text(std::uint16_t code) noexcept {
  switch (code) {
    case 0x0000: return "error reset / no error";
    case 0x2310: return "continuous over-current (device output side)";
    case kEmcyOverTemperature: return "excess temperature (device)";
    case kEmcyEncoder: return "incremental sensor 1 fault (encoder)";
    case 0x8130: return "life guard error or heartbeat error";
    default:
      switch (code >> 12) {
        case 0x1: return "generic error";
        case 0x2: return "current error";
        case 0x3: return "voltage error";
        case 0x4: return "temperature error";
        case 0x5: return "device hardware error";
        case 0x6: return "device software error";
        case 0x7: return "additional modules error";
        case 0x8: return "monitoring error";
        case 0x9: return "external error";
        case 0xF: return "additional functions error";
        default: return "unknown emergency error code";
      }
  }
}

}  // namespace pedalwave::drivers::canopen
