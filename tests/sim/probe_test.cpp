// `contourd --probe modbus|gpio` (daemon/probe.hpp) against devices on this machine: the simulated
// dynamometer as a Modbus TCP server on loopback (the same server contour-machine-sim runs, here
// in-process so the test needs no CAN interface), the simulated GPIO backend; plus the error
// cases (no server, no such interface, config without the device, bad --probe kind).
#include "daemon/probe.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "drivers/gpio/sim_gpio.hpp"
// DynamometerServer lives in contour-machine-sim, which is not a library (as in
// tests/unit/drivers/modbus_dynamometer_test.cpp).
#include "tools/contour-machine-sim/dynamometer_server.cpp"

using nlohmann::json;

namespace {

struct ProbeRun {
  int exit = -1;
  std::vector<json> lines;  // every stdout line, parsed (a non-JSON line fails the test)
  std::string err;
};

std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string temp_path(const std::string& what) {
  return "/tmp/contour-probe-test-" + std::to_string(::getpid()) + "-" + what;
}

// Runs the contourd binary; stdout lines are parsed as JSON.
ProbeRun contourd(const std::string& args) {
  const std::string err_path = temp_path("stderr");
  const std::string cmd =
      std::string(CONTOUR_BINARY_DIR "/daemon/contourd ") + args + " 2>" + err_path;
  ProbeRun r;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) return r;
  std::string out;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int st = ::pclose(p);
  r.exit = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  r.err = read_file(err_path);
  ::unlink(err_path.c_str());
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line)) {
    json j = json::parse(line, nullptr, false);
    EXPECT_FALSE(j.is_discarded()) << "not a JSON line: " << line;
    if (!j.is_discarded()) r.lines.push_back(std::move(j));
  }
  return r;
}

// config/hil.yaml with text substitutions, written to a temp file.
std::string hil_config_with(const std::vector<std::pair<std::string, std::string>>& subst,
                            const std::string& tag) {
  std::string text = read_file(CONTOUR_SOURCE_DIR "/config/hil.yaml");
  for (const auto& [from, to] : subst) {
    const auto pos = text.find(from);
    EXPECT_NE(pos, std::string::npos) << "config/hil.yaml no longer contains '" << from << "'";
    if (pos != std::string::npos) text.replace(pos, from.size(), to);
  }
  const std::string path = temp_path(tag + ".yaml");
  std::ofstream(path) << text;
  return path;
}

std::vector<json> samples(const ProbeRun& r) {
  std::vector<json> s;
  for (const auto& j : r.lines)
    if (!j.contains("summary")) s.push_back(j);
  return s;
}

// The two registers of a float32 in abcd (Modbus big-endian) order, computed here independently
// of the project's codec.
std::array<std::uint16_t, 2> float_words_abcd(float f) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &f, sizeof bits);
  return {static_cast<std::uint16_t>(bits >> 16), static_cast<std::uint16_t>(bits & 0xFFFF)};
}

class ModbusProbe : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto cfg = contour::config::load_config_file(CONTOUR_SOURCE_DIR "/config/hil.yaml");
    server_ = std::make_unique<contour::sim::DynamometerServer>(
        cfg.dynamometer.reader.map, contour::sim::ForceModelParams{},
        cfg.dynamometer.reader.transport.unit_id);
    server_->start("127.0.0.1", 0);
    server_->set_fixed_forces(std::array<double, 3>{100.0, -50.0, 25.0});
  }
  void TearDown() override {
    for (const auto& p : configs_) ::unlink(p.c_str());
  }
  // hil.yaml pointing at the in-test server; the response timeout is widened from 20 ms to 1 s
  // because this VM's steal time can delay a loopback reply past 20 ms (not what is tested here).
  std::string config(std::vector<std::pair<std::string, std::string>> extra = {}) {
    extra.insert(extra.begin(), {{"port: 1502", "port: " + std::to_string(server_->port())},
                                 {"\n  timeout_ms: 20\n", "\n  timeout_ms: 1000\n"}});
    configs_.push_back(hil_config_with(extra, "modbus" + std::to_string(configs_.size())));
    return configs_.back();
  }
  std::unique_ptr<contour::sim::DynamometerServer> server_;
  std::vector<std::string> configs_;
};

}  // namespace

