// CdrReader — reads what CdrWriter (cdr.hpp) writes: plain CDR (XCDR1), little-endian, after the
// 4-byte encapsulation header {0x00, 0x01, 0x00, 0x00} (CDR_LE). The same rules, read back: a
// primitive of size n is aligned to n from the end of the header, a string is a uint32 length
// including the NUL then the bytes and the NUL, a sequence a uint32 count then the elements, a
// fixed array the elements only, a nested message its fields in order.
//
// A message is read field by field in its .msg order, e.g. a std_msgs/Header then float64[] x:
//   CdrReader cdr(message.data);        // throws on a header other than CDR_LE
//   const auto stamp = cdr.read_time(); const auto frame = cdr.read_string();
//   const auto x = cdr.read_sequence<double>();
// Errors (std::runtime_error): "CDR offset <n>: <what>: expected <...>" — a field running past the
// message, a string without its NUL, a sequence longer than the message could hold or than a bound;
// callers prefix the file and topic.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace pedalwave::mcap {

class CdrReader {
 public:
  explicit CdrReader(std::span<const std::byte> message) : buf_(message) {
    if (buf_.size() < 4)
      fail(0, "message of " + std::to_string(buf_.size()) + " bytes: expected at least the 4-byte encapsulation header");
    if (buf_[0] != std::byte{0x00} || buf_[1] != std::byte{0x01})
      fail(0, "encapsulation " + std::to_string(std::to_integer<int>(buf_[0])) + "," +
                  std::to_string(std::to_integer<int>(buf_[1])) + ": expected 0,1 (CDR_LE, plain little-endian CDR)");
    pos_ = 4;
  }

  template <class T>
    requires std::is_arithmetic_v<T>
  T read(const char* field = "value") {
    if constexpr (std::is_same_v<T, bool>) {
      need(1, field);
      return std::to_integer<unsigned>(buf_[pos_++]) != 0;
    } else {
      align(sizeof(T));
      need(sizeof(T), field);
      using U = std::conditional_t<sizeof(T) == 1, std::uint8_t,
                std::conditional_t<sizeof(T) == 2, std::uint16_t,
                std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>>;
      U bits = 0;
      for (std::size_t i = 0; i < sizeof(T); ++i)
        bits = static_cast<U>(bits | static_cast<U>(static_cast<U>(std::to_integer<unsigned>(buf_[pos_ + i])) << (8 * i)));
      pos_ += sizeof(T);
      return std::bit_cast<T>(bits);
    }
  }
  bool read_bool(const char* f = "bool") { return read<bool>(f); }
  std::uint8_t read_u8(const char* f = "uint8") { return read<std::uint8_t>(f); }
  std::int8_t read_i8(const char* f = "int8") { return read<std::int8_t>(f); }
  std::uint16_t read_u16(const char* f = "uint16") { return read<std::uint16_t>(f); }
  std::int16_t read_i16(const char* f = "int16") { return read<std::int16_t>(f); }
  std::uint32_t read_u32(const char* f = "uint32") { return read<std::uint32_t>(f); }
  std::int32_t read_i32(const char* f = "int32") { return read<std::int32_t>(f); }
  std::uint64_t read_u64(const char* f = "uint64") { return read<std::uint64_t>(f); }
  std::int64_t read_i64(const char* f = "int64") { return read<std::int64_t>(f); }
  float read_f32(const char* f = "float32") { return read<float>(f); }
  double read_f64(const char* f = "float64") { return read<double>(f); }

  std::string read_string(const char* field = "string") {
    const std::uint32_t n = read<std::uint32_t>(field);
    if (n == 0) fail(pos_ - 4, std::string(field) + ": string length 0: expected the length including its NUL (≥ 1)");
    need(n, field);
    if (buf_[pos_ + n - 1] != std::byte{0})
      fail(pos_ + n - 1, std::string(field) + ": string of " + std::to_string(n) + " bytes does not end in NUL");
    std::string s(reinterpret_cast<const char*>(buf_.data() + pos_), n - 1);
    pos_ += n;
    return s;
  }

  // builtin_interfaces/Time (or Duration) → [ns].
  std::int64_t read_time(const char* field = "stamp") {
    const std::int32_t sec = read<std::int32_t>(field);
    const std::uint32_t nsec = read<std::uint32_t>(field);
    if (nsec >= 1'000'000'000u)
      fail(pos_ - 4, std::string(field) + ".nanosec = " + std::to_string(nsec) + ": expected < 1e9");
    return static_cast<std::int64_t>(sec) * 1'000'000'000 + nsec;
  }

  // A sequence's element count; max_count: the type's bound (T[<=N]), else what the bytes left could hold.
  std::size_t read_sequence_length(const char* field, std::size_t element_size = 1,
                                   std::size_t max_count = static_cast<std::size_t>(-1)) {
    const std::size_t at = pos_;
    const std::uint32_t n = read<std::uint32_t>(field);
    if (n > max_count)
      fail(at, std::string(field) + ": sequence of " + std::to_string(n) + " elements: expected at most " + std::to_string(max_count));
    if (element_size > 0 && n > (buf_.size() - pos_) / element_size)
      fail(at, std::string(field) + ": sequence of " + std::to_string(n) + " elements of " + std::to_string(element_size) +
                   " bytes, the message has " + std::to_string(buf_.size() - pos_) + " left");
    return n;
  }

  template <class T>
    requires std::is_arithmetic_v<T>
  std::vector<T> read_sequence(const char* field = "sequence", std::size_t max_count = static_cast<std::size_t>(-1)) {
    const std::size_t n = read_sequence_length(field, sizeof(T), max_count);
    std::vector<T> v;
    v.reserve(n);
    for (std::size_t i = 0; i < n; ++i) v.push_back(read<T>(field));
    return v;
  }
  std::vector<std::string> read_string_sequence(const char* field = "sequence",
                                                std::size_t max_count = static_cast<std::size_t>(-1)) {
    const std::size_t n = read_sequence_length(field, 5, max_count);
    std::vector<std::string> v;
    v.reserve(n);
    for (std::size_t i = 0; i < n; ++i) v.push_back(read_string(field));
    return v;
  }
  template <class T>
    requires std::is_arithmetic_v<T>
  std::vector<T> read_array(std::size_t n, const char* field = "array") {
    std::vector<T> v;
    v.reserve(n);
    for (std::size_t i = 0; i < n; ++i) v.push_back(read<T>(field));
    return v;
  }

  // [bytes] of payload read so far (after the encapsulation header), and left.
  [[nodiscard]] std::size_t offset() const noexcept { return pos_ - 4; }
  [[nodiscard]] std::size_t remaining() const noexcept { return buf_.size() - pos_; }

 private:
  [[noreturn]] static void fail(std::size_t at, const std::string& what) {
    throw std::runtime_error("CDR offset " + std::to_string(at) + ": " + what);
  }
  void need(std::size_t n, const char* field) const {
    if (n > buf_.size() - pos_)
      fail(pos_, std::string(field) + " needs " + std::to_string(n) + " bytes, the message has " +
                     std::to_string(buf_.size() - pos_) + " left: expected a complete message");
  }
  void align(std::size_t n) {
    const std::size_t pad = (n - (pos_ - 4) % n) % n;
    need(pad, "padding");
    pos_ += pad;
  }

  std::span<const std::byte> buf_;
  std::size_t pos_ = 0;
};

}  // namespace pedalwave::mcap
