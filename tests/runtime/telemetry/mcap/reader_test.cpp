// The MCAP reader: files our writer wrote (every compression, several chunks, out-of-order times)
// read back exactly; hand-built and corrupted files refused with the named error (bad magic,
// truncated record, unknown compression, CRC mismatches, missing schema); a file truncated at every
// offset and with bytes flipped gives a clean ReadError, never a crash. The CDR reader reads what
// the CDR writer writes. (tests/runtime/telemetry/mcap/peer/ reads files @mcap/core wrote.)
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "mcap_test_reader.hpp"
#include "pedalwave/mcap/cdr.hpp"
#include "pedalwave/mcap/cdr_reader.hpp"
#include "pedalwave/mcap/reader.hpp"
#include "pedalwave/mcap/ros2_decode.hpp"
#include "pedalwave/mcap/ros2msg.hpp"
#include "pedalwave/mcap/writer.hpp"

namespace fs = std::filesystem;
using namespace pedalwave::mcap;

namespace {

fs::path temp_file(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("pedalwave_mcap_reader_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d / name;
}

class RemoveTempFiles : public ::testing::Environment {
 public:
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(fs::temp_directory_path() / ("pedalwave_mcap_reader_" + std::to_string(::getpid())), ec);
  }
};
const auto* const kEnv = ::testing::AddGlobalTestEnvironment(new RemoveTempFiles);

struct Sent {
  ChannelId channel;
  std::uint32_t sequence;
  Timestamp log_time, publish_time;
  std::vector<std::byte> data;
};

// Three channels (two on one ros2msg schema, one without a schema), messages of 0 … 300 bytes,
// log times mostly rising with some going back (a late message), several chunks.
std::vector<Sent> write_file(const fs::path& path, Compression c, bool crc = true, int n = 400) {
  Writer w(path, {.profile = "ros2", .library = "reader test", .compression = c, .chunk_size = 3000, .crc = crc});
  const SchemaId s = w.add_schema("std_msgs/msg/String", "ros2msg", "string data\n");
  const ChannelId a = w.add_channel(s, "/a", "cdr", {{"offered_qos_profiles", "- depth: 1"}});
  const ChannelId b = w.add_channel(s, "/b", "cdr");
  const ChannelId x = w.add_channel(0, "/raw", "application/octet-stream");
  std::vector<Sent> sent;
  std::mt19937 rng(7);
  for (int i = 0; i < n; ++i) {
    Sent m;
    m.channel = i % 3 == 0 ? a : (i % 3 == 1 ? b : x);
    m.sequence = static_cast<std::uint32_t>(1000 + i);
    m.log_time = 1'000'000'000ull + static_cast<Timestamp>(i) * 1000u - (i % 17 == 5 ? 2500u : 0u);
    m.publish_time = m.log_time - 7;
    m.data.resize(static_cast<std::size_t>(rng() % 300));
    for (auto& byte : m.data) byte = static_cast<std::byte>(rng() & 0xFFu);
    w.write(Message{m.channel, m.sequence, m.log_time, m.publish_time, m.data});
    sent.push_back(std::move(m));
  }
  w.close();
  return sent;
}

std::vector<std::byte> bytes_of(const fs::path& p) { return test::read_bytes(p.string()); }

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const ReadError& e) {
    return e.what();
  }
  return "";
}

// Little-endian record builder for hand-made files (independent of the writer).
struct Builder {
  std::vector<std::byte> b;
  void u8(unsigned v) { b.push_back(static_cast<std::byte>(v)); }
  void u16(unsigned v) { for (int i = 0; i < 2; ++i) u8((v >> (8 * i)) & 0xFF); }
  void u32(std::uint32_t v) { for (int i = 0; i < 4; ++i) u8((v >> (8 * i)) & 0xFF); }
  void u64(std::uint64_t v) { for (int i = 0; i < 8; ++i) u8(static_cast<unsigned>((v >> (8 * i)) & 0xFF)); }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size()));
    for (char c : s) u8(static_cast<unsigned char>(c));
  }
  void magic() { for (unsigned c : {0x89u, 0x4Du, 0x43u, 0x41u, 0x50u, 0x30u, 0x0Du, 0x0Au}) u8(c); }
  void record(unsigned op, const Builder& body) {
    u8(op);
    u64(body.b.size());
    b.insert(b.end(), body.b.begin(), body.b.end());
  }
};
Builder header_record() {
  Builder h;
  h.str("ros2");
  h.str("hand");
  return h;
}

}  // namespace

