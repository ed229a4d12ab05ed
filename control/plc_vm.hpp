#pragma once
// The soft PLC's virtual machine: executes one linked program (control/plc_compiler.hpp link())
// over the flat PLC memory, once per scan, and the standard function blocks with IEC 61131-3's
// semantics (control/plc_fb.cpp is not separate: they are the kCallFb cases below).
//
// Real-time contract: run() is noexcept, allocates nothing, takes no lock and makes no system
// call; its cost is bounded by the program's compile-time worst case (CompiledProgram::
// worst_case instructions; bench_plc measures ~1-3 ns per instruction). The operand stack is the
// caller's, pre-sized to CompiledProgram::max_stack cells.
//
// Time: `now_ns` is the scan's time stamp (the engine passes cycle * servo period, so timers
// count simulated time in lockstep tests exactly as on the machine). Timers compare differences
// of now_ns, so its origin does not matter.
//
// Runtime errors (integer or REAL division by zero, an array index out of its bounds) end the
// scan at that instruction and are reported with its index (CompiledProgram::lines gives the
// source line); the caller decides what happens (the engine faults the machine).
#include <cstdint>
#include <span>

#include "control/plc_types.hpp"

namespace contour::control::plc {

enum class RunStatus : std::uint8_t { kOk, kDivisionByZero, kIndexOutOfRange };
[[nodiscard]] const char* to_string(RunStatus s) noexcept;

struct RunResult {
  RunStatus status = RunStatus::kOk;
  std::uint32_t pc = 0;         // the failing instruction (status != kOk)
  std::uint64_t executed = 0;   // instructions, FB calls weighted kFbCallCost
  std::int64_t bad_index = 0;   // kIndexOutOfRange: the index
};

// Runs `code` from its first instruction to kRet. mem: the whole PLC memory (image + locals);
// stack: at least max_stack cells.
RunResult run(std::span<const Instr> code, std::span<Cell> mem, std::span<Cell> stack,
              std::int64_t now_ns) noexcept;

// One standard FB step on an instance at `self` (exposed for the FB tests).
void call_fb(FbKind kind, Cell* self, std::int64_t now_ns) noexcept;

}  // namespace contour::control::plc
