#include "control/plc_compiler.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>

#include "control/plc_parser.hpp"

namespace contour::control::plc {

void SymbolTable::add(ExternalSymbol s) {
  const std::string key = upper(s.name);
  if (by_upper_.count(key) != 0) throw std::invalid_argument("duplicate symbol '" + s.name + "'");
  by_upper_[key] = list_.size();
  list_.push_back(std::move(s));
}

const ExternalSymbol* SymbolTable::find(std::string_view name) const {
  const auto it = by_upper_.find(upper(name));
  return it == by_upper_.end() ? nullptr : &list_[it->second];
}

std::vector<Instr> link(const CompiledProgram& p, std::int32_t locals_base) {
  std::vector<Instr> code = p.code;
  for (Instr& in : code) {
    switch (in.op) {
      case Op::kLoad:
      case Op::kStore:
      case Op::kLoadInd:
      case Op::kStoreInd:
      case Op::kCallFb:
        if ((in.a & kLocalFlag) != 0) in.a = locals_base + (in.a & ~kLocalFlag);
        break;
      default:
        break;
    }
  }
  return code;
}

namespace {

constexpr std::uint64_t kSat = std::numeric_limits<std::uint64_t>::max();
std::uint64_t sat_add(std::uint64_t a, std::uint64_t b) { return a > kSat - b ? kSat : a + b; }
std::uint64_t sat_mul(std::uint64_t a, std::uint64_t b) {
  if (a == 0 || b == 0) return 0;
  return a > kSat / b ? kSat : a * b;
}

// IEC 61131-3 implicit conversions (3rd edition, widening only).
bool widens(Type from, Type to) {
  if (from == to) return true;
  switch (from) {
    case Type::kInt:
      return to == Type::kDint || to == Type::kReal || to == Type::kLreal;
    case Type::kDint:
      return to == Type::kLreal;
    case Type::kReal:
      return to == Type::kLreal;
    default:
      return false;
  }
}

bool parse_elementary(const std::string& u, Type& out) {
  if (u == "BOOL") out = Type::kBool;
  else if (u == "INT") out = Type::kInt;
  else if (u == "DINT") out = Type::kDint;
  else if (u == "REAL") out = Type::kReal;
  else if (u == "LREAL") out = Type::kLreal;
  else if (u == "TIME") out = Type::kTime;
  else return false;
  return true;
}

std::int64_t type_min(Type t) {
  return t == Type::kInt ? -32768 : t == Type::kDint ? -2147483648LL
                                                      : std::numeric_limits<std::int64_t>::min();
}
std::int64_t type_max(Type t) {
  return t == Type::kInt ? 32767 : t == Type::kDint ? 2147483647LL
                                                     : std::numeric_limits<std::int64_t>::max();
}

// Levenshtein distance, for "did you mean".
std::size_t distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

struct Local {
  std::string raw;
  Pos pos;
  Type type = Type::kVoid;
  bool constant = false;
  bool fb = false;
  FbKind fb_kind = FbKind::kTon;
  bool array = false;
  std::int64_t lo = 0, hi = 0;
  std::int32_t slot = 0;  // kLocalFlag | offset
  Cell value{};           // constants
  const ExternalSymbol* ext = nullptr;  // VAR_EXTERNAL alias
  bool loop_active = false;             // FOR control variable of an enclosing loop
};

struct TypeInfo {
  Type type = Type::kVoid;
  bool untyped = false;  // a plain number literal (or constant arithmetic of them)
  bool ok = false;
};

struct ConstVal {
  Type type = Type::kVoid;
  bool untyped = false;
  Cell v{};
};

// A resolved variable reference.
struct Ref {
  enum Kind { kNone, kScalar, kArrayElem, kFbMember, kExternal, kFbInstance, kArrayWhole } kind =
      kNone;
  Type type = Type::kVoid;
  std::int32_t slot = 0;
  const Local* local = nullptr;
  const ExternalSymbol* ext = nullptr;
  const FbMember* member = nullptr;
};

struct CompileAbort {};  // too many errors

class Compiler {
 public:
  Compiler(const SymbolTable& ext, const CompileOptions& opt, std::vector<Diagnostic>& errors)
      : ext_(ext), opt_(opt), errors_(errors) {}

  std::shared_ptr<CompiledProgram> run(const ProgramAst& ast) {
    auto p = std::make_shared<CompiledProgram>();
    out_ = p.get();
    out_->name = ast.name;
    out_->file = opt_.file;
    const std::size_t errors_before = errors_.size();
    try {
      declare(ast);
      const std::uint64_t body = emit_block(ast.body);
      emit(Op::kRet, ast.pos);
      out_->worst_case = sat_add(body, 1);
      if (out_->worst_case > opt_.instruction_budget)
        error(ast.pos, "program '" + ast.name + "': worst case of " +
                           (out_->worst_case == kSat ? std::string("more than 2^64")
                                                     : std::to_string(out_->worst_case)) +
                           " instructions per scan exceeds the budget of " +
                           std::to_string(opt_.instruction_budget) +
                           " (plc.instruction_budget; FOR loops count every iteration)");
    } catch (const CompileAbort&) {
    }
    out_->max_stack = std::max(1, max_depth_);
    if (errors_.size() != errors_before) return nullptr;
    return p;
  }

 private:
  // ---- errors ----
  void error(Pos p, const std::string& m) {
    errors_.push_back({opt_.file, p.line, p.column, m});
    if (errors_.size() > 200) throw CompileAbort{};
  }

  // ---- declarations ----
  std::int32_t alloc(std::int32_t n, Cell init) {
    const std::int32_t off = out_->locals;
    out_->locals += n;
    for (std::int32_t k = 0; k < n; ++k) out_->locals_init.push_back(init);
    return kLocalFlag | off;
  }
  Cell& init_cell(std::int32_t slot) {
    return out_->locals_init[static_cast<std::size_t>(slot & ~kLocalFlag)];
  }

  void declare(const ProgramAst& ast) {
    for (const VarDecl& d : ast.decls) {
      for (const auto& [raw, pos] : d.names) declare_one(d, raw, pos);
    }
  }

