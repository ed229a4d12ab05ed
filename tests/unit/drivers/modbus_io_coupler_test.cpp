// IoCoupler (the soft PLC's Modbus remote I/O) against contour-machine-sim's simulated coupler
// (tools/contour-machine-sim/plant_io.hpp) on loopback: inputs of every table read, outputs
// written in runs that never touch an address between two outputs, a lost coupler going stale
// (the PLC engine's fault) and coming back without restarting the coupler object, exception
// replies counted, the safe outputs written at stop, the coupler's own watchdog, RT calls
// without allocation. Waits are bounded polls on conditions (no wall-clock assertion).
#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <thread>

#include "drivers/modbus/io_coupler.hpp"
#include "tests/support/alloc_counter.hpp"
// The simulated coupler lives in contour-machine-sim, which is not a library (as in
// modbus_dynamometer_test.cpp).
#include "tools/contour-machine-sim/dynamometer_server.cpp"
#include "tools/contour-machine-sim/plant_io.cpp"

namespace dm = contour::drivers::modbus;
using contour::sim::CouplerServer;
using contour::sim::FaultMode;
using namespace std::chrono_literals;

namespace {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

bool eventually(const std::function<bool()>& f, std::chrono::milliseconds limit = 5000ms) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < end) {
    if (f()) return true;
    std::this_thread::sleep_for(2ms);
  }
  return f();
}

dm::IoCouplerSettings settings(int port) {
  dm::IoCouplerSettings s;
  s.name = "test";
  s.transport.transport = dm::Transport::kTcp;
  s.transport.host = "127.0.0.1";
  s.transport.port = port;
  s.transport.response_timeout = 20ms;
  s.poll_hz = 200;
  s.stale_after = 100ms;
  s.reconnect_min = 10ms;
  s.reconnect_max = 100ms;
  s.discrete_inputs = {2, 4};   // 2..5
  s.input_registers = {0, 2};
  s.holding_inputs = {10, 1};
  s.coils = {0, 1, 5};          // runs {0,1} and {5}
  s.holding_outputs = {20, 21};
  return s;
}

}  // namespace

TEST(ModbusIoCoupler, ReadsInputsAndWritesOutputRuns) {
  CouplerServer server(1, 5000ms);
  server.start();
  server.set_discrete(3, true);
  server.set_discrete(5, true);
  server.set_input_register(1, 0xBEEF);
  // Another master's values at coil 3 and register 22: never overwritten by the runs.
  server.set_coil(3, true);
  server.set_holding(22, 77);
  dm::CouplerOutputs safe{};
  dm::IoCoupler c(settings(server.port()), safe);
  EXPECT_EQ(c.coil_base(), 0);
  EXPECT_EQ(c.holding_output_base(), 20);
  c.start();
  dm::CouplerInputs in;
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kOk; }));
  EXPECT_EQ(in.discrete[0], 0);  // address 2
  EXPECT_EQ(in.discrete[1], 1);  // address 3
  EXPECT_EQ(in.discrete[3], 1);  // address 5
  EXPECT_EQ(in.input_registers[1], 0xBEEF);
  dm::CouplerOutputs out{};
  out.coils[1] = 1;
  out.coils[5] = 1;
  out.holding[1] = 1234;  // register 21
  c.write(out);
  ASSERT_TRUE(eventually([&] { return server.coil(1) && server.coil(5) && server.holding(21) == 1234; }));
  EXPECT_FALSE(server.coil(0));
  EXPECT_TRUE(server.coil(3));
  EXPECT_EQ(server.holding(22), 77);
  c.stop();
  server.stop();
}

TEST(ModbusIoCoupler, LostCouplerGoesStaleAndRecovers) {
  CouplerServer server(1, 5000ms);
  server.start();
  dm::IoCoupler c(settings(server.port()), dm::CouplerOutputs{});
  c.start();
  dm::CouplerInputs in;
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kOk; }));
  const int port = server.port();
  server.stop();  // the coupler is gone (cable pulled)
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kStale; }));
  EXPECT_GT(c.read(now_ns(), in).age_ns, 100000000);
  EXPECT_FALSE(c.status().last_error.empty());
  server.start("127.0.0.1", port);  // back on the same port
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kOk; }));
  EXPECT_GE(c.status().reconnects, 1u);
  c.stop();
  server.stop();
}

