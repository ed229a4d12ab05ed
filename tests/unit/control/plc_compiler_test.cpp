// Structured Text compiler and VM: every load-error class with file:line:column (all of a file at
// once), the statements and operators of the subset with IEC 61131-3 semantics (INT wrap-around,
// REAL precision, implicit widening only, conversions, CASE ranges, FOR with EXIT), runtime
// errors, and the compile-time worst case: never below what a scan really executes, and a
// program above the budget refused.
#include <gtest/gtest.h>

#include <functional>
#include <random>
#include <string>
#include <vector>

#include "control/plc_compiler.hpp"
#include "control/plc_vm.hpp"

using namespace contour::control::plc;

namespace {

// A tiny PLC: a few outside symbols, one program, its memory.
struct Rig {
  Rig() {
    add("door_closed", Type::kBool, Access::kRead, "an input (gpio DOOR)");
    add("air_ok", Type::kBool, Access::kRead, "an input");
    add("lamp", Type::kBool, Access::kReadWrite);
    add("count", Type::kInt, Access::kReadWrite);
    add("big", Type::kDint, Access::kReadWrite);
    add("speed", Type::kReal, Access::kReadWrite);
    add("pos", Type::kLreal, Access::kRead, "NC status");
    add("t_out", Type::kTime, Access::kReadWrite);
    add("NC.feed_hold", Type::kBool, Access::kReadWrite);
    add("NC.program_running", Type::kBool, Access::kRead, "NC status");
    add("drive_enable", Type::kBool, Access::kRead,
        "owned by the NC (the PLC can request a stop, never enable a drive)");
  }
  std::int32_t add(const std::string& n, Type t, Access a, const std::string& what = "") {
    syms.add({n, t, a, next, what});
    return next++;
  }
  CompileResult compile(const std::string& body, const std::string& vars = "",
                        std::uint64_t budget = 100000) {
    const std::string src = "PROGRAM p\n" + vars + body + "\nEND_PROGRAM\n";
    return compile_program(src, syms, {"p.st", budget});
  }
  // Compiles (must succeed) and prepares memory.
  void load(const std::string& body, const std::string& vars = "") {
    CompileResult r = compile(body, vars);
    ASSERT_TRUE(r.errors.empty()) << r.errors.front().format();
    prog = r.program;
    mem.assign(static_cast<std::size_t>(next + prog->locals), int_cell(0));
    for (int k = 0; k < prog->locals; ++k)
      mem[static_cast<std::size_t>(next + k)] = prog->locals_init[static_cast<std::size_t>(k)];
    code = link(*prog, next);
    stack.assign(static_cast<std::size_t>(prog->max_stack), int_cell(0));
  }
  RunResult scan(std::int64_t now_ns = 0) {
    const RunResult r = run(code, mem, stack, now_ns);
    EXPECT_LE(r.executed, prog->worst_case) << "executed more than the compile-time bound";
    return r;
  }
  Cell& sig(const std::string& n) { return mem[static_cast<std::size_t>(syms.find(n)->slot)]; }
  Cell& local(const std::string& n) {
    for (const auto& v : prog->variables)
      if (upper(v.name) == upper(n)) return mem[static_cast<std::size_t>(next + v.slot)];
    throw std::runtime_error("no local " + n);
  }

