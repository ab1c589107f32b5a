// CAN codec: round trips within the documented resolution, every malformed-frame class rejected
// with its own status, counter wrap-around.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pd = pedalwave::drivers;
namespace can = pedalwave::drivers::can;
using can::CodecStatus;

namespace {

can_frame valid_feedback() {
  can::FeedbackFrame fb{{0.5, -1.25, 0.01, pd::kStatusOverTemp}, 7};
  can_frame f{};
  EXPECT_EQ(can::encode_feedback(3, fb, f), CodecStatus::kOk);
  return f;
}

}  // namespace

TEST(CanProtocol, FeedbackRoundTripWithinResolution) {
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> beta(-3.2, 3.2), rate(-32.0, 32.0), defl(-0.65, 0.65);
  std::uniform_int_distribution<int> node(1, can::kMaxNode), nib(0, 15), ctr(0, 255);
  for (int i = 0; i < 5000; ++i) {
    can::FeedbackFrame in{{beta(rng), rate(rng), defl(rng),
                           pd::wire::unpack_module_status(static_cast<std::uint8_t>(nib(rng)))},
                          static_cast<std::uint8_t>(ctr(rng))};
    const int n = node(rng);
    can_frame f{};
    ASSERT_EQ(can::encode_feedback(n, in, f), CodecStatus::kOk);
    EXPECT_EQ(f.can_id, can::kFeedbackBase + static_cast<canid_t>(n));
    can::FeedbackFrame out{};
    int n2 = 0;
    ASSERT_EQ(can::decode_feedback(f, n2, out), CodecStatus::kOk);
    EXPECT_EQ(n2, n);
    EXPECT_LE(std::abs(out.sample.beta - in.sample.beta), pd::wire::kBetaLsb / 2 + 1e-12);
    EXPECT_LE(std::abs(out.sample.beta_dot - in.sample.beta_dot), pd::wire::kBetaDotLsb / 2 + 1e-12);
    EXPECT_LE(std::abs(out.sample.deflection - in.sample.deflection), pd::wire::kDeflectionLsb / 2 + 1e-12);
    EXPECT_EQ(out.sample.status, in.sample.status);
    EXPECT_EQ(out.counter, in.counter & 0x0F);  // classic frames carry the counter mod 16
  }
}

TEST(CanProtocol, CommandAndGainsRoundTripWithinResolution) {
  std::mt19937 rng(777);
  std::uniform_real_distribution<double> tau(-32.0, 32.0), ang(-3.2, 3.2), rate(-32.0, 32.0),
      kp(0.0, 650.0), kd(0.0, 65.0);
  std::uniform_int_distribution<int> node(1, can::kMaxNode), ctr(0, 15), bit(0, 1);
  for (int i = 0; i < 5000; ++i) {
    const int n = node(rng);
    can::JointCommand c{tau(rng), ang(rng), rate(rng), bit(rng) == 1,
                        static_cast<std::uint8_t>(ctr(rng))};
    can_frame f{};
    ASSERT_EQ(can::encode_command(n, c, f), CodecStatus::kOk);
    can::JointCommand d{};
    int n2 = 0;
    ASSERT_EQ(can::decode_command(f, n2, d), CodecStatus::kOk);
    EXPECT_EQ(n2, n);
    EXPECT_LE(std::abs(d.tau - c.tau), pd::wire::kTauLsb / 2 + 1e-12);
    EXPECT_LE(std::abs(d.beta_ref - c.beta_ref), pd::wire::kBetaLsb / 2 + 1e-12);
    EXPECT_LE(std::abs(d.beta_dot_ref - c.beta_dot_ref), pd::wire::kBetaDotLsb / 2 + 1e-12);
    EXPECT_EQ(d.torque_off, c.torque_off);
    EXPECT_EQ(d.counter, c.counter);

    can::JointGains g{kp(rng), kd(rng), static_cast<std::uint8_t>(ctr(rng))};
    ASSERT_EQ(can::encode_gains(n, g, f), CodecStatus::kOk);
    can::JointGains h{};
    ASSERT_EQ(can::decode_gains(f, n2, h), CodecStatus::kOk);
    EXPECT_LE(std::abs(h.kp - g.kp), pd::wire::kKpLsb / 2 + 1e-12);
    EXPECT_LE(std::abs(h.kd - g.kd), pd::wire::kKdLsb / 2 + 1e-12);
    EXPECT_EQ(h.counter, g.counter);
  }
}

