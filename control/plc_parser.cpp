// The Structured Text subset of contourd's soft PLC: its whole grammar, and the recursive-descent
// parser that follows it rule by rule (each parse_* function below implements the rule of the
// same name). Semantics (types, what each construct means) are IEC 61131-3's; what the subset
// leaves out is listed at the end. daemon/PLC.md is the user's guide.
//
// ---- Tokens ------------------------------------------------------------------------------------
//   Letters are case-insensitive everywhere (keywords, identifiers, units).
//   comment     = "(*" ... "*)" | "/*" ... "*/" | "//" ... end of line
//   identifier  = letter { letter | digit | "_" }            (no "__", not ending in "_" is not
//                                                             enforced; keywords are reserved)
//   integer     = digit { ["_"] digit }
//               | ( "2" | "8" | "16" ) "#" based_digit { ["_"] based_digit }
//   real        = integer "." integer [ ( "E" | "e" ) [ "+" | "-" ] integer ]
//   time        = ( "T" | "TIME" ) "#" [ "-" ] interval        e.g. T#1s, T#1m30s, TIME#250ms
//   interval    = number unit { ["_"] number unit }   number = integer [ "." integer ]
//   unit        = "d" | "h" | "m" | "s" | "ms" | "us" | "ns"
//   symbols     = ":=" "=>" ".." "(" ")" "[" "]" "," ";" ":" "." "+" "-" "*" "**" "/" "="
//                 "<>" "<" ">" "<=" ">=" "&" "#"
//
// ---- Syntax (EBNF: {} repeat, [] optional, | choice) -------------------------------------------
//   program      = "PROGRAM" identifier { var_block } statements "END_PROGRAM"
//   var_block    = ( "VAR" [ "CONSTANT" ] | "VAR_EXTERNAL" ) { var_decl } "END_VAR"
//   var_decl     = identifier { "," identifier } ":" type_spec [ ":=" initialiser ] ";"
//   type_spec    = type_name                       BOOL INT DINT REAL LREAL TIME or a standard
//                                                  FB: TON TOF TP R_TRIG F_TRIG SR RS CTU CTD CTUD
//                | "ARRAY" "[" expression ".." expression "]" "OF" type_name   (elementary only)
//   initialiser  = expression | "[" expression { "," expression } "]"
//   statements   = { statement }
//   statement    = assignment | fb_call | if | case | for | "EXIT" ";" | "RETURN" ";" | ";"
//   assignment   = variable ":=" expression ";"
//   fb_call      = identifier "(" [ fb_param { "," fb_param } ] ")" ";"
//   fb_param     = identifier ":=" expression | identifier "=>" variable
//   if           = "IF" expression "THEN" statements
//                  { "ELSIF" expression "THEN" statements }
//                  [ "ELSE" statements ] "END_IF" [ ";" ]
//   case         = "CASE" expression "OF" { case_arm } [ "ELSE" statements ] "END_CASE" [ ";" ]
//   case_arm     = case_label { "," case_label } ":" statements
//   case_label   = expression [ ".." expression ]            (constant expressions)
//   for          = "FOR" identifier ":=" expression "TO" expression [ "BY" expression ]
//                  "DO" statements "END_FOR" [ ";" ]          (constant bounds and step)
//   expression   = xor_expr { "OR" xor_expr }
//   xor_expr     = and_expr { "XOR" and_expr }
//   and_expr     = equality { ( "AND" | "&" ) equality }
//   equality     = comparison { ( "=" | "<>" ) comparison }
//   comparison   = sum { ( "<" | ">" | "<=" | ">=" ) sum }
//   sum          = term { ( "+" | "-" ) term }
//   term         = unary { ( "*" | "/" | "MOD" ) unary }
//   unary        = ( "-" | "NOT" ) unary | power
//   power        = primary { "**" primary }
//   primary      = literal | variable | call | "(" expression ")"
//   call         = identifier "(" [ expression { "," expression } ] ")"
//   variable     = identifier [ "[" expression "]" ] [ "." identifier ]
//                  (fb.Q, NC.feed_hold, table[i])
//   literal      = integer | real | time | "TRUE" | "FALSE"
//                | type_name "#" ( [ "-" ] integer | [ "-" ] real | "TRUE" | "FALSE" )
//
// ---- Left out on purpose -----------------------------------------------------------------------
//   WHILE and REPEAT (no loop may run unbounded: FOR with constant bounds only), user-defined
//   FUNCTION / FUNCTION_BLOCK / types, STRING, pointers and references, RETAIN, SFC, several
//   PROGRAMs in one file. Each is a syntax error that says so.
#include "control/plc_parser.hpp"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

