// Seed 000 figures (issue 4 table), run through the real `contour-sim contour` binary so the CLI
// and JSON contract are tested with them. Each bar has a deliberately detuned variant that must
// miss it, so the checks can fail. Paper settings (no transport delay) use --delay-cycles 0; the
// delay row uses the CANopen default of config/table1.yaml (1 cycle).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "tests/support/sim_config.hpp"
#include "tests/support/temp_dir.hpp"

namespace {

std::string sim_binary() {
  if (const char* env = std::getenv("CONTOUR_SIM_BIN")) return env;  // dev override
  return CONTOUR_BINARY_DIR "/tools/contour-sim";
}

// Runs contour-sim contour with `args`; returns the last stdout line parsed as JSON.
nlohmann::json run(const std::string& args, int* exit_code = nullptr) {
  const std::string cmd = "cd " CONTOUR_SOURCE_DIR " && " + sim_binary() + " contour " + args;
  FILE* p = popen(cmd.c_str(), "r");
  if (p == nullptr) return {};
  std::string out, last;
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), buf.size(), p) != nullptr) out += buf.data();
  const int rc = pclose(p);
  if (exit_code != nullptr) *exit_code = WEXITSTATUS(rc);
  const auto end = out.find_last_not_of('\n');
  if (end == std::string::npos) return {};
  const auto start = out.rfind('\n', end);
  last = out.substr(start == std::string::npos ? 0 : start + 1, end + 1 - (start == std::string::npos ? 0 : start + 1));
  return nlohmann::json::parse(last, nullptr, false);
}

std::string prog(const char* name) { return std::string("--path config/programs/") + name; }

}  // namespace

TEST(ContourFigures, BinaryExists) {
  ASSERT_TRUE(std::filesystem::exists(sim_binary())) << sim_binary();
}

TEST(ContourFigures, JsonContract) {
  int rc = -1;
  const auto j = run(prog("eq11.yaml") + " --controller ccc --feed-mm-min 4000", &rc);
  ASSERT_TRUE(j.is_object());
  EXPECT_EQ(rc, 0);
  for (const char* k : {"controller", "feed_mm_min", "samples", "max_contour_error_um",
                        "rms_contour_error_um", "max_model_error_blu", "end_position_error_um",
                        "stable"}) {
    EXPECT_TRUE(j.contains(k)) << k;
  }
  EXPECT_EQ(j["controller"], "ccc");
  EXPECT_EQ(j["delay_cycles"], 1);  // table1.yaml: CANopen synchronous PDOs
  EXPECT_TRUE(j["stable"].get<bool>());
}

TEST(ContourFigures, ModelAccuracyEq11UnderP) {
  // Paper: 8e-4 BLU at 1 m/min, 5e-2 BLU at 4 m/min.
  const auto slow = run(prog("eq11.yaml") + " --controller p --feed-mm-min 1000 --delay-cycles 0");
  const auto fast = run(prog("eq11.yaml") + " --controller p --feed-mm-min 4000 --delay-cycles 0");
  EXPECT_LE(slow["max_model_error_blu"].get<double>(), 1e-3);
  EXPECT_LE(fast["max_model_error_blu"].get<double>(), 6e-2);
  // Also with the bus delay (the model then sees the predicted position).
  const auto d1 = run(prog("eq11.yaml") + " --controller p --feed-mm-min 4000");
  EXPECT_LE(d1["max_model_error_blu"].get<double>(), 6e-2);
  // Detuned: the literal one-step window and the linear (Koren-type) model miss the bar by far.
  const auto literal =
      run(prog("eq11.yaml") + " --controller p --feed-mm-min 4000 --delay-cycles 0 --window-rule literal");
  EXPECT_GT(literal["max_model_error_blu"].get<double>(), 100 * 6e-2);
  const auto linear =
      run(prog("eq11.yaml") + " --controller p --feed-mm-min 4000 --delay-cycles 0 --model linear");
  EXPECT_GT(linear["max_model_error_blu"].get<double>(), 100 * 6e-2);
}

