// Pure CANopen codec tests: SDO client state machines against scripted server frames, CiA 402
// decoding and sequencing, PDO packing, scaling with 32-bit wrap-around, bus-load figures.
#include <gtest/gtest.h>

#include <random>

#include "drivers/canopen/codec.hpp"

namespace co = contour::drivers::canopen;
using contour::drivers::CanFrame;

namespace {
CanFrame resp(std::uint8_t node, std::initializer_list<int> bytes) {
  CanFrame f;
  f.id = 0x580u + node;
  f.dlc = 8;
  std::size_t i = 0;
  for (int b : bytes) f.data[i++] = static_cast<std::uint8_t>(b);
  return f;
}
}  // namespace

TEST(SdoClient, ExpeditedDownloadUsesSizeSpecificCommandSpecifiers) {
  co::SdoTransfer t;
  const std::uint8_t one[1] = {9};
  CanFrame r = t.start_download(5, 0x6060, 0, one);
  EXPECT_EQ(r.id, 0x605u);
  EXPECT_EQ(r.dlc, 8);
  EXPECT_EQ(r.data[0], 0x2F);
  EXPECT_EQ(r.data[1], 0x60);
  EXPECT_EQ(r.data[2], 0x60);
  EXPECT_EQ(r.data[3], 0x00);
  EXPECT_EQ(r.data[4], 9);
  const std::uint8_t two[2] = {0x32, 0x00};
  EXPECT_EQ(t.start_download(5, 0x1017, 0, two).data[0], 0x2B);
  const std::uint8_t three[3] = {1, 2, 3};
  EXPECT_EQ(t.start_download(5, 0x2000, 0, three).data[0], 0x27);
  const std::uint8_t four[4] = {0x10, 0x00, 0x40, 0x60};
  r = t.start_download(5, 0x1600, 1, four);
  EXPECT_EQ(r.data[0], 0x23);
  EXPECT_FALSE(t.on_frame(resp(5, {0x60, 0x00, 0x16, 0x01})).has_value());
  EXPECT_EQ(t.status(), co::SdoTransfer::Status::kDone);
}

TEST(SdoClient, ExpeditedUploadAndMultiplexerMismatch) {
  co::SdoTransfer t;
  CanFrame r = t.start_upload(1, 0x1000, 0);
  EXPECT_EQ(r.data[0], 0x40);
  t.on_frame(resp(1, {0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00}));
  ASSERT_EQ(t.status(), co::SdoTransfer::Status::kDone);
  ASSERT_EQ(t.data().size(), 4u);
  EXPECT_EQ(t.data()[0], 0x92);
  t.start_upload(1, 0x6061, 0);
  t.on_frame(resp(1, {0x4F, 0x61, 0x60, 0x00, 0x09}));
  ASSERT_EQ(t.data().size(), 1u);
  // wrong index in the answer -> the client aborts
  t.start_upload(1, 0x6061, 0);
  auto a = t.on_frame(resp(1, {0x4F, 0x60, 0x60, 0x00, 0x09}));
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->data[0], 0x80);
  EXPECT_EQ(t.status(), co::SdoTransfer::Status::kAborted);
  // frames of other nodes are ignored
  t.start_upload(1, 0x6061, 0);
  EXPECT_FALSE(t.on_frame(resp(2, {0x4F, 0x61, 0x60, 0x00, 0x09})).has_value());
  EXPECT_EQ(t.status(), co::SdoTransfer::Status::kWaiting);
}

