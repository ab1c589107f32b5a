// pedalwave::mcap::Writer — a streaming MCAP writer (format major version 0, https://mcap.dev/spec).
//
// What it writes, in file order:
//
//   magic "\x89MCAP0\r\n", Header(profile, library)
//   Data section, per chunk:   Chunk{ Schema*, Channel*, Message* } (zstd, lz4 or uncompressed),
//                              then one MessageIndex per channel that has messages in the chunk
//   DataEnd(data_section_crc)
//   Summary section, grouped by opcode: Schema*, Channel*, ChunkIndex* (one per chunk), Statistics
//   Summary Offset section:    one SummaryOffset per group above
//   Footer(summary_start, summary_offset_start, summary_crc), magic
//
// Schema and Channel records go into the open chunk when they are added (so a streaming reader
// meets them before the first message that refers to them) and are repeated in the summary (so an
// indexed reader finds them without scanning). A chunk is closed — compressed, written with its
// message indexes and handed to the OS with fflush — once its uncompressed records reach
// WriterOptions::chunk_size, on flush() and on close(). Memory is one chunk (uncompressed and
// compressed) plus its per-channel index, reused from chunk to chunk, plus the summary (one small
// ChunkIndex per chunk, the schemas and channels).
//
// CRCs: every chunk's uncompressed records (Chunk.uncompressed_crc), the data section
// (DataEnd.data_section_crc: all bytes from the start of the file, leading magic and Header
// included, up to the DataEnd record — the reading MCAP's maintainers settled on, foxglove/mcap
// #398/#578) and the summary (Footer.summary_crc: from the first summary record through the
// Footer's summary_offset_start field). WriterOptions::crc = false writes 0 ("not computed").
//
// Crash behaviour: the file on disk is, at every moment, magic + Header + the completed chunks with
// their message indexes (+ a partly written chunk if the process dies inside a write). A streaming
// reader (@mcap/core's McapStreamReader, `mcap recover`) reads every message of the completed
// chunks; only the summary is missing, so indexed readers need `mcap recover` first. flush()
// bounds what a crash can lose. A Writer destroyed without close() closes the file properly in its
// destructor; if that fails (disk full, …) it says so on stderr, naming the file and what the file
// still holds.
//
// Threads: a Writer is used from one thread at a time (the recorder's). Not for the real-time cycle:
// it allocates and does file I/O. Neither copyable nor movable: hold it in a std::optional or a
// std::unique_ptr where it is opened later (e.g. only when --record ends in .mcap).
//
// Wiring a recorder (e.g. pedalwave_monitor --record run.mcap), with ros2msg.hpp and cdr.hpp:
//
//   namespace mcap = pedalwave::mcap;
//   mcap::Writer out("run.mcap", {.compression = mcap::Compression::zstd});
//   const mcap::MsgDirectoryLookup msgs({"<repo>/ros2/interfaces"});           // <pkg>/msg/<T>.msg
//   const auto js = out.add_ros2_channel("/snake/joint_states", "sensor_msgs/msg/JointState",
//                                        mcap::concatenate_msg_definitions("sensor_msgs/msg/JointState", msgs),
//                                        mcap::offered_qos_profiles_yaml({.depth = 10}));
//   mcap::CdrWriter cdr;
//   for (each received sample) {                       // the recorder's thread
//     cdr.reset();
//     cdr.write_time(stamp_ns);  cdr.write_string(frame_id);             // std_msgs/Header
//     cdr.write_sequence(names); cdr.write_sequence(positions); …        // JointState fields
//     out.write(js, receive_time_ns, cdr.bytes());                      // sequence: per-channel count
//   }
//   out.close();   // or let the destructor do it
//
// Errors: a file that cannot be created or written throws std::runtime_error naming the file and
// the OS error; a call with bad arguments (an unknown channel or schema id, an empty topic, a
// chunk_size of 0, more than 65535 schemas or channels) throws std::invalid_argument naming the
// file and the value. After an I/O error the writer refuses further writes (std::logic_error).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "pedalwave/mcap/crc32.hpp"

struct ZSTD_CCtx_s;  // zstd.h's ZSTD_CCtx
struct LZ4F_cctx_s;  // lz4frame.h's LZ4F_cctx

