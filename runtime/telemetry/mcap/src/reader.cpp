#include "pedalwave/mcap/reader.hpp"

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>

#include "pedalwave/mcap/crc32.hpp"
#include "records.hpp"

namespace pedalwave::mcap {
namespace {

using namespace detail;  // the opcodes and the magic (records.hpp)
constexpr std::string_view kMagicText =
    "the MCAP magic 89 4d 43 41 50 30 0d 0a (\"\\x89MCAP0\\r\\n\")";

const char* op_name(std::uint8_t op) {
  switch (op) {
    case kHeader: return "Header";
    case kFooter: return "Footer";
    case kSchema: return "Schema";
    case kChannel: return "Channel";
    case kMessage: return "Message";
    case kChunk: return "Chunk";
    case kMessageIndex: return "MessageIndex";
    case kChunkIndex: return "ChunkIndex";
    case kAttachment: return "Attachment";
    case kAttachmentIndex: return "AttachmentIndex";
    case kStatistics: return "Statistics";
    case kMetadata: return "Metadata";
    case kMetadataIndex: return "MetadataIndex";
    case kSummaryOffset: return "SummaryOffset";
    case kDataEnd: return "DataEnd";
    default: return "unknown";
  }
}

std::string hex32(std::uint32_t v) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%08x", v);
  return b;
}

// Where a problem is: the file, the byte, and inside a chunk the chunk's place and the offset in
// its uncompressed records.
struct Place {
  const std::string* file;
  std::uint64_t chunk_at = 0;  // file offset of the Chunk record (0: not in a chunk)
  bool in_chunk = false;

  [[noreturn]] void fail(std::uint64_t at, const std::string& what) const {
    if (in_chunk)
      throw ReadError(*file + ": byte " + std::to_string(chunk_at) + " (the Chunk there, uncompressed offset " +
                          std::to_string(at) + "): " + what,
                      chunk_at);
    throw ReadError(*file + ": byte " + std::to_string(at) + ": " + what, at);
  }
};

// Little-endian fields of one record's body, bounds-checked against the record.
class Fields {
 public:
  Fields(std::span<const std::byte> body, std::uint64_t body_at, const Place& place, const char* record)
      : s_(body), at_(body_at), place_(place), record_(record) {}

  template <class U>
  U le(const char* field) {
    need(sizeof(U), field);
    U v = 0;
    for (std::size_t i = 0; i < sizeof(U); ++i)
      v = static_cast<U>(v | static_cast<U>(static_cast<U>(std::to_integer<unsigned>(s_[pos_ + i])) << (8 * i)));
    pos_ += sizeof(U);
    return v;
  }
  std::uint8_t u8(const char* f) { return le<std::uint8_t>(f); }
  std::uint16_t u16(const char* f) { return le<std::uint16_t>(f); }
  std::uint32_t u32(const char* f) { return le<std::uint32_t>(f); }
  std::uint64_t u64(const char* f) { return le<std::uint64_t>(f); }
  std::span<const std::byte> bytes(std::uint64_t n, const char* field) {
    need(n, field);
    auto r = s_.subspan(pos_, static_cast<std::size_t>(n));
    pos_ += static_cast<std::size_t>(n);
    return r;
  }
  std::string str(const char* field) {
    const std::uint32_t n = u32(field);
    const auto b = bytes(n, field);
    return std::string(reinterpret_cast<const char*>(b.data()), b.size());
  }
  std::map<std::string, std::string> string_map(const char* field) {
    const std::uint32_t n = u32(field);
    Fields m(bytes(n, field), at_ + pos_ - n, place_, record_);
    std::map<std::string, std::string> out;
    while (!m.done()) {
      std::string k = m.str(field);
      out[std::move(k)] = m.str(field);
    }
    return out;
  }
  std::span<const std::byte> rest() { return s_.subspan(pos_); }
  [[nodiscard]] bool done() const { return pos_ == s_.size(); }
  [[nodiscard]] std::uint64_t at() const { return at_ + pos_; }

