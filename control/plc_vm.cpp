#include "control/plc_vm.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace contour::control::plc {

const char* to_string(RunStatus s) noexcept {
  switch (s) {
    case RunStatus::kOk:
      return "ok";
    case RunStatus::kDivisionByZero:
      return "division by zero";
    case RunStatus::kIndexOutOfRange:
      return "array index out of range";
  }
  return "?";
}

namespace {

inline bool b(const Cell& c) noexcept { return c.i != 0; }
inline void set_b(Cell& c, bool v) noexcept { c.i = v ? 1 : 0; }

// Timers. PT < 0 is taken as 0. The start time is the scan in which the timer's condition began.
void ton(Cell* s, std::int64_t now) noexcept {
  using namespace fb;
  const bool in = b(s[kTimerIn]);
  if (in) {
    if (!b(s[kTimerM])) s[kTimerStart].i = now;
    const std::int64_t pt = std::max<std::int64_t>(0, s[kTimerPt].i);
    const std::int64_t el = now - s[kTimerStart].i;
    set_b(s[kTimerQ], el >= pt);
    s[kTimerEt].i = std::min(el, pt);
  } else {
    set_b(s[kTimerQ], false);
    s[kTimerEt].i = 0;
  }
  set_b(s[kTimerM], in);
}

void tof(Cell* s, std::int64_t now) noexcept {
  using namespace fb;
  const bool in = b(s[kTimerIn]);
  const std::int64_t pt = std::max<std::int64_t>(0, s[kTimerPt].i);
  if (in) {
    set_b(s[kTimerQ], true);
    s[kTimerEt].i = 0;
    set_b(s[kTimerRun], false);
  } else {
    if (b(s[kTimerM])) {  // falling edge: start the delay
      s[kTimerStart].i = now;
      set_b(s[kTimerRun], true);
    }
    if (b(s[kTimerRun])) {
      const std::int64_t el = now - s[kTimerStart].i;
      if (el >= pt) {
        set_b(s[kTimerQ], false);
        s[kTimerEt].i = pt;
        set_b(s[kTimerRun], false);
      } else {
        set_b(s[kTimerQ], true);
        s[kTimerEt].i = el;
      }
    } else {
      set_b(s[kTimerQ], false);  // ET keeps PT after a completed delay, 0 before any
    }
  }
  set_b(s[kTimerM], in);
}

void tp(Cell* s, std::int64_t now) noexcept {
  using namespace fb;
  const bool in = b(s[kTimerIn]);
  const std::int64_t pt = std::max<std::int64_t>(0, s[kTimerPt].i);
  if (!b(s[kTimerRun]) && in && !b(s[kTimerM])) {  // rising edge, not pulsing: start a pulse
    set_b(s[kTimerRun], true);
    s[kTimerStart].i = now;
  }
  if (b(s[kTimerRun])) {
    const std::int64_t el = now - s[kTimerStart].i;
    if (el >= pt) {
      set_b(s[kTimerRun], false);
      s[kTimerEt].i = pt;
    } else {
      set_b(s[kTimerQ], true);
      s[kTimerEt].i = el;
    }
  }
  if (!b(s[kTimerRun])) {
    set_b(s[kTimerQ], false);
    if (!in) s[kTimerEt].i = 0;  // ET holds PT while IN stays TRUE after the pulse
  }
  set_b(s[kTimerM], in);
}

constexpr std::int64_t kCvMax = 32767, kCvMin = -32768;  // INT counters (CTU, CTD, CTUD)

}  // namespace

