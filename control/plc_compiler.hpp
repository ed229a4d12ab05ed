#pragma once
// Structured Text compiler of the soft PLC (issue 20): parses one program (control/plc_parser),
// resolves its names against the program's own variables and the outside symbols (the I/O
// image's signals, NC.* status and requests), type-checks it with IEC 61131-3's rules, and
// emits flat, allocation-free stack code (control/plc_types.hpp Instr) for control/plc_vm.
//
// Load errors, each "file:line:column: message", all of one file at once: syntax errors, unknown
// variable or signal (with the nearest known name), type mismatch, assignment to an input (or
// to an NC status, an NC-owned output, a constant, an FB's output), non-constant FOR bounds, and
// a worst case above the instruction budget. The cross-program rule (an output written by two
// programs) is checked by the caller from CompiledProgram::writes.
//
// Worst case: the compiler bounds the instructions one scan can execute (no WHILE/REPEAT, FOR
// with constant bounds; an IF counts its costliest branch, a FOR its iterations times its body;
// each FB call counts kFbCallCost) and refuses a program above the budget. The VM counts what it
// really executes; tests check that the count never exceeds the bound.
//
// Compile-time only (allocates); the result is immutable and shared.
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "control/plc_ast.hpp"
#include "control/plc_types.hpp"

namespace contour::control::plc {

// A name a program can use without declaring it.
struct ExternalSymbol {
  std::string name;  // as declared: "door_closed", "NC.feed_hold"
  Type type = Type::kBool;
  Access access = Access::kRead;
  std::int32_t slot = 0;  // absolute slot in the PLC memory
  // For kRead symbols: what the symbol is, for "assignment to ..." errors ("an input (gpio DOOR)",
  // "NC status", "owned by the NC: the PLC can only request a stop").
  std::string what;
};

class SymbolTable {
 public:
  // Throws std::invalid_argument on a duplicate name (names are case-insensitive).
  void add(ExternalSymbol s);
  [[nodiscard]] const ExternalSymbol* find(std::string_view name) const;  // any case
  [[nodiscard]] const std::vector<ExternalSymbol>& all() const noexcept { return list_; }

 private:
  std::vector<ExternalSymbol> list_;
  std::unordered_map<std::string, std::size_t> by_upper_;
};

struct CompileOptions {
  std::string file = "<string>";  // for messages
  std::uint64_t instruction_budget = 20000;
};

// An outside symbol the program assigns (first place it does, for the two-writers message).
struct SignalWrite {
  std::int32_t slot = 0;
  Pos pos;
};

// A variable of the program (for `plc status` / debugging): locals and FB instances.
struct LocalInfo {
  std::string name;
  Type type = Type::kVoid;  // element type; kVoid for an FB instance
  bool fb = false;
  FbKind fb_kind = FbKind::kTon;
  std::int32_t slot = 0;   // relative to the program's locals
  std::int32_t count = 1;  // cells (array length, FB size)
};

struct CompiledProgram {
  std::string name;  // PROGRAM name
  std::string file;
  std::vector<Instr> code;        // local slots carry kLocalFlag until linked
  std::vector<std::int32_t> lines;  // source line of each instruction (runtime errors)
  std::int32_t locals = 0;        // cells of program memory
  std::vector<Cell> locals_init;  // initial values (size == locals)
  std::int32_t max_stack = 0;     // operand stack cells needed
  std::uint64_t worst_case = 0;   // instructions (FB calls weighted kFbCallCost)
  std::vector<SignalWrite> writes;
  std::vector<LocalInfo> variables;
};

struct CompileResult {
  std::shared_ptr<const CompiledProgram> program;  // null when errors is not empty
  std::vector<Diagnostic> errors;
};

CompileResult compile_program(std::string_view source, const SymbolTable& externals,
                              const CompileOptions& opt);

// The program's code with its local slots placed at `locals_base` in the PLC memory.
std::vector<Instr> link(const CompiledProgram& p, std::int32_t locals_base);

}  // namespace contour::control::plc