  void declare_one(const VarDecl& d, const std::string& raw, Pos pos) {
    const std::string key = upper(raw);
    if (locals_.count(key) != 0) {
      error(pos, "'" + raw + "' is declared twice (first at line " +
                     std::to_string(locals_[key].pos.line) + ")");
      return;
    }
    if (key == "NC") {
      error(pos, "'NC' is reserved for the NC's status and requests (NC.feed_hold, ...)");
      return;
    }
    const ExternalSymbol* ext = ext_.find(raw);
    Local l;
    l.raw = raw;
    l.pos = pos;
    if (d.section == DeclSection::kExternal) {
      if (ext == nullptr) {
        error(pos, "VAR_EXTERNAL '" + raw + "': " + unknown_text(raw));
        return;
      }
      Type t = Type::kVoid;
      if (d.type.array || !parse_elementary(d.type.name, t)) {
        error(d.type.pos, "VAR_EXTERNAL '" + raw + "': signals are of an elementary type");
        return;
      }
      if (t != ext->type) {
        error(d.type.pos, "type mismatch: VAR_EXTERNAL '" + raw + "' is declared " + type_name(t) +
                              " but the signal is " + type_name(ext->type));
        return;
      }
      if (d.init) error(d.init->pos, "VAR_EXTERNAL '" + raw + "' takes no initial value");
      l.ext = ext;
      l.type = ext->type;
      locals_[key] = l;
      return;
    }
    if (ext != nullptr) {
      error(pos, "'" + raw + "' is already a signal (" + describe(*ext) +
                     "); name the local variable differently, or use VAR_EXTERNAL");
      return;
    }
    FbKind fbk{};
    if (!d.type.array && find_fb(d.type.name, fbk)) {
      if (d.section == DeclSection::kConstant) {
        error(d.type.pos, "a function block instance cannot be CONSTANT");
        return;
      }
      if (d.init) error(d.init->pos, "a function block instance takes no initial value");
      const FbInfo& info = fb_info(fbk);
      l.fb = true;
      l.fb_kind = fbk;
      l.slot = alloc(info.size, int_cell(0));
      for (int m = 0; m < info.size; ++m)
        init_cell(l.slot + m) = int_cell(info.members[static_cast<std::size_t>(m)].init);
      out_->variables.push_back({raw, Type::kVoid, true, fbk, l.slot & ~kLocalFlag, info.size});
      locals_[key] = l;
      return;
    }
    Type t = Type::kVoid;
    if (!parse_elementary(d.type.name, t)) {
      error(d.type.pos, "unknown type '" + d.type.name +
                            "' (BOOL, INT, DINT, REAL, LREAL, TIME, or a standard function block: "
                            "TON, TOF, TP, R_TRIG, F_TRIG, SR, RS, CTU, CTD, CTUD)");
      return;
    }
    l.type = t;
    const Cell zero = is_real(t) ? real_cell(0.0) : int_cell(0);
    if (d.type.array) {
      if (d.section == DeclSection::kConstant) {
        error(d.type.pos, "constant arrays are not part of the ST subset");
        return;
      }
      const auto lo = const_int(*d.type.lo, "array bound");
      const auto hi = const_int(*d.type.hi, "array bound");
      if (!lo || !hi) return;
      if (*hi < *lo || *hi - *lo >= 65536) {
        error(d.type.pos, "array bounds [" + std::to_string(*lo) + ".." + std::to_string(*hi) +
                              "]: need lower <= upper and at most 65536 elements");
        return;
      }
      l.array = true;
      l.lo = *lo;
      l.hi = *hi;
      const auto n = static_cast<std::int32_t>(*hi - *lo + 1);
      l.slot = alloc(n, zero);
      if (d.init) error(d.init->pos, "an array is initialised with [a, b, ...]");
      if (!d.array_init.empty()) {
        if (static_cast<std::int64_t>(d.array_init.size()) > n)
          error(d.array_init.front()->pos, "more initial values than array elements");
        for (std::size_t k = 0; k < d.array_init.size() && static_cast<std::int64_t>(k) < n; ++k) {
          if (auto v = const_value(*d.array_init[k], t)) init_cell(l.slot + static_cast<std::int32_t>(k)) = *v;
        }
      }
      out_->variables.push_back({raw, t, false, FbKind::kTon, l.slot & ~kLocalFlag, n});
      locals_[key] = l;
      return;
    }
    if (!d.array_init.empty())
      error(d.array_init.front()->pos, "'" + raw + "' is not an array");
    Cell v = zero;
    if (d.init) {
      if (auto c = const_value(*d.init, t)) v = *c;
    } else if (d.section == DeclSection::kConstant) {
      error(pos, "the constant '" + raw + "' needs a value (" + raw + " : " + type_name(t) +
                     " := ...;)");
    }
    if (d.section == DeclSection::kConstant) {
      l.constant = true;
      l.value = v;
      locals_[key] = l;
      return;
    }
    l.slot = alloc(1, v);
    out_->variables.push_back({raw, t, false, FbKind::kTon, l.slot & ~kLocalFlag, 1});
    locals_[key] = l;
  }

  // ---- constant evaluation (initial values, bounds, case labels) ----
  std::optional<ConstVal> const_eval(const Expr& e) {
    switch (e.kind) {
      case ExprKind::kLiteral:
        return ConstVal{e.type, e.untyped, e.value};
      case ExprKind::kName: {
        if (e.index || !e.member.empty()) return std::nullopt;
        const auto it = locals_.find(upper(e.name));
        if (it == locals_.end() || !it->second.constant) return std::nullopt;
        return ConstVal{it->second.type, false, it->second.value};
      }
      case ExprKind::kUnary: {
        auto a = const_eval(*e.args[0]);
        if (!a) return std::nullopt;
        if (e.op == "-" && a->type != Type::kBool) {
          if (is_real(a->type)) a->v.r = -a->v.r;
          else a->v.i = -a->v.i;
          return a;
        }
        if (e.op == "NOT" && a->type == Type::kBool) {
          a->v.i = a->v.i != 0 ? 0 : 1;
          return a;
        }
        return std::nullopt;
      }
      case ExprKind::kBinary: {
        auto a = const_eval(*e.args[0]);
        auto b = const_eval(*e.args[1]);
        if (!a || !b) return std::nullopt;
        if (is_int_cell(a->type) && is_int_cell(b->type) && a->type != Type::kBool &&
            b->type != Type::kBool) {
          ConstVal r;
          r.type = a->untyped ? b->type : a->type;
          r.untyped = a->untyped && b->untyped;
          const std::int64_t x = a->v.i, y = b->v.i;
          if (e.op == "+") r.v.i = x + y;
          else if (e.op == "-") r.v.i = x - y;
          else if (e.op == "*") r.v.i = x * y;
          else if (e.op == "/" && y != 0) r.v.i = x / y;
          else if (e.op == "MOD" && y != 0) r.v.i = x % y;
          else return std::nullopt;
          return r;
        }
        if (is_real(a->type) && is_real(b->type)) {
          ConstVal r;
          r.type = a->untyped ? b->type : a->type;
          r.untyped = a->untyped && b->untyped;
          const double x = a->v.r, y = b->v.r;
          if (e.op == "+") r.v.r = x + y;
          else if (e.op == "-") r.v.r = x - y;
          else if (e.op == "*") r.v.r = x * y;
          else if (e.op == "/" && y != 0.0) r.v.r = x / y;
          else return std::nullopt;
          return r;
        }
        return std::nullopt;
      }
      default:
        return std::nullopt;
    }
  }

  std::optional<std::int64_t> const_int(const Expr& e, const char* what) {
    const auto c = const_eval(e);
    if (!c || !is_int_cell(c->type) || c->type == Type::kBool || c->type == Type::kTime) {
      error(e.pos, std::string(what) +
                       " must be a constant integer (a literal or a VAR CONSTANT name)");
      return std::nullopt;
    }
    return c->v.i;
  }

  // A constant of type t (initial values): literals adapt, typed values widen.
  std::optional<Cell> const_value(const Expr& e, Type t) {
    const auto c = const_eval(e);
    if (!c) {
      error(e.pos, "an initial value must be a constant expression");
      return std::nullopt;
    }
    return convert_const(*c, t, e.pos);
  }

