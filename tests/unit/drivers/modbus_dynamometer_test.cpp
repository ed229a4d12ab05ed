// DynamometerReader against the simulated DynamometerServer on loopback (127.0.0.1, a free port
// per test): decoding of every register type and word order to newtons, timeout / exception /
// connection drop / server restart recovery without restarting the reader (counted in status),
// stale detection, achieved poll rate, RT-side read without allocation, and mbpoll (an
// independent Modbus client) reading the same values.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "drivers/modbus/dynamometer_reader.hpp"
#include "drivers/modbus/register_codec.hpp"
#include "tests/support/alloc_counter.hpp"
// DynamometerServer lives in contour-machine-sim, which is not a library (see report).
#include "tools/contour-machine-sim/dynamometer_server.cpp"

namespace dm = contour::drivers::modbus;
using contour::sim::DynamometerServer;
using contour::sim::FaultMode;
using namespace std::chrono_literals;

namespace {

dm::RegisterMap make_map(dm::RegisterType t, dm::WordOrder o, dm::RegisterFunction fn) {
  dm::RegisterMap m;
  m.function = fn;
  const bool is_int = t != dm::RegisterType::kFloat32;
  for (std::size_t c = 0; c < 3; ++c) {
    dm::ChannelMap& ch = m.channels[c];
    ch.enabled = true;
    ch.address = static_cast<std::uint16_t>(2 + 2 * c);
    ch.type = t;
    ch.order = o;
    ch.scale = is_int ? 0.1 : 1.0;
    ch.offset_N = t == dm::RegisterType::kUint16 ? -2000.0 : 0.0;
  }
  m.status = {true, 0, 2, true};
  return m;
}

dm::DynamometerSettings settings_for(const dm::RegisterMap& m, int port, double rate_hz = 200.0) {
  dm::DynamometerSettings s;
  s.transport.transport = dm::Transport::kTcp;
  s.transport.host = "127.0.0.1";
  s.transport.port = port;
  s.transport.response_timeout = 20ms;
  s.map = m;
  s.poll_rate_hz = rate_hz;
  s.stale_after = 50ms;
  s.reconnect_min = 20ms;
  s.reconnect_max = 200ms;
  return s;
}

contour::sim::ForceModelParams quiet_model() {
  contour::sim::ForceModelParams p;
  p.noise_std_N = 0.0;
  return p;
}

// Waits until pred(reading) holds, polling the RT side every 1 ms; returns false on timeout.
template <typename Pred>
bool wait_for(dm::DynamometerReader& r, Pred pred, std::chrono::milliseconds limit,
              dm::ForceReading* out = nullptr) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < end) {
    const dm::ForceReading x = r.read(dm::steady_now_ns());
    if (pred(x)) {
      if (out) *out = x;
      return true;
    }
    std::this_thread::sleep_for(1ms);
  }
  return false;
}

struct Loop {
  explicit Loop(dm::RegisterMap m = make_map(dm::RegisterType::kFloat32, dm::WordOrder::kAbcd,
                                             dm::RegisterFunction::kInput))
      : map(m), server(m, quiet_model()) {
    server.start("127.0.0.1", 0);
    server.set_fixed_forces(std::array<double, 3>{100.0, -50.0, 25.0});
    reader = std::make_unique<dm::DynamometerReader>(settings_for(map, server.port()));
    reader->start();
  }
  dm::RegisterMap map;
  DynamometerServer server;
  std::unique_ptr<dm::DynamometerReader> reader;
};

std::uint64_t seq_now(dm::DynamometerReader& r) { return r.read(dm::steady_now_ns()).sample.seq; }

}  // namespace