namespace contour::control::plc {

namespace {

enum class Tok : std::uint8_t { kIdent, kInt, kReal, kTime, kSym, kEof };

struct Token {
  Tok kind = Tok::kEof;
  std::string text;  // identifiers: upper case; symbols: the symbol
  std::string raw;   // as written
  Pos pos;
  std::int64_t ival = 0;
  double rval = 0.0;
};

struct SyntaxError : std::runtime_error {
  SyntaxError(Pos p, const std::string& m) : std::runtime_error(m), pos(p) {}
  Pos pos;
};

// ---- Lexer -------------------------------------------------------------------------------------
class Lexer {
 public:
  Lexer(std::string_view src, const std::string& file, std::vector<Diagnostic>& errors)
      : s_(src), file_(file), errors_(errors) {}

  std::vector<Token> run() {
    std::vector<Token> out;
    for (;;) {
      skip_space_and_comments();
      Token t;
      t.pos = {line_, col_};
      if (i_ >= s_.size()) {
        t.kind = Tok::kEof;
        out.push_back(t);
        return out;
      }
      const char c = s_[i_];
      try {
        if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') {
          lex_identifier(t);
        } else if (std::isdigit(static_cast<unsigned char>(c))) {
          lex_number(t);
        } else {
          lex_symbol(t);
        }
        out.push_back(std::move(t));
      } catch (const SyntaxError& e) {
        errors_.push_back({file_, e.pos.line, e.pos.column, e.what()});
        advance();  // skip the offending character and go on
      }
    }
  }

 private:
  [[nodiscard]] char peek(std::size_t k = 0) const { return i_ + k < s_.size() ? s_[i_ + k] : '\0'; }
  void advance() {
    if (i_ >= s_.size()) return;
    if (s_[i_] == '\n') {
      ++line_;
      col_ = 1;
    } else {
      ++col_;
    }
    ++i_;
  }

  void skip_space_and_comments() {
    for (;;) {
      while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) advance();
      if (peek() == '(' && peek(1) == '*') {
        skip_block("*)");
      } else if (peek() == '/' && peek(1) == '*') {
        skip_block("*/");
      } else if (peek() == '/' && peek(1) == '/') {
        while (i_ < s_.size() && s_[i_] != '\n') advance();
      } else {
        return;
      }
    }
  }

  void skip_block(const char* close) {
    const Pos start{line_, col_};
    advance();
    advance();
    while (i_ < s_.size() && !(peek() == close[0] && peek(1) == close[1])) advance();
    if (i_ >= s_.size()) {
      errors_.push_back({file_, start.line, start.column, "comment not closed"});
      return;
    }
    advance();
    advance();
  }

  void lex_identifier(Token& t) {
    const std::size_t b = i_;
    while (std::isalnum(static_cast<unsigned char>(peek())) || peek() == '_') advance();
    t.raw = std::string(s_.substr(b, i_ - b));
    t.text = upper(t.raw);
    t.kind = Tok::kIdent;
    if ((t.text == "T" || t.text == "TIME" || t.text == "LT" || t.text == "LTIME") && peek() == '#') {
      advance();
      lex_duration(t, b);
    }
  }

