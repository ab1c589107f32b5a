// CANopen (CiA 301) codecs (canopen.hpp): NMT, SYNC, heartbeat, EMCY byte layouts, and the SDO
// client against the SDO server (expedited and segmented, both directions), their aborts and
// toggle checking. Byte layouts checked against CiA 301's command specifiers (e.g. the expedited
// 2-byte download 0x2B, the 4-byte upload response 0x43, the segmented initiate 0x21 / 0x41).
#include <gtest/gtest.h>

#include <map>
#include <utility>
#include <vector>

#include "pedalwave/drivers/canopen.hpp"

namespace co = pedalwave::drivers::canopen;

namespace {

std::vector<std::uint8_t> bytes(const can_frame& f) { return {f.data, f.data + f.len}; }

// An object dictionary of byte strings; (0x2000, 1) is read-only.
class TestOd final : public co::ObjectDictionary {
 public:
  std::map<std::pair<std::uint16_t, std::uint8_t>, std::vector<std::uint8_t>> objects;
  std::size_t read(std::uint16_t index, std::uint8_t sub, std::span<std::uint8_t> out,
                   std::uint32_t& abort) noexcept override {
    const auto it = objects.find({index, sub});
    if (it == objects.end()) {
      abort = co::kAbortNoObject;
      return 0;
    }
    if (it->second.size() > out.size()) {
      abort = co::kAbortOutOfMemory;
      return 0;
    }
    std::copy(it->second.begin(), it->second.end(), out.begin());
    return it->second.size();
  }
  std::uint32_t write(std::uint16_t index, std::uint8_t sub,
                      std::span<const std::uint8_t> data) noexcept override {
    if (index == 0x2000 && sub == 1) return co::kAbortReadOnly;
    objects[{index, sub}] = std::vector<std::uint8_t>(data.begin(), data.end());
    return 0;
  }
};

// Runs one client transfer against the server until it ends; returns the last step and counts the
// frames the client sent.
co::SdoStep run(co::SdoClient& c, co::SdoServer& s, can_frame request, int& sent) {
  sent = 1;
  for (int i = 0; i < 1000; ++i) {
    can_frame response{}, next{};
    if (!s.on_frame(request, response)) return co::SdoStep::kIgnored;
    const co::SdoStep step = c.on_frame(response, next);
    if (step != co::SdoStep::kSend) return step;
    request = next;
    ++sent;
  }
  return co::SdoStep::kIgnored;
}

}  // namespace