void call_fb(FbKind kind, Cell* s, std::int64_t now) noexcept {
  using namespace fb;
  switch (kind) {
    case FbKind::kTon:
      ton(s, now);
      return;
    case FbKind::kTof:
      tof(s, now);
      return;
    case FbKind::kTp:
      tp(s, now);
      return;
    case FbKind::kRTrig: {
      const bool clk = b(s[kTrigClk]);
      set_b(s[kTrigQ], clk && !b(s[kTrigM]));
      set_b(s[kTrigM], clk);
      return;
    }
    case FbKind::kFTrig: {
      const bool clk = b(s[kTrigClk]);
      set_b(s[kTrigQ], !clk && !b(s[kTrigM]));
      set_b(s[kTrigM], !clk);
      return;
    }
    case FbKind::kSr:  // set dominant
      set_b(s[kBiQ1], b(s[kBiSet]) || (!b(s[kBiReset]) && b(s[kBiQ1])));
      return;
    case FbKind::kRs:  // reset dominant
      set_b(s[kBiQ1], !b(s[kBiReset]) && (b(s[kBiSet]) || b(s[kBiQ1])));
      return;
    case FbKind::kCtu: {
      const bool cu = b(s[kCtuCu]);
      const bool edge = cu && !b(s[kCtuM]);
      set_b(s[kCtuM], cu);
      if (b(s[kCtuR])) s[kCtuCv].i = 0;
      else if (edge && s[kCtuCv].i < kCvMax) ++s[kCtuCv].i;
      set_b(s[kCtuQ], s[kCtuCv].i >= s[kCtuPv].i);
      return;
    }
    case FbKind::kCtd: {
      const bool cd = b(s[kCtdCd]);
      const bool edge = cd && !b(s[kCtdM]);
      set_b(s[kCtdM], cd);
      if (b(s[kCtdLd])) s[kCtdCv].i = s[kCtdPv].i;
      else if (edge && s[kCtdCv].i > kCvMin) --s[kCtdCv].i;
      set_b(s[kCtdQ], s[kCtdCv].i <= 0);
      return;
    }
    case FbKind::kCtud: {
      const bool cu = b(s[kCtudCu]), cd = b(s[kCtudCd]);
      const bool eu = cu && !b(s[kCtudMu]);
      const bool ed = cd && !b(s[kCtudMd]);
      set_b(s[kCtudMu], cu);
      set_b(s[kCtudMd], cd);
      std::int64_t& cv = s[kCtudCv].i;
      if (b(s[kCtudR])) {
        cv = 0;
      } else if (b(s[kCtudLd])) {
        cv = s[kCtudPv].i;
      } else if (!(eu && ed)) {
        if (eu && cv < kCvMax) ++cv;
        else if (ed && cv > kCvMin) --cv;
      }
      set_b(s[kCtudQu], cv >= s[kCtudPv].i);
      set_b(s[kCtudQd], cv <= 0);
      return;
    }
  }
}

namespace {
std::int64_t real_to_int(double v) noexcept {
  if (std::isnan(v)) return 0;
  const double r = std::nearbyint(v);  // default rounding mode: to nearest, ties to even
  if (r >= 9.2233720368547758e18) return std::numeric_limits<std::int64_t>::max();
  if (r <= -9.2233720368547758e18) return std::numeric_limits<std::int64_t>::min();
  return static_cast<std::int64_t>(r);
}
std::int64_t trunc_to_int(double v) noexcept { return real_to_int(std::trunc(v)); }
}  // namespace

