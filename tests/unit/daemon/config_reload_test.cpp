// daemon/config_reload: every changed key of a SIGHUP reload is found and classified (issue 16:
// nothing silently ignored).
#include "daemon/config_reload.hpp"

#include <gtest/gtest.h>

namespace contour::daemon {
namespace {

TEST(ConfigReload, EveryChangedKeyIsFoundAddedAndRemovedOnesToo) {
  const YAML::Node a = YAML::Load(
      "machine:\n  axes:\n    - {name: X, max_mm: 200}\n    - {name: Y}\n"
      "interpolator: {fir_ms: 100}\nsafety: {ferror_mm: 1.0}\n");
  const YAML::Node b = YAML::Load(
      "machine:\n  axes:\n    - {name: X, max_mm: 50}\n    - {name: Y}\n"
      "interpolator: {fir_ms: 80}\nsafety: {ferror_mm: 1.0, stop_decel_mm_s2: 500}\n"
      "control: {kp: 0.5}\n");
  const auto d = diff_config(a, b);
  ASSERT_EQ(d.size(), 4u);
  EXPECT_EQ(d[0].key, "control.kp");
  EXPECT_EQ(d[0].old_value, "<absent>");
  EXPECT_EQ(d[0].cls, ReloadClass::kGains);
  EXPECT_EQ(d[1].key, "interpolator.fir_ms");
  EXPECT_EQ(d[1].cls, ReloadClass::kRestart);
  EXPECT_EQ(d[2].key, "machine.axes[0].max_mm");
  EXPECT_EQ(d[2].old_value, "200");
  EXPECT_EQ(d[2].new_value, "50");
  EXPECT_EQ(d[2].cls, ReloadClass::kLimits);
  EXPECT_EQ(d[3].key, "safety.stop_decel_mm_s2");
  EXPECT_EQ(d[3].cls, ReloadClass::kLimits);
  EXPECT_TRUE(diff_config(a, a).empty());
}

TEST(ConfigReload, ClassesOfKeys) {
  EXPECT_EQ(classify_key("machine.axes[2].min_mm"), ReloadClass::kLimits);
  EXPECT_EQ(classify_key("machine.axes[2].sim.delay_cycles"), ReloadClass::kRestart);
  EXPECT_EQ(classify_key("machine.axes[1].name"), ReloadClass::kRestart);
  EXPECT_EQ(classify_key("interpolator.feed_override_max_percent"), ReloadClass::kLimits);
  EXPECT_EQ(classify_key("control.coupling.cp"), ReloadClass::kGains);
  EXPECT_EQ(classify_key("controlled"), ReloadClass::kRestart);
  EXPECT_EQ(classify_key("log.level"), ReloadClass::kLog);
  EXPECT_EQ(classify_key("mqtt.host"), ReloadClass::kCompanion);
  EXPECT_EQ(classify_key("bus.type"), ReloadClass::kRestart);
  EXPECT_EQ(classify_key("socket.path"), ReloadClass::kRestart);
}

TEST(ConfigReload, ListsThatChangeLengthReportEachElement) {
  const auto d = diff_config(YAML::Load("a: [1, 2]\n"), YAML::Load("a: [1, 2, 3]\n"));
  ASSERT_EQ(d.size(), 1u);
  EXPECT_EQ(d[0].key, "a[2]");
  EXPECT_EQ(d[0].new_value, "3");
}

}  // namespace
}  // namespace contour::daemon
