// Reading a line (LinuxCNC 2.9 rules): normalisation, words, [expressions], #parameters, O-words,
// and the per-line checks done before execution. Values are evaluated while reading, as LinuxCNC
// does: a parameter set on a line is not visible to reads on the same line.
#include <algorithm>
#include <charconv>
#include <functional>
#include <cmath>
#include <numbers>

#include "control/gcode_interp.hpp"

namespace contour::control::gcode_detail {

namespace {
constexpr long double kPi = 3.141592653589793238462643383279502884L;  // LinuxCNC's M_PIl
constexpr double kToleranceEqual = 0.0001;  // LinuxCNC TOLERANCE_EQUAL (EQ/NE)

enum Op {
  kNoOp = 0,
  kDivide,
  kModulo,
  kPower,
  kTimes,
  kAnd,
  kXor,
  kMinus,
  kOr,
  kPlus,
  kRightBracket,
  kLt,
  kEq,
  kNe,
  kLe,
  kGe,
  kGt
};

int precedence(int op) {
  switch (op) {
    case kRightBracket: return 1;
    case kAnd: case kXor: case kOr: return 2;
    case kLt: case kEq: case kNe: case kLe: case kGe: case kGt: return 3;
    case kMinus: case kPlus: return 4;
    case kNoOp: case kDivide: case kModulo: case kTimes: return 5;
    case kPower: return 6;
    default: return 0;
  }
}

bool is_digit(char c) { return c >= '0' && c <= '9'; }

// Modal group of a G code x10, -1 if unknown (LinuxCNC's _gees table, reduced to the codes
// LinuxCNC knows; unsupported ones are refused in check_g_codes with their reason).
int g_group(int g10) {
  switch (g10) {
    case 0: case 10: case 20: case 30: case 330: case 331: case 382: case 383: case 384: case 385:
    case 50: case 51: case 52: case 700: case 710: case 711: case 712: case 720: case 721:
    case 722: case 730: case 740: case 760: case 800: case 810: case 820: case 830: case 840:
    case 850: case 860: case 870: case 880: case 890:
      return 1;
    case 40: case 53: case 100: case 280: case 281: case 300: case 301: case 520: case 530:
    case 920:
      return 0;
    case 921: case 922: case 923: return 16;
    case 170: case 171: case 180: case 181: case 190: case 191: return 2;
    case 900: case 910: return 3;
    case 901: case 911: return 4;
    case 930: case 940: case 950: return 5;
    case 200: case 210: return 6;
    case 400: case 410: case 411: case 420: case 421: return 7;
    case 430: case 431: case 432: case 490: return 8;
    case 980: case 990: return 10;
    case 540: case 550: case 560: case 570: case 580: case 590: case 591: case 592: case 593:
      return 12;
    case 610: case 611: case 640: return 13;
    case 960: case 970: return 14;
    case 70: case 80: return 15;
    default: return -1;
  }
}

// Modal group of an M code (LinuxCNC's _ems), -1 if unknown.
int m_group(int m) {
  if (m >= 100 && m <= 199) return 10;
  switch (m) {
    case 0: case 1: case 2: case 30: case 60: case 99: return 4;
    case 3: case 4: case 5: case 19: case 70: case 71: case 72: case 73: return 7;
    case 6: case 61: return 6;
    case 7: case 8: case 9: return 8;
    case 48: case 49: case 50: case 51: case 52: case 53: return 9;
    case 62: case 63: case 64: case 65: case 66: case 67: case 68: return 5;
    default: return -1;
  }
}
}  // namespace

void LineBlock::reset() {
  w = {};
  g_modes.fill(-1);
  g_cols.fill(0);
  m_modes.fill(-1);
  m_cols.fill(0);
  m_count = 0;
  user_m = false;
  p_number = -1.0;
  q_number = -1.0;
  l_number = -1;
  h_number = -1;
  t_number = 0;
  d_number = 0.0;
  radius = {};
  theta = {};
  motion_to_be = -1;
  comment.clear();
  comment_col = 0;
  o_type = OType::kNone;
  o_present = false;
  o_name.clear();
  o_col = 0;
  param_cnt = 0;
  params.fill(0.0);
  param_sets.clear();
  named_sets.clear();
}

int Interpreter::col_at(int i) const {
  if (i >= 0 && static_cast<std::size_t>(i) < cols_.size()) return cols_[static_cast<std::size_t>(i)];
  return static_cast<int>(raw_.size()) + 1;
}

// LinuxCNC's close_and_downcase: spaces, tabs and CRs removed and letters lower-cased outside
// comments; text after ';' kept as is; nested and unclosed comments are errors.
void Interpreter::normalize(std::string_view raw) {
  raw_.assign(raw);
  while (!raw_.empty() && (raw_.back() == ' ' || raw_.back() == '\t' || raw_.back() == '\r' ||
                           raw_.back() == '\n' || raw_.back() == '\v' || raw_.back() == '\f'))
    raw_.pop_back();
  line_.clear();
  cols_.clear();
  bool comment = false;
  bool semicomment = false;
  int comment_start = 0;
  for (std::size_t m = 0; m < raw_.size(); ++m) {
    const char c = raw_[m];
    const int col = static_cast<int>(m) + 1;
    if (c == ';' && !comment) semicomment = true;
    if (semicomment) {
      line_ += c;
      cols_.push_back(col);
      continue;
    }
    if (comment) {
      line_ += c;
      cols_.push_back(col);
      if (c == ')') comment = false;
      else if (c == '(') fail(col, "nested comment");
    } else if (c == ' ' || c == '\t' || c == '\r') {
    } else if (c == '\n') {
      fail(col, "newline inside a line");
    } else if (c >= 'A' && c <= 'Z') {
      line_ += static_cast<char>(c + 32);
      cols_.push_back(col);
    } else if (c == '(') {
      comment = true;
      comment_start = col;
      line_ += c;
      cols_.push_back(col);
    } else {
      line_ += c;
      cols_.push_back(col);
    }
  }
  if (comment) fail(comment_start, "unterminated comment");
}

void Interpreter::read_items() {
  blk_.reset();
  int i = 0;
  const int n = static_cast<int>(line_.size());
  if (i < n && line_[0] == '/') ++i;
  if (i < n && line_[static_cast<std::size_t>(i)] == 'n') read_n_number(i);
  if (i < n && line_[static_cast<std::size_t>(i)] == 'o') {
    read_o(i);
    if (skipping_) return;
    while (i < n) {
      const char c = line_[static_cast<std::size_t>(i)];
      if (c == ';') break;
      if (c == '(') {
        const int start = i;
        while (i < n && line_[static_cast<std::size_t>(i)] != ')') ++i;
        ++i;
        blk_.comment = line_.substr(static_cast<std::size_t>(start + 1),
                                    static_cast<std::size_t>(i - start - 2));
        blk_.comment_col = col_at(start);
        continue;
      }
      fail(col_at(i), "unexpected text after the O-word command (only comments may follow)");
    }
    return;
  }
  if (skipping_) return;
  while (i < n) read_one_item(i);
}

int Interpreter::read_n_number(int& i) {
  const int start = i;
  ++i;
  const auto digits = [&] {
    const int b = i;
    while (i < static_cast<int>(line_.size()) && is_digit(line_[static_cast<std::size_t>(i)])) ++i;
    if (i == b) fail(col_at(start), "N word needs an unsigned integer line number");
    return std::string_view(line_).substr(static_cast<std::size_t>(b), static_cast<std::size_t>(i - b));
  };
  const std::string_view d = digits();
  if (i < static_cast<int>(line_.size()) && line_[static_cast<std::size_t>(i)] == '.') {
    ++i;  // fractional line numbers (N10.5) are accepted and ignored, as LinuxCNC does
    digits();
  }
  int v = 0;
  std::from_chars(d.data(), d.data() + d.size(), v);
  return v;
}

void Interpreter::read_one_item(int& i) {
  const char c = line_[static_cast<std::size_t>(i)];
  const int col = col_at(i);
  const auto letter_word = [&](char l, bool once) -> WordVal& {
    WordVal& w = blk_[l];
    if (once && w.set) fail(col, std::string("word '") + static_cast<char>(l - 32) + "' appears twice on the line");
    ++i;
    w.v = read_real_value(i);
    w.set = true;
    w.col = col;
    return w;
  };
  switch (c) {
    case '#': read_parameter_setting(i); return;
    case '(': {
      const int start = i;
      while (line_[static_cast<std::size_t>(i)] != ')') ++i;
      ++i;
      blk_.comment = line_.substr(static_cast<std::size_t>(start + 1),
                                  static_cast<std::size_t>(i - start - 2));
      blk_.comment_col = col_at(start);
      return;
    }
    case ';': i = static_cast<int>(line_.size()); return;
    case '@':
    case '^': {
      WordVal& w = c == '@' ? blk_.radius : blk_.theta;
      if (w.set) fail(col, std::string("polar word '") + c + "' appears twice on the line");
      ++i;
      w.v = read_real_value(i);
      w.set = true;
      w.col = col;
      return;
    }
    case 'g': read_g(i); return;
    case 'm': read_m(i); return;
    case 'f': {
      const WordVal& w = letter_word('f', true);
      if (w.v < 0.0) fail(col, "negative feed rate (F)");
      return;
    }
    case 's': {
      const WordVal& w = letter_word('s', true);
      if (w.v < 0.0) fail(col, "negative spindle speed (S)");
      return;
    }
    case 'x': case 'y': case 'z': case 'i': case 'j': case 'k': case 'r':
      letter_word(c, true);
      return;
    case 'd': letter_word('d', true); blk_.d_number = blk_['d'].v; return;
    case 'p': {
      if (blk_.p_number > -1.0) fail(col, "word 'P' appears twice on the line");
      ++i;
      blk_.p_number = read_real_value(i);
      blk_['p'].set = true;
      blk_['p'].v = blk_.p_number;
      blk_['p'].col = col;
      return;
    }
    case 'q': {
      if (blk_.q_number > -1.0) fail(col, "word 'Q' appears twice on the line");
      ++i;
      blk_.q_number = read_real_value(i);
      blk_['q'].set = true;
      blk_['q'].v = blk_.q_number;
      blk_['q'].col = col;
      return;
    }
    case 'h': {
      if (blk_['h'].set) fail(col, "word 'H' appears twice on the line");
      ++i;
      const int v = read_integer_value(i);
      if (v < -1) fail(col, "negative H word");
      blk_.h_number = v;
      blk_['h'] = {true, static_cast<double>(v), col};
      return;
    }
    case 'l': {
      if (blk_.l_number > -1) fail(col, "word 'L' appears twice on the line");
      ++i;
      const int v = read_integer_value(i);
      if (v < 0) fail(col, "negative L word");
      blk_.l_number = v;
      blk_['l'] = {true, static_cast<double>(v), col};
      return;
    }
    case 't': {
      if (blk_['t'].set) fail(col, "word 'T' appears twice on the line");
      ++i;
      const int v = read_integer_value(i);
      if (v < 0) fail(col, "negative tool number (T)");
      blk_.t_number = v;
      blk_['t'] = {true, static_cast<double>(v), col};
      return;
    }
    case 'a': case 'b': case 'c': case 'u': case 'v': case 'w':
      fail(col, std::string("axis ") + static_cast<char>(c - 32) +
                    " is not configured (contourd has X Y Z)");
    case 'e':
      fail(col, "word 'E' is not supported (it belongs to lathe threading and analog I/O codes)");
    case '$':
      fail(col, "'$' spindle selection is not supported (contourd has one spindle)");
    case 'n':
      fail(col, "N word (line number) must be at the start of the line");
    case 'o':
      fail(col, "O word must be at the start of the line (after an optional N word)");
    default:
      break;
  }
  if (static_cast<unsigned char>(c) < ' ' || static_cast<unsigned char>(c) > 'z') {
    const unsigned u = static_cast<unsigned char>(c);  // "\\%03o"
    const std::string oct{'\\', static_cast<char>('0' + ((u >> 6) & 7)), static_cast<char>('0' + ((u >> 3) & 7)),
                          static_cast<char>('0' + (u & 7))};
    fail(col, std::string("bad character '") + oct + "'");
  }
  fail(col, std::string("unexpected character '") + c + "'");
}

void Interpreter::read_g(int& i) {
  const int col = col_at(i);
  ++i;
  double v = read_real_value(i) * 10.0;
  if (!(v > -1e6 && v < 1e6)) fail(col, "G code out of range");
  int value = static_cast<int>(std::floor(v));
  if (v - value > 0.999) value = static_cast<int>(std::ceil(v));
  else if (v - value > 0.001) fail(col, "G code out of range (not of the form NN.N)");
  if (value > 999) fail(col, "G code out of range");
  if (value < 0) fail(col, "negative G code");
  const int mode = g_group(value);
  if (mode < 0) {
    std::string n = "G" + std::to_string(value / 10);
    if (value % 10) n += "." + std::to_string(value % 10);
    fail(col, "unknown G code " + n);
  }
  const auto m = static_cast<std::size_t>(mode);
  // G80 together with another motion code is ignored (LinuxCNC).
  if (value == g::k80 && blk_.g_modes[m] != -1) return;
  if (blk_.g_modes[m] != g::k80 && blk_.g_modes[m] != -1)
    fail(col, "two G codes of the same modal group on one line");
  blk_.g_modes[m] = value;
  blk_.g_cols[m] = col;
}

void Interpreter::read_m(int& i) {
  const int col = col_at(i);
  ++i;
  const int value = read_integer_value(i);
  if (value < 0) fail(col, "negative M code");
  if (value > 199) fail(col, "M code greater than 199: M" + std::to_string(value));
  const int mode = m_group(value);
  if (mode < 0) fail(col, "unknown M code M" + std::to_string(value));
  const auto m = static_cast<std::size_t>(mode);
  if (blk_.m_modes[m] != -1) fail(col, "two M codes of the same modal group on one line");
  blk_.m_modes[m] = value;
  blk_.m_cols[m] = col;
  ++blk_.m_count;
  if (value >= 100) blk_.user_m = true;
}

double Interpreter::read_real_value(int& i) {
  const int n = static_cast<int>(line_.size());
  if (i >= n) fail(col_at(i), "missing value (nothing after the word)");
  const char c = line_[static_cast<std::size_t>(i)];
  const char c1 = i + 1 < n ? line_[static_cast<std::size_t>(i + 1)] : '\0';
  const int col = col_at(i);
  double v = 0.0;
  if (c == '[') {
    v = read_real_expression(i);
  } else if (c == '#') {
    v = read_parameter(i, false);
  } else if (c == '+' && c1 != '\0' && !is_digit(c1) && c1 != '.') {
    ++i;
    v = read_real_value(i);
  } else if (c == '-' && c1 != '\0' && !is_digit(c1) && c1 != '.') {
    ++i;
    v = -read_real_value(i);
  } else if (c >= 'a' && c <= 'z') {
    v = read_unary(i);
  } else {
    v = read_real_number(i);
  }
  if (std::isnan(v)) fail(col, "calculation resulted in 'not a number'");
  if (std::isinf(v)) fail(col, "calculation resulted in infinity");
  return v;
}

double Interpreter::read_real_number(int& i) {
  const int n = static_cast<int>(line_.size());
  const int start = i;
  int j = i;
  while (j < n && (line_[static_cast<std::size_t>(j)] == '+' || line_[static_cast<std::size_t>(j)] == '-')) ++j;
  const int signs = j - i;
  while (j < n && (is_digit(line_[static_cast<std::size_t>(j)]) || line_[static_cast<std::size_t>(j)] == '.')) ++j;
  const std::string_view tok = std::string_view(line_).substr(static_cast<std::size_t>(i), static_cast<std::size_t>(j - i));
  i = j;
  double v = 0.0;
  bool ok = signs <= 1 && tok.size() > static_cast<std::size_t>(signs);
  if (ok) {
    const char* b = tok.data() + signs;
    const char* e = tok.data() + tok.size();
    const auto r = std::from_chars(b, e, v, std::chars_format::fixed);
    ok = r.ec == std::errc() && r.ptr == e;
    if (ok && tok[0] == '-') v = -v;
  }
  if (!ok) fail(col_at(start), "bad number format '" + std::string(tok) + "'");
  return v;
}

int Interpreter::read_integer_value(int& i) {
  const int col = col_at(i);
  const double v = read_real_value(i);
  if (!(std::abs(v) < 2e9)) fail(col, "integer value out of range");
  int k = static_cast<int>(std::floor(v));
  if (v - k > 0.9999) k = static_cast<int>(std::ceil(v));
  else if (v - k > 0.0001) fail(col, "non-integer value where an integer is required");
  return k;
}

int Interpreter::read_operation(int& i) {
  const int n = static_cast<int>(line_.size());
  const auto at = [&](int k) { return k < n ? line_[static_cast<std::size_t>(k)] : '\0'; };
  const int col = col_at(i);
  const char c = at(i);
  ++i;
  const auto two = [&](char a, char b, int op) {
    if (at(i) == a && at(i + 1) == b) {
      i += 2;
      return op;
    }
    return -1;
  };
  int op = -1;
  switch (c) {
    case '+': return kPlus;
    case '-': return kMinus;
    case '/': return kDivide;
    case '*':
      if (at(i) == '*') {
        ++i;
        return kPower;
      }
      return kTimes;
    case ']': return kRightBracket;
    case 'a': op = two('n', 'd', kAnd); break;
    case 'm': op = two('o', 'd', kModulo); break;
    case 'x': op = two('o', 'r', kXor); break;
    case 'o':
      if (at(i) == 'r') {
        ++i;
        return kOr;
      }
      break;
    case 'e':
      if (at(i) == 'q') {
        ++i;
        return kEq;
      }
      break;
    case 'n':
      if (at(i) == 'e') {
        ++i;
        return kNe;
      }
      break;
    case 'g':
      if (at(i) == 'e') { ++i; return kGe; }
      if (at(i) == 't') { ++i; return kGt; }
      break;
    case 'l':
      if (at(i) == 'e') { ++i; return kLe; }
      if (at(i) == 't') { ++i; return kLt; }
      break;
    case '\0':
      fail(col, "unclosed expression (missing ']')");
    default:
      break;
  }
  if (op < 0) fail(col, std::string("unknown operation in expression at '") + c + "'");
  return op;
}

namespace {
double apply_binary(double l, int op, double r, const std::function<void(const std::string&)>& err) {
  double d = 0.0;
  switch (op) {
    case kDivide:
      if (r == 0.0) err("division by zero");
      return l / r;
    case kModulo: {
      double v = std::fmod(l, r);
      if (v < 0.0) v += std::abs(r);
      return v;
    }
    case kPower:
      if (l < 0.0 && std::floor(r) != r) err("negative number raised to a non-integer power");
      return std::pow(l, r);
    case kTimes: return l * r;
    case kAnd: return (l == 0.0 || r == 0.0) ? 0.0 : 1.0;
    case kXor: return ((l == 0.0) != (r == 0.0)) ? 1.0 : 0.0;
    case kMinus: return l - r;
    case kOr: return (l != 0.0 || r != 0.0) ? 1.0 : 0.0;
    case kPlus: return l + r;
    case kLt: return l < r ? 1.0 : 0.0;
    case kEq: d = std::abs(l - r); return d < kToleranceEqual ? 1.0 : 0.0;
    case kNe: d = std::abs(l - r); return d >= kToleranceEqual ? 1.0 : 0.0;
    case kLe: return l <= r ? 1.0 : 0.0;
    case kGe: return l >= r ? 1.0 : 0.0;
    case kGt: return l > r ? 1.0 : 0.0;
    default: return 0.0;
  }
}
}  // namespace

// Operator-precedence evaluation with LinuxCNC's stack algorithm (left associative at equal
// precedence; ** binds tightest, then * / MOD, + -, comparisons, AND OR XOR).
double Interpreter::read_real_expression(int& i) {
  const int col = col_at(i);
  ++i;  // '['
  std::array<double, 8> values{};
  std::array<int, 8> ops{};
  values[0] = read_real_value(i);
  ops[0] = read_operation(i);
  std::size_t k = 1;
  const auto err = [&](const std::string& m) { fail(col, m); };
  while (ops[0] != kRightBracket) {
    values[k] = read_real_value(i);
    ops[k] = read_operation(i);
    if (precedence(ops[k]) > precedence(ops[k - 1])) {
      ++k;
      if (k >= values.size()) fail(col, "expression too deeply nested");
    } else {
      while (precedence(ops[k]) <= precedence(ops[k - 1])) {
        values[k - 1] = apply_binary(values[k - 1], ops[k - 1], values[k], err);
        ops[k - 1] = ops[k];
        if (k > 1 && precedence(ops[k - 1]) <= precedence(ops[k - 2])) {
          --k;
        } else {
          break;
        }
      }
    }
  }
  return values[0];
}

double Interpreter::read_unary(int& i) {
  const int n = static_cast<int>(line_.size());
  const int col = col_at(i);
  const std::string_view rest = std::string_view(line_).substr(static_cast<std::size_t>(i));
  static constexpr std::string_view kNames[] = {"abs", "acos", "asin", "atan", "cos", "exp",
                                                "exists", "fix", "fup", "ln", "round", "sin",
                                                "sqrt", "tan"};
  std::string_view name;
  // LinuxCNC matches by first letter then the rest: "exists" before "exp" is a prefix issue only
  // for "exp": check the longer name first.
  for (std::string_view cand : {std::string_view("exists"), std::string_view("acos"),
                                std::string_view("asin"), std::string_view("atan"),
                                std::string_view("abs"), std::string_view("cos"),
                                std::string_view("exp"), std::string_view("fix"),
                                std::string_view("fup"), std::string_view("ln"),
                                std::string_view("round"), std::string_view("sin"),
                                std::string_view("sqrt"), std::string_view("tan")}) {
    if (rest.substr(0, cand.size()) == cand) {
      name = cand;
      break;
    }
  }
  (void)kNames;
  if (name.empty())
    fail(col, std::string("unknown word or function starting with '") + line_[static_cast<std::size_t>(i)] + "'");
  i += static_cast<int>(name.size());
  if (i >= n || line_[static_cast<std::size_t>(i)] != '[')
    fail(col_at(i), "'[' missing after " + std::string(name));
  if (name == "exists") {
    ++i;
    if (i >= n || line_[static_cast<std::size_t>(i)] != '#') fail(col_at(i), "EXISTS needs [#parameter]");
    const double v = read_parameter(i, true);
    if (i >= n || line_[static_cast<std::size_t>(i)] != ']') fail(col_at(i), "']' missing after EXISTS[#...");
    ++i;
    return v;
  }
  double v = read_real_expression(i);
  if (name == "atan") {
    if (i >= n || line_[static_cast<std::size_t>(i)] != '/') fail(col_at(i), "'/' missing after the first ATAN argument");
    ++i;
    if (i >= n || line_[static_cast<std::size_t>(i)] != '[') fail(col_at(i), "'[' missing after ATAN[...]/");
    const double x = read_real_expression(i);
    return static_cast<double>((std::atan2(v, x) * 180.0) / kPi);
  }
  if (name == "abs") return std::abs(v);
  if (name == "acos") {
    if (v < -1.0 || v > 1.0) fail(col, "ACOS argument out of range [-1, 1]");
    return static_cast<double>((std::acos(v) * 180.0) / kPi);
  }
  if (name == "asin") {
    if (v < -1.0 || v > 1.0) fail(col, "ASIN argument out of range [-1, 1]");
    return static_cast<double>((std::asin(v) * 180.0) / kPi);
  }
  if (name == "cos") return static_cast<double>(std::cos((v * kPi) / 180.0L));
  if (name == "exp") return std::exp(v);
  if (name == "fix") return std::floor(v);
  if (name == "fup") return std::ceil(v);
  if (name == "ln") {
    if (v <= 0.0) fail(col, "LN of zero or a negative number");
    return std::log(v);
  }
  if (name == "round") {
    if (!(std::abs(v) < 2e9)) fail(col, "ROUND argument out of range");
    return static_cast<double>(static_cast<int>(v + (v < 0.0 ? -0.5 : 0.5)));
  }
  if (name == "sin") return static_cast<double>(std::sin((v * kPi) / 180.0L));
  if (name == "sqrt") {
    if (v < 0.0) fail(col, "SQRT of a negative number");
    return std::sqrt(v);
  }
  return static_cast<double>(std::tan((v * kPi) / 180.0L));
}

std::string Interpreter::read_name(int& i) {
  const int col = col_at(i);
  ++i;  // '<'
  const auto close = line_.find('>', static_cast<std::size_t>(i));
  if (close == std::string::npos) fail(col, "name not terminated by '>'");
  std::string name = line_.substr(static_cast<std::size_t>(i), close - static_cast<std::size_t>(i));
  i = static_cast<int>(close) + 1;
  return name;
}

double Interpreter::read_parameter(int& i, bool check_exists) {
  const int col = col_at(i);
  ++i;  // '#'
  if (i < static_cast<int>(line_.size()) && line_[static_cast<std::size_t>(i)] == '<') {
    const std::string name = read_name(i);
    double v = 0.0;
    const bool exists = find_named(name, v);
    if (check_exists) return exists ? 1.0 : 0.0;
    if (exists) return v;
    if (defining_sub_) return 0.0;  // names need not exist while a subroutine is being defined
    fail(col, "named parameter #<" + name + "> not defined");
  }
  const int index = read_integer_value(i);
  if (check_exists) return (index >= 1 && index < kParameterCount) ? 1.0 : 0.0;
  return param_get(index, col);
}

double Interpreter::param_get(int index, int col) const {
  if (index < 1 || index >= kParameterCount)
    fail(col, "parameter number " + std::to_string(index) + " out of range 1.." +
                  std::to_string(kParameterCount - 1));
  if (index >= 5420 && index <= 5428 && comp_side_ != CompSide::kOff)
    fail(col, "cannot read the current position (#5420-#5428) with cutter radius compensation on");
  return params_[static_cast<std::size_t>(index)];
}

void Interpreter::read_parameter_setting(int& i) {
  const int col = col_at(i);
  ++i;  // '#'
  const int n = static_cast<int>(line_.size());
  if (i < n && line_[static_cast<std::size_t>(i)] == '<') {
    const std::string name = read_name(i);
    add_named(name);
    if (i >= n || line_[static_cast<std::size_t>(i)] != '=') fail(col_at(i), "'=' missing in parameter setting");
    ++i;
    const double v = read_real_value(i);
    blk_.named_sets.emplace_back(name, v);
    return;
  }
  const int index = read_integer_value(i);
  if (index < 1 || index >= kParameterCount)
    fail(col, "parameter number " + std::to_string(index) + " out of range");
  if ((index >= 5400 && index <= 5413) || (index >= 5420 && index <= 5428))
    fail(col, "parameter #" + std::to_string(index) + " is read-only");
  if (i >= n || line_[static_cast<std::size_t>(i)] != '=') fail(col_at(i), "'=' missing in parameter setting");
  ++i;
  const double v = read_real_value(i);
  blk_.param_sets.emplace_back(index, v);
}

void Interpreter::read_o(int& i) {
  const int n = static_cast<int>(line_.size());
  const int col = col_at(i);
  blk_.o_present = true;
  blk_.o_col = col;
  ++i;
  std::string name;
  if (i < n && line_[static_cast<std::size_t>(i)] == '<') {
    name = read_name(i);
  } else {
    name = std::to_string(read_integer_value(i));
  }
  const std::string_view rest = std::string_view(line_).substr(static_cast<std::size_t>(std::min(i, n)));
  struct Kw {
    std::string_view text;
    OType type;
  };
  static constexpr Kw kWords[] = {{"sub", OType::kSub},         {"endsub", OType::kEndsub},
                                  {"call", OType::kCall},       {"do", OType::kDo},
                                  {"while", OType::kWhile},     {"repeat", OType::kRepeat},
                                  {"if", OType::kIf},           {"elseif", OType::kElseif},
                                  {"else", OType::kElse},       {"endif", OType::kEndif},
                                  {"break", OType::kBreak},     {"continue", OType::kContinue},
                                  {"endwhile", OType::kEndwhile}, {"endrepeat", OType::kEndrepeat},
                                  {"return", OType::kReturn}};
  OType type = OType::kNone;
  for (const auto& k : kWords) {
    if (rest.substr(0, k.text.size()) == k.text) {
      type = k.type;
      i += static_cast<int>(k.text.size());
      break;
    }
  }
  if (type == OType::kNone) {
    if (rest.empty() || rest[0] == '(' || rest[0] == ';')
      fail(col, "Fanuc-style O" + name + " program numbers are not supported (use o<name> sub)");
    fail(col, "unknown command after O-word (sub, endsub, call, do, while, endwhile, repeat, "
              "endrepeat, if, elseif, else, endif, break, continue, return)");
  }
  blk_.o_type = type;
  // Names: sub/endsub/call/return are global; the others are local to the subroutine.
  if (type == OType::kSub || type == OType::kEndsub || type == OType::kCall || type == OType::kReturn) {
    blk_.o_name = name;
  } else {
    std::string scope;
    if (frames_.size() > 1) scope = frames_.back().sub_name;
    else if (defining_sub_) scope = sub_name_;
    blk_.o_name = scope + "#" + name;
  }
  const auto at = [&](int k) { return k < n ? line_[static_cast<std::size_t>(k)] : '\0'; };
  switch (type) {
    case OType::kSub:
      if (defining_sub_) fail(col, "nested subroutine definition (o<...> sub inside a sub)");
      break;
    case OType::kEndsub:
    case OType::kReturn:
      if (skipping_ && skipping_o_ != blk_.o_name) return;
      if (at(i) == '[') {
        return_value_ = read_real_expression(i);
        value_returned_ = true;
      } else {
        return_value_ = 0.0;
        value_returned_ = false;
      }
      break;
    default:
      if (defining_sub_) {
        blk_.o_type = OType::kNone;  // no evaluation while a definition is read
        return;
      }
      if (type == OType::kCall) {
        if (skipping_) {
          blk_.o_type = OType::kNone;
          return;
        }
        int cnt = 0;
        while (at(i) == '[' || at(i) == '(') {
          if (at(i) == '(') {
            while (i < n && line_[static_cast<std::size_t>(i)] != ')') ++i;
            ++i;
            continue;
          }
          if (cnt >= kSubParams) fail(col_at(i), "too many subroutine arguments (at most 30)");
          blk_.params[static_cast<std::size_t>(cnt++)] = read_real_expression(i);
        }
        blk_.param_cnt = cnt;
      } else if (type == OType::kWhile || type == OType::kRepeat || type == OType::kIf ||
                 type == OType::kElseif) {
        if (skipping_ && skipping_o_ != blk_.o_name) return;
        if (at(i) != '[') {
          const char* w = type == OType::kWhile ? "while" : type == OType::kRepeat ? "repeat"
                          : type == OType::kIf ? "if" : "elseif";
          fail(col_at(i), std::string("'[' missing after '") + w + "'");
        }
        test_value_ = read_real_expression(i);
      }
      break;
  }
}

// LinuxCNC's enhance_block: which motion this line makes, and the axis-word rules.
void Interpreter::enhance_block() {
  const bool polar = blk_.radius.set || blk_.theta.set;
  if (polar) {
    if (plane_ != 1) fail(blk_.radius.set ? blk_.radius.col : blk_.theta.col,
                          "polar coordinates (@ ^) only in the G17 plane");
    if (blk_['x'].set) fail(blk_['x'].col, "X word together with polar coordinates");
    if (blk_['y'].set) fail(blk_['y'].col, "Y word together with polar coordinates");
  }
  const bool axis = blk_['x'].set || blk_['y'].set || blk_['z'].set;
  const bool ijk = blk_['i'].set || blk_['j'].set || blk_['k'].set;
  const int mode0 = blk_.g_modes[gm::kModal0];
  const int mode1 = blk_.g_modes[gm::kMotion];
  const bool covets = mode0 == g::k10 || mode0 == g::k28 || mode0 == g::k30 || mode0 == g::k52 ||
                      mode0 == g::k92;
  const int c1 = blk_.g_cols[gm::kMotion];
  const int c0 = blk_.g_cols[gm::kModal0];
  if (mode1 != -1) {
    if (mode1 == g::k80) {
      if ((polar || axis) && !covets) fail(c1, "axis words with G80 (no motion mode to use them)");
      if (polar && mode0 == g::k92) fail(c0, "polar coordinates can only be used for motion");
      if (!axis && (mode0 == g::k52 || mode0 == g::k92)) fail(c0, "G52/G92 without axis words");
    } else {
      if (covets) fail(c0, "two G codes on the line both use the axis words");
      if (!axis && !polar && mode1 != g::k0 && mode1 != g::k1 && mode1 != g::k2 && mode1 != g::k3)
        fail(c1, "all axis words missing with a canned cycle");
    }
    blk_.motion_to_be = mode1;
  } else if (covets) {
    if (polar && mode0 == g::k92) fail(c0, "polar coordinates can only be used for motion");
    if (!axis && (mode0 == g::k52 || mode0 == g::k92)) fail(c0, "G52/G92 without axis words");
  } else if (axis || polar) {
    const int tlo = blk_.g_modes[gm::kToolOffset];
    if ((motion_mode_ == -1 || motion_mode_ == g::k80) && tlo != g::k43_1 && tlo != g::k43_2) {
      int col = 1;
      for (char l : {'x', 'y', 'z'})
        if (blk_[l].set) {
          col = blk_[l].col;
          break;
        }
      if (polar) col = blk_.radius.set ? blk_.radius.col : blk_.theta.col;
      fail(col, "axis words without a motion mode (G0/G1/G2/G3 or a canned cycle) to use them");
    }
    if (tlo != g::k43_1) blk_.motion_to_be = motion_mode_;
  } else if (ijk && (motion_mode_ == g::k2 || motion_mode_ == g::k3)) {
    blk_.motion_to_be = motion_mode_;
  }
  if (polar && blk_.motion_to_be == -1)
    fail(blk_.radius.set ? blk_.radius.col : blk_.theta.col, "polar coordinates can only be used for motion");
}

void Interpreter::check_items() {
  check_g_codes();
  if (blk_.m_count > 4) fail(blk_.m_cols[4] ? blk_.m_cols[4] : 1, "too many M codes on one line (at most 4)");
  check_other_codes();
}

namespace {
std::string g_text(int g10) {
  std::string n = "G" + std::to_string(g10 / 10);
  if (g10 % 10) n += "." + std::to_string(g10 % 10);
  return n;
}
}  // namespace

// Codes LinuxCNC knows that contourd refuses (control/GCODE.md gives the reasons), then
// LinuxCNC's group 0 checks.
void Interpreter::check_g_codes() {
  for (std::size_t grp = 0; grp < blk_.g_modes.size(); ++grp) {
    const int code = blk_.g_modes[grp];
    if (code < 0) continue;
    const int col = blk_.g_cols[grp];
    const std::string n = g_text(code);
    switch (code) {
      case 330: case 331:
        fail(col, n + " (spindle-synchronised motion) is not supported: contourd has no spindle encoder sync");
      case 760: fail(col, "G76 (threading cycle) is not supported: it needs spindle-synchronised motion");
      case 50: case 51: case 52: case 53:
        fail(col, n + " (spline) is not supported: program lines and arcs");
      case 382: case 383: case 384: case 385:
        fail(col, n + " (probing) is not supported: contourd has no probe input in programs");
      case 70: case 80:
        fail(col, n + " (lathe diameter/radius mode) is not supported: contourd is a mill");
      case 700: case 710: case 711: case 712: case 720: case 721: case 722:
        fail(col, n + " (lathe roughing cycle) is not supported: contourd is a mill");
      case 740: case 840:
        fail(col, n + " (tapping cycle) is not supported: it needs spindle-synchronised motion");
      case 860: case 870: case 880:
        fail(col, n + " (boring cycle with spindle stop/orient or manual step) is not supported");
      case 930: fail(col, "G93 (inverse time feed) is not supported: use G94 (units per minute)");
      case 950: fail(col, "G95 (feed per revolution) is not supported: use G94 (units per minute)");
      case 960: fail(col, "G96 (constant surface speed) is not supported: use G97 (RPM)");
      case 171: case 181: case 191:
        fail(col, n + " (UVW plane) is not supported: contourd has X Y Z");
      default: break;
    }
  }
  const int mode0 = blk_.g_modes[gm::kModal0];
  const int mode1 = blk_.g_modes[gm::kMotion];
  const int c0 = blk_.g_cols[gm::kModal0];
  if (mode0 == g::k4) {
    if (blk_.p_number == -1.0) fail(c0, "G4 needs P (dwell seconds)");
    if (mode1 == g::k2 || mode1 == g::k3) fail(c0, "G4 not allowed with G2 or G3 (both use P)");
  } else if (mode0 == g::k10) {
    const int p = blk_.p_number >= 0 ? static_cast<int>(blk_.p_number + 0.5) : static_cast<int>(blk_.p_number - 0.5);
    const int l = blk_.l_number;
    if (l == 0) fail(c0, "G10 L0 (reload tool table) is not supported: the daemon owns the tool table");
    if (l != 2 && l != 1 && l != 20 && l != 10 && l != 11) fail(c0, "G10 needs L1, L2, L10, L11 or L20");
    if ((blk_.p_number + 0.0001) - p > 0.0002) fail(c0, "G10 P value is not an integer");
    if ((l == 2 || l == 20) && (p < 0 || p > 9)) fail(c0, "G10 L" + std::to_string(l) + " P out of range 0..9");
    if ((l == 1 || l == 10 || l == 11) && p < 1) fail(c0, "G10 L" + std::to_string(l) + " P (tool number) out of range");
  } else if (mode0 == g::k53) {
    if (blk_.motion_to_be != g::k0 && blk_.motion_to_be != g::k1) fail(c0, "G53 needs G0 or G1");
    const int dm = blk_.g_modes[gm::kDistance];
    if (dm == g::k91 || (dm != g::k90 && !absolute_)) fail(c0, "G53 is not allowed with G91 (incremental)");
  }
}

void Interpreter::check_other_codes() {
  const int motion = blk_.motion_to_be;
  const bool cycle = motion == g::k73 || (motion >= g::k81 && motion <= g::k89);
  const int cc = blk_.g_modes[gm::kCutterComp];
  const int tlo = blk_.g_modes[gm::kToolOffset];
  const int m0 = blk_.g_modes[gm::kModal0];
  // M codes contourd refuses (LinuxCNC knows them).
  for (std::size_t grp = 0; grp < blk_.m_modes.size(); ++grp) {
    const int m = blk_.m_modes[grp];
    const int col = blk_.m_cols[grp];
    switch (m) {
      case 19: fail(col, "M19 (spindle orientation) is not supported");
      case 48: case 49: case 50: case 51: case 52: case 53:
        fail(col, "M" + std::to_string(m) + " (override/feed-hold control from the program) is not supported: overrides are the operator's");
      case 60: fail(col, "M60 (pallet change) is not supported");
      case 62: case 63: case 64: case 65: case 66: case 67: case 68:
        fail(col, "M" + std::to_string(m) + " (digital/analog I/O) is not supported: use a user M-code (M100-M199)");
      case 70: case 71: case 72: case 73:
        fail(col, "M" + std::to_string(m) + " (save/restore modal state) is not supported");
      case 99: fail(col, "M99 (Fanuc-style subprogram return) is not supported: use o<name> sub/endsub");
      default: break;
    }
  }
  if (blk_.user_m) return;  // user M-codes take P and Q (LinuxCNC bypasses the checks)
  const auto bad = [&](char l, const std::string& m) { fail(blk_[l].col, m); };
  if (blk_['d'].set && cc != g::k41 && cc != g::k42 && cc != g::k41_1 && cc != g::k42_1)
    bad('d', "D word with no G41, G41.1, G42 or G42.1 to use it");
  if (blk_['h'].set && tlo != g::k43 && tlo != g::k43_2) bad('h', "H word with no G43 or G43.2 to use it");
  if (blk_['i'].set && motion != g::k2 && motion != g::k3 && m0 != g::k10)
    bad('i', "I word with no G2, G3 or G10 to use it");
  if (blk_['j'].set && motion != g::k2 && motion != g::k3 && m0 != g::k10)
    bad('j', "J word with no G2, G3 or G10 to use it");
  if (blk_['k'].set && motion != g::k2 && motion != g::k3) bad('k', "K word with no G2 or G3 to use it");
  if (blk_.l_number != -1 && !cycle && m0 != g::k10 && cc != g::k41 && cc != g::k41_1 &&
      cc != g::k42 && cc != g::k42_1)
    bad('l', "L word with no G10, cutter compensation or canned cycle to use it");
  if (blk_['p'].set) {
    if (m0 != g::k10 && m0 != g::k4 && blk_.g_modes[gm::kControl] != g::k64 && motion != g::k82 &&
        motion != g::k89 && motion != g::k2 && motion != g::k3)
      bad('p', "P word with no G2, G3, G4, G10, G64, G82 or G89 to use it");
    const int pv = static_cast<int>(std::nearbyint(std::clamp(blk_.p_number, -2e9, 2e9)));
    if ((motion == g::k2 || motion == g::k3) && std::abs(pv - blk_.p_number) > 0.001)
      bad('p', "P value (turns) is not an integer with G2/G3");
    if ((motion == g::k2 || motion == g::k3) && pv < 1) bad('p', "P value (turns) must be 1 or more with G2/G3");
  }
  if (blk_.q_number != -1.0 && motion != g::k83 && motion != g::k73 && m0 != g::k10 &&
      blk_.g_modes[gm::kControl] != g::k64 && blk_.m_modes[6] != 61)
    bad('q', "Q word with no G10, G64, G73, G83 or M61 to use it");
  if (blk_['r'].set && motion != g::k2 && motion != g::k3 && !cycle && cc != g::k41_1 &&
      cc != g::k42_1 && m0 != g::k10)
    bad('r', "R word with no G2, G3, G10 or canned cycle to use it");
}

// ---- named parameters

void Interpreter::add_named(const std::string& name) {
  double v = 0.0;
  if (find_named(name, v)) return;
  const std::size_t level = name[0] == '_' ? 0 : frames_.size() - 1;
  frames_[level].locals[name] = NamedParam{};
}

bool Interpreter::find_named(const std::string& name, double& value) const {
  const std::size_t level = (!name.empty() && name[0] == '_') ? 0 : frames_.size() - 1;
  const auto& m = frames_[level].locals;
  const auto it = m.find(name);
  if (it == m.end()) {
    value = 0.0;
    return false;
  }
  value = it->second.lookup >= 0 ? lookup_predefined(it->second.lookup) : it->second.value;
  return true;
}

void Interpreter::store_named(const std::string& name, double value, int col) {
  const std::size_t level = name[0] == '_' ? 0 : frames_.size() - 1;
  auto& m = frames_[level].locals;
  const auto it = m.find(name);
  if (it == m.end()) fail(col, "cannot assign #<" + name + ">");
  if (it->second.readonly) fail(col, "cannot assign to read-only parameter #<" + name + ">");
  it->second.value = value;
}

namespace {
enum Predef {
  kLine, kMotionMode, kPlane, kCcomp, kMetric, kImperial, kAbsolute, kIncremental, kInverseTime,
  kUnitsPerMinute, kUnitsPerRev, kCoordSystem, kToolOffset, kRetractRPlane, kRetractOldZ,
  kSpindleRpmMode, kSpindleCssMode, kIjkAbsoluteMode, kLatheDiameterMode, kLatheRadiusMode,
  kSpindleOn, kSpindleCw, kMist, kFlood, kSpeedOverride, kFeedOverride, kAdaptiveFeed, kFeedHold,
  kFeed, kRpm, kCurrentTool, kCurrentPocket, kSelectedPocket, kSelectedTool, kX, kY, kZ, kA, kB,
  kC, kU, kV, kW, kAbsX, kAbsY, kAbsZ, kAbsA, kAbsB, kAbsC, kValue, kValueReturned, kTask,
  kCallLevel, kRemapLevel
};
}  // namespace

void Interpreter::init_named_parameters() {
  auto& g = frames_.front().locals;
  const auto ro = [&](const char* n, double v) { g[n] = NamedParam{v, true, -1}; };
  const auto lk = [&](const char* n, int which) { g[n] = NamedParam{0.0, true, which}; };
  ro("_vmajor", 2.9);
  ro("_vminor", 0.0);
  ro("_metric_machine", 1.0);
  lk("_line", kLine); lk("_motion_mode", kMotionMode); lk("_plane", kPlane); lk("_ccomp", kCcomp);
  lk("_metric", kMetric); lk("_imperial", kImperial); lk("_absolute", kAbsolute);
  lk("_incremental", kIncremental); lk("_inverse_time", kInverseTime);
  lk("_units_per_minute", kUnitsPerMinute); lk("_units_per_rev", kUnitsPerRev);
  lk("_coord_system", kCoordSystem); lk("_tool_offset", kToolOffset);
  lk("_retract_r_plane", kRetractRPlane); lk("_retract_old_z", kRetractOldZ);
  lk("_spindle_rpm_mode", kSpindleRpmMode); lk("_spindle_css_mode", kSpindleCssMode);
  lk("_ijk_absolute_mode", kIjkAbsoluteMode); lk("_lathe_diameter_mode", kLatheDiameterMode);
  lk("_lathe_radius_mode", kLatheRadiusMode); lk("_spindle_on", kSpindleOn);
  lk("_spindle_cw", kSpindleCw); lk("_mist", kMist); lk("_flood", kFlood);
  lk("_speed_override", kSpeedOverride); lk("_feed_override", kFeedOverride);
  lk("_adaptive_feed", kAdaptiveFeed); lk("_feed_hold", kFeedHold); lk("_feed", kFeed);
  lk("_rpm", kRpm); lk("_current_tool", kCurrentTool); lk("_current_pocket", kCurrentPocket);
  lk("_selected_pocket", kSelectedPocket); lk("_selected_tool", kSelectedTool);
  lk("_x", kX); lk("_y", kY); lk("_z", kZ); lk("_a", kA); lk("_b", kB); lk("_c", kC); lk("_u", kU);
  lk("_v", kV); lk("_w", kW); lk("_abs_x", kAbsX); lk("_abs_y", kAbsY); lk("_abs_z", kAbsZ);
  lk("_abs_a", kAbsA); lk("_abs_b", kAbsB); lk("_abs_c", kAbsC); lk("_value", kValue);
  lk("_value_returned", kValueReturned); lk("_task", kTask); lk("_call_level", kCallLevel);
  lk("_remap_level", kRemapLevel);
}

double Interpreter::lookup_predefined(int which) const {
  switch (which) {
    case kLine: return sequence_;
    case kMotionMode: return motion_mode_;
    case kPlane: return plane_ == 1 ? 170 : plane_ == 3 ? 180 : 190;
    case kCcomp: return comp_side_ == CompSide::kRight ? 420 : comp_side_ == CompSide::kLeft ? 410 : 400;
    case kMetric: return units_ == Units::kMm;
    case kImperial: return units_ == Units::kInch;
    case kAbsolute: return absolute_;
    case kIncremental: return !absolute_;
    case kInverseTime: return 0.0;
    case kUnitsPerMinute: return 1.0;
    case kUnitsPerRev: return 0.0;
    case kCoordSystem: return origin_index_ < 7 ? 530 + 10 * origin_index_ : 584 + origin_index_;
    case kToolOffset: return (tool_off_[0] != 0.0 || tool_off_[1] != 0.0 || tool_off_[2] != 0.0) ? 1.0 : 0.0;
    case kRetractRPlane: return retract_r_plane_;
    case kRetractOldZ: return !retract_r_plane_;
    case kSpindleRpmMode: return 1.0;
    case kSpindleCssMode: return 0.0;
    case kIjkAbsoluteMode: return ijk_absolute_;
    case kLatheDiameterMode: return 0.0;
    case kLatheRadiusMode: return 1.0;
    case kSpindleOn: return spindle_ != SpindleDir::kOff;
    case kSpindleCw: return spindle_ == SpindleDir::kCw;
    case kMist: return mist_;
    case kFlood: return flood_;
    case kSpeedOverride: return 1.0;
    case kFeedOverride: return 1.0;
    case kAdaptiveFeed: return 0.0;
    case kFeedHold: return 1.0;
    case kFeed: return feed_rate_;
    case kRpm: return std::abs(speed_);
    case kCurrentTool: return params_[kParamToolNumber];
    case kCurrentPocket: return current_pocket_ < 0 ? -1.0 : tool_table_[static_cast<std::size_t>(current_pocket_)].pocket;
    case kSelectedPocket: {
      if (selected_pocket_ < 0) return -1.0;
      const int p = tool_table_[static_cast<std::size_t>(selected_pocket_)].pocket;
      return p == 0 ? -1.0 : p;
    }
    case kSelectedTool: return selected_tool_;
    case kX: return cur_[0];
    case kY: return cur_[1];
    case kZ: return cur_[2];
    case kA: case kB: case kC: case kU: case kV: case kW: return 0.0;
    case kAbsX: case kAbsY: {
      double x = cur_[0] + axis_off_[0];
      double y = cur_[1] + axis_off_[1];
      const double t = rotation_xy_ * std::numbers::pi / 180.0;
      const double xx = x * std::cos(t) - y * std::sin(t);
      const double yy = x * std::sin(t) + y * std::cos(t);
      return which == kAbsX ? xx + origin_[0] + tool_off_[0] : yy + origin_[1] + tool_off_[1];
    }
    case kAbsZ: return cur_[2] + axis_off_[2] + origin_[2] + tool_off_[2];
    case kAbsA: case kAbsB: case kAbsC: return 0.0;
    case kValue: return return_value_;
    case kValueReturned: return value_returned_;
    case kTask: return 1.0;
    case kCallLevel: return static_cast<double>(frames_.size() - 1);
    case kRemapLevel: return 0.0;
    default: return 0.0;
  }
}

}  // namespace contour::control::gcode_detail