TEST(ModbusDynamometer, AllTypesAndWordOrdersDecodeToNewtons) {
  const dm::RegisterType types[] = {dm::RegisterType::kInt16, dm::RegisterType::kUint16,
                                    dm::RegisterType::kInt32, dm::RegisterType::kFloat32};
  const dm::WordOrder orders[] = {dm::WordOrder::kAbcd, dm::WordOrder::kBadc, dm::WordOrder::kCdab,
                                  dm::WordOrder::kDcba};
  const std::array<double, 3> want{123.4, -56.7, 890.1};
  int checked = 0;
  for (auto t : types) {
    for (auto o : orders) {
      for (auto fn : {dm::RegisterFunction::kInput, dm::RegisterFunction::kHolding}) {
        const dm::RegisterMap m = make_map(t, o, fn);
        DynamometerServer server(m, quiet_model());
        server.start("127.0.0.1", 0);
        server.set_fixed_forces(want);
        dm::DynamometerReader reader(settings_for(m, server.port()));
        reader.start();
        dm::ForceReading r;
        ASSERT_TRUE(wait_for(
            reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s,
            &r))
            << dm::to_string(t) << "/" << dm::to_string(o) << ": " << reader.status().last_error;
        const double tol = t == dm::RegisterType::kFloat32 ? 1e-4 : 0.05 + 1e-9;
        for (std::size_t c = 0; c < 3; ++c) {
          EXPECT_NEAR(r.sample.force_N[c], want[c], tol)
              << dm::to_string(t) << "/" << dm::to_string(o) << " channel " << c;
        }
        EXPECT_EQ(r.sample.raw_start, 0);
        EXPECT_EQ(r.sample.raw_count, dm::register_block(m).count);
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 32);
}

TEST(ModbusDynamometer, StatusBitInvalidIsReportedInvalid) {
  Loop l;
  l.server.set_status_valid(false);
  EXPECT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kInvalid; },
      2s));
  EXPECT_GT(l.reader->status().invalid, 0u);
  l.server.set_status_valid(true);
  EXPECT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
}

TEST(ModbusDynamometer, TimeoutGoesStaleThenRecoversCounted) {
  Loop l;
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
  l.server.set_fault(FaultMode::kNoReply);
  dm::ForceReading r;
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kStale; }, 1s,
      &r));
  EXPECT_GT(r.age_ns, 50'000'000);
  std::this_thread::sleep_for(150ms);
  const dm::DynamometerStatus during = l.reader->status();
  EXPECT_GE(during.timeouts, 3u);
  EXPECT_NE(during.last_error.find("timed out"), std::string::npos) << during.last_error;
  const std::uint64_t polls0 = during.polls;
  l.server.set_fault(FaultMode::kNone);
  ASSERT_TRUE(wait_for(
      *l.reader,
      [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk && x.fresh; }, 2s));
  const dm::DynamometerStatus after = l.reader->status();
  std::printf(
      "[figure] timeout recovery: %llu polls after the fault cleared (timeouts=%llu, "
      "reconnects=%llu)\n",
      static_cast<unsigned long long>(after.polls - polls0),
      static_cast<unsigned long long>(after.timeouts),
      static_cast<unsigned long long>(after.reconnects));
  EXPECT_LE(after.polls - polls0, 3u);
}

TEST(ModbusDynamometer, ExceptionReplyDecodedAndCounted) {
  Loop l;
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
  l.server.set_fault(FaultMode::kException, 0ms, 2);
  std::this_thread::sleep_for(100ms);
  const dm::DynamometerStatus st = l.reader->status();
  EXPECT_GE(st.exceptions, 5u);
  EXPECT_NE(st.last_error.find("illegal data address"), std::string::npos) << st.last_error;
  EXPECT_EQ(st.reconnects, 0u);  // an exception is a reply: the link is fine
  const std::uint64_t polls0 = st.polls;
  l.server.set_fault(FaultMode::kNone);
  ASSERT_TRUE(wait_for(
      *l.reader,
      [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk && x.fresh; }, 2s));
  std::printf("[figure] exception recovery: %llu polls\n",
              static_cast<unsigned long long>(l.reader->status().polls - polls0));
  EXPECT_LE(l.reader->status().polls - polls0, 2u);
}

TEST(ModbusDynamometer, DelayedReplyBeyondTimeoutIsATimeout) {
  Loop l;
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
  l.server.set_fault(FaultMode::kDelay, 40ms);
  std::this_thread::sleep_for(300ms);
  EXPECT_GE(l.reader->status().timeouts, 2u);
  l.server.set_fault(FaultMode::kDelay, 2ms);  // within the 20 ms timeout: fine
  const std::uint64_t s0 = seq_now(*l.reader);
  const bool ok = wait_for(
      *l.reader,
      [s0](const dm::ForceReading& x) {
        return x.state == dm::ForceState::kOk && x.sample.seq > s0 + 5;
      },
      3s);
  const dm::DynamometerStatus st = l.reader->status();
  ASSERT_TRUE(ok) << "polls " << st.polls << " samples " << st.samples << " timeouts "
                  << st.timeouts << " protocol " << st.protocol_errors << " conn "
                  << st.connection_errors << " reconnects " << st.reconnects
                  << " last: " << st.last_error;
  EXPECT_NEAR(l.reader->read(dm::steady_now_ns()).sample.force_N[0], 100.0, 1e-4);
}