  // After "T#": [-] number unit { [_] number unit }.
  void lex_duration(Token& t, std::size_t begin) {
    bool neg = false;
    if (peek() == '-') {
      neg = true;
      advance();
    }
    double total_ns = 0.0;
    int parts = 0;
    for (;;) {
      if (peek() == '_' && parts > 0) advance();
      if (!std::isdigit(static_cast<unsigned char>(peek()))) break;
      const std::size_t nb = i_;
      while (std::isdigit(static_cast<unsigned char>(peek())) || peek() == '_') advance();
      if (peek() == '.' && std::isdigit(static_cast<unsigned char>(peek(1)))) {
        advance();
        while (std::isdigit(static_cast<unsigned char>(peek()))) advance();
      }
      std::string num;
      for (char ch : s_.substr(nb, i_ - nb))
        if (ch != '_') num.push_back(ch);
      const double v = std::strtod(num.c_str(), nullptr);
      std::string unit;
      while (std::isalpha(static_cast<unsigned char>(peek()))) {
        unit.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(peek()))));
        advance();
        // "1m30s": stop the unit before a digit; "ms", "us", "ns" are two letters.
        if (unit == "m" && peek() != 's') break;
        if (unit == "d" || unit == "h" || unit == "s" || unit.size() == 2) break;
      }
      double scale = 0.0;
      if (unit == "d") scale = 86400e9;
      else if (unit == "h") scale = 3600e9;
      else if (unit == "m") scale = 60e9;
      else if (unit == "s") scale = 1e9;
      else if (unit == "ms") scale = 1e6;
      else if (unit == "us") scale = 1e3;
      else if (unit == "ns") scale = 1.0;
      else
        throw SyntaxError(t.pos, "time literal: unit '" + unit +
                                     "' (expected d, h, m, s, ms, us or ns)");
      total_ns += v * scale;
      ++parts;
    }
    t.raw = std::string(s_.substr(begin, i_ - begin));
    if (parts == 0) throw SyntaxError(t.pos, "time literal '" + t.raw + "' has no duration");
    if (std::abs(total_ns) > 9.2e18) throw SyntaxError(t.pos, "time literal out of range");
    t.kind = Tok::kTime;
    t.ival = static_cast<std::int64_t>(std::llround(neg ? -total_ns : total_ns));
  }

  void lex_number(Token& t) {
    const std::size_t b = i_;
    std::string digits;
    while (std::isdigit(static_cast<unsigned char>(peek())) || peek() == '_') {
      if (peek() != '_') digits.push_back(peek());
      advance();
    }
    if (peek() == '#') {  // based integer 2#, 8#, 16#
      const int base = std::atoi(digits.c_str());
      if (base != 2 && base != 8 && base != 16) {
        // "INT#5" style typed literals start with an identifier, never with digits.
        throw SyntaxError(t.pos, "based literal: base " + digits + " (expected 2, 8 or 16)");
      }
      advance();
      std::string v;
      while (std::isxdigit(static_cast<unsigned char>(peek())) || peek() == '_') {
        if (peek() != '_') v.push_back(peek());
        advance();
      }
      t.raw = std::string(s_.substr(b, i_ - b));
      char* end = nullptr;
      errno = 0;
      const unsigned long long u = std::strtoull(v.c_str(), &end, base);
      if (v.empty() || *end != '\0' || errno != 0)
        throw SyntaxError(t.pos, "bad based literal '" + t.raw + "'");
      t.kind = Tok::kInt;
      t.ival = static_cast<std::int64_t>(u);
      return;
    }
    bool real = false;
    if (peek() == '.' && std::isdigit(static_cast<unsigned char>(peek(1)))) {
      real = true;
      digits.push_back('.');
      advance();
      while (std::isdigit(static_cast<unsigned char>(peek())) || peek() == '_') {
        if (peek() != '_') digits.push_back(peek());
        advance();
      }
    }
    if ((peek() == 'e' || peek() == 'E') &&
        (std::isdigit(static_cast<unsigned char>(peek(1))) ||
         ((peek(1) == '+' || peek(1) == '-') && std::isdigit(static_cast<unsigned char>(peek(2)))))) {
      real = true;
      digits.push_back('e');
      advance();
      if (peek() == '+' || peek() == '-') {
        digits.push_back(peek());
        advance();
      }
      while (std::isdigit(static_cast<unsigned char>(peek()))) {
        digits.push_back(peek());
        advance();
      }
    }
    t.raw = std::string(s_.substr(b, i_ - b));
    if (real) {
      t.kind = Tok::kReal;
      t.rval = std::strtod(digits.c_str(), nullptr);
      return;
    }
    errno = 0;
    const long long v = std::strtoll(digits.c_str(), nullptr, 10);
    if (errno != 0) throw SyntaxError(t.pos, "integer literal '" + t.raw + "' out of range");
    t.kind = Tok::kInt;
    t.ival = v;
  }

  void lex_symbol(Token& t) {
    static const char* const kTwo[] = {":=", "=>", "..", "**", "<>", "<=", ">="};
    for (const char* two : kTwo) {
      if (peek() == two[0] && peek(1) == two[1]) {
        t.kind = Tok::kSym;
        t.text = t.raw = two;
        advance();
        advance();
        return;
      }
    }
    const char c = peek();
    if (std::string_view("()[],;:.+-*/=<>&#").find(c) == std::string_view::npos) {
      if (c == '"' || c == '\'')
        throw SyntaxError(t.pos, "strings are not part of the ST subset");
      throw SyntaxError(t.pos, std::string("unexpected character '") + c + "'");
    }
    t.kind = Tok::kSym;
    t.text = t.raw = std::string(1, c);
    advance();
  }

  std::string_view s_;
  const std::string& file_;
  std::vector<Diagnostic>& errors_;
  std::size_t i_ = 0;
  int line_ = 1;
  int col_ = 1;
};