TEST(CanProtocol, FdCommandRoundTripEveryCount) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> tau(-32.0, 32.0), ang(-3.2, 3.2), rate(-32.0, 32.0),
      kp(0.0, 650.0), kd(0.0, 65.0);
  for (int count = 1; count <= can::kFdJointsPerFrame; ++count) {
    for (int rep = 0; rep < 200; ++rep) {
      can::FdCommandGroup g{};
      g.group = rep % can::kMaxFdGroups;
      g.count = count;
      g.counter = static_cast<std::uint8_t>(rep * 7);
      g.torque_off = (rep % 3) == 0;
      for (int k = 0; k < count; ++k)
        g.joint[k] = {tau(rng), ang(rng), rate(rng), kp(rng), kd(rng)};
      canfd_frame f{};
      ASSERT_EQ(can::encode_fd_command(g, f), CodecStatus::kOk);
      EXPECT_EQ(f.len, can::fd_command_len(count));
      EXPECT_LE(f.len, CANFD_MAX_DLEN);
      can::FdCommandGroup d{};
      ASSERT_EQ(can::decode_fd_command(f, d), CodecStatus::kOk);
      EXPECT_EQ(d.group, g.group);
      EXPECT_EQ(d.count, count);
      EXPECT_EQ(d.counter, g.counter);
      EXPECT_EQ(d.torque_off, g.torque_off);
      for (int k = 0; k < count; ++k) {
        EXPECT_LE(std::abs(d.joint[k].tau - g.joint[k].tau), pd::wire::kTauLsb / 2 + 1e-12);
        EXPECT_LE(std::abs(d.joint[k].beta_ref - g.joint[k].beta_ref), pd::wire::kBetaLsb / 2 + 1e-12);
        EXPECT_LE(std::abs(d.joint[k].beta_dot_ref - g.joint[k].beta_dot_ref),
                  pd::wire::kBetaDotLsb / 2 + 1e-12);
        EXPECT_LE(std::abs(d.joint[k].kp - g.joint[k].kp), pd::wire::kKpLsb / 2 + 1e-12);
        EXPECT_LE(std::abs(d.joint[k].kd - g.joint[k].kd), pd::wire::kKdLsb / 2 + 1e-12);
      }
    }
  }
  // Six joints fill exactly one 64-byte FD frame.
  EXPECT_EQ(can::fd_command_len(6), 64);
  EXPECT_EQ(can::fd_command_len(1), 16);
}

TEST(CanProtocol, SaturationAndNonFiniteAreReportedAndSafe) {
  can_frame f{};
  can::FeedbackFrame fb{{10.0, 0.0, 0.0, 0}, 0};  // β beyond ±3.2767 rad
  EXPECT_EQ(can::encode_feedback(1, fb, f), CodecStatus::kClamped);
  can::FeedbackFrame d{};
  int n = 0;
  ASSERT_EQ(can::decode_feedback(f, n, d), CodecStatus::kOk);
  EXPECT_NEAR(d.sample.beta, 32767 * pd::wire::kBetaLsb, 1e-12);

  // A NaN command goes out as torque-off.
  can::JointCommand c{std::numeric_limits<double>::quiet_NaN(), 0.1, 0.0, false, 3};
  EXPECT_EQ(can::encode_command(2, c, f), CodecStatus::kNotFinite);
  can::JointCommand dc{};
  ASSERT_EQ(can::decode_command(f, n, dc), CodecStatus::kOk);
  EXPECT_TRUE(dc.torque_off);
  EXPECT_EQ(dc.tau, 0.0);

  can::FdCommandGroup g{};
  g.count = 2;
  g.joint[1].kd = std::numeric_limits<double>::infinity();
  canfd_frame ff{};
  EXPECT_EQ(can::encode_fd_command(g, ff), CodecStatus::kNotFinite);
  can::FdCommandGroup dg{};
  ASSERT_EQ(can::decode_fd_command(ff, dg), CodecStatus::kOk);
  EXPECT_TRUE(dg.torque_off);

  // Negative gains saturate to zero.
  EXPECT_EQ(can::encode_gains(1, {-1.0, 0.5, 0}, f), CodecStatus::kClamped);
  can::JointGains dg2{};
  ASSERT_EQ(can::decode_gains(f, n, dg2), CodecStatus::kOk);
  EXPECT_EQ(dg2.kp, 0.0);

  // Encoders refuse nodes/groups outside the protocol.
  EXPECT_EQ(can::encode_feedback(0, fb, f), CodecStatus::kBadArgument);
  EXPECT_EQ(can::encode_command(64, c, f), CodecStatus::kBadArgument);
  g.count = 7;
  EXPECT_EQ(can::encode_fd_command(g, ff), CodecStatus::kBadArgument);
}