TEST(ModbusDynamometer, ConnectionDropReconnects) {
  Loop l;
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
  l.server.set_fault(FaultMode::kDropConnection);
  std::this_thread::sleep_for(60ms);
  const std::uint64_t polls0 = l.reader->status().polls;
  l.server.set_fault(FaultMode::kNone);
  const std::uint64_t s0 = seq_now(*l.reader);
  ASSERT_TRUE(wait_for(
      *l.reader,
      [s0](const dm::ForceReading& x) {
        return x.state == dm::ForceState::kOk && x.sample.seq > s0;
      },
      3s));
  const dm::DynamometerStatus st = l.reader->status();
  EXPECT_GE(st.reconnects, 1u);
  EXPECT_GE(st.connection_errors, 1u);
  std::printf("[figure] drop recovery: %llu polls, reconnects=%llu\n",
              static_cast<unsigned long long>(st.polls - polls0),
              static_cast<unsigned long long>(st.reconnects));
}

TEST(ModbusDynamometer, ServerRestartRecoversWithoutRestartingReader) {
  Loop l;
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
  l.server.stop();
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kStale; }, 1s));
  std::this_thread::sleep_for(300ms);  // reader sees refused connects with backoff
  EXPECT_FALSE(l.reader->status().connected);
  const auto t0 = std::chrono::steady_clock::now();
  l.server.start("127.0.0.1", 0);  // same port as before
  l.server.set_fixed_forces(std::array<double, 3>{7.0, 8.0, 9.0});
  dm::ForceReading r;
  ASSERT_TRUE(wait_for(
      *l.reader,
      [](const dm::ForceReading& x) {
        return x.state == dm::ForceState::kOk && x.sample.force_N[2] > 8.5;
      },
      3s, &r));
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const dm::DynamometerStatus st = l.reader->status();
  EXPECT_GE(st.reconnects, 1u);
  EXPECT_GE(st.connection_errors, 2u);
  EXPECT_LT(ms, 500.0);  // backoff capped at 200 ms in this test
  std::printf(
      "[figure] server restart: data back %.1f ms after restart (backoff max 200 ms), "
      "reconnects=%llu connection_errors=%llu\n",
      ms, static_cast<unsigned long long>(st.reconnects),
      static_cast<unsigned long long>(st.connection_errors));
}