TEST(ContourFigures, Eq11CoupledVsUncoupled) {
  const auto j = run(prog("eq11.yaml") + " --compare --feed-mm-min 4000 --delay-cycles 0");
  EXPECT_GE(j["ratio_p_ccc"].get<double>(), 23.0);
  EXPECT_GE(j["ratio_pid_ccc"].get<double>(), 20.0);
  // Detuned: coupling gains / 10 miss the bar.
  const std::string cfg = contour::test::process_temp_dir() + "weak_ccc.yaml";
  {
    FILE* f = std::fopen(cfg.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("control:\n  coupling: {cp: 1.5, ci_per_s: 30, cd_s: 0.03}\n"
               "machine:\n  axes: [{name: X}, {name: Y}, {name: Z}]\n", f);
    std::fclose(f);
  }
  const auto weak =
      run(prog("eq11.yaml") + " --compare --feed-mm-min 4000 --delay-cycles 0 --config " + cfg);
  EXPECT_LT(weak["ratio_p_ccc"].get<double>(), 23.0);
}

TEST(ContourFigures, HelixEllipseCubic) {
  for (const char* name : {"helix.yaml", "ellipse.yaml", "cubic.yaml"}) {
    const auto j = run(prog(name) + " --compare --feed-mm-min 4000 --delay-cycles 0");
    EXPECT_GE(j["ratio_p_ccc"].get<double>(), 10.0) << name;
    EXPECT_GE(j["ratio_pid_ccc"].get<double>(), 10.0) << name;
  }
}

TEST(ContourFigures, Table2GcodeWithoutAccDec) {
  const auto j = run(prog("table2.ngc") + " --compare --feed-mm-min 4000 --delay-cycles 0");
  EXPECT_GE(j["ratio_p_ccc"].get<double>(), 5.0);
  EXPECT_GT(j["samples"].get<long>(), 1000);
}

TEST(ContourFigures, RestPositionOnTheEndPoint) {
  for (const char* name : {"eq11.yaml", "helix.yaml", "ellipse.yaml", "cubic.yaml", "table2.ngc"}) {
    for (const char* delay : {"0", "1"}) {
      const auto j = run(prog(name) + " --controller ccc --delay-cycles " + delay);
      EXPECT_LE(j["end_position_error_um"].get<double>(), 0.5) << name << " delay " << delay;
    }
  }
  // Detuned: the paper's integrator (along-path component kept) stops far from the end point.
  const auto paper = run(prog("eq11.yaml") + " --controller ccc --delay-cycles 0 --no-integrator-fix");
  EXPECT_GT(paper["end_position_error_um"].get<double>(), 50.0);
}

TEST(ContourFigures, OneCycleTransportDelay) {
  const auto j = run(prog("eq11.yaml") + " --compare --feed-mm-min 4000 --delay-cycles 1");
  ASSERT_TRUE(j.contains("runs"));
  for (const auto& r : j["runs"]) EXPECT_TRUE(r["stable"].get<bool>()) << r["controller"];
  EXPECT_GE(j["ratio_p_ccc"].get<double>(), 15.0);
  EXPECT_LT(j["coupled_loop_spectral_radius"].get<double>(), 1.0);
  // Detuned: without the predictor the paper's gains are unstable with one cycle of delay (with
  // the round-1 derivative; the model-blended derivative keeps even that loop stable, issue 16).
  int rc = 0;
  const auto raw = run(prog("eq11.yaml") +
                           " --controller ccc --delay-cycles 1 --no-delay-compensation "
                           "--model-blend-ms 0 --same-geometry never",
                       &rc);
  EXPECT_FALSE(raw["stable"].get<bool>());
  EXPECT_GT(raw["coupled_loop_spectral_radius"].get<double>(), 1.0);
  EXPECT_FALSE(raw["stability_check"]["stable"].get<bool>());
  EXPECT_EQ(rc, 1);
}

TEST(ContourFigures, CsvAndPlot) {
  const std::string dir = contour::test::process_temp_dir();
  const std::string csv = dir + "eq11_ccc.csv";
  const std::string png = dir + "eq11_compare.png";
  std::filesystem::remove(csv);
  std::filesystem::remove(png);
  const auto j = run(prog("eq11.yaml") + " --controller ccc --compare --csv " + csv + " --plot " + png);
  ASSERT_TRUE(j.is_object());
  EXPECT_GT(std::filesystem::file_size(csv), 10000u);
  if (std::system("command -v gnuplot >/dev/null 2>&1") == 0) {
    EXPECT_GT(std::filesystem::file_size(png), 1000u);
  } else {
    GTEST_SKIP() << "gnuplot not installed: the PNG part is not checked";
  }
}

TEST(ContourFigures, BadInputIsAClearError) {
  int rc = 0;
  run("--path /nonexistent.yaml --controller ccc 2>/dev/null", &rc);
  EXPECT_NE(rc, 0);
  run("--path config/programs/eq11.yaml --controller pd 2>/dev/null", &rc);
  EXPECT_EQ(rc, 2);
}

// Issue 16: the velocity command K u no longer carries the encoder counts through the
// derivative. On the parametric seed-000 curves (constant feed, no corners) the round-1 law moved
// each cycle's command by 4-21 mm/s RMS (X/Y/Z), the default filter by <= 1.4; the ratios above
// are unchanged (within 10 %, control/CHATTER.md). Detuned: the filter off gives the old figure.
TEST(ContourFigures, CommandChatterOfTheCoupledController) {
  for (const char* name : {"eq11.yaml", "helix.yaml", "ellipse.yaml", "cubic.yaml"}) {
    const auto j = run(prog(name) + " --controller ccc --feed-mm-min 4000");
    ASSERT_TRUE(j.contains("command_chatter_rms_mm_s")) << name;
    for (const auto& x : j["command_chatter_rms_mm_s"]) EXPECT_LE(x.get<double>(), 2.0) << name;
    const auto off = run(prog(name) + " --controller ccc --feed-mm-min 4000 --model-blend-ms 0");
    double worst = 0.0;
    for (const auto& x : off["command_chatter_rms_mm_s"]) worst = std::max(worst, x.get<double>());
    EXPECT_GT(worst, 10.0) << name;
  }
}

// Issue 16: the stability check in the JSON. A drive whose position arrives one cycle fresher
// than the predictor assumes: with the round-1 derivative the check refuses it (and the run does
// not come to rest); with the default filter both agree that it is stable.
TEST(ContourFigures, StabilityCheckSeesADelayMismatch) {
  int rc = 0;
  const auto raw = run(prog("eq11.yaml") +
                           " --controller ccc --delay-cycles 1 --plant-delay-cycles 0 "
                           "--model-blend-ms 0 --same-geometry never",
                       &rc);
  ASSERT_TRUE(raw.contains("stability_check"));
  EXPECT_FALSE(raw["stability_check"]["stable"].get<bool>());
  EXPECT_NE(raw["stability_check"]["reason"].get<std::string>().find("plant delay 0"),
            std::string::npos);
  EXPECT_FALSE(raw["stable"].get<bool>());
  const auto filtered =
      run(prog("eq11.yaml") + " --controller ccc --delay-cycles 1 --plant-delay-cycles 0", &rc);
  EXPECT_TRUE(filtered["stability_check"]["stable"].get<bool>())
      << filtered["stability_check"]["reason"];
  EXPECT_TRUE(filtered["stable"].get<bool>());
  EXPECT_EQ(rc, 0);
  // Matched delays: stable, as the figures above need.
  const auto matched = run(prog("eq11.yaml") + " --controller ccc");
  EXPECT_TRUE(matched["stability_check"]["stable"].get<bool>());
}

namespace {

// Per-axis RMS of the cycle-to-cycle change of vx/vy/vz_mm_s in a contourd telemetry CSV.
std::array<double, 3> csv_chatter(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "r");
  std::array<double, 3> rms{};
  if (f == nullptr) return rms;
  std::array<char, 4096> buf{};
  std::vector<std::string> head;
  std::array<int, 3> col{-1, -1, -1};
  std::array<double, 3> prev{}, sum{};
  long n = 0;
  bool first = true;
  while (std::fgets(buf.data(), buf.size(), f) != nullptr) {
    std::vector<std::string> c;
    std::string cell;
    for (const char* p = buf.data(); *p != '\0' && *p != '\n'; ++p) {
      if (*p == ',') {
        c.push_back(cell);
        cell.clear();
      } else {
        cell += *p;
      }
    }
    c.push_back(cell);
    if (head.empty()) {
      head = c;
      for (std::size_t i = 0; i < head.size(); ++i) {
        if (head[i] == "vx_mm_s") col[0] = static_cast<int>(i);
        if (head[i] == "vy_mm_s") col[1] = static_cast<int>(i);
        if (head[i] == "vz_mm_s") col[2] = static_cast<int>(i);
      }
      continue;
    }
    std::array<double, 3> v{};
    for (std::size_t a = 0; a < 3; ++a) v[a] = std::stod(c.at(static_cast<std::size_t>(col[a])));
    if (!first) {
      for (std::size_t a = 0; a < 3; ++a) sum[a] += (v[a] - prev[a]) * (v[a] - prev[a]);
      ++n;
    }
    prev = v;
    first = false;
  }
  std::fclose(f);
  for (std::size_t a = 0; a < 3; ++a) rms[a] = n > 0 ? std::sqrt(sum[a] / static_cast<double>(n)) : 0.0;
  return rms;
}

std::string sim_yaml_with(const std::string& derivative) {
  // sim.yaml with its PLC program paths absolute (tests/support), a derivative: line after
  // control.delay_compensation.
  std::istringstream in(contour::test::sim_yaml());
  std::string text, line;
  while (std::getline(in, line)) {
    text += line + "\n";
    if (line.rfind("  delay_compensation:", 0) == 0) text += "  derivative: " + derivative + "\n";
  }
  const std::string path = contour::test::process_temp_dir() + "sim_derivative.yaml";
  std::FILE* o = std::fopen(path.c_str(), "w");
  if (o != nullptr) {
    std::fputs(text.c_str(), o);
    std::fclose(o);
  }
  return path;
}

}  // namespace

