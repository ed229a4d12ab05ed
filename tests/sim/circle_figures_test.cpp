// Issue 6 bars (seed 003): kp 30/27 1/s, tau 10/12 ms, 1 kHz loop, config/geometry/example.yaml
// (~20 um), 0.1 um ballbar noise. Each figure is printed so a run documents the numbers.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>

#include "config/circle_test_config.hpp"
#include "config/geometry_config.hpp"
#include "control/circle_test.hpp"

namespace cc = contour::control::circle;
using contour::control::GeometricErrorModel;

namespace {
struct Bench {
  contour::config::CircleTestConfig cfg;
  GeometricErrorModel geometry;
};
Bench load() {
  Bench s{contour::config::load_circle_test_config(CONTOUR_SOURCE_DIR "/config/circle_test.yaml"),
          {}};
  s.geometry = contour::config::load_geometry_file(s.cfg.geometry_file);
  return s;
}
cc::Circle circle(double r, double f, cc::Direction d) {
  cc::Circle c;
  c.radius_mm = r;
  c.feed_mm_min = f;
  c.direction = d;
  return c;
}
cc::SimOptions sim_options(const Bench& s, std::uint64_t seed) {
  cc::SimOptions o;
  o.geometry = &s.geometry;
  o.noise_um = 0.1;
  o.seed = seed;
  return o;
}
// Servo ellipse after matching Y to X with the fit's ratio, on the same circle.
cc::EllipseMetrics servo_after(const Bench& s, const cc::Circle& c, const cc::FitResult& f,
                               std::uint64_t seed) {
  auto axes = s.cfg.axes;
  axes[1].position_gain *= cc::match_y_to_x(f, c.omega_rad_s()).ratio_y;
  const auto run = cc::simulate_circle(axes, c, sim_options(s, seed));
  return cc::ellipse_metrics(run.servo_angle_rad, run.servo_deviation_um);
}
double rel(double est, double truth) { return std::abs(est / truth - 1.0); }
}  // namespace

TEST(CircleFigures, PaperCircleGeometryAwareVersusNaive) {
  const Bench s = load();
  const cc::Circle c = circle(100.0, 3000.0, cc::Direction::kCw);
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const auto run = cc::simulate_circle(s.cfg.axes, c, sim_options(s, seed));
    const auto before = cc::ellipse_metrics(run.servo_angle_rad, run.servo_deviation_um);
    EXPECT_NEAR(before.ellipse_um, 185.0, 5.0);

    cc::BallbarFitOptions o;
    o.kp_ref_x_per_s = s.cfg.axes[0].kp_per_s();
    o.geometry = &s.geometry;
    const auto geo = cc::fit_ballbar(c, run.ballbar, o);
    o.geometry = nullptr;
    const auto naive = cc::fit_ballbar(c, run.ballbar, o);
    const auto after_geo = servo_after(s, c, geo, seed);
    const auto after_naive = servo_after(s, c, naive, seed);
    std::printf("seed %d: kpY geo %.5f naive %.5f (true 27); tauX geo %.3f naive %.3f ms, tauY geo "
                "%.3f naive %.3f ms (loop 10.5/12.5); servo ellipse %.3f -> geo %.3f (45 deg %.3f) "
                "naive %.3f um\n",
                static_cast<int>(seed), geo.dynamics[1].kp_per_s, naive.dynamics[1].kp_per_s,
                geo.dynamics[0].tau_s * 1e3, naive.dynamics[0].tau_s * 1e3,
                geo.dynamics[1].tau_s * 1e3, naive.dynamics[1].tau_s * 1e3, before.ellipse_um,
                after_geo.ellipse_um, after_geo.ellipse_45_um, after_naive.ellipse_um);
    EXPECT_TRUE(geo.converged);
    EXPECT_LT(rel(geo.dynamics[1].kp_per_s, s.cfg.axes[1].kp_per_s()), 0.005);  // bar 0.5 %
    EXPECT_LE(after_geo.ellipse_um, 5.0);                                        // bar 5 um
    EXPECT_LE(after_geo.ellipse_45_um, 1.0);                                     // goal 1 um
    // The naive fit on the same data is far off: compensation leaves > 5 um, tau off > 30 %.
    EXPECT_GT(after_naive.ellipse_um, 5.0);
    EXPECT_GT(rel(naive.dynamics[0].tau_s, s.cfg.axes[0].tau_loop_s()), 0.3);
    EXPECT_GT(rel(naive.dynamics[1].tau_s, s.cfg.axes[1].tau_loop_s()), 0.3);
  }
}

TEST(CircleFigures, EncoderRecordKpAndTau) {
  const Bench s = load();
  for (const auto& c : {circle(100.0, 3000.0, cc::Direction::kCw),
                        circle(10.0, 5000.0, cc::Direction::kCcw)}) {
    const auto run = cc::simulate_circle(s.cfg.axes, c, sim_options(s, 4));
    const auto f = cc::fit_machine_record(c, run.record);
    for (std::size_t a = 0; a < 2; ++a) {
      std::printf("encoder R %.0f: axis %zu kp %.5f tau %.4f ms\n", c.radius_mm, a,
                  f.dynamics[a].kp_per_s, f.dynamics[a].tau_s * 1e3);
      EXPECT_LT(rel(f.dynamics[a].kp_per_s, s.cfg.axes[a].kp_per_s()), 0.005);
      EXPECT_LT(rel(f.dynamics[a].tau_s, s.cfg.axes[a].tau_loop_s()), 0.03);
    }
  }
}