TEST_F(ModbusProbe, SamplesCarryTheServedForcesRawRegistersStatusAndSequence) {
  const std::uint64_t before = server_->requests();
  const ProbeRun r = contourd("--config " + config() + " --probe modbus --count 5");
  ASSERT_EQ(r.exit, 0) << r.err;
  const auto s = samples(r);
  ASSERT_EQ(s.size(), 5u);
  EXPECT_EQ(server_->requests() - before, 5u) << "one register-block read per sample";
  const std::array<float, 3> want{100.0f, -50.0f, 25.0f};
  for (std::size_t i = 0; i < s.size(); ++i) {
    const json& j = s[i];
    EXPECT_EQ(j["probe"], "modbus");
    EXPECT_EQ(j["index"], i);
    ASSERT_EQ(j["ok"], true) << j.dump();
    EXPECT_EQ(j["valid"], true);
    EXPECT_EQ(j["seq"], i + 1);
    EXPECT_DOUBLE_EQ(j["fx_n"].get<double>(), want[0]);
    EXPECT_DOUBLE_EQ(j["fy_n"].get<double>(), want[1]);
    EXPECT_DOUBLE_EQ(j["fz_n"].get<double>(), want[2]);
    // hil.yaml: fx, fy, fz float32 abcd at 0, 2, 4; status at 6, valid bit 0.
    EXPECT_EQ(j["raw_start"], 0);
    const auto raw = j["raw"].get<std::vector<std::uint16_t>>();
    ASSERT_EQ(raw.size(), 7u);
    for (std::size_t c = 0; c < 3; ++c) {
      const auto w = float_words_abcd(want[c]);
      EXPECT_EQ(raw[2 * c], w[0]) << "channel " << c;
      EXPECT_EQ(raw[2 * c + 1], w[1]) << "channel " << c;
    }
    EXPECT_EQ(j["status"]["address"], 6);
    EXPECT_EQ(j["status"]["value"].get<int>() & 1, 1);
    EXPECT_EQ(j["status"]["valid"], true);
    EXPECT_GE(j["age_ms"].get<double>(), 0.0);
    EXPECT_GE(j["latency_ms"].get<double>(), 0.0);
    if (i > 0) {
      EXPECT_GT(j["t_ns"].get<std::int64_t>(), s[i - 1]["t_ns"].get<std::int64_t>());
    }
  }
  const json& sum = r.lines.back();
  EXPECT_EQ(sum["summary"], true);
  EXPECT_EQ(sum["total"], 5);
  EXPECT_EQ(sum["ok"], 5);
  EXPECT_EQ(sum["exit"], 0);
}

TEST_F(ModbusProbe, DefaultCountIsTenAndOnlyConfiguredChannelsArePrinted) {
  const ProbeRun r = contourd(
      "--config " + config({{"    fy: {address: 2, type: float32, word_order: abcd}\n", ""}}) +
      " --probe modbus");
  ASSERT_EQ(r.exit, 0) << r.err;
  const auto s = samples(r);
  ASSERT_EQ(s.size(), static_cast<std::size_t>(contour::daemon::kProbeDefaultModbusCount));
  for (const auto& j : s) {
    EXPECT_TRUE(j.contains("fx_n")) << j.dump();
    EXPECT_FALSE(j.contains("fy_n")) << j.dump();
    EXPECT_TRUE(j.contains("fz_n")) << j.dump();
  }
}

TEST_F(ModbusProbe, InvalidStatusBitIsReportedAndExitsOne) {
  server_->set_status_valid(false);
  const ProbeRun r = contourd("--config " + config() + " --probe modbus --count 2");
  EXPECT_EQ(r.exit, 1) << "the device answered, but no sample was valid";
  for (const auto& j : samples(r)) {
    EXPECT_EQ(j["ok"], true) << "the read itself succeeded";
    EXPECT_EQ(j["valid"], false);
    EXPECT_EQ(j["status"]["valid"], false);
  }
}

TEST_F(ModbusProbe, ExceptionReplyIsAnErrorRecordWithItsText) {
  server_->set_fault(contour::sim::FaultMode::kException, std::chrono::milliseconds(0), 4);
  const ProbeRun r = contourd("--config " + config() + " --probe modbus --count 2");
  EXPECT_EQ(r.exit, 69);
  const auto s = samples(r);
  ASSERT_EQ(s.size(), 2u);
  for (const auto& j : s) {
    EXPECT_EQ(j["ok"], false);
    EXPECT_EQ(j["error"], "exception") << j.dump();
    EXPECT_FALSE(j["error_text"].get<std::string>().empty());
    EXPECT_FALSE(j.contains("fx_n"));
  }
}

TEST_F(ModbusProbe, NoReplyIsATimeoutRecordAndTheNextSampleRecovers) {
  server_->set_fault(contour::sim::FaultMode::kNoReply);
  ProbeRun r = contourd("--config " + config() + " --probe modbus --count 2");
  EXPECT_EQ(r.exit, 69);
  auto s = samples(r);
  ASSERT_EQ(s.size(), 2u);
  for (const auto& j : s) {
    EXPECT_EQ(j["ok"], false);
    EXPECT_EQ(j["error"], "timeout") << j.dump();
  }
  server_->set_fault(contour::sim::FaultMode::kNone);
  r = contourd("--config " + config() + " --probe modbus --count 2");
  EXPECT_EQ(r.exit, 0);
}

TEST_F(ModbusProbe, NoServerGivesConnectionErrorsAndExit69) {
  const std::string cfg = config();  // the port of a server that is then stopped
  server_->stop();
  const ProbeRun r = contourd("--config " + cfg + " --probe modbus --count 3");
  EXPECT_EQ(r.exit, 69) << r.err;
  const auto s = samples(r);
  ASSERT_EQ(s.size(), 3u);
  for (const auto& j : s) {
    EXPECT_EQ(j["ok"], false);
    EXPECT_EQ(j["error"], "connection") << j.dump();
    EXPECT_NE(j["error_text"].get<std::string>().find("127.0.0.1"), std::string::npos) << j.dump();
  }
  EXPECT_EQ(r.lines.back()["exit"], 69);
}