namespace pedalwave::mcap {

using SchemaId = std::uint16_t;   // 1 … 65535 (0 means "no schema")
using ChannelId = std::uint16_t;  // 1 … 65535
using Timestamp = std::uint64_t;  // [ns] since an epoch the recorder states (ROS: the Unix epoch)

// Chunk compression. The Chunk record's compression string: "" / "zstd" / "lz4" (LZ4 frame format).
enum class Compression : std::uint8_t { none, zstd, lz4 };
[[nodiscard]] std::string_view to_string(Compression c) noexcept;
// "none" (or ""), "zstd", "lz4" → Compression; anything else throws std::invalid_argument naming it.
[[nodiscard]] Compression compression_from_string(std::string_view name);

struct WriterOptions {
  std::string profile = "ros2";             // Header.profile ("ros2": cdr messages, ros2msg schemas)
  std::string library = "pedalwave-mcap";   // Header.library
  Compression compression = Compression::zstd;
  std::uint64_t chunk_size = 1024 * 1024;   // [bytes] uncompressed records at which a chunk is closed (> 0)
  int zstd_level = 3;                       // zstd compression level (1 … 19)
  bool crc = true;                          // compute chunk, data-section and summary CRCs
};

// One message. data is copied into the chunk before write() returns.
struct Message {
  ChannelId channel = 0;
  std::uint32_t sequence = 0;     // the publisher's counter (or the recorder's)
  Timestamp log_time = 0;         // [ns] when it was recorded
  Timestamp publish_time = 0;     // [ns] when it was published (log_time if not known)
  std::span<const std::byte> data;
};

// What has been written so far (the Statistics record at close() holds the same).
struct WriterStats {
  std::uint64_t message_count = 0;
  std::uint32_t chunk_count = 0;                // completed chunks
  Timestamp message_start_time = 0;             // [ns] earliest log_time (0 without messages)
  Timestamp message_end_time = 0;               // [ns] latest log_time
  std::uint64_t bytes_written = 0;              // [bytes] handed to the file so far
  std::uint64_t uncompressed_bytes = 0;         // [bytes] records in completed chunks, uncompressed
  std::uint64_t compressed_bytes = 0;           // [bytes] the same, as stored
};

class Writer {
 public:
  // Creates (truncates) `path` and writes the magic and the Header. Throws std::runtime_error
  // naming the path when it cannot be created, std::invalid_argument for bad options.
  explicit Writer(std::filesystem::path path, WriterOptions options = {});
  // Closes the file if still open (see close()); never throws: a failure is one line on stderr.
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // A Schema record. name: "sensor_msgs/msg/JointState"; encoding: "ros2msg"; data: the schema
  // text (for ros2msg: concatenate_msg_definitions()). The same triple added twice gets one id.
  SchemaId add_schema(std::string_view name, std::string_view encoding, std::string_view data);

  // A Channel record on `schema` (0: none). message_encoding: "cdr" for ROS 2. metadata: for the
  // ros2 profile it must hold "offered_qos_profiles" (add_ros2_channel() sets it). The same
  // channel added twice gets one id.
  ChannelId add_channel(SchemaId schema, std::string_view topic, std::string_view message_encoding,
                        const std::map<std::string, std::string>& metadata = {});

  // Schema (ros2msg) + Channel (cdr, offered_qos_profiles) in one call, for the ros2 profile.
  ChannelId add_ros2_channel(std::string_view topic, std::string_view type_name,
                             std::string_view msg_definition, std::string_view offered_qos_profiles);

  // Appends one Message record to the open chunk; closes the chunk when it reaches chunk_size.
  void write(const Message& message);
  // The same with sequence = this channel's message count so far and publish_time = log_time.
  void write(ChannelId channel, Timestamp log_time, std::span<const std::byte> data);

  // Closes the open chunk now (if it holds anything) and fflushes the file: whatever was written
  // before survives a crash. Costs compression ratio when called often (small chunks).
  void flush();

  // Closes the open chunk, writes DataEnd, the summary, the summary offsets, the Footer and the
  // magic, and closes the file. Throws std::runtime_error on an I/O error (the file then holds the
  // completed chunks). Idempotent.
  void close();

  [[nodiscard]] bool is_open() const noexcept { return file_ != nullptr; }
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }
  [[nodiscard]] const WriterOptions& options() const noexcept { return options_; }
  [[nodiscard]] const WriterStats& stats() const noexcept { return stats_; }

 private:
  struct SchemaInfo {
    SchemaId id;
    std::string name, encoding, data;
  };
  struct ChannelInfo {
    ChannelId id;
    SchemaId schema_id;
    std::string topic, message_encoding;
    std::map<std::string, std::string> metadata;
    std::uint64_t message_count = 0;
  };
  struct ChunkIndexInfo {
    Timestamp message_start_time, message_end_time;
    std::uint64_t chunk_start_offset, chunk_length;
    std::vector<std::pair<ChannelId, std::uint64_t>> message_index_offsets;
    std::uint64_t message_index_length;
    std::uint64_t compressed_size, uncompressed_size;
  };
  // One channel's entries in the open chunk: (log_time, offset in the uncompressed records).
  struct ChunkChannelIndex {
    std::vector<std::pair<Timestamp, std::uint64_t>> entries;
  };

  void require_open(const char* what) const;
  void put(const void* data, std::size_t size);      // to the file: position, data CRC
  void put(const std::vector<std::byte>& bytes) { put(bytes.data(), bytes.size()); }
  void close_chunk();
  void write_summary_and_footer();
  [[noreturn]] void io_error(const char* what);
  void free_codecs() noexcept;

  std::filesystem::path path_;
  WriterOptions options_;
  std::FILE* file_ = nullptr;
  bool failed_ = false;              // an I/O error happened: no more writes
  enum class Section : std::uint8_t { data, summary, none };
  Section section_ = Section::data;  // which CRC the bytes put() go into
  std::uint64_t position_ = 0;       // [bytes] offset of the next byte in the file
  Crc32 data_crc_;                   // running CRC of the data section (from byte 0)
  Crc32 summary_crc_;                // running CRC from the first summary record

  std::vector<SchemaInfo> schemas_;
  std::vector<ChannelInfo> channels_;
  std::vector<ChunkIndexInfo> chunk_indexes_;
  WriterStats stats_;

  // The open chunk.
  std::vector<std::byte> chunk_;             // uncompressed records
  std::vector<std::byte> compressed_;        // scratch for the compressed records
  ZSTD_CCtx_s* zstd_ = nullptr;              // compression contexts, kept from chunk to chunk
  LZ4F_cctx_s* lz4_ = nullptr;
  std::vector<std::byte> scratch_;           // scratch for one record (index records, summary)
  std::map<ChannelId, ChunkChannelIndex> chunk_index_;
  bool chunk_has_messages_ = false;
  Timestamp chunk_start_time_ = 0, chunk_end_time_ = 0;
};

}  // namespace pedalwave::mcap