class McapReaderRoundTrip : public ::testing::TestWithParam<Compression> {};

TEST_P(McapReaderRoundTrip, ReadsEveryMessageOfOurWriterExactlyInLogTimeOrder) {
  const fs::path p = temp_file("round_" + std::string(to_string(GetParam())) + ".mcap");
  const std::vector<Sent> sent = write_file(p, GetParam());
  const Reader r(p);
  EXPECT_EQ(r.profile(), "ros2");
  EXPECT_EQ(r.library(), "reader test");
  EXPECT_TRUE(r.has_summary());
  EXPECT_EQ(r.message_count(), sent.size());
  EXPECT_GE(r.chunk_count(), 10u);
  ASSERT_EQ(r.channels().size(), 3u);
  ASSERT_EQ(r.schemas().size(), 1u);
  const ChannelRecord* a = r.channel("/a");
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->message_encoding, "cdr");
  EXPECT_EQ(a->metadata.at("offered_qos_profiles"), "- depth: 1");
  ASSERT_NE(r.schema_of(*a), nullptr);
  EXPECT_EQ(r.schema_of(*a)->name, "std_msgs/msg/String");
  EXPECT_EQ(r.schema_of(*a)->data, "string data\n");
  EXPECT_EQ(r.schema_of(*r.channel("/raw")), nullptr);
  EXPECT_EQ(r.channel("/none"), nullptr);

  // All messages: the writer's, stably sorted by log time.
  std::vector<Sent> expect = sent;
  std::stable_sort(expect.begin(), expect.end(), [](const Sent& x, const Sent& y) { return x.log_time < y.log_time; });
  const auto all = r.messages();
  ASSERT_EQ(all.size(), expect.size());
  for (std::size_t i = 0; i < all.size(); ++i) {
    EXPECT_EQ(all[i].channel, expect[i].channel) << i;
    EXPECT_EQ(all[i].sequence, expect[i].sequence) << i;
    EXPECT_EQ(all[i].log_time, expect[i].log_time) << i;
    EXPECT_EQ(all[i].publish_time, expect[i].publish_time) << i;
    EXPECT_EQ(all[i].data, expect[i].data) << i;
  }
  // One topic.
  const std::vector<std::string> topics{"/b"};
  const auto b = r.messages_on(topics);
  std::size_t k = 0;
  for (const Sent& s : expect)
    if (s.channel == r.channel("/b")->id) {
      ASSERT_LT(k, b.size());
      EXPECT_EQ(b[k].sequence, s.sequence);
      EXPECT_EQ(b[k].data, s.data);
      ++k;
    }
  EXPECT_EQ(k, b.size());
  // A topic the file lacks: named, with the topics it has.
  const std::vector<std::string> missing{"/nope"};
  const std::string e = error_of([&] { (void)r.messages_on(missing); });
  EXPECT_NE(e.find(p.string()), std::string::npos) << e;
  EXPECT_NE(e.find("/nope"), std::string::npos) << e;
  EXPECT_NE(e.find("/a (std_msgs/msg/String)"), std::string::npos) << e;
}

INSTANTIATE_TEST_SUITE_P(All, McapReaderRoundTrip,
                         ::testing::Values(Compression::none, Compression::zstd, Compression::lz4),
                         [](const ::testing::TestParamInfo<Compression>& p) {
                           return p.param == Compression::none ? std::string("none") : std::string(to_string(p.param));
                         });

TEST(McapReader, FileWithoutCrcsReads) {
  const fs::path p = temp_file("nocrc.mcap");
  const auto sent = write_file(p, Compression::zstd, false, 50);
  EXPECT_EQ(Reader(p).messages().size(), sent.size());
}

