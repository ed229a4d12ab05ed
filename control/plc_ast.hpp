#pragma once
// Syntax tree of one Structured Text program (control/plc_parser.cpp builds it, the grammar is
// there; control/plc_compiler.cpp type-checks it and emits the flat code). Names are kept as
// written (messages quote them); comparisons use the upper-case form (IEC identifiers are
// case-insensitive). Compile-time only: allocates freely.
#include <memory>
#include <string>
#include <vector>

#include "control/plc_types.hpp"

namespace contour::control::plc {

struct Pos {
  int line = 0;
  int column = 0;
};

enum class ExprKind : std::uint8_t { kLiteral, kName, kUnary, kBinary, kCall };

struct Expr {
  ExprKind kind = ExprKind::kLiteral;
  Pos pos;
  // kLiteral: value and type; `untyped` for a plain number (5, 2.5) that takes its type from
  // the context (INT, DINT, REAL or LREAL as needed).
  Cell value{};
  Type type = Type::kVoid;
  bool untyped = false;
  // kName: name [ '[' index ']' ] [ '.' member ]; kCall: the function's name.
  std::string name;
  std::unique_ptr<Expr> index;
  std::string member;
  Pos member_pos;
  // kUnary / kBinary: the operator in upper case ("-", "NOT", "+", "AND", "<=", "MOD", "**").
  std::string op;
  std::vector<std::unique_ptr<Expr>> args;  // unary: 1, binary: 2, call: the arguments
};
using ExprPtr = std::unique_ptr<Expr>;

enum class StmtKind : std::uint8_t { kAssign, kFbCall, kIf, kCase, kFor, kExit, kReturn, kEmpty };

struct Stmt;
using StmtList = std::vector<Stmt>;

struct FbParam {
  std::string name;
  Pos pos;
  bool output = false;  // `Q => target` (else `IN := value`)
  ExprPtr value;        // input: the value; output: the target (a kName)
};

struct CaseLabel {
  ExprPtr lo;
  ExprPtr hi;  // null: a single value
};

struct CaseArm {
  Pos pos;
  std::vector<CaseLabel> labels;
  StmtList body;
};

struct Stmt {
  StmtKind kind = StmtKind::kEmpty;
  Pos pos;
  ExprPtr target;  // kAssign: the variable; kFor: the control variable (a kName)
  ExprPtr value;   // kAssign: the value; kCase: the selector; kFor: the start
  ExprPtr to;      // kFor
  ExprPtr by;      // kFor (may be null: BY 1)
  std::string instance;  // kFbCall
  std::vector<FbParam> params;
  std::vector<ExprPtr> conds;   // kIf: IF and ELSIF conditions
  std::vector<StmtList> bodies; // kIf: one per condition, then the ELSE body if has_else
  bool has_else = false;
  std::vector<CaseArm> arms;    // kCase
  StmtList else_body;           // kCase ELSE
  StmtList body;                // kFor
};

enum class DeclSection : std::uint8_t { kVar, kConstant, kExternal };

struct TypeRef {
  Pos pos;
  std::string name;     // elementary or FB type name (for an array: the element type)
  bool array = false;
  ExprPtr lo, hi;       // array bounds (constant expressions)
};

struct VarDecl {
  DeclSection section = DeclSection::kVar;
  std::vector<std::pair<std::string, Pos>> names;
  TypeRef type;
  ExprPtr init;                   // scalar initial value
  std::vector<ExprPtr> array_init;  // [a, b, c]
};

struct ProgramAst {
  std::string name;
  Pos pos;
  std::vector<VarDecl> decls;
  StmtList body;
};

}  // namespace contour::control::plc