  std::optional<Cell> convert_const(const ConstVal& c, Type t, Pos pos) {
    if (c.untyped) {
      if (is_real(c.type)) {
        if (!is_real(t)) {
          error(pos, std::string("type mismatch: a REAL literal where ") + type_name(t) +
                         " is expected");
          return std::nullopt;
        }
        return normalise(t, c.v);
      }
      if (is_real(t)) return normalise(t, real_cell(static_cast<double>(c.v.i)));
      if (!is_integer(t)) {
        error(pos, std::string("type mismatch: an integer literal where ") + type_name(t) +
                       " is expected" + (t == Type::kTime ? " (write T#5s)" : "") +
                       (t == Type::kBool ? " (write TRUE or FALSE)" : ""));
        return std::nullopt;
      }
      if (c.v.i < type_min(t) || c.v.i > type_max(t)) {
        error(pos, std::to_string(c.v.i) + " does not fit " + type_name(t) + " (" +
                       std::to_string(type_min(t)) + " .. " + std::to_string(type_max(t)) + ")");
        return std::nullopt;
      }
      return c.v;
    }
    if (!widens(c.type, t)) {
      error(pos, std::string("type mismatch: ") + type_name(c.type) + " where " + type_name(t) +
                     " is expected");
      return std::nullopt;
    }
    if (is_real(t) && !is_real(c.type)) return normalise(t, real_cell(static_cast<double>(c.v.i)));
    return normalise(t, c.v);
  }

  // ---- names ----
  std::string describe(const ExternalSymbol& s) const {
    return std::string(type_name(s.type)) + " " +
           (s.what.empty() ? (s.access == Access::kRead ? "input" : "signal") : s.what);
  }

  std::string unknown_text(const std::string& raw) const {
    std::string best;
    std::size_t best_d = 3;
    const std::string u = upper(raw);
    auto consider = [&](const std::string& name) {
      const std::size_t d = distance(u, upper(name));
      if (d < best_d) {
        best_d = d;
        best = name;
      }
    };
    for (const auto& s : ext_.all()) consider(s.name);
    for (const auto& [k, l] : locals_) consider(l.raw);
    std::string m = "unknown variable or signal '" + raw + "'";
    if (!best.empty()) m += " (did you mean '" + best + "'?)";
    return m;
  }

  Ref resolve(const Expr& e, bool report) {
    Ref r;
    const std::string key = upper(e.name);
    const auto it = locals_.find(key);
    if (it != locals_.end()) {
      const Local& l = it->second;
      r.local = &l;
      if (l.ext != nullptr) {
        if (e.index || !e.member.empty()) {
          if (report) error(e.pos, "'" + e.name + "' is a signal: no index or member");
          return {};
        }
        r.kind = Ref::kExternal;
        r.ext = l.ext;
        r.type = l.ext->type;
        r.slot = l.ext->slot;
        return r;
      }
      if (l.fb) {
        if (e.index) {
          if (report) error(e.pos, "'" + e.name + "' is not an array");
          return {};
        }
        if (e.member.empty()) {
          r.kind = Ref::kFbInstance;
          return r;
        }
        const FbInfo& info = fb_info(l.fb_kind);
        const std::string mu = upper(e.member);
        for (int m = 0; m < info.size; ++m) {
          const FbMember& mem = info.members[static_cast<std::size_t>(m)];
          if (mem.dir != MemberDir::kState && mu == mem.name) {
            r.kind = Ref::kFbMember;
            r.member = &mem;
            r.type = mem.type;
            r.slot = l.slot + m;
            return r;
          }
        }
        if (report) {
          std::string names;
          for (int m = 0; m < info.size; ++m) {
            const FbMember& mem = info.members[static_cast<std::size_t>(m)];
            if (mem.dir == MemberDir::kState) continue;
            names += names.empty() ? "" : ", ";
            names += mem.name;
          }
          error(e.member_pos, std::string(info.name) + " has no member '" + e.member + "' (" +
                                  names + ")");
        }
        return {};
      }
      if (!e.member.empty()) {
        if (report) error(e.member_pos, "'" + e.name + "' has no members");
        return {};
      }
      r.type = l.type;
      if (l.array) {
        r.kind = e.index ? Ref::kArrayElem : Ref::kArrayWhole;
        r.slot = l.slot;
        return r;
      }
      if (e.index) {
        if (report) error(e.pos, "'" + e.name + "' is not an array");
        return {};
      }
      r.kind = Ref::kScalar;
      r.slot = l.slot;
      return r;
    }
    const std::string full = e.member.empty() ? e.name : e.name + "." + e.member;
    const ExternalSymbol* s = ext_.find(full);
    if (s == nullptr) {
      if (report) {
        if (key == "NC" && !e.member.empty())
          error(e.member_pos, "unknown NC signal 'NC." + e.member + "'" +
                                  suggestion("NC." + e.member));
        else
          error(e.pos, unknown_text(full));
      }
      return {};
    }
    if (e.index) {
      if (report) error(e.pos, "'" + full + "' is a signal, not an array");
      return {};
    }
    r.kind = Ref::kExternal;
    r.ext = s;
    r.type = s->type;
    r.slot = s->slot;
    return r;
  }

  std::string suggestion(const std::string& raw) const {
    std::string best;
    std::size_t best_d = 4;
    for (const auto& s : ext_.all()) {
      const std::size_t d = distance(upper(raw), upper(s.name));
      if (d < best_d) {
        best_d = d;
        best = s.name;
      }
    }
    return best.empty() ? "" : " (did you mean '" + best + "'?)";
  }

  // ---- type inference (no code, no errors) ----
  TypeInfo infer(const Expr& e) {
    switch (e.kind) {
      case ExprKind::kLiteral:
        return {e.type, e.untyped, true};
      case ExprKind::kName: {
        const Ref r = resolve(e, false);
        if (r.kind == Ref::kNone || r.kind == Ref::kFbInstance || r.kind == Ref::kArrayWhole)
          return {};
        if (r.local != nullptr && r.local->constant) return {r.local->type, false, true};
        return {r.type, false, true};
      }
      case ExprKind::kUnary: {
        if (e.op == "NOT") return {Type::kBool, false, true};
        return infer(*e.args[0]);
      }
      case ExprKind::kBinary: {
        const std::string& op = e.op;
        if (op == "AND" || op == "OR" || op == "XOR" || op == "=" || op == "<>" || op == "<" ||
            op == ">" || op == "<=" || op == ">=")
          return {Type::kBool, false, true};
        const TypeInfo a = infer(*e.args[0]);
        const TypeInfo b = infer(*e.args[1]);
        if (!a.ok || !b.ok) return {};
        if (op == "**") return {a.untyped && b.untyped ? Type::kLreal : real_of(a, b), false, true};
        if (a.type == Type::kTime || b.type == Type::kTime) return {Type::kTime, false, true};
        const auto c = common(a, b);
        if (!c) return {};
        return {*c, a.untyped && b.untyped, true};
      }
      case ExprKind::kCall:
        return infer_call(e);
    }
    return {};
  }

  static Type real_of(const TypeInfo& a, const TypeInfo& b) {
    if (a.type == Type::kLreal || b.type == Type::kLreal || a.type == Type::kDint ||
        b.type == Type::kDint)
      return Type::kLreal;
    if ((a.type == Type::kReal && !a.untyped) || (b.type == Type::kReal && !b.untyped))
      return Type::kReal;
    return Type::kLreal;
  }

