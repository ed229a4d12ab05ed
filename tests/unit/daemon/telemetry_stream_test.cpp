// The telemetry subscription (issue 21): every sample the loop produces reaches a subscriber, in
// batches, with the true contour error; decimation only on request; a slow subscriber loses its
// own oldest samples (counted) and never blocks the publisher or the other subscribers.
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "daemon/command_server.hpp"
#include "daemon/telemetry.hpp"
#include "tests/support/daemon_process.hpp"

using contour::daemon::ClientInfo;
using contour::daemon::CommandServer;
using contour::daemon::CommandServerOptions;
using contour::daemon::SpscRing;
using contour::daemon::StreamChunk;
using contour::daemon::StreamOptions;
using contour::daemon::StreamSample;
using contour::daemon::TelemetrySample;
using contour::daemon::TelemetryWriter;
using nlohmann::json;

namespace {

TelemetrySample sample(std::uint64_t cycle) {
  TelemetrySample s;
  s.cycle = cycle;
  s.t_s = static_cast<double>(cycle) * 1e-3;
  s.ref_mm = {0.001 * static_cast<double>(cycle), 2.0, -1.5};
  s.act_mm = {0.001 * static_cast<double>(cycle) - 0.002, 2.0005, -1.5};
  s.eps_mm = {0.0, 0.0005, 0.0};
  s.state = contour::daemon::MachineState::kRunning;
  return s;
}

TEST(TelemetryStream, EncodesTheDocumentedFields) {
  StreamSample ss{sample(1234), 0.5};
  ss.s.line = 7;
  ss.s.job = 3;
  ss.s.in_program = true;
  const json j = json::parse(contour::daemon::encode_stream_sample(ss));
  for (const char* k : {"cycle", "t_s", "state", "job", "line", "in_program", "progress_mm",
                        "ref_mm", "act_mm", "cmd_mm_s", "eps_um", "model_error_um",
                        "true_error_um", "override", "force_n", "force_override", "spindle_rpm",
                        "recording"}) {
    EXPECT_TRUE(j.contains(k)) << k << " missing in " << j.dump();
  }
  EXPECT_EQ(j["cycle"], 1234u);
  EXPECT_EQ(j["state"], "RUNNING");
  EXPECT_EQ(j["line"], 7);
  EXPECT_EQ(j["job"], 3);
  EXPECT_DOUBLE_EQ(j["ref_mm"][0].get<double>(), 1.234);  // shortest round-trip form
  EXPECT_DOUBLE_EQ(j["act_mm"][1].get<double>(), 2.0005);
  EXPECT_NEAR(j["eps_um"][1].get<double>(), 0.5, 1e-12);
  EXPECT_NEAR(j["model_error_um"].get<double>(), 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(j["true_error_um"].get<double>(), 0.5);
  ss.true_contour_error_um = std::nan("");
  EXPECT_TRUE(json::parse(contour::daemon::encode_stream_sample(ss))["true_error_um"].is_null());
}

TEST(TelemetryStream, WriterHandsOverEverySampleInBatchesWhateverTheLegacyDecimation) {
  SpscRing<TelemetrySample> ring(4096);
  TelemetryWriter w(ring, 1e-3);
  int legacy = 0;
  w.set_stream([&](const TelemetrySample&) { ++legacy; }, 100);  // the old 1:100 callback
  std::vector<std::uint64_t> cycles;
  std::vector<std::size_t> sizes;
  w.set_batch_stream(
      [&](std::span<const StreamSample> b) {
        sizes.push_back(b.size());
        for (const auto& s : b) cycles.push_back(s.s.cycle);
      },
      20);
  for (std::uint64_t c = 1; c <= 1000; ++c) ASSERT_TRUE(ring.push(sample(c)));
  w.drain();
  ASSERT_EQ(cycles.size(), 1000u);
  for (std::size_t i = 0; i < cycles.size(); ++i) ASSERT_EQ(cycles[i], i + 1) << "out of order";
  EXPECT_EQ(sizes.size(), 50u);
  for (std::size_t n : sizes) EXPECT_EQ(n, 20u);
  EXPECT_EQ(legacy, 10);  // the legacy callback keeps its own rate
  // A partial batch goes out once it is kMaxBatchAge old (next drain), not before.
  for (std::uint64_t c = 1001; c <= 1005; ++c) ASSERT_TRUE(ring.push(sample(c)));
  w.drain();
  EXPECT_EQ(cycles.size(), 1000u);
  std::this_thread::sleep_for(TelemetryWriter::kMaxBatchAge + std::chrono::milliseconds(5));
  w.drain();
  EXPECT_EQ(cycles.size(), 1005u);
}

TEST(TelemetryStream, SamplesCarryTheTrueContourErrorInAProgram) {
  SpscRing<TelemetrySample> ring(64);
  TelemetryWriter w(ring, 1e-3);
  std::vector<StreamSample> got;
  w.set_batch_stream([&](std::span<const StreamSample> b) { got.insert(got.end(), b.begin(), b.end()); },
                     1);
  w.begin_job(5);
  contour::control::PlannedSegment seg{};
  seg.kind = contour::control::SegmentKind::kMotion;
  seg.start_mm = Eigen::Vector3d(0, 0, 0);
  seg.end_mm = Eigen::Vector3d(100, 0, 0);
  seg.path_start_mm = 0.0;
  seg.length_mm = 100.0;
  w.add_segment(5, seg);
  TelemetrySample s = sample(10);
  s.job = 5;
  s.in_program = true;
  s.ref_mm = {50, 0, 0};
  s.act_mm = {49.9, 0.003, 0.004};  // 5 um off the X axis line
  s.progress_mm = 50.0;
  ASSERT_TRUE(ring.push(s));
  TelemetrySample idle = sample(11);  // not in a program: no true error
  ASSERT_TRUE(ring.push(idle));
  w.drain();
  ASSERT_EQ(got.size(), 2u);
  EXPECT_NEAR(got[0].true_contour_error_um, 5.0, 1e-9);
  EXPECT_TRUE(std::isnan(got[1].true_contour_error_um));
}

// --- command server side ----------------------------------------------------------------------

std::string temp_socket_path() {
  return "/tmp/contourd-stream-test-" + std::to_string(::getpid()) + "-" +
         std::to_string(std::random_device{}() % 100000) + ".sock";
}

void send_all(int fd, const std::string& s) {
  std::size_t off = 0;
  while (off < s.size()) {
    const ssize_t n = ::send(fd, s.data() + off, s.size() - off, MSG_NOSIGNAL);
    if (n <= 0) return;
    off += static_cast<std::size_t>(n);
  }
}

// Line reader with its own buffer (batch lines are long).
struct LineReader {
  int fd;
  std::string buf;
  std::string next(int timeout_ms = 5000) {
    for (;;) {
      const auto nl = buf.find('\n');
      if (nl != std::string::npos) {
        std::string line = buf.substr(0, nl);
        buf.erase(0, nl + 1);
        return line;
      }
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, timeout_ms) != 1) return "<timeout>";
      char tmp[65536];
      const ssize_t n = ::read(fd, tmp, sizeof tmp);
      if (n <= 0) return "<eof>";
      buf.append(tmp, static_cast<std::size_t>(n));
    }
  }
};

