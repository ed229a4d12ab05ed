// contour-gcode-diff (issue 19): differential test of contourd's G-code interpreter against
// LinuxCNC's own RS274/NGC interpreter, program by program.
//
// For each program it runs, in a private scratch directory:
//   - LinuxCNC's interpreter through its Python module (linuxcnc_ref.py): every canonical call at
//     full double precision with its source line -> the precise reference (tolerance 1e-6 mm);
//   - `rs274 -g` (LinuxCNC's standalone interpreter): every canonical call printed with 4 decimals
//     -> the verdict (accepted/rejected and the text of the failing line) and the calls the module
//     does not report (spindle, coolant, M0/M1/M2);
//   - contourd's GcodeParser.
// Moves are compared in machine coordinates (LinuxCNC's canonical positions plus the G5x, G92,
// rotation and tool offsets it reports), mm: end points, arc centres, planes, turns and direction,
// rapid vs feed, feed rates, dwells, tool changes, user M-codes, line numbers. A program LinuxCNC
// rejects must be rejected by contourd on the same line.
//
// Usage: contour-gcode-diff [--var F.var] [--tbl F.tbl] [--subroutines DIR] [--verbose] [--final]
//        PROGRAM...
// --final also prints, per program LinuxCNC accepts, where LinuxCNC's machine ends (the end of its
// last move, machine coordinates, mm): `FINAL <program> <x> <y> <z>` (the end-to-end tests compare
// the daemon's final machine position with it).
// The .var/.tbl files are in mm (LinuxCNC formats); without them a built-in machine is used.
// Exit: 0 all programs identical or rejected by both; 1 any mismatch; 2 usage; 77 LinuxCNC's
// interpreter is not installed (tools/deps.d/linuxcnc.list), with the reason on stderr.
// Test-only tool: contourd never runs LinuxCNC.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "control/gcode.hpp"

using contour::control::Block;
using contour::control::BlockKind;
using contour::control::GcodeError;
using contour::control::GcodeParser;
using contour::control::MachineContext;
using contour::control::Plane;
using contour::control::PlaneAxes;
using contour::control::ProgramSetup;
using contour::control::SpindleDir;
using contour::control::ToolData;
using Eigen::Vector3d;