TEST(McapReader, UnchunkedHandMadeFileReads) {
  Builder f;
  f.magic();
  f.record(0x01, header_record());
  Builder s;
  s.u16(1); s.str("t/msg/T"); s.str("ros2msg"); s.str("int32 x\n");
  f.record(0x03, s);
  Builder c;
  c.u16(4); c.u16(1); c.str("/t"); c.str("cdr"); c.u32(0);
  f.record(0x04, c);
  for (int i = 0; i < 3; ++i) {
    Builder m;
    m.u16(4); m.u32(static_cast<std::uint32_t>(i)); m.u64(30 - 10 * static_cast<std::uint64_t>(i)); m.u64(0);
    m.u8(0xA0 + static_cast<unsigned>(i));
    f.record(0x05, m);
  }
  Builder unknown;  // an opcode from the future: skipped
  unknown.u32(42);
  f.record(0x80, unknown);
  Builder de;
  de.u32(0);
  f.record(0x0F, de);
  Builder foot;
  foot.u64(0); foot.u64(0); foot.u32(0);
  f.record(0x02, foot);
  f.magic();
  const Reader r(f.b, "hand.mcap");
  const auto m = r.messages();
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[0].log_time, 10u);  // log-time order
  EXPECT_EQ(m[0].data, std::vector<std::byte>{std::byte{0xA2}});
  EXPECT_EQ(r.channel("/t")->id, 4u);
  EXPECT_FALSE(r.has_summary());
}

// ---- refused files -----------------------------------------------------------------------------------
TEST(McapReader, BadMagicIsNamed) {
  const fs::path p = temp_file("magic.mcap");
  write_file(p, Compression::none, true, 10);
  auto b = bytes_of(p);
  b[1] = std::byte{'X'};
  const std::string e = error_of([&] { Reader(b, p.string()); });
  EXPECT_NE(e.find(p.string() + ": byte 0: bad magic: expected the MCAP magic"), std::string::npos) << e;
  EXPECT_NE(error_of([&] { Reader(std::vector<std::byte>{}, "empty.mcap"); }).find("empty.mcap: byte 0"), std::string::npos);
  EXPECT_NE(error_of([&] { Reader(fs::path("/nonexistent/x.mcap")); }).find("/nonexistent/x.mcap: cannot open"),
            std::string::npos);
}

// The first record after the Header is our writer's first Chunk: its offset and its fields.
std::size_t first_chunk(const std::vector<std::byte>& b) {
  const auto rs = test::split_records(b, 8, b.size() - 8);
  for (const auto& r : rs.list)
    if (r.op == 0x06) return static_cast<std::size_t>(r.offset);
  throw std::runtime_error("no chunk");
}

TEST(McapReader, ChunkCrcMismatchIsNamedWithTheChunksOffset) {
  for (Compression c : {Compression::none, Compression::zstd, Compression::lz4}) {
    const fs::path p = temp_file("crc.mcap");
    write_file(p, c, true, 60);
    auto b = bytes_of(p);
    const std::size_t at = first_chunk(b);
    b[at + 9 + 24] ^= std::byte{0x01};  // first byte of uncompressed_crc
    const std::string e = error_of([&] { Reader(b, p.string()); });
    EXPECT_NE(e.find(p.string() + ": byte " + std::to_string(at) + ": Chunk CRC mismatch"), std::string::npos)
        << to_string(c) << ": " << e;
    // With CRC checks off the same file reads.
    EXPECT_NO_THROW(Reader(b, p.string(), ReaderOptions{.check_crcs = false}));
  }
}

TEST(McapReader, DataAndSummaryCrcMismatchesAreNamed) {
  const fs::path p = temp_file("crc2.mcap");
  write_file(p, Compression::zstd, true, 60);
  const auto good = bytes_of(p);
  const auto rs = test::split_records(good, 8, good.size() - 8);
  std::size_t index_at = 0, stats_at = 0;
  for (const auto& r : rs.list) {
    if (r.op == 0x07 && index_at == 0) index_at = static_cast<std::size_t>(r.offset);
    if (r.op == 0x0B) stats_at = static_cast<std::size_t>(r.offset);
  }
  ASSERT_GT(index_at, 0u);
  ASSERT_GT(stats_at, 0u);
  auto b = good;
  b[index_at + 9 + 2 + 4] ^= std::byte{0x10};  // a MessageIndex entry's time: data section only
  EXPECT_NE(error_of([&] { Reader(b, "d.mcap"); }).find("data section CRC mismatch"), std::string::npos);
  b = good;
  b[stats_at + 9] ^= std::byte{0x10};  // Statistics.message_count: summary only
  EXPECT_NE(error_of([&] { Reader(b, "s.mcap"); }).find("summary CRC mismatch"), std::string::npos);
}

