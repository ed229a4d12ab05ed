// G-code interpreter (issues 18, 19), one test per feature and per error class: full circles,
// expressions, parameters, O-words, subroutine files, canned cycles, cutter compensation, offsets,
// machine context read-back, .var/.tbl text formats, MDI, run-from-line, preview, user M-codes,
// messages, refusals, lexical limits. Expected values are LinuxCNC 2.9's (RS274/NGC) semantics;
// the program-level comparison with LinuxCNC itself is tests/conformance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "control/gcode.hpp"
#include "control/gcode_machine.hpp"

using namespace contour::control;
using Eigen::Vector3d;

namespace {
ProgramSetup base() {
  ProgramSetup s;
  s.tools = {{1, 10.0}, {2, 25.5}};
  s.rapid_mm_min = 6000;
  return s;
}

std::vector<Block> run(const std::string& text, ProgramSetup st = base(), GcodeParser* keep = nullptr) {
  GcodeParser p(std::move(st), "t.ngc");
  std::vector<Block> out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) p.parse_line(line, out);
  p.finish(out);
  if (keep) *keep = std::move(p);
  return out;
}

std::vector<Block> motions(const std::vector<Block>& v) {
  std::vector<Block> m;
  for (const auto& b : v)
    if (b.kind == BlockKind::kMotion) m.push_back(b);
  return m;
}

std::vector<Block> feeds(const std::vector<Block>& v) {
  std::vector<Block> m;
  for (const auto& b : v)
    if (b.kind == BlockKind::kMotion && !b.rapid) m.push_back(b);
  return m;
}

// The GcodeError of a program ("" when it runs), and its line.
struct Failure {
  std::string what;
  int line = 0;
};
Failure failure(const std::string& text, ProgramSetup st = base()) {
  try {
    run(text, std::move(st));
  } catch (const GcodeError& e) {
    return {e.what(), e.line()};
  }
  return {};
}
}  // namespace

TEST(GcodeInterp, FullCircleIsOneArcOfOneTurnAndPAddsTurns) {
  const auto m = motions(run("G1 X0 Y0 F100\nG2 I.5 J.5\nG3 I1 Z-3 P3\nM2"));
  ASSERT_EQ(m.size(), 3u);
  const PathSegment& c = m[1].seg;
  EXPECT_EQ(c.kind, PathSegment::Kind::kArc);
  EXPECT_EQ(c.start, c.end);
  EXPECT_EQ(c.turns, 0);
  EXPECT_NEAR(c.center.x(), 0.5, 1e-12);
  EXPECT_NEAR(c.center.y(), 0.5, 1e-12);
  EXPECT_NEAR(arc_sweep_rad(c), 2 * std::numbers::pi, 1e-12);
  const PathSegment& h = m[2].seg;  // helix, three turns
  EXPECT_TRUE(h.ccw);
  EXPECT_EQ(h.turns, 2);
  EXPECT_NEAR(h.end.z(), -3, 1e-12);
  EXPECT_NEAR(arc_sweep_rad(h), 6 * std::numbers::pi, 1e-9);
}

