// HIL: the soft PLC's example machine logic (config/plc/*.st) on contour-machine-sim's Modbus TCP
// I/O coupler, with contourd driving the simulated CANopen drives over vcan0 (issue 20: "the
// carousel M6 sequence in a program (sim and HIL over vcan with the Modbus I/O coupler); a lost
// I/O coupler raising a fault"). Both are child processes:
//   contour-machine-sim --config config/hil.yaml --can vcan0 --plant-io 127.0.0.1:0 --plant-stdin
//   contourd --config <tmp>/hil_plc.yaml = config/hil.yaml + config/plc/hil_machine.yaml (the
//            coupler's port substituted, the .st paths made absolute) + a tool table (tools 1..8,
//            tool T in pocket T: config/hil.yaml has none and T3 needs one)
// The plant events (coupler no reply, door) are typed on the simulator's stdin at the moment the
// test chooses, and acknowledged on its stdout. The test also reads the coupler itself (libmodbus,
// a second client): what the field sees, not only what the daemon says.
// Waits are bounded polls (the VM has heavy steal time); no wall-clock assertion.
#include <gtest/gtest.h>
#include <modbus/modbus.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/daemon_process.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;
using namespace std::chrono_literals;

const std::string kSrc = CONTOUR_SOURCE_DIR;
constexpr int kStaleMs = 2000;  // the coupler's stale_ms in the test's config (see assemble_config)

// contour-machine-sim with the plant coupler on a free port and plant events from stdin.
class PlantSim {
 public:
  PlantSim() {
    const std::string bin = CONTOUR_BINARY_DIR "/tools/contour-machine-sim";
    std::vector<std::string> args = {bin,          "--config",   kSrc + "/config/hil.yaml",
                                     "--can",      "vcan0",      "--plant-io",
                                     "127.0.0.1:0", "--plant-stdin"};
    int out[2], in[2];
    if (::pipe(out) != 0 || ::pipe(in) != 0) throw std::runtime_error("pipe");
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(out[1], 1);
      ::dup2(in[0], 0);
      ::close(out[0]);
      ::close(out[1]);
      ::close(in[0]);
      ::close(in[1]);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(bin.c_str(), argv.data());
      _exit(127);
    }
    ::close(out[1]);
    ::close(in[0]);
    out_fd_ = out[0];
    in_fd_ = in[1];
    wait_output("ready:", 0, 20s);
    const auto at = output_.find("plant io: modbus tcp 127.0.0.1:");
    if (at != std::string::npos) port_ = std::atoi(output_.c_str() + at + 31);
  }
  ~PlantSim() { stop(); }
  PlantSim(const PlantSim&) = delete;
  PlantSim& operator=(const PlantSim&) = delete;

  [[nodiscard]] bool ready() const { return output_.find("ready:") != std::string::npos && port_ > 0; }
  [[nodiscard]] int port() const { return port_; }

  // Types a plant event on the simulator's stdin and waits for its acknowledgement line.
  bool event(const std::string& kind) {
    const std::size_t from = poll_output().size();
    const std::string line = kind + "\n";
    if (::write(in_fd_, line.data(), line.size()) != static_cast<ssize_t>(line.size())) return false;
    return wait_output("{\"plant\":\"" + kind + "\"", from, 30s);
  }
  // Everything the simulator printed up to now (reads without blocking).
  const std::string& poll_output() {
    for (;;) {
      pollfd p{out_fd_, POLLIN, 0};
      if (out_fd_ < 0 || ::poll(&p, 1, 0) != 1) break;
      char buf[4096];
      const ssize_t n = ::read(out_fd_, buf, sizeof buf);
      if (n <= 0) break;
      output_.append(buf, static_cast<std::size_t>(n));
    }
    return output_;
  }
  // SIGTERM; returns the JSON summary line (the last line printed), or null.
  json stop() {
    if (pid_ > 0) {
      ::close(in_fd_);
      ::kill(pid_, SIGTERM);
      char buf[4096];
      ssize_t n;
      while ((n = ::read(out_fd_, buf, sizeof buf)) > 0) output_.append(buf, static_cast<std::size_t>(n));
      ::waitpid(pid_, nullptr, 0);
      ::close(out_fd_);
      out_fd_ = -1;
      pid_ = -1;
    }
    std::istringstream lines(output_);
    std::string last;
    for (std::string l; std::getline(lines, l);)
      if (!l.empty()) last = l;
    return json::parse(last, nullptr, false);
  }
  [[nodiscard]] const std::string& output() const { return output_; }

 private:
  bool wait_output(const std::string& text, std::size_t from, std::chrono::seconds limit) {
    const auto until = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < until) {
      if (poll_output().find(text, from) != std::string::npos) return true;
      pollfd p{out_fd_, POLLIN, 0};
      ::poll(&p, 1, 50);
    }
    return poll_output().find(text, from) != std::string::npos;
  }

  pid_t pid_ = -1;
  int out_fd_ = -1, in_fd_ = -1;
  int port_ = 0;
  std::string output_;
};

