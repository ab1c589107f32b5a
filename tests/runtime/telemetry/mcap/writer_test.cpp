// The MCAP writer against the specification: record layouts, offsets, indexes, CRCs, chunking,
// compression, the summary; what a crash leaves; errors. Files are read back with the independent
// record reader of mcap_test_reader.hpp (tests/runtime/telemetry/mcap/interop/ reads them with @mcap/core too).
#include <gtest/gtest.h>

#include <sys/resource.h>
#include <unistd.h>

#include <csignal>

#include <algorithm>
#include <filesystem>
#include <map>
#include <numeric>
#include <set>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "mcap_test_reader.hpp"
#include "pedalwave/mcap/crc32.hpp"
#include "pedalwave/mcap/writer.hpp"

namespace fs = std::filesystem;
using namespace pedalwave::mcap;
using namespace pedalwave::mcap::test;

namespace {

fs::path temp_dir() { return fs::temp_directory_path() / ("pedalwave_mcap_test_" + std::to_string(::getpid())); }

fs::path temp_file(const std::string& name) {
  fs::create_directories(temp_dir());
  return temp_dir() / name;
}

// The files of this process's tests are removed when it ends.
class RemoveTempFiles : public ::testing::Environment {
 public:
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(temp_dir(), ec);
  }
};
[[maybe_unused]] const auto* const kRemoveTempFiles = ::testing::AddGlobalTestEnvironment(new RemoveTempFiles);

std::vector<std::byte> payload(std::size_t n, unsigned seed) {
  std::vector<std::byte> b(n);
  for (std::size_t i = 0; i < n; ++i) b[i] = static_cast<std::byte>((seed * 31u + i * 7u) & 0xFFu);
  return b;
}

struct SchemaRec {
  std::uint16_t id;
  std::string name, encoding, data;
};
struct ChannelRec {
  std::uint16_t id, schema_id;
  std::string topic, encoding;
  std::map<std::string, std::string> metadata;
};

// Everything a full structural check of a finished file found.
struct FileView {
  std::string profile, library;
  std::vector<MessageRec> messages;           // in file order
  std::vector<Chunk> chunks;
  std::map<std::uint16_t, SchemaRec> data_schemas, summary_schemas;
  std::map<std::uint16_t, ChannelRec> data_channels, summary_channels;
  std::uint64_t stats_message_count = 0, stats_start = 0, stats_end = 0;
  std::uint32_t stats_chunk_count = 0, stats_channel_count = 0;
  std::uint16_t stats_schema_count = 0;
  std::map<std::uint16_t, std::uint64_t> stats_channel_counts;
  std::uint32_t data_crc = 0, summary_crc = 0;
};

SchemaRec decode_schema(std::span<const std::byte> body) {
  Cursor c(body);
  SchemaRec s;
  s.id = c.u16();
  s.name = c.str();
  s.encoding = c.str();
  s.data = c.str();
  EXPECT_TRUE(c.done());
  return s;
}
ChannelRec decode_channel(std::span<const std::byte> body) {
  Cursor c(body);
  ChannelRec ch;
  ch.id = c.u16();
  ch.schema_id = c.u16();
  ch.topic = c.str();
  ch.encoding = c.str();
  ch.metadata = c.string_map();
  EXPECT_TRUE(c.done());
  return ch;
}