TEST(GcodeInterp, ExpressionsPrecedenceAndFunctions) {
  const auto m = motions(run(
      "G1 F100 X[2+3*4**2] Y[ATAN[1]/[1]] Z[7 MOD 3]\n"
      "G1 X[1 EQ 1 AND 0] Y[FIX[-1.5]] Z[FUP[-1.5]]\n"
      "G1 X[ROUND[2.5]] Y[SQRT[16]+ABS[-1]] Z[-2**2]\n"
      "#<d>=3\n#<_g>=[#<d>*2]\nG1 X#<_g> Y[EXISTS[#<d>]] Z[EXISTS[#<nope>]]\nM2"));
  ASSERT_EQ(m.size(), 4u);
  EXPECT_NEAR(m[0].seg.end.x(), 50, 1e-12);  // ** binds tighter than *, * tighter than +
  EXPECT_NEAR(m[0].seg.end.y(), 45, 1e-12);  // ATAN[y]/[x] in degrees
  EXPECT_NEAR(m[0].seg.end.z(), 1, 1e-12);
  EXPECT_NEAR(m[1].seg.end.x(), 0, 1e-12);   // EQ before AND
  EXPECT_NEAR(m[1].seg.end.y(), -2, 1e-12);  // FIX rounds down, FUP up
  EXPECT_NEAR(m[1].seg.end.z(), -1, 1e-12);
  EXPECT_NEAR(m[2].seg.end.x(), 3, 1e-12);
  EXPECT_NEAR(m[2].seg.end.y(), 5, 1e-12);
  EXPECT_NEAR(m[2].seg.end.z(), 4, 1e-12);   // unary minus binds tighter than **: (-2)**2
  EXPECT_NEAR(m[3].seg.end.x(), 6, 1e-12);
  EXPECT_NEAR(m[3].seg.end.y(), 1, 1e-12);
  EXPECT_NEAR(m[3].seg.end.z(), 0, 1e-12);
}

TEST(GcodeInterp, ParametersOnALineAreReadBeforeAnyIsSet) {
  const auto m = motions(run("#1=1\n#1=2 G1 X#1 F100\nG1 X#1\nM2"));
  ASSERT_EQ(m.size(), 2u);
  EXPECT_NEAR(m[0].seg.end.x(), 1, 1e-12);
  EXPECT_NEAR(m[1].seg.end.x(), 2, 1e-12);
}

TEST(GcodeInterp, OWordLoopsConditionalsAndSubroutines) {
  const auto m = motions(run(
      "o<sq> sub\no<sq> return [#1*#1]\no<sq> endsub\n"
      "#1=0\no1 while [#1 LT 3]\nG1 X#1 F100\n#1=[#1+1]\no1 endwhile\n"
      "o2 repeat [2]\nG1 Y1\no2 endrepeat\n"
      "o3 if [#1 EQ 2]\nG1 Z1\no3 elseif [#1 EQ 3]\nG1 Z2\no3 else\nG1 Z3\no3 endif\n"
      "o4 do\n#1=[#1+1]\no6 if [#1 GT 5]\no4 break\no6 endif\nG1 Y#1\no4 while [1]\n"
      "#2=0\no7 while [#2 LT 3]\n#2=[#2+1]\no8 if [#2 EQ 2]\no7 continue\no8 endif\nG1 Z[10+#2]\no7 endwhile\n"
      "o<sq> call [3]\nG1 X#<_value>\nM2"));
  std::vector<double> got;
  for (const auto& b : m) got.push_back(b.seg.end.x() * 100 + b.seg.end.y() * 10 + b.seg.end.z());
  // X0 X1 X2; Y1 twice; Z2 (elseif); do-while: Y4, Y5 (6 breaks); while: Z11, Z13 (2 continues);
  // X9 from the sub's return value.
  const std::vector<double> want{0, 100, 200, 210, 210, 212, 242, 252, 261, 263, 963};
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) EXPECT_NEAR(got[i], want[i], 1e-9) << i;
}

TEST(GcodeInterp, SubroutineFilesComeThroughTheCallback) {
  ProgramSetup st = base();
  std::vector<std::string> asked;
  st.load_subroutine = [&](const std::string& name) -> std::optional<std::string> {
    asked.push_back(name);
    if (name == "ext") return std::string("o<ext> sub\nG1 X#1 F100\no<ext> endsub\n");
    return std::nullopt;
  };
  const auto m = motions(run("o<EXT> call [7]\no<ext> call [8]\nM2", st));
  ASSERT_EQ(m.size(), 2u);
  EXPECT_NEAR(m[0].seg.end.x(), 7, 1e-12);
  EXPECT_NEAR(m[1].seg.end.x(), 8, 1e-12);
  ASSERT_FALSE(asked.empty());
  EXPECT_EQ(asked[0], "ext");  // names are lower case, as LinuxCNC reads them
  // Not in the program nor in a file: LinuxCNC searches the rest of the program for it and fails
  // at its end, naming the call.
  const Failure f = failure("G0 X1\no<missing> call\nM2", st);
  EXPECT_EQ(f.line, 3);
  EXPECT_NE(f.what.find("o<missing> (called at line 2)"), std::string::npos) << f.what;
  // Without a callback there are no subroutine files.
  EXPECT_NE(failure("o<ext> call [1]\nM2").what.find("o<ext>"), std::string::npos);
}