TEST(McapReader, UnknownCompressionIsNamed) {
  const fs::path p = temp_file("comp.mcap");
  write_file(p, Compression::zstd, true, 60);
  auto b = bytes_of(p);
  const std::size_t at = first_chunk(b);
  // compression string after the 3 u64 and the u32 CRC: length 4, "zstd" → "zstx".
  b[at + 9 + 28 + 4 + 3] = std::byte{'x'};
  const std::string e = error_of([&] { Reader(b, p.string()); });
  EXPECT_NE(e.find(p.string() + ": byte " + std::to_string(at + 9 + 28) + ": Chunk compression \"zstx\": expected"),
            std::string::npos)
      << e;
}

TEST(McapReader, MissingSchemaAndChannelAreNamed) {
  Builder f;
  f.magic();
  f.record(0x01, header_record());
  const std::size_t channel_at = f.b.size();
  Builder c;
  c.u16(1); c.u16(9); c.str("/t"); c.str("cdr"); c.u32(0);
  f.record(0x04, c);
  std::string e = error_of([&] { Reader(f.b, "noschema.mcap"); });
  EXPECT_NE(e.find("noschema.mcap: byte " + std::to_string(channel_at + 9) + ": Channel 1 (\"/t\") refers to schema 9"),
            std::string::npos)
      << e;
  EXPECT_NE(e.find("missing schema"), std::string::npos) << e;

  Builder g;
  g.magic();
  g.record(0x01, header_record());
  Builder m;
  m.u16(3); m.u32(0); m.u64(1); m.u64(1);
  g.record(0x05, m);
  e = error_of([&] { Reader(g.b, "nochannel.mcap"); });
  EXPECT_NE(e.find("Message on channel 3: no such Channel record"), std::string::npos) << e;

  Builder h;  // a record before the Header
  h.magic();
  h.record(0x05, m);
  EXPECT_NE(error_of([&] { Reader(h.b, "first.mcap"); }).find("expected the Header record"), std::string::npos);
}

TEST(McapReader, TruncatedRecordIsNamed) {
  const fs::path p = temp_file("trunc.mcap");
  write_file(p, Compression::lz4, true, 60);
  auto b = bytes_of(p);
  const std::size_t at = first_chunk(b);
  b.resize(at + 100);
  const std::string e = error_of([&] { Reader(b, p.string()); });
  EXPECT_NE(e.find(p.string() + ": byte " + std::to_string(at) + ": Chunk record (opcode 0x06) truncated: its length says"),
            std::string::npos)
      << e;
  EXPECT_NE(e.find("91 bytes after its length field"), std::string::npos) << e;
  // Cut after a whole record: the file ends without its Footer.
  b.resize(at);
  EXPECT_NE(error_of([&] { Reader(b, p.string()); }).find("ends without a Footer"), std::string::npos);
}