 private:
  void need(std::uint64_t n, const char* field) const {
    if (n > s_.size() - pos_)
      place_.fail(at_ + pos_, std::string(record_) + " record field " + field + " needs " + std::to_string(n) +
                                  " bytes, the record has " + std::to_string(s_.size() - pos_) +
                                  " left: expected a record as long as its fields (a corrupt length?)");
  }
  std::span<const std::byte> s_;
  std::uint64_t at_;
  std::size_t pos_ = 0;
  const Place& place_;
  const char* record_;
};

// One record: opcode, where it starts and its body.
struct RecordView {
  std::uint8_t op = 0;
  std::uint64_t at = 0;  // opcode's offset
  std::span<const std::byte> body;
  std::uint64_t body_at = 0;
};

// Reads the record at `pos` of `s` (offsets relative to `s`; `what_end` names where s ends).
RecordView next_record(std::span<const std::byte> s, std::uint64_t pos, const Place& place, const char* what_end) {
  const std::uint64_t left = s.size() - pos;
  if (left < 9)
    place.fail(pos, std::string("record truncated: ") + std::to_string(left) + " byte(s) before " + what_end +
                        ": expected an opcode and an 8-byte length (9 bytes)");
  RecordView r;
  r.op = std::to_integer<std::uint8_t>(s[pos]);
  r.at = pos;
  std::uint64_t len = 0;
  for (std::size_t i = 0; i < 8; ++i) len |= static_cast<std::uint64_t>(std::to_integer<unsigned>(s[pos + 1 + i])) << (8 * i);
  if (len > left - 9)
    place.fail(pos, std::string(op_name(r.op)) + " record (opcode 0x" + hex32(r.op).substr(8) + ") truncated: its length says " +
                        std::to_string(len) + " bytes, " + what_end + " is " + std::to_string(left - 9) +
                        " bytes after its length field");
  r.body_at = pos + 9;
  r.body = s.subspan(static_cast<std::size_t>(pos + 9), static_cast<std::size_t>(len));
  return r;
}

}  // namespace

struct Reader::Sink {
  // Messages wanted: by channel id (empty: all). Collected in file order.
  std::vector<ChannelId> wanted;
  std::vector<ReadMessage> out;
  bool want(ChannelId c) const {
    return wanted.empty() || std::find(wanted.begin(), wanted.end(), c) != wanted.end();
  }
};

namespace {

// The parser's state for one pass over the file.
class Pass {
 public:
  Pass(const std::string& name, std::span<const std::byte> file, const ReaderOptions& o,
       std::map<SchemaId, SchemaRecord>& schemas, std::map<ChannelId, ChannelRecord>& channels)
      : name_(name), file_(file), o_(o), schemas_(schemas), channels_(channels) {}

  std::string profile, library;
  std::uint64_t messages = 0;
  std::uint32_t chunks = 0;
  bool summary = false;
  bool unfinished = false;  // ended early, read up to there (ReaderOptions::allow_unfinished)
  std::function<void(const ReadMessage&, std::span<const std::byte>)> on_message;  // data separately

