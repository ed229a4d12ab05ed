#include "control/plc_types.hpp"

#include <cctype>

namespace contour::control::plc {

const char* type_name(Type t) noexcept {
  switch (t) {
    case Type::kBool:
      return "BOOL";
    case Type::kInt:
      return "INT";
    case Type::kDint:
      return "DINT";
    case Type::kReal:
      return "REAL";
    case Type::kLreal:
      return "LREAL";
    case Type::kTime:
      return "TIME";
    case Type::kVoid:
      return "(no value)";
  }
  return "?";
}

Cell normalise(Type t, Cell c) noexcept {
  switch (t) {
    case Type::kBool:
      return int_cell(c.i != 0 ? 1 : 0);
    case Type::kInt:
      return int_cell(wrap16(c.i));
    case Type::kDint:
      return int_cell(wrap32(c.i));
    case Type::kReal:
      return real_cell(static_cast<double>(static_cast<float>(c.r)));
    case Type::kLreal:
    case Type::kTime:
    case Type::kVoid:
      return c;
  }
  return c;
}

namespace {
using M = FbMember;
constexpr MemberDir I = MemberDir::kIn, O = MemberDir::kOut, S = MemberDir::kState;
constexpr M kNone{"", Type::kVoid, MemberDir::kState, 0};

constexpr std::array<FbInfo, kFbKinds> kFbs{{
    {FbKind::kTon, "TON", 7,
     {{{"IN", Type::kBool, I, 0}, {"PT", Type::kTime, I, 0}, {"Q", Type::kBool, O, 0},
       {"ET", Type::kTime, O, 0}, {"", Type::kBool, S, 0}, {"", Type::kTime, S, 0},
       {"", Type::kBool, S, 0}, kNone, kNone, kNone}}},
    {FbKind::kTof, "TOF", 7,
     {{{"IN", Type::kBool, I, 0}, {"PT", Type::kTime, I, 0}, {"Q", Type::kBool, O, 0},
       {"ET", Type::kTime, O, 0}, {"", Type::kBool, S, 0}, {"", Type::kTime, S, 0},
       {"", Type::kBool, S, 0}, kNone, kNone, kNone}}},
    {FbKind::kTp, "TP", 7,
     {{{"IN", Type::kBool, I, 0}, {"PT", Type::kTime, I, 0}, {"Q", Type::kBool, O, 0},
       {"ET", Type::kTime, O, 0}, {"", Type::kBool, S, 0}, {"", Type::kTime, S, 0},
       {"", Type::kBool, S, 0}, kNone, kNone, kNone}}},
    {FbKind::kRTrig, "R_TRIG", 3,
     {{{"CLK", Type::kBool, I, 0}, {"Q", Type::kBool, O, 0}, {"", Type::kBool, S, 0}, kNone,
       kNone, kNone, kNone, kNone, kNone, kNone}}},
    // F_TRIG's memory starts TRUE (3rd edition): no falling edge on the first scan.
    {FbKind::kFTrig, "F_TRIG", 3,
     {{{"CLK", Type::kBool, I, 0}, {"Q", Type::kBool, O, 0}, {"", Type::kBool, S, 1}, kNone,
       kNone, kNone, kNone, kNone, kNone, kNone}}},
    {FbKind::kSr, "SR", 3,
     {{{"S1", Type::kBool, I, 0}, {"R", Type::kBool, I, 0}, {"Q1", Type::kBool, O, 0}, kNone,
       kNone, kNone, kNone, kNone, kNone, kNone}}},
    {FbKind::kRs, "RS", 3,
     {{{"S", Type::kBool, I, 0}, {"R1", Type::kBool, I, 0}, {"Q1", Type::kBool, O, 0}, kNone,
       kNone, kNone, kNone, kNone, kNone, kNone}}},
    {FbKind::kCtu, "CTU", 6,
     {{{"CU", Type::kBool, I, 0}, {"R", Type::kBool, I, 0}, {"PV", Type::kInt, I, 0},
       {"Q", Type::kBool, O, 0}, {"CV", Type::kInt, O, 0}, {"", Type::kBool, S, 0}, kNone, kNone,
       kNone, kNone}}},
    {FbKind::kCtd, "CTD", 6,
     {{{"CD", Type::kBool, I, 0}, {"LD", Type::kBool, I, 0}, {"PV", Type::kInt, I, 0},
       {"Q", Type::kBool, O, 0}, {"CV", Type::kInt, O, 0}, {"", Type::kBool, S, 0}, kNone, kNone,
       kNone, kNone}}},
    {FbKind::kCtud, "CTUD", 10,
     {{{"CU", Type::kBool, I, 0}, {"CD", Type::kBool, I, 0}, {"R", Type::kBool, I, 0},
       {"LD", Type::kBool, I, 0}, {"PV", Type::kInt, I, 0}, {"QU", Type::kBool, O, 0},
       {"QD", Type::kBool, O, 0}, {"CV", Type::kInt, O, 0}, {"", Type::kBool, S, 0},
       {"", Type::kBool, S, 0}}}},
}};
}  // namespace

const FbInfo& fb_info(FbKind k) noexcept { return kFbs[static_cast<std::size_t>(k)]; }

bool find_fb(std::string_view upper_name, FbKind& out) noexcept {
  for (const auto& f : kFbs) {
    if (upper_name == f.name) {
      out = f.kind;
      return true;
    }
  }
  return false;
}

std::string Diagnostic::format() const {
  return file + ":" + std::to_string(line) + ":" + std::to_string(column) + ": " + message;
}

std::string upper(std::string_view s) {
  std::string out(s);
  for (char& ch : out) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  return out;
}

}  // namespace contour::control::plc