std::shared_ptr<const StreamChunk> chunk_of(std::uint64_t first, std::size_t n, std::size_t pad = 0) {
  std::vector<StreamSample> v;
  for (std::size_t i = 0; i < n; ++i) v.push_back({sample(first + i), 1.0});
  auto c = contour::daemon::make_stream_chunk(v, 0);
  if (pad == 0) return c;
  auto p = std::make_shared<StreamChunk>(*c);
  for (auto& it : p->items) it.json.insert(it.json.size() - 1, ",\"pad\":\"" + std::string(pad, 'x') + "\"");
  return p;
}

class StreamServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    opt_.path = temp_socket_path();
    opt_.max_stream_samples = 500;
    opt_.max_batch_samples = 100;
    server_ = std::make_unique<CommandServer>(opt_, [this](const json& req, const ClientInfo& c) {
      const auto dec = req.value("decimation", 1u);
      server_->subscribe(c.id, "telemetry", StreamOptions{dec});
      return json{{"client", c.id}};
    });
    server_->start();
  }
  void TearDown() override { server_->stop(); }
  std::uint64_t subscribe(int fd, LineReader& r, unsigned decimation = 1) {
    send_all(fd, json{{"id", 1}, {"cmd", "sub"}, {"decimation", decimation}}.dump() + "\n");
    const json rep = json::parse(r.next());
    return rep["result"]["client"].get<std::uint64_t>();
  }
  CommandServerOptions opt_;
  std::unique_ptr<CommandServer> server_;
};