// Records of the data section before DataEnd, checked: chunks (CRC, inner records) each followed by
// its message indexes, whose entries point at the messages. Returns the offset of DataEnd (or the
// end of what was parsed when there is none).
std::size_t check_data_section(std::span<const std::byte> file, std::size_t begin, std::size_t end,
                               FileView& v, bool expect_data_end) {
  const Records recs = split_records(file, begin, end);
  if (!expect_data_end) {
    EXPECT_TRUE(recs.complete) << "a record is cut off";
  }
  std::size_t i = 0;
  while (i < recs.list.size() && recs.list[i].op == 0x06) {
    const Chunk k = decode_chunk(recs.list[i].body);
    EXPECT_EQ(k.uncompressed_crc, crc32(k.records)) << "chunk at " << recs.list[i].offset;
    // Inner records: Schema, Channel, Message only; messages on known channels.
    const Records inner = split_records(k.records, 0, k.records.size());
    EXPECT_TRUE(inner.complete);
    std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> expected_index;
    std::uint64_t tmin = UINT64_MAX, tmax = 0;
    for (const auto& r : inner.list) {
      if (r.op == 0x03) {
        const auto s = decode_schema(r.body);
        v.data_schemas[s.id] = s;
      } else if (r.op == 0x04) {
        const auto ch = decode_channel(r.body);
        EXPECT_TRUE(ch.schema_id == 0 || v.data_schemas.count(ch.schema_id)) << "channel before its schema";
        v.data_channels[ch.id] = ch;
      } else if (r.op == 0x05) {
        auto m = decode_message(r.body);
        EXPECT_TRUE(v.data_channels.count(m.channel)) << "message before its channel";
        expected_index[m.channel].emplace_back(m.log_time, r.offset);
        tmin = std::min(tmin, m.log_time);
        tmax = std::max(tmax, m.log_time);
        v.messages.push_back(std::move(m));
      } else {
        ADD_FAILURE() << "record op " << int(r.op) << " inside a chunk";
      }
    }
    if (expected_index.empty()) {
      EXPECT_EQ(k.start_time, 0u);
      EXPECT_EQ(k.end_time, 0u);
    } else {
      EXPECT_EQ(k.start_time, tmin);
      EXPECT_EQ(k.end_time, tmax);
    }
    ++i;
    // The message indexes right after: one per channel with messages, entries by time.
    std::set<std::uint16_t> seen;
    while (i < recs.list.size() && recs.list[i].op == 0x07) {
      Cursor c(recs.list[i].body);
      const auto channel = c.u16();
      const auto n = c.u32();
      EXPECT_EQ(n % 16, 0u);
      std::vector<std::pair<std::uint64_t, std::uint64_t>> entries;
      for (std::uint32_t e = 0; e < n / 16; ++e) {
        const auto t = c.u64();
        entries.emplace_back(t, c.u64());
      }
      EXPECT_TRUE(c.done());
      EXPECT_TRUE(std::is_sorted(entries.begin(), entries.end(),
                                 [](auto& a, auto& b) { return a.first < b.first; }));
      auto want = expected_index[channel];
      std::stable_sort(want.begin(), want.end(), [](auto& a, auto& b) { return a.first < b.first; });
      EXPECT_EQ(entries, want) << "message index of channel " << channel;
      EXPECT_TRUE(seen.insert(channel).second) << "two indexes for channel " << channel;
      ++i;
    }
    EXPECT_EQ(seen.size(), expected_index.size());
    v.chunks.push_back(k);
  }
  if (!expect_data_end) {
    EXPECT_EQ(i, recs.list.size()) << "unexpected record op " << int(recs.list[i].op);
    return recs.list.empty() ? begin : recs.list.back().offset + recs.list.back().size;
  }
  if (i >= recs.list.size() || recs.list[i].op != 0x0F) {
    ADD_FAILURE() << "no DataEnd after the chunks";
    return end;
  }
  return recs.list[i].offset;
}