TEST(CanOpenNmt, CommandsSyncHeartbeatAndEmcyLayouts) {
  can_frame f{};
  ASSERT_TRUE(co::encode_nmt(co::NmtCommand::kStart, 5, f));
  EXPECT_EQ(f.can_id, 0x000u);
  EXPECT_EQ(bytes(f), (std::vector<std::uint8_t>{0x01, 0x05}));
  ASSERT_TRUE(co::encode_nmt(co::NmtCommand::kResetCommunication, 0, f));  // every node
  EXPECT_EQ(bytes(f), (std::vector<std::uint8_t>{0x82, 0x00}));
  co::NmtCommand cmd{};
  std::uint8_t node = 0;
  ASSERT_TRUE(co::decode_nmt(f, cmd, node));
  EXPECT_EQ(cmd, co::NmtCommand::kResetCommunication);
  EXPECT_FALSE(co::encode_nmt(co::NmtCommand::kStop, 128, f));
  f.data[0] = 0x03;  // no such command
  EXPECT_FALSE(co::decode_nmt(f, cmd, node));

  ASSERT_TRUE(co::encode_sync(0, f));
  EXPECT_EQ(f.can_id, 0x080u);
  EXPECT_EQ(f.len, 0);
  ASSERT_TRUE(co::encode_sync(240, f));
  EXPECT_EQ(bytes(f), (std::vector<std::uint8_t>{240}));
  EXPECT_FALSE(co::encode_sync(241, f));

  ASSERT_TRUE(co::encode_heartbeat(3, co::NmtState::kOperational, f));
  EXPECT_EQ(f.can_id, 0x703u);
  EXPECT_EQ(bytes(f), (std::vector<std::uint8_t>{0x05}));
  co::NmtState st{};
  f.can_id = 0x77F;
  f.data[0] = 0x00;  // boot-up of node 127
  ASSERT_TRUE(co::decode_heartbeat(f, node, st));
  EXPECT_EQ(node, 127);
  EXPECT_EQ(st, co::NmtState::kBootUp);
  EXPECT_STREQ(co::to_string(st), "boot-up");
  f.data[0] = 0xFF;  // pre-operational with the guarding toggle bit
  ASSERT_TRUE(co::decode_heartbeat(f, node, st));
  EXPECT_EQ(st, co::NmtState::kPreOperational);
  f.data[0] = 0x10;
  EXPECT_FALSE(co::decode_heartbeat(f, node, st)) << "no such state";
  f.data[0] = 0x05;
  f.can_id = 0x700;
  EXPECT_FALSE(co::decode_heartbeat(f, node, st)) << "node 0";
  f.can_id = 0x705 | CAN_RTR_FLAG;
  EXPECT_FALSE(co::decode_heartbeat(f, node, st)) << "a remote frame";

  co::Emcy e{0x8611, 0x81, {1, 2, 3, 4, 5}};  // following error, manufacturer bits
  ASSERT_TRUE(co::encode_emcy(9, e, f));
  EXPECT_EQ(f.can_id, 0x089u);
  EXPECT_EQ(bytes(f), (std::vector<std::uint8_t>{0x11, 0x86, 0x81, 1, 2, 3, 4, 5}));
  co::Emcy d{};
  ASSERT_TRUE(co::decode_emcy(f, node, d));
  EXPECT_EQ(node, 9);
  EXPECT_EQ(d.code, 0x8611);
  EXPECT_EQ(d.error_register, 0x81);
  EXPECT_EQ(d.vendor, e.vendor);
  f.can_id = 0x080;
  EXPECT_FALSE(co::decode_emcy(f, node, d)) << "a SYNC is no EMCY";
}

TEST(CanOpenSdo, ExpeditedFramesAsCiA301) {
  co::SdoClient c;
  can_frame req{}, next{};
  // Write controlword 0x6040:00 = 0x000F (2 bytes) to node 2.
  const std::uint8_t cw[2] = {0x0F, 0x00};
  ASSERT_TRUE(c.start_download(2, 0x6040, 0, cw, req));
  EXPECT_EQ(req.can_id, 0x602u);
  EXPECT_EQ(bytes(req), (std::vector<std::uint8_t>{0x2B, 0x40, 0x60, 0x00, 0x0F, 0x00, 0x00, 0x00}));
  can_frame resp{};
  resp.can_id = 0x583;  // another node's answer
  resp.len = 8;
  resp.data[0] = 0x60;
  EXPECT_EQ(c.on_frame(resp, next), co::SdoStep::kIgnored);
  resp.can_id = 0x582;
  resp.data[1] = 0x40;
  resp.data[2] = 0x60;
  EXPECT_EQ(c.on_frame(resp, next), co::SdoStep::kDone);
  EXPECT_FALSE(c.busy());
  // Read statusword 0x6041:00: the 2-byte expedited answer 0x4B.
  ASSERT_TRUE(c.start_upload(2, 0x6041, 0, req));
  EXPECT_EQ(bytes(req), (std::vector<std::uint8_t>{0x40, 0x41, 0x60, 0x00, 0, 0, 0, 0}));
  resp = can_frame{};
  resp.can_id = 0x582;
  resp.len = 8;
  const std::uint8_t ans[8] = {0x4B, 0x41, 0x60, 0x00, 0x37, 0x02, 0x00, 0x00};
  std::copy(ans, ans + 8, resp.data);
  ASSERT_EQ(c.on_frame(resp, next), co::SdoStep::kDone);
  EXPECT_EQ(std::vector<std::uint8_t>(c.data().begin(), c.data().end()),
            (std::vector<std::uint8_t>{0x37, 0x02}));
  // 1, 3 and 4 bytes: 0x2F, 0x27, 0x23.
  for (auto [n, cs] : {std::pair{1, 0x2F}, {3, 0x27}, {4, 0x23}}) {
    const std::vector<std::uint8_t> v(static_cast<std::size_t>(n), 0xAA);
    ASSERT_TRUE(c.start_download(2, 0x6060, 0, v, req));
    EXPECT_EQ(req.data[0], cs) << n;
  }
}