std::size_t replace_all(std::string& s, const std::string& from, const std::string& to) {
  std::size_t n = 0;
  for (auto at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size())) {
    s.replace(at, from.size(), to);
    ++n;
  }
  return n;
}

// config/hil.yaml + config/plc/hil_machine.yaml (coupler port, absolute .st paths) + a tool table,
// written to `dir`; returns the path. Fails the test if the shipped files no longer have the
// shape substituted here.
std::string assemble_config(const fs::path& dir, int port) {
  std::string hil = contour::test::slurp(kSrc + "/config/hil.yaml");
  std::string plc = contour::test::slurp(kSrc + "/config/plc/hil_machine.yaml");
  EXPECT_EQ(hil.find("\nplc:"), std::string::npos) << "config/hil.yaml has a plc: section now";
  EXPECT_EQ(hil.find("\nprogram:"), std::string::npos) << "config/hil.yaml has a program: section now";
  EXPECT_EQ(replace_all(plc, "port: 1503,", "port: " + std::to_string(port) + ","), 1U) << plc;
  EXPECT_EQ(replace_all(plc, "{file: plc/", "{file: " + kSrc + "/config/plc/"), 5U) << plc;
  // stale_ms 200 is a machine's figure; on this shared VM the coupler's poll thread has been seen
  // to stall for 200-350 ms (mlockall at the RT thread's start, steal time): "PLC I/O stale" at
  // cycle 0 and contourd exiting. The test's coupler gets 2 s (a lost coupler is still found).
  EXPECT_EQ(replace_all(plc, "stale_ms: 200}", "stale_ms: " + std::to_string(kStaleMs) + "}"), 1U) << plc;
  // Likewise the response timeout: 20 ms under User-Mode Linux (tools/with-vcan's fallback) gave
  // ~50 % timeouts and late replies taken for the next request ("Invalid data"). 500 ms here.
  EXPECT_EQ(replace_all(plc, "timeout_ms: 20,", "timeout_ms: 500,"), 1U) << plc;
  std::string tools =
      "\n# The carousel's 8 pockets (toolchanger.st: tool T lives in pocket T).\nprogram:\n  tools:\n";
  for (int t = 1; t <= 8; ++t)
    tools += "    - {number: " + std::to_string(t) + ", length_mm: " + std::to_string(5 * t) + "}\n";
  fs::create_directories(dir);
  const fs::path p = dir / "hil_plc.yaml";
  std::ofstream(p) << hil << "\n" << plc << tools;
  return p.string();
}

