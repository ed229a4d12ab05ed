#pragma once
// Soft PLC (issue 20), shared vocabulary of the Structured Text compiler (control/plc_compiler)
// and the virtual machine (control/plc_vm): elementary types, the memory cell, the flat
// instruction set, the standard function blocks' layouts, and the symbols a program sees from
// outside (the I/O image's signals, the NC's status and requests).
//
// Memory model: one flat array of 8-byte cells per PLC (the I/O image first, then each program's
// locals, FB instances included). A cell holds either an integer (BOOL 0/1, INT, DINT, TIME in
// ns, all sign-extended into int64) or a double (REAL rounded to float precision, LREAL); which
// one is known statically from the type, never tagged at run time.
// Pure: no I/O, no allocation in anything the VM calls per scan.
#include <array>
#include <cstdint>
#include <string>
#include <string_view>

namespace contour::control::plc {

// IEC 61131-3 elementary types of the subset. TIME is a duration in nanoseconds (int64).
enum class Type : std::uint8_t { kBool, kInt, kDint, kReal, kLreal, kTime, kVoid };
[[nodiscard]] const char* type_name(Type t) noexcept;  // "BOOL", "INT", ...
[[nodiscard]] inline bool is_integer(Type t) noexcept { return t == Type::kInt || t == Type::kDint; }
[[nodiscard]] inline bool is_real(Type t) noexcept { return t == Type::kReal || t == Type::kLreal; }
[[nodiscard]] inline bool is_int_cell(Type t) noexcept { return !is_real(t); }

union Cell {
  std::int64_t i;
  double r;
};
static_assert(sizeof(Cell) == 8);
[[nodiscard]] inline Cell int_cell(std::int64_t v) noexcept {
  Cell c;
  c.i = v;
  return c;
}
[[nodiscard]] inline Cell real_cell(double v) noexcept {
  Cell c;
  c.r = v;
  return c;
}

// Normalises a value to its type's range: INT wraps to 16 bits, DINT to 32, BOOL to 0/1, REAL to
// float precision (IEC REAL is 32-bit). What a store from outside (field, force) must apply.
[[nodiscard]] Cell normalise(Type t, Cell c) noexcept;
[[nodiscard]] inline std::int64_t wrap16(std::int64_t v) noexcept {
  return static_cast<std::int16_t>(static_cast<std::uint16_t>(static_cast<std::uint64_t>(v) & 0xFFFFu));
}
[[nodiscard]] inline std::int64_t wrap32(std::int64_t v) noexcept {
  return static_cast<std::int32_t>(
      static_cast<std::uint32_t>(static_cast<std::uint64_t>(v) & 0xFFFFFFFFu));
}

// How a program may use an outside symbol.
enum class Access : std::uint8_t {
  kRead,       // inputs, NC status, NC-owned outputs: reading only ("assignment to an input")
  kReadWrite,  // outputs, NC requests, memory signals
};

// ---- The standard function blocks -----------------------------------------------------------
enum class FbKind : std::uint8_t { kTon, kTof, kTp, kRTrig, kFTrig, kSr, kRs, kCtu, kCtd, kCtud };
inline constexpr int kFbKinds = 10;

enum class MemberDir : std::uint8_t { kIn, kOut, kState };
struct FbMember {
  const char* name;  // upper case, as the standard names it
  Type type;
  MemberDir dir;
  std::int64_t init;  // initial value (integer cells only: every member is BOOL/INT/TIME)
};
struct FbInfo {
  FbKind kind;
  const char* name;  // "TON", ...
  std::uint8_t size; // cells
  std::array<FbMember, 10> members;
};
[[nodiscard]] const FbInfo& fb_info(FbKind k) noexcept;
// Looks a standard FB type up by its upper-case name; false if none.
bool find_fb(std::string_view upper_name, FbKind& out) noexcept;
// Each call counts as this many instructions toward the budget (its body is a fixed few dozen
// machine instructions, measured in tools/bench/bench_plc.cpp).
inline constexpr std::uint64_t kFbCallCost = 8;

// Member offsets inside an instance (the layouts fb_info() describes).
namespace fb {
inline constexpr int kTimerIn = 0, kTimerPt = 1, kTimerQ = 2, kTimerEt = 3, kTimerM = 4,
                     kTimerStart = 5, kTimerRun = 6;
inline constexpr int kTrigClk = 0, kTrigQ = 1, kTrigM = 2;
inline constexpr int kBiSet = 0, kBiReset = 1, kBiQ1 = 2;  // SR: S1, R; RS: S, R1
inline constexpr int kCtuCu = 0, kCtuR = 1, kCtuPv = 2, kCtuQ = 3, kCtuCv = 4, kCtuM = 5;
inline constexpr int kCtdCd = 0, kCtdLd = 1, kCtdPv = 2, kCtdQ = 3, kCtdCv = 4, kCtdM = 5;
inline constexpr int kCtudCu = 0, kCtudCd = 1, kCtudR = 2, kCtudLd = 3, kCtudPv = 4, kCtudQu = 5,
                     kCtudQd = 6, kCtudCv = 7, kCtudMu = 8, kCtudMd = 9;
}  // namespace fb

// ---- The flat instruction set ---------------------------------------------------------------
// A stack machine. Operands: `a` (slot, jump target, FB instance base or a small constant) and
// `imm` (a literal). Slots index the flat memory; in a compiled-but-unlinked program, local slots
// carry kLocalFlag (link() relocates them).
enum class Op : std::uint8_t {
  kPush,       // push imm
  kLoad,       // push mem[a]
  kStore,      // mem[a] = pop
  kCheckIndex, // idx = pop; error unless imm.i >> 32 <= idx <= (int32)imm.i; push idx - lower
  kLoadInd,    // i = pop; push mem[a + i]
  kStoreInd,   // v = pop; i = pop; mem[a + i] = v
  kPop,
  // integer (int64 cells; the compiler wraps INT/DINT results)
  kAddI, kSubI, kMulI, kDivI, kModI, kNegI, kAbsI, kMinI, kMaxI, kLimitI, kWrap16, kWrap32,
  // real (double cells; the compiler rounds REAL results to float)
  kAddR, kSubR, kMulR, kDivR, kNegR, kAbsR, kMinR, kMaxR, kLimitR, kSqrtR, kExptR, kF32,
  // comparison -> BOOL
  kEqI, kNeI, kLtI, kLeI, kGtI, kGeI, kEqR, kNeR, kLtR, kLeR, kGtR, kGeR,
  // BOOL logic (0/1)
  kAnd, kOr, kXor, kNot,
  // conversion
  kIntToReal,   // int64 -> double
  kRealToInt,   // round to nearest, ties to even (IEC REAL_TO_INT); saturates at int64 range
  kTruncReal,   // toward zero (TRUNC)
  kNonZero,     // x <> 0 -> BOOL (INT_TO_BOOL)
  kSel,         // in1 = pop; in0 = pop; g = pop; push g ? in1 : in0
  // control
  kJmp, kJz, kJnz,  // to a (kJz/kJnz pop the condition)
  kCallFb,          // FB instance at slot a, kind in `b`
  kRet,
};

struct Instr {
  Op op = Op::kRet;
  std::uint8_t b = 0;  // kCallFb: FbKind
  std::int32_t a = 0;
  Cell imm{};
};
static_assert(sizeof(Instr) == 16);

inline constexpr std::int32_t kLocalFlag = 0x40000000;

// A compile or load error: "file:line:column: message".
struct Diagnostic {
  std::string file;
  int line = 0;
  int column = 0;
  std::string message;
  [[nodiscard]] std::string format() const;
};

// Upper-case ASCII copy (IEC identifiers and keywords are case-insensitive).
[[nodiscard]] std::string upper(std::string_view s);

}  // namespace contour::control::plc