TEST(GcodeInterp, CannedDrillCycleRetractsToRPlaneOrOldZ) {
  const std::string prog = "G17 G0 X0 Y0 Z10\n{} G81 X5 Y5 Z-2 R2 F100\nX10\nG80\nM2";
  for (const bool g99 : {true, false}) {
    std::string p = prog;
    p.replace(p.find("{}"), 2, g99 ? "G99" : "G98");
    const auto v = run(p);
    const auto f = feeds(v);
    ASSERT_EQ(f.size(), 2u);
    EXPECT_EQ(f[0].seg.end, Vector3d(5, 5, -2));
    EXPECT_EQ(f[1].seg.end, Vector3d(10, 5, -2));
    EXPECT_EQ(f[0].seg.start.z(), 2);  // feed starts at the R plane
    EXPECT_EQ(f[0].line, 2);
    EXPECT_EQ(f[1].line, 3);           // modal cycle repeats on the next XY
    const auto m = motions(v);
    EXPECT_TRUE(m.back().rapid);       // retract after the last hole
    EXPECT_NEAR(m.back().seg.end.z(), g99 ? 2.0 : 10.0, 1e-12) << (g99 ? "G99" : "G98");
  }
}

TEST(GcodeInterp, PeckAndDwellCyclesEmitDwellsAndPecks) {
  const auto v = run("G0 X0 Y0 Z5\nG82 X1 Z-1 R1 P0.5 F60\nG80\nG83 X2 Z-3 R1 Q1 F60\nG80\nM2");
  int dwells = 0;
  for (const auto& b : v)
    if (b.kind == BlockKind::kDwell) {
      ++dwells;
      EXPECT_DOUBLE_EQ(b.dwell_s, 0.5);
      EXPECT_EQ(b.line, 2);
    }
  EXPECT_EQ(dwells, 1);
  int g83_feeds = 0;
  for (const auto& b : feeds(v)) g83_feeds += b.line == 4;
  EXPECT_EQ(g83_feeds, 4);  // pecks to Z0, Z-1, Z-2, Z-3 (the last one shorter than Q is Z-3)
  // Error cases, each on the cycle's line.
  EXPECT_EQ(failure("G0 Z5\nG83 X1 Z-1 R1 F10\nM2").line, 2);        // G83 without Q
  EXPECT_EQ(failure("G0 Z5\nG81 X1 Z-1 F10\nM2").line, 2);           // no R
  EXPECT_EQ(failure("G0 Z5\nG81 X1 Z2 R1 F10\nM2").line, 2);         // R below the bottom
}