  // The common type of two operands, or nullopt (a mismatch).
  static std::optional<Type> common(const TypeInfo& a, const TypeInfo& b) {
    if (a.untyped && b.untyped) {
      if (is_real(a.type) || is_real(b.type)) return Type::kLreal;
      return Type::kDint;
    }
    if (a.untyped || b.untyped) {
      const TypeInfo& lit = a.untyped ? a : b;
      const TypeInfo& typed = a.untyped ? b : a;
      if (is_real(lit.type)) {
        if (is_real(typed.type)) return typed.type;
        if (typed.type == Type::kInt) return Type::kReal;
        if (typed.type == Type::kDint) return Type::kLreal;
        return std::nullopt;
      }
      if (is_integer(typed.type) || is_real(typed.type)) return typed.type;
      return std::nullopt;
    }
    if (a.type == b.type) return a.type;
    if (widens(a.type, b.type)) return b.type;
    if (widens(b.type, a.type)) return a.type;
    return std::nullopt;
  }

  // ---- code emission ----
  static int stack_effect(Op op) {
    switch (op) {
      case Op::kPush:
      case Op::kLoad:
        return 1;
      case Op::kStore:
      case Op::kPop:
      case Op::kJz:
      case Op::kJnz:
        return -1;
      case Op::kStoreInd:
      case Op::kLimitI:
      case Op::kLimitR:
      case Op::kSel:
        return -2;
      case Op::kCheckIndex:
      case Op::kLoadInd:
      case Op::kNegI:
      case Op::kAbsI:
      case Op::kWrap16:
      case Op::kWrap32:
      case Op::kNegR:
      case Op::kAbsR:
      case Op::kSqrtR:
      case Op::kF32:
      case Op::kNot:
      case Op::kIntToReal:
      case Op::kRealToInt:
      case Op::kTruncReal:
      case Op::kNonZero:
      case Op::kJmp:
      case Op::kCallFb:
      case Op::kRet:
        return 0;
      default:
        return -1;  // binary operators
    }
  }

  std::size_t emit(Op op, Pos pos, std::int32_t a = 0, Cell imm = {}, std::uint8_t b = 0) {
    Instr in;
    in.op = op;
    in.a = a;
    in.imm = imm;
    in.b = b;
    out_->code.push_back(in);
    out_->lines.push_back(pos.line);
    depth_ += stack_effect(op);
    max_depth_ = std::max(max_depth_, depth_);
    cost_ = sat_add(cost_, op == Op::kCallFb ? kFbCallCost : 1);
    return out_->code.size() - 1;
  }
  void patch(std::size_t at) { out_->code[at].a = static_cast<std::int32_t>(out_->code.size()); }
  void push_int(std::int64_t v, Pos p) { emit(Op::kPush, p, 0, int_cell(v)); }
  void push_real(double v, Pos p) { emit(Op::kPush, p, 0, real_cell(v)); }

  // Converts the value on the stack from `from` to `to` (an implicit widening).
  void widen(Type from, Type to, Pos p) {
    if (from == to) return;
    if (is_real(to) && !is_real(from)) {
      emit(Op::kIntToReal, p);
      if (to == Type::kReal) emit(Op::kF32, p);
    }
    // INT -> DINT and REAL -> LREAL need nothing: the cell already holds the value.
  }

  // Emits e producing a value of type `want` (kVoid: its own type). Returns the type produced
  // (kVoid after an error, which was reported).
  Type emit_expr(const Expr& e, Type want) {
    const TypeInfo ti = infer(e);
    if (ti.ok && ti.untyped) {
      // Constant arithmetic of plain literals: fold.
      if (auto c = const_eval(e)) {
        const Type t = want == Type::kVoid ? ti.type : want;
        const auto v = convert_const(*c, t, e.pos);
        if (!v) return Type::kVoid;
        emit(Op::kPush, e.pos, 0, *v);
        return t;
      }
    }
    // An untyped expression that does not fold (MIN(1, 2) + 3) takes the wanted type.
    const Type ctx = ti.ok && ti.untyped && (is_integer(want) || is_real(want)) ? want : Type::kVoid;
    const Type got = emit_raw(e, ti, ctx);
    if (got == Type::kVoid || want == Type::kVoid || got == want) return got;
    if (!widens(got, want)) {
      error(e.pos, std::string("type mismatch: ") + type_name(got) + " where " + type_name(want) +
                       " is expected" + conversion_hint(got, want));
      return Type::kVoid;
    }
    widen(got, want, e.pos);
    return want;
  }

  static std::string conversion_hint(Type from, Type to) {
    if (from == Type::kVoid || to == Type::kVoid) return "";
    return std::string(" (convert with ") + type_name(from) + "_TO_" + type_name(to) + ")";
  }

  // ctx: the type an untyped expression takes (kVoid: its default, DINT or LREAL).
  Type emit_raw(const Expr& e, const TypeInfo& ti, Type ctx) {
    switch (e.kind) {
      case ExprKind::kLiteral: {
        if (e.untyped) {  // in a typed context it was folded above; alone: DINT / LREAL
          const Type t = ctx != Type::kVoid ? ctx : e.type;
          const auto v = convert_const({e.type, true, e.value}, t, e.pos);
          if (!v) return Type::kVoid;
          emit(Op::kPush, e.pos, 0, *v);
          return t;
        }
        emit(Op::kPush, e.pos, 0, normalise(e.type, e.value));
        return e.type;
      }
      case ExprKind::kName:
        return emit_load(e);
      case ExprKind::kUnary:
        return emit_unary(e, ctx);
      case ExprKind::kBinary:
        return emit_binary(e, ti, ctx);
      case ExprKind::kCall:
        return emit_call(e, ctx);
    }
    return Type::kVoid;
  }

  Type emit_load(const Expr& e) {
    const Ref r = resolve(e, true);
    switch (r.kind) {
      case Ref::kNone:
        return Type::kVoid;
      case Ref::kFbInstance:
        error(e.pos, "'" + e.name + "' is a function block instance, not a value (read one of its "
                                    "outputs, e.g. " + e.name + ".Q)");
        return Type::kVoid;
      case Ref::kArrayWhole:
        error(e.pos, "'" + e.name + "' is an array: index it, e.g. " + e.name + "[i]");
        return Type::kVoid;
      case Ref::kArrayElem:
        if (!emit_index(e, *r.local)) return Type::kVoid;
        emit(Op::kLoadInd, e.pos, r.slot);
        return r.type;
      default:
        if (r.local != nullptr && r.local->constant) {
          emit(Op::kPush, e.pos, 0, r.local->value);
          return r.local->type;
        }
        emit(Op::kLoad, e.pos, r.slot);
        return r.type;
    }
  }

  // Pushes the zero-based element index (checked against the bounds at run time).
  bool emit_index(const Expr& e, const Local& l) {
    const Type it = emit_expr(*e.index, Type::kVoid);
    if (it == Type::kVoid) return false;
    if (!is_integer(it)) {
      error(e.index->pos, std::string("an array index is INT or DINT, not ") + type_name(it));
      return false;
    }
    Cell bounds;
    bounds.i = static_cast<std::int64_t>(
        (static_cast<std::uint64_t>(l.lo) << 32) | (static_cast<std::uint64_t>(l.hi) & 0xFFFFFFFFu));
    emit(Op::kCheckIndex, e.pos, 0, bounds);
    return true;
  }