// ---- Parser ------------------------------------------------------------------------------------
bool is_keyword(const std::string& u) {
  static const char* const kKeywords[] = {
      "PROGRAM", "END_PROGRAM", "VAR", "VAR_EXTERNAL", "VAR_INPUT", "VAR_OUTPUT", "VAR_IN_OUT",
      "VAR_GLOBAL", "VAR_TEMP", "CONSTANT", "RETAIN", "END_VAR", "IF", "THEN", "ELSIF", "ELSE",
      "END_IF", "CASE", "OF", "END_CASE", "FOR", "TO", "BY", "DO", "END_FOR", "WHILE", "END_WHILE",
      "REPEAT", "UNTIL", "END_REPEAT", "EXIT", "RETURN", "AND", "OR", "XOR", "NOT", "MOD", "TRUE",
      "FALSE", "ARRAY", "FUNCTION", "FUNCTION_BLOCK", "END_FUNCTION", "END_FUNCTION_BLOCK", "TYPE",
      "END_TYPE", "STRUCT", "END_STRUCT"};
  for (const char* k : kKeywords)
    if (u == k) return true;
  return false;
}

class Parser {
 public:
  Parser(std::vector<Token> toks, const std::string& file, std::vector<Diagnostic>& errors)
      : t_(std::move(toks)), file_(file), errors_(errors) {}

  // program = "PROGRAM" identifier { var_block } statements "END_PROGRAM"
  ProgramAst parse_program() {
    ProgramAst p;
    try {
      if (is_word("FUNCTION") || is_word("FUNCTION_BLOCK") || is_word("TYPE"))
        fail("user-defined functions, function blocks and types are not part of the ST subset: "
             "a file holds one PROGRAM");
      p.pos = cur().pos;
      expect_word("PROGRAM");
      p.name = expect_identifier("program name").raw;
    } catch (const SyntaxError& e) {
      report(e);
      return p;
    }
    while (is_word("VAR") || is_word("VAR_EXTERNAL") || is_word("VAR_INPUT") ||
           is_word("VAR_OUTPUT") || is_word("VAR_IN_OUT") || is_word("VAR_GLOBAL") ||
           is_word("VAR_TEMP")) {
      parse_var_block(p);
    }
    p.body = parse_statements();
    try {
      if (!is_word("END_PROGRAM")) {
        if (cur().kind == Tok::kEof) fail("END_PROGRAM expected before the end of the file");
        fail("unexpected '" + cur().raw + "' (a statement or END_PROGRAM expected)");
      }
      next();
      if (cur().kind != Tok::kEof) {
        if (is_word("PROGRAM")) fail("one PROGRAM per file (list each file in plc.programs)");
        fail("unexpected '" + cur().raw + "' after END_PROGRAM");
      }
    } catch (const SyntaxError& e) {
      report(e);
    }
    return p;
  }

 private:
  // var_block = ( "VAR" [ "CONSTANT" ] | "VAR_EXTERNAL" ) { var_decl } "END_VAR"
  void parse_var_block(ProgramAst& p) {
    DeclSection sec = DeclSection::kVar;
    try {
      const Token kw = next();
      if (kw.text == "VAR_INPUT" || kw.text == "VAR_OUTPUT" || kw.text == "VAR_IN_OUT" ||
          kw.text == "VAR_GLOBAL" || kw.text == "VAR_TEMP")
        throw SyntaxError(kw.pos, kw.raw + " is not part of the ST subset (a PROGRAM has VAR, "
                                           "VAR CONSTANT and VAR_EXTERNAL)");
      if (kw.text == "VAR_EXTERNAL") sec = DeclSection::kExternal;
      if (is_word("CONSTANT")) {
        if (sec == DeclSection::kExternal) fail("VAR_EXTERNAL CONSTANT: drop CONSTANT");
        next();
        sec = DeclSection::kConstant;
      }
      if (is_word("RETAIN") || is_word("PERSISTENT"))
        fail("RETAIN is not supported: PLC variables start from their initial values at every "
             "start of contourd");
    } catch (const SyntaxError& e) {
      report(e);
      sync_to_word("END_VAR");
      if (is_word("END_VAR")) next();
      return;
    }
    while (!is_word("END_VAR") && cur().kind != Tok::kEof && !is_word("END_PROGRAM")) {
      try {
        p.decls.push_back(parse_var_decl(sec));
      } catch (const SyntaxError& e) {
        report(e);
        sync_past(";", "END_VAR");
      }
    }
    try {
      expect_word("END_VAR");
    } catch (const SyntaxError& e) {
      report(e);
    }
  }

  // var_decl = identifier { "," identifier } ":" type_spec [ ":=" initialiser ] ";"
  VarDecl parse_var_decl(DeclSection sec) {
    VarDecl d;
    d.section = sec;
    for (;;) {
      const Token id = expect_identifier("variable name");
      d.names.emplace_back(id.raw, id.pos);
      if (!accept_sym(",")) break;
    }
    expect_sym(":");
    d.type = parse_type_spec();
    if (accept_sym(":=")) {
      if (is_sym("[")) {
        next();
        for (;;) {
          d.array_init.push_back(parse_expression());
          if (!accept_sym(",")) break;
        }
        expect_sym("]");
      } else {
        d.init = parse_expression();
      }
    }
    expect_sym(";");
    return d;
  }