TEST(ModbusDynamometer, AchievedPollRateOnLoopback) {
  for (double rate : {200.0, 1000.0}) {
    const dm::RegisterMap m =
        make_map(dm::RegisterType::kFloat32, dm::WordOrder::kAbcd, dm::RegisterFunction::kInput);
    DynamometerServer server(m, quiet_model());
    server.start("127.0.0.1", 0);
    dm::DynamometerReader reader(settings_for(m, server.port(), rate));
    reader.start();
    ASSERT_TRUE(wait_for(
        reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
    const std::uint64_t s0 = reader.status().samples;
    const auto t0 = std::chrono::steady_clock::now();
    std::this_thread::sleep_for(1s);
    const std::uint64_t n = reader.status().samples - s0;
    const double secs =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double achieved = static_cast<double>(n) / secs;
    std::printf("[figure] poll rate: configured %.0f Hz, achieved %.1f Hz on loopback\n", rate,
                achieved);
    // Paced, not free-running; the lower bound is loose because this shared 2-core host runs
    // other builds (at load average 9: 161 Hz of 200, 460 Hz of 1000; idle: 200.0 and 909).
    EXPECT_GT(achieved, 0.4 * rate);
    EXPECT_LT(achieved, 1.05 * rate);
  }
}

TEST(ModbusDynamometer, RtReadAllocatesNothing) {
  Loop l;
  ASSERT_TRUE(wait_for(
      *l.reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
  double sum = 0;
  contour::test::AllocGuard g;
  for (int i = 0; i < 10000; ++i) sum += l.reader->read(dm::steady_now_ns()).sample.force_N[0];
  EXPECT_EQ(g.counts().total(), 0u);
  EXPECT_GT(sum, 0.0);
}

TEST(ModbusDynamometer, MbpollReadsTheSameValues) {
  if (std::system("command -v mbpoll >/dev/null 2>&1") != 0) {
    GTEST_SKIP()
        << "mbpoll not installed (Debian package mbpoll): independent-client check not run";
  }
  // int16 + float32 abcd (mbpoll -B) on holding registers.
  dm::RegisterMap m;
  m.function = dm::RegisterFunction::kHolding;
  m.channels[0] = {true, 10, dm::RegisterType::kFloat32, dm::WordOrder::kAbcd, 1.0, 0.0};
  m.channels[1] = {true, 12, dm::RegisterType::kFloat32, dm::WordOrder::kAbcd, 1.0, 0.0};
  m.channels[2] = {true, 14, dm::RegisterType::kInt16, dm::WordOrder::kAbcd, 0.1, 0.0};
  DynamometerServer server(m, quiet_model());
  server.start("127.0.0.1", 0);
  server.set_fixed_forces(std::array<double, 3>{321.5, -12.25, -45.6});
  dm::DynamometerReader reader(settings_for(m, server.port()));
  reader.start();
  dm::ForceReading r;
  ASSERT_TRUE(wait_for(
      reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s, &r));

  auto run = [&](const std::string& args) {
    const std::string cmd = "mbpoll -m tcp -p " + std::to_string(server.port()) +
                            " -a 1 -0 -1 -o 1 " + args + " 127.0.0.1 2>&1";
    std::string out;
    FILE* p = popen(cmd.c_str(), "r");
    if (!p) return out;
    char buf[256];
    while (fgets(buf, sizeof buf, p)) out += buf;
    pclose(p);
    return out;
  };
  // Lines look like "[10]: \t321.5".
  auto value_at = [](const std::string& out, int ref) {
    const std::string key = "[" + std::to_string(ref) + "]:";
    const auto pos = out.find(key);
    if (pos == std::string::npos) return std::nan("");
    return std::stod(out.substr(pos + key.size()));
  };
  const std::string floats = run("-t 4:float -B -r 10 -c 2");
  const std::string ints = run("-t 4 -r 14 -c 1");
  const double f0 = value_at(floats, 10);
  const double f1 = value_at(floats, 12);
  // mbpoll prints 16-bit registers unsigned: reinterpret as int16, then the map's scale.
  const double i2 = static_cast<std::int16_t>(static_cast<std::uint16_t>(value_at(ints, 14))) * 0.1;
  std::printf("[figure] mbpoll: Fx %.4f Fy %.4f Fz %.4f N; reader: %.4f %.4f %.4f N\n", f0, f1, i2,
              r.sample.force_N[0], r.sample.force_N[1], r.sample.force_N[2]);
  EXPECT_NEAR(f0, r.sample.force_N[0], 1e-3) << floats;
  EXPECT_NEAR(f1, r.sample.force_N[1], 1e-3) << floats;
  EXPECT_NEAR(i2, r.sample.force_N[2], 1e-9) << ints;
  // Raw registers: mbpoll's 16-bit view equals the reader's raw block.
  const std::string raw = run("-t 4 -r 10 -c 5");
  for (int k = 0; k < 5; ++k) {
    const double v = value_at(raw, 10 + k);  // mbpoll prints 16-bit registers unsigned
    const auto reg = r.sample.raw[static_cast<std::size_t>(10 + k - r.sample.raw_start)];
    EXPECT_EQ(static_cast<std::uint16_t>(v), reg) << raw;
  }
}

#include "drivers/modbus/force_filter.hpp"
#include "drivers/modbus/probe.hpp"

TEST(ModbusDynamometer, ProbeReturnsSamplesAndTranslatedErrors) {
  const dm::RegisterMap m =
      make_map(dm::RegisterType::kInt32, dm::WordOrder::kDcba, dm::RegisterFunction::kInput);
  DynamometerServer server(m, quiet_model());
  server.start("127.0.0.1", 0);
  server.set_fixed_forces(std::array<double, 3>{11.1, 22.2, -33.3});
  const auto recs = dm::probe_dynamometer(settings_for(m, server.port()), 5);
  ASSERT_EQ(recs.size(), 5u);
  for (const auto& r : recs) {
    ASSERT_TRUE(r.ok) << r.error_text;
    EXPECT_TRUE(r.sample.valid);
    EXPECT_NEAR(r.sample.force_N[2], -33.3, 0.05 + 1e-9);
    EXPECT_LT(r.latency_ms, 20.0);
  }
  const int port = server.port();
  server.stop();
  const auto bad = dm::probe_dynamometer(settings_for(m, port), 2);
  ASSERT_EQ(bad.size(), 2u);
  EXPECT_FALSE(bad[0].ok);
  EXPECT_EQ(bad[0].error, dm::ErrorKind::kConnection);
  EXPECT_NE(bad[0].error_text.find("Connection refused"), std::string::npos) << bad[0].error_text;
}

TEST(ModbusDynamometer, ServerModelFirstOrderFeedResponseAndMaterialStep) {
  const dm::RegisterMap m =
      make_map(dm::RegisterType::kFloat32, dm::WordOrder::kAbcd, dm::RegisterFunction::kInput);
  contour::sim::ForceModelParams p = quiet_model();
  p.harmonics.clear();
  p.step_at_mm = 10.0;
  p.step_factor = 1.5;
  DynamometerServer server(m, p);
  server.start("127.0.0.1", 0);
  dm::DynamometerReader reader(settings_for(m, server.port(), 500.0));
  reader.start();
  dm::ForceReading r;
  ASSERT_TRUE(wait_for(
      reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s, &r));
  EXPECT_NEAR(r.sample.force_N[0], p.force0_N, 1e-3);  // at the operating point
  // Feed step +100 mm/min: Fx -> force0 + K_f * 100 with tau_f = 50 ms.
  const double target = p.force0_N + p.k_feed_N_per_mm_min * 100.0;
  const auto t0 = std::chrono::steady_clock::now();
  server.set_feed(p.feed0_mm_min + 100.0);
  const double f63 = p.force0_N + 0.632 * (target - p.force0_N);
  ASSERT_TRUE(wait_for(
      reader, [f63](const dm::ForceReading& x) { return x.sample.force_N[0] >= f63; }, 2s));
  const double tau_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::printf(
      "[figure] simulated feed step: 63 %% of K_f*dF reached after %.1f ms (tau_f = 50 ms)\n",
      tau_ms);
  EXPECT_GT(tau_ms, 35.0);
  EXPECT_LT(tau_ms, 75.0);
  std::this_thread::sleep_for(400ms);
  EXPECT_NEAR(reader.read(dm::steady_now_ns()).sample.force_N[0], target, 0.5);
  // Material step at 10 mm of path.
  server.set_path_position(12.0);
  ASSERT_TRUE(wait_for(
      reader, [&](const dm::ForceReading& x) { return x.sample.force_N[0] > 1.4 * target; }, 1s,
      &r));
  EXPECT_NEAR(r.sample.force_N[0], 1.5 * target, 0.5);
  EXPECT_NEAR(r.sample.force_N[1], 0.5 * 1.5 * target, 0.5);  // channel ratios 1 : 0.5 : 0.3
}

TEST(ModbusDynamometer, FilterRemovesToothPassingFromServedForce) {
  // 2 teeth at 600 rpm: 20 Hz tooth passing, sampled by the reader at 200 Hz over TCP.
  const dm::RegisterMap m =
      make_map(dm::RegisterType::kFloat32, dm::WordOrder::kAbcd, dm::RegisterFunction::kInput);
  contour::sim::ForceModelParams p;
  p.teeth = 2;
  p.spindle0_rpm = 600.0;
  p.noise_std_N = 0.0;
  p.harmonics = {0.4, 0.15};
  DynamometerServer server(m, p);
  server.start("127.0.0.1", 0);
  dm::DynamometerSettings ds = settings_for(m, server.port(), 200.0);
  ds.filter_enabled = true;
  ds.filter.teeth = 2;
  ds.filter.butterworth_order = 2;
  ds.filter.cutoff_hz = 5.0;
  dm::DynamometerReader reader(ds);
  reader.set_spindle_rpm(600.0);
  reader.start();
  ASSERT_TRUE(wait_for(
      reader, [](const dm::ForceReading& x) { return x.state == dm::ForceState::kOk; }, 2s));
  std::vector<double> raw, filt;
  int n = 0;
  std::int64_t last_t = 0;
  double max_jitter_ms = 0;
  // The consumer may miss samples (gaps are harmless: the filter runs on the poll thread). Until
  // 2 s of samples after the settling second are in (a count, not a wall-clock time: a loaded
  // machine gets there later; 30 s at most).
  const auto end = std::chrono::steady_clock::now() + 30s;
  while (raw.size() < 400 && std::chrono::steady_clock::now() < end) {
    const dm::ForceReading x = reader.read(dm::steady_now_ns());
    if (x.fresh && x.state == dm::ForceState::kOk) {
      if (last_t != 0 && x.sample.seq)
        max_jitter_ms = std::max(
            max_jitter_ms, std::abs(static_cast<double>(x.sample.t_ns - last_t) * 1e-6 - 5.0));
      last_t = x.sample.t_ns;
      const double y = x.sample.filtered_N[0];
      if (++n > 200) {  // after 1 s of settling
        raw.push_back(x.sample.force_N[0]);
        filt.push_back(y);
      }
    }
    std::this_thread::sleep_for(500us);
  }
  auto rms_dev = [](const std::vector<double>& v, double& mean) {
    mean = 0;
    for (double a : v) mean += a;
    mean /= static_cast<double>(v.size());
    double s = 0;
    for (double a : v) s += (a - mean) * (a - mean);
    return std::sqrt(s / static_cast<double>(v.size()));
  };
  ASSERT_GT(raw.size(), 200u);
  double raw_mean = 0, f_mean = 0;
  const double raw_rms = rms_dev(raw, raw_mean);
  const double f_rms = rms_dev(filt, f_mean);
  const double att_db = 20.0 * std::log10(f_rms / raw_rms);
  // RMS rather than peak-to-peak: on the shared 2-core host the poll period jitters (max printed
  // below; 13-18 ms seen at load average 9), and a period average of non-uniform samples leaks.
  std::printf(
      "[figure] served force, 20 Hz tooth passing at a 200 Hz poll: raw ripple %.1f N rms, "
      "filtered %.2f N rms, attenuation %.1f dB (%zu samples)\n",
      raw_rms, f_rms, att_db, raw.size());
  std::printf("[figure] consumer-seen sample period jitter max %.2f ms\n", max_jitter_ms);
  EXPECT_GT(raw_rms, 50.0);  // the harmonics are really there
  EXPECT_LT(att_db, -25.0);
  EXPECT_NEAR(f_mean, p.force0_N, 10.0);
}

TEST(ModbusDynamometer, RtuMissingDeviceIsCountedNotFatal) {
  // No serial port or pty pair is available to the tests: only the RTU error path runs here.
  dm::DynamometerSettings s = settings_for(
      make_map(dm::RegisterType::kInt16, dm::WordOrder::kAbcd, dm::RegisterFunction::kInput), 0);
  s.transport.transport = dm::Transport::kRtu;
  s.transport.device = "/dev/ttyNOPE_h8";
  s.reconnect_min = 10ms;
  s.reconnect_max = 40ms;
  dm::ModbusClient c(s.transport);
  const dm::ModbusError e = c.connect();
  EXPECT_EQ(e.kind, dm::ErrorKind::kConnection);
  EXPECT_NE(e.text.find("/dev/ttyNOPE_h8"), std::string::npos) << e.text;
  dm::DynamometerReader reader(s);
  reader.start();
  std::this_thread::sleep_for(300ms);
  const dm::DynamometerStatus st = reader.status();
  reader.stop();
  EXPECT_EQ(st.polls, 0u);
  EXPECT_GE(st.connection_errors, 3u);
  EXPECT_LE(st.connection_errors, 12u);  // backoff 10, 20, 40, 40 ... ms: no spinning
  EXPECT_EQ(reader.read(dm::steady_now_ns()).state, dm::ForceState::kNoData);
  std::printf("[message] %s\n", st.last_error.c_str());
}

TEST(ModbusDynamometer, BadSettingsThrow) {
  dm::DynamometerSettings s;
  EXPECT_THROW(dm::DynamometerReader{s}, std::invalid_argument);  // nothing mapped
  s.map.channels[0] = {true, 0, dm::RegisterType::kInt16, dm::WordOrder::kAbcd, 1, 0};
  s.map.channels[1] = {true, 40, dm::RegisterType::kInt16, dm::WordOrder::kAbcd, 1, 0};
  EXPECT_THROW(dm::DynamometerReader{s}, std::invalid_argument);  // span 41 > 32
  s.map.channels[1].enabled = false;
  s.filter_enabled = true;
  s.filter.butterworth_order = 3;
  EXPECT_THROW(dm::DynamometerReader{s}, std::invalid_argument);
}
