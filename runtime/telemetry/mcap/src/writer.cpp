#include "pedalwave/mcap/writer.hpp"

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <tuple>

#include "records.hpp"

namespace pedalwave::mcap {
namespace {

using namespace detail;  // the opcodes and the magic (records.hpp)

// Little-endian serialization into a byte buffer (spec "Serialization").
void put_u8(std::vector<std::byte>& b, std::uint8_t v) { b.push_back(static_cast<std::byte>(v)); }
template <class U>
void put_le(std::vector<std::byte>& b, U v) {
  for (std::size_t i = 0; i < sizeof(U); ++i) b.push_back(static_cast<std::byte>((v >> (8 * i)) & 0xFFu));
}
void put_u16(std::vector<std::byte>& b, std::uint16_t v) { put_le(b, v); }
void put_u32(std::vector<std::byte>& b, std::uint32_t v) { put_le(b, v); }
void put_u64(std::vector<std::byte>& b, std::uint64_t v) { put_le(b, v); }
void put_raw(std::vector<std::byte>& b, const void* p, std::size_t n) {
  const auto* s = static_cast<const std::byte*>(p);
  b.insert(b.end(), s, s + n);
}
// String and uint32-length-prefixed Bytes: <uint32 length><bytes>.
void put_str(std::vector<std::byte>& b, std::string_view s) {
  put_u32(b, static_cast<std::uint32_t>(s.size()));
  put_raw(b, s.data(), s.size());
}
// Opens a record: opcode and a length placeholder; returns where the length goes.
std::size_t begin_record(std::vector<std::byte>& b, Op op) {
  put_u8(b, op);
  const std::size_t at = b.size();
  put_u64(b, 0);
  return at;
}
// Patches the record's content length (everything after the 8 length bytes).
void end_record(std::vector<std::byte>& b, std::size_t length_at) {
  const std::uint64_t n = b.size() - length_at - 8;
  for (std::size_t i = 0; i < 8; ++i) b[length_at + i] = static_cast<std::byte>((n >> (8 * i)) & 0xFFu);
}
std::uint32_t checked_u32(std::size_t n, const char* what) {
  if (n > 0xFFFFFFFFu) throw std::invalid_argument(std::string(what) + " longer than 4 GiB");
  return static_cast<std::uint32_t>(n);
}

}  // namespace

std::string_view to_string(Compression c) noexcept {
  switch (c) {
    case Compression::zstd: return "zstd";
    case Compression::lz4: return "lz4";
    case Compression::none: break;
  }
  return "";
}

Compression compression_from_string(std::string_view name) {
  if (name == "zstd") return Compression::zstd;
  if (name == "lz4") return Compression::lz4;
  if (name == "none" || name.empty()) return Compression::none;
  throw std::invalid_argument("MCAP compression '" + std::string(name) + "': expected zstd, lz4 or none");
}

Writer::Writer(std::filesystem::path path, WriterOptions options)
    : path_(std::move(path)), options_(std::move(options)) {
  if (options_.chunk_size == 0)
    throw std::invalid_argument(path_.string() + ": MCAP chunk_size 0: expected a size > 0 bytes");
  if (options_.compression == Compression::zstd &&
      (options_.zstd_level < 1 || options_.zstd_level > ZSTD_maxCLevel()))
    throw std::invalid_argument(path_.string() + ": zstd level " + std::to_string(options_.zstd_level) +
                                ": expected 1 … " + std::to_string(ZSTD_maxCLevel()));
  if (options_.compression == Compression::zstd) {
    zstd_ = ZSTD_createCCtx();
    if (zstd_ == nullptr) throw std::bad_alloc();
  } else if (options_.compression == Compression::lz4) {
    if (LZ4F_isError(LZ4F_createCompressionContext(&lz4_, LZ4F_VERSION)) != 0u) throw std::bad_alloc();
  }
  file_ = std::fopen(path_.c_str(), "wb");
  if (file_ == nullptr) {
    const int err = errno;
    free_codecs();
    throw std::runtime_error(path_.string() + ": cannot create the MCAP file: " + std::strerror(err));
  }
  try {
    put(kMagic.data(), kMagic.size());
    scratch_.clear();
    const std::size_t at = begin_record(scratch_, kHeader);
    put_str(scratch_, options_.profile);
    put_str(scratch_, options_.library);
    end_record(scratch_, at);
    put(scratch_);
    if (std::fflush(file_) != 0) io_error("write");
  } catch (...) {
    std::fclose(file_);
    file_ = nullptr;
    free_codecs();
    throw;
  }
}

Writer::~Writer() {
  if (file_ != nullptr) {
    try {
      close();
    } catch (const std::exception& e) {
      std::fprintf(stderr,
                   "pedalwave::mcap: %s: not closed cleanly (%s); it holds the %u chunk(s) completed "
                   "before: a streaming reader reads them, `mcap recover` rebuilds the index\n",
                   path_.c_str(), e.what(), static_cast<unsigned>(stats_.chunk_count));
    }
  }
  free_codecs();
}

void Writer::free_codecs() noexcept {
  if (zstd_ != nullptr) ZSTD_freeCCtx(zstd_);
  if (lz4_ != nullptr) LZ4F_freeCompressionContext(lz4_);
  zstd_ = nullptr;
  lz4_ = nullptr;
}

void Writer::require_open(const char* what) const {
  if (file_ == nullptr)
    throw std::logic_error(path_.string() + ": MCAP " + what + " after close()");
  if (failed_)
    throw std::logic_error(path_.string() + ": MCAP " + what + " after a write error");
}

void Writer::io_error(const char* what) {
  const int err = errno;
  failed_ = true;
  throw std::runtime_error(path_.string() + ": cannot " + what + " the MCAP file: " + std::strerror(err));
}

void Writer::put(const void* data, std::size_t size) {
  if (size == 0) return;
  if (std::fwrite(data, 1, size, file_) != size) io_error("write");
  if (options_.crc) {
    if (section_ == Section::data) data_crc_.update(data, size);
    else if (section_ == Section::summary) summary_crc_.update(data, size);
  }
  position_ += size;
  stats_.bytes_written = position_;
}

SchemaId Writer::add_schema(std::string_view name, std::string_view encoding, std::string_view data) {
  require_open("add_schema");
  for (const auto& s : schemas_)
    if (s.name == name && s.encoding == encoding && s.data == data) return s.id;
  if (schemas_.size() >= 0xFFFFu)
    throw std::invalid_argument(path_.string() + ": MCAP schema '" + std::string(name) +
                                "': the file already has 65535 schemas");
  const auto id = static_cast<SchemaId>(schemas_.size() + 1);
  schemas_.push_back({id, std::string(name), std::string(encoding), std::string(data)});
  // Into the open chunk, before any message of a channel using it.
  const std::size_t at = begin_record(chunk_, kSchema);
  put_u16(chunk_, id);
  put_str(chunk_, name);
  put_str(chunk_, encoding);
  put_u32(chunk_, checked_u32(data.size(), "schema data"));
  put_raw(chunk_, data.data(), data.size());
  end_record(chunk_, at);
  return id;
}

ChannelId Writer::add_channel(SchemaId schema, std::string_view topic, std::string_view message_encoding,
                              const std::map<std::string, std::string>& metadata) {
  require_open("add_channel");
  if (schema > schemas_.size())
    throw std::invalid_argument(path_.string() + ": MCAP channel '" + std::string(topic) + "': schema id " +
                                std::to_string(schema) + " was not added (expected 0 … " +
                                std::to_string(schemas_.size()) + ")");
  if (topic.empty())
    throw std::invalid_argument(path_.string() + ": MCAP channel with an empty topic: expected a topic name");
  for (const auto& c : channels_)
    if (c.schema_id == schema && c.topic == topic && c.message_encoding == message_encoding &&
        c.metadata == metadata)
      return c.id;
  if (channels_.size() >= 0xFFFFu)
    throw std::invalid_argument(path_.string() + ": MCAP channel '" + std::string(topic) +
                                "': the file already has 65535 channels");
  const auto id = static_cast<ChannelId>(channels_.size() + 1);
  channels_.push_back({id, schema, std::string(topic), std::string(message_encoding), metadata, 0});
  const std::size_t at = begin_record(chunk_, kChannel);
  put_u16(chunk_, id);
  put_u16(chunk_, schema);
  put_str(chunk_, topic);
  put_str(chunk_, message_encoding);
  std::vector<std::byte> map;
  for (const auto& [k, v] : metadata) {
    put_str(map, k);
    put_str(map, v);
  }
  put_u32(chunk_, checked_u32(map.size(), "channel metadata"));
  put_raw(chunk_, map.data(), map.size());
  end_record(chunk_, at);
  return id;
}

ChannelId Writer::add_ros2_channel(std::string_view topic, std::string_view type_name,
                                   std::string_view msg_definition, std::string_view offered_qos_profiles) {
  const SchemaId schema = add_schema(type_name, "ros2msg", msg_definition);
  return add_channel(schema, topic, "cdr", {{"offered_qos_profiles", std::string(offered_qos_profiles)}});
}

void Writer::write(const Message& m) {
  require_open("write");
  if (m.channel == 0 || m.channel > channels_.size())
    throw std::invalid_argument(path_.string() + ": MCAP message on channel id " + std::to_string(m.channel) +
                                ": no such channel (expected 1 … " + std::to_string(channels_.size()) + ")");
  // Message record: channel_id, sequence, log_time, publish_time, data (to the record's end).
  const std::uint64_t offset = chunk_.size();
  put_u8(chunk_, kMessage);
  put_u64(chunk_, 2 + 4 + 8 + 8 + static_cast<std::uint64_t>(m.data.size()));
  put_u16(chunk_, m.channel);
  put_u32(chunk_, m.sequence);
  put_u64(chunk_, m.log_time);
  put_u64(chunk_, m.publish_time);
  put_raw(chunk_, m.data.data(), m.data.size());
  chunk_index_[m.channel].entries.emplace_back(m.log_time, offset);

  // Times and counts of the chunk and of the file.
  if (!chunk_has_messages_) {
    chunk_start_time_ = chunk_end_time_ = m.log_time;
    chunk_has_messages_ = true;
  } else {
    chunk_start_time_ = std::min(chunk_start_time_, m.log_time);
    chunk_end_time_ = std::max(chunk_end_time_, m.log_time);
  }
  if (stats_.message_count == 0) {
    stats_.message_start_time = stats_.message_end_time = m.log_time;
  } else {
    stats_.message_start_time = std::min(stats_.message_start_time, m.log_time);
    stats_.message_end_time = std::max(stats_.message_end_time, m.log_time);
  }
  ++stats_.message_count;
  ++channels_[m.channel - 1].message_count;

  if (chunk_.size() >= options_.chunk_size) close_chunk();
}

void Writer::write(ChannelId channel, Timestamp log_time, std::span<const std::byte> data) {
  require_open("write");
  if (channel == 0 || channel > channels_.size())
    throw std::invalid_argument(path_.string() + ": MCAP message on channel id " + std::to_string(channel) +
                                ": no such channel (expected 1 … " + std::to_string(channels_.size()) + ")");
  const auto sequence = static_cast<std::uint32_t>(channels_[channel - 1].message_count);
  write(Message{channel, sequence, log_time, log_time, data});
}

void Writer::flush() {
  require_open("flush");
  close_chunk();
  if (std::fflush(file_) != 0) io_error("flush");
}

void Writer::close_chunk() {
  if (chunk_.empty()) return;

  // Compress the records (the uncompressed CRC is of what a reader gets back).
  const std::uint32_t crc = options_.crc ? crc32(chunk_) : 0u;
  std::span<const std::byte> records = chunk_;
  if (options_.compression == Compression::zstd) {
    compressed_.resize(ZSTD_compressBound(chunk_.size()));
    const std::size_t n = ZSTD_compressCCtx(zstd_, compressed_.data(), compressed_.size(), chunk_.data(),
                                            chunk_.size(), options_.zstd_level);
    if (ZSTD_isError(n) != 0u)
      throw std::runtime_error(path_.string() + ": zstd compression failed: " + ZSTD_getErrorName(n));
    records = std::span<const std::byte>(compressed_.data(), n);
  } else if (options_.compression == Compression::lz4) {
    LZ4F_preferences_t prefs;
    std::memset(&prefs, 0, sizeof prefs);
    prefs.frameInfo.contentSize = chunk_.size();
    compressed_.resize(LZ4F_compressFrameBound(chunk_.size(), &prefs));
    // One LZ4 frame (header, blocks, end mark) through the writer's context.
    std::size_t n = 0;
    auto step = [&](std::size_t r) {
      if (LZ4F_isError(r) != 0u)
        throw std::runtime_error(path_.string() + ": lz4 compression failed: " + LZ4F_getErrorName(r));
      n += r;
    };
    step(LZ4F_compressBegin(lz4_, compressed_.data(), compressed_.size(), &prefs));
    step(LZ4F_compressUpdate(lz4_, compressed_.data() + n, compressed_.size() - n, chunk_.data(), chunk_.size(),
                             nullptr));
    step(LZ4F_compressEnd(lz4_, compressed_.data() + n, compressed_.size() - n, nullptr));
    records = std::span<const std::byte>(compressed_.data(), n);
  }

  // Chunk record: times, uncompressed size and CRC, compression, uint64-prefixed records.
  ChunkIndexInfo index{};
  index.message_start_time = chunk_has_messages_ ? chunk_start_time_ : 0;
  index.message_end_time = chunk_has_messages_ ? chunk_end_time_ : 0;
  index.chunk_start_offset = position_;
  index.compressed_size = records.size();
  index.uncompressed_size = chunk_.size();
  const std::string_view compression = to_string(options_.compression);
  scratch_.clear();
  put_u8(scratch_, kChunk);
  put_u64(scratch_, 8 + 8 + 8 + 4 + 4 + compression.size() + 8 + records.size());
  put_u64(scratch_, index.message_start_time);
  put_u64(scratch_, index.message_end_time);
  put_u64(scratch_, chunk_.size());
  put_u32(scratch_, crc);
  put_str(scratch_, compression);
  put_u64(scratch_, records.size());
  put(scratch_);
  put(records.data(), records.size());
  index.chunk_length = position_ - index.chunk_start_offset;

  // One Message Index per channel with messages here: (log_time, offset in the records), by time.
  const std::uint64_t indexes_start = position_;
  index.message_index_offsets.reserve(chunk_index_.size());
  for (auto& [channel, ci] : chunk_index_) {
    if (ci.entries.empty()) continue;
    const auto by_time = [](const auto& a, const auto& b) { return a.first < b.first; };
    if (!std::is_sorted(ci.entries.begin(), ci.entries.end(), by_time))  // (stable_sort allocates)
      std::stable_sort(ci.entries.begin(), ci.entries.end(), by_time);
    index.message_index_offsets.emplace_back(channel, position_);
    scratch_.clear();
    const std::size_t at = begin_record(scratch_, kMessageIndex);
    put_u16(scratch_, channel);
    put_u32(scratch_, checked_u32(ci.entries.size() * 16, "message index"));
    for (const auto& [t, off] : ci.entries) {
      put_u64(scratch_, t);
      put_u64(scratch_, off);
    }
    end_record(scratch_, at);
    put(scratch_);
    ci.entries.clear();  // keeps its capacity for the next chunk
  }
  index.message_index_length = position_ - indexes_start;
  if (std::fflush(file_) != 0) io_error("write");

  stats_.uncompressed_bytes += index.uncompressed_size;
  stats_.compressed_bytes += index.compressed_size;
  ++stats_.chunk_count;
  chunk_indexes_.push_back(std::move(index));
  chunk_.clear();
  chunk_has_messages_ = false;
}

void Writer::write_summary_and_footer() {
  // DataEnd closes the data section: its CRC covers every byte before this record.
  const std::uint32_t data_crc = options_.crc ? data_crc_.value() : 0u;
  section_ = Section::none;
  scratch_.clear();
  std::size_t at = begin_record(scratch_, kDataEnd);
  put_u32(scratch_, data_crc);
  end_record(scratch_, at);
  put(scratch_);

  // Summary, grouped by opcode; each group's place is kept for its Summary Offset record.
  section_ = Section::summary;
  const std::uint64_t summary_start = position_;
  std::vector<std::tuple<Op, std::uint64_t, std::uint64_t>> groups;  // opcode, start, length
  auto group = [&](Op op, auto&& write_records) {
    const std::uint64_t start = position_;
    write_records();
    if (position_ > start) groups.emplace_back(op, start, position_ - start);
  };
  group(kSchema, [&] {
    for (const auto& s : schemas_) {
      scratch_.clear();
      at = begin_record(scratch_, kSchema);
      put_u16(scratch_, s.id);
      put_str(scratch_, s.name);
      put_str(scratch_, s.encoding);
      put_str(scratch_, s.data);
      end_record(scratch_, at);
      put(scratch_);
    }
  });
  group(kChannel, [&] {
    for (const auto& c : channels_) {
      scratch_.clear();
      at = begin_record(scratch_, kChannel);
      put_u16(scratch_, c.id);
      put_u16(scratch_, c.schema_id);
      put_str(scratch_, c.topic);
      put_str(scratch_, c.message_encoding);
      std::vector<std::byte> map;
      for (const auto& [k, v] : c.metadata) {
        put_str(map, k);
        put_str(map, v);
      }
      put_u32(scratch_, static_cast<std::uint32_t>(map.size()));
      put_raw(scratch_, map.data(), map.size());
      end_record(scratch_, at);
      put(scratch_);
    }
  });
  group(kChunkIndex, [&] {
    for (const auto& ci : chunk_indexes_) {
      scratch_.clear();
      at = begin_record(scratch_, kChunkIndex);
      put_u64(scratch_, ci.message_start_time);
      put_u64(scratch_, ci.message_end_time);
      put_u64(scratch_, ci.chunk_start_offset);
      put_u64(scratch_, ci.chunk_length);
      put_u32(scratch_, static_cast<std::uint32_t>(ci.message_index_offsets.size() * (2 + 8)));
      for (const auto& [channel, offset] : ci.message_index_offsets) {
        put_u16(scratch_, channel);
        put_u64(scratch_, offset);
      }
      put_u64(scratch_, ci.message_index_length);
      put_str(scratch_, to_string(options_.compression));
      put_u64(scratch_, ci.compressed_size);
      put_u64(scratch_, ci.uncompressed_size);
      end_record(scratch_, at);
      put(scratch_);
    }
  });
  group(kStatistics, [&] {
    scratch_.clear();
    at = begin_record(scratch_, kStatistics);
    put_u64(scratch_, stats_.message_count);
    put_u16(scratch_, static_cast<std::uint16_t>(schemas_.size()));
    put_u32(scratch_, static_cast<std::uint32_t>(channels_.size()));
    put_u32(scratch_, 0);  // attachments
    put_u32(scratch_, 0);  // metadata records
    put_u32(scratch_, stats_.chunk_count);
    put_u64(scratch_, stats_.message_start_time);
    put_u64(scratch_, stats_.message_end_time);
    put_u32(scratch_, static_cast<std::uint32_t>(channels_.size() * (2 + 8)));
    for (const auto& c : channels_) {
      put_u16(scratch_, c.id);
      put_u64(scratch_, c.message_count);
    }
    end_record(scratch_, at);
    put(scratch_);
  });

  // Summary Offset section: where each group starts and how long it is.
  const std::uint64_t summary_offset_start = position_;
  for (const auto& [op, start, length] : groups) {
    scratch_.clear();
    at = begin_record(scratch_, kSummaryOffset);
    put_u8(scratch_, op);
    put_u64(scratch_, start);
    put_u64(scratch_, length);
    end_record(scratch_, at);
    put(scratch_);
  }

  // Footer: its opcode, length and two offsets are the last bytes the summary CRC covers.
  scratch_.clear();
  put_u8(scratch_, kFooter);
  put_u64(scratch_, 8 + 8 + 4);
  put_u64(scratch_, summary_start);
  put_u64(scratch_, summary_offset_start);
  put(scratch_);
  section_ = Section::none;
  scratch_.clear();
  put_u32(scratch_, options_.crc ? summary_crc_.value() : 0u);
  put(scratch_);
  put(kMagic.data(), kMagic.size());
}

void Writer::close() {
  if (file_ == nullptr) return;
  if (failed_) {
    std::fclose(file_);
    file_ = nullptr;
    throw std::runtime_error(path_.string() +
                             ": MCAP file closed after a write error: it holds the chunks completed before");
  }
  try {
    close_chunk();
    write_summary_and_footer();
    if (std::fflush(file_) != 0) io_error("write");
    std::FILE* f = file_;
    file_ = nullptr;
    if (std::fclose(f) != 0) {
      failed_ = true;
      throw std::runtime_error(path_.string() + ": cannot close the MCAP file: " + std::strerror(errno));
    }
  } catch (...) {
    if (file_ != nullptr) {
      std::fclose(file_);
      file_ = nullptr;
    }
    throw;
  }
}

}  // namespace pedalwave::mcap