  Type emit_unary(const Expr& e, Type ctx) {
    if (e.op == "NOT") {
      const Type t = emit_expr(*e.args[0], Type::kVoid);
      if (t == Type::kVoid) return t;
      if (t != Type::kBool) {
        error(e.pos, std::string("NOT takes a BOOL, not ") + type_name(t) +
                         " (bitwise operations are not part of the ST subset)");
        return Type::kVoid;
      }
      emit(Op::kNot, e.pos);
      return Type::kBool;
    }
    const Type t = emit_expr(*e.args[0], ctx);
    if (t == Type::kVoid) return t;
    if (is_real(t)) {
      emit(Op::kNegR, e.pos);
    } else if (is_integer(t) || t == Type::kTime) {
      emit(Op::kNegI, e.pos);
      wrap(t, e.pos);
    } else {
      error(e.pos, std::string("unary '-' takes a number, not ") + type_name(t));
      return Type::kVoid;
    }
    return t;
  }

  void wrap(Type t, Pos p) {
    if (t == Type::kInt) emit(Op::kWrap16, p);
    else if (t == Type::kDint) emit(Op::kWrap32, p);
    else if (t == Type::kReal) emit(Op::kF32, p);
  }

  Type emit_binary(const Expr& e, const TypeInfo& ti, Type ctx) {
    const std::string& op = e.op;
    const Expr& l = *e.args[0];
    const Expr& r = *e.args[1];
    if (op == "AND" || op == "OR" || op == "XOR") {
      const Type a = emit_expr(l, Type::kVoid);
      const Type b = emit_expr(r, Type::kVoid);
      if (a == Type::kVoid || b == Type::kVoid) return Type::kVoid;
      if (a != Type::kBool || b != Type::kBool) {
        error(e.pos, op + " takes BOOL operands, not " + type_name(a) + " and " + type_name(b) +
                         " (bitwise operations are not part of the ST subset)");
        return Type::kVoid;
      }
      emit(op == "AND" ? Op::kAnd : op == "OR" ? Op::kOr : Op::kXor, e.pos);
      return Type::kBool;
    }
    const TypeInfo a = infer(l);
    const TypeInfo b = infer(r);
    if (!a.ok || !b.ok) {
      // Report the unresolved operand's error.
      emit_expr(l, Type::kVoid);
      emit_expr(r, Type::kVoid);
      return Type::kVoid;
    }
    const bool cmp = op == "=" || op == "<>" || op == "<" || op == ">" || op == "<=" || op == ">=";
    // TIME arithmetic: TIME +- TIME, TIME * / integer.
    if (!cmp && (a.type == Type::kTime || b.type == Type::kTime)) {
      if ((op == "+" || op == "-") && a.type == Type::kTime && b.type == Type::kTime) {
        emit_expr(l, Type::kTime);
        emit_expr(r, Type::kTime);
        emit(op == "+" ? Op::kAddI : Op::kSubI, e.pos);
        return Type::kTime;
      }
      if ((op == "*" || op == "/") && a.type == Type::kTime && (is_integer(b.type) || b.untyped)) {
        emit_expr(l, Type::kTime);
        if (emit_expr(r, Type::kDint) == Type::kVoid) return Type::kVoid;
        emit(op == "*" ? Op::kMulI : Op::kDivI, e.pos);
        return Type::kTime;
      }
      if (op == "*" && b.type == Type::kTime && (is_integer(a.type) || a.untyped)) {
        if (emit_expr(l, Type::kDint) == Type::kVoid) return Type::kVoid;
        emit_expr(r, Type::kTime);
        emit(Op::kMulI, e.pos);
        return Type::kTime;
      }
      error(e.pos, std::string("type mismatch: ") + type_name(a.type) + " " + op + " " +
                       type_name(b.type) + " (TIME +/- TIME, TIME * or / an integer)");
      return Type::kVoid;
    }
    if (op == "**") {
      const Type t = ctx != Type::kVoid && is_real(ctx) ? ctx : ti.type;
      if (emit_expr(l, t) == Type::kVoid || emit_expr(r, t) == Type::kVoid) return Type::kVoid;
      emit(Op::kExptR, e.pos);
      wrap(t, e.pos);
      return t;
    }
    auto c = common(a, b);
    if (!c) {
      error(e.pos, std::string("type mismatch: ") + type_name(a.type) + " " + op + " " +
                       type_name(b.type) + conversion_hint(b.type, a.type));
      return Type::kVoid;
    }
    if (!cmp && a.untyped && b.untyped && ctx != Type::kVoid) c = ctx;
    const Type t = *c;
    if (t == Type::kBool && !cmp) {
      error(e.pos, "'" + op + "' takes numbers, not BOOL");
      return Type::kVoid;
    }
    if (t == Type::kBool && op != "=" && op != "<>") {
      error(e.pos, "'" + op + "' compares numbers or times; BOOL has = and <>");
      return Type::kVoid;
    }
    if (emit_expr(l, t) == Type::kVoid || emit_expr(r, t) == Type::kVoid) return Type::kVoid;
    const bool real = is_real(t);
    if (cmp) {
      Op o{};
      if (op == "=") o = real ? Op::kEqR : Op::kEqI;
      else if (op == "<>") o = real ? Op::kNeR : Op::kNeI;
      else if (op == "<") o = real ? Op::kLtR : Op::kLtI;
      else if (op == "<=") o = real ? Op::kLeR : Op::kLeI;
      else if (op == ">") o = real ? Op::kGtR : Op::kGtI;
      else o = real ? Op::kGeR : Op::kGeI;
      emit(o, e.pos);
      return Type::kBool;
    }
    if (op == "MOD") {
      if (real) {
        error(e.pos, "MOD takes integers");
        return Type::kVoid;
      }
      emit(Op::kModI, e.pos);
      wrap(t, e.pos);
      return t;
    }
    Op o{};
    if (op == "+") o = real ? Op::kAddR : Op::kAddI;
    else if (op == "-") o = real ? Op::kSubR : Op::kSubI;
    else if (op == "*") o = real ? Op::kMulR : Op::kMulI;
    else o = real ? Op::kDivR : Op::kDivI;
    emit(o, e.pos);
    wrap(t, e.pos);
    return t;
  }

  // ---- functions ----
  static bool split_conversion(const std::string& u, Type& from, Type& to) {
    const auto p = u.find("_TO_");
    if (p == std::string::npos) return false;
    return parse_elementary(u.substr(0, p), from) && parse_elementary(u.substr(p + 4), to);
  }

  TypeInfo infer_call(const Expr& e) {
    const std::string u = upper(e.name);
    Type from{}, to{};
    if (split_conversion(u, from, to)) return {to, false, true};
    if (u == "TRUNC") return {Type::kDint, false, true};
    if (u == "SQRT") {
      if (e.args.size() == 1) {
        const TypeInfo a = infer(*e.args[0]);
        return {a.type == Type::kReal && !a.untyped ? Type::kReal : Type::kLreal, false, true};
      }
      return {};
    }
    if (u == "ABS" || u == "MOVE") {
      if (e.args.size() != 1) return {};
      return infer(*e.args[0]);
    }
    if (u == "MIN" || u == "MAX" || u == "LIMIT" || u == "SEL") {
      std::size_t first = u == "SEL" ? 1 : 0;
      if (e.args.size() < first + 1) return {};
      TypeInfo acc = infer(*e.args[first]);
      for (std::size_t k = first + 1; k < e.args.size() && acc.ok; ++k) {
        const TypeInfo b = infer(*e.args[k]);
        if (!b.ok) return {};
        if (u == "SEL" && (acc.type == Type::kBool || acc.type == Type::kTime) && b.type == acc.type)
          continue;
        const auto c = common(acc, b);
        if (!c) return {};
        acc = {*c, acc.untyped && b.untyped, true};
      }
      return acc;
    }
    return {};
  }

