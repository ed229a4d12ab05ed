// The standard function blocks of the soft PLC against IEC 61131-3's timing diagrams and truth
// tables (TON, TOF, TP: the standard's figures sampled every 1 ms scan; R_TRIG, F_TRIG, SR, RS,
// CTU, CTD, CTUD: their defining statements). Each row is (scan time ms, inputs) -> expected
// outputs. The same behaviour through compiled Structured Text is checked at the end.
#include <gtest/gtest.h>

#include <array>
#include <string>
#include <vector>

#include "control/plc_compiler.hpp"
#include "control/plc_vm.hpp"

using namespace contour::control::plc;

namespace {

constexpr std::int64_t kMs = 1000000;

struct Fb {
  explicit Fb(FbKind k) : kind(k) {
    const FbInfo& info = fb_info(k);
    cells.resize(info.size);
    for (int m = 0; m < info.size; ++m) cells[static_cast<std::size_t>(m)].i = info.members[static_cast<std::size_t>(m)].init;
  }
  void call(std::int64_t t_ms) { call_fb(kind, cells.data(), t_ms * kMs); }
  Cell& operator[](int m) { return cells[static_cast<std::size_t>(m)]; }
  FbKind kind;
  std::vector<Cell> cells;
};

struct TimerRow {
  std::int64_t t_ms;
  bool in;
  bool q;
  std::int64_t et_ms;
};

void run_timer(FbKind k, std::int64_t pt_ms, const std::vector<TimerRow>& rows) {
  Fb f(k);
  f[fb::kTimerPt].i = pt_ms * kMs;
  for (const auto& r : rows) {
    f[fb::kTimerIn].i = r.in;
    f.call(r.t_ms);
    EXPECT_EQ(f[fb::kTimerQ].i != 0, r.q) << fb_info(k).name << " Q at t=" << r.t_ms << " ms";
    EXPECT_EQ(f[fb::kTimerEt].i, r.et_ms * kMs) << fb_info(k).name << " ET at t=" << r.t_ms << " ms";
  }
}

// TON: Q rises PT after IN rises and falls with IN; an IN pulse shorter than PT gives no Q;
// ET ramps from 0 to PT while IN is TRUE and is 0 while IN is FALSE.
TEST(PlcFb, TonTimingDiagram) {
  run_timer(FbKind::kTon, 5,
            {{0, false, false, 0}, {1, false, false, 0}, {2, true, false, 0}, {3, true, false, 1},
             {6, true, false, 4}, {7, true, true, 5}, {9, true, true, 5}, {10, false, false, 0},
             {11, true, false, 0}, {13, true, false, 2}, {14, false, false, 0},  // short pulse
             {15, false, false, 0}, {20, true, false, 0}, {25, true, true, 5}, {26, false, false, 0}});
}

// PT 0: Q follows IN at once.
TEST(PlcFb, TonZeroPreset) {
  run_timer(FbKind::kTon, 0, {{0, false, false, 0}, {1, true, true, 0}, {2, false, false, 0}});
}

// TOF: Q rises with IN and falls PT after IN falls; IN rising again within PT keeps Q and
// restarts the delay at the next fall; ET counts from the fall and holds PT after Q fell.
TEST(PlcFb, TofTimingDiagram) {
  run_timer(FbKind::kTof, 5,
            {{0, false, false, 0}, {1, false, false, 0}, {2, true, true, 0}, {3, true, true, 0},
             {4, false, true, 0}, {5, false, true, 1}, {8, false, true, 4}, {9, false, false, 5},
             {12, false, false, 5}, {13, true, true, 0}, {14, false, true, 0},
             {16, false, true, 2}, {17, true, true, 0},  // back within PT: delay restarts
             {18, false, true, 0}, {22, false, true, 4}, {23, false, false, 5}});
}

// TP: a rising IN starts a pulse of exactly PT; IN edges during the pulse are ignored; after the
// pulse ET holds PT while IN is TRUE and returns to 0 with IN FALSE.
TEST(PlcFb, TpTimingDiagram) {
  run_timer(FbKind::kTp, 5,
            {{0, false, false, 0}, {1, true, true, 0}, {2, false, true, 1},  // IN drops: pulse on
             {3, true, true, 2},                                             // retrigger ignored
             {5, true, true, 4}, {6, true, false, 5}, {8, true, false, 5},  // held at PT
             {9, false, false, 0}, {10, true, true, 0}, {11, false, true, 1},
             {15, false, false, 0},  // ended with IN FALSE: ET back to 0 at the end
             {16, true, true, 0}, {21, true, false, 5}, {25, true, false, 5}, {26, false, false, 0}});
}

TEST(PlcFb, RTrigAndFTrig) {
  Fb r(FbKind::kRTrig), f(FbKind::kFTrig);
  const std::array<bool, 8> clk{true, true, false, false, true, false, true, true};
  // R_TRIG's memory starts FALSE: a TRUE input on the first scan is an edge.
  const std::array<bool, 8> rq{true, false, false, false, true, false, true, false};
  const std::array<bool, 8> fq{false, false, true, false, false, true, false, false};
  for (std::size_t k = 0; k < clk.size(); ++k) {
    r[fb::kTrigClk].i = clk[k];
    f[fb::kTrigClk].i = clk[k];
    r.call(0);
    f.call(0);
    EXPECT_EQ(r[fb::kTrigQ].i != 0, rq[k]) << "R_TRIG scan " << k;
    EXPECT_EQ(f[fb::kTrigQ].i != 0, fq[k]) << "F_TRIG scan " << k;
  }
  // F_TRIG's memory starts TRUE: a FALSE input on the first scan is not an edge.
  Fb f2(FbKind::kFTrig);
  f2[fb::kTrigClk].i = 0;
  f2.call(0);
  EXPECT_EQ(f2[fb::kTrigQ].i, 0);
}

TEST(PlcFb, SrSetDominantRsResetDominant) {
  // (set, reset) sequence and Q1 for SR (S1 wins) and RS (R1 wins).
  const std::vector<std::array<bool, 4>> rows{
      // S, R, SR.Q1, RS.Q1
      {false, false, false, false}, {true, false, true, true},   {false, false, true, true},
      {true, true, true, false},    {false, false, true, false}, {false, true, false, false},
      {true, true, true, false},    {false, true, false, false}};
  Fb sr(FbKind::kSr), rs(FbKind::kRs);
  for (std::size_t k = 0; k < rows.size(); ++k) {
    sr[fb::kBiSet].i = rows[k][0];
    sr[fb::kBiReset].i = rows[k][1];
    rs[fb::kBiSet].i = rows[k][0];
    rs[fb::kBiReset].i = rows[k][1];
    sr.call(0);
    rs.call(0);
    EXPECT_EQ(sr[fb::kBiQ1].i != 0, rows[k][2]) << "SR row " << k;
    EXPECT_EQ(rs[fb::kBiQ1].i != 0, rows[k][3]) << "RS row " << k;
  }
}

TEST(PlcFb, CtuCountsRisingEdgesUpToPvAndResets) {
  Fb c(FbKind::kCtu);
  c[fb::kCtuPv].i = 3;
  auto step = [&](bool cu, bool r) {
    c[fb::kCtuCu].i = cu;
    c[fb::kCtuR].i = r;
    c.call(0);
  };
  step(false, false);
  EXPECT_EQ(c[fb::kCtuCv].i, 0);
  step(true, false);   // edge: 1
  step(true, false);   // held: no count
  EXPECT_EQ(c[fb::kCtuCv].i, 1);
  step(false, false);
  step(true, false);   // 2
  EXPECT_EQ(c[fb::kCtuQ].i, 0);
  step(false, false);
  step(true, false);   // 3 = PV
  EXPECT_EQ(c[fb::kCtuCv].i, 3);
  EXPECT_EQ(c[fb::kCtuQ].i, 1);
  step(false, false);
  step(true, false);   // 4: keeps counting past PV
  EXPECT_EQ(c[fb::kCtuCv].i, 4);
  step(true, true);    // R wins
  EXPECT_EQ(c[fb::kCtuCv].i, 0);
  EXPECT_EQ(c[fb::kCtuQ].i, 0);
  // Saturates at INT's maximum.
  c[fb::kCtuCv].i = 32767;
  step(false, false);
  step(true, false);
  EXPECT_EQ(c[fb::kCtuCv].i, 32767);
}

TEST(PlcFb, CtdLoadsPvAndCountsDownToZero) {
  Fb c(FbKind::kCtd);
  c[fb::kCtdPv].i = 2;
  auto step = [&](bool cd, bool ld) {
    c[fb::kCtdCd].i = cd;
    c[fb::kCtdLd].i = ld;
    c.call(0);
  };
  step(false, false);
  EXPECT_EQ(c[fb::kCtdQ].i, 1);  // CV 0 <= 0
  step(false, true);             // load
  EXPECT_EQ(c[fb::kCtdCv].i, 2);
  EXPECT_EQ(c[fb::kCtdQ].i, 0);
  step(true, true);              // LD wins over an edge
  EXPECT_EQ(c[fb::kCtdCv].i, 2);
  step(false, false);
  step(true, false);
  EXPECT_EQ(c[fb::kCtdCv].i, 1);
  step(false, false);
  step(true, false);
  EXPECT_EQ(c[fb::kCtdCv].i, 0);
  EXPECT_EQ(c[fb::kCtdQ].i, 1);
  step(false, false);
  step(true, false);             // goes on below zero
  EXPECT_EQ(c[fb::kCtdCv].i, -1);
  c[fb::kCtdCv].i = -32768;
  step(false, false);
  step(true, false);
  EXPECT_EQ(c[fb::kCtdCv].i, -32768);  // saturates at INT's minimum
}

TEST(PlcFb, CtudBothDirectionsResetAndLoadPriority) {
  Fb c(FbKind::kCtud);
  c[fb::kCtudPv].i = 2;
  auto step = [&](bool cu, bool cd, bool r, bool ld) {
    c[fb::kCtudCu].i = cu;
    c[fb::kCtudCd].i = cd;
    c[fb::kCtudR].i = r;
    c[fb::kCtudLd].i = ld;
    c.call(0);
  };
  step(false, false, false, false);
  EXPECT_EQ(c[fb::kCtudQd].i, 1);
  EXPECT_EQ(c[fb::kCtudQu].i, 0);
  step(true, false, false, false);  // +1
  step(false, false, false, false);
  step(true, false, false, false);  // +1 = 2 = PV
  EXPECT_EQ(c[fb::kCtudCv].i, 2);
  EXPECT_EQ(c[fb::kCtudQu].i, 1);
  step(false, false, false, false);
  step(true, true, false, false);  // both edges in one scan: no change
  EXPECT_EQ(c[fb::kCtudCv].i, 2);
  step(false, false, false, false);
  step(false, true, false, false);  // -1
  EXPECT_EQ(c[fb::kCtudCv].i, 1);
  step(false, false, true, true);  // R wins over LD
  EXPECT_EQ(c[fb::kCtudCv].i, 0);
  step(false, false, false, true);  // load PV
  EXPECT_EQ(c[fb::kCtudCv].i, 2);
}

// The same TON through the compiler and the VM: the timer in a compiled program behaves as
// call_fb does, with ET readable as TIME and the preset given as a T# literal.
TEST(PlcFb, TonThroughStructuredText) {
  SymbolTable syms;
  syms.add({"start", Type::kBool, Access::kRead, 0, "an input"});
  syms.add({"lamp", Type::kBool, Access::kReadWrite, 1, ""});
  syms.add({"elapsed_ms", Type::kDint, Access::kReadWrite, 2, ""});
  const char* src = R"(
PROGRAM t
VAR
  delay : TON;
END_VAR
  delay(IN := start, PT := T#5ms);
  lamp := delay.Q;
  elapsed_ms := TIME_TO_DINT(delay.ET);
END_PROGRAM
)";
  const CompileResult r = compile_program(src, syms, {"t.st", 1000});
  ASSERT_TRUE(r.errors.empty()) << r.errors.front().format();
  std::vector<Cell> mem(3 + static_cast<std::size_t>(r.program->locals));
  for (int k = 0; k < r.program->locals; ++k) mem[3 + static_cast<std::size_t>(k)] = r.program->locals_init[static_cast<std::size_t>(k)];
  const auto code = link(*r.program, 3);
  std::vector<Cell> stack(static_cast<std::size_t>(r.program->max_stack));
  std::vector<bool> lamp;
  for (int t = 0; t < 10; ++t) {
    mem[0].i = t >= 2 ? 1 : 0;
    const RunResult rr = run(code, mem, stack, t * kMs);
    ASSERT_EQ(rr.status, RunStatus::kOk);
    EXPECT_LE(rr.executed, r.program->worst_case);
    lamp.push_back(mem[1].i != 0);
    EXPECT_EQ(mem[2].i, t >= 2 ? std::min(t - 2, 5) : 0) << "t=" << t;
  }
  EXPECT_EQ(lamp, (std::vector<bool>{false, false, false, false, false, false, false, true, true, true}));
}

}  // namespace
