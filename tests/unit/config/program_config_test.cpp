// `program:` and `interpolator:` sections: values, defaults, and errors with line and key path.
#include <gtest/gtest.h>

#include "config/config.hpp"

using namespace contour::config;

namespace {
const char* kMachine = "machine:\n  axes:\n    - {name: X}\n    - {name: Y}\n    - {name: Z}\n";

std::vector<std::string> errors_of(const std::string& yaml) {
  try {
    load_config_string(std::string(kMachine) + yaml, "p.yaml");
  } catch (const ConfigError& e) {
    return e.errors();
  }
  return {};
}
bool any_contains(const std::vector<std::string>& v, const std::string& s) {
  for (const auto& e : v)
    if (e.find(s) != std::string::npos) return true;
  return false;
}
}  // namespace

TEST(ProgramConfig, ParsesOffsetsToolsReferences) {
  const auto cfg = load_config_string(std::string(kMachine) +
                                      "program:\n  work_offsets: {G54: [1, 2, 3], G59: [4, 5, 6]}\n"
                                      "  tools:\n    - {number: 2, length_mm: 25.5}\n"
                                      "  g28_mm: [0, 0, 100]\n  g30_mm: [10, 10, 100]\n  rapid_mm_min: 8000\n"
                                      "interpolator:\n  fir_ms: 80\n  blend: g64\n  tolerance_um: 20\n"
                                      "  rounding: floor\n  method: exhaustive\n");
  EXPECT_EQ(cfg.program.work_offsets_mm[0][2], 3);
  EXPECT_EQ(cfg.program.work_offsets_mm[5][0], 4);
  ASSERT_EQ(cfg.program.tools.size(), 1u);
  EXPECT_EQ(cfg.program.tools[0].length_mm, 25.5);
  EXPECT_EQ(cfg.program.g30_mm[0], 10);
  EXPECT_EQ(cfg.program.rapid_mm_min, 8000);
  EXPECT_EQ(cfg.interpolator.fir_ms, 80);
  EXPECT_EQ(cfg.interpolator.blend, contour::control::BlendMode::kFull);
  EXPECT_TRUE(cfg.interpolator.floor_rounding);
  EXPECT_EQ(cfg.interpolator.method, contour::control::BlendMethod::kExhaustive);
  const auto st = to_program_setup(cfg.program, cfg.interpolator);
  EXPECT_DOUBLE_EQ(st.default_tolerance_mm, 0.02);
  EXPECT_EQ(st.work_offsets_mm[0].y(), 2);
  EXPECT_EQ(fir_taps(100, 0.001), 101);
}

TEST(ProgramConfig, DefaultsWhenAbsent) {
  const auto cfg = load_config_string(kMachine);
  EXPECT_EQ(cfg.interpolator.fir_ms, 100);
  EXPECT_EQ(cfg.interpolator.blend, contour::control::BlendMode::kLimited);
  EXPECT_EQ(cfg.interpolator.tolerance_um, 50);
  EXPECT_TRUE(cfg.program.tools.empty());
}

TEST(ProgramConfig, ErrorsNameLineAndKey) {
  auto e = errors_of("program:\n  work_offsets: {G54: [1, 2], G60: [0, 0, 0]}\n  tools:\n    - {number: 1}\n"
                     "    - {number: 1, length_mm: 3}\n  bogus: 1\ninterpolator:\n  blend: g65\n  fir_ms: -3\n");
  EXPECT_TRUE(any_contains(e, "program.work_offsets.G54: expected 3..3 numbers")) << e.size();
  EXPECT_TRUE(any_contains(e, "program.work_offsets.G60: unknown key"));
  EXPECT_TRUE(any_contains(e, "program.tools[0].length_mm"));
  EXPECT_TRUE(any_contains(e, "tool 1 is defined twice"));
  EXPECT_TRUE(any_contains(e, "p.yaml:11:3: program.bogus: unknown key"));
  EXPECT_TRUE(any_contains(e, "interpolator.blend"));
  EXPECT_TRUE(any_contains(e, "interpolator.fir_ms"));
}