  void run() {
    const Place top{&name_};
    if (file_.size() < kMagic.size() ||
        std::memcmp(file_.data(), kMagic.data(), kMagic.size()) != 0) {
      if (file_.size() < kMagic.size())
        top.fail(0, "file of " + std::to_string(file_.size()) + " bytes: expected at least " + std::string(kMagicText));
      top.fail(0, "bad magic: expected " + std::string(kMagicText));
    }
    std::uint64_t pos = kMagic.size();
    bool first = true;
    bool data_end = false;
    std::uint64_t summary_start = 0;
    for (;;) {
      if (pos == file_.size()) {
        if (o_.allow_unfinished && !first) {
          unfinished = true;
          return;
        }
        top.fail(pos, "the file ends without a Footer record and the closing magic (an unfinished "
                      "recording? `mcap recover` rewrites one): expected a Footer");
      }
      if (o_.allow_unfinished && !first && !record_fits(pos)) {  // cut inside its last record
        unfinished = true;
        return;
      }
      const RecordView r = next_record(file_, pos, top, "the end of the file");
      if (first && r.op != kHeader)
        top.fail(r.at, std::string(op_name(r.op)) + " record first: expected the Header record (opcode 0x01)");
      first = false;
      Fields f(r.body, r.body_at, top, op_name(r.op));
      switch (r.op) {
        case kHeader:
          if (r.at != kMagic.size()) top.fail(r.at, "a second Header record: expected one, after the magic");
          profile = f.str("profile");
          library = f.str("library");
          break;
        case kFooter: {
          const std::uint64_t s_start = f.u64("summary_start");
          (void)f.u64("summary_offset_start");
          const std::uint32_t crc = f.u32("summary_crc");
          if (s_start != 0 && s_start != summary_start && summary_start != 0)
            top.fail(r.body_at, "Footer summary_start " + std::to_string(s_start) + ": expected " +
                                    std::to_string(summary_start) + " (where the summary begins)");
          if (s_start != 0) summary = true;
          if (o_.check_crcs && crc != 0 && s_start != 0) {
            if (s_start > r.at) top.fail(r.body_at, "Footer summary_start " + std::to_string(s_start) + " beyond the Footer");
            // From the first summary record through the Footer's summary_offset_start field.
            const auto covered = file_.subspan(static_cast<std::size_t>(s_start),
                                               static_cast<std::size_t>(r.body_at + 16 - s_start));
            const std::uint32_t got = crc32(covered);
            if (got != crc)
              top.fail(r.body_at + 16, "summary CRC mismatch: the summary section has CRC " + hex32(got) +
                                           ", the Footer says " + hex32(crc));
          }
          const std::uint64_t end = r.body_at + r.body.size();
          if (o_.allow_unfinished && file_.size() - end < kMagic.size() &&
              std::memcmp(file_.data() + end, kMagic.data(), static_cast<std::size_t>(file_.size() - end)) == 0) {
            unfinished = true;  // cut inside the closing magic
            return;
          }
          if (file_.size() - end < kMagic.size())
            top.fail(end, "the file ends " + std::to_string(file_.size() - end) +
                              " byte(s) after the Footer: expected " + std::string(kMagicText));
          if (std::memcmp(file_.data() + end, kMagic.data(), kMagic.size()) != 0)
            top.fail(end, "bad closing magic after the Footer: expected " + std::string(kMagicText));
          if (file_.size() != end + kMagic.size())
            top.fail(end + kMagic.size(), std::to_string(file_.size() - end - kMagic.size()) +
                                              " byte(s) after the closing magic: expected the end of the file");
          return;
        }
        case kSchema: schema(f, top); break;
        case kChannel: channel(f, top); break;
        case kMessage:
          if (data_end) top.fail(r.at, "Message record after DataEnd: expected messages in the data section");
          message(f, top, r.at);
          break;
        case kChunk:
          if (data_end) top.fail(r.at, "Chunk record after DataEnd: expected chunks in the data section");
          chunk(f, r);
          break;
        case kDataEnd: {
          const std::uint32_t crc = f.u32("data_section_crc");
          if (o_.check_crcs && crc != 0) {
            const std::uint32_t got = crc32(file_.subspan(0, static_cast<std::size_t>(r.at)));
            if (got != crc)
              top.fail(r.body_at, "data section CRC mismatch: bytes 0 … " + std::to_string(r.at) + " have CRC " +
                                      hex32(got) + ", DataEnd says " + hex32(crc));
          }
          data_end = true;
          summary_start = r.at + r.body.size() + 9;
          break;
        }
        default:  // index, statistics, attachment, metadata, summary offset, unknown: skipped
          break;
      }
      pos = r.body_at + r.body.size();
    }
  }

 private:
  // Whether a whole record starts at `pos` (its opcode, length and body inside the file).
  [[nodiscard]] bool record_fits(std::uint64_t pos) const {
    const std::uint64_t left = file_.size() - pos;
    if (left < 9) return false;
    std::uint64_t len = 0;
    for (std::size_t i = 0; i < 8; ++i)
      len |= static_cast<std::uint64_t>(std::to_integer<unsigned>(file_[static_cast<std::size_t>(pos + 1 + i)])) << (8 * i);
    return len <= left - 9;
  }