  // type_spec = type_name | "ARRAY" "[" expression ".." expression "]" "OF" type_name
  TypeRef parse_type_spec() {
    TypeRef t;
    t.pos = cur().pos;
    if (is_word("ARRAY")) {
      next();
      expect_sym("[");
      t.lo = parse_expression();
      expect_sym("..");
      t.hi = parse_expression();
      if (is_sym(",")) fail("multi-dimensional arrays are not part of the ST subset");
      expect_sym("]");
      expect_word("OF");
      t.array = true;
      t.pos = cur().pos;
    }
    if (is_word("STRING") || is_word("WSTRING"))
      fail("STRING is not part of the ST subset");
    t.name = expect_identifier("type name").text;
    return t;
  }

  // statements = { statement }
  StmtList parse_statements() {
    StmtList out;
    for (;;) {
      if (cur().kind == Tok::kEof || is_word("END_PROGRAM") || is_word("END_IF") ||
          is_word("ELSIF") || is_word("ELSE") || is_word("END_CASE") || is_word("END_FOR") ||
          is_word("END_VAR"))
        return out;
      // A case arm's label ends the previous arm's statements: "2:" or "3..5:" or "1, 2:".
      if (in_case_ > 0 && starts_case_label()) return out;
      const std::size_t before = i_;
      try {
        out.push_back(parse_statement());
      } catch (const SyntaxError& e) {
        report(e);
        sync_statement();
        if (i_ == before) next();  // always make progress
      }
    }
  }

  // statement = assignment | fb_call | if | case | for | "EXIT" ";" | "RETURN" ";" | ";"
  Stmt parse_statement() {
    Stmt s;
    s.pos = cur().pos;
    if (accept_sym(";")) return s;
    if (is_word("IF")) return parse_if();
    if (is_word("CASE")) return parse_case();
    if (is_word("FOR")) return parse_for();
    if (is_word("WHILE") || is_word("REPEAT"))
      fail(cur().raw + " is not supported: a scan must end within its instruction budget, so "
                       "the only loop is FOR with constant bounds");
    if (is_word("EXIT") || is_word("RETURN")) {
      s.kind = is_word("EXIT") ? StmtKind::kExit : StmtKind::kReturn;
      next();
      expect_sym(";");
      return s;
    }
    if (cur().kind != Tok::kIdent || is_keyword(cur().text)) {
      if (cur().kind == Tok::kEof) fail("END_PROGRAM expected before the end of the file");
      fail("a statement expected, found '" + cur().raw + "'");
    }
    // fb_call = identifier "(" ... ")" ";"
    if (peek_sym(1, "(")) return parse_fb_call();
    // assignment = variable ":=" expression ";"
    s.kind = StmtKind::kAssign;
    s.target = parse_variable();
    if (is_sym("=")) fail("'=' compares; assignment is ':='");
    expect_sym(":=");
    s.value = parse_expression();
    expect_sym(";");
    return s;
  }

  // fb_call = identifier "(" [ fb_param { "," fb_param } ] ")" ";"
  // fb_param = identifier ":=" expression | identifier "=>" variable
  Stmt parse_fb_call() {
    Stmt s;
    s.kind = StmtKind::kFbCall;
    s.pos = cur().pos;
    s.instance = next().raw;
    expect_sym("(");
    if (!is_sym(")")) {
      for (;;) {
        FbParam prm;
        prm.pos = cur().pos;
        const Token name = expect_identifier("parameter name (IN := value)");
        prm.name = name.text;
        if (accept_sym("=>")) {
          prm.output = true;
          prm.value = parse_variable();
        } else {
          if (!is_sym(":="))
            fail("formal parameter expected: write " + name.raw + " := value (positional "
                 "arguments are not part of the ST subset)");
          next();
          prm.value = parse_expression();
        }
        s.params.push_back(std::move(prm));
        if (!accept_sym(",")) break;
      }
    }
    expect_sym(")");
    expect_sym(";");
    return s;
  }

