// pedalwave::mcap::Reader — reads an MCAP file (format major version 0, https://mcap.dev/spec):
// the one Writer writes, and any other conforming writer's (chunked or not; zstd, lz4 or
// uncompressed chunks; with or without the summary section).
//
// What it does: reads the whole file into memory and checks it from the first byte to the last —
// the leading magic, the Header, every record of the data section (top-level Schema, Channel and
// Message records; Chunks, decompressed and split into their Schema, Channel and Message records;
// every other record skipped by its length, as the spec asks of readers), DataEnd, the summary
// section, the Footer and the trailing magic. CRCs are checked where the writer computed them (a
// stored 0 means "not computed"): each Chunk's uncompressed records, the data section
// (DataEnd.data_section_crc) and the summary (Footer.summary_crc). Messages of chosen topics are
// returned in log-time order (stable: equal times keep their order in the file). A linear scan:
// the summary's indexes are not used to seek (what identification reads is most of the file).
//
// Errors: std::runtime_error (ReadError) naming the file, the byte offset in the file (and, inside
// a chunk, the offset in its uncompressed records) and what was expected, e.g.
//   run.mcap: byte 0: bad magic: expected the MCAP magic 89 4d 43 41 50 30 0d 0a ("\x89MCAP0\r\n")
//   run.mcap: byte 4711: Chunk record truncated: its length says 9000 bytes, the file ends 120 bytes after its opcode
//   run.mcap: byte 4711: Chunk compression "brotli": expected "zstd", "lz4" or "" (none)
//   run.mcap: byte 4711: Chunk CRC mismatch: the records decompress to CRC 0x1234abcd, the chunk says 0xdeadbeef
//   run.mcap: byte 5000 (in the Chunk at byte 4711, uncompressed offset 88): Channel 3 ("/a") refers to schema 7: no such Schema record before it
// A file that ends early (a recording whose writer died: no summary, no footer) is an error too,
// unless ReaderOptions::allow_unfinished: then the messages of its whole records (every completed
// chunk) are read and complete() says false. (`mcap recover`, the official CLI, rewrites such a file.)
//
// Not for the real-time cycle: it allocates and does file I/O.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "pedalwave/mcap/writer.hpp"

namespace pedalwave::mcap {

// A malformed or unreadable file. what() names the file, the offset and what was expected.
class ReadError : public std::runtime_error {
 public:
  ReadError(const std::string& what, std::uint64_t offset) : std::runtime_error(what), offset_(offset) {}
  // [bytes] from the start of the file where the problem was found.
  [[nodiscard]] std::uint64_t offset() const noexcept { return offset_; }

 private:
  std::uint64_t offset_;
};

struct SchemaRecord {
  SchemaId id = 0;
  std::string name;       // "pedalwave/msg/JointState"
  std::string encoding;   // "ros2msg"
  std::string data;       // the schema text (bytes)
};

struct ChannelRecord {
  ChannelId id = 0;
  SchemaId schema_id = 0;  // 0: no schema
  std::string topic;
  std::string message_encoding;  // "cdr"
  std::map<std::string, std::string> metadata;
};

// One message as read: its channel, its fields and a copy of its data.
struct ReadMessage {
  ChannelId channel = 0;
  std::uint32_t sequence = 0;
  Timestamp log_time = 0;
  Timestamp publish_time = 0;
  std::vector<std::byte> data;
  std::uint64_t offset = 0;  // [bytes] the record's place in the file (of its Chunk when in one)
};

struct ReaderOptions {
  bool check_crcs = true;                          // chunk, data-section and summary CRCs
  std::uint64_t max_chunk_size = 1ull << 32;       // [bytes] uncompressed: refuse more (a corrupt size)
  // A file that ends early — at a record's end or inside its last record, after the Header (what a
  // recorder that died leaves) — is read up to its last whole record instead of refused; complete()
  // then says false. Damage anywhere else is still an error.
  bool allow_unfinished = false;
};

class Reader {
 public:
  // Reads and checks the whole file (see above). Throws ReadError.
  explicit Reader(std::filesystem::path path, ReaderOptions options = {});
  // The same from bytes in memory; `name` stands for the file in errors.
  Reader(std::vector<std::byte> bytes, std::string name, ReaderOptions options = {});

  [[nodiscard]] const std::string& profile() const noexcept { return profile_; }   // Header.profile
  [[nodiscard]] const std::string& library() const noexcept { return library_; }   // Header.library
  [[nodiscard]] const std::map<SchemaId, SchemaRecord>& schemas() const noexcept { return schemas_; }
  [[nodiscard]] const std::map<ChannelId, ChannelRecord>& channels() const noexcept { return channels_; }
  // The channel of a topic (the first one when several have it); nullptr when none.
  [[nodiscard]] const ChannelRecord* channel(std::string_view topic) const;
  // A channel's schema; nullptr for schema 0.
  [[nodiscard]] const SchemaRecord* schema_of(const ChannelRecord& channel) const;
  [[nodiscard]] std::uint64_t message_count() const noexcept { return message_count_; }  // all channels
  [[nodiscard]] std::uint32_t chunk_count() const noexcept { return chunk_count_; }
  [[nodiscard]] bool has_summary() const noexcept { return has_summary_; }
  // False when the file ended early and ReaderOptions::allow_unfinished read what was there.
  [[nodiscard]] bool complete() const noexcept { return complete_; }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }

  // The messages on `channels` (all channels when empty), in log-time order (stable). Rescans the
  // file's records (checked already by the constructor).
  [[nodiscard]] std::vector<ReadMessage> messages(std::span<const ChannelId> channels = {}) const;
  // The same by topic; a topic no channel has is a ReadError naming it and the topics present.
  [[nodiscard]] std::vector<ReadMessage> messages_on(std::span<const std::string> topics) const;
  // Every topic, "topic (schema name)", comma-separated (for error messages).
  [[nodiscard]] std::string topics_text() const;

 private:
  struct Sink;
  void scan(Sink* sink) const;
  void scan_checked();

  std::string name_;
  std::vector<std::byte> bytes_;
  ReaderOptions options_;
  std::string profile_, library_;
  std::map<SchemaId, SchemaRecord> schemas_;
  std::map<ChannelId, ChannelRecord> channels_;
  std::uint64_t message_count_ = 0;
  std::uint32_t chunk_count_ = 0;
  bool has_summary_ = false;
  bool complete_ = true;
};

// True when the file starts with the MCAP magic (false for a shorter or unreadable file).
[[nodiscard]] bool has_mcap_magic(const std::filesystem::path& path);

}  // namespace pedalwave::mcap