TEST_F(StreamServerTest, EverySampleInBatchLinesAndDecimationOnlyOnRequest) {
  int a = contour::test::connect_unix(opt_.path);
  int b = contour::test::connect_unix(opt_.path);
  ASSERT_GE(a, 0);
  ASSERT_GE(b, 0);
  LineReader ra{a, {}}, rb{b, {}};
  subscribe(a, ra);
  subscribe(b, rb, 10);
  std::vector<std::uint64_t> got_a, got_b;
  int lines_a = 0;
  auto read_a = [&](int timeout_ms) {
    const std::string l = ra.next(timeout_ms);
    if (l == "<timeout>") return false;
    const json j = json::parse(l);
    EXPECT_EQ(j["event"], "telemetry");
    EXPECT_EQ(j["dropped"], 0u);
    EXPECT_EQ(j["decimation"], 1u);
    EXPECT_EQ(j["count"].get<std::size_t>(), j["samples"].size());
    EXPECT_LE(j["samples"].size(), opt_.max_batch_samples);
    for (const auto& s : j["samples"]) got_a.push_back(s["cycle"].get<std::uint64_t>());
    ++lines_a;
    return true;
  };
  auto read_b = [&](int timeout_ms) {
    const std::string l = rb.next(timeout_ms);
    if (l == "<timeout>") return false;
    const json j = json::parse(l);
    EXPECT_EQ(j["decimation"], 10u);
    EXPECT_EQ(j["dropped"], 0u);
    for (const auto& s : j["samples"]) got_b.push_back(s["cycle"].get<std::uint64_t>());
    return true;
  };
  // 20-sample chunks as the writer hands them over; both subscribers read as they arrive.
  // The readers keep up (at most ~320 samples outstanding, below max_stream_samples = 500), so
  // nothing may be dropped however slowly this host schedules the server thread.
  for (std::uint64_t c = 1; c <= 1000; c += 20) {
    server_->publish_stream("telemetry", chunk_of(c, 20));
    const std::uint64_t end = c + 19;
    while (read_a(0)) {
    }
    while (read_b(0)) {
    }
    while (got_a.size() + 300 < end) ASSERT_TRUE(read_a(5000)) << got_a.size();
    while (got_b.size() * 10 + 300 < end) ASSERT_TRUE(read_b(5000)) << got_b.size();
  }
  while (got_a.size() < 1000) ASSERT_TRUE(read_a(5000)) << got_a.size();
  while (got_b.size() < 100) ASSERT_TRUE(read_b(5000)) << got_b.size();
  for (std::size_t i = 0; i < got_a.size(); ++i) ASSERT_EQ(got_a[i], i + 1);
  EXPECT_LT(lines_a, 1000) << "not batched";
  for (std::size_t i = 0; i < got_b.size(); ++i) ASSERT_EQ(got_b[i], 10 * (i + 1));
  EXPECT_EQ(server_->stats().stream_dropped, 0u);
  ::close(a);
  ::close(b);
}