namespace {

#ifndef CONTOUR_GCODE_REF_SCRIPT
#define CONTOUR_GCODE_REF_SCRIPT "linuxcnc_ref.py"
#endif

const char* kDefaultVar =
    "5161\t0.000000\n5162\t0.000000\n5163\t50.000000\n5181\t-20.000000\n5182\t-30.000000\n"
    "5183\t40.000000\n5220\t1.000000\n5221\t10.000000\n5222\t20.000000\n5223\t-5.000000\n"
    "5241\t100.000000\n5242\t-50.000000\n5243\t0.000000\n";
const char* kDefaultTbl =
    "T1  P1   D+6.000000 Z+40.000000 ;6 mm end mill\n"
    "T2  P2   D+10.000000 Z+55.500000 ;10 mm end mill\n"
    "T3  P3   D+3.175000 Z+31.750000 ;1/8 in end mill\n"
    "T4  P4   D+5.000000 Z+60.000000 ;5 mm drill\n";

struct Ev {
  enum class Kind { kTraverse, kFeed, kArc, kDwell, kTool, kUserM, kStop, kOptStop, kMessage };
  Kind kind = Kind::kFeed;
  int line = 0;
  Vector3d end = Vector3d::Zero();
  double c1 = 0, c2 = 0;  // arc centre, in-plane coordinates
  int plane = 1;          // 1 XY, 2 YZ, 3 XZ
  int rot = 0;
  double feed = 0;        // mm/min (feed moves, arcs)
  double value = 0;       // dwell s, user M P
  double value2 = 0;      // user M Q
  int ivalue = 0;         // tool number, user M number
  // machine state at the event (rs274 comparison)
  int spindle = 0;        // 0 off, 1 cw, -1 ccw
  double rpm = 0;
  bool mist = false, flood = false;
  std::string text;  // messages
};

const char* kind_name(Ev::Kind k) {
  switch (k) {
    case Ev::Kind::kTraverse: return "TRAVERSE";
    case Ev::Kind::kFeed: return "FEED";
    case Ev::Kind::kArc: return "ARC";
    case Ev::Kind::kDwell: return "DWELL";
    case Ev::Kind::kTool: return "TOOL_CHANGE";
    case Ev::Kind::kUserM: return "USER_M";
    case Ev::Kind::kStop: return "PROGRAM_STOP";
    case Ev::Kind::kOptStop: return "OPTIONAL_STOP";
    case Ev::Kind::kMessage: return "MESSAGE";
  }
  return "?";
}

std::string describe(const Ev& e) {
  char buf[320];
  switch (e.kind) {
    case Ev::Kind::kTraverse:
    case Ev::Kind::kFeed:
      std::snprintf(buf, sizeof buf, "line %d %s to (%.6f, %.6f, %.6f) feed %.6f", e.line, kind_name(e.kind),
                    e.end.x(), e.end.y(), e.end.z(), e.feed);
      break;
    case Ev::Kind::kArc:
      std::snprintf(buf, sizeof buf, "line %d ARC plane %d to (%.6f, %.6f, %.6f) centre (%.6f, %.6f) rotation %d feed %.6f",
                    e.line, e.plane, e.end.x(), e.end.y(), e.end.z(), e.c1, e.c2, e.rot, e.feed);
      break;
    case Ev::Kind::kDwell:
      std::snprintf(buf, sizeof buf, "line %d DWELL %.6f s", e.line, e.value);
      break;
    case Ev::Kind::kTool:
      std::snprintf(buf, sizeof buf, "line %d TOOL_CHANGE tool %d", e.line, e.ivalue);
      break;
    case Ev::Kind::kUserM:
      std::snprintf(buf, sizeof buf, "line %d M%d P%g Q%g", e.line, e.ivalue, e.value, e.value2);
      break;
    case Ev::Kind::kMessage:
      return "line " + std::to_string(e.line) + " MESSAGE '" + e.text + "'";
    default:
      std::snprintf(buf, sizeof buf, "line %d %s", e.line, kind_name(e.kind));
      break;
  }
  std::string s = buf;
  char st[96];
  std::snprintf(st, sizeof st, " [spindle %d %.1f rpm, mist %d, flood %d]", e.spindle, e.rpm, e.mist, e.flood);
  return s + st;
}

// ---- shell helpers

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) {
    if (c == '\'') q += "'\\''";
    else q += c;
  }
  return q + "'";
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_file(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

bool executable(const std::string& p) { return ::access(p.c_str(), X_OK) == 0; }

std::vector<std::string> split_lines(const std::string& t) {
  std::vector<std::string> v;
  std::string cur;
  std::istringstream in(t);
  while (std::getline(in, cur)) v.push_back(cur);
  return v;
}

std::string rtrim(std::string s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  return s;
}

// ---- machine transform, as LinuxCNC's canon applies it

struct Frame {
  double unit = 1.0;  // mm per program unit (rs274 output); 1 for the module (already mm)
  Vector3d g5x = Vector3d::Zero(), g92 = Vector3d::Zero(), tlo = Vector3d::Zero();
  double rot = 0.0;
  Vector3d to_machine(double x, double y, double z) const {
    double px = x * unit + g92.x(), py = y * unit + g92.y();
    const double pz = z * unit + g92.z();
    const double t = rot * std::numbers::pi / 180.0;
    const double xx = px * std::cos(t) - py * std::sin(t);
    const double yy = px * std::sin(t) + py * std::cos(t);
    return {xx + g5x.x() + tlo.x(), yy + g5x.y() + tlo.y(), pz + g5x.z() + tlo.z()};
  }
};

Ev arc_event(const Frame& f, int plane, double fe, double se, double fc, double sc, int rot, double ae) {
  Ev e;
  e.kind = Ev::Kind::kArc;
  e.plane = plane;
  e.rot = rot;
  Vector3d c;
  if (plane == 1) {
    e.end = f.to_machine(fe, se, ae);
    c = f.to_machine(fc, sc, ae);
    e.c1 = c.x();
    e.c2 = c.y();
  } else if (plane == 3) {
    e.end = f.to_machine(se, ae, fe);
    c = f.to_machine(sc, ae, fc);
    e.c1 = c.z();
    e.c2 = c.x();
  } else {
    e.end = f.to_machine(ae, fe, se);
    c = f.to_machine(ae, fc, sc);
    e.c1 = c.y();
    e.c2 = c.z();
  }
  return e;
}

// ---- reference: the Python module

struct RefResult {
  std::vector<Ev> events;
  bool rejected = false;
  int line = 0;
  std::string message;
  bool ran = false;
  std::string failure;  // the reference itself failed to run
};

std::vector<std::string> words(const std::string& s) {
  std::vector<std::string> v;
  std::istringstream in(s);
  std::string w;
  while (in >> w) v.push_back(w);
  return v;
}

RefResult parse_module(const std::string& out, const std::vector<ToolData>& tools) {
  RefResult r;
  Frame f;
  int plane = 1;
  double feed = 0.0;
  for (const auto& l : split_lines(out)) {
    if (l.rfind("END ", 0) == 0) {
      std::istringstream in(l.substr(4));
      int status = 0;
      in >> status >> r.line;
      std::getline(in, r.message);
      r.rejected = status != 0;
      r.ran = true;
      continue;
    }
    const auto w = words(l);
    if (w.size() < 2) continue;
    const int line = std::atoi(w[0].c_str());
    const std::string& c = w[1];
    const auto d = [&](std::size_t i) { return i < w.size() ? std::strtod(w[i].c_str(), nullptr) : 0.0; };
    Ev e;
    e.line = line;
    if (c == "TRAVERSE" || c == "FEED") {
      e.kind = c == "FEED" ? Ev::Kind::kFeed : Ev::Kind::kTraverse;
      e.end = f.to_machine(d(2), d(3), d(4));
      if (e.kind == Ev::Kind::kFeed) e.feed = feed;
      r.events.push_back(e);
    } else if (c == "ARC") {
      Ev a = arc_event(f, plane, d(2), d(3), d(4), d(5), static_cast<int>(d(6)), d(7));
      a.line = line;
      a.feed = feed;
      r.events.push_back(a);
    } else if (c == "PLANE") {
      plane = static_cast<int>(d(2));
    } else if (c == "FEEDRATE") {
      feed = d(2);
    } else if (c == "DWELL") {
      e.kind = Ev::Kind::kDwell;
      e.value = d(2);
      r.events.push_back(e);
    } else if (c == "G5X") {
      f.g5x = Vector3d(d(3), d(4), d(5));
    } else if (c == "G92") {
      f.g92 = Vector3d(d(2), d(3), d(4));
    } else if (c == "ROTATION") {
      f.rot = d(2);
    } else if (c == "TLO") {
      f.tlo = Vector3d(d(2), d(3), d(4));
    } else if (c == "TOOL") {
      const int pocket = static_cast<int>(d(2));
      e.kind = Ev::Kind::kTool;
      e.ivalue = (pocket >= 1 && pocket <= static_cast<int>(tools.size())) ? tools[static_cast<std::size_t>(pocket - 1)].number : 0;
      r.events.push_back(e);
    } else if (c == "MESSAGE") {
      e.kind = Ev::Kind::kMessage;
      const std::size_t at = l.find("MESSAGE ");
      e.text = l.substr(at + 8);
      r.events.push_back(e);
    } else if (c == "USERM") {
      e.kind = Ev::Kind::kUserM;
      e.ivalue = static_cast<int>(d(2));
      e.value = d(3);
      e.value2 = d(4);
      r.events.push_back(e);
    }
  }
  return r;
}

// ---- reference: rs274 -g

struct Rs274Result {
  std::vector<Ev> events;
  bool rejected = false;
  std::string error;      // error message
  std::string line_text;  // text of the failing line as rs274 prints it
};

Rs274Result parse_rs274(const std::string& out, const std::string& err, int rc, const std::vector<ToolData>& tools) {
  Rs274Result r;
  Frame f;
  f.unit = 1.0;
  int plane = 1;
  double feed = 0.0;
  int spindle = 0;
  double rpm = 0;
  bool mist = false, flood = false;
  const auto state = [&](Ev& e) {
    e.spindle = spindle;
    e.rpm = rpm;
    e.mist = mist;
    e.flood = flood;
  };
  for (const auto& l : split_lines(out)) {
    // "   12 N..... NAME(args)" or "   12 N0010  NAME(args)"
    std::size_t p = l.find_first_not_of(' ');
    if (p == std::string::npos) continue;
    p = l.find(' ', p);
    if (p == std::string::npos) continue;
    p = l.find_first_not_of(' ', p);
    if (p == std::string::npos || l[p] != 'N') continue;
    p = l.find(' ', p);
    if (p == std::string::npos) continue;
    p = l.find_first_not_of(' ', p);
    if (p == std::string::npos) continue;
    const std::string call = l.substr(p);
    const std::size_t open = call.find('(');
    if (open == std::string::npos) continue;
    const std::string name = call.substr(0, open);
    std::string args = call.substr(open + 1);
    if (!args.empty() && args.back() == ')') args.pop_back();
    std::vector<double> v;
    {
      std::string a = args;
      for (auto& ch : a)
        if (ch == ',') ch = ' ';
      std::istringstream in(a);
      std::string tok;
      while (in >> tok) {
        char* end = nullptr;
        const double x = std::strtod(tok.c_str(), &end);
        if (end != tok.c_str()) v.push_back(x);
      }
    }
    const auto a = [&](std::size_t i) { return i < v.size() ? v[i] : 0.0; };
    Ev e;
    if (name == "USE_LENGTH_UNITS") {
      f.unit = args.find("INCHES") != std::string::npos ? 25.4 : 1.0;
    } else if (name == "SET_G5X_OFFSET") {
      f.g5x = Vector3d(a(1), a(2), a(3)) * f.unit;
    } else if (name == "SET_G92_OFFSET") {
      f.g92 = Vector3d(a(0), a(1), a(2)) * f.unit;
    } else if (name == "SET_XY_ROTATION") {
      f.rot = a(0);
    } else if (name == "USE_TOOL_LENGTH_OFFSET") {
      f.tlo = Vector3d(a(0), a(1), a(2)) * f.unit;
    } else if (name == "SELECT_PLANE") {
      plane = args.find("XZ") != std::string::npos ? 3 : args.find("YZ") != std::string::npos ? 2 : 1;
    } else if (name == "SET_FEED_RATE") {
      feed = a(0) * f.unit;
    } else if (name == "STRAIGHT_TRAVERSE" || name == "STRAIGHT_FEED") {
      e.kind = name == "STRAIGHT_FEED" ? Ev::Kind::kFeed : Ev::Kind::kTraverse;
      e.end = f.to_machine(a(0), a(1), a(2));
      if (e.kind == Ev::Kind::kFeed) e.feed = feed;
      state(e);
      r.events.push_back(e);
    } else if (name == "ARC_FEED") {
      e = arc_event(f, plane, a(0), a(1), a(2), a(3), static_cast<int>(a(4)), a(5));
      e.feed = feed;
      state(e);
      r.events.push_back(e);
    } else if (name == "DWELL") {
      e.kind = Ev::Kind::kDwell;
      e.value = a(0);
      state(e);
      r.events.push_back(e);
    } else if (name == "START_SPINDLE_CLOCKWISE") {
      spindle = 1;
    } else if (name == "START_SPINDLE_COUNTERCLOCKWISE") {
      spindle = -1;
    } else if (name == "STOP_SPINDLE_TURNING") {
      spindle = 0;
    } else if (name == "SET_SPINDLE_SPEED") {
      rpm = a(1);
    } else if (name == "MIST_ON") {
      mist = true;
    } else if (name == "MIST_OFF") {
      mist = false;
    } else if (name == "FLOOD_ON") {
      flood = true;
    } else if (name == "FLOOD_OFF") {
      flood = false;
    } else if (name == "CHANGE_TOOL") {
      const int pocket = static_cast<int>(a(0));
      e.kind = Ev::Kind::kTool;
      e.ivalue = (pocket >= 1 && pocket <= static_cast<int>(tools.size())) ? tools[static_cast<std::size_t>(pocket - 1)].number : 0;
      state(e);
      r.events.push_back(e);
    } else if (name == "PROGRAM_STOP") {
      e.kind = Ev::Kind::kStop;
      state(e);
      r.events.push_back(e);
    } else if (name == "OPTIONAL_PROGRAM_STOP") {
      e.kind = Ev::Kind::kOptStop;
      state(e);
      r.events.push_back(e);
    }
  }
  // Errors: "<message>\n<line text>\n" on stderr after "executing".
  auto el = split_lines(err);
  el.erase(std::remove_if(el.begin(), el.end(), [](const std::string& s) {
             return s == "executing" || s.rfind("UNEXPECTED", 0) == 0 || s.empty();
           }),
           el.end());
  if (rc != 0 || !el.empty()) {
    r.rejected = true;
    if (!el.empty()) {
      // The last two lines: message and line text ("executing" may precede them on the same line).
      std::string msg = el.size() >= 2 ? el[el.size() - 2] : el.back();
      const std::string ex = "executing";
      if (msg.rfind(ex, 0) == 0) msg = msg.substr(ex.size());
      r.error = msg;
      r.line_text = el.size() >= 2 ? el.back() : "";
    }
  }
  return r;
}

// ---- contourd

struct OurResult {
  std::vector<Ev> events;
  bool rejected = false;
  int line = 0;
  std::string file;
  std::string message;
};

// LinuxCNC's interpreter re-reads the machine position from its canonical layer at the first line
// after a tool change (M6, M61). The standalone interpreters' canonical layers do not model the
// machine: the Python module returns the end of the last straight move in the program coordinates
// it had then (arcs and later offset changes ignored); rs274 returns a position kept through G5x
// and G92 changes but not through tool length offset changes. A real machine (and contourd)
// stays where it is. To compare the rest of such a program, contourd is re-synchronised to the
// reference's idea of the position at that point, through the same call the daemon uses to
// re-synchronise the interpreter to the machine (GcodeParser::set_position_mm).
enum class Refresh { kModule, kRs274 };

OurResult run_contourd(const std::string& path, const MachineContext& m, const std::string& subdir, bool block_delete,
                       Refresh refresh) {
  const bool start_at_program_origin = refresh == Refresh::kModule;
  OurResult r;
  ProgramSetup s;
  s.machine = m;
  s.require_program_end = true;
  s.block_delete = block_delete;
  // The module starts at the origin of the program coordinate system, rs274 at machine zero.
  if (start_at_program_origin) {
    const int sys = m.active_system();
    Frame f;
    f.g5x = m.work_offset_mm(sys);
    if (m.g92_applied()) f.g92 = m.g92_offset_mm();
    f.rot = m.work_rotation_deg(sys);
    s.start_mm = f.to_machine(0, 0, 0);
  }
  if (!subdir.empty()) {
    s.load_subroutine = [subdir](const std::string& name) -> std::optional<std::string> {
      std::ifstream in(subdir + "/" + name + ".ngc", std::ios::binary);
      if (!in) return std::nullopt;
      std::ostringstream ss;
      ss << in.rdbuf();
      return ss.str();
    };
  }
  GcodeParser p(s, path);
  std::vector<Block> blocks;
  std::ifstream in(path, std::ios::binary);
  std::string line;
  std::optional<Block> last_straight;
  std::optional<Block> last_motion;
  std::vector<std::pair<std::size_t, Ev>> pending_messages;  // (index into blocks, message)
  try {
    while (!p.ended() && std::getline(in, line)) {
      const std::size_t before = blocks.size();
      const int tool_before = p.modal_state().tool;
      p.parse_line(line, blocks);
      // Messages come first in their line (LinuxCNC executes the comment before anything else).
      for (const auto& msg : p.take_messages()) {
        if (msg.kind != contour::control::Message::Kind::kMsg && msg.kind != contour::control::Message::Kind::kDebug) continue;
        Ev e;
        e.kind = Ev::Kind::kMessage;
        e.line = msg.line;
        e.text = msg.text;
        pending_messages.push_back({msg.out_index, e});
      }
      bool tool_change = p.modal_state().tool != tool_before;
      for (std::size_t i = before; i < blocks.size(); ++i) {
        const Block& b = blocks[i];
        if (b.kind == BlockKind::kToolChange) tool_change = true;
        if (b.kind != BlockKind::kMotion) continue;
        last_motion = b;
        if (b.seg.kind == contour::control::PathSegment::Kind::kLine) last_straight = b;
      }
      if (!tool_change || p.ended()) continue;
      const auto st = p.modal_state();
      Frame cur;
      cur.g5x = st.work_offset_mm;
      cur.g92 = st.g92_offset_mm;
      cur.tlo = st.tool_offset_mm;
      cur.rot = st.xy_rotation_deg;
      if (refresh == Refresh::kModule) {
        const Vector3d prog = last_straight ? contour::control::work_coordinates(*last_straight, last_straight->seg.end)
                                            : Vector3d::Zero();
        p.set_position_mm(cur.to_machine(prog.x(), prog.y(), prog.z()));
      } else {
        const Vector3d tlo_then = last_motion ? last_motion->tool_offset_mm : Vector3d::Zero();
        p.set_position_mm(p.position_mm() + st.tool_offset_mm - tlo_then);
      }
    }
    if (!p.ended()) p.finish(blocks);
  } catch (const GcodeError& e) {
    r.rejected = true;
    r.line = e.line();
    r.message = e.what();
    const std::string w = e.what();
    r.file = w.substr(0, w.find(':' + std::to_string(e.line()) + ':'));
  }
  std::size_t next_msg = 0;
  for (std::size_t bi = 0; bi <= blocks.size(); ++bi) {
    while (next_msg < pending_messages.size() && pending_messages[next_msg].first == bi)
      r.events.push_back(pending_messages[next_msg++].second);
    if (bi == blocks.size()) break;
    const Block& b = blocks[bi];
    Ev e;
    e.line = b.line;
    e.spindle = b.spindle == SpindleDir::kCw ? 1 : b.spindle == SpindleDir::kCcw ? -1 : 0;
    e.rpm = b.spindle_rpm;
    e.mist = b.mist;
    e.flood = b.flood;
    switch (b.kind) {
      case BlockKind::kMotion:
        if (b.seg.kind == contour::control::PathSegment::Kind::kLine) {
          e.kind = b.rapid ? Ev::Kind::kTraverse : Ev::Kind::kFeed;
          e.end = b.seg.end;
          if (!b.rapid) e.feed = b.feed_mm_min;
        } else {
          e.kind = Ev::Kind::kArc;
          e.end = b.seg.end;
          e.plane = b.seg.plane == Plane::kXY ? 1 : b.seg.plane == Plane::kZX ? 3 : 2;
          const PlaneAxes pa = contour::control::plane_axes(b.seg.plane);
          e.c1 = b.seg.center[pa.a];
          e.c2 = b.seg.center[pa.b];
          e.rot = (b.seg.ccw ? 1 : -1) * (b.seg.turns + 1);
          e.feed = b.feed_mm_min;
        }
        break;
      case BlockKind::kDwell:
        if (b.user_m != 0) {
          e.kind = Ev::Kind::kUserM;
          e.ivalue = b.user_m;
          e.value = b.user_p;
          e.value2 = b.user_q;
        } else {
          e.kind = Ev::Kind::kDwell;
          e.value = b.dwell_s;
        }
        break;
      case BlockKind::kToolChange:
        e.kind = Ev::Kind::kTool;
        e.ivalue = b.tool;
        break;
      case BlockKind::kProgramStop:
        e.kind = Ev::Kind::kStop;
        break;
      case BlockKind::kOptionalStop:
        e.kind = Ev::Kind::kOptStop;
        break;
      case BlockKind::kEnd:
        continue;
    }
    r.events.push_back(e);
  }
  return r;
}

// ---- comparison

bool near(double a, double b, double tol) { return std::abs(a - b) <= tol; }

// Compares one event; `tol` in mm for positions; `with_state` also compares spindle/coolant and
// stops (rs274 has them, the module does not); `with_lines` compares source lines (module).
std::string diff_event(const Ev& a, const Ev& b, double tol, double feed_tol, bool with_state, bool with_lines) {
  if (a.kind != b.kind) return "different call";
  if (with_lines && a.line != b.line) return "different line";
  switch (a.kind) {
    case Ev::Kind::kArc:
      if (a.plane != b.plane) return "different plane";
      if (a.rot != b.rot) return "different direction or turns";
      if (!near(a.c1, b.c1, tol) || !near(a.c2, b.c2, tol)) return "different arc centre";
      [[fallthrough]];
    case Ev::Kind::kTraverse:
    case Ev::Kind::kFeed:
      for (int i = 0; i < 3; ++i)
        if (!near(a.end[i], b.end[i], tol)) return "different end point";
      if (a.kind != Ev::Kind::kTraverse && !near(a.feed, b.feed, feed_tol * std::max(1.0, std::abs(b.feed))))
        return "different feed";
      break;
    case Ev::Kind::kDwell:
      if (!near(a.value, b.value, 1e-9)) return "different dwell";
      break;
    case Ev::Kind::kTool:
      if (a.ivalue != b.ivalue) return "different tool";
      break;
    case Ev::Kind::kMessage:
      if (a.text != b.text) return "different message text";
      break;
    case Ev::Kind::kUserM:
      if (a.ivalue != b.ivalue || !near(a.value, b.value, 1e-9) || !near(a.value2, b.value2, 1e-9))
        return "different user M-code";
      break;
    default:
      break;
  }
  if (with_state) {
    if (a.spindle != b.spindle) return "different spindle direction";
    if (!near(a.rpm, b.rpm, 1e-3)) return "different spindle speed";
    if (a.mist != b.mist || a.flood != b.flood) return "different coolant";
  }
  return "";
}

// First difference between two event lists ("" when equal). Module comparisons ignore the
// calls the module does not report (stops).
std::string diff_lists(const std::vector<Ev>& ours, const std::vector<Ev>& ref, const char* ref_name,
                       double tol, double feed_tol, bool with_state, bool with_lines) {
  std::vector<Ev> a, b;
  for (const auto& e : ours)
    if ((with_state || (e.kind != Ev::Kind::kStop && e.kind != Ev::Kind::kOptStop)) &&
        !(with_state && e.kind == Ev::Kind::kMessage))
      a.push_back(e);
  for (const auto& e : ref)
    if ((with_state || (e.kind != Ev::Kind::kStop && e.kind != Ev::Kind::kOptStop)) &&
        !(with_state && e.kind == Ev::Kind::kMessage))
      b.push_back(e);
  const std::size_t n = std::min(a.size(), b.size());
  for (std::size_t i = 0; i < n; ++i) {
    const std::string d = diff_event(a[i], b[i], tol, feed_tol, with_state, with_lines);
    if (!d.empty())
      return d + " at call " + std::to_string(i + 1) + "\n    contourd: " + describe(a[i]) + "\n    " +
             ref_name + ": " + describe(b[i]);
  }
  if (a.size() != b.size()) {
    std::string s = "contourd has " + std::to_string(a.size()) + " calls, " + ref_name + " " + std::to_string(b.size());
    if (a.size() > n) s += "\n    contourd: " + describe(a[n]) + "\n    " + ref_name + ": (none)";
    else s += std::string("\n    contourd: (none)\n    ") + ref_name + ": " + describe(b[n]);
    return s;
  }
  return "";
}

int run_shell(const std::string& cmd) {
  const int rc = std::system(cmd.c_str());
  if (rc == -1) return -1;
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : 128;
}

std::string to_inch_var(const MachineContext& m) {
  MachineContext in = m;
  // rs274's user units are inches: lengths of the .var file in inches (rotations stay degrees).
  for (int k : in.persistent) {
    const bool rotation = k >= 5230 && k <= 5390 && (k - 5230) % 20 == 0;
    const bool flag = k == 5210 || k == 5220;
    const bool abc = (k >= 5164 && k <= 5166) || (k >= 5184 && k <= 5186) || (k >= 5214 && k <= 5216) ||
                     (k > 5220 && k <= 5390 && ((k - 5201) % 20 >= 3 && (k - 5201) % 20 <= 5));
    if (!rotation && !flag && !abc) in.parameters[static_cast<std::size_t>(k)] /= 25.4;
  }
  return contour::control::format_var_file(in);
}

std::string to_inch_tbl(std::vector<ToolData> t) {
  for (auto& d : t) {
    d.diameter_mm /= 25.4;
    for (std::size_t i : {0u, 1u, 2u, 6u, 7u, 8u}) d.offset[i] /= 25.4;
  }
  return contour::control::format_tool_table(t);
}

}  // namespace