TEST(CanProtocol, MalformedFeedbackRejectedWithDistinctStatus) {
  int node = 0;
  can::FeedbackFrame fb{};
  // Wrong id: outside 0x181…0x1BF, a command id, extended/RTR/error flag.
  for (canid_t id : {can::kFeedbackBase, can::kFeedbackBase + 64u, can::kCommandBase + 1u,
                     can::kSyncId}) {
    can_frame f = valid_feedback();
    f.can_id = id;
    EXPECT_EQ(can::decode_feedback(f, node, fb), CodecStatus::kWrongId) << std::hex << id;
  }
  for (canid_t flag : {CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_ERR_FLAG}) {
    can_frame f = valid_feedback();
    f.can_id |= flag;
    EXPECT_EQ(can::decode_feedback(f, node, fb), CodecStatus::kWrongId);
  }
  // Wrong length.
  for (int len : {0, 1, 7}) {
    can_frame f = valid_feedback();
    f.len = static_cast<std::uint8_t>(len);
    EXPECT_EQ(can::decode_feedback(f, node, fb), CodecStatus::kWrongLength);
  }
  // Every single-bit error in the payload and in the id's node bits fails the CRC-8.
  const can_frame good = valid_feedback();
  for (int byte = 0; byte < 8; ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      can_frame f = good;
      f.data[byte] ^= static_cast<std::uint8_t>(1u << bit);
      EXPECT_EQ(can::decode_feedback(f, node, fb), CodecStatus::kChecksum) << byte << "/" << bit;
      EXPECT_EQ(node, 3);
    }
  }
  for (int bit = 0; bit < 5; ++bit) {  // another valid node id, but the CRC covers the id
    can_frame f = good;
    f.can_id ^= (1u << bit);
    EXPECT_EQ(can::decode_feedback(f, node, fb), CodecStatus::kChecksum);
  }
}

TEST(CanProtocol, MalformedCommandSyncGainsFdRejected) {
  int node = 0;
  can_frame f{};
  can::JointCommand c{0.1, 0.2, 0.3, false, 1};
  ASSERT_EQ(can::encode_command(5, c, f), CodecStatus::kOk);
  can::JointCommand dc{};
  can_frame g = f;
  g.can_id = can::kGainsBase + 5;
  EXPECT_EQ(can::decode_command(g, node, dc), CodecStatus::kWrongId);
  g = f;
  g.len = 6;
  EXPECT_EQ(can::decode_command(g, node, dc), CodecStatus::kWrongLength);
  g = f;
  g.data[2] ^= 0x40;
  EXPECT_EQ(can::decode_command(g, node, dc), CodecStatus::kChecksum);

  // SYNC.
  ASSERT_EQ(can::encode_sync(200, f), CodecStatus::kOk);
  std::uint8_t ctr = 0;
  ASSERT_EQ(can::decode_sync(f, ctr), CodecStatus::kOk);
  EXPECT_EQ(ctr, 200);
  g = f;
  g.can_id = 0x081;
  EXPECT_EQ(can::decode_sync(g, ctr), CodecStatus::kWrongId);
  g = f;
  g.len = 1;
  EXPECT_EQ(can::decode_sync(g, ctr), CodecStatus::kWrongLength);
  g = f;
  g.data[0] ^= 1;
  EXPECT_EQ(can::decode_sync(g, ctr), CodecStatus::kChecksum);

  // Gains.
  can::JointGains jg{};
  ASSERT_EQ(can::encode_gains(2, {30.0, 15.0, 4}, f), CodecStatus::kOk);
  g = f;
  g.can_id = can::kFeedbackBase + 2;
  EXPECT_EQ(can::decode_gains(g, node, jg), CodecStatus::kWrongId);
  g = f;
  g.len = 2;
  EXPECT_EQ(can::decode_gains(g, node, jg), CodecStatus::kWrongLength);
  g = f;
  g.data[0] ^= 0x10;
  EXPECT_EQ(can::decode_gains(g, node, jg), CodecStatus::kChecksum);

  // FD command group.
  can::FdCommandGroup grp{};
  grp.group = 1;
  grp.count = 4;
  canfd_frame ff{};
  ASSERT_EQ(can::encode_fd_command(grp, ff), CodecStatus::kOk);
  can::FdCommandGroup dg{};
  canfd_frame h = ff;
  h.can_id = can::kFdCommandBase + can::kMaxFdGroups;
  EXPECT_EQ(can::decode_fd_command(h, dg), CodecStatus::kWrongId);
  h = ff;
  h.len = 8;
  EXPECT_EQ(can::decode_fd_command(h, dg), CodecStatus::kWrongLength);
  h = ff;
  h.data[17] ^= 0x01;
  EXPECT_EQ(can::decode_fd_command(h, dg), CodecStatus::kChecksum);
}