  SymbolTable syms;
  std::int32_t next = 0;
  std::shared_ptr<const CompiledProgram> prog;
  std::vector<Cell> mem, stack;
  std::vector<Instr> code;
};

std::string all(const std::vector<Diagnostic>& d) {
  std::string s;
  for (const auto& e : d) s += e.format() + "\n";
  return s;
}

// ---- load errors ------------------------------------------------------------------------------

TEST(PlcCompiler, UnknownSignalWithPositionAndSuggestion) {
  Rig r;
  const auto res = r.compile("  lamp := door_close;");
  ASSERT_EQ(res.errors.size(), 1u) << all(res.errors);
  EXPECT_EQ(res.errors[0].format(),
            "p.st:2:11: unknown variable or signal 'door_close' (did you mean 'door_closed'?)");
  EXPECT_EQ(res.program, nullptr);
}

TEST(PlcCompiler, UnknownNcSignal) {
  Rig r;
  const auto res = r.compile("  NC.feed_hlod := TRUE;");
  ASSERT_EQ(res.errors.size(), 1u) << all(res.errors);
  EXPECT_NE(res.errors[0].message.find("unknown NC signal 'NC.feed_hlod'"), std::string::npos);
  EXPECT_NE(res.errors[0].message.find("NC.feed_hold"), std::string::npos);
}

TEST(PlcCompiler, TypeMismatch) {
  Rig r;
  auto res = r.compile("  count := speed;");
  ASSERT_EQ(res.errors.size(), 1u) << all(res.errors);
  EXPECT_EQ(res.errors[0].format(),
            "p.st:2:12: type mismatch: REAL where INT is expected (convert with REAL_TO_INT)");
  res = r.compile("  lamp := count;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("type mismatch: INT where BOOL"), std::string::npos);
  res = r.compile("  lamp := count AND air_ok;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("AND takes BOOL operands"), std::string::npos);
  res = r.compile("  count := big;");  // DINT -> INT narrows: explicit only
  ASSERT_EQ(res.errors.size(), 1u);
  res = r.compile("  t_out := 5;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("T#5s"), std::string::npos);
  res = r.compile("  count := 40000;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("40000 does not fit INT"), std::string::npos);
}

TEST(PlcCompiler, AssignmentToAnInput) {
  Rig r;
  auto res = r.compile("  door_closed := TRUE;");
  ASSERT_EQ(res.errors.size(), 1u) << all(res.errors);
  EXPECT_EQ(res.errors[0].format(),
            "p.st:2:3: assignment to an input: 'door_closed' is an input (gpio DOOR)");
  res = r.compile("  NC.program_running := FALSE;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("assignment to an input"), std::string::npos);
  // The NC-owned outputs are read-only: the PLC cannot enable a drive.
  res = r.compile("  drive_enable := TRUE;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("never enable a drive"), std::string::npos);
  // ... not through an FB output either.
  res = r.compile("  t(IN := TRUE, Q => drive_enable);", "VAR t : TON; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u) << all(res.errors);
  EXPECT_NE(res.errors[0].message.find("assignment to an input"), std::string::npos);
  res = r.compile("  N := 3;", "VAR CONSTANT N : INT := 2; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("'N' is a constant"), std::string::npos);
  res = r.compile("  t.Q := TRUE;", "VAR t : TON; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("belongs to the function block"), std::string::npos);
}

TEST(PlcCompiler, SyntaxErrors) {
  Rig r;
  auto res = r.compile("  lamp := (air_ok AND;\n  count := 1;");
  ASSERT_EQ(res.errors.size(), 1u) << all(res.errors);
  EXPECT_EQ(res.errors[0].format(), "p.st:2:22: an expression expected, found ';'");
  res = r.compile("  WHILE TRUE DO lamp := TRUE; END_WHILE;");
  ASSERT_GE(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("WHILE is not supported"), std::string::npos);
  EXPECT_EQ(res.errors[0].line, 2);
  EXPECT_EQ(res.errors[0].column, 3);
  res = r.compile("  lamp = TRUE;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("assignment is ':='"), std::string::npos);
  res = r.compile("  IF air_ok THEN lamp := TRUE;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("END_IF expected"), std::string::npos);
  res = compile_program("PROGRAM a\nEND_PROGRAM\nPROGRAM b\nEND_PROGRAM\n", r.syms, {"two.st", 100});
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_EQ(res.errors[0].format(), "two.st:3:1: one PROGRAM per file (list each file in plc.programs)");
  res = compile_program("lamp := TRUE;", r.syms, {"x.st", 100});
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_EQ(res.errors[0].format(), "x.st:1:1: PROGRAM expected, found 'lamp'");
  res = r.compile("  (* never closed\n  lamp := TRUE;");
  ASSERT_GE(res.errors.size(), 1u);
  EXPECT_NE(all(res.errors).find("comment not closed"), std::string::npos);
}

// Every error of a file in one go: syntax, unknown name, type, input assignment, bad FOR.
TEST(PlcCompiler, AllErrorsAtOnce) {
  Rig r;
  const std::string vars = "VAR i : INT; n : INT; END_VAR\n";
  const auto res = r.compile(
      "  lamp := ;\n"                    // line 3: syntax
      "  lamp := undefined_thing;\n"      // line 4: unknown
      "  count := speed;\n"               // line 5: type
      "  air_ok := FALSE;\n"              // line 6: input
      "  FOR i := 1 TO n DO lamp := TRUE; END_FOR;\n",  // line 7: non-constant bound
      vars);
  ASSERT_EQ(res.errors.size(), 5u) << all(res.errors);
  EXPECT_EQ(res.errors[0].line, 3);
  EXPECT_EQ(res.errors[1].line, 4);
  EXPECT_EQ(res.errors[2].line, 5);
  EXPECT_EQ(res.errors[3].line, 6);
  EXPECT_EQ(res.errors[4].line, 7);
  EXPECT_NE(res.errors[4].message.find("must be a constant integer"), std::string::npos);
}

TEST(PlcCompiler, DeclarationErrors) {
  Rig r;
  auto res = r.compile("", "VAR x : INTEGER; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("unknown type 'INTEGER'"), std::string::npos);
  res = r.compile("", "VAR lamp : BOOL; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("already a signal"), std::string::npos);
  res = r.compile("", "VAR_EXTERNAL speed : INT; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("declared INT but the signal is REAL"), std::string::npos);
  res = r.compile("", "VAR a : INT; a : BOOL; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("declared twice"), std::string::npos);
  res = r.compile("", "VAR RETAIN a : INT; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("RETAIN is not supported"), std::string::npos);
}

TEST(PlcCompiler, BudgetRefusesAProgramWhoseWorstCaseExceedsIt) {
  Rig r;
  const std::string vars = "VAR i : INT; END_VAR\n";
  const std::string loop = "  FOR i := 1 TO 1000 DO count := count + 1; END_FOR;";
  auto res = r.compile(loop, vars, 5000);
  ASSERT_EQ(res.errors.size(), 1u) << all(res.errors);
  EXPECT_NE(res.errors[0].message.find("exceeds the budget of 5000"), std::string::npos);
  EXPECT_EQ(res.errors[0].line, 1);  // the PROGRAM line
  res = r.compile(loop, vars, 20000);
  ASSERT_TRUE(res.errors.empty()) << all(res.errors);
  // The bound is tight enough to be useful: within 10 % of what the loop executes.
  r.load(loop, vars);
  const RunResult rr = r.scan();
  EXPECT_EQ(r.sig("count").i, 1000);
  EXPECT_GE(rr.executed, res.program->worst_case * 9 / 10);
}

// ---- semantics --------------------------------------------------------------------------------

TEST(PlcVm, IfElsifElse) {
  Rig r;
  r.load(
      "  IF count > 10 THEN big := 3;\n"
      "  ELSIF count > 5 THEN big := 2;\n"
      "  ELSIF count > 0 THEN big := 1;\n"
      "  ELSE big := 0; END_IF;\n");
  for (const auto& [c, want] : std::vector<std::pair<int, int>>{{20, 3}, {7, 2}, {1, 1}, {0, 0}, {-5, 0}}) {
    r.sig("count").i = c;
    r.scan();
    EXPECT_EQ(r.sig("big").i, want) << c;
  }
}

TEST(PlcVm, CaseWithListsRangesAndElse) {
  Rig r;
  r.load(
      "  CASE count OF\n"
      "    1, 3: big := 13;\n"
      "    4..6: big := 46;\n"
      "    N: big := 99;\n"
      "  ELSE big := -1;\n"
      "  END_CASE;\n",
      "VAR CONSTANT N : INT := 10; END_VAR\n");
  for (const auto& [c, want] :
       std::vector<std::pair<int, int>>{{1, 13}, {3, 13}, {2, -1}, {4, 46}, {6, 46}, {10, 99}, {7, -1}}) {
    r.sig("count").i = c;
    r.scan();
    EXPECT_EQ(r.sig("big").i, want) << c;
  }
  const auto res = r.compile("  CASE count OF 1..5: ; 3: ; END_CASE;");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("overlaps"), std::string::npos);
}

TEST(PlcVm, ForWithStepExitAndArrays) {
  Rig r;
  r.load(
      "  big := 0;\n"
      "  FOR i := 8 TO 1 BY -1 DO\n"
      "    table[i] := i * 10;\n"
      "  END_FOR;\n"
      "  FOR i := 1 TO 8 DO\n"
      "    IF table[i] > 40 THEN EXIT; END_IF;\n"
      "    big := big + table[i];\n"
      "  END_FOR;\n",
      "VAR i : INT; table : ARRAY[1..8] OF INT := [1, 2]; END_VAR\n");
  r.scan();
  EXPECT_EQ(r.sig("big").i, 10 + 20 + 30 + 40);
  EXPECT_EQ(r.local("i").i, 5);  // where EXIT left
  // The FOR variable cannot be assigned inside its loop.
  const auto res = r.compile("  FOR i := 1 TO 2 DO i := 5; END_FOR;", "VAR i : INT; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("may not be assigned"), std::string::npos);
  // A loop whose increment would wrap its variable never ends: refused.
  const auto res2 = r.compile("  FOR i := 1 TO 32767 DO ; END_FOR;", "VAR i : INT; END_VAR\n");
  ASSERT_EQ(res2.errors.size(), 1u);
  EXPECT_NE(res2.errors[0].message.find("overflows INT"), std::string::npos);
}

TEST(PlcVm, IntegerWrapAndRealPrecision) {
  Rig r;
  r.load(
      "  count := count + 1;\n"
      "  big := big * 2;\n"
      "  speed := speed + REAL#0.1;\n");
  r.sig("count").i = 32767;
  r.sig("big").i = 2000000000;
  r.sig("speed").r = 0.0;
  r.scan();
  EXPECT_EQ(r.sig("count").i, -32768);            // INT wraps at 16 bits
  EXPECT_EQ(r.sig("big").i, -294967296);          // DINT at 32
  EXPECT_EQ(r.sig("speed").r, static_cast<double>(0.1f));  // REAL is 32-bit
}

TEST(PlcVm, PrecedenceWideningAndConversions) {
  Rig r;
  r.load(
      "  lamp := NOT air_ok AND door_closed OR count = 3;\n"  // ((NOT a) AND d) OR (c = 3)
      "  big := count * 2 + 1;\n"                            // INT result widened to DINT
      "  speed := INT_TO_REAL(count) / 4.0;\n"
      "  count := REAL_TO_INT(2.5);\n"                       // ties to even: 2
      "  x := TRUNC(-2.7);\n"
      "  t_out := T#1m30s + T#250ms;\n"
      "  ms := TIME_TO_DINT(t_out);\n"
      "  y := LIMIT(0, 15, 10) + MAX(1, 2, 7) + MIN(4, 3) + ABS(-2);\n"
      "  z := SEL(door_closed, 1.5, 2.5) + 2.0 ** 3.0;\n",
      "VAR x : DINT; ms : DINT; y : INT; z : LREAL; END_VAR\n");
  r.sig("air_ok").i = 0;
  r.sig("door_closed").i = 1;
  r.sig("count").i = 5;
  r.scan();
  EXPECT_EQ(r.sig("lamp").i, 1);
  EXPECT_EQ(r.sig("big").i, 11);
  EXPECT_DOUBLE_EQ(r.sig("speed").r, 1.25);
  EXPECT_EQ(r.sig("count").i, 2);
  EXPECT_EQ(r.local("x").i, -2);
  EXPECT_EQ(r.sig("t_out").i, 90250000000LL);
  EXPECT_EQ(r.local("ms").i, 90250);
  EXPECT_EQ(r.local("y").i, 10 + 7 + 3 + 2);
  EXPECT_DOUBLE_EQ(r.local("z").r, 2.5 + 8.0);
}

TEST(PlcVm, FbInputsKeepTheirValuesAndOutputsCanBeAssignedInTheCall) {
  Rig r;
  r.load(
      "  IF NOT init THEN edge(CLK := air_ok); init := TRUE; END_IF;\n"
      "  edge(Q => lamp);\n",  // CLK not given: keeps the value of the last call
      "VAR edge : R_TRIG; init : BOOL; END_VAR\n");
  r.sig("air_ok").i = 1;
  r.scan();
  EXPECT_EQ(r.sig("lamp").i, 0);  // first call saw the edge, the second (same CLK) does not
  const auto res = r.compile("  t(IN := TRUE, PTT := T#1s);", "VAR t : TON; END_VAR\n");
  ASSERT_EQ(res.errors.size(), 1u);
  EXPECT_NE(res.errors[0].message.find("TON has no parameter 'PTT'"), std::string::npos);
}

TEST(PlcVm, RuntimeErrorsStopTheScanWithTheLine) {
  Rig r;
  r.load("  lamp := TRUE;\n  big := 10 / count;\n  lamp := FALSE;\n");
  r.sig("count").i = 0;
  RunResult rr = r.scan();
  EXPECT_EQ(rr.status, RunStatus::kDivisionByZero);
  EXPECT_EQ(r.prog->lines[rr.pc], 3);
  EXPECT_EQ(r.sig("lamp").i, 1);  // the statements before it ran, the ones after did not
  r.load("  big := a[count];\n", "VAR a : ARRAY[0..3] OF DINT; END_VAR\n");
  r.sig("count").i = 4;
  rr = r.scan();
  EXPECT_EQ(rr.status, RunStatus::kIndexOutOfRange);
  EXPECT_EQ(rr.bad_index, 4);
  r.sig("count").i = 3;
  EXPECT_EQ(r.scan().status, RunStatus::kOk);
}

TEST(PlcVm, CaseInsensitiveNamesAndComments) {
  Rig r;
  r.load(
      "  // line comment\n"
      "  (* block *) LAMP := Door_Closed; /* C style */\n"
      "  nc.FEED_HOLD := not DOOR_CLOSED;\n");
  r.sig("door_closed").i = 0;
  r.scan();
  EXPECT_EQ(r.sig("lamp").i, 0);
  EXPECT_EQ(r.sig("NC.feed_hold").i, 1);
}

// The written-signals list is what the engine checks for two writers.
TEST(PlcCompiler, ReportsTheSignalsItWrites) {
  Rig r;
  const auto res = r.compile("  lamp := TRUE;\n  IF air_ok THEN lamp := FALSE; NC.feed_hold := TRUE; END_IF;");
  ASSERT_TRUE(res.errors.empty());
  ASSERT_EQ(res.program->writes.size(), 2u);
  EXPECT_EQ(res.program->writes[0].slot, r.syms.find("lamp")->slot);
  EXPECT_EQ(res.program->writes[0].pos.line, 2);
  EXPECT_EQ(res.program->writes[1].slot, r.syms.find("NC.feed_hold")->slot);
}

// Seeded random nests of IF/CASE/FOR: the scan never executes more than the bound.
TEST(PlcVm, RandomProgramsStayWithinTheirBound) {
  std::mt19937 rng(20);
  for (int trial = 0; trial < 40; ++trial) {
    std::string body;
    std::function<void(int)> gen = [&](int depth) {
      const int n = 1 + static_cast<int>(rng() % 4);
      for (int k = 0; k < n; ++k) {
        const unsigned pick = depth > 2 ? 0 : rng() % 4;
        if (pick == 0) {
          body += "count := count + " + std::to_string(rng() % 5) + ";\n";
        } else if (pick == 1) {
          body += "IF count MOD 3 = " + std::to_string(rng() % 3) + " THEN\n";
          gen(depth + 1);
          body += "ELSE\n";
          gen(depth + 1);
          body += "END_IF;\n";
        } else if (pick == 2) {
          body += "CASE count MOD 4 OF 0: \n";
          gen(depth + 1);
          body += "1..2: big := big + 1;\nELSE\n";
          gen(depth + 1);
          body += "END_CASE;\n";
        } else {
          const std::string v = "i" + std::to_string(depth);
          body += "FOR " + v + " := 1 TO " + std::to_string(1 + rng() % 4) + " DO\n";
          gen(depth + 1);
          body += "IF count > 100 THEN EXIT; END_IF;\nEND_FOR;\n";
        }
      }
    };
    gen(0);
    Rig r;
    r.load(body, "VAR i0, i1, i2, i3 : INT; END_VAR\n");
    for (int s = 0; s < 5; ++s) {
      r.sig("count").i = static_cast<std::int64_t>(rng() % 200);
      const RunResult rr = r.scan();
      ASSERT_EQ(rr.status, RunStatus::kOk) << body;
    }
  }
}

}  // namespace