TEST(Probe, ConfigWithoutTheDeviceExits78WithAJsonError) {
  // config/sim.yaml: the in-process simulated machine, no dynamometer section, bus.type sim.
  for (const char* kind : {"modbus", "can"}) {
    const ProbeRun r =
        contourd(std::string("--config " CONTOUR_SOURCE_DIR "/config/sim.yaml --probe ") + kind);
    EXPECT_EQ(r.exit, 78) << kind;
    ASSERT_EQ(r.lines.size(), 1u) << kind;
    EXPECT_EQ(r.lines[0]["probe"], kind);
    EXPECT_TRUE(r.lines[0]["error"].is_string()) << r.lines[0].dump();
  }
}

TEST(Probe, MissingCanInterfaceExits69NamingIt) {
  const std::string cfg = hil_config_with({{"interface: vcan0", "interface: vcan9"}}, "vcan9");
  const ProbeRun r = contourd("--config " + cfg + " --probe can");
  ::unlink(cfg.c_str());
  EXPECT_EQ(r.exit, 69);
  ASSERT_EQ(r.lines.size(), 1u);
  EXPECT_EQ(r.lines[0]["interface"], "vcan9");
  EXPECT_NE(r.lines[0]["error"].get<std::string>().find("vcan9"), std::string::npos)
      << r.lines[0].dump();
}

TEST(Probe, BadKindAndStrayFlagsAreUsageErrors) {
  ProbeRun r = contourd("--config " CONTOUR_SOURCE_DIR "/config/hil.yaml --probe ethercat");
  EXPECT_EQ(r.exit, 2);
  EXPECT_TRUE(r.lines.empty());
  EXPECT_NE(r.err.find("unknown kind 'ethercat'"), std::string::npos) << r.err;
  r = contourd("--config " CONTOUR_SOURCE_DIR "/config/hil.yaml --count 3");
  EXPECT_EQ(r.exit, 2);
  EXPECT_NE(r.err.find("--probe"), std::string::npos) << r.err;
}

TEST(Probe, GpioLinesByNameWithTheSimBackend) {
  const ProbeRun r = contourd("--config " CONTOUR_SOURCE_DIR "/config/hil.yaml --probe gpio");
  ASSERT_EQ(r.exit, 0) << r.err;
  const auto s = samples(r);
  const std::vector<std::pair<std::string, std::string>> want = {
      {"estop", "ESTOP"},       {"drive_enable", "DRIVE_EN"}, {"spindle_enable", "SPINDLE_EN"},
      {"coolant_mist", "MIST"}, {"coolant_flood", "FLOOD"},   {"alive", "ALIVE"}};
  ASSERT_EQ(s.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(s[i]["role"], want[i].first);
    EXPECT_NE(s[i]["line"].get<std::string>().find(want[i].second), std::string::npos)
        << s[i].dump();
    EXPECT_EQ(s[i]["ok"], true);
    EXPECT_EQ(s[i]["direction"], i == 0 ? "input" : "output");
  }
  // The simulated E-stop chain starts closed, as in the daemon with `backend: sim`.
  EXPECT_EQ(s[0]["estop"], "released") << s[0].dump();
}

TEST(Probe, GpioReportsTheEstopLevelAndLeavesOutputsInactive) {
  const auto cfg = contour::config::load_config_file(CONTOUR_SOURCE_DIR "/config/hil.yaml");
  for (const bool high : {true, false}) {
    auto sim = contour::drivers::gpio::SimGpio::create();
    sim->set_input_level("ESTOP", high);
    contour::daemon::ProbeOptions opt;
    opt.kind = contour::daemon::ProbeKind::kGpio;
    opt.gpio_backend = sim;
    char* buf = nullptr;
    std::size_t len = 0;
    FILE* out = ::open_memstream(&buf, &len);
    ASSERT_NE(out, nullptr);
    const int code = contour::daemon::run_probe(cfg, opt, out);
    std::fclose(out);
    const std::string text(buf, len);
    std::free(buf);
    EXPECT_EQ(code, 0) << text;
    std::istringstream in(text);
    std::string line;
    std::getline(in, line);
    const json estop = json::parse(line);
    EXPECT_EQ(estop["role"], "estop");
    // hil.yaml's E-stop is active-low (the default, a normally closed chain): high = released.
    EXPECT_EQ(estop["active"], !high) << line;
    EXPECT_EQ(estop["estop"], high ? "released" : "asserted") << line;
    for (const char* out_line : {"DRIVE_EN", "SPINDLE_EN", "MIST", "FLOOD", "ALIVE"})
      EXPECT_FALSE(sim->output_active(out_line)) << out_line << " must stay inactive";
  }
}