  Type emit_call(const Expr& e, Type ctx) {
    const std::string u = upper(e.name);
    auto want_args = [&](std::size_t n) {
      if (e.args.size() == n) return true;
      error(e.pos, e.name + " takes " + std::to_string(n) + " argument" + (n == 1 ? "" : "s") +
                       ", not " + std::to_string(e.args.size()));
      return false;
    };
    Type from{}, to{};
    if (split_conversion(u, from, to)) {
      if (!want_args(1)) return Type::kVoid;
      if (emit_expr(*e.args[0], from) == Type::kVoid) return Type::kVoid;
      convert(from, to, e.pos);
      return to;
    }
    if (u == "TRUNC") {
      if (!want_args(1)) return Type::kVoid;
      const TypeInfo a = infer(*e.args[0]);
      if (emit_expr(*e.args[0], a.untyped || !a.ok ? Type::kLreal : a.type) == Type::kVoid)
        return Type::kVoid;
      if (!is_real(a.untyped || !a.ok ? Type::kLreal : a.type)) {
        error(e.pos, "TRUNC takes a REAL or LREAL");
        return Type::kVoid;
      }
      emit(Op::kTruncReal, e.pos);
      emit(Op::kWrap32, e.pos);
      return Type::kDint;
    }
    if (u == "SQRT") {
      if (!want_args(1)) return Type::kVoid;
      const TypeInfo t = infer_call(e);
      if (!t.ok) {
        emit_expr(*e.args[0], Type::kVoid);
        return Type::kVoid;
      }
      if (emit_expr(*e.args[0], t.type) == Type::kVoid) return Type::kVoid;
      emit(Op::kSqrtR, e.pos);
      wrap(t.type, e.pos);
      return t.type;
    }
    if (u == "ABS" || u == "MOVE") {
      if (!want_args(1)) return Type::kVoid;
      const Type t = emit_expr(*e.args[0], ctx);
      if (t == Type::kVoid || u == "MOVE") return t;
      if (is_real(t)) {
        emit(Op::kAbsR, e.pos);
      } else if (is_integer(t) || t == Type::kTime) {
        emit(Op::kAbsI, e.pos);
        wrap(t, e.pos);
      } else {
        error(e.pos, "ABS takes a number");
        return Type::kVoid;
      }
      return t;
    }
    if (u == "MIN" || u == "MAX" || u == "LIMIT" || u == "SEL") {
      if (u == "LIMIT" && !want_args(3)) return Type::kVoid;
      if (u == "SEL" && !want_args(3)) return Type::kVoid;
      if ((u == "MIN" || u == "MAX") && e.args.size() < 2) {
        error(e.pos, e.name + " takes at least 2 arguments");
        return Type::kVoid;
      }
      const TypeInfo t = infer_call(e);
      if (!t.ok) {
        for (const auto& a : e.args) emit_expr(*a, Type::kVoid);
        error(e.pos, "type mismatch between the arguments of " + e.name);
        return Type::kVoid;
      }
      const Type ty = t.untyped ? (ctx != Type::kVoid ? ctx : is_real(t.type) ? Type::kLreal : Type::kDint)
                                : t.type;
      if (u == "SEL") {
        if (emit_expr(*e.args[0], Type::kBool) == Type::kVoid) return Type::kVoid;
        if (emit_expr(*e.args[1], ty) == Type::kVoid || emit_expr(*e.args[2], ty) == Type::kVoid)
          return Type::kVoid;
        emit(Op::kSel, e.pos);
        return ty;
      }
      if (ty == Type::kBool) {
        error(e.pos, e.name + " takes numbers or times");
        return Type::kVoid;
      }
      const bool real = is_real(ty);
      for (std::size_t k = 0; k < e.args.size(); ++k) {
        if (emit_expr(*e.args[k], ty) == Type::kVoid) return Type::kVoid;
        if (u != "LIMIT" && k > 0)
          emit(u == "MIN" ? (real ? Op::kMinR : Op::kMinI) : (real ? Op::kMaxR : Op::kMaxI), e.pos);
      }
      if (u == "LIMIT") emit(real ? Op::kLimitR : Op::kLimitI, e.pos);
      return ty;
    }
    FbKind k{};
    if (find_fb(u, k)) {
      error(e.pos, e.name + " is a function block type: declare an instance (t : " + e.name +
                       ";) and call it as a statement: t(...);");
      return Type::kVoid;
    }
    const auto it = locals_.find(u);
    if (it != locals_.end() && it->second.fb) {
      error(e.pos, "a function block call is a statement of its own: " + e.name +
                       "(...); then read " + e.name + ".Q");
      return Type::kVoid;
    }
    error(e.pos, "unknown function '" + e.name +
                     "' (the subset has ABS, MIN, MAX, LIMIT, SEL, SQRT, TRUNC, MOVE and the "
                     "X_TO_Y conversions)");
    return Type::kVoid;
  }

  // Explicit conversion X_TO_Y of the value on the stack. TIME <-> numbers in milliseconds.
  void convert(Type from, Type to, Pos p) {
    if (from == to) return;
    if (to == Type::kBool) {
      if (is_real(from)) {
        push_real(0.0, p);
        emit(Op::kNeR, p);
      } else {
        emit(Op::kNonZero, p);
      }
      return;
    }
    if (from == Type::kTime) {  // ns -> ms
      if (is_real(to)) {
        emit(Op::kIntToReal, p);
        push_real(1e6, p);
        emit(Op::kDivR, p);
        wrap(to, p);
      } else {
        push_int(1000000, p);
        emit(Op::kDivI, p);
        wrap(to, p);
      }
      return;
    }
    if (to == Type::kTime) {  // ms -> ns
      if (is_real(from)) {
        push_real(1e6, p);
        emit(Op::kMulR, p);
        emit(Op::kRealToInt, p);
      } else {
        push_int(1000000, p);
        emit(Op::kMulI, p);
      }
      return;
    }
    if (is_real(from) && is_real(to)) {
      wrap(to, p);
      return;
    }
    if (is_real(from)) {
      emit(Op::kRealToInt, p);
      wrap(to, p);
      return;
    }
    if (is_real(to)) {
      emit(Op::kIntToReal, p);
      wrap(to, p);
      return;
    }
    wrap(to, p);  // between BOOL, INT, DINT
  }

  // ---- statements ----
  std::uint64_t emit_block(const StmtList& list) {
    std::uint64_t total = 0;
    for (const Stmt& s : list) total = sat_add(total, emit_stmt(s));
    return total;
  }

  std::uint64_t emit_stmt(const Stmt& s) {
    const std::uint64_t c0 = cost_;
    switch (s.kind) {
      case StmtKind::kEmpty:
        return 0;
      case StmtKind::kAssign:
        emit_assign(*s.target, *s.value);
        depth_ = 0;
        return cost_ - c0;
      case StmtKind::kFbCall:
        emit_fb_call(s);
        depth_ = 0;
        return cost_ - c0;
      case StmtKind::kReturn:
        emit(Op::kRet, s.pos);
        return cost_ - c0;
      case StmtKind::kExit:
        if (exits_.empty()) {
          error(s.pos, "EXIT outside a FOR loop");
          return 0;
        }
        exits_.back().push_back(emit(Op::kJmp, s.pos));
        return cost_ - c0;
      case StmtKind::kIf:
        return emit_if(s);
      case StmtKind::kCase:
        return emit_case(s);
      case StmtKind::kFor:
        return emit_for(s);
    }
    return 0;
  }