TEST(SdoClient, SegmentedUploadTogglesAndChecksSize) {
  co::SdoTransfer t;
  t.start_upload(3, 0x1008, 0);
  auto r = t.on_frame(resp(3, {0x41, 0x08, 0x10, 0x00, 10, 0, 0, 0}));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->data[0], 0x60);
  r = t.on_frame(resp(3, {0x00, 'c', 'o', 'n', 't', 'o', 'u', 'r'}));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->data[0], 0x70);
  // last segment: toggle 1, 4 unused bytes (n = 4 -> bits 3..1 = 100), c = 1 -> 0x19
  r = t.on_frame(resp(3, {0x19, '-', 's', 'x', 0, 0, 0, 0}));
  EXPECT_FALSE(r);
  ASSERT_EQ(t.status(), co::SdoTransfer::Status::kDone);
  EXPECT_EQ(std::string(t.data().begin(), t.data().end()), "contour-sx");
  // toggle error
  t.start_upload(3, 0x1008, 0);
  t.on_frame(resp(3, {0x41, 0x08, 0x10, 0x00, 10, 0, 0, 0}));
  r = t.on_frame(resp(3, {0x10, 'x', 'x', 'x', 'x', 'x', 'x', 'x'}));
  ASSERT_TRUE(r);
  EXPECT_EQ(t.abort_code(), 0x05030000u);
}

TEST(SdoClient, SegmentedDownloadSplitsIntoSevenByteSegments) {
  co::SdoTransfer t;
  std::vector<std::uint8_t> d(10);
  for (std::size_t i = 0; i < d.size(); ++i) d[i] = static_cast<std::uint8_t>(i + 1);
  CanFrame r = t.start_download(2, 0x2001, 1, d);
  EXPECT_EQ(r.data[0], 0x21);
  EXPECT_EQ(co::get_u32(&r.data[4]), 10u);
  auto s = t.on_frame(resp(2, {0x60, 0x01, 0x20, 0x01}));
  ASSERT_TRUE(s);
  EXPECT_EQ(s->data[0], 0x00);  // toggle 0, 7 bytes, not last
  EXPECT_EQ(s->data[7], 7);
  s = t.on_frame(resp(2, {0x20}));
  ASSERT_TRUE(s);
  EXPECT_EQ(s->data[0], 0x10 | (4 << 1) | 1);  // toggle 1, 4 unused, last
  EXPECT_EQ(s->data[3], 10);
  EXPECT_FALSE(t.on_frame(resp(2, {0x30})));
  EXPECT_EQ(t.status(), co::SdoTransfer::Status::kDone);
}

TEST(SdoClient, ServerAbortIsDecodedToText) {
  co::SdoTransfer t;
  t.start_upload(7, 0x2222, 0);
  t.on_frame(resp(7, {0x80, 0x22, 0x22, 0x00, 0x00, 0x00, 0x02, 0x06}));
  EXPECT_EQ(t.status(), co::SdoTransfer::Status::kAborted);
  EXPECT_TRUE(t.abort_from_server());
  EXPECT_EQ(co::sdo_abort_text(t.abort_code()),
            "0x06020000 object does not exist in the object dictionary");
  EXPECT_EQ(co::sdo_abort_text(0x12345678), "0x12345678 unknown abort code");
  const CanFrame to = t.timeout_abort();
  EXPECT_EQ(co::get_u32(&to.data[4]), 0x05040000u);
}

TEST(Cia402, StatuswordDecodingFollowsTheMaskTable) {
  EXPECT_EQ(co::decode_statusword(0x0250), co::Cia402State::kSwitchOnDisabled);
  EXPECT_EQ(co::decode_statusword(0x0231), co::Cia402State::kReadyToSwitchOn);
  EXPECT_EQ(co::decode_statusword(0x0233), co::Cia402State::kSwitchedOn);
  EXPECT_EQ(co::decode_statusword(0x1237), co::Cia402State::kOperationEnabled);
  EXPECT_EQ(co::decode_statusword(0x0217), co::Cia402State::kQuickStopActive);
  EXPECT_EQ(co::decode_statusword(0x021F), co::Cia402State::kFaultReactionActive);
  EXPECT_EQ(co::decode_statusword(0x0218), co::Cia402State::kFault);
  EXPECT_EQ(co::decode_statusword(0x0000), co::Cia402State::kNotReadyToSwitchOn);
  for (auto s : {co::Cia402State::kSwitchOnDisabled, co::Cia402State::kReadyToSwitchOn,
                 co::Cia402State::kSwitchedOn, co::Cia402State::kOperationEnabled,
                 co::Cia402State::kQuickStopActive, co::Cia402State::kFaultReactionActive,
                 co::Cia402State::kFault})
    EXPECT_EQ(co::decode_statusword(co::statusword_for(s)), s);
}