TEST(CanOpenSdo, SegmentedDownloadFramesAndToggle) {
  co::SdoClient c;
  can_frame req{};
  const std::vector<std::uint8_t> text = {'0', '1', '2', '3', '4', '5', '6', '7', '8', '9'};
  ASSERT_TRUE(c.start_download(1, 0x1008, 0, text, req));
  EXPECT_EQ(bytes(req), (std::vector<std::uint8_t>{0x21, 0x08, 0x10, 0x00, 10, 0, 0, 0}));
  can_frame resp{}, seg{};
  resp.can_id = 0x581;
  resp.len = 8;
  resp.data[0] = 0x60;
  resp.data[1] = 0x08;
  resp.data[2] = 0x10;
  ASSERT_EQ(c.on_frame(resp, seg), co::SdoStep::kSend);
  // First segment: t = 0, 7 bytes, more to come.
  EXPECT_EQ(bytes(seg), (std::vector<std::uint8_t>{0x00, '0', '1', '2', '3', '4', '5', '6'}));
  resp = can_frame{};
  resp.can_id = 0x581;
  resp.len = 8;
  resp.data[0] = 0x20;  // t = 0 confirmed
  ASSERT_EQ(c.on_frame(resp, seg), co::SdoStep::kSend);
  // Second: t = 1, 3 bytes (n = 4 without data), last.
  EXPECT_EQ(seg.data[0], 0x10 | (4 << 1) | 1);
  EXPECT_EQ(seg.data[1], '7');
  EXPECT_EQ(seg.data[3], '9');
  // A response with the wrong toggle: the client aborts with 0x05030000.
  can_frame abort{};
  EXPECT_EQ(c.on_frame(resp, abort), co::SdoStep::kAbort);
  EXPECT_EQ(c.abort_code(), co::kAbortToggle);
  EXPECT_EQ(bytes(abort), (std::vector<std::uint8_t>{0x80, 0x08, 0x10, 0x00, 0x00, 0x00, 0x03, 0x05}));
  EXPECT_STREQ(co::abort_text(c.abort_code()), "toggle bit not alternated");
}

TEST(CanOpenSdo, ClientAndServerTransferEverySizeBothWays) {
  TestOd od;
  co::SdoServer server(4, od);
  co::SdoClient c;
  for (std::size_t n : {1u, 2u, 4u, 5u, 7u, 8u, 14u, 15u, 100u, 256u}) {
    SCOPED_TRACE(n);
    std::vector<std::uint8_t> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<std::uint8_t>(i * 37 + n);
    can_frame req{};
    int sent = 0;
    ASSERT_TRUE(c.start_download(4, 0x1A00, static_cast<std::uint8_t>(n % 256), v, req));
    ASSERT_EQ(run(c, server, req, sent), co::SdoStep::kDone) << std::hex << c.abort_code();
    // Expedited: one frame; segmented: the initiate + ⌈n/7⌉ segments.
    EXPECT_EQ(sent, n <= 4 ? 1 : 1 + static_cast<int>((n + 6) / 7));
    EXPECT_EQ((od.objects[{0x1A00, static_cast<std::uint8_t>(n % 256)}]), v);
    ASSERT_TRUE(c.start_upload(4, 0x1A00, static_cast<std::uint8_t>(n % 256), req));
    ASSERT_EQ(run(c, server, req, sent), co::SdoStep::kDone) << std::hex << c.abort_code();
    EXPECT_EQ(sent, n <= 4 ? 1 : 1 + static_cast<int>((n + 6) / 7));
    EXPECT_EQ(std::vector<std::uint8_t>(c.data().begin(), c.data().end()), v);
  }
  // Too long for the client: refused before anything is sent.
  can_frame req{};
  const std::vector<std::uint8_t> big(co::SdoClient::kMaxData + 1, 1);
  EXPECT_FALSE(c.start_download(4, 0x1A00, 0, big, req));
  EXPECT_FALSE(c.start_download(0, 0x1A00, 0, std::vector<std::uint8_t>{1}, req)) << "node 0";
}