  // Resolves an assignment target; false (error reported) if it cannot be written.
  bool writable(const Expr& target, Ref& r) {
    r = resolve(target, true);
    switch (r.kind) {
      case Ref::kNone:
        return false;
      case Ref::kFbInstance:
        error(target.pos, "'" + target.name + "' is a function block instance: call it, " +
                              target.name + "(IN := ...);");
        return false;
      case Ref::kArrayWhole:
        error(target.pos, "assign array elements one by one: " + target.name + "[i] := ...");
        return false;
      case Ref::kFbMember:
        error(target.pos, "'" + target.name + "." + target.member +
                              "' belongs to the function block: inputs are given in its call (" +
                              target.name + "(" + r.member->name + " := ...);), outputs are its "
                              "results");
        return false;
      case Ref::kExternal:
        if (r.ext->access == Access::kRead) {
          error(target.pos, "assignment to an input: '" + r.ext->name + "' is " +
                                (r.ext->what.empty() ? "an input" : r.ext->what));
          return false;
        }
        note_write(r.ext->slot, target.pos);
        return true;
      default:
        if (r.local != nullptr && r.local->constant) {
          error(target.pos, "'" + target.name + "' is a constant");
          return false;
        }
        if (r.local != nullptr && r.local->loop_active) {
          error(target.pos, "the FOR control variable '" + target.name +
                                "' may not be assigned inside its loop");
          return false;
        }
        return true;
    }
  }

  void note_write(std::int32_t slot, Pos pos) {
    for (const auto& w : out_->writes)
      if (w.slot == slot) return;
    out_->writes.push_back({slot, pos});
  }

  void emit_assign(const Expr& target, const Expr& value) {
    Ref r;
    if (!writable(target, r)) {
      emit_expr(value, Type::kVoid);  // still report errors inside the value
      return;
    }
    if (r.kind == Ref::kArrayElem) {
      if (!emit_index(target, *r.local)) return;
      if (emit_expr(value, r.type) == Type::kVoid) return;
      emit(Op::kStoreInd, target.pos, r.slot);
      return;
    }
    if (emit_expr(value, r.type) == Type::kVoid) return;
    emit(Op::kStore, target.pos, r.slot);
  }

  void emit_fb_call(const Stmt& s) {
    const auto it = locals_.find(upper(s.instance));
    if (it == locals_.end() || !it->second.fb) {
      FbKind k{};
      if (it == locals_.end() && find_fb(upper(s.instance), k))
        error(s.pos, s.instance + " is a function block type: declare an instance in VAR (t : " +
                         s.instance + ";) and call t(...)");
      else if (it == locals_.end())
        error(s.pos, unknown_text(s.instance));
      else
        error(s.pos, "'" + s.instance + "' is not a function block instance");
      for (const auto& p : s.params)
        if (!p.output) emit_expr(*p.value, Type::kVoid);
      return;
    }
    const Local& inst = it->second;
    const FbInfo& info = fb_info(inst.fb_kind);
    std::vector<std::string> seen;
    auto member_of = [&](const FbParam& p) -> int {
      for (int m = 0; m < info.size; ++m) {
        const FbMember& mem = info.members[static_cast<std::size_t>(m)];
        if (mem.dir != MemberDir::kState && p.name == mem.name) return m;
      }
      return -1;
    };
    for (const FbParam& p : s.params) {
      if (std::find(seen.begin(), seen.end(), p.name) != seen.end()) {
        error(p.pos, "parameter " + p.name + " given twice");
        continue;
      }
      seen.push_back(p.name);
      const int m = member_of(p);
      if (m < 0) {
        error(p.pos, std::string(info.name) + " has no parameter '" + p.name + "'");
        if (!p.output) emit_expr(*p.value, Type::kVoid);
        continue;
      }
      const FbMember& mem = info.members[static_cast<std::size_t>(m)];
      if (p.output) continue;  // after the call
      if (mem.dir != MemberDir::kIn) {
        error(p.pos, std::string(info.name) + "." + mem.name + " is an output: write " + mem.name +
                         " => variable");
        continue;
      }
      if (emit_expr(*p.value, mem.type) == Type::kVoid) continue;
      emit(Op::kStore, p.pos, inst.slot + m);
    }
    emit(Op::kCallFb, s.pos, inst.slot, {}, static_cast<std::uint8_t>(inst.fb_kind));
    for (const FbParam& p : s.params) {
      if (!p.output) continue;
      const int m = member_of(p);
      if (m < 0) continue;
      const FbMember& mem = info.members[static_cast<std::size_t>(m)];
      if (mem.dir != MemberDir::kOut) {
        error(p.pos, std::string(info.name) + "." + mem.name + " is an input: write " + mem.name +
                         " := value");
        continue;
      }
      Ref r;
      if (!writable(*p.value, r)) continue;
      if (!widens(mem.type, r.type)) {
        error(p.pos, std::string("type mismatch: ") + info.name + "." + mem.name + " is " +
                         type_name(mem.type) + ", '" + p.value->name + "' is " + type_name(r.type));
        continue;
      }
      if (r.kind == Ref::kArrayElem) {
        if (!emit_index(*p.value, *r.local)) continue;
        emit(Op::kLoad, p.pos, inst.slot + m);
        widen(mem.type, r.type, p.pos);
        emit(Op::kStoreInd, p.pos, r.slot);
      } else {
        emit(Op::kLoad, p.pos, inst.slot + m);
        widen(mem.type, r.type, p.pos);
        emit(Op::kStore, p.pos, r.slot);
      }
    }
  }

  bool emit_condition(const Expr& c) {
    const Type t = emit_expr(c, Type::kVoid);
    if (t == Type::kVoid) return false;
    if (t != Type::kBool) {
      error(c.pos, std::string("a condition is BOOL, not ") + type_name(t));
      return false;
    }
    return true;
  }

  std::uint64_t emit_if(const Stmt& s) {
    std::uint64_t conds = 0, worst_body = 0;
    std::vector<std::size_t> to_end;
    for (std::size_t k = 0; k < s.conds.size(); ++k) {
      const std::uint64_t c0 = cost_;
      emit_condition(*s.conds[k]);
      depth_ = 1;  // keep the stack bookkeeping right after an error
      const std::size_t jz = emit(Op::kJz, s.conds[k]->pos);
      conds = sat_add(conds, cost_ - c0);
      std::uint64_t body = emit_block(s.bodies[k]);
      const bool more = k + 1 < s.conds.size() || s.has_else;
      if (more) {
        to_end.push_back(emit(Op::kJmp, s.pos));
        body = sat_add(body, 1);
      }
      worst_body = std::max(worst_body, body);
      patch(jz);
    }
    if (s.has_else) worst_body = std::max(worst_body, emit_block(s.bodies.back()));
    for (std::size_t j : to_end) patch(j);
    return sat_add(conds, worst_body);
  }