TEST(GcodeInterp, CutterCompensationOffsetsThePathAndRefusesGouges) {
  // G41.1 D2: tool radius 1 left of the path; a square traversed counter-clockwise from outside.
  const auto m = feeds(run("G0 X-5 Y-5\nG41.1 D2\nG1 X0 Y0 F100\nX10\nY10\nG40 G1 X15 Y15\nM2"));
  ASSERT_GE(m.size(), 3u);
  bool seen_offset_edge = false;
  for (const auto& b : m)
    if (std::abs(b.seg.start.y() - 1) < 1e-9 && std::abs(b.seg.end.y() - 1) < 1e-9) seen_offset_edge = true;
  EXPECT_TRUE(seen_offset_edge) << "the X0->X10 edge runs at Y1 (left of the path by the radius)";
  // Tool radius 2 inside an arc of radius 1.
  const Failure f = failure("G0 X0 Y0\nG41.1 D4\nG1 X10 Y0 F100\nG3 X10 Y2 J1\nG40 X20\nM2");
  EXPECT_FALSE(f.what.empty());
  EXPECT_GE(f.line, 4);
  // Compensation in G19 is refused (LinuxCNC: XY or XZ only).
  EXPECT_EQ(failure("G19\nG41.1 D1 G1 Y1 Z1 F100\nM2").line, 2);
}

TEST(GcodeInterp, WorkOffsetsG10G92AndTheMachineContextReadBack) {
  GcodeParser p(base(), "t.ngc");
  const auto m = motions(run("G10 L2 P1 X5\nG0 X0\nG92 X0\nG0 X1\nG92.1\nG0 X1\nG10 L20 P2 Y0\nG55 G0 Y3\nM2",
                             base(), &p));
  ASSERT_EQ(m.size(), 4u);
  EXPECT_NEAR(m[0].seg.end.x(), 5, 1e-12);   // G54 X = 5
  EXPECT_NEAR(m[1].seg.end.x(), 6, 1e-12);   // G92 made the current point X0
  EXPECT_NEAR(m[2].seg.end.x(), 6, 1e-12);   // G92.1 cleared it: X1 in G54 = 6
  EXPECT_NEAR(m[3].seg.end.y(), 3, 1e-12);   // G10 L20 P2 Y0 at machine Y0: G55 Y = 0
  EXPECT_EQ(m[3].coord_system, 2);
  EXPECT_TRUE(p.machine_changed());
  const MachineContext mc = p.machine();
  EXPECT_NEAR(mc.work_offset_mm(1).x(), 5, 1e-12);
  EXPECT_NEAR(mc.parameters[kParamG54], 5, 1e-12);  // #5221 = G54 X
  EXPECT_NEAR(mc.work_offset_mm(2).y(), 0, 1e-12);
  // Nothing changed: nothing to persist.
  GcodeParser q(base(), "t.ngc");
  run("G0 X1\nM2", base(), &q);
  EXPECT_FALSE(q.machine_changed());
}

TEST(GcodeInterp, ReferencePositionsAreStoredByG28_1) {
  GcodeParser p(base(), "t.ngc");
  const auto m = motions(run("G0 X3 Y4 Z5\nG28.1\nG0 X0 Y0 Z0\nG28\nM2", base(), &p));
  ASSERT_GE(m.size(), 2u);
  EXPECT_EQ(m.back().seg.end, Vector3d(3, 4, 5));
  EXPECT_EQ(p.machine().g28_mm(), Vector3d(3, 4, 5));
  EXPECT_NEAR(p.machine().parameters[kParamG28 + 2], 5, 1e-12);  // #5163
  EXPECT_TRUE(p.machine_changed());
}