TEST(CanOpenSdo, AbortsAndTimeouts) {
  TestOd od;
  od.objects[{0x2000, 1}] = {1, 2};
  co::SdoServer server(4, od);
  co::SdoClient c;
  can_frame req{};
  int sent = 0;
  // The server aborts: no such object, a read-only one.
  ASSERT_TRUE(c.start_upload(4, 0x6077, 0, req));
  EXPECT_EQ(run(c, server, req, sent), co::SdoStep::kAbort);
  EXPECT_EQ(c.abort_code(), co::kAbortNoObject);
  EXPECT_STREQ(co::abort_text(c.abort_code()), "object does not exist in the object dictionary");
  const std::uint8_t one[1] = {9};
  ASSERT_TRUE(c.start_download(4, 0x2000, 1, one, req));
  EXPECT_EQ(run(c, server, req, sent), co::SdoStep::kAbort);
  EXPECT_EQ(c.abort_code(), co::kAbortReadOnly);
  // A segment without a transfer: the server aborts (command specifier).
  can_frame seg{}, resp{};
  seg.can_id = 0x604;
  seg.len = 8;
  seg.data[0] = 0x00;
  ASSERT_TRUE(server.on_frame(seg, resp));
  EXPECT_EQ(resp.can_id, 0x584u);
  EXPECT_EQ(resp.data[0], 0x80);
  EXPECT_EQ(resp.data[4] | (resp.data[5] << 8) | (resp.data[6] << 16) | (resp.data[7] << 24),
            static_cast<int>(co::kAbortCommand));
  // Fewer bytes than the size indicated: too low.
  can_frame init{};
  init.can_id = 0x604;
  init.len = 8;
  init.data[0] = 0x21;
  init.data[1] = 0x00;
  init.data[2] = 0x30;
  init.data[4] = 9;  // 9 bytes announced
  ASSERT_TRUE(server.on_frame(init, resp));
  EXPECT_EQ(resp.data[0], 0x60);
  seg.data[0] = 0x01;  // t = 0, 7 bytes, last
  ASSERT_TRUE(server.on_frame(seg, resp));
  EXPECT_EQ(resp.data[0], 0x80);
  EXPECT_EQ(resp.data[4] | (resp.data[5] << 8) | (resp.data[6] << 16) | (resp.data[7] << 24),
            static_cast<int>(co::kAbortLengthLow));
  // No answer: the client gives up with an abort frame for the server (0x05040000).
  ASSERT_TRUE(c.start_upload(4, 0x1000, 0, req));
  can_frame abort{};
  c.timeout(abort);
  EXPECT_FALSE(c.busy());
  EXPECT_EQ(c.abort_code(), co::kAbortTimeout);
  EXPECT_EQ(bytes(abort), (std::vector<std::uint8_t>{0x80, 0x00, 0x10, 0x00, 0x00, 0x00, 0x04, 0x05}));
  // The client's abort ends the server's transfer without an answer.
  EXPECT_FALSE(server.on_frame(abort, resp));
}