TEST(Cia402, SequencerEnablesQuickStopsAndResetsFaultsWithAnEdge) {
  co::Cia402Sequencer seq;
  co::Cia402State s = co::Cia402State::kSwitchOnDisabled;
  std::uint16_t prev = 0;
  int steps = 0;
  std::vector<std::uint16_t> sent;
  while (s != co::Cia402State::kOperationEnabled && steps++ < 10) {
    const auto cw = seq.next(s, co::DriveRequest::kEnabled, false);
    sent.push_back(cw);
    s = co::drive_transition(s, cw, prev, 2, false);
    prev = cw;
  }
  EXPECT_EQ(sent, (std::vector<std::uint16_t>{0x0006, 0x0007, 0x000F}));
  EXPECT_EQ(seq.next(s, co::DriveRequest::kQuickStop, false), 0x0002);
  s = co::drive_transition(s, 0x0002, 0x000F, 2, false);
  EXPECT_EQ(s, co::Cia402State::kQuickStopActive);
  s = co::drive_transition(s, 0x0002, 0x0002, 2, true);  // option 2: off after the ramp
  EXPECT_EQ(s, co::Cia402State::kSwitchOnDisabled);
  // fault: no reset unless allowed; then 0x0080 rising edge, and the drive leaves Fault
  s = co::Cia402State::kFault;
  EXPECT_EQ(seq.next(s, co::DriveRequest::kEnabled, false), 0x0000);
  const auto cw = seq.next(s, co::DriveRequest::kEnabled, true);
  EXPECT_EQ(cw, 0x0080);
  EXPECT_EQ(co::drive_transition(s, cw, 0x0000, 2, false), co::Cia402State::kSwitchOnDisabled);
  // a held bit 7 is not an edge
  EXPECT_EQ(co::drive_transition(s, 0x0080, 0x0080, 2, false), co::Cia402State::kFault);
  EXPECT_EQ(seq.next(s, co::DriveRequest::kEnabled, true), 0x0000);  // drops for the next edge
  // An operator reset with the drives still requested disabled (FAULT state) sends the edge too.
  co::Cia402Sequencer seq2;
  EXPECT_EQ(seq2.next(s, co::DriveRequest::kDisabled, false), 0x0000);
  EXPECT_EQ(seq2.next(s, co::DriveRequest::kDisabled, true), 0x0080);
}

TEST(Pdo, PackUnpackLittleEndianRoundTripRandomised) {
  std::mt19937 rng(42);
  co::PdoMapping m;
  m.entries[0] = {0x6040, 0, 16};
  m.entries[1] = {0x60FF, 0, 32};
  m.entries[2] = {0x6060, 0, 8};
  m.count = 3;
  EXPECT_EQ(m.bytes(), 7u);
  EXPECT_EQ(m.validate(), "");
  for (int k = 0; k < 1000; ++k) {
    co::PdoValues v{};
    v[0] = rng() & 0xFFFF;
    v[1] = static_cast<std::uint32_t>(rng());
    v[2] = rng() & 0xFF;
    CanFrame f;
    co::pack_pdo(m, v, f);
    ASSERT_EQ(f.dlc, 7);
    EXPECT_EQ(f.data[0], v[0] & 0xFF);
    EXPECT_EQ(f.data[1], (v[0] >> 8) & 0xFF);
    EXPECT_EQ(f.data[2], v[1] & 0xFF);
    EXPECT_EQ(f.data[5], (v[1] >> 24) & 0xFF);
    co::PdoValues u{};
    ASSERT_TRUE(co::unpack_pdo(m, f, u));
    for (int i = 0; i < 3; ++i) EXPECT_EQ(u[static_cast<std::size_t>(i)], v[static_cast<std::size_t>(i)]);
  }
  CanFrame shortf;
  shortf.dlc = 3;
  co::PdoValues u{};
  EXPECT_FALSE(co::unpack_pdo(m, shortf, u));
  m.entries[3] = {0x6064, 0, 32};
  m.count = 4;
  EXPECT_NE(m.validate(), "");  // 88 bits
  EXPECT_EQ((co::PdoEntry{0x6064, 0, 32}.mapping_word()), 0x60640020u);
}