  std::uint64_t emit_case(const Stmt& s) {
    const std::uint64_t c0 = cost_;
    const TypeInfo sel = infer(*s.value);
    Type t = sel.ok ? (sel.untyped ? Type::kDint : sel.type) : Type::kVoid;
    if (sel.ok && !is_integer(t)) {
      error(s.value->pos, std::string("a CASE selector is INT or DINT, not ") + type_name(t));
      t = Type::kVoid;
    }
    const std::int32_t tmp = alloc(1, int_cell(0));
    if (emit_expr(*s.value, t) != Type::kVoid) emit(Op::kStore, s.value->pos, tmp);
    depth_ = 0;
    std::uint64_t tests = cost_ - c0;
    std::uint64_t worst_body = 0;
    std::vector<std::size_t> to_end;
    std::vector<std::pair<std::int64_t, std::int64_t>> seen;
    for (const CaseArm& arm : s.arms) {
      const std::uint64_t a0 = cost_;
      bool first = true;
      for (const CaseLabel& l : arm.labels) {
        const auto lo = const_int(*l.lo, "a CASE label");
        const auto hi = l.hi ? const_int(*l.hi, "a CASE label") : lo;
        if (!lo || !hi) continue;
        if (*hi < *lo) error(l.lo->pos, "CASE range " + std::to_string(*lo) + ".." +
                                            std::to_string(*hi) + " is empty");
        for (const auto& [slo, shi] : seen)
          if (*lo <= shi && slo <= *hi)
            error(l.lo->pos, "CASE label " + std::to_string(*lo) +
                                 (*hi != *lo ? ".." + std::to_string(*hi) : "") +
                                 " overlaps an earlier one");
        seen.emplace_back(*lo, *hi);
        if (*lo == *hi) {
          emit(Op::kLoad, l.lo->pos, tmp);
          push_int(*lo, l.lo->pos);
          emit(Op::kEqI, l.lo->pos);
        } else {
          emit(Op::kLoad, l.lo->pos, tmp);
          push_int(*lo, l.lo->pos);
          emit(Op::kGeI, l.lo->pos);
          emit(Op::kLoad, l.lo->pos, tmp);
          push_int(*hi, l.lo->pos);
          emit(Op::kLeI, l.lo->pos);
          emit(Op::kAnd, l.lo->pos);
        }
        if (!first) emit(Op::kOr, l.lo->pos);
        first = false;
      }
      if (first) push_int(0, arm.pos);
      const std::size_t jz = emit(Op::kJz, arm.pos);
      depth_ = 0;
      tests = sat_add(tests, cost_ - a0);
      std::uint64_t body = emit_block(arm.body);
      to_end.push_back(emit(Op::kJmp, arm.pos));
      body = sat_add(body, 1);
      worst_body = std::max(worst_body, body);
      patch(jz);
    }
    worst_body = std::max(worst_body, emit_block(s.else_body));
    for (std::size_t j : to_end) patch(j);
    return sat_add(tests, worst_body);
  }

  std::uint64_t emit_for(const Stmt& s) {
    const Expr& var = *s.target;
    const auto it = locals_.find(upper(var.name));
    if (it == locals_.end() || it->second.fb || it->second.array || it->second.constant ||
        it->second.ext != nullptr || !is_integer(it->second.type)) {
      if (it == locals_.end())
        error(var.pos, "FOR control variable '" + var.name + "' is not declared (declare it in "
                                                             "VAR as INT or DINT)");
      else
        error(var.pos, "the FOR control variable '" + var.name + "' must be a local INT or DINT");
      emit_block(s.body);
      return 0;
    }
    Local& lv = it->second;
    if (lv.loop_active) {
      error(var.pos, "'" + var.name + "' already controls an enclosing FOR loop");
      return 0;
    }
    const auto from = const_int(*s.value, "a FOR start");
    const auto to = const_int(*s.to, "a FOR end");
    const auto by = s.by ? const_int(*s.by, "a FOR step") : std::optional<std::int64_t>(1);
    if (!from || !to || !by) {
      emit_block(s.body);
      return 0;
    }
    if (*by == 0) {
      error(s.by->pos, "a FOR step of 0 never ends");
      return 0;
    }
    const Type t = lv.type;
    for (const auto& [v, e] : {std::pair{*from, s.value.get()}, std::pair{*to, s.to.get()}}) {
      if (v < type_min(t) || v > type_max(t))
        error(e->pos, std::to_string(v) + " does not fit the " + type_name(t) +
                          " control variable '" + var.name + "'");
    }
    // The increment after the last iteration must not wrap (it would loop for ever).
    if (*to + *by > type_max(t) || *to + *by < type_min(t)) {
      error(s.to->pos, "FOR end " + std::to_string(*to) + " with step " + std::to_string(*by) +
                           " overflows " + type_name(t) + ": use a wider control variable");
      return 0;
    }
    const std::int64_t span = *by > 0 ? *to - *from : *from - *to;
    const std::uint64_t iterations =
        span < 0 ? 0 : static_cast<std::uint64_t>(span / (*by > 0 ? *by : -*by)) + 1;

    const std::uint64_t c0 = cost_;
    push_int(*from, s.pos);
    emit(Op::kStore, s.pos, lv.slot);
    const std::uint64_t init = cost_ - c0;
    const std::size_t top = out_->code.size();
    const std::uint64_t t0 = cost_;
    emit(Op::kLoad, s.pos, lv.slot);
    push_int(*to, s.pos);
    emit(*by > 0 ? Op::kGtI : Op::kLtI, s.pos);
    const std::size_t jexit = emit(Op::kJnz, s.pos);
    const std::uint64_t test = cost_ - t0;
    lv.loop_active = true;
    exits_.emplace_back();
    const std::uint64_t body = emit_block(s.body);
    lv.loop_active = false;
    const std::uint64_t i0 = cost_;
    emit(Op::kLoad, s.pos, lv.slot);
    push_int(*by, s.pos);
    emit(Op::kAddI, s.pos);
    wrap(t, s.pos);
    emit(Op::kStore, s.pos, lv.slot);
    emit(Op::kJmp, s.pos, static_cast<std::int32_t>(top));
    const std::uint64_t incr = cost_ - i0;
    patch(jexit);
    for (std::size_t j : exits_.back()) patch(j);
    exits_.pop_back();
    const std::uint64_t per_iter = sat_add(sat_add(test, body), incr);
    return sat_add(sat_add(init, sat_mul(iterations, per_iter)), test);
  }

  const SymbolTable& ext_;
  const CompileOptions& opt_;
  std::vector<Diagnostic>& errors_;
  CompiledProgram* out_ = nullptr;
  std::unordered_map<std::string, Local> locals_;
  int depth_ = 0;
  int max_depth_ = 0;
  std::uint64_t cost_ = 0;
  std::vector<std::vector<std::size_t>> exits_;
};

}  // namespace

CompileResult compile_program(std::string_view source, const SymbolTable& externals,
                              const CompileOptions& opt) {
  CompileResult r;
  const ProgramAst ast = parse_program(source, opt.file, r.errors);
  if (ast.name.empty()) return r;  // not even a PROGRAM header
  // Type errors are reported even with syntax errors elsewhere (all at once); the parser's
  // recovery dropped the bad statements.
  Compiler c(externals, opt, r.errors);
  auto p = c.run(ast);
  if (r.errors.empty()) r.program = std::move(p);
  std::stable_sort(r.errors.begin(), r.errors.end(), [](const Diagnostic& a, const Diagnostic& b) {
    return a.line != b.line ? a.line < b.line : a.column < b.column;
  });
  return r;
}

}  // namespace contour::control::plc
