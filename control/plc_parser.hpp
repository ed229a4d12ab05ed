#pragma once
// Parser of the Structured Text subset (IEC 61131-3 ST). The whole grammar — tokens and syntax —
// is written out at the top of control/plc_parser.cpp, one parse function per rule.
// Compile-time only (allocates, may be slow); never called from the real-time cycle.
#include <string>
#include <string_view>
#include <vector>

#include "control/plc_ast.hpp"
#include "control/plc_types.hpp"

namespace contour::control::plc {

// Parses one source file holding one PROGRAM. Syntax errors are appended to `errors` (each with
// file:line:column); the parser recovers at the next statement, so one call reports them all.
// The returned tree holds what could be parsed (only meaningful when no error was added).
ProgramAst parse_program(std::string_view source, const std::string& file,
                         std::vector<Diagnostic>& errors);

}  // namespace contour::control::plc