// Truncated at every offset and with bytes flipped: a ReadError naming the file, never a crash, a
// hang or another exception (run under ASan+UBSan in the sanitizer build).
TEST(McapReader, EveryTruncationAndByteFlipIsACleanError) {
  for (Compression c : {Compression::none, Compression::zstd, Compression::lz4}) {
    const fs::path p = temp_file("fuzz.mcap");
    write_file(p, c, true, 40);
    const auto good = bytes_of(p);
    ASSERT_NO_THROW(Reader(good, "fuzz.mcap"));
    for (std::size_t n = 0; n < good.size(); ++n) {
      std::vector<std::byte> b(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
      try {
        Reader r(std::move(b), "fuzz.mcap");
        ADD_FAILURE() << to_string(c) << ": a file cut at " << n << " of " << good.size() << " bytes was accepted";
      } catch (const ReadError& e) {
        ASSERT_EQ(std::string(e.what()).rfind("fuzz.mcap: ", 0), 0u) << e.what();
        ASSERT_LE(e.offset(), n);
      }
    }
    // Byte flips with CRC checks off (so that the parsers, not the CRCs, meet the damage): read or
    // refused, nothing else.
    std::mt19937 rng(11);
    for (int k = 0; k < 3000; ++k) {
      auto b = good;
      const std::size_t at = rng() % b.size();
      b[at] ^= static_cast<std::byte>(1u << (rng() % 8));
      try {
        Reader r(std::move(b), "flip.mcap", ReaderOptions{.check_crcs = false, .max_chunk_size = 1 << 20});
        (void)r.messages();
      } catch (const ReadError& e) {
        ASSERT_EQ(std::string(e.what()).rfind("flip.mcap: ", 0), 0u) << e.what();
      }
    }
  }
}

// ---- CDR ---------------------------------------------------------------------------------------------
TEST(CdrReader, ReadsWhatTheWriterWrites) {
  CdrWriter w;
  w.write_time(-1'500'000'000);  // sec −2, nanosec 5e8
  w.write_string("robot");
  w.write_u64(42);
  w.write_i64(-123456789012345);
  w.write_f64(1.0 / 3.0);
  w.write_u8(7);
  const std::vector<double> xs{0.1, -2.5, 1e300};
  w.write_sequence(xs);
  w.write_bool(true);
  w.write_i16(-300);
  const std::vector<std::string> names{"a", "bc"};
  w.write_sequence(names);
  w.write_f32(1.5f);
  w.write_u32(0);  // an empty sequence
  CdrReader r(w.bytes());
  EXPECT_EQ(r.read_time(), -1'500'000'000);
  EXPECT_EQ(r.read_string(), "robot");
  EXPECT_EQ(r.read_u64(), 42u);
  EXPECT_EQ(r.read_i64(), -123456789012345);
  EXPECT_EQ(r.read_f64(), 1.0 / 3.0);
  EXPECT_EQ(r.read_u8(), 7u);
  EXPECT_EQ(r.read_sequence<double>("xs", 63), xs);
  EXPECT_TRUE(r.read_bool());
  EXPECT_EQ(r.read_i16(), -300);
  EXPECT_EQ(r.read_string_sequence(), names);
  EXPECT_EQ(r.read_f32(), 1.5f);
  EXPECT_TRUE(r.read_sequence<double>().empty());
  EXPECT_EQ(r.remaining(), 0u);
}

TEST(CdrReader, BadMessagesAreNamed) {
  CdrWriter w;
  w.write_u8(1);
  const std::vector<double> xs{1, 2, 3};
  w.write_sequence(xs);
  auto bytes = std::vector<std::byte>(w.bytes().begin(), w.bytes().end());
  auto err = [](std::span<const std::byte> b, auto&& f) {
    try {
      CdrReader r(b);
      f(r);
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  // Cut short: the sequence's third double is missing.
  const std::string e1 = err(std::span(bytes).first(bytes.size() - 4), [](CdrReader& r) {
    (void)r.read_u8();
    (void)r.read_sequence<double>("beta");
  });
  EXPECT_NE(e1.find("beta"), std::string::npos) << e1;
  EXPECT_NE(e1.find("CDR offset"), std::string::npos) << e1;
  // Over the bound.
  const std::string e2 = err(bytes, [](CdrReader& r) {
    (void)r.read_u8();
    (void)r.read_sequence<double>("beta", 2);
  });
  EXPECT_NE(e2.find("expected at most 2"), std::string::npos) << e2;
  // Big-endian encapsulation.
  bytes[1] = std::byte{0x00};
  EXPECT_NE(err(bytes, [](CdrReader&) {}).find("expected 0,1 (CDR_LE"), std::string::npos);
}

// ---- decoding by the schema the file carries ----------------------------------------------------------
TEST(Ros2MsgDecoder, DecodesAMessageByItsConcatenatedSchema) {
  MsgMapLookup defs;
  defs.add("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n");
  defs.add("std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id\n");
  defs.add("pkg/msg/P", "int32 a   # a comment\nstring b\n");
  defs.add("pkg/msg/S",
           "# a message\nstd_msgs/Header header\nuint8 K=3\nstring<=4 C=\"x\"\nuint64 seq\nfloat64[<=3] x\n"
           "string<=15 s\nP[] ps\nint16[2] fixed\nbool flag\nfloat32 f 1.5\n");
  const std::string schema = concatenate_msg_definitions("pkg/msg/S", defs);
  const Ros2MsgDecoder dec("pkg/msg/S", schema);
  CdrWriter w;
  w.write_time(3'000'000'007);
  w.write_string("robot");
  w.write_u64(77);
  const std::vector<double> x{1.5, -2.25};
  w.write_sequence(x);
  w.write_string("RUNNING");
  w.write_sequence_length(2);
  w.write_i32(-4); w.write_string("p0");
  w.write_i32(5); w.write_string("p1");
  w.write_i16(-1); w.write_i16(2);
  w.write_bool(true);
  w.write_f32(0.5f);
  const DecodedMessage m = dec.decode(w.bytes());
  EXPECT_EQ(m.scalar("header.stamp.sec"), 3);
  EXPECT_EQ(m.scalar("header.stamp.nanosec"), 7);
  EXPECT_EQ(m.strings.at("header.frame_id"), std::vector<std::string>{"robot"});
  EXPECT_EQ(m.scalar("seq"), 77);
  EXPECT_EQ(m.at("x"), x);
  EXPECT_EQ(m.strings.at("s"), std::vector<std::string>{"RUNNING"});
  EXPECT_EQ(m.at("ps.a"), (std::vector<double>{-4, 5}));
  EXPECT_EQ(m.strings.at("ps.b"), (std::vector<std::string>{"p0", "p1"}));
  EXPECT_EQ(m.at("fixed"), (std::vector<double>{-1, 2}));
  EXPECT_EQ(m.scalar("flag"), 1);
  EXPECT_EQ(m.scalar("f"), 0.5);
  EXPECT_EQ(m.numbers.count("K"), 0u);  // constants are no fields
  // Errors name what is wrong.
  try {
    (void)m.at("beta");
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'beta'"), std::string::npos) << e.what();
  }
  const auto cut = w.bytes().first(w.bytes().size() - 6);
  try {
    (void)dec.decode(cut);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("CDR offset"), std::string::npos) << e.what();
  }
  // A sequence of messages claiming 4e9 elements: refused at once (no loop over them).
  const Ros2MsgDecoder seq("pkg/msg/S2", std::string("pkg/P[] ps\n") + std::string(80, '=') + "\nMSG: pkg/P\nint32 a\n");
  // Encapsulation CDR_LE, then the count 4e9 = 0xEE6B2800 little-endian.
  const std::vector<std::byte> huge{std::byte{0}, std::byte{1}, std::byte{0}, std::byte{0},
                                    std::byte{0x00}, std::byte{0x28}, std::byte{0x6B}, std::byte{0xEE}};
  try {
    (void)seq.decode(huge);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("sequence of 4000000000 elements"), std::string::npos) << e.what();
  }
  try {
    Ros2MsgDecoder bad("pkg/msg/S", "pkg/Q q\n");
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pkg/Q"), std::string::npos) << e.what();
  }
}

// What a recorder that died leaves (the file cut anywhere after the Header): with allow_unfinished
// the messages of the whole records before the cut, in order — for our writer's files, those of the
// completed chunks — and complete() false; the whole file complete() true.
TEST(McapReader, UnfinishedFileGivesTheMessagesOfItsWholeChunks) {
  const fs::path p = temp_file("unfinished.mcap");
  write_file(p, Compression::zstd, true, 90);
  const auto good = bytes_of(p);
  const ReaderOptions o{.allow_unfinished = true};
  const Reader whole(good, "whole.mcap", o);
  EXPECT_TRUE(whole.complete());
  const auto all = whole.messages();
  const auto rs = test::split_records(good, 8, good.size() - 8);
  std::size_t header_end = 0;
  for (const auto& r : rs.list)
    if (r.op == 0x01) header_end = static_cast<std::size_t>(r.offset + r.size);
  std::size_t previous = 0;
  for (std::size_t n = header_end; n < good.size(); n += 7) {
    const Reader cut(std::vector<std::byte>(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n)), "cut.mcap", o);
    EXPECT_FALSE(cut.complete()) << n;
    // Messages of the chunks that end at or before n.
    std::uint64_t expect = 0;
    for (const auto& r : rs.list)
      if (r.op == 0x06 && r.offset + r.size <= n) {
        const test::Chunk k = test::decode_chunk(r.body);
        const auto inner = test::split_records(k.records, 0, k.records.size());
        for (const auto& m : inner.list) expect += m.op == 0x05 ? 1 : 0;
      }
    ASSERT_EQ(cut.message_count(), expect) << "cut at " << n;
    ASSERT_GE(cut.message_count(), previous);
    previous = cut.message_count();
  }
  EXPECT_GT(previous, 0u);
  // Cut inside the Header: still an error.
  EXPECT_NE(error_of([&] { Reader(std::vector<std::byte>(good.begin(), good.begin() + 12), "h.mcap", o); }).find("h.mcap: byte 8"),
            std::string::npos);
}