RunResult run(std::span<const Instr> code, std::span<Cell> mem, std::span<Cell> stack,
              std::int64_t now_ns) noexcept {
  RunResult res;
  Cell* const m = mem.data();
  Cell* const st = stack.data();
  std::size_t sp = 0;  // next free stack cell
  std::uint32_t pc = 0;
  std::uint64_t n = 0;
  // Binary operators: y = pop, x = pop, push f(x, y).
#define CONTOUR_PLC_BIN_I(expr)        \
  {                                    \
    const std::int64_t y = st[--sp].i; \
    const std::int64_t x = st[sp - 1].i; \
    st[sp - 1].i = (expr);             \
  }                                    \
  break
#define CONTOUR_PLC_BIN_R(expr)        \
  {                                    \
    const double y = st[--sp].r;       \
    const double x = st[sp - 1].r;     \
    st[sp - 1].r = (expr);             \
  }                                    \
  break
#define CONTOUR_PLC_CMP_R(expr)        \
  {                                    \
    const double y = st[--sp].r;       \
    const double x = st[sp - 1].r;     \
    st[sp - 1].i = (expr) ? 1 : 0;     \
  }                                    \
  break
  for (;;) {
    const Instr& in = code[pc];
    ++n;
    ++pc;
    switch (in.op) {
      case Op::kPush:
        st[sp++] = in.imm;
        break;
      case Op::kLoad:
        st[sp++] = m[in.a];
        break;
      case Op::kStore:
        m[in.a] = st[--sp];
        break;
      case Op::kCheckIndex: {
        const std::int64_t idx = st[sp - 1].i;
        const std::int64_t lo = static_cast<std::int32_t>(static_cast<std::uint64_t>(in.imm.i) >> 32);
        const std::int64_t hi =
            static_cast<std::int32_t>(static_cast<std::uint64_t>(in.imm.i) & 0xFFFFFFFFu);
        if (idx < lo || idx > hi) {
          res.status = RunStatus::kIndexOutOfRange;
          res.pc = pc - 1;
          res.bad_index = idx;
          res.executed = n;
          return res;
        }
        st[sp - 1].i = idx - lo;
        break;
      }
      case Op::kLoadInd:
        st[sp - 1] = m[in.a + st[sp - 1].i];
        break;
      case Op::kStoreInd: {
        const Cell v = st[--sp];
        const std::int64_t i = st[--sp].i;
        m[in.a + i] = v;
        break;
      }
      case Op::kPop:
        --sp;
        break;
      case Op::kAddI:
        CONTOUR_PLC_BIN_I(static_cast<std::int64_t>(static_cast<std::uint64_t>(x) +
                                                    static_cast<std::uint64_t>(y)));
      case Op::kSubI:
        CONTOUR_PLC_BIN_I(static_cast<std::int64_t>(static_cast<std::uint64_t>(x) -
                                                    static_cast<std::uint64_t>(y)));
      case Op::kMulI:
        CONTOUR_PLC_BIN_I(static_cast<std::int64_t>(static_cast<std::uint64_t>(x) *
                                                    static_cast<std::uint64_t>(y)));
      case Op::kDivI:
      case Op::kModI: {
        const std::int64_t y = st[--sp].i;
        const std::int64_t x = st[sp - 1].i;
        if (y == 0) {
          res.status = RunStatus::kDivisionByZero;
          res.pc = pc - 1;
          res.executed = n;
          return res;
        }
        // INT64_MIN / -1 overflows; values come from at most 32-bit types except TIME.
        if (y == -1) st[sp - 1].i = in.op == Op::kDivI ? static_cast<std::int64_t>(0 - static_cast<std::uint64_t>(x)) : 0;
        else st[sp - 1].i = in.op == Op::kDivI ? x / y : x % y;
        break;
      }
      case Op::kNegI:
        st[sp - 1].i = static_cast<std::int64_t>(0 - static_cast<std::uint64_t>(st[sp - 1].i));
        break;
      case Op::kAbsI:
        if (st[sp - 1].i < 0)
          st[sp - 1].i = static_cast<std::int64_t>(0 - static_cast<std::uint64_t>(st[sp - 1].i));
        break;
      case Op::kMinI:
        CONTOUR_PLC_BIN_I(std::min(x, y));
      case Op::kMaxI:
        CONTOUR_PLC_BIN_I(std::max(x, y));
      case Op::kLimitI: {  // LIMIT(MN, IN, MX)
        const std::int64_t mx = st[--sp].i;
        const std::int64_t v = st[--sp].i;
        const std::int64_t mn = st[sp - 1].i;
        st[sp - 1].i = std::min(std::max(v, mn), mx);
        break;
      }
      case Op::kWrap16:
        st[sp - 1].i = wrap16(st[sp - 1].i);
        break;
      case Op::kWrap32:
        st[sp - 1].i = wrap32(st[sp - 1].i);
        break;
      case Op::kAddR:
        CONTOUR_PLC_BIN_R(x + y);
      case Op::kSubR:
        CONTOUR_PLC_BIN_R(x - y);
      case Op::kMulR:
        CONTOUR_PLC_BIN_R(x * y);
      case Op::kDivR: {
        const double y = st[--sp].r;
        if (y == 0.0) {
          res.status = RunStatus::kDivisionByZero;
          res.pc = pc - 1;
          res.executed = n;
          return res;
        }
        st[sp - 1].r /= y;
        break;
      }
      case Op::kNegR:
        st[sp - 1].r = -st[sp - 1].r;
        break;
      case Op::kAbsR:
        st[sp - 1].r = std::fabs(st[sp - 1].r);
        break;
      case Op::kMinR:
        CONTOUR_PLC_BIN_R(std::fmin(x, y));
      case Op::kMaxR:
        CONTOUR_PLC_BIN_R(std::fmax(x, y));
      case Op::kLimitR: {
        const double mx = st[--sp].r;
        const double v = st[--sp].r;
        const double mn = st[sp - 1].r;
        st[sp - 1].r = std::fmin(std::fmax(v, mn), mx);
        break;
      }
      case Op::kSqrtR:
        st[sp - 1].r = std::sqrt(st[sp - 1].r);
        break;
      case Op::kExptR:
        CONTOUR_PLC_BIN_R(std::pow(x, y));
      case Op::kF32:
        st[sp - 1].r = static_cast<double>(static_cast<float>(st[sp - 1].r));
        break;
      case Op::kEqI:
        CONTOUR_PLC_BIN_I(x == y ? 1 : 0);
      case Op::kNeI:
        CONTOUR_PLC_BIN_I(x != y ? 1 : 0);
      case Op::kLtI:
        CONTOUR_PLC_BIN_I(x < y ? 1 : 0);
      case Op::kLeI:
        CONTOUR_PLC_BIN_I(x <= y ? 1 : 0);
      case Op::kGtI:
        CONTOUR_PLC_BIN_I(x > y ? 1 : 0);
      case Op::kGeI:
        CONTOUR_PLC_BIN_I(x >= y ? 1 : 0);
      case Op::kEqR:
        CONTOUR_PLC_CMP_R(x == y);
      case Op::kNeR:
        CONTOUR_PLC_CMP_R(x != y);
      case Op::kLtR:
        CONTOUR_PLC_CMP_R(x < y);
      case Op::kLeR:
        CONTOUR_PLC_CMP_R(x <= y);
      case Op::kGtR:
        CONTOUR_PLC_CMP_R(x > y);
      case Op::kGeR:
        CONTOUR_PLC_CMP_R(x >= y);
      case Op::kAnd:
        CONTOUR_PLC_BIN_I(x & y);
      case Op::kOr:
        CONTOUR_PLC_BIN_I(x | y);
      case Op::kXor:
        CONTOUR_PLC_BIN_I(x ^ y);
      case Op::kNot:
        st[sp - 1].i ^= 1;
        break;
      case Op::kIntToReal:
        st[sp - 1].r = static_cast<double>(st[sp - 1].i);
        break;
      case Op::kRealToInt:
        st[sp - 1].i = real_to_int(st[sp - 1].r);
        break;
      case Op::kTruncReal:
        st[sp - 1].i = trunc_to_int(st[sp - 1].r);
        break;
      case Op::kNonZero:
        st[sp - 1].i = st[sp - 1].i != 0 ? 1 : 0;
        break;
      case Op::kSel: {
        const Cell in1 = st[--sp];
        const Cell in0 = st[--sp];
        st[sp - 1] = st[sp - 1].i != 0 ? in1 : in0;
        break;
      }
      case Op::kJmp:
        pc = static_cast<std::uint32_t>(in.a);
        break;
      case Op::kJz:
        if (st[--sp].i == 0) pc = static_cast<std::uint32_t>(in.a);
        break;
      case Op::kJnz:
        if (st[--sp].i != 0) pc = static_cast<std::uint32_t>(in.a);
        break;
      case Op::kCallFb:
        n += kFbCallCost - 1;
        call_fb(static_cast<FbKind>(in.b), m + in.a, now_ns);
        break;
      case Op::kRet:
        res.executed = n;
        return res;
    }
  }
#undef CONTOUR_PLC_BIN_I
#undef CONTOUR_PLC_BIN_R
#undef CONTOUR_PLC_CMP_R
}

}  // namespace contour::control::plc
