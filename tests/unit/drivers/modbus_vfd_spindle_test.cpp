// Spindle limits/ramp/at-speed (pure) and the Modbus VFD spindle against a minimal simulated VFD
// (libmodbus TCP server on loopback whose actual speed follows the setpoint while running).
#include <gtest/gtest.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "drivers/modbus/vfd_spindle.hpp"
#include "tests/support/sim_vfd.hpp"

namespace dm = contour::drivers::modbus;
using contour::drivers::SpindleLimits;
using namespace std::chrono_literals;

TEST(Spindle, ClampRampAtSpeed) {
  SpindleLimits l;
  l.min_rpm = 500;
  l.max_rpm = 12000;
  l.rate_rpm_s = 1000;
  EXPECT_EQ(contour::drivers::clamp_spindle_rpm(20000, l), 12000);
  EXPECT_EQ(contour::drivers::clamp_spindle_rpm(-100, l), -500);
  EXPECT_EQ(contour::drivers::clamp_spindle_rpm(0, l), 0);
  EXPECT_EQ(contour::drivers::clamp_spindle_rpm(std::nan(""), l), 0);
  contour::drivers::SpindleRamp r(l);
  for (int i = 0; i < 10; ++i) r.step(3000, 0.1);
  EXPECT_NEAR(r.setpoint(), 1000, 1e-9);                           // 1000 rpm/s for 1 s
  EXPECT_TRUE(contour::drivers::spindle_at_speed(2960, 3000, l));  // 2 % of 3000 = 60
  EXPECT_FALSE(contour::drivers::spindle_at_speed(2900, 3000, l));
}

namespace {
using contour::test::SimVfd;

dm::VfdSettings vfd_settings(int port) {
  dm::VfdSettings s;
  s.transport.transport = dm::Transport::kTcp;
  s.transport.port = port;
  s.limits.min_rpm = 500;
  s.limits.max_rpm = 12000;
  s.limits.rate_rpm_s = 20000;
  s.setpoint_register = 0;
  s.run_address = 1;
  s.actual_register = 2;
  s.setpoint_counts_per_rpm = 0.5;  // e.g. 0.1 Hz units on a 2-pole... any scale
  s.actual_counts_per_rpm = 0.5;
  s.update_rate_hz = 50;
  return s;
}

template <typename P>
bool eventually(P p, std::chrono::milliseconds lim) {
  const auto end = std::chrono::steady_clock::now() + lim;
  while (std::chrono::steady_clock::now() < end) {
    if (p()) return true;
    std::this_thread::sleep_for(5ms);
  }
  return false;
}
}  // namespace

TEST(VfdSpindle, ReachesSpeedWritesRegistersAndStops) {
  SimVfd vfd;
  dm::VfdSpindle sp(vfd_settings(vfd.port()));
  sp.start();
  EXPECT_EQ(sp.set_speed(3000), 3000);
  ASSERT_TRUE(eventually([&] { return sp.status().at_speed; }, 2s));
  EXPECT_EQ(vfd.setpoint.load(), 1500);
  EXPECT_EQ(vfd.run_cmd.load(), 1);
  EXPECT_NEAR(sp.status().actual_rpm, 3000, 1);
  EXPECT_EQ(sp.set_speed(-99999), -12000);
  ASSERT_TRUE(eventually([&] { return sp.status().at_speed; }, 2s));
  EXPECT_EQ(vfd.run_cmd.load(), 2);
  sp.stop();
  ASSERT_TRUE(eventually([&] { return vfd.run_cmd.load() == 0 && sp.status().at_speed; }, 2s));
  EXPECT_FALSE(sp.status().running);
}

TEST(VfdSpindle, CommunicationLossIsNotAtSpeed) {
  auto vfd = std::make_unique<SimVfd>();
  dm::VfdSpindle sp(vfd_settings(vfd->port()));
  sp.start();
  sp.set_speed(2000);
  ASSERT_TRUE(eventually([&] { return sp.status().at_speed; }, 2s));
  vfd.reset();
  ASSERT_TRUE(eventually([&] { return !sp.status().comm_ok; }, 2s));
  EXPECT_FALSE(sp.status().at_speed);
  EXPECT_EQ(sp.status().fault, contour::drivers::SpindleFault::kCommunication);
  EXPECT_GT(sp.comm_errors(), 0u);
}

TEST(VfdSpindle, BadSettingsThrow) {
  dm::VfdSettings s;
  s.limits.min_rpm = 5000;
  s.limits.max_rpm = 1000;
  EXPECT_THROW(dm::VfdSpindle{s}, std::invalid_argument);
}