TEST_F(StreamServerTest, ASlowSubscriberLosesItsOldestSamplesCountedAndBlocksNobody) {
  int slow = contour::test::connect_unix(opt_.path);
  int fast = contour::test::connect_unix(opt_.path);
  ASSERT_GE(slow, 0);
  ASSERT_GE(fast, 0);
  // A small receive buffer on the slow side so that the kernel cannot hide its backlog.
  int small = 4096;
  ::setsockopt(slow, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
  LineReader rs{slow, {}}, rf{fast, {}};
  const auto slow_id = subscribe(slow, rs);
  subscribe(fast, rf);
  // 20000 samples of ~1.5 kB (30 MB): far more than the socket buffers, the 64 KiB low-water
  // mark and the 500-sample queue hold. The slow client reads nothing meanwhile.
  const std::uint64_t total = 20000;
  std::vector<std::uint64_t> got_fast;
  const auto t0 = std::chrono::steady_clock::now();
  for (std::uint64_t c = 1; c <= total; c += 50) {
    server_->publish_stream("telemetry", chunk_of(c, 50, 1000));
    // The fast subscriber keeps up: it reads what is there, and waits for the server whenever
    // more than ~300 samples are outstanding (below the 500-sample queue), so it never loses one
    // however slowly this host schedules the server thread.
    for (;;) {
      pollfd p{fast, POLLIN, 0};
      const bool behind = got_fast.size() + 300 < c + 49;
      if (::poll(&p, 1, behind ? 5000 : 0) != 1) {
        ASSERT_FALSE(behind) << "fast subscriber starved at " << got_fast.size();
        break;
      }
      const json j = json::parse(rf.next());
      for (const auto& s : j["samples"]) got_fast.push_back(s["cycle"].get<std::uint64_t>());
    }
  }
  const double publish_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  while (got_fast.size() < total) {
    const std::string l = rf.next();
    ASSERT_NE(l, "<timeout>") << got_fast.size();
    const json j = json::parse(l);
    EXPECT_EQ(j["dropped"], 0u);
    for (const auto& s : j["samples"]) got_fast.push_back(s["cycle"].get<std::uint64_t>());
  }
  for (std::size_t i = 0; i < got_fast.size(); ++i) ASSERT_EQ(got_fast[i], i + 1);
  const std::uint64_t dropped = server_->stream_dropped(slow_id, "telemetry");
  EXPECT_GT(dropped, 0u);
  EXPECT_EQ(server_->stats().stream_dropped, dropped);
  EXPECT_EQ(server_->stats().oversize_buffer, 0u) << "slow subscriber disconnected";
  // Now the slow one reads: what it gets plus what was dropped is everything, the gaps are where
  // "dropped" grew, and the newest samples are there (oldest dropped first).
  std::uint64_t received = 0, last_cycle = 0, last_dropped = 0, gaps = 0;
  for (;;) {
    const std::string l = rs.next(500);
    if (l == "<timeout>") break;
    const json j = json::parse(l);
    const auto d = j["dropped"].get<std::uint64_t>();
    for (const auto& s : j["samples"]) {
      const auto c = s["cycle"].get<std::uint64_t>();
      if (last_cycle != 0 && c != last_cycle + 1) gaps += c - last_cycle - 1;
      last_cycle = c;
      ++received;
    }
    last_dropped = d;
  }
  EXPECT_EQ(last_cycle, total) << "the newest sample must arrive";
  EXPECT_EQ(received + last_dropped, total);
  EXPECT_EQ(last_dropped, dropped);
  EXPECT_LE(gaps, dropped);
  std::printf("slow subscriber: %llu of %llu samples dropped (counted); publishing took %.3f s\n",
              static_cast<unsigned long long>(dropped), static_cast<unsigned long long>(total),
              publish_s);
  ::close(slow);
  ::close(fast);
}

TEST_F(StreamServerTest, ASingleEventOnAStreamTopicArrivesInTheBatchFormat) {
  int a = contour::test::connect_unix(opt_.path);
  ASSERT_GE(a, 0);
  LineReader ra{a, {}};
  subscribe(a, ra);
  server_->publish_stream("telemetry", chunk_of(1, 1));
  server_->publish("telemetry", {{"event", "telemetry"}, {"cycle", 2u}, {"x", 1.5}});
  std::vector<json> samples;
  while (samples.size() < 2) {
    const std::string l = ra.next();
    ASSERT_NE(l, "<timeout>");
    const json j = json::parse(l);
    for (const auto& s : j["samples"]) samples.push_back(s);
  }
  EXPECT_EQ(samples[1]["cycle"], 2u);
  EXPECT_EQ(samples[1]["x"], 1.5);
  EXPECT_FALSE(samples[1].contains("event"));
  ::close(a);
}

}  // namespace