class Rig {
 public:
  explicit Rig(const std::string& tag)
      : dir_(fs::temp_directory_path() / ("plc_carousel_hil_" + tag + "_" + std::to_string(::getpid()))) {}
  ~Rig() {
    daemon.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  // Starts contourd (CANopen bring-up included: up to 60 s for the socket, 30 s for READY).
  void start_daemon() {
    config_ = assemble_config(dir_, sim.port());
    daemon = std::make_unique<contour::test::DaemonProcess>(
        "plc_hil", contour::test::DaemonProcess::Options{config_, {}, 6000, 3000});
  }
  PlantSim sim;
  std::unique_ptr<contour::test::DaemonProcess> daemon;

 private:
  fs::path dir_;
  std::string config_;
};

json signal(const json& io, const std::string& name) {
  for (const auto& s : io["signals"])
    if (s["name"] == name) return s;
  ADD_FAILURE() << "no signal " << name << " in " << io.dump();
  return json::object();
}

// The field side, read by a second Modbus client every few ms in a thread: what the coupler's
// coils and inputs went through while the daemon drove them.
struct FieldTrace {
  std::set<int> pockets;          // input register 0 values seen (0 = between pockets)
  bool turned = false;            // coil 0 or 1 (carousel cw / ccw) seen on
  bool unclamp_coil = false;      // coil 2 (drawbar_unclamp) seen on
  bool unclamped = false;         // discrete input 5 (drawbar_unclamped) seen on
  std::uint64_t reads = 0;
};
class FieldObserver {
 public:
  explicit FieldObserver(int port) {
    ctx_ = modbus_new_tcp("127.0.0.1", port);
    if (ctx_ == nullptr) return;
    modbus_set_slave(ctx_, 1);
    modbus_set_response_timeout(ctx_, 2, 0);
    ok_ = modbus_connect(ctx_) == 0;
    if (ok_) th_ = std::thread([this] { run(); });
  }
  ~FieldObserver() {
    stop_ = true;
    if (th_.joinable()) th_.join();
    if (ctx_ != nullptr) {
      modbus_close(ctx_);
      modbus_free(ctx_);
    }
  }
  [[nodiscard]] bool ok() const { return ok_; }
  FieldTrace trace() {
    std::lock_guard lk(mu_);
    return trace_;
  }
  // One read now (the observer thread stopped): coils 0..9, discrete inputs 0..11, register 0.
  struct Image {
    std::uint8_t coils[10]{}, di[12]{};
    std::uint16_t pocket = 0xFFFF;
    bool ok = false;
  };
  Image read_now() {
    stop_ = true;
    if (th_.joinable()) th_.join();
    Image im;
    im.ok = ok_ && modbus_read_bits(ctx_, 0, 10, im.coils) == 10 &&
            modbus_read_input_bits(ctx_, 0, 12, im.di) == 12 &&
            modbus_read_input_registers(ctx_, 0, 1, &im.pocket) == 1;
    return im;
  }

 private:
  void run() {
    while (!stop_) {
      std::uint8_t coils[3]{}, di[6]{};
      std::uint16_t pocket = 0;
      if (modbus_read_bits(ctx_, 0, 3, coils) == 3 && modbus_read_input_bits(ctx_, 0, 6, di) == 6 &&
          modbus_read_input_registers(ctx_, 0, 1, &pocket) == 1) {
        std::lock_guard lk(mu_);
        trace_.pockets.insert(pocket);
        trace_.turned = trace_.turned || coils[0] != 0 || coils[1] != 0;
        trace_.unclamp_coil = trace_.unclamp_coil || coils[2] != 0;
        trace_.unclamped = trace_.unclamped || di[5] != 0;
        ++trace_.reads;
      }
      std::this_thread::sleep_for(3ms);
    }
  }
  modbus_t* ctx_ = nullptr;
  bool ok_ = false;
  std::atomic<bool> stop_{false};
  std::thread th_;
  std::mutex mu_;
  FieldTrace trace_;
};

// `contourctl --socket S --json io`: the parsed reply (null on failure).
json contourctl_io(const std::string& sock) {
  const std::string cmd = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl --socket " + sock +
                          " --json io 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) return json();
  std::string out;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p) != nullptr) out += buf;
  const int rc = ::pclose(p);
  EXPECT_EQ(rc, 0) << cmd << "\n" << out;
  return json::parse(out, nullptr, false);
}

json device(contour::test::DaemonProcess& d, const std::string& name) {
  const json ps = d.ok({{"cmd", "plc_status"}});
  for (const auto& dev : ps["devices"])
    if (dev["name"] == name) return dev;
  ADD_FAILURE() << "no device " << name << " in " << ps.dump();
  return json::object();
}

// The device's entry once its state is "ok", or the last one after 10 s.
json device_ok(contour::test::DaemonProcess& d, const std::string& name) {
  json dev = device(d, name);
  for (int i = 0; i < 200 && dev["state"] != "ok"; ++i) {
    std::this_thread::sleep_for(50ms);
    dev = device(d, name);
  }
  return dev;
}