  // if = "IF" expression "THEN" statements { "ELSIF" ... } [ "ELSE" statements ] "END_IF" [";"]
  Stmt parse_if() {
    Stmt s;
    s.kind = StmtKind::kIf;
    s.pos = cur().pos;
    next();
    s.conds.push_back(parse_expression());
    expect_word("THEN");
    s.bodies.push_back(parse_statements());
    while (is_word("ELSIF")) {
      next();
      s.conds.push_back(parse_expression());
      expect_word("THEN");
      s.bodies.push_back(parse_statements());
    }
    if (is_word("ELSE")) {
      next();
      s.has_else = true;
      s.bodies.push_back(parse_statements());
    }
    expect_end("END_IF", s.pos);
    return s;
  }

  // case = "CASE" expression "OF" { case_arm } [ "ELSE" statements ] "END_CASE" [";"]
  // case_arm = case_label { "," case_label } ":" statements
  Stmt parse_case() {
    Stmt s;
    s.kind = StmtKind::kCase;
    s.pos = cur().pos;
    next();
    s.value = parse_expression();
    expect_word("OF");
    ++in_case_;
    while (!is_word("ELSE") && !is_word("END_CASE") && cur().kind != Tok::kEof &&
           !is_word("END_PROGRAM")) {
      CaseArm arm;
      arm.pos = cur().pos;
      try {
        for (;;) {
          CaseLabel l;
          l.lo = parse_sum();
          if (accept_sym("..")) l.hi = parse_sum();
          arm.labels.push_back(std::move(l));
          if (!accept_sym(",")) break;
        }
        expect_sym(":");
      } catch (const SyntaxError& e) {
        --in_case_;
        throw;
      }
      arm.body = parse_statements();
      s.arms.push_back(std::move(arm));
    }
    --in_case_;
    if (is_word("ELSE")) {
      next();
      s.else_body = parse_statements();
    }
    expect_end("END_CASE", s.pos);
    return s;
  }

  // for = "FOR" identifier ":=" expression "TO" expression [ "BY" expression ] "DO" statements
  //       "END_FOR" [";"]
  Stmt parse_for() {
    Stmt s;
    s.kind = StmtKind::kFor;
    s.pos = cur().pos;
    next();
    auto v = std::make_unique<Expr>();
    v->kind = ExprKind::kName;
    v->pos = cur().pos;
    v->name = expect_identifier("FOR control variable").raw;
    s.target = std::move(v);
    expect_sym(":=");
    s.value = parse_expression();
    expect_word("TO");
    s.to = parse_expression();
    if (is_word("BY")) {
      next();
      s.by = parse_expression();
    }
    expect_word("DO");
    s.body = parse_statements();
    expect_end("END_FOR", s.pos);
    return s;
  }

  // ---- expressions (lowest precedence first) ----
  // expression = xor_expr { "OR" xor_expr }
  ExprPtr parse_expression() { return binary_chain(&Parser::parse_xor, {"OR"}); }
  // xor_expr = and_expr { "XOR" and_expr }
  ExprPtr parse_xor() { return binary_chain(&Parser::parse_and, {"XOR"}); }
  // and_expr = equality { ( "AND" | "&" ) equality }
  ExprPtr parse_and() { return binary_chain(&Parser::parse_equality, {"AND", "&"}); }
  // equality = comparison { ( "=" | "<>" ) comparison }
  ExprPtr parse_equality() { return binary_chain(&Parser::parse_comparison, {"=", "<>"}); }
  // comparison = sum { ( "<" | ">" | "<=" | ">=" ) sum }
  ExprPtr parse_comparison() { return binary_chain(&Parser::parse_sum, {"<", ">", "<=", ">="}); }
  // sum = term { ( "+" | "-" ) term }
  ExprPtr parse_sum() { return binary_chain(&Parser::parse_term, {"+", "-"}); }
  // term = unary { ( "*" | "/" | "MOD" ) unary }
  ExprPtr parse_term() { return binary_chain(&Parser::parse_unary, {"*", "/", "MOD"}); }

  // unary = ( "-" | "NOT" ) unary | power
  ExprPtr parse_unary() {
    if (is_sym("-") || is_word("NOT")) {
      auto e = std::make_unique<Expr>();
      e->kind = ExprKind::kUnary;
      e->pos = cur().pos;
      e->op = next().text;
      e->args.push_back(parse_unary());
      // Fold "-5" into a literal, so that INT#-32768 style bounds and case labels stay constant.
      if (e->op == "-" && e->args[0]->kind == ExprKind::kLiteral && e->args[0]->type != Type::kBool) {
        ExprPtr lit = std::move(e->args[0]);
        if (is_real(lit->type)) lit->value.r = -lit->value.r;
        else lit->value.i = -lit->value.i;
        lit->pos = e->pos;
        return lit;
      }
      return e;
    }
    return parse_power();
  }

  // power = primary { "**" primary }
  ExprPtr parse_power() { return binary_chain(&Parser::parse_primary, {"**"}); }