// The full check of a finished file (see FileView).
FileView check_file(const fs::path& path) {
  FileView v;
  const auto bytes = read_bytes(path.string());
  const std::span<const std::byte> file(bytes);
  EXPECT_GE(file.size(), 8u + 9u + 29u + 8u);
  // Magic at both ends.
  EXPECT_TRUE(std::equal(kMagicBytes.begin(), kMagicBytes.end(), file.begin()));
  EXPECT_TRUE(std::equal(kMagicBytes.begin(), kMagicBytes.end(), file.end() - 8));
  // Footer: the fixed 29 bytes before the trailing magic.
  const std::size_t footer_at = file.size() - 8 - 29;
  Cursor f(file.subspan(footer_at, 29));
  EXPECT_EQ(f.u8(), 0x02);
  EXPECT_EQ(f.u64(), 20u);
  const auto summary_start = f.u64();
  const auto summary_offset_start = f.u64();
  v.summary_crc = f.u32();
  // Header first.
  const Records head = split_records(file, 8, file.size());
  Cursor h(head.list.at(0).body);
  EXPECT_EQ(head.list.at(0).op, 0x01);
  v.profile = h.str();
  v.library = h.str();
  // Data section up to DataEnd, which comes right before the summary.
  const std::size_t data_end_at =
      check_data_section(file, 8 + head.list[0].size, summary_start, v, /*expect_data_end=*/true);
  {
    const Records de = split_records(file, data_end_at, summary_start);
    EXPECT_EQ(de.list.size(), 1u);
    Cursor c(de.list.at(0).body);
    v.data_crc = c.u32();
    EXPECT_TRUE(c.done());
    EXPECT_EQ(v.data_crc, crc32(file.subspan(0, data_end_at))) << "data section CRC";
  }
  // Summary CRC: first summary record through the footer's summary_offset_start.
  EXPECT_EQ(v.summary_crc, crc32(file.subspan(summary_start, footer_at + 1 + 8 + 8 + 8 - summary_start)));
  // Summary records grouped by opcode; the summary offsets point at exactly those groups.
  const Records summary = split_records(file, summary_start, summary_offset_start);
  EXPECT_TRUE(summary.complete);
  std::vector<std::tuple<std::uint8_t, std::uint64_t, std::uint64_t>> groups;
  for (const auto& r : summary.list) {
    if (groups.empty() || std::get<0>(groups.back()) != r.op) groups.emplace_back(r.op, r.offset, 0);
    std::get<2>(groups.back()) += r.size;
  }
  std::set<std::uint8_t> ops;
  for (const auto& g : groups) EXPECT_TRUE(ops.insert(std::get<0>(g)).second) << "summary not grouped";
  const Records offsets = split_records(file, summary_offset_start, footer_at);
  EXPECT_TRUE(offsets.complete);
  EXPECT_EQ(offsets.list.size(), groups.size());
  for (std::size_t g = 0; g < std::min(groups.size(), offsets.list.size()); ++g) {
    Cursor c(offsets.list[g].body);
    EXPECT_EQ(offsets.list[g].op, 0x0E);
    EXPECT_EQ(c.u8(), std::get<0>(groups[g]));
    EXPECT_EQ(c.u64(), std::get<1>(groups[g]));
    EXPECT_EQ(c.u64(), std::get<2>(groups[g]));
  }
  // Each summary record.
  std::size_t chunk_no = 0;
  for (const auto& r : summary.list) {
    if (r.op == 0x03) {
      const auto s = decode_schema(r.body);
      v.summary_schemas[s.id] = s;
    } else if (r.op == 0x04) {
      const auto ch = decode_channel(r.body);
      v.summary_channels[ch.id] = ch;
    } else if (r.op == 0x08) {
      // Chunk Index: where its chunk and message indexes are, sizes as in the chunk.
      Cursor c(r.body);
      const auto t0 = c.u64(), t1 = c.u64(), at = c.u64(), len = c.u64();
      const auto chunk_recs = split_records(file, at, at + len);
      EXPECT_EQ(chunk_recs.list.size(), 1u);
      EXPECT_EQ(chunk_recs.list.at(0).op, 0x06);
      EXPECT_EQ(chunk_recs.list.at(0).size, len);
      const Chunk k = decode_chunk(chunk_recs.list.at(0).body);
      EXPECT_EQ(t0, k.start_time);
      EXPECT_EQ(t1, k.end_time);
      Cursor m(c.bytes(c.u32()));
      std::uint64_t first_index = UINT64_MAX, last_index_end = 0;
      while (!m.done()) {
        const auto channel = m.u16();
        const auto off = m.u64();
        const auto idx = split_records(file, off, file.size());
        EXPECT_EQ(idx.list.at(0).op, 0x07);
        EXPECT_EQ(Cursor(idx.list.at(0).body).u16(), channel);
        first_index = std::min(first_index, off);
        last_index_end = std::max(last_index_end, off + idx.list.at(0).size);
      }
      const auto index_length = c.u64();
      if (first_index != UINT64_MAX) {
        EXPECT_EQ(first_index, at + len) << "message indexes right after their chunk";
        EXPECT_EQ(index_length, last_index_end - first_index);
      }
      EXPECT_EQ(c.str(), k.compression);
      EXPECT_EQ(c.u64(), k.compressed_size);
      EXPECT_EQ(c.u64(), k.uncompressed_size);
      EXPECT_TRUE(c.done());
      ++chunk_no;
    } else if (r.op == 0x0B) {
      Cursor c(r.body);
      v.stats_message_count = c.u64();
      v.stats_schema_count = c.u16();
      v.stats_channel_count = c.u32();
      EXPECT_EQ(c.u32(), 0u);
      EXPECT_EQ(c.u32(), 0u);
      v.stats_chunk_count = c.u32();
      v.stats_start = c.u64();
      v.stats_end = c.u64();
      Cursor m(c.bytes(c.u32()));
      while (!m.done()) {
        const auto ch = m.u16();
        v.stats_channel_counts[ch] = m.u64();
      }
      EXPECT_TRUE(c.done());
    } else {
      ADD_FAILURE() << "summary record op " << int(r.op);
    }
  }
  EXPECT_EQ(chunk_no, v.chunks.size()) << "one chunk index per chunk";
  // The summary repeats the data section's schemas and channels.
  EXPECT_EQ(v.summary_schemas.size(), v.data_schemas.size());
  for (const auto& [id, s] : v.data_schemas) {
    EXPECT_EQ(v.summary_schemas[id].name, s.name);
    EXPECT_EQ(v.summary_schemas[id].data, s.data);
  }
  EXPECT_EQ(v.summary_channels.size(), v.data_channels.size());
  for (const auto& [id, ch] : v.data_channels) {
    EXPECT_EQ(v.summary_channels[id].topic, ch.topic);
    EXPECT_EQ(v.summary_channels[id].metadata, ch.metadata);
  }
  return v;
}