  void schema(Fields& f, const Place& place) {
    const std::uint64_t at = f.at();
    SchemaRecord s;
    s.id = f.u16("id");
    s.name = f.str("name");
    s.encoding = f.str("encoding");
    const std::uint32_t n = f.u32("data");
    const auto d = f.bytes(n, "data");
    s.data.assign(reinterpret_cast<const char*>(d.data()), d.size());
    if (s.id == 0) place.fail(at, "Schema \"" + s.name + "\" with id 0: expected an id 1 … 65535 (0 means none)");
    const auto it = schemas_.find(s.id);
    if (it == schemas_.end()) {
      schemas_.emplace(s.id, std::move(s));
    } else if (it->second.name != s.name || it->second.encoding != s.encoding || it->second.data != s.data) {
      place.fail(at, "Schema id " + std::to_string(s.id) + " (\"" + s.name + "\") differs from the Schema record "
                     "with that id before it (\"" + it->second.name + "\"): expected one definition per id");
    }
  }

  void channel(Fields& f, const Place& place) {
    const std::uint64_t at = f.at();
    ChannelRecord c;
    c.id = f.u16("id");
    c.schema_id = f.u16("schema_id");
    c.topic = f.str("topic");
    c.message_encoding = f.str("message_encoding");
    c.metadata = f.string_map("metadata");
    if (c.schema_id != 0 && schemas_.count(c.schema_id) == 0)
      place.fail(at, "Channel " + std::to_string(c.id) + " (\"" + c.topic + "\") refers to schema " +
                         std::to_string(c.schema_id) + ": no such Schema record before it (missing schema)");
    const auto it = channels_.find(c.id);
    if (it == channels_.end()) {
      channels_.emplace(c.id, std::move(c));
    } else if (it->second.topic != c.topic || it->second.schema_id != c.schema_id ||
               it->second.message_encoding != c.message_encoding || it->second.metadata != c.metadata) {
      place.fail(at, "Channel id " + std::to_string(c.id) + " (\"" + c.topic + "\") differs from the Channel record "
                     "with that id before it (\"" + it->second.topic + "\"): expected one definition per id");
    }
  }

  void message(Fields& f, const Place& place, std::uint64_t record_at) {
    const std::uint64_t at = f.at();
    ReadMessage m;
    m.channel = f.u16("channel_id");
    m.sequence = f.u32("sequence");
    m.log_time = f.u64("log_time");
    m.publish_time = f.u64("publish_time");
    if (channels_.count(m.channel) == 0)
      place.fail(at, "Message on channel " + std::to_string(m.channel) +
                         ": no such Channel record before it (expected its Channel record first)");
    m.offset = place.in_chunk ? place.chunk_at : record_at;
    ++messages;
    if (on_message) on_message(m, f.rest());
  }