int main(int argc, char** argv) {
  std::string var_path, tbl_path, subdir;
  std::string rs274 = "/usr/bin/rs274";
  std::string python = "/usr/bin/python3";
  std::string script = CONTOUR_GCODE_REF_SCRIPT;
  bool verbose = false;
  bool final_position = false;
  std::vector<std::string> programs;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "contour-gcode-diff: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--var") var_path = next();
    else if (a == "--tbl") tbl_path = next();
    else if (a == "--subroutines") subdir = next();
    else if (a == "--rs274") rs274 = next();
    else if (a == "--python") python = next();
    else if (a == "--ref-script") script = next();
    else if (a == "--verbose" || a == "-v") verbose = true;
    else if (a == "--final") final_position = true;
    else if (a == "--help" || a == "-h") {
      std::cout << "usage: contour-gcode-diff [--var F.var] [--tbl F.tbl] [--subroutines DIR] "
                   "[--rs274 PATH] [--python PATH] [--ref-script PATH] [--verbose] [--final] PROGRAM...\n";
      return 0;
    } else if (!a.empty() && a[0] == '-') {
      std::cerr << "contour-gcode-diff: unknown option " << a << "\n";
      return 2;
    } else {
      char real[4096];
      programs.push_back(::realpath(a.c_str(), real) ? std::string(real) : a);
    }
  }
  if (programs.empty()) {
    std::cerr << "contour-gcode-diff: no programs given\n";
    return 2;
  }
  if (!executable(rs274)) {
    std::cerr << "contour-gcode-diff: SKIP: LinuxCNC's interpreter " << rs274
              << " is not installed (package linuxcnc-uspace, tools/deps.d/linuxcnc.list)\n";
    return 77;
  }
  if (!executable(python) ||
      run_shell(quote(python) + " -c 'import gcode' >/dev/null 2>&1") != 0) {
    std::cerr << "contour-gcode-diff: SKIP: " << python
              << " cannot import LinuxCNC's `gcode` module (package linuxcnc-uspace)\n";
    return 77;
  }
  if (::access(script.c_str(), R_OK) != 0) {
    std::cerr << "contour-gcode-diff: reference script " << script << " not found\n";
    return 2;
  }
  // The machine both sides run: .var and .tbl in mm.
  const std::string var_text = var_path.empty() ? std::string(kDefaultVar) : read_file(var_path);
  const std::string tbl_text = tbl_path.empty() ? std::string(kDefaultTbl) : read_file(tbl_path);
  MachineContext machine;
  try {
    contour::control::apply_var_file(machine, contour::control::parse_var_file(var_text, var_path.empty() ? "<built-in var>" : var_path));
    machine.tools = contour::control::parse_tool_table(tbl_text, tbl_path.empty() ? "<built-in tbl>" : tbl_path);
  } catch (const std::exception& e) {
    std::cerr << "contour-gcode-diff: " << e.what() << "\n";
    return 2;
  }
  char tmpl[] = "/tmp/contour-gcode-diff.XXXXXX";
  const char* dir = ::mkdtemp(tmpl);
  if (dir == nullptr) {
    std::perror("contour-gcode-diff: mkdtemp");
    return 2;
  }
  const std::string tmp = dir;
  const std::string mm_tbl = tmp + "/mm.tbl";
  const std::string in_tbl = tmp + "/inch.tbl";
  write_file(mm_tbl, contour::control::format_tool_table(machine.tools));
  write_file(in_tbl, to_inch_tbl(machine.tools));
  std::string ini;
  if (!subdir.empty()) {
    char real[4096];
    const std::string abs = ::realpath(subdir.c_str(), real) ? std::string(real) : subdir;
    ini = tmp + "/machine.ini";
    write_file(ini, "[RS274NGC]\nSUBROUTINE_PATH = " + abs + "\n");
  }

  int n = 0, identical = 0, both = 0, mismatched = 0, only_ours = 0, only_theirs = 0, diff_moves = 0, rs_differs = 0;
  for (const auto& prog : programs) {
    ++n;
    // Per-program switches: a line "; conformance: block-delete" in the program.
    const std::string text = read_file(prog);
    const bool block_delete = text.find("; conformance: block-delete") != std::string::npos;
    const bool user_m = [&] {
      for (const auto& l : split_lines(text)) {
        std::string u;
        for (char c : l) {
          if (c == ';' || c == '(') break;
          if (!std::isspace(static_cast<unsigned char>(c))) u += static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
        }
        for (std::size_t p = u.find("M1"); p != std::string::npos; p = u.find("M1", p + 1)) {
          const bool word_start = p == 0 || !std::isdigit(static_cast<unsigned char>(u[p - 1]));
          if (word_start && p + 3 < u.size() + 0 && std::isdigit(static_cast<unsigned char>(u[p + 2])) &&
              std::isdigit(static_cast<unsigned char>(u[p + 3])))
            return true;
        }
      }
      return false;
    }();
    // Parameters in user units (#5161-#5390 offsets and positions, #5401-#5413 tool data): rs274's
    // machine is an inch machine, so its moves differ from a metric machine's when a program reads
    // them; its verdict still counts.
    const bool user_unit_params = [&] {
      for (std::size_t p = text.find('#'); p != std::string::npos; p = text.find('#', p + 1)) {
        std::size_t q = p + 1;
        while (q < text.size() && text[q] == ' ') ++q;
        const int v = std::atoi(text.c_str() + q);
        if ((v >= 5161 && v <= 5390) || (v >= 5401 && v <= 5413)) return true;
      }
      return false;
    }();
    write_file(tmp + "/mm.var", contour::control::format_var_file(machine));
    write_file(tmp + "/inch.var", to_inch_var(machine));
    const std::string env = "cd " + quote(tmp) + " && HOME=" + quote(tmp) + (ini.empty() ? "" : " INI_FILE_NAME=" + quote(ini));
    // rs274 -g: batch mode; tool table and parameters in inches (its user units).
    const int rc_rs = run_shell(env + " timeout 120 " + quote(rs274) + " -g -t inch.tbl -v inch.var" +
                                (ini.empty() ? "" : " -i " + quote(ini)) + (block_delete ? " -b" : "") + " " +
                                quote(prog) + " > rs274.out 2> rs274.err < /dev/null");
    const Rs274Result rs = parse_rs274(read_file(tmp + "/rs274.out"), read_file(tmp + "/rs274.err"), rc_rs, machine.tools);
    ::unlink((tmp + "/.tool.mmap").c_str());
    const int rc_py = run_shell(env + " timeout 120 " + quote(python) + " " + quote(script) +
                                " --var mm.var --tbl mm.tbl" + (block_delete ? " --block-delete" : "") + " " +
                                quote(prog) + " > module.out 2> module.err < /dev/null");
    const RefResult mod = parse_module(read_file(tmp + "/module.out"), machine.tools);
    ::unlink((tmp + "/.tool.mmap").c_str());
    const OurResult ours = run_contourd(prog, machine, subdir, block_delete, Refresh::kModule);
    if (std::getenv("CONTOUR_GCODE_DIFF_KEEP") != nullptr) {
      std::ofstream d(tmp + "/contourd.events");
      for (const auto& e : ours.events) d << describe(e) << "\n";
      std::ofstream m(tmp + "/module.events");
      for (const auto& e : mod.events) m << describe(e) << "\n";
    }
    if (rc_py != 0 || !mod.ran) {
      ++mismatched;
      std::cout << "MISMATCH " << prog << ": LinuxCNC's interpreter module failed (exit " << rc_py << "): "
                << read_file(tmp + "/module.err") << "\n";
      continue;
    }
    // LinuxCNC's verdict is the module's: like contourd it runs a metric machine (rs274's machine
    // is an inch machine: #5400-#5413, #5161-#5390 and G10 L1 values are in inches there) with a
    // user M-code handler for M100-M199 (rs274 has none). rs274, when it agrees, confirms the
    // verdict, gives the text of the failing line, and checks spindle, coolant and stops.
    const bool lcnc_rejected = mod.rejected;
    if (final_position && !lcnc_rejected) {
      const Ev* last = nullptr;
      for (const auto& e : mod.events) {
        if (e.kind == Ev::Kind::kTraverse || e.kind == Ev::Kind::kFeed || e.kind == Ev::Kind::kArc) last = &e;
      }
      if (last != nullptr) {
        char b[256];
        std::snprintf(b, sizeof b, "%.9f %.9f %.9f", last->end.x(), last->end.y(), last->end.z());
        std::cout << "FINAL " << prog << " " << b << "\n";
      }
    }
    const bool rs_agrees = !user_m && rs.rejected == mod.rejected;
    if (!rs_agrees) {
      ++rs_differs;
      if (verbose)
        std::cout << "NOTE " << prog << ": rs274 " << (user_m ? "has no user M-codes" : (rs.rejected ? "rejects: " + rs.error : "accepts"))
                  << "; checked against LinuxCNC's module only\n";
    }
    std::string problem;
    if (lcnc_rejected && !ours.rejected) {
      ++only_theirs;
      problem = "rejected only by LinuxCNC: line " + std::to_string(mod.line) + ": " + mod.message +
                (rs_agrees ? " at '" + rs.line_text + "'" : "");
    } else if (!lcnc_rejected && ours.rejected) {
      ++only_ours;
      problem = "rejected only by contourd: " + ours.message;
    } else if (lcnc_rejected) {
      // Same line: rs274 prints the failing line's text, which must be contourd's error line;
      // without rs274, the module's line number (the line after the last line that made a call
      // for errors found while reading, else that line).
      std::string our_text;
      {
        const std::string f = ours.file == prog ? prog : (subdir.empty() ? ours.file : subdir + "/" + ours.file);
        const auto lines = split_lines(read_file(f));
        if (ours.line >= 1 && ours.line <= static_cast<int>(lines.size()))
          our_text = rtrim(lines[static_cast<std::size_t>(ours.line - 1)]);
      }
      const std::string ref_text = rtrim(rs.line_text);
      // The module counts an error found at the end of the file on the line after the last one.
      const bool eof_error = mod.message.find("File ended") != std::string::npos;
      const bool same_line = rs_agrees ? our_text == ref_text : (ours.line == mod.line || (eof_error && ours.line + 1 == mod.line));
      if (!same_line) {
        ++diff_moves;
        problem = "rejected by both on different lines\n    contourd: " + ours.message + "  ('" + our_text + "')\n    " +
                  (rs_agrees ? "rs274: " + rs.error + " ('" + ref_text + "')"
                             : "LinuxCNC: line " + std::to_string(mod.line) + ": " + mod.message);
      }
    }
    if (problem.empty()) {
      // Moves: the module at 1e-6 mm with lines; rs274 at its print precision with machine state.
      std::string d = diff_lists(ours.events, mod.events, "LinuxCNC", 1e-6, 1e-9, false, true);
      if (d.empty() && rs_agrees && !rs.rejected && !user_unit_params) {
        const OurResult ours0 = run_contourd(prog, machine, subdir, block_delete, Refresh::kRs274);
        d = diff_lists(ours0.events, rs.events, "rs274", 4e-4 * 25.4, 1e-4, true, false);
      }
      if (!d.empty()) {
        ++diff_moves;
        problem = d;
      }
    }
    if (!problem.empty()) {
      ++mismatched;
      std::cout << "MISMATCH " << prog << ": " << problem << "\n";
    } else if (lcnc_rejected) {
      ++both;
      std::cout << "REJECTED-BOTH " << prog << ": " << ours.message << "\n";
    } else {
      ++identical;
      if (verbose) std::cout << "OK " << prog << " (" << ours.events.size() << " calls)\n";
    }
  }
  if (std::getenv("CONTOUR_GCODE_DIFF_KEEP") != nullptr) std::cerr << "contour-gcode-diff: kept " << tmp << "\n";
  else run_shell("rm -rf " + quote(tmp));
  std::cout << "conformance: " << n << " programs, " << identical << " identical, " << both
            << " rejected by both, " << mismatched << " mismatched (" << only_ours
            << " rejected only by contourd, " << only_theirs << " rejected only by LinuxCNC, " << diff_moves
            << " with different moves or error lines); rs274 confirmed " << (n - rs_differs) << " of " << n << "\n";
  return mismatched == 0 ? 0 : 1;
}
