// CdrWriter — serializes ROS 2 messages as rmw_cyclonedds / rmw_fastrtps put them on the wire and
// rosbag2 stores them: plain CDR (XCDR1), little-endian, after the 4-byte encapsulation header
// {0x00, 0x01, 0x00, 0x00} (CDR_LE, options 0).
//
// Rules (OMG CDR, XCDR1): a primitive of size n (1, 2, 4, 8) starts at an offset that is a multiple
// of n, counted from the end of the encapsulation header; padding bytes are 0. A string is a uint32
// length including the terminating NUL, the bytes, the NUL. A sequence (T[], T[<=N]) is a uint32
// element count then the elements; a fixed array (T[N]) is the N elements without a count. A nested
// message is its fields in order (no alignment of its own). bool, byte, char, int8 and uint8 are one
// byte. builtin_interfaces/Time and Duration are {int32 sec, uint32 nanosec}.
//
// A message is written field by field in its .msg order, e.g. std_msgs/msg/String:
//   CdrWriter cdr;  cdr.write_string("hello");  out.write(channel, t, cdr.bytes());
// reset() starts the next message and keeps the buffer's capacity (no allocation once warm).
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace pedalwave::mcap {

class CdrWriter {
 public:
  CdrWriter() { reset(); }

  // Starts a new message: only the encapsulation header remains.
  void reset() {
    buf_.clear();
    const std::byte header[4] = {std::byte{0x00}, std::byte{0x01}, std::byte{0x00}, std::byte{0x00}};
    buf_.insert(buf_.end(), header, header + 4);
  }

  // The message so far, encapsulation header included.
  [[nodiscard]] std::span<const std::byte> bytes() const noexcept { return buf_; }
  // [bytes] of payload after the encapsulation header (the offset alignment counts from).
  [[nodiscard]] std::size_t payload_size() const noexcept { return buf_.size() - 4; }

  // Primitives (bool, int8 … uint64, float32, float64), aligned to their size.
  template <class T>
    requires std::is_arithmetic_v<T>
  void write(T value) {
    if constexpr (std::is_same_v<T, bool>) {
      buf_.push_back(std::byte{value ? std::uint8_t{1} : std::uint8_t{0}});
    } else {
      align(sizeof(T));
      using U = std::conditional_t<sizeof(T) == 1, std::uint8_t,
                std::conditional_t<sizeof(T) == 2, std::uint16_t,
                std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>>;
      const U bits = std::bit_cast<U>(value);
      for (std::size_t i = 0; i < sizeof(T); ++i)
        buf_.push_back(static_cast<std::byte>((bits >> (8 * i)) & 0xFFu));
    }
  }
  void write_bool(bool v) { write(v); }
  void write_u8(std::uint8_t v) { write(v); }    // uint8, byte, char
  void write_i8(std::int8_t v) { write(v); }
  void write_u16(std::uint16_t v) { write(v); }
  void write_i16(std::int16_t v) { write(v); }
  void write_u32(std::uint32_t v) { write(v); }
  void write_i32(std::int32_t v) { write(v); }
  void write_u64(std::uint64_t v) { write(v); }
  void write_i64(std::int64_t v) { write(v); }
  void write_f32(float v) { write(v); }
  void write_f64(double v) { write(v); }

  // string: uint32 length + 1, the bytes, NUL.
  void write_string(std::string_view s) {
    write(static_cast<std::uint32_t>(s.size() + 1));
    const auto* p = reinterpret_cast<const std::byte*>(s.data());
    buf_.insert(buf_.end(), p, p + s.size());
    buf_.push_back(std::byte{0});
  }

  // builtin_interfaces/Time (or Duration) from [ns]: sec = floor(ns / 1e9), nanosec = the rest in
  // [0, 1e9) (negative times round toward −∞, as rclcpp's Time does).
  void write_time(std::int64_t ns) {
    std::int64_t sec = ns / 1'000'000'000;
    std::int64_t nsec = ns % 1'000'000'000;
    if (nsec < 0) {
      nsec += 1'000'000'000;
      sec -= 1;
    }
    write(static_cast<std::int32_t>(sec));
    write(static_cast<std::uint32_t>(nsec));
  }

  // The uint32 element count of a sequence whose elements the caller writes next (nested messages).
  void write_sequence_length(std::size_t n) { write(static_cast<std::uint32_t>(n)); }

  // Sequence of primitives or strings: count, then the elements.
  template <class T>
  void write_sequence(std::span<const T> items) {
    write_sequence_length(items.size());
    write_array(items);
  }
  template <class T>
  void write_sequence(const std::vector<T>& items) {
    write_sequence(std::span<const T>(items));
  }

  // Fixed-size array (T[N]): the elements only.
  template <class T>
  void write_array(std::span<const T> items) {
    if constexpr (std::is_convertible_v<const T&, std::string_view>) {
      for (const auto& s : items) write_string(s);
    } else {
      for (const T& v : items) write(v);
    }
  }

 private:
  void align(std::size_t n) {
    while (payload_size() % n != 0) buf_.push_back(std::byte{0});
  }

  std::vector<std::byte> buf_;
};

}  // namespace pedalwave::mcap