  // primary = literal | variable | call | "(" expression ")"
  ExprPtr parse_primary() {
    const Token& t = cur();
    auto e = std::make_unique<Expr>();
    e->pos = t.pos;
    if (accept_sym("(")) {
      e = parse_expression();
      expect_sym(")");
      return e;
    }
    switch (t.kind) {
      case Tok::kInt:
        e->kind = ExprKind::kLiteral;
        e->type = Type::kDint;
        e->untyped = true;
        e->value.i = t.ival;
        next();
        return e;
      case Tok::kReal:
        e->kind = ExprKind::kLiteral;
        e->type = Type::kLreal;
        e->untyped = true;
        e->value.r = t.rval;
        next();
        return e;
      case Tok::kTime:
        e->kind = ExprKind::kLiteral;
        e->type = Type::kTime;
        e->value.i = t.ival;
        next();
        return e;
      case Tok::kIdent:
        break;
      default:
        if (t.kind == Tok::kEof) fail("an expression expected before the end of the file");
        fail("an expression expected, found '" + t.raw + "'");
    }
    if (t.text == "TRUE" || t.text == "FALSE") {
      e->kind = ExprKind::kLiteral;
      e->type = Type::kBool;
      e->value.i = t.text == "TRUE" ? 1 : 0;
      next();
      return e;
    }
    if (is_keyword(t.text)) fail("an expression expected, found the keyword '" + t.raw + "'");
    // typed literal: type_name "#" value
    if (peek_sym(1, "#")) return parse_typed_literal();
    if (peek_sym(1, "(")) {
      // call = identifier "(" [ expression { "," expression } ] ")"
      e->kind = ExprKind::kCall;
      e->name = next().raw;
      expect_sym("(");
      if (!is_sym(")")) {
        for (;;) {
          if (cur().kind == Tok::kIdent && (peek_sym(1, ":=") || peek_sym(1, "=>")))
            fail("a function block call is a statement of its own: " + e->name + "(...);");
          e->args.push_back(parse_expression());
          if (!accept_sym(",")) break;
        }
      }
      expect_sym(")");
      return e;
    }
    return parse_variable();
  }

  ExprPtr parse_typed_literal() {
    auto e = std::make_unique<Expr>();
    e->kind = ExprKind::kLiteral;
    e->pos = cur().pos;
    const Token type = next();
    next();  // '#'
    bool neg = false;
    if (accept_sym("-")) neg = true;
    const Token& v = cur();
    if (type.text == "BOOL") {
      e->type = Type::kBool;
      if (v.kind == Tok::kInt && (v.ival == 0 || v.ival == 1) && !neg) e->value.i = v.ival;
      else if (v.kind == Tok::kIdent && (v.text == "TRUE" || v.text == "FALSE") && !neg)
        e->value.i = v.text == "TRUE" ? 1 : 0;
      else
        fail("BOOL# takes 0, 1, TRUE or FALSE");
      next();
      return e;
    }
    Type ty = Type::kVoid;
    if (type.text == "INT") ty = Type::kInt;
    else if (type.text == "DINT") ty = Type::kDint;
    else if (type.text == "REAL") ty = Type::kReal;
    else if (type.text == "LREAL") ty = Type::kLreal;
    else
      throw SyntaxError(type.pos, "typed literal: unknown type '" + type.raw +
                                      "' (INT#, DINT#, REAL#, LREAL#, BOOL#, T#)");
    e->type = ty;
    if (v.kind == Tok::kInt) {
      if (is_real(ty)) e->value.r = static_cast<double>(neg ? -v.ival : v.ival);
      else e->value.i = neg ? -v.ival : v.ival;
    } else if (v.kind == Tok::kReal && is_real(ty)) {
      e->value.r = neg ? -v.rval : v.rval;
    } else {
      fail("typed literal " + type.raw + "# needs a number");
    }
    next();
    return e;
  }

  // variable = identifier [ "[" expression "]" ] [ "." identifier ]
  ExprPtr parse_variable() {
    auto e = std::make_unique<Expr>();
    e->kind = ExprKind::kName;
    e->pos = cur().pos;
    const Token id = expect_identifier("variable");
    if (is_keyword(id.text)) throw SyntaxError(id.pos, "'" + id.raw + "' is a keyword");
    e->name = id.raw;
    if (accept_sym("[")) {
      e->index = parse_expression();
      if (is_sym(",")) fail("multi-dimensional arrays are not part of the ST subset");
      expect_sym("]");
    }
    if (accept_sym(".")) {
      e->member_pos = cur().pos;
      e->member = expect_identifier("member name after '.'").raw;
      if (is_sym(".")) fail("nested structures are not part of the ST subset");
    }
    return e;
  }