// Frames whose CRC is right but whose fields are impossible (reserved bits in a classic command,
// joint count 7 in an FD frame; an FD count that disagrees with the length is a length error).
// The field is patched and the matching CRC found by trying every CRC value.
TEST(CanProtocol, ImpossibleFieldsWithValidCrcAreBadField) {
  can_frame f{};
  ASSERT_EQ(can::encode_command(1, {0.0, 0.0, 0.0, false, 0}, f), CodecStatus::kOk);
  f.data[6] |= 0x80;
  int node = 0;
  can::JointCommand c{};
  int hits = 0;
  for (int crc = 0; crc < 256; ++crc) {
    f.data[7] = static_cast<std::uint8_t>(crc);
    const CodecStatus s = can::decode_command(f, node, c);
    if (s != CodecStatus::kChecksum) {
      EXPECT_EQ(s, CodecStatus::kBadField);
      ++hits;
    }
  }
  EXPECT_EQ(hits, 1);  // exactly one CRC value matches, and then the field check fires

  // FD: a 16-byte frame (count 1) whose count field says 2 → length mismatch.
  can::FdCommandGroup g{};
  g.count = 1;
  canfd_frame ff{};
  ASSERT_EQ(can::encode_fd_command(g, ff), CodecStatus::kOk);
  ff.data[1] = static_cast<std::uint8_t>(1u << 4);  // count-1 = 1 → 2 joints
  int found = 0;
  for (int lo = 0; lo < 256 && !found; ++lo)
    for (int hi = 0; hi < 256; ++hi) {
      ff.data[14] = static_cast<std::uint8_t>(lo);
      ff.data[15] = static_cast<std::uint8_t>(hi);
      can::FdCommandGroup d{};
      const CodecStatus s = can::decode_fd_command(ff, d);
      if (s != CodecStatus::kChecksum) {
        EXPECT_EQ(s, CodecStatus::kWrongLength);
        found = 1;
        break;
      }
    }
  EXPECT_EQ(found, 1);
  ff.data[1] = static_cast<std::uint8_t>(6u << 4);  // count 7: impossible
  found = 0;
  for (int lo = 0; lo < 256 && !found; ++lo)
    for (int hi = 0; hi < 256; ++hi) {
      ff.data[14] = static_cast<std::uint8_t>(lo);
      ff.data[15] = static_cast<std::uint8_t>(hi);
      can::FdCommandGroup d{};
      const CodecStatus s = can::decode_fd_command(ff, d);
      if (s != CodecStatus::kChecksum) {
        EXPECT_EQ(s, CodecStatus::kBadField);
        found = 1;
        break;
      }
    }
  EXPECT_EQ(found, 1);
}

TEST(CanProtocol, CounterWrapAround) {
  // SYNC carries 8 bits: 255 → 0 survives the round trip.
  can_frame f{};
  for (unsigned c : {254u, 255u, 0u, 1u}) {
    ASSERT_EQ(can::encode_sync(static_cast<std::uint8_t>(c), f), CodecStatus::kOk);
    std::uint8_t d = 0xAA;
    ASSERT_EQ(can::decode_sync(f, d), CodecStatus::kOk);
    EXPECT_EQ(d, c);
  }
  // Classic feedback echoes c mod 16: 15 → 0 wraps like the SYNC counter 255 → 0.
  for (unsigned c = 250; c < 262; ++c) {
    can::FeedbackFrame fb{};
    fb.counter = static_cast<std::uint8_t>(c & 0xFF);
    ASSERT_EQ(can::encode_feedback(1, fb, f), CodecStatus::kOk);
    can::FeedbackFrame d{};
    int node = 0;
    ASSERT_EQ(can::decode_feedback(f, node, d), CodecStatus::kOk);
    EXPECT_EQ(d.counter, c & 0x0F);
  }
}