TEST(CircleFigures, TauFromSmallRadiusHighFeed) {
  const Bench s = load();
  const cc::Circle c = circle(10.0, 5000.0, cc::Direction::kCw);
  const auto run = cc::simulate_circle(s.cfg.axes, c, sim_options(s, 5));
  cc::BallbarFitOptions o;
  o.kp_ref_x_per_s = s.cfg.axes[0].kp_per_s();
  o.geometry = &s.geometry;
  const auto f = cc::fit_ballbar(c, run.ballbar, o);
  std::printf("R 10 F 5000: tau %.4f / %.4f ms (loop 10.5 / 12.5), kpY %.5f\n",
              f.dynamics[0].tau_s * 1e3, f.dynamics[1].tau_s * 1e3, f.dynamics[1].kp_per_s);
  for (std::size_t a = 0; a < 2; ++a) {
    EXPECT_LT(rel(f.dynamics[a].tau_s, s.cfg.axes[a].tau_loop_s()), 0.03);  // bar 3 %
  }
  EXPECT_LT(rel(f.dynamics[1].kp_per_s, s.cfg.axes[1].kp_per_s()), 0.005);
  // At the paper's circle tau is barely observable: the same fit is much less accurate there.
}

TEST(CircleFigures, TauAbsorbsTheLoopDelay) {
  Bench s = load();
  for (auto& a : s.cfg.axes) a.drive.delay_cycles = 2;
  const cc::Circle c = circle(10.0, 5000.0, cc::Direction::kCw);
  const auto run = cc::simulate_circle(s.cfg.axes, c, sim_options(s, 6));
  cc::BallbarFitOptions o;
  o.kp_ref_x_per_s = s.cfg.axes[0].kp_per_s();
  o.geometry = &s.geometry;
  const auto f = cc::fit_ballbar(c, run.ballbar, o);
  std::printf("delay 2: tau %.4f / %.4f ms (tau + 2.5 T = 12.5 / 14.5)\n", f.dynamics[0].tau_s * 1e3,
              f.dynamics[1].tau_s * 1e3);
  EXPECT_NEAR(f.dynamics[0].tau_s * 1e3, 12.5, 12.5 * 0.03);
  EXPECT_NEAR(f.dynamics[1].tau_s * 1e3, 14.5, 14.5 * 0.03);
}

TEST(CircleFigures, GeometricModelTenPercentWrong) {
  const Bench s = load();
  for (double scale : {0.9, 1.1}) {
    const GeometricErrorModel wrong = s.geometry.scaled(scale);
    cc::BallbarFitOptions o;
    o.kp_ref_x_per_s = s.cfg.axes[0].kp_per_s();
    o.geometry = &wrong;
    const cc::Circle big = circle(100.0, 3000.0, cc::Direction::kCw);
    const auto f1 = cc::fit_ballbar(big, cc::simulate_circle(s.cfg.axes, big, sim_options(s, 7)).ballbar, o);
    const cc::Circle small = circle(10.0, 5000.0, cc::Direction::kCw);
    const auto f2 =
        cc::fit_ballbar(small, cc::simulate_circle(s.cfg.axes, small, sim_options(s, 8)).ballbar, o);
    std::printf("model x%.1f: kpY %.5f (R100); tau %.4f / %.4f ms (R10), %.4f / %.4f ms (R100)\n",
                scale, f1.dynamics[1].kp_per_s, f2.dynamics[0].tau_s * 1e3,
                f2.dynamics[1].tau_s * 1e3, f1.dynamics[0].tau_s * 1e3, f1.dynamics[1].tau_s * 1e3);
    EXPECT_LT(rel(f1.dynamics[1].kp_per_s, s.cfg.axes[1].kp_per_s()), 0.01);  // bar 1 %
    for (std::size_t a = 0; a < 2; ++a) {
      EXPECT_LT(rel(f2.dynamics[a].tau_s, s.cfg.axes[a].tau_loop_s()), 0.10);  // bar 10 %
    }
    EXPECT_LE(servo_after(s, big, f1, 7).ellipse_um, 5.0);
  }
}