  ExprPtr binary_chain(ExprPtr (Parser::*sub)(), std::initializer_list<const char*> ops) {
    ExprPtr left = (this->*sub)();
    for (;;) {
      const char* hit = nullptr;
      for (const char* op : ops) {
        if ((cur().kind == Tok::kSym || cur().kind == Tok::kIdent) && cur().text == op) hit = op;
      }
      if (hit == nullptr) return left;
      auto e = std::make_unique<Expr>();
      e->kind = ExprKind::kBinary;
      e->pos = cur().pos;
      e->op = std::string(hit) == "&" ? "AND" : hit;
      next();
      e->args.push_back(std::move(left));
      e->args.push_back((this->*sub)());
      left = std::move(e);
    }
  }

  // ---- token helpers ----
  [[nodiscard]] const Token& cur() const { return t_[i_]; }
  Token next() {
    Token t = t_[i_];
    if (i_ + 1 < t_.size()) ++i_;
    return t;
  }
  [[nodiscard]] bool is_word(const char* w) const {
    return cur().kind == Tok::kIdent && cur().text == w;
  }
  [[nodiscard]] bool is_sym(const char* s) const {
    return cur().kind == Tok::kSym && cur().text == s;
  }
  [[nodiscard]] bool peek_sym(std::size_t k, const char* s) const {
    const std::size_t j = std::min(i_ + k, t_.size() - 1);
    return t_[j].kind == Tok::kSym && t_[j].text == s;
  }
  bool accept_sym(const char* s) {
    if (!is_sym(s)) return false;
    next();
    return true;
  }
  [[noreturn]] void fail(const std::string& m) const { throw SyntaxError(cur().pos, m); }
  std::string found() const {
    return cur().kind == Tok::kEof ? "the end of the file" : "'" + cur().raw + "'";
  }
  void expect_sym(const char* s) {
    if (!accept_sym(s)) fail(std::string("'") + s + "' expected, found " + found());
  }
  void expect_word(const char* w) {
    if (!is_word(w)) fail(std::string(w) + " expected, found " + found());
    next();
  }
  void expect_end(const char* w, Pos opened) {
    if (!is_word(w))
      fail(std::string(w) + " expected (for the statement at line " + std::to_string(opened.line) +
           "), found " + found());
    next();
    accept_sym(";");
  }
  Token expect_identifier(const char* what) {
    if (cur().kind != Tok::kIdent || is_keyword(cur().text))
      fail(std::string(what) + " expected, found " + found());
    return next();
  }
  [[nodiscard]] bool starts_case_label() const {
    // integer-ish token sequence up to ':' (not ':='), e.g. "2:", "-1:", "3..5:", "1, 2:", "N:".
    std::size_t j = i_;
    int n = 0;
    while (j < t_.size() && n < 16) {
      const Token& t = t_[j];
      if (t.kind == Tok::kSym && t.text == ":") return n > 0;
      if (t.kind == Tok::kSym && (t.text == ";" || t.text == ":=" || t.text == "(" || t.text == "["))
        return false;
      if (t.kind == Tok::kEof) return false;
      if (t.kind == Tok::kIdent && is_keyword(t.text)) return false;
      ++j;
      ++n;
    }
    return false;
  }
  void report(const SyntaxError& e) {
    errors_.push_back({file_, e.pos.line, e.pos.column, e.what()});
  }
  void sync_to_word(const char* w) {
    while (cur().kind != Tok::kEof && !is_word(w)) next();
  }
  void sync_past(const char* sym, const char* stop_word) {
    while (cur().kind != Tok::kEof && !is_word(stop_word)) {
      if (is_sym(sym)) {
        next();
        return;
      }
      next();
    }
  }
  // After a bad statement: skip to just past the next ';', or stop at a block keyword.
  void sync_statement() {
    while (cur().kind != Tok::kEof) {
      if (is_sym(";")) {
        next();
        return;
      }
      if (is_word("END_IF") || is_word("ELSIF") || is_word("ELSE") || is_word("END_CASE") ||
          is_word("END_FOR") || is_word("END_PROGRAM") || is_word("IF") || is_word("CASE") ||
          is_word("FOR"))
        return;
      next();
    }
  }

  std::vector<Token> t_;
  std::size_t i_ = 0;
  const std::string& file_;
  std::vector<Diagnostic>& errors_;
  int in_case_ = 0;
};

}  // namespace

ProgramAst parse_program(std::string_view source, const std::string& file,
                         std::vector<Diagnostic>& errors) {
  Lexer lx(source, file, errors);
  Parser p(lx.run(), file, errors);
  return p.parse_program();
}

}  // namespace contour::control::plc