// Issue 16 through the daemon's offline path (`contour-sim run`, config/sim.yaml, Table 2): the
// round-1 law moved the velocity command by 14.2 / 13.1 / 20.0 mm/s RMS per cycle (X/Y/Z); the
// default filter by 2.5 / 3.0 / 1.0 (the coupling's reaction at the blended corners), and with
// the interpolator's 5 ms jerk stage (interpolator.fir2_ms) 1.28 / 1.61 / 1.04 (control/CHATTER.md). `contour-sim contour --reference-csv ... --daemon-clamps` replays
// that run's reference through the same control stage and gives the same figure.
TEST(ContourFigures, DaemonTable2CommandChatter) {
  const std::string dir = contour::test::process_temp_dir();
  const std::string csv = dir + "t2_default.csv", csv_off = dir + "t2_off.csv";
  const std::string cmd = "cd " CONTOUR_SOURCE_DIR " && " + sim_binary() +
                          " run --program config/programs/table2.ngc --config ";
  ASSERT_EQ(std::system((cmd + "config/sim.yaml --csv " + csv + " >/dev/null").c_str()), 0);
  ASSERT_EQ(std::system((cmd + sim_yaml_with("{model_blend_ms: 0, same_geometry: never}") +
                         " --csv " + csv_off + " >/dev/null")
                            .c_str()),
            0);
  const auto now = csv_chatter(csv), off = csv_chatter(csv_off);
  for (std::size_t a = 0; a < 3; ++a) {
    EXPECT_LE(now[a], 2.0) << "axis " << a;   // issue 16's goal (fir2_ms 5: 1.28 / 1.61 / 1.04)
    EXPECT_GT(off[a], 10.0) << "axis " << a;  // detuned: the round-1 figure
  }
  EXPECT_LT(now[2], 1.5);
  const auto replay = run(prog("table2.ngc") + " --controller ccc --settle-s 0.05 --daemon-clamps " +
                          "--reference-csv " + csv);
  ASSERT_TRUE(replay.contains("command_chatter_rms_mm_s"));
  for (std::size_t a = 0; a < 3; ++a) {
    EXPECT_NEAR(replay["command_chatter_rms_mm_s"][a].get<double>(), now[a], 0.1 * now[a]) << a;
  }
  // With the clamped command fed back to the controller (the proposed daemon wiring) it is lower.
  const auto told = run(prog("table2.ngc") + " --controller ccc --settle-s 0.05 --command-applied " +
                        "--reference-csv " + csv);
  EXPECT_LT(told["command_chatter_rms_mm_s"][1].get<double>(),
            replay["command_chatter_rms_mm_s"][1].get<double>());
}