TEST(GcodeInterp, ToolChangeUserMCodesAndMessages) {
  GcodeParser p(base(), "t.ngc");
  const auto v = run("T2 M6\nG43 G0 Z0\nM101 P2 Q3\n(MSG,hello)\n#1=4\n(DEBUG,val #1)\nM2", base(), &p);
  const Block* tc = nullptr;
  const Block* um = nullptr;
  for (const auto& b : v) {
    if (b.kind == BlockKind::kToolChange) tc = &b;
    if (b.user_m) um = &b;
  }
  ASSERT_NE(tc, nullptr);
  EXPECT_EQ(tc->tool, 2);
  EXPECT_EQ(tc->line, 1);
  EXPECT_NEAR(motions(v).at(0).seg.end.z(), 25.5, 1e-12);  // G43: T2's length
  ASSERT_NE(um, nullptr);
  EXPECT_EQ(um->kind, BlockKind::kDwell);
  EXPECT_EQ(um->user_m, 101);
  EXPECT_DOUBLE_EQ(um->user_p, 2);
  EXPECT_DOUBLE_EQ(um->user_q, 3);
  const auto msgs = p.take_messages();
  ASSERT_EQ(msgs.size(), 2u);
  EXPECT_EQ(msgs[0].kind, Message::Kind::kMsg);
  EXPECT_EQ(msgs[0].text, "hello");
  EXPECT_EQ(msgs[0].line, 4);
  EXPECT_EQ(msgs[1].kind, Message::Kind::kDebug);
  EXPECT_NE(msgs[1].text.find("val 4"), std::string::npos) << msgs[1].text;
  EXPECT_EQ(p.machine().tool_in_spindle, 2);
  // A tool that is not in the table.
  EXPECT_EQ(failure("G0 X0\nT13 M6\nM2").line, 2);
}

TEST(GcodeInterp, DeliberateRefusalsNameFileLineColumnAndWord) {
  struct Case {
    const char* program;
    const char* where;
    const char* word;
  };
  const Case cases[] = {
      {"G1 X1 F1\nG33 Z-1 K1\nM2", "t.ngc:2:1:", "G33"},
      {"G1 X1 F1\nX2 G76 P1 Z-1\nM2", "t.ngc:2:4:", "G76"},
      {"G0 X0\nG5.1 X1 I1 J1\nM2", "t.ngc:2:1:", "G5.1"},
      {"G93 G1 X1 F1\nM2", "t.ngc:1:1:", "G93"},
      {"G0 X0\nG38.2 Z-5 F10\nM2", "t.ngc:2:1:", "G38.2"},
      {"G0 X0 A5\nM2", "t.ngc:1:7:", "axis A"},
      {"M62 P1\nM2", "t.ngc:1:1:", "M62"},
  };
  for (const auto& c : cases) {
    const Failure f = failure(c.program);
    EXPECT_EQ(f.what.rfind(c.where, 0), 0u) << c.program << " -> " << f.what;
    EXPECT_NE(f.what.find(c.word), std::string::npos) << c.program << " -> " << f.what;
  }
}

TEST(GcodeInterp, LexicalLimitsBlockDeleteAndRunawayLoops) {
  const std::string ok_line = "G1 X1 F100 (" + std::string(252 - 13, 'a') + ")";
  ASSERT_EQ(ok_line.size(), 252u);
  EXPECT_EQ(failure(ok_line + "\nM2").what, "");
  const Failure longf = failure("G0 X0\n" + ok_line + "a\nM2");
  EXPECT_EQ(longf.line, 2);
  EXPECT_NE(longf.what.find("line too long"), std::string::npos) << longf.what;
  ProgramSetup del = base();
  del.block_delete = true;
  EXPECT_EQ(motions(run("G0 X1\n/G0 X5\nM2", del)).size(), 1u);
  EXPECT_EQ(motions(run("G0 X1\n/G0 X5\nM2")).size(), 2u);  // switch off: executed
  EXPECT_EQ(failure("G0 X1\nN10 G0 X1 N20\nM2").line, 2);  // N not first
  ProgramSetup bounded = base();
  bounded.max_executed_lines = 1000;
  const Failure loop = failure("o1 while [1]\nG0 X1\no1 endwhile\nM2", bounded);
  EXPECT_FALSE(loop.what.empty());
  ProgramSetup strict = base();
  strict.require_program_end = true;
  EXPECT_FALSE(failure("G0 X1\n", strict).what.empty());
  EXPECT_EQ(failure("G0 X1\n").what, "");
}

