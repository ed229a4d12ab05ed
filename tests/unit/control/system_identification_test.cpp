// Feed-drive identification (issue 16, `contourctl identify`): on the simulated drives
// (control/feed_drive.hpp, Table 1, BLU 0.5 um, delay 0/1/2 cycles) K and tau within 2 % and the
// delay exact, also with +-1 BLU of encoder noise; bad records are refused with a reason.
#include "control/system_identification.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "control/feed_drive.hpp"

namespace contour::control {
namespace {

struct Plant {
  double gain_per_s, tau_s;
  int delay;
};

// The experiment as the daemon runs it: the target written in cycle k is what the drive gets
// (u = v / K_cmd); the position read in cycle k is the quantised encoder (+ noise counts).
IdentificationInput record(const Plant& pl, double k_cmd, const std::vector<double>& v,
                           int noise_counts, unsigned seed, double start_mm = 12.3456789) {
  FeedDriveParams p;
  p.gain_per_s = pl.gain_per_s;
  p.tau_s = pl.tau_s;
  p.period_s = 0.001;
  p.blu_mm = 0.0005;
  p.delay_cycles = pl.delay;
  FeedDrive d(p);
  d.reset(start_mm);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> noise(-noise_counts, noise_counts);
  IdentificationInput in;
  in.period_s = 0.001;
  in.command_gain_per_s = k_cmd;
  for (double vk : v) {
    in.position_mm.push_back(d.measured_mm() + (noise_counts > 0 ? noise(rng) * p.blu_mm : 0.0));
    in.v_cmd_mm_s.push_back(vk);
    d.step(vk / k_cmd);
  }
  return in;
}

TEST(SystemIdentification, ExcitationIsSmallBoundedAndReturnsToTheStart) {
  const ExcitationParams ep;
  const std::vector<double> v = make_excitation(ep);
  double sum = 0.0, vmax = 0.0;
  for (double x : v) {
    sum += x * ep.period_s;
    vmax = std::max(vmax, std::abs(x));
  }
  EXPECT_NEAR(sum, 0.0, 1e-12);             // net displacement zero
  EXPECT_EQ(vmax, ep.amplitude_mm_s);
  EXPECT_NEAR(excitation_excursion_mm(v, ep.period_s), 0.5, 1e-9);  // A * long pulse
  EXPECT_LE(static_cast<double>(v.size()) * ep.period_s, 1.5);
  EXPECT_EQ(v.front(), 0.0);
  EXPECT_EQ(v.back(), 0.0);
}

TEST(SystemIdentification, RecoversTable1DrivesAtEveryDelay) {
  const std::vector<double> v = make_excitation(ExcitationParams{});
  for (const Plant& pl : {Plant{120.0, 0.030, 0}, Plant{120.0, 0.030, 1}, Plant{120.0, 0.030, 2},
                          Plant{115.0, 0.025, 0}, Plant{115.0, 0.025, 1}, Plant{115.0, 0.025, 2}}) {
    const IdentificationResult r = identify_axis(record(pl, pl.gain_per_s, v, 0, 1));
    ASSERT_TRUE(r.ok) << r.message;
    EXPECT_NEAR(r.gain_per_s / pl.gain_per_s, 1.0, 0.02) << pl.gain_per_s << " d" << pl.delay;
    EXPECT_NEAR(r.tau_s / pl.tau_s, 1.0, 0.02) << pl.tau_s << " d" << pl.delay;
    EXPECT_EQ(r.delay_cycles, pl.delay);
    EXPECT_NEAR(r.velocity_gain, 1.0, 0.02);
    EXPECT_GT(r.delay_confidence, 2.0);
  }
}

TEST(SystemIdentification, RobustToOneCountOfEncoderNoise) {
  const std::vector<double> v = make_excitation(ExcitationParams{});
  for (unsigned seed = 1; seed <= 4; ++seed) {
    for (const Plant& pl : {Plant{120.0, 0.030, 1}, Plant{115.0, 0.025, 0},
                            Plant{120.0, 0.030, 2}}) {
      const IdentificationResult r = identify_axis(record(pl, pl.gain_per_s, v, 1, seed));
      ASSERT_TRUE(r.ok) << r.message;
      EXPECT_NEAR(r.gain_per_s / pl.gain_per_s, 1.0, 0.02) << "seed " << seed;
      EXPECT_NEAR(r.tau_s / pl.tau_s, 1.0, 0.02) << "seed " << seed;
      EXPECT_EQ(r.delay_cycles, pl.delay) << "seed " << seed;
    }
  }
}

TEST(SystemIdentification, GainIsTheDrivesNotTheConfigured) {
  // The loop scales with K_cmd = 100 1/s, the drive has 120: K = 120, velocity gain 1.2.
  const std::vector<double> v = make_excitation(ExcitationParams{});
  const IdentificationResult r = identify_axis(record({120.0, 0.030, 1}, 100.0, v, 0, 1));
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.gain_per_s, 120.0, 2.4);
  EXPECT_NEAR(r.velocity_gain, 1.2, 0.024);
}

TEST(SystemIdentification, AMisalignedRecordShiftsTheDelay) {
  // The estimator is sensitive to the sample alignment: dropping the first position sample (the
  // positions then run one cycle early) must read one cycle less of delay.
  const std::vector<double> v = make_excitation(ExcitationParams{});
  IdentificationInput in = record({120.0, 0.030, 2}, 120.0, v, 0, 1);
  in.position_mm.erase(in.position_mm.begin());
  in.v_cmd_mm_s.pop_back();
  const IdentificationResult r = identify_axis(in);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.delay_cycles, 1);
}

TEST(SystemIdentification, BadRecordsAreRefusedWithAReason) {
  IdentificationInput in;
  in.v_cmd_mm_s.assign(200, 0.0);
  in.position_mm.assign(200, 1.0);
  IdentificationResult r = identify_axis(in);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("no excitation"), std::string::npos) << r.message;
  in.position_mm.pop_back();
  r = identify_axis(in);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("length"), std::string::npos) << r.message;
  in.v_cmd_mm_s.assign(10, 1.0);
  in.position_mm.assign(10, 1.0);
  EXPECT_FALSE(identify_axis(in).ok);
  // An axis that does not move (drive not enabled): no consistent positive gain.
  in.v_cmd_mm_s = make_excitation(ExcitationParams{});
  in.position_mm.assign(in.v_cmd_mm_s.size(), 3.0);
  r = identify_axis(in);
  EXPECT_FALSE(r.ok) << r.message;
  EXPECT_THROW(make_excitation(ExcitationParams{0.001, -1.0}), std::invalid_argument);
}

}  // namespace
}  // namespace contour::control