  void chunk(Fields& f, const RecordView& r) {
    const Place top{&name_};
    (void)f.u64("message_start_time");
    (void)f.u64("message_end_time");
    const std::uint64_t size = f.u64("uncompressed_size");
    const std::uint32_t crc = f.u32("uncompressed_crc");
    const std::string compression = f.str("compression");
    const std::uint64_t n = f.u64("records");
    const std::uint64_t records_at = f.at();
    const auto stored = f.bytes(n, "records");
    ++chunks;
    if (size > o_.max_chunk_size)
      top.fail(r.body_at + 16, "Chunk uncompressed_size " + std::to_string(size) + ": expected at most " +
                                   std::to_string(o_.max_chunk_size) + " bytes (ReaderOptions::max_chunk_size)");
    std::span<const std::byte> records;
    if (compression.empty()) {
      if (n != size)
        top.fail(r.body_at + 16, "uncompressed Chunk of " + std::to_string(n) + " bytes says uncompressed_size " +
                                     std::to_string(size) + ": expected the two equal");
      records = stored;
    } else if (compression == "zstd") {
      // The frame's own content size, when it states one, must agree before anything is allocated.
      const unsigned long long declared = ZSTD_getFrameContentSize(stored.data(), stored.size());
      if (declared == ZSTD_CONTENTSIZE_ERROR)
        top.fail(records_at, "zstd Chunk: no zstd frame header: expected a zstd frame of " + std::to_string(size) + " bytes");
      if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != size)
        top.fail(records_at, "zstd Chunk's frame holds " + std::to_string(declared) + " bytes: expected uncompressed_size " +
                                 std::to_string(size));
      buf_.resize(static_cast<std::size_t>(size));
      const std::size_t got = ZSTD_decompress(buf_.data(), buf_.size(), stored.data(), stored.size());
      if (ZSTD_isError(got) != 0u)
        top.fail(records_at, std::string("zstd Chunk does not decompress: ") + ZSTD_getErrorName(got) +
                                 ": expected a zstd frame of " + std::to_string(size) + " bytes");
      if (got != size)
        top.fail(records_at, "zstd Chunk decompresses to " + std::to_string(got) + " bytes: expected uncompressed_size " +
                                 std::to_string(size));
      records = buf_;
    } else if (compression == "lz4") {
      LZ4F_dctx* d = nullptr;
      if (LZ4F_isError(LZ4F_createDecompressionContext(&d, LZ4F_VERSION)) != 0u) throw std::bad_alloc();
      const std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> guard(d, LZ4F_freeDecompressionContext);
      std::size_t in_pos = 0, out_pos = 0, ret = 1;
      {  // The frame's content size, when it states one, must agree before anything is allocated.
        LZ4F_frameInfo_t info{};
        std::size_t in_n = stored.size();
        ret = LZ4F_getFrameInfo(d, &info, stored.data(), &in_n);
        if (LZ4F_isError(ret) != 0u)
          top.fail(records_at, std::string("lz4 Chunk: no LZ4 frame header: ") + LZ4F_getErrorName(ret) +
                                   ": expected an LZ4 frame of " + std::to_string(size) + " bytes");
        if (info.contentSize != 0 && info.contentSize != size)
          top.fail(records_at, "lz4 Chunk's frame holds " + std::to_string(info.contentSize) +
                                   " bytes: expected uncompressed_size " + std::to_string(size));
        in_pos = in_n;
        if (ret == 0) ret = 1;
      }
      buf_.resize(static_cast<std::size_t>(size));
      while (ret != 0 && in_pos < stored.size()) {
        std::size_t in_n = stored.size() - in_pos, out_n = buf_.size() - out_pos;
        ret = LZ4F_decompress(d, buf_.data() + out_pos, &out_n, stored.data() + in_pos, &in_n, nullptr);
        if (LZ4F_isError(ret) != 0u)
          top.fail(records_at + in_pos, std::string("lz4 Chunk does not decompress: ") + LZ4F_getErrorName(ret) +
                                            ": expected an LZ4 frame of " + std::to_string(size) + " bytes");
        in_pos += in_n;
        out_pos += out_n;
        if (in_n == 0 && out_n == 0) break;  // no progress: output full or input ended
      }
      if (ret != 0)
        top.fail(records_at + in_pos, "lz4 Chunk ends inside its frame (" + std::to_string(out_pos) +
                                          " bytes decompressed): expected a complete LZ4 frame of " +
                                          std::to_string(size) + " bytes");
      if (out_pos != size)
        top.fail(records_at, "lz4 Chunk decompresses to " + std::to_string(out_pos) +
                                 " bytes: expected uncompressed_size " + std::to_string(size));
      records = buf_;
    } else {
      top.fail(r.body_at + 28, "Chunk compression \"" + compression + "\": expected \"zstd\", \"lz4\" or \"\" (none)");
    }
    if (o_.check_crcs && crc != 0) {
      const std::uint32_t got = crc32(records);
      if (got != crc)
        top.fail(r.at, "Chunk CRC mismatch: the records decompress to CRC " + hex32(got) + ", the chunk says " + hex32(crc));
    }
    const Place in{&name_, r.at, true};
    std::uint64_t pos = 0;
    while (pos < records.size()) {
      const RecordView c = next_record(records, pos, in, "the chunk's end");
      Fields cf(c.body, c.body_at, in, op_name(c.op));
      switch (c.op) {
        case kSchema: schema(cf, in); break;
        case kChannel: channel(cf, in); break;
        case kMessage: message(cf, in, c.at); break;
        default:
          if (c.op == kHeader || c.op == kFooter || c.op == kChunk || c.op == kDataEnd)
            in.fail(c.at, std::string(op_name(c.op)) + " record inside a Chunk: expected Schema, Channel or Message records");
          break;
      }
      pos = c.body_at + c.body.size();
    }
  }

