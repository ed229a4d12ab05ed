// libgpiod v1.6 backend error paths. No kernel here has gpio-sim and /dev has no gpiochip, so
// success paths cannot run; what is tested: missing chip, missing line name, offset without chip,
// unconfigured line: each a GpioError naming the role and line. Busy lines need a real chip: the
// test for it runs only if /dev/gpiochip0 exists, and says so otherwise.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "drivers/gpio/gpiod_backend.hpp"

namespace dg = contour::drivers::gpio;

namespace {
std::string error_of(auto&& f) {
  try {
    f();
  } catch (const dg::GpioError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(GpioGpiod, MissingChipIsAClearError) {
  dg::GpiodBackend b;
  dg::LineSpec s;
  s.chip = "gpiochip77";
  s.offset = 3;
  s.role = "estop";
  const std::string e = error_of([&] { b.request_input(s, true); });
  EXPECT_NE(e.find("estop (gpiochip77:3)"), std::string::npos) << e;
  EXPECT_NE(e.find("open chip 'gpiochip77'"), std::string::npos) << e;
  std::printf("[message] %s\n", e.c_str());
}

TEST(GpioGpiod, MissingLineNameIsAClearError) {
  dg::GpiodBackend b;
  dg::LineSpec s;
  s.name = "NO_SUCH_LINE";
  s.role = "drive_enable";
  const std::string e = error_of([&] { b.request_output(s, false); });
  EXPECT_NE(e.find("drive_enable (line 'NO_SUCH_LINE')"), std::string::npos) << e;
  std::printf("[message] %s\n", e.c_str());
}

TEST(GpioGpiod, NamedLineOnMissingChip) {
  dg::GpiodBackend b;
  dg::LineSpec s;
  s.name = "ESTOP";
  s.chip = "/dev/gpiochip99";
  s.role = "estop";
  const std::string e = error_of([&] { b.request_input(s, true); });
  EXPECT_NE(e.find("estop"), std::string::npos) << e;
  EXPECT_FALSE(e.empty());
  std::printf("[message] %s\n", e.c_str());
}

TEST(GpioGpiod, UnconfiguredOrIncompleteLine) {
  dg::GpiodBackend b;
  dg::LineSpec s;
  s.role = "coolant_mist";
  EXPECT_NE(error_of([&] { b.request_output(s, false); }).find("no offset or name"),
            std::string::npos);
  s.offset = 2;
  EXPECT_NE(error_of([&] { b.request_output(s, false); }).find("offset given without chip"),
            std::string::npos);
}

TEST(GpioGpiod, BusyLineNeedsARealChip) {
  if (!std::filesystem::exists("/dev/gpiochip0")) {
    GTEST_SKIP() << "no /dev/gpiochip0 (and no gpio-sim in this kernel): busy-line path not run";
  }
  dg::GpiodBackend a("contourd-test-a");
  dg::GpiodBackend b("contourd-test-b");
  dg::LineSpec s;
  s.chip = "gpiochip0";
  s.offset = 0;
  s.role = "spindle_enable";
  auto first = a.request_input(s, false);
  const std::string e = error_of([&] { b.request_input(s, false); });
  EXPECT_NE(e.find("busy"), std::string::npos) << e;
}
