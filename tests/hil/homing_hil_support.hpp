#pragma once
// Shared pieces of the homing HIL tests (homing_hil_test, index_homing_hil_test,
// drive_homing_hil_test): config/hil.yaml with X's travel -20..200 mm and a home: section of the
// test's own (Y and Z unhomed), and "X at rest at the target" through the socket.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/daemon_process.hpp"

namespace contour::test {

// Writes the variant to a file of this process and returns its path. `home` is X's home: flow
// map; `load_ceiling_percent` > 0 replaces hil.yaml's bus.load_ceiling_percent (80): homing maps
// more PDOs (0x60FD in TPDO2, the touch probe in TPDO3) than hil.yaml's 1 Mbit/s bus has room
// for under 80 % (vcan has no bit time; the tests raise the ceiling, not the bit rate the
// simulator expects). A missing anchor text in hil.yaml fails the test, naming it.
inline std::string hil_homing_config(const std::string& tag, const std::string& home,
                                     int load_ceiling_percent = 0) {
  std::string y = slurp(std::string(CONTOUR_SOURCE_DIR) + "/config/hil.yaml");
  auto sub = [&y](const std::string& from, const std::string& to) {
    const auto at = y.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) y.replace(at, from.size(), to);
  };
  sub("machine:\n", "machine:\n  allow_unhomed: true  # Y and Z are not homed here\n");
  sub("min_mm: -200, max_mm: 200, max_velocity_mm_min: 10000}",
      "min_mm: -20, max_mm: 200, max_velocity_mm_min: 10000,\n       home: " + home + "}");
  if (load_ceiling_percent > 0)
    sub("load_ceiling_percent: 80", "load_ceiling_percent: " + std::to_string(load_ceiling_percent));
  const auto path = std::filesystem::temp_directory_path() /
                    ("contour_hil_homing_" + tag + "_" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(path) << y;
  return path.string();
}

// X at rest at `target_mm`: two samples at least 300 cycles apart, 1 um from each other and 2 um
// from the target (the final move is a trapezoid that rings some 25 um past its end and settles
// within ~0.3 s: being within 2 um once can be mid-swing).
inline nlohmann::json wait_x_at_rest(DaemonProcess& d, double target_mm) {
  using nlohmann::json;
  for (int k = 0; k < 60; ++k) {
    const json s1 = d.ok({{"cmd", "status"}});
    const auto c1 = s1["cycle"].get<std::uint64_t>();
    const json s2 = d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() >= c1 + 300; });
    const double x1 = s1["act_mm"][0].get<double>(), x2 = s2["act_mm"][0].get<double>();
    if (std::abs(x2 - x1) < 0.001 && std::abs(x2 - target_mm) < 0.002) return s2;
  }
  ADD_FAILURE() << "X never came to rest at " << target_mm << " mm\n" << d.log();
  return d.ok({{"cmd", "status"}});
}

}  // namespace contour::test