TEST(CircleFigures, GeometricModelRandomlyTenPercentWrong) {
  const Bench s = load();
  for (unsigned seed : {11u, 12u, 13u}) {
    // Every coefficient and squareness off by an independent factor in [0.9, 1.1].
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0.9, 1.1);
    contour::control::GeometricErrorParams p = s.geometry.params();
    for (auto& axis : p.axes) {
      for (auto& poly : axis.translation_mm) {
        for (double& c : poly.c) c *= u(rng);
      }
      for (auto& poly : axis.rotation_rad) {
        for (double& c : poly.c) c *= u(rng);
      }
    }
    p.squareness_xy_rad *= u(rng);
    const GeometricErrorModel wrong(p);
    cc::BallbarFitOptions o;
    o.kp_ref_x_per_s = s.cfg.axes[0].kp_per_s();
    o.geometry = &wrong;
    const cc::Circle big = circle(100.0, 3000.0, cc::Direction::kCw);
    const auto f1 =
        cc::fit_ballbar(big, cc::simulate_circle(s.cfg.axes, big, sim_options(s, seed)).ballbar, o);
    const cc::Circle small = circle(10.0, 5000.0, cc::Direction::kCw);
    const auto f2 = cc::fit_ballbar(
        small, cc::simulate_circle(s.cfg.axes, small, sim_options(s, seed + 100)).ballbar, o);
    std::printf("random model seed %u: kpY %.5f (R100); tau %.4f / %.4f ms (R10)\n", seed,
                f1.dynamics[1].kp_per_s, f2.dynamics[0].tau_s * 1e3, f2.dynamics[1].tau_s * 1e3);
    EXPECT_LT(rel(f1.dynamics[1].kp_per_s, s.cfg.axes[1].kp_per_s()), 0.01);
    for (std::size_t a = 0; a < 2; ++a) {
      EXPECT_LT(rel(f2.dynamics[a].tau_s, s.cfg.axes[a].tau_loop_s()), 0.10);
    }
  }
}

TEST(CircleFigures, ReversalWithoutGeometricModel) {
  const Bench s = load();
  const cc::Circle cw = circle(100.0, 3000.0, cc::Direction::kCw);
  const cc::Circle ccw = circle(100.0, 3000.0, cc::Direction::kCcw);
  const auto run_cw = cc::simulate_circle(s.cfg.axes, cw, sim_options(s, 9));
  const auto run_ccw = cc::simulate_circle(s.cfg.axes, ccw, sim_options(s, 10));
  cc::ReversalFitOptions o;
  o.kp_ref_x_per_s = s.cfg.axes[0].kp_per_s();
  // tau is not observable by reversal; assume both axes lag like X's configuration.
  o.tau_assumed_s = {s.cfg.axes[0].tau_loop_s(), s.cfg.axes[0].tau_loop_s()};
  const auto f = cc::fit_reversal(cw, run_cw.ballbar, ccw, run_ccw.ballbar, o);
  const auto after_cw = servo_after(s, cw, f, 9);
  const auto after_ccw = servo_after(s, ccw, f, 10);
  std::printf("reversal: kpY %.5f, servo ellipse after CW %.3f (45 deg %.3f), CCW %.3f um\n",
              f.dynamics[1].kp_per_s, after_cw.ellipse_um, after_cw.ellipse_45_um,
              after_ccw.ellipse_um);
  EXPECT_FALSE(f.tau_estimated);
  EXPECT_LE(after_cw.ellipse_um, 2.0);  // bar 2 um
  EXPECT_LE(after_ccw.ellipse_um, 2.0);
  // Without reversal the same geometry-free data fitted naively misses the bar.
  cc::BallbarFitOptions n;
  n.kp_ref_x_per_s = o.kp_ref_x_per_s;
  EXPECT_GT(servo_after(s, cw, cc::fit_ballbar(cw, run_cw.ballbar, n), 9).ellipse_um, 2.0);
}

// The tool front end: last stdout line is the JSON contract of the issue.
TEST(CircleFigures, ContourSimCircleJson) {
  const std::string bin = CONTOUR_BINARY_DIR "/tools/contour-sim";
  if (std::FILE* f = std::fopen(bin.c_str(), "r")) {
    std::fclose(f);
  } else {
    GTEST_SKIP() << bin << " not built: the CLI contract is not checked in this run";
  }
  const std::string cmd = bin + " circle --config " CONTOUR_SOURCE_DIR
                                "/config/circle_test.yaml --direction both 2>&1";
  std::FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out, last;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p) != nullptr) out += buf;
  ASSERT_EQ(pclose(p), 0) << out;
  const auto pos = out.find_last_of('\n', out.size() - 2);
  last = out.substr(pos == std::string::npos ? 0 : pos + 1);
  const auto j = nlohmann::json::parse(last);
  std::set<std::string> seen;
  for (const auto& m : j.at("methods")) {
    seen.insert(m.at("method").get<std::string>());
    for (const char* axis : {"X", "Y"}) {
      for (const char* k : {"kp_true", "kp_est", "tau_true_ms", "tau_est_ms"}) {
        EXPECT_TRUE(m.at(axis).contains(k)) << axis << "." << k;
      }
    }
    for (const char* k : {"kp_y_new", "ellipse_servo_um_before", "ellipse_servo_um_after",
                          "ellipse_total_um_before", "ellipse_total_um_after"}) {
      EXPECT_TRUE(m.contains(k)) << k;
    }
    EXPECT_NEAR(m.at("ellipse_servo_um_before").get<double>(), 185.0, 5.0);
  }
  EXPECT_EQ(seen, (std::set<std::string>{"encoder", "geometry", "naive", "reversal"}));
}