TEST(GcodeInterp, MdiKeepsModalStateAndFollowsTheMachinePosition) {
  GcodeParser p(base(), "mdi");
  std::vector<Block> out;
  p.mdi("G91 G1 F100", out);  // G1 without axis words: a zero-length feed, as LinuxCNC
  out.clear();
  p.set_position_mm(Vector3d(10, 0, 0));
  p.mdi("X1", out);  // G91 and G1 continue; starts from the machine's position
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].seg.start, Vector3d(10, 0, 0));
  EXPECT_EQ(out[0].seg.end, Vector3d(11, 0, 0));
  EXPECT_FALSE(out[0].rapid);
  EXPECT_DOUBLE_EQ(out[0].feed_mm_min, 100);
  EXPECT_FALSE(p.modal_state().absolute);
  EXPECT_THROW(p.mdi("G1 X1 X2", out), GcodeError);
  out.clear();
  p.mdi("X-1", out);  // still usable after an error
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].seg.end, Vector3d(10, 0, 0));
}

TEST(GcodeInterp, RunFromLineEmitsNothingBeforeItAndReportsTheState) {
  ProgramSetup st = base();
  st.run_from_line = 5;
  GcodeParser p(base(), "t.ngc");
  const auto v = run("G21 G90 G54\nT2 M6\nM3 S1000\nG0 X5 Y5 F300\nG1 X10\nG1 Y10\nM2", st, &p);
  for (const auto& b : v) {
    if (b.kind != BlockKind::kEnd) {
      EXPECT_GE(b.line, 5) << static_cast<int>(b.kind);
    }
  }
  ASSERT_TRUE(p.resume_state().has_value());
  const ModalState& s = *p.resume_state();
  EXPECT_EQ(s.line, 5);
  EXPECT_EQ(s.tool, 2);
  EXPECT_EQ(s.spindle, SpindleDir::kCw);
  EXPECT_DOUBLE_EQ(s.spindle_rpm, 1000);
  EXPECT_DOUBLE_EQ(s.feed_mm_min, 300);
  EXPECT_NEAR(s.position_mm.x(), 5, 1e-12);
  EXPECT_NEAR(s.position_mm.y(), 5, 1e-12);
  EXPECT_EQ(feeds(v).size(), 2u);
}

TEST(GcodeInterp, PreviewExtentsInMachineAndWorkCoordinatesAndTools) {
  ProgramSetup st = base();
  st.work_offsets_mm[0] = Vector3d(100, 0, 0);
  ProgramPreview pv;
  for (const auto& b : run("G0 X0 Y0\nG1 X10 F100\nG2 X0 I-5\nT1 M6\nM2", st)) pv.add(b);
  EXPECT_NEAR(pv.work.min_mm.y(), -5, 1e-9);  // the arc's lowest point, not only its end points
  EXPECT_NEAR(pv.work.max_mm.x(), 10, 1e-9);
  EXPECT_NEAR(pv.machine.max_mm.x(), 110, 1e-9);
  EXPECT_EQ(pv.tools.count(1), 1u);
  EXPECT_NEAR(pv.feed_length_mm, 10 + 5 * std::numbers::pi, 1e-9);
}

