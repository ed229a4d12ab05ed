// contourd (the built binary) on the built-in simulated machine with a PLC program on X's drive
// digital I/O (plc.signals cia402, issue 20): the sim bus' default switches (daemon/sim_bus.hpp:
// home switch below min_mm + 0.5 mm) reach the PLC through the loop, the program's output goes
// to 0x60FE:01, `io` names the sources "axis x 0x60FD bit 2", and the start inhibit the ST
// program derives from the home switch refuses `run` until the axis leaves it. Bounded polls.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

json signal(const json& io, const std::string& name) {
  for (const auto& s : io["signals"])
    if (s["name"] == name) return s;
  return json::object();
}

// The io snapshot is published by the loop a little after the status: poll it (bounded).
json wait_io(contour::test::DaemonProcess& d, const std::string& name, bool value) {
  json io;
  for (int i = 0; i < 300; ++i) {
    io = d.ok({{"cmd", "io"}});
    if (signal(io, name)["value"] == value) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return io;
}

TEST(PlcDriveIoDaemon, HomeSwitchOnTheDriveInputReachesThePlcAndItsOutput) {
  const fs::path dir =
      fs::temp_directory_path() / ("drive_io_daemon_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::stringstream sim;
  sim << contour::test::sim_yaml(contour::test::SimPlc::kNone);  // this test brings its own plc:
  std::ofstream(dir / "home.st") << "PROGRAM homing\n  NC.inhibit_start := x_home;\n"
                                    "  x_lamp := x_home;\nEND_PROGRAM\n";
  std::ofstream(dir / "c.yaml")
      << sim.str()
      << "\nplc:\n  programs: [{file: home.st}]\n  signals:\n"
         "    - {name: x_home, cia402: {axis: X, input: home_switch}}\n"
         "    - {name: x_plus, cia402: {axis: X, input: positive_limit}}\n"
         "    - {name: x_lamp, cia402: {axis: X, output: 16}}\n";
  contour::test::DaemonProcess::Options o;
  o.config = (dir / "c.yaml").string();
  {
    contour::test::DaemonProcess d("driveio", o);
    ASSERT_TRUE(d.connected()) << d.log();
    ASSERT_EQ(d.state(), "READY") << d.log();

    json io = d.ok({{"cmd", "io"}});
    EXPECT_EQ(signal(io, "x_home")["source"], "axis x 0x60FD bit 2");
    EXPECT_EQ(signal(io, "x_plus")["source"], "axis x 0x60FD bit 1");
    EXPECT_EQ(signal(io, "x_lamp")["source"], "axis x 0x60FE:01 bit 16");
    EXPECT_EQ(signal(io, "x_lamp")["direction"], "output");
    EXPECT_EQ(signal(io, "x_home")["value"], false);

    // Onto the home switch (min_mm -200: on below -199.5 mm).
    d.ok({{"cmd", "set-position"}, {"axis", "X"}, {"position_mm", -199.8}});
    json st = d.wait_status(
        [](const json& s) { return s["plc"]["requests"]["inhibit_start"] == true; }, 500);
    EXPECT_EQ(st["plc"]["requests"]["inhibit_start"], true) << d.log();
    io = wait_io(d, "x_lamp", true);
    EXPECT_EQ(signal(io, "x_home")["value"], true);
    EXPECT_EQ(signal(io, "x_lamp")["value"], true);
    EXPECT_EQ(signal(io, "x_plus")["value"], false);
    // The loop refuses the jog (the reply only says it was posted): the axis stays put for
    // 600 cycles, three times what the jog would take.
    d.call({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", 300}, {"distance_mm", 1.0}});
    const std::uint64_t c0 = d.ok({{"cmd", "status"}})["cycle"].get<std::uint64_t>();
    st = d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() > c0 + 600; },
                       3000);
    EXPECT_NEAR(st["act_mm"][0].get<double>(), -199.8, 0.01) << st.dump();

    d.ok({{"cmd", "set-position"}, {"axis", "X"}, {"position_mm", 0.0}});
    st = d.wait_status([](const json& s) { return s["plc"]["requests"]["inhibit_start"] == false; },
                       500);
    EXPECT_EQ(st["plc"]["requests"]["inhibit_start"], false) << d.log();
    EXPECT_EQ(signal(wait_io(d, "x_lamp", false), "x_lamp")["value"], false);
    d.ok({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", 300}, {"distance_mm", 1.0}});
    st = d.wait_status(
        [](const json& s) { return std::abs(s["act_mm"][0].get<double>() - 1.0) < 0.01; }, 3000);
    EXPECT_NEAR(st["act_mm"][0].get<double>(), 1.0, 0.01) << st.dump();
  }
  fs::remove_all(dir);
}

}  // namespace