struct Written {
  ChannelId channel;
  std::uint32_t sequence;
  Timestamp log_time, publish_time;
  std::vector<std::byte> data;
};

// A recording of `n` messages on two channels (one with a schema, one without), sizes varied.
std::vector<Written> write_recording(Writer& w, int n) {
  const SchemaId s = w.add_schema("std_msgs/msg/String", "ros2msg", "string data\n");
  const ChannelId a = w.add_channel(s, "/chatter", "cdr", {{"offered_qos_profiles", "- depth: 1"}});
  const ChannelId b = w.add_channel(0, "/raw", "x-bytes");
  std::vector<Written> out;
  for (int i = 0; i < n; ++i) {
    const ChannelId ch = (i % 3 == 2) ? b : a;
    Written m{ch, static_cast<std::uint32_t>(1000 + i), 1'700'000'000'000'000'000ull + 1'000'000ull * i,
              1'700'000'000'000'000'000ull + 1'000'000ull * i - 5, payload(10 + (i * 37) % 200, i)};
    w.write(Message{m.channel, m.sequence, m.log_time, m.publish_time, m.data});
    out.push_back(std::move(m));
  }
  return out;
}

void expect_messages(const std::vector<MessageRec>& got, const std::vector<Written>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].channel, want[i].channel) << i;
    EXPECT_EQ(got[i].sequence, want[i].sequence) << i;
    EXPECT_EQ(got[i].log_time, want[i].log_time) << i;
    EXPECT_EQ(got[i].publish_time, want[i].publish_time) << i;
    EXPECT_EQ(got[i].data, want[i].data) << i;
  }
}

class McapWriterCompression : public ::testing::TestWithParam<Compression> {};

// Several chunks with every structure, offset and CRC checked, for each compression.
TEST_P(McapWriterCompression, ChunkedFileIsWellFormedAndHoldsEveryMessage) {
  const auto path = temp_file("chunked_" + std::string(to_string(GetParam())) + ".mcap");
  std::vector<Written> written;
  WriterStats stats;
  {
    Writer w(path, {.profile = "ros2", .library = "test", .compression = GetParam(), .chunk_size = 4000});
    written = write_recording(w, 300);
    w.close();
    stats = w.stats();
  }
  const FileView v = check_file(path);
  EXPECT_EQ(v.profile, "ros2");
  EXPECT_EQ(v.library, "test");
  expect_messages(v.messages, written);
  // Chunks: several; each closed at the first message that took it to chunk_size.
  ASSERT_GE(v.chunks.size(), 5u);
  for (std::size_t i = 0; i + 1 < v.chunks.size(); ++i) {
    const auto& k = v.chunks[i];
    EXPECT_GE(k.uncompressed_size, 4000u);
    const Records inner = split_records(k.records, 0, k.records.size());
    EXPECT_LT(k.uncompressed_size - inner.list.back().size, 4000u) << "chunk " << i << " closed late";
    EXPECT_EQ(k.compression, to_string(GetParam()));
    if (GetParam() != Compression::none) {
      EXPECT_LT(k.compressed_size, k.uncompressed_size);
    }
  }
  // Statistics.
  EXPECT_EQ(v.stats_message_count, 300u);
  EXPECT_EQ(v.stats_schema_count, 1u);
  EXPECT_EQ(v.stats_channel_count, 2u);
  EXPECT_EQ(v.stats_chunk_count, v.chunks.size());
  EXPECT_EQ(v.stats_start, written.front().log_time);
  EXPECT_EQ(v.stats_end, written.back().log_time);
  EXPECT_EQ(v.stats_channel_counts.at(1), 200u);
  EXPECT_EQ(v.stats_channel_counts.at(2), 100u);
  EXPECT_EQ(stats.message_count, 300u);
  EXPECT_EQ(stats.chunk_count, v.chunks.size());
  EXPECT_EQ(stats.bytes_written, fs::file_size(path));
  // Schema and channel as given.
  EXPECT_EQ(v.summary_schemas.at(1).name, "std_msgs/msg/String");
  EXPECT_EQ(v.summary_schemas.at(1).encoding, "ros2msg");
  EXPECT_EQ(v.summary_channels.at(1).metadata.at("offered_qos_profiles"), "- depth: 1");
  EXPECT_EQ(v.summary_channels.at(2).schema_id, 0u);
}