TEST(PlcCarouselHil, M6TurnsTheCarouselOverTheCouplerAndTheProgramGoesOn) {
  Rig r("m6");
  ASSERT_TRUE(r.sim.ready()) << r.sim.stop().dump() << r.sim.output();
  r.start_daemon();
  auto& d = *r.daemon;
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  // The coupler answers, the inputs come from it: door closed, drawbar clamped, pocket 1.
  // READY does not wait for the coupler, and plc_status/io are the engine's image published every
  // 20 cycles: under UML with steal time the first published "ok" has been seen to come after
  // READY (CI: polls 5, reads 4, state no_data). Wait for it, bounded.
  json dev = device_ok(d, "plant");
  EXPECT_EQ(dev["state"], "ok") << dev.dump();
  EXPECT_EQ(dev["endpoint"].get<std::string>().find(std::to_string(r.sim.port())) != std::string::npos, true)
      << dev.dump();
  json io = d.ok({{"cmd", "io"}});
  EXPECT_EQ(signal(io, "door_closed")["value"], true) << io.dump();
  EXPECT_EQ(signal(io, "door_closed")["source"].get<std::string>().find("modbus plant"), 0U) << io.dump();
  EXPECT_EQ(signal(io, "carousel_pocket")["value"], 1) << io.dump();
  EXPECT_EQ(d.ok({{"cmd", "status"}}).value("tool", -1), 0);

  FieldObserver field(r.sim.port());
  ASSERT_TRUE(field.ok()) << "cannot connect to the coupler at port " << r.sim.port();

  // T2 into an empty spindle (turn to pocket 2, open, close), then T3 (the old tool back to
  // pocket 2, open, turn to pocket 3, close); coolant on for the last move.
  const std::string prog =
      "G21 G90\nG1 X5 F600\nT2 M6\nG1 X10\nT3 M6\nM8\nG1 X20\nM9\nG1 X25\nM2\n";
  const auto job = d.ok({{"cmd", "load"}, {"program", prog}, {"name", "carousel.ngc"}})["job"].get<std::uint64_t>();
  d.ok({{"cmd", "run"}});
  bool saw_hold = false, saw_manual_change = false, saw_flood = false;
  std::set<std::int64_t> handshakes;  // the tools of the PLC's tool-change requests seen
  // Bounded: 6000 rounds of status + plc_status + io (at most ~300 requests/s: under the
  // socket's default max_requests_per_s of 500).
  for (int i = 0; i < 6000; ++i) {
    const json st = d.ok({{"cmd", "status"}});
    saw_hold = saw_hold || st["state"] == "HOLD";
    saw_manual_change = saw_manual_change || st.contains("tool_change");
    const json ps = d.ok({{"cmd", "plc_status"}});
    if (ps["tool_change"]["state"] != "idle") handshakes.insert(ps["tool_change"]["tool"].get<std::int64_t>());
    saw_flood = saw_flood || signal(d.ok({{"cmd", "io"}}), "coolant_flood")["value"] == true;
    if (st.value("finished_job", std::uint64_t{0}) >= job && st["state"] != "RUNNING" &&
        st["state"] != "HOLD")
      break;
    std::this_thread::sleep_for(10ms);
  }
  const json res = d.ok({{"cmd", "result"}, {"job", job}});
  EXPECT_TRUE(res.value("completed", false)) << res.dump() << "\n" << d.log();
  EXPECT_FALSE(saw_hold) << "M6 went to HOLD although the PLC runs the tool changer";
  EXPECT_FALSE(saw_manual_change) << "status showed a manual tool change";
  EXPECT_TRUE(handshakes.count(2) == 1 && handshakes.count(3) == 1)
      << "the PLC's tool-change handshakes for T2 and T3 were not both seen (" << handshakes.size()
      << " seen)";
  EXPECT_TRUE(saw_flood) << "M8 never reached coolant_flood";

  const json st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["state"], "READY") << st.dump();
  EXPECT_EQ(st.value("tool", -1), 3) << st.dump();
  EXPECT_NEAR(st["act_mm"][0].get<double>(), 25.0, 0.05) << st.dump();

  // The field: the coupler saw the carousel turn through pockets 2 and 3 and the drawbar open.
  const FieldTrace tr = field.trace();
  EXPECT_GT(tr.reads, 10U);
  EXPECT_TRUE(tr.turned);
  EXPECT_TRUE(tr.pockets.count(2) == 1 && tr.pockets.count(3) == 1) << "pockets seen: " << tr.pockets.size();
  EXPECT_TRUE(tr.unclamp_coil) << "drawbar_unclamp (coil 2) never on";
  EXPECT_TRUE(tr.unclamped) << "drawbar_unclamped (input 5) never on";
  const auto im = field.read_now();
  ASSERT_TRUE(im.ok);
  EXPECT_EQ(im.pocket, 3);
  EXPECT_EQ(im.di[3], 1) << "carousel not in position";
  EXPECT_EQ(im.di[4], 1) << "drawbar not clamped";
  EXPECT_EQ(im.di[5], 0);
  EXPECT_EQ(im.coils[0] | im.coils[1] | im.coils[2], 0) << "carousel motor or drawbar valve left on";

  // The daemon's image, through contourctl.
  const json ctl = contourctl_io(d.sock());
  ASSERT_TRUE(ctl.is_object()) << ctl.dump();
  EXPECT_EQ(signal(ctl, "carousel_pocket")["value"], 3) << ctl.dump();
  EXPECT_EQ(signal(ctl, "carousel_in_position")["value"], true);
  EXPECT_EQ(signal(ctl, "drawbar_clamped")["value"], true);
  EXPECT_EQ(signal(ctl, "drawbar_unclamp")["value"], false);
  EXPECT_EQ(signal(ctl, "coolant_flood")["value"], false);
  EXPECT_EQ(signal(ctl, "carousel_pocket")["source"], "modbus plant ir 0") << ctl.dump();

  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
  const json summary = r.sim.stop();
  ASSERT_TRUE(summary.is_object()) << r.sim.output();
  EXPECT_EQ(summary["plant"]["carousel_pocket"], 3) << summary.dump();
  EXPECT_GE(summary["plant"]["carousel_moves"].get<int>(), 2) << summary.dump();
  std::printf("[figure] M6 over the coupler: coupler requests %s, observer reads %llu\n",
              summary["plant"]["requests"].dump().c_str(), static_cast<unsigned long long>(tr.reads));
}