// The timing record (PROTOCOL.md §1.1): classic timing frame and the 16-byte FD feedback frame.
TEST(CanTiming, TimingFrameRoundTripAndChecksum) {
  namespace can = pedalwave::drivers::can;
  namespace wire = pedalwave::drivers::wire;
  const wire::ModuleTiming t{0xFEDCBA98u, 1234, false, 0x0B};
  can_frame f{};
  ASSERT_EQ(can::encode_timing(5, t, 0x27, f), can::CodecStatus::kOk);
  EXPECT_EQ(f.can_id, can::kTimingBase + 5);
  int node = 0;
  wire::ModuleTiming back{};
  std::uint8_t echo = 0;
  ASSERT_EQ(can::decode_timing(f, node, back, echo), can::CodecStatus::kOk);
  EXPECT_EQ(node, 5);
  EXPECT_EQ(back.sample_us, t.sample_us);
  EXPECT_EQ(back.applied_age_us, 1234);
  EXPECT_FALSE(back.no_command);
  EXPECT_EQ(back.applied_tag, 0x0B);
  EXPECT_EQ(echo, 0x07);  // c mod 16
  // "no command" and a saturated age survive; any flipped bit fails the CRC.
  const wire::ModuleTiming off{7, 60000, true, 3};
  ASSERT_EQ(can::encode_timing(1, off, 0, f), can::CodecStatus::kOk);
  ASSERT_EQ(can::decode_timing(f, node, back, echo), can::CodecStatus::kOk);
  EXPECT_TRUE(back.no_command);
  EXPECT_EQ(back.applied_age_us, wire::kAgeMaxUs);
  for (int bit = 0; bit < 56; ++bit) {
    can_frame g = f;
    g.data[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
    EXPECT_EQ(can::decode_timing(g, node, back, echo), can::CodecStatus::kChecksum) << bit;
  }
}

TEST(CanTiming, FdFeedbackCarriesTheTimingRecord) {
  namespace can = pedalwave::drivers::can;
  namespace wire = pedalwave::drivers::wire;
  const can::FeedbackFrame fb{{0.5, -1.25, 0.01, pedalwave::drivers::kStatusSaturated}, 9};
  const wire::ModuleTiming t{123456789u, 800, false, 0xC3};
  canfd_frame f{};
  ASSERT_EQ(can::encode_feedback_fd(3, fb, t, f), can::CodecStatus::kOk);
  EXPECT_EQ(f.len, can::kFdFeedbackLen);
  EXPECT_EQ(f.can_id, can::kFeedbackBase + 3);
  int node = 0;
  can::FeedbackFrame b{};
  wire::ModuleTiming bt{};
  ASSERT_EQ(can::decode_feedback_fd(f, node, b, bt), can::CodecStatus::kOk);
  EXPECT_EQ(node, 3);
  EXPECT_NEAR(b.sample.beta, 0.5, 0.5e-4);
  EXPECT_NEAR(b.sample.beta_dot, -1.25, 0.5e-3);
  EXPECT_NEAR(b.sample.deflection, 0.01, 1e-5);
  EXPECT_EQ(b.counter, 9);
  EXPECT_EQ(bt.sample_us, t.sample_us);
  EXPECT_EQ(bt.applied_age_us, 800);
  EXPECT_EQ(bt.applied_tag, 0xC3);
  for (int bit = 0; bit < 14 * 8; ++bit) {
    canfd_frame g = f;
    g.data[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
    EXPECT_EQ(can::decode_feedback_fd(g, node, b, bt), can::CodecStatus::kChecksum) << bit;
  }
  canfd_frame shorter = f;
  shorter.len = 12;
  EXPECT_EQ(can::decode_feedback_fd(shorter, node, b, bt), can::CodecStatus::kWrongLength);
}