  const std::string& name_;
  std::span<const std::byte> file_;
  const ReaderOptions& o_;
  std::map<SchemaId, SchemaRecord>& schemas_;
  std::map<ChannelId, ChannelRecord>& channels_;
  std::vector<std::byte> buf_;  // one decompressed chunk
};

std::vector<std::byte> read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ReadError(path.string() + ": cannot open the MCAP file: " + std::strerror(errno), 0);
  in.seekg(0, std::ios::end);
  const std::streamoff n = in.tellg();
  in.seekg(0, std::ios::beg);
  if (n < 0) throw ReadError(path.string() + ": cannot read the MCAP file (not a regular file?)", 0);
  std::vector<std::byte> b(static_cast<std::size_t>(n));
  if (n > 0 && !in.read(reinterpret_cast<char*>(b.data()), n))
    throw ReadError(path.string() + ": cannot read the MCAP file: " + std::strerror(errno), 0);
  return b;
}

}  // namespace

Reader::Reader(std::filesystem::path path, ReaderOptions options)
    : Reader(read_file(path), path.string(), options) {}

Reader::Reader(std::vector<std::byte> bytes, std::string name, ReaderOptions options)
    : name_(std::move(name)), bytes_(std::move(bytes)), options_(options) {
  scan_checked();
}

void Reader::scan_checked() {
  Pass p(name_, bytes_, options_, schemas_, channels_);
  p.run();
  profile_ = p.profile;
  library_ = p.library;
  message_count_ = p.messages;
  chunk_count_ = p.chunks;
  has_summary_ = p.summary;
  complete_ = !p.unfinished;
}

void Reader::scan(Sink* sink) const {
  // A second pass over a file the constructor checked: CRCs already verified.
  ReaderOptions o = options_;
  o.check_crcs = false;
  std::map<SchemaId, SchemaRecord> schemas;
  std::map<ChannelId, ChannelRecord> channels;
  Pass p(name_, bytes_, o, schemas, channels);
  p.on_message = [sink](const ReadMessage& m, std::span<const std::byte> data) {
    if (!sink->want(m.channel)) return;
    ReadMessage c = m;
    c.data.assign(data.begin(), data.end());
    sink->out.push_back(std::move(c));
  };
  p.run();
}

const ChannelRecord* Reader::channel(std::string_view topic) const {
  for (const auto& [id, c] : channels_)
    if (c.topic == topic) return &c;
  return nullptr;
}

const SchemaRecord* Reader::schema_of(const ChannelRecord& c) const {
  const auto it = schemas_.find(c.schema_id);
  return it == schemas_.end() ? nullptr : &it->second;
}

std::vector<ReadMessage> Reader::messages(std::span<const ChannelId> channels) const {
  Sink sink;
  sink.wanted.assign(channels.begin(), channels.end());
  scan(&sink);
  std::stable_sort(sink.out.begin(), sink.out.end(),
                   [](const ReadMessage& a, const ReadMessage& b) { return a.log_time < b.log_time; });
  return std::move(sink.out);
}

std::vector<ReadMessage> Reader::messages_on(std::span<const std::string> topics) const {
  std::vector<ChannelId> ids;
  for (const std::string& t : topics) {
    bool found = false;
    for (const auto& [id, c] : channels_)
      if (c.topic == t) {
        ids.push_back(id);
        found = true;
      }
    if (!found)
      throw ReadError(name_ + ": no channel on topic \"" + t + "\": the file has " + topics_text(), 0);
  }
  return messages(ids);
}

std::string Reader::topics_text() const {
  if (channels_.empty()) return "no channels";
  std::string s;
  for (const auto& [id, c] : channels_) {
    if (!s.empty()) s += ", ";
    s += c.topic;
    if (const SchemaRecord* sc = schema_of(c)) s += " (" + sc->name + ")";
  }
  return s;
}

bool has_mcap_magic(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::array<char, 8> b{};
  if (!in.read(b.data(), b.size())) return false;
  return std::memcmp(b.data(), kMagic.data(), kMagic.size()) == 0;
}

}  // namespace pedalwave::mcap