TEST(PlcCarouselHil, LostCouplerFaultsTheMachineAndResetWaitsForItToAnswer) {
  Rig r("lost");
  ASSERT_TRUE(r.sim.ready()) << r.sim.stop().dump() << r.sim.output();
  r.start_daemon();
  auto& d = *r.daemon;
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  ASSERT_EQ(device_ok(d, "plant")["state"], "ok");

  const auto job =
      d.ok({{"cmd", "load"}, {"program", "G21 G90\nG1 X40 F600\nM2\n"}})["job"].get<std::uint64_t>();
  d.ok({{"cmd", "run"}});
  json st = d.wait_status([](const json& s) { return s["act_mm"][0].get<double>() > 1.0; });
  ASSERT_EQ(st["state"], "RUNNING") << st.dump() << "\n" << d.log();

  ASSERT_TRUE(r.sim.event("coupler_no_reply")) << r.sim.output();
  st = d.wait_status([](const json& s) { return s["state"] == "FAULT"; });
  ASSERT_EQ(st["state"], "FAULT") << st.dump() << "\n" << d.log();
  EXPECT_EQ(st["cause"], "machine logic fault") << st.dump();
  EXPECT_EQ(st["plc"]["cause"]["action"], "engine_fault") << st.dump();
  EXPECT_EQ(st["plc"]["cause"]["engine_fault"], "PLC I/O stale") << st.dump();
  EXPECT_EQ(st["plc"]["cause"].value("device", ""), "plant") << st.dump();
  EXPECT_FALSE(st["plc"]["cause"].contains("axis")) << "a coupler is not an axis: " << st.dump();
  EXPECT_EQ(st["fault"].value("axis", 0), -1) << st.dump();
  // The latched fault names the coupler and its age against stale_ms. plc_status is the engine's
  // own snapshot, published after the loop's: it may still be a few cycles behind the status that
  // reported the FAULT (seen: cycle 780 against a fault at 792), so wait for it to catch up.
  json ps;
  for (int i = 0; i < 3000; ++i) {
    ps = d.ok({{"cmd", "plc_status"}});
    if (!ps["faults"].empty()) break;
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(ps["faults"].size(), 1U) << ps.dump();
  EXPECT_EQ(ps["faults"][0]["kind"], "PLC I/O stale") << ps.dump();
  EXPECT_EQ(ps["faults"][0]["device"], "plant") << ps.dump();
  EXPECT_NEAR(ps["faults"][0]["limit"].get<double>(), kStaleMs * 1e-3, 1e-9) << ps.dump();
  EXPECT_GT(ps["faults"][0]["value"].get<double>(), kStaleMs * 1e-3) << ps.dump();
  EXPECT_EQ(device(d, "plant")["state"], "stale");
  std::string log;
  for (int i = 0; i < 500; ++i) {
    log = d.log();
    if (log.find("machine logic fault") != std::string::npos) break;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_NE(log.find("PLC I/O stale: coupler plant"), std::string::npos) << log;

  // Motion stops: the commands ramp to 0, the axes stand still, the program ended unfinished.
  st = d.wait_status([](const json& s) {
    for (const auto& v : s["cmd_mm_s"])
      if (v.get<double>() != 0.0) return false;
    return true;
  });
  const auto c0 = st["cycle"].get<std::uint64_t>();
  const json a = d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() > c0 + 500; });
  const auto c1 = a["cycle"].get<std::uint64_t>();
  const json b = d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() > c1 + 300; });
  EXPECT_EQ(b["state"], "FAULT");
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(b["cmd_mm_s"][i].get<double>(), 0.0) << b.dump();
    EXPECT_NEAR(b["act_mm"][i].get<double>(), a["act_mm"][i].get<double>(), 1e-9) << "axis " << i;
  }
  EXPECT_LT(b["act_mm"][0].get<double>(), 39.0) << "the move was not stopped";
  EXPECT_FALSE(d.ok({{"cmd", "result"}, {"job", job}}).value("completed", true));

  // Still lost: reset is refused and the machine stays in FAULT.
  const json refused = d.call({{"cmd", "reset"}});
  EXPECT_FALSE(refused.value("ok", true)) << refused.dump();
  EXPECT_NE(refused.value("error", "").find("latched PLC fault's cause remains"), std::string::npos)
      << refused.dump();
  EXPECT_EQ(d.state(), "FAULT");
  // The loop keeps a reset pending for 250 cycles (ServoLoop::kResetWindowCycles) while the socket
  // answers after 1 s of wall time; lockstep cycles under User-Mode Linux run slower than real
  // time, so the answer above can come while the window is still open, and a coupler back within
  // it completes the reset that was reported refused (a known defect, stop 33's note). Let the
  // window close first: this test is about the coupler, not that race.
  {
    const auto refused_at = d.ok({{"cmd", "status"}})["cycle"].get<std::uint64_t>();
    d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() >= refused_at + 300; });
  }
  EXPECT_EQ(d.state(), "FAULT");

  // Back: once the coupler answers again, reset clears the fault and the machine runs again.
  ASSERT_TRUE(r.sim.event("coupler_ok")) << r.sim.output();
  json dev;
  for (int i = 0; i < 3000; ++i) {
    dev = device(d, "plant");
    if (dev["state"] == "ok") break;
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(dev["state"], "ok") << dev.dump();
  EXPECT_EQ(d.state(), "FAULT") << "the fault cleared itself without a reset";
  d.ok({{"cmd", "reset"}});
  st = d.wait_status([](const json& s) { return s["state"] == "READY"; });
  ASSERT_EQ(st["state"], "READY") << st.dump() << "\n" << d.log();
  // (plc_status, the engine's snapshot, may trail the READY status by a few cycles.)
  json after_reset;
  for (int i = 0; i < 3000; ++i) {
    after_reset = d.ok({{"cmd", "plc_status"}});
    if (after_reset["faults"].empty()) break;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_TRUE(after_reset["faults"].empty()) << after_reset.dump();
  // The interlocks may hold the start for a moment while the PLC sees the coupler's inputs again.
  st = d.wait_status([](const json& s) { return s["plc"]["requests"]["inhibit_start"] == false; }, 1000);
  ASSERT_EQ(st["plc"]["requests"]["inhibit_start"], false)
      << st.dump() << "\n" << d.ok({{"cmd", "io"}}).dump() << "\n" << d.log();
  const auto job2 =
      d.ok({{"cmd", "load"}, {"program", "G21 G90\nG1 X0 F1200\nM2\n"}})["job"].get<std::uint64_t>();
  const json ran = d.call({{"cmd", "run"}});
  ASSERT_TRUE(ran.value("ok", false)) << ran.dump() << "\n" << d.log();
  const json res = d.wait_finished(job2);
  EXPECT_TRUE(res.value("completed", false)) << res.dump() << "\n" << d.log();
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
  const json summary = r.sim.stop();
  ASSERT_TRUE(summary.is_object()) << r.sim.output();
  // (The coupler's own watchdog dropped its coils while it did not answer; it also trips once
  // while contourd boots, so the count proves nothing: printed only.)
  std::printf("[figure] lost coupler: coupler requests %s, watchdog trips %s\n",
              summary["plant"]["requests"].dump().c_str(),
              summary["plant"]["watchdog_trips"].dump().c_str());
}

TEST(PlcCarouselHil, DoorOpenOverTheCouplerHoldsTheProgramUntilClosedAndResumed) {
  Rig r("door");
  ASSERT_TRUE(r.sim.ready()) << r.sim.stop().dump() << r.sim.output();
  r.start_daemon();
  auto& d = *r.daemon;
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();

  const auto job =
      d.ok({{"cmd", "load"}, {"program", "G21 G90\nG1 X30 F600\nM2\n"}})["job"].get<std::uint64_t>();
  d.ok({{"cmd", "run"}});
  json st = d.wait_status([](const json& s) { return s["act_mm"][0].get<double>() > 1.0; });
  ASSERT_EQ(st["state"], "RUNNING") << st.dump() << "\n" << d.log();

  ASSERT_TRUE(r.sim.event("door_open")) << r.sim.output();
  st = d.wait_status([](const json& s) { return s["state"] == "HOLD"; });
  ASSERT_EQ(st["state"], "HOLD") << st.dump() << "\n" << d.log();
  EXPECT_EQ(st["plc"]["requests"]["feed_hold"], true);
  EXPECT_EQ(st["plc"]["requests"]["inhibit_start"], true);
  EXPECT_EQ(st["plc"]["cause"]["action"], "feed_hold_req");
  // The io image is the PLC engine's snapshot, which may trail the loop's status by a few cycles.
  json door;
  for (int i = 0; i < 3000; ++i) {
    door = signal(d.ok({{"cmd", "io"}}), "door_closed");
    if (door["value"] == false) break;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_EQ(door["value"], false) << door.dump();
  EXPECT_LT(st["act_mm"][0].get<double>(), 29.0);

  // Open: resume is refused, the program stays held.
  const json refused = d.call({{"cmd", "resume"}});
  std::this_thread::sleep_for(200ms);
  EXPECT_EQ(d.state(), "HOLD") << refused.dump();

  ASSERT_TRUE(r.sim.event("door_close")) << r.sim.output();
  st = d.wait_status([](const json& s) { return s["plc"]["requests"]["feed_hold"] == false; });
  EXPECT_EQ(st["plc"]["requests"]["feed_hold"], false) << st.dump();
  EXPECT_EQ(st["state"], "HOLD") << "closing the door must not resume by itself";
  d.ok({{"cmd", "resume"}});
  const json res = d.wait_finished(job);
  EXPECT_TRUE(res.value("completed", false)) << res.dump() << "\n" << d.log();
  st = d.ok({{"cmd", "status"}});
  EXPECT_NEAR(st["act_mm"][0].get<double>(), 30.0, 0.05) << st.dump();
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
}

}  // namespace