TEST(ModbusIoCoupler, NoReplyAndExceptionsAreCountedAndGoStale) {
  CouplerServer server(1, 5000ms);
  server.start();
  dm::IoCoupler c(settings(server.port()), dm::CouplerOutputs{});
  c.start();
  dm::CouplerInputs in;
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kOk; }));
  server.set_fault(FaultMode::kNoReply);
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kStale; }));
  EXPECT_GE(c.status().timeouts, 1u);
  server.set_fault(FaultMode::kException, 0ms, 2);
  ASSERT_TRUE(eventually([&] { return c.status().exceptions >= 1; }));
  EXPECT_EQ(c.read(now_ns(), in).state, dm::CouplerState::kStale);  // no record published
  EXPECT_NE(c.status().last_error.find("illegal data address"), std::string::npos);
  server.set_fault(FaultMode::kNone);
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kOk; }));
  c.stop();
  server.stop();
}

TEST(ModbusIoCoupler, SafeOutputsAtStopAndTheCouplersWatchdog) {
  CouplerServer server(1, 150ms);
  server.start();
  dm::CouplerOutputs safe{};
  safe.coils[0] = 1;  // e.g. a normally-energised "ready" lamp: safe state ON
  dm::IoCoupler c(settings(server.port()), safe);
  c.start();
  // Before the RT side writes, the safe outputs are applied.
  ASSERT_TRUE(eventually([&] { return server.coil(0); }));
  dm::CouplerOutputs out{};
  out.coils[5] = 1;
  c.write(out);
  ASSERT_TRUE(eventually([&] { return server.coil(5) && !server.coil(0); }));
  c.stop();
  EXPECT_TRUE(server.coil(0));   // safe outputs written on the way out
  EXPECT_FALSE(server.coil(5));
  // Nobody polls any more: the coupler's watchdog drops every coil.
  ASSERT_TRUE(eventually([&] { return !server.coil(0); }));
  EXPECT_GE(server.watchdog_trips(), 1u);
  server.stop();
}

TEST(ModbusIoCoupler, RtCallsDoNotAllocate) {
  CouplerServer server(1, 5000ms);
  server.start();
  dm::IoCoupler c(settings(server.port()), dm::CouplerOutputs{});
  c.start();
  dm::CouplerInputs in;
  ASSERT_TRUE(eventually([&] { return c.read(now_ns(), in).state == dm::CouplerState::kOk; }));
  dm::CouplerOutputs out{};
  std::size_t allocs = 0;
  {
    contour::test::AllocGuard g;
    for (int i = 0; i < 10000; ++i) {
      (void)c.read(now_ns(), in);
      out.coils[0] = static_cast<std::uint8_t>(i & 1);
      c.write(out);
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
  c.stop();
  server.stop();
}

TEST(ModbusIoCoupler, BadSettingsNameTheCouplerAndTable) {
  auto s = settings(1502);
  s.discrete_inputs = {0, 300};
  try {
    dm::IoCoupler c(s, dm::CouplerOutputs{});
    FAIL() << "accepted 300 discrete inputs";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("modbus coupler 'test': discrete inputs span 300"),
              std::string::npos);
  }
  s = settings(1502);
  s.coils = {0, 400};
  EXPECT_THROW(dm::IoCoupler(s, dm::CouplerOutputs{}), std::invalid_argument);
}

TEST(PlantEvents, ParseAndApply) {
  const auto e = contour::sim::parse_plant_event("door_open@1500");
  EXPECT_EQ(e.kind, "door_open");
  EXPECT_EQ(e.sync, 1500);
  EXPECT_THROW(contour::sim::parse_plant_event("teleport@3"), std::invalid_argument);
  EXPECT_THROW(contour::sim::parse_plant_event("door_open@x"), std::invalid_argument);
  CouplerServer server;
  contour::sim::PlantIo io(server);
  contour::control::plc::PlantFaults f;
  contour::sim::apply_plant_event(e, io.plant(), f, server);
  io.step(0.001, {0, 0, 0});
  EXPECT_EQ(io.plant().get(contour::control::plc::PlantPoint::kDoorClosed), 0);
}