INSTANTIATE_TEST_SUITE_P(All, McapWriterCompression,
                         ::testing::Values(Compression::none, Compression::zstd, Compression::lz4),
                         [](const ::testing::TestParamInfo<Compression>& p) {
                           return std::string(p.param == Compression::none ? "none" : to_string(p.param));
                         });

// The byte layout of a tiny uncompressed file, field by field against the specification's tables.
TEST(McapWriter, RecordLayoutsAreTheSpecifications) {
  const auto path = temp_file("layout.mcap");
  {
    Writer w(path, {.profile = "ros2", .library = "L", .compression = Compression::none, .chunk_size = 1 << 20});
    const auto s = w.add_schema("p/msg/T", "ros2msg", "int8 x\n");
    const auto c = w.add_channel(s, "/t", "cdr", {{"k", "v"}});
    const std::vector<std::byte> data = {std::byte{0xAB}, std::byte{0xCD}};
    w.write(Message{c, 7, 100, 90, data});
  }
  const auto b = read_bytes(path.string());
  const auto at = [&](std::size_t off, std::initializer_list<int> want) {
    std::vector<std::byte> w;
    for (int x : want) w.push_back(static_cast<std::byte>(x));
    return std::vector<std::byte>(b.begin() + static_cast<long>(off), b.begin() + static_cast<long>(off + w.size())) == w;
  };
  // Magic, Header: op 1, length 4+4+4+1 = 13, "ros2", "L".
  EXPECT_TRUE(at(0, {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'}));
  EXPECT_TRUE(at(8, {0x01, 13, 0, 0, 0, 0, 0, 0, 0, 4, 0, 0, 0, 'r', 'o', 's', '2', 1, 0, 0, 0, 'L'}));
  // Chunk at 30: op 6; times 100, 100; records: Schema, Channel, Message.
  const std::size_t chunk = 30;
  EXPECT_TRUE(at(chunk, {0x06}));
  EXPECT_TRUE(at(chunk + 9, {100, 0, 0, 0, 0, 0, 0, 0, 100, 0, 0, 0, 0, 0, 0, 0}));
  const std::size_t records_len_at = chunk + 9 + 8 + 8 + 8 + 4 + 4;  // compression "" is 4 bytes
  const std::size_t records = records_len_at + 8;
  // Schema: op 3, len 2 + (4+7) + (4+7) + (4+7) = 35, id 1.
  EXPECT_TRUE(at(records, {0x03, 35, 0, 0, 0, 0, 0, 0, 0, 1, 0, 7, 0, 0, 0, 'p', '/', 'm', 's', 'g', '/', 'T'}));
  // Channel: op 4, len 2+2+(4+2)+(4+3)+(4+(4+1+4+1)) = 31, id 1, schema 1, "/t", "cdr", {k: v}.
  const std::size_t channel = records + 9 + 35;
  EXPECT_TRUE(at(channel, {0x04, 31, 0, 0, 0, 0, 0, 0, 0, 1, 0, 1, 0, 2, 0, 0, 0, '/', 't', 3, 0, 0, 0, 'c', 'd', 'r',
                           10, 0, 0, 0, 1, 0, 0, 0, 'k', 1, 0, 0, 0, 'v'}));
  // Message: op 5, len 2+4+8+8+2 = 24, channel 1, sequence 7, log 100, publish 90, data.
  const std::size_t message = channel + 9 + 31;
  EXPECT_TRUE(at(message, {0x05, 24, 0, 0, 0, 0, 0, 0, 0, 1, 0, 7, 0, 0, 0, 100, 0, 0, 0, 0, 0, 0, 0, 90, 0, 0, 0, 0,
                           0, 0, 0, 0xAB, 0xCD}));
  const std::size_t records_len = message + 9 + 24 - records;
  EXPECT_TRUE(at(records_len_at, {static_cast<int>(records_len), 0, 0, 0, 0, 0, 0, 0}));
  // Message Index right after the chunk: op 7, len 2+4+16, channel 1, [(100, offset of message)].
  const std::size_t index = records + records_len;
  EXPECT_TRUE(at(index, {0x07, 22, 0, 0, 0, 0, 0, 0, 0, 1, 0, 16, 0, 0, 0, 100, 0, 0, 0, 0, 0, 0, 0,
                         static_cast<int>(message - records), 0, 0, 0, 0, 0, 0, 0}));
  // DataEnd right after: op 15, len 4.
  EXPECT_TRUE(at(index + 9 + 22, {0x0F, 4, 0, 0, 0, 0, 0, 0, 0}));
  check_file(path);
}

// A file without messages is still a whole MCAP file (header, data end, summary, footer).
TEST(McapWriter, EmptyRecordingIsAValidFile) {
  const auto path = temp_file("empty.mcap");
  { Writer w(path); }
  const FileView v = check_file(path);
  EXPECT_TRUE(v.chunks.empty());
  EXPECT_EQ(v.stats_message_count, 0u);
  EXPECT_EQ(v.stats_start, 0u);
}

// The writer's streaming state: on disk there is always magic, header and whole chunks; flush()
// puts the open chunk there. The image of the file while recording is what a crash leaves.
TEST(McapWriter, WhatACrashLeavesHoldsEveryCompletedChunk) {
  const auto path = temp_file("crash.mcap");
  Writer w(path, {.compression = Compression::zstd, .chunk_size = 3000});
  const auto written = write_recording(w, 120);
  const auto chunks_before_flush = w.stats().chunk_count;
  ASSERT_GE(chunks_before_flush, 3u);
  // Before flush(): the completed chunks, and exactly the messages in them.
  {
    const auto image = read_bytes(path.string());
    FileView v;
    const auto head = split_records(image, 8, image.size());
    const auto end = check_data_section(image, 8 + head.list.at(0).size, image.size(), v, false);
    EXPECT_EQ(end, image.size());
    EXPECT_EQ(v.chunks.size(), chunks_before_flush);
    ASSERT_LT(v.messages.size(), written.size());
    expect_messages(v.messages, std::vector<Written>(written.begin(), written.begin() + v.messages.size()));
  }
  // After flush(): every message written so far.
  w.flush();
  {
    const auto image = read_bytes(path.string());
    FileView v;
    const auto head = split_records(image, 8, image.size());
    check_data_section(image, 8 + head.list.at(0).size, image.size(), v, false);
    EXPECT_EQ(v.chunks.size(), chunks_before_flush + 1);
    expect_messages(v.messages, written);
  }
  // And the recording goes on to a whole file.
  w.write(1, 1'800'000'000'000'000'000ull, payload(5, 1));
  w.close();
  const FileView v = check_file(path);
  EXPECT_EQ(v.messages.size(), written.size() + 1);
}

// A writer destroyed without close() still finishes the file.
TEST(McapWriter, DestructorWithoutCloseFinishesTheFile) {
  const auto path = temp_file("noclose.mcap");
  std::vector<Written> written;
  {
    Writer w(path, {.compression = Compression::lz4, .chunk_size = 2000});
    written = write_recording(w, 50);
  }
  const FileView v = check_file(path);
  expect_messages(v.messages, written);
}

// write(channel, t, data): per-channel sequence numbers from 0, publish_time = log_time; log times
// out of order still give time-sorted indexes (check_file) and the right start and end.
TEST(McapWriter, ConvenienceWriteNumbersEachChannelAndOutOfOrderTimesAreIndexed) {
  const auto path = temp_file("sequence.mcap");
  {
    Writer w(path, {.compression = Compression::none, .chunk_size = 1 << 20});
    const auto a = w.add_channel(0, "/a", "x");
    const auto b = w.add_channel(0, "/b", "x");
    const std::vector<std::byte> d = {std::byte{1}};
    for (Timestamp t : {50, 10, 30, 20, 40}) w.write(a, t, d);
    w.write(b, 5, d);
    w.write(b, 60, d);
  }
  const FileView v = check_file(path);
  ASSERT_EQ(v.messages.size(), 7u);
  for (std::uint32_t i = 0; i < 5; ++i) EXPECT_EQ(v.messages[i].sequence, i);
  EXPECT_EQ(v.messages[5].sequence, 0u);
  EXPECT_EQ(v.messages[6].sequence, 1u);
  EXPECT_EQ(v.messages[1].publish_time, 10u);
  EXPECT_EQ(v.stats_start, 5u);
  EXPECT_EQ(v.stats_end, 60u);
  EXPECT_EQ(v.chunks.at(0).start_time, 5u);
  EXPECT_EQ(v.chunks.at(0).end_time, 60u);
}

// Schemas and channels added twice get one id and one record; new ones after some chunks are
// in the chunk where they were added (a streaming reader meets them before their messages).
TEST(McapWriter, SchemasAndChannelsAreDeduplicatedAndComeBeforeTheirMessages) {
  const auto path = temp_file("dedup.mcap");
  {
    Writer w(path, {.compression = Compression::zstd, .chunk_size = 500});
    const auto s1 = w.add_schema("a/msg/A", "ros2msg", "int8 x\n");
    EXPECT_EQ(w.add_schema("a/msg/A", "ros2msg", "int8 x\n"), s1);
    const auto s2 = w.add_schema("a/msg/A", "ros2msg", "int16 x\n");
    EXPECT_NE(s2, s1);
    const auto c1 = w.add_channel(s1, "/x", "cdr");
    EXPECT_EQ(w.add_channel(s1, "/x", "cdr"), c1);
    EXPECT_NE(w.add_channel(s1, "/x", "cdr", {{"k", "v"}}), c1);
    for (int i = 0; i < 100; ++i) w.write(c1, i, payload(20, i));
    const auto late = w.add_ros2_channel("/late", "b/msg/B", "string s\n", "qos");
    w.write(late, 1000, payload(3, 0));
  }
  const FileView v = check_file(path);  // checks channels come before their messages
  EXPECT_EQ(v.summary_schemas.size(), 3u);
  EXPECT_EQ(v.summary_channels.size(), 3u);
  EXPECT_EQ(v.summary_channels.at(3).topic, "/late");
  EXPECT_EQ(v.summary_channels.at(3).encoding, "cdr");
  EXPECT_EQ(v.summary_channels.at(3).metadata.at("offered_qos_profiles"), "qos");
  EXPECT_EQ(v.summary_schemas.at(3).encoding, "ros2msg");
}

TEST(McapWriter, CrcsCanBeLeftOut) {
  const auto path = temp_file("nocrc.mcap");
  {
    Writer w(path, {.compression = Compression::none, .chunk_size = 100, .crc = false});
    write_recording(w, 10);
  }
  const auto b = read_bytes(path.string());
  const auto recs = split_records(b, 8, b.size() - 8);
  for (const auto& r : recs.list) {
    if (r.op == 0x06) {
      EXPECT_EQ(decode_chunk(r.body).uncompressed_crc, 0u);
    }
    if (r.op == 0x0F) {
      EXPECT_EQ(Cursor(r.body).u32(), 0u);
    }
    if (r.op == 0x02) {
      Cursor c(r.body);
      c.u64();
      c.u64();
      EXPECT_EQ(c.u32(), 0u);
    }
  }
}

TEST(McapWriter, BadCallsAreRefusedWithTheFileAndValueNamed) {
  const auto bad_dir = temp_file("no_such_dir") / "x.mcap";
  try {
    Writer w(bad_dir);
    FAIL() << "opened a file in a missing folder";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(bad_dir.string()), std::string::npos) << e.what();
  }
  EXPECT_THROW(Writer(temp_file("zero.mcap"), {.chunk_size = 0}), std::invalid_argument);
  EXPECT_THROW(Writer(temp_file("lvl.mcap"), {.zstd_level = 99}), std::invalid_argument);
  const auto path = temp_file("bad.mcap");
  Writer w(path);
  try {
    w.write(3, 0, {});
    FAIL() << "wrote on a channel that does not exist";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("channel id 3"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
  }
  EXPECT_THROW(w.add_channel(5, "/t", "cdr"), std::invalid_argument);
  EXPECT_THROW(w.add_channel(0, "", "cdr"), std::invalid_argument);
  w.close();
  EXPECT_THROW(w.write(1, 0, {}), std::logic_error);
  EXPECT_NO_THROW(w.close());  // idempotent
  check_file(path);
}

// Streaming: memory is one chunk. Once the buffers have held one chunk, a message that does not
// close the chunk allocates nothing, and closing a chunk allocates a bounded number of times
// (its entry in the summary's chunk index list, the list growing geometrically; liblz4's frame
// buffer) — nothing grows with the messages.
TEST(McapWriter, MemoryIsOneChunkNotTheRecording) {
  for (const auto compression : {Compression::zstd, Compression::lz4, Compression::none}) {
    const auto path = temp_file("memory.mcap");
    Writer w(path, {.compression = compression, .chunk_size = 8192});
    const auto a = w.add_channel(0, "/a", "x");
    const auto b = w.add_channel(0, "/b", "x");
    const auto d = payload(100, 1);
    for (int i = 0; i < 1000; ++i) w.write(i % 2 ? a : b, i, d);  // warm-up: several chunks
    const auto chunks_before = w.stats().chunk_count;
    std::uint64_t in_chunk_allocations = 0, closing_allocations = 0;
    for (int i = 0; i < 20000; ++i) {
      const auto chunks = w.stats().chunk_count;
      const pedalwave::test::AllocationScope scope;
      w.write(i % 2 ? a : b, 1000 + i, d);
      (w.stats().chunk_count == chunks ? in_chunk_allocations : closing_allocations) += scope.count();
    }
    const auto closed = w.stats().chunk_count - chunks_before;
    ASSERT_GE(closed, 200u);
    EXPECT_EQ(in_chunk_allocations, 0u) << to_string(compression);
    EXPECT_LE(closing_allocations, 2 * closed + 16) << to_string(compression) << ": " << closed << " chunks";
  }
}

// A write the OS refuses (a full disk: /dev/full) is an error naming the file and the OS's reason.
TEST(McapWriter, FullDiskIsAnErrorNamingTheFile) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "SKIPPED: no /dev/full on this machine";
  try {
    Writer w("/dev/full");
    FAIL() << "wrote the header to a full disk";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("/dev/full: cannot write the MCAP file"), std::string::npos) << what;
    EXPECT_NE(what.find("No space left on device"), std::string::npos) << what;
  }
}

// A disk that fills up during the recording (the file-size limit, RLIMIT_FSIZE, stands in for
// it): the write that fails throws naming the file, later writes are refused, the destructor says
// on stderr that the file was not finished and what it holds, and the file holds the chunks
// completed before the failure.
TEST(McapWriter, DiskFullDuringRecordingKeepsTheCompletedChunksAndSaysSo) {
  const auto path = temp_file("fsize.mcap");
  rlimit old{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // EFBIG instead of the signal
  rlimit small = old;
  small.rlim_cur = 40000;  // [bytes]
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  std::string error, on_destruction;
  std::uint32_t chunks_done = 0;
  {
    Writer w(path, {.compression = Compression::none, .chunk_size = 8000});
    const auto c = w.add_channel(0, "/big", "x");
    try {
      for (int i = 0; i < 10000; ++i) w.write(c, i, payload(200, i));
    } catch (const std::runtime_error& e) {
      error = e.what();
    }
    chunks_done = w.stats().chunk_count;
    EXPECT_THROW(w.write(c, 0, payload(1, 0)), std::logic_error);
    ::testing::internal::CaptureStderr();
  }
  on_destruction = ::testing::internal::GetCapturedStderr();
  setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);

  EXPECT_NE(error.find(path.string() + ": cannot write the MCAP file: File too large"), std::string::npos) << error;
  EXPECT_NE(on_destruction.find(path.string() + ": not closed cleanly"), std::string::npos) << on_destruction;
  EXPECT_NE(on_destruction.find("it holds the " + std::to_string(chunks_done) + " chunk(s) completed"),
            std::string::npos)
      << on_destruction;
  // The file: magic, header, then whole chunks each with its message index, then a cut-off tail.
  const auto image = read_bytes(path.string());
  EXPECT_LE(image.size(), 40000u);
  const auto recs = split_records(image, 8, image.size());
  std::size_t chunks = 0, messages = 0;
  for (std::size_t i = 1; i < recs.list.size(); ++i) {
    if (recs.list[i].op != 0x06) {
      EXPECT_EQ(recs.list[i].op, 0x07);
      continue;
    }
    const Chunk k = decode_chunk(recs.list[i].body);
    EXPECT_EQ(k.uncompressed_crc, crc32(k.records));
    messages += split_records(k.records, 0, k.records.size()).list.size() - (chunks == 0 ? 1 : 0);
    ++chunks;
  }
  EXPECT_EQ(chunks, chunks_done);
  EXPECT_GE(chunks, 3u);
  EXPECT_GT(messages, 0u);
}

TEST(McapWriter, CompressionNames) {
  EXPECT_EQ(compression_from_string("zstd"), Compression::zstd);
  EXPECT_EQ(compression_from_string("lz4"), Compression::lz4);
  EXPECT_EQ(compression_from_string("none"), Compression::none);
  try {
    (void)compression_from_string("gzip");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'gzip'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("zstd, lz4 or none"), std::string::npos);
  }
}

// A long recording of small chunks: every chunk is closed at the configured size (what bounds the
// writer's buffers), the statistics count every message.
TEST(McapWriter, LongRecordingClosesEveryChunkAtTheConfiguredSize) {
  const auto path = temp_file("long.mcap");
  const std::uint64_t chunk_size = 16 * 1024;
  std::uint64_t n = 0;
  {
    Writer w(path, {.compression = Compression::lz4, .chunk_size = chunk_size});
    const auto c = w.add_channel(0, "/big", "x");
    const auto d = payload(300, 3);
    for (; n < 20000; ++n) w.write(c, n, d);
  }
  const FileView v = check_file(path);
  EXPECT_EQ(v.stats_message_count, n);
  for (std::size_t i = 0; i + 1 < v.chunks.size(); ++i) {
    EXPECT_GE(v.chunks[i].uncompressed_size, chunk_size);
    EXPECT_LT(v.chunks[i].uncompressed_size, chunk_size + 9 + 22 + 300);
  }
}

}  // namespace