TEST(Scaling, UnwrapperFollowsAcross32BitWrapBothWays) {
  co::PositionUnwrapper u;
  u.reset(2147483000);
  std::int64_t expect = 2147483000;
  std::int64_t raw = expect;
  for (int k = 0; k < 3000; ++k) {  // forward over +2^31
    raw += 1000;
    expect += 1000;
    EXPECT_EQ(u.update(static_cast<std::int32_t>(static_cast<std::uint32_t>(raw & 0xFFFFFFFF))), expect);
  }
  for (int k = 0; k < 6000; ++k) {  // and back
    raw -= 1000;
    expect -= 1000;
    EXPECT_EQ(u.update(static_cast<std::int32_t>(static_cast<std::uint32_t>(raw & 0xFFFFFFFF))), expect);
  }
  EXPECT_EQ(co::mm_to_counts_wrapped(1.0, 2000.0), 2000);
  EXPECT_EQ(co::mm_to_counts_wrapped(2147483648.0 / 2000.0, 2000.0), -2147483647 - 1);
  EXPECT_DOUBLE_EQ(co::counts_to_mm(-3000, 2000.0), -1.5);
  EXPECT_EQ(co::mm_s_to_counts_s(1e12, 2000.0), 2147483647);
  EXPECT_EQ(co::mm_s_to_counts_s(-0.00025, 2000.0), -1);  // rounds half away from zero
}

TEST(BusLoad, MatchesTheNotesTable) {
  EXPECT_EQ(co::frame_bits_nominal(0), 47);
  EXPECT_EQ(co::frame_bits_worst(0), 55);
  for (int n = 0; n <= 8; ++n) EXPECT_EQ(co::frame_bits_worst(n), 55 + 10 * n) << n;
  std::vector<co::CyclicFrame> three{{0, 1}};
  for (int i = 0; i < 3; ++i) {
    three.push_back({6, 1});
    three.push_back({6, 1});
  }
  auto l = co::estimate_bus_load(three, 1e6, 1e-3);
  EXPECT_NEAR(l.nominal, 0.617, 1e-9);
  EXPECT_NEAR(l.worst_case, 0.745, 1e-9);
  auto four = three;
  four.push_back({6, 1});
  four.push_back({6, 1});
  l = co::estimate_bus_load(four, 1e6, 1e-3);
  EXPECT_NEAR(l.nominal, 0.807, 1e-9);
  EXPECT_NEAR(l.worst_case, 0.975, 1e-9);
}

TEST(Emcy, DecodeAndText) {
  co::Emcy e;
  e.code = 0x2310;
  e.error_register = 0x03;
  const CanFrame f = co::emcy_frame(2, e);
  EXPECT_EQ(f.id, 0x82u);
  EXPECT_EQ(f.data[0], 0x10);
  EXPECT_EQ(f.data[1], 0x23);
  auto d = co::decode_emcy(f);
  ASSERT_TRUE(d);
  EXPECT_EQ(d->code, 0x2310);
  EXPECT_STREQ(co::emcy_code_text(0x2310), "continuous over-current");
  EXPECT_STREQ(co::emcy_code_text(0x2399), "current, device output side");
  CanFrame shortf = f;
  shortf.dlc = 3;
  EXPECT_FALSE(co::decode_emcy(shortf));
  EXPECT_FALSE(co::decode_heartbeat(shortf));
  EXPECT_EQ(co::nmt_frame(co::NmtCommand::kResetCommunication, 0).data[0], 0x82);
  EXPECT_EQ(co::decode_heartbeat(co::heartbeat_frame(4, co::NmtState::kOperational)),
            co::NmtState::kOperational);
}