TEST(GcodeInterp, VarAndToolTableTextRoundTripAndErrorsNameTheLine) {
  const std::string tbl = "T1 P1 Z10.5 D6 ;end mill\nT2 P2 X0.1 Z25.5 D3.175 I1 J2 Q0 ;ball\n";
  const auto tools = parse_tool_table(tbl, "m.tbl");
  ASSERT_EQ(tools.size(), 2u);
  EXPECT_EQ(tools[0].number, 1);
  EXPECT_DOUBLE_EQ(tools[0].length_mm(), 10.5);
  EXPECT_DOUBLE_EQ(tools[1].diameter_mm, 3.175);
  EXPECT_EQ(tools[1].comment, "ball");
  const auto again = parse_tool_table(format_tool_table(tools), "m.tbl");
  ASSERT_EQ(again.size(), 2u);
  EXPECT_EQ(again[1].offset, tools[1].offset);
  EXPECT_DOUBLE_EQ(again[1].front_angle_deg, 1);
  EXPECT_EQ(again[1].comment, "ball");
  try {
    (void)parse_tool_table("T1 Z1\nT2 K5\n", "m.tbl");
    ADD_FAILURE() << "unknown letter accepted";
  } catch (const MachineFileError& e) {
    EXPECT_EQ(e.line(), 2);
    EXPECT_EQ(std::string(e.what()).rfind("m.tbl:2", 0), 0u) << e.what();
  }
  EXPECT_THROW((void)parse_tool_table("T1 Z1\nT1 Z2\n", "m.tbl"), MachineFileError);  // T twice

  const auto vars = parse_var_file("5161\t1.5\n5221 -2\n\n5222 3\n", "m.var");
  MachineContext mc;
  apply_var_file(mc, vars);
  EXPECT_EQ(mc.g28_mm(), Vector3d(1.5, 0, 0));
  EXPECT_EQ(mc.work_offset_mm(1), Vector3d(-2, 3, 0));
  MachineContext back;
  apply_var_file(back, parse_var_file(format_var_file(mc), "m.var"));
  EXPECT_EQ(back.work_offset_mm(1), mc.work_offset_mm(1));
  EXPECT_EQ(back.g28_mm(), mc.g28_mm());
  try {
    (void)parse_var_file("5221 1\n5161 2\n", "m.var");
    ADD_FAILURE() << "out-of-order .var accepted";
  } catch (const MachineFileError& e) {
    EXPECT_EQ(e.line(), 2);
  }
  EXPECT_THROW((void)parse_var_file("5161 abc\n", "m.var"), MachineFileError);
}

TEST(GcodeInterp, MachineContextDrivesOffsetsAndTools) {
  MachineContext mc;
  mc.set_work_offset_mm(2, Vector3d(0, 40, 0));
  mc.tools = parse_tool_table("T7 P1 Z12 D4\n", "m.tbl");
  mc.tool_in_spindle = 7;
  ProgramSetup st;
  st.machine = mc;
  const auto m = motions(run("G55 G43 G0 X0 Y0 Z0\nM2", st));
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].seg.end, Vector3d(0, 40, 12));
  EXPECT_EQ(m[0].coord_system, 2);
  EXPECT_NEAR(m[0].tool_offset_mm.z(), 12, 1e-12);
}

// Issue 19: a 1,000,000-line program without loops or subroutines streams in bounded memory (the
// interpreter keeps no program lines); one with a loop keeps only the loop's lines.
TEST(GcodeInterp, MillionLineProgramStreamsWithoutKeepingLines) {
  GcodeParser p(base(), "long.ngc");
  std::vector<Block> out;
  std::size_t blocks = 0;
  std::size_t most_retained = 0;
  std::string line;
  for (int i = 0; i < 1000000; ++i) {
    line = "N" + std::to_string(i) + " G1 X" + std::to_string(i % 100) + " Y" + std::to_string(i % 7) + " F1000";
    p.parse_line(line, out);
    blocks += out.size();
    out.clear();
    if (i % 1000 == 0) most_retained = std::max(most_retained, p.retained_lines());
  }
  p.parse_line("M2", out);
  EXPECT_GE(blocks, 990000u);
  EXPECT_EQ(most_retained, 0u);
  GcodeParser q(base(), "loop.ngc");
  out.clear();
  q.parse_line("#1=0", out);
  q.parse_line("o1 while [#1 LT 3]", out);
  q.parse_line("G1 X#1 F100", out);
  q.parse_line("#1=[#1+1]", out);
  const std::size_t inside = q.retained_lines();  // the jump back can reach these
  q.parse_line("o1 endwhile", out);
  EXPECT_EQ(motions(out).size(), 3u);
  EXPECT_GT(inside, 0u);
  EXPECT_LE(inside, 4u);
  EXPECT_EQ(q.retained_lines(), 0u);  // released once the loop is done
}
