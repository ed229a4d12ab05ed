// machine.axes[].identified (issue 16): the drive model measured by `contourctl identify` and
// stored by `gains save`, validated on load, and compared at start-up with the model the
// controller uses (sim:): a delay that differs is a warning naming the axis.
#include <gtest/gtest.h>

#include <string>

#include "config/config.hpp"

namespace {

using contour::config::identification_warnings;
using contour::config::load_config_string;

std::string machine(const std::string& x_extra) {
  return "machine:\n  axes:\n"
         "    - name: X\n      sim: {gain_per_s: 120, tau_ms: 30, delay_cycles: 1}\n" +
         x_extra + "    - {name: Y}\n";
}

TEST(IdentifiedConfig, AbsentMeansNothingMeasuredAndNoWarning) {
  const auto cfg = load_config_string(machine(""));
  EXPECT_FALSE(cfg.machine.axes[0].identified.present);
  EXPECT_TRUE(identification_warnings(cfg.machine).empty());
}

TEST(IdentifiedConfig, AMatchingMeasurementGivesNoWarning) {
  const auto cfg = load_config_string(machine(
      "      identified: {gain_per_s: 121.5, tau_ms: 31, delay_cycles: 1, date: \"2026-11-27T05:00:00Z\"}\n"));
  const auto& id = cfg.machine.axes[0].identified;
  ASSERT_TRUE(id.present);
  EXPECT_DOUBLE_EQ(id.gain_per_s, 121.5);
  EXPECT_DOUBLE_EQ(id.tau_s, 0.031);
  EXPECT_EQ(id.delay_cycles, 1);
  EXPECT_EQ(id.date, "2026-11-27T05:00:00Z");
  EXPECT_TRUE(identification_warnings(cfg.machine).empty());
}

TEST(IdentifiedConfig, ADifferentDelayIsAWarningNamingTheAxis) {
  const auto cfg = load_config_string(
      machine("      identified: {gain_per_s: 120, tau_ms: 30, delay_cycles: 2}\n"));
  const auto w = identification_warnings(cfg.machine);
  ASSERT_EQ(w.size(), 1U);
  EXPECT_NE(w[0].find("machine.axes[0] (X)"), std::string::npos) << w[0];
  EXPECT_NE(w[0].find("measured as 2 cycles"), std::string::npos) << w[0];
  EXPECT_NE(w[0].find("sim.delay_cycles is 1"), std::string::npos) << w[0];
}

TEST(IdentifiedConfig, GainAndTimeConstantBeyondTheVerdictThresholdsWarn) {
  // +10 % gain (threshold 5 %), +20 % tau (threshold 10 %); delay equal.
  const auto cfg = load_config_string(
      machine("      identified: {gain_per_s: 132, tau_ms: 36, delay_cycles: 1}\n"));
  const auto w = identification_warnings(cfg.machine);
  ASSERT_EQ(w.size(), 2U);
  EXPECT_NE(w[0].find("gain"), std::string::npos) << w[0];
  EXPECT_NE(w[0].find("+10 %"), std::string::npos) << w[0];
  EXPECT_NE(w[1].find("time constant"), std::string::npos) << w[1];
  EXPECT_NE(w[1].find("+20 %"), std::string::npos) << w[1];
}

TEST(IdentifiedConfig, IncompleteOrOutOfRangeIsAnErrorNamingTheKey) {
  try {
    (void)load_config_string(machine("      identified: {gain_per_s: 120, tau_ms: 30}\n"));
    FAIL() << "accepted an identified block without delay_cycles";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("delay_cycles"), std::string::npos) << e.what();
  }
  try {
    (void)load_config_string(
        machine("      identified: {gain_per_s: 120, tau_ms: 30, delay_cycles: 1, k: 3}\n"));
    FAIL() << "accepted an unknown key";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("identified.k"), std::string::npos) << e.what();
  }
  try {
    (void)load_config_string(
        machine("      identified: {gain_per_s: -1, tau_ms: 30, delay_cycles: 1}\n"));
    FAIL() << "accepted a negative gain";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("gain_per_s"), std::string::npos) << e.what();
  }
}

}  // namespace
