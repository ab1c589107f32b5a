// A minimal MCAP record reader for the tests, written from the specification independently of the
// writer: splits a file (or an in-memory image of one) into records, decodes their fields and
// decompresses chunks with libzstd / liblz4's own decoders. Throws std::runtime_error on anything
// malformed (a test failure, not a crash).
#pragma once

#include <lz4frame.h>
#include <zstd.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace pedalwave::mcap::test {

inline const std::vector<std::byte> kMagicBytes = {std::byte{0x89}, std::byte{'M'}, std::byte{'C'},
                                                   std::byte{'A'},  std::byte{'P'}, std::byte{'0'},
                                                   std::byte{'\r'}, std::byte{'\n'}};

inline std::vector<std::byte> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open " + path);
  std::vector<char> c((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::byte> b(c.size());
  if (!c.empty()) std::memcpy(b.data(), c.data(), c.size());
  return b;
}

// Reads little-endian fields from a span, bounds-checked.
class Cursor {
 public:
  explicit Cursor(std::span<const std::byte> s) : s_(s) {}
  template <class U>
  U le() {
    need(sizeof(U));
    U v = 0;
    for (std::size_t i = 0; i < sizeof(U); ++i) v |= static_cast<U>(static_cast<U>(s_[pos_ + i]) << (8 * i));
    pos_ += sizeof(U);
    return v;
  }
  std::uint8_t u8() { return le<std::uint8_t>(); }
  std::uint16_t u16() { return le<std::uint16_t>(); }
  std::uint32_t u32() { return le<std::uint32_t>(); }
  std::uint64_t u64() { return le<std::uint64_t>(); }
  std::span<const std::byte> bytes(std::size_t n) {
    need(n);
    auto r = s_.subspan(pos_, n);
    pos_ += n;
    return r;
  }
  std::string str() {
    const auto n = u32();
    const auto b = bytes(n);
    return std::string(reinterpret_cast<const char*>(b.data()), b.size());
  }
  std::map<std::string, std::string> string_map() {
    const auto n = u32();
    Cursor c(bytes(n));
    std::map<std::string, std::string> m;
    while (!c.done()) {
      auto k = c.str();
      m[k] = c.str();
    }
    return m;
  }
  std::span<const std::byte> rest() { return bytes(s_.size() - pos_); }
  bool done() const { return pos_ == s_.size(); }
  std::size_t pos() const { return pos_; }

 private:
  void need(std::size_t n) const {
    if (pos_ + n > s_.size()) throw std::runtime_error("MCAP record field runs past its end");
  }
  std::span<const std::byte> s_;
  std::size_t pos_ = 0;
};

struct Record {
  std::uint8_t op = 0;
  std::uint64_t offset = 0;  // of the opcode, from the start of the parsed span
  std::uint64_t size = 0;    // 1 + 8 + content length
  std::span<const std::byte> body;
};

// Splits [begin, end) of `bytes` into records. complete = false when the last record is cut off.
struct Records {
  std::vector<Record> list;
  bool complete = true;
};
inline Records split_records(std::span<const std::byte> bytes, std::size_t begin, std::size_t end) {
  Records r;
  std::size_t pos = begin;
  while (pos < end) {
    if (end - pos < 9) {
      r.complete = false;
      break;
    }
    Cursor c(bytes.subspan(pos, 9));
    Record rec;
    rec.op = c.u8();
    const std::uint64_t len = c.u64();
    if (len > end - pos - 9) {
      r.complete = false;
      break;
    }
    rec.offset = pos;
    rec.size = 9 + len;
    rec.body = bytes.subspan(pos + 9, len);
    r.list.push_back(rec);
    pos += rec.size;
  }
  return r;
}

struct Chunk {
  std::uint64_t start_time, end_time, uncompressed_size;
  std::uint32_t uncompressed_crc;
  std::string compression;
  std::vector<std::byte> records;  // decompressed
  std::uint64_t compressed_size;
};
inline Chunk decode_chunk(std::span<const std::byte> body) {
  Cursor c(body);
  Chunk k;
  k.start_time = c.u64();
  k.end_time = c.u64();
  k.uncompressed_size = c.u64();
  k.uncompressed_crc = c.u32();
  k.compression = c.str();
  const auto n = c.u64();
  const auto data = c.bytes(n);
  if (!c.done()) throw std::runtime_error("chunk record longer than its fields");
  k.compressed_size = n;
  k.records.resize(k.uncompressed_size);
  if (k.compression.empty()) {
    if (n != k.uncompressed_size) throw std::runtime_error("uncompressed chunk with a size mismatch");
    std::memcpy(k.records.data(), data.data(), n);
  } else if (k.compression == "zstd") {
    const auto got = ZSTD_decompress(k.records.data(), k.records.size(), data.data(), data.size());
    if (ZSTD_isError(got) || got != k.uncompressed_size) throw std::runtime_error("zstd chunk does not decompress");
  } else if (k.compression == "lz4") {
    LZ4F_dctx* dctx = nullptr;
    LZ4F_createDecompressionContext(&dctx, LZ4F_VERSION);
    std::size_t dst = k.records.size(), src = data.size();
    const auto rc = LZ4F_decompress(dctx, k.records.data(), &dst, data.data(), &src, nullptr);
    LZ4F_freeDecompressionContext(dctx);
    if (LZ4F_isError(rc) || rc != 0 || dst != k.uncompressed_size || src != data.size())
      throw std::runtime_error("lz4 chunk does not decompress");
  } else {
    throw std::runtime_error("unknown chunk compression " + k.compression);
  }
  return k;
}

struct MessageRec {
  std::uint16_t channel;
  std::uint32_t sequence;
  std::uint64_t log_time, publish_time;
  std::vector<std::byte> data;
};
inline MessageRec decode_message(std::span<const std::byte> body) {
  Cursor c(body);
  MessageRec m;
  m.channel = c.u16();
  m.sequence = c.u32();
  m.log_time = c.u64();
  m.publish_time = c.u64();
  const auto d = c.rest();
  m.data.assign(d.begin(), d.end());
  return m;
}

}  // namespace pedalwave::mcap::test
