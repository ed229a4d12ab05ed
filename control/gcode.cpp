#include "control/gcode.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>

namespace contour::control {

namespace {
std::string fmt_num(double v) {
  char buf[32];
  auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 6);
  return std::string(buf, r.ptr);
}

std::string g_name(int g10) {
  std::string s = "G" + std::to_string(g10 / 10);
  if (g10 % 10 != 0) s += "." + std::to_string(g10 % 10);
  return s;
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

char upper(char c) { return (c >= 'a' && c <= 'z') ? static_cast<char>(c - 'a' + 'A') : c; }

// Modal groups (RS274/NGC table 4); -1 = unsupported (message given at lookup).
int g_group(int g10) {
  switch (g10) {
    case 0: case 10: case 20: case 30: case 800: return 1;
    case 40: case 280: case 300: case 530: return 0;
    case 170: case 180: case 190: return 2;
    case 900: case 910: return 3;
    case 901: case 911: return 4;
    case 940: return 5;
    case 200: case 210: return 6;
    case 400: return 7;
    case 430: case 490: return 8;
    case 540: case 550: case 560: case 570: case 580: case 590: return 12;
    case 610: case 611: case 640: return 13;
    default: return -1;
  }
}

std::string unsupported_g(int g10) {
  const std::string n = g_name(g10);
  if (g10 == 410 || g10 == 420 || g10 == 411 || g10 == 421)
    return n + ": cutter radius compensation is not supported (program the tool-centre path)";
  if (g10 >= 730 && g10 <= 890 && g10 != 800) return n + ": canned cycles are not supported";
  if (g10 == 100) return "G10: setting offsets from the program is not supported (use the YAML program: section)";
  if (g10 >= 920 && g10 <= 923) return n + ": coordinate system offsets are not supported";
  if (g10 == 930 || g10 == 950) return n + ": only G94 (units per minute) feed mode is supported";
  if (g10 == 980 || g10 == 990) return n + ": canned-cycle return modes are not supported";
  return n + " is not supported";
}

int m_group(int m) {
  switch (m) {
    case 0: case 1: case 2: case 30: return 4;
    case 3: case 4: case 5: return 7;
    case 6: return 6;
    case 7: case 8: case 9: return 8;
    default: return -1;
  }
}
}  // namespace

GcodeError::GcodeError(const std::string& file, int line, int column, const std::string& message)
    : std::runtime_error(file + ":" + std::to_string(line) + ":" + std::to_string(column) + ": " +
                         message),
      line_(line),
      column_(column) {}

GcodeParser::GcodeParser(ProgramSetup setup, std::string file_name)
    : setup_(std::move(setup)),
      file_(std::move(file_name)),
      pos_(setup_.start_mm),
      blend_(setup_.default_blend),
      tolerance_mm_(setup_.default_tolerance_mm) {}

void GcodeParser::fail(int column, const std::string& msg) const {
  throw GcodeError(file_, line_, column, msg);
}

Eigen::Vector3d GcodeParser::offset_mm() const {
  Eigen::Vector3d o = setup_.work_offsets_mm[static_cast<std::size_t>(work_)];
  o.z() += tool_length_mm_;
  return o;
}

Block GcodeParser::base_block() const {
  Block b;
  b.line = line_;
  b.blend = blend_;
  b.tolerance_mm = tolerance_mm_;
  b.spindle = spindle_;
  b.spindle_rpm = rpm_;
  b.mist = mist_;
  b.flood = flood_;
  b.tool = tool_;
  b.feed_mm_min = feed_mm_min_;
  return b;
}

void GcodeParser::parse_line(std::string_view text, std::vector<Block>& out) {
  ++line_;
  if (ended_) return;
  words_.clear();
  const int n = static_cast<int>(text.size());
  int i = 0;
  auto col = [&](int at) { return at + 1; };
  while (i < n && is_space(text[static_cast<std::size_t>(i)])) ++i;
  if (i < n && text[static_cast<std::size_t>(i)] == '%') {
    // Tape marker: the first opens the program, the second ends it.
    for (int j = i + 1; j < n; ++j) {
      const char c = text[static_cast<std::size_t>(j)];
      if (c == ';') break;
      if (!is_space(c)) fail(col(j), "text after '%' tape marker");
    }
    ++percent_count_;
    if (percent_count_ == 2 || (percent_count_ == 1 && content_seen_)) {
      ended_ = true;
      Block b = base_block();
      b.kind = BlockKind::kEnd;
      b.seg = PathSegment::line(pos_, pos_);
      out.push_back(b);
    }
    return;
  }
  if (i < n && text[static_cast<std::size_t>(i)] == '/') fail(col(i), "block delete '/' is not supported");
  while (i < n) {
    const char c = text[static_cast<std::size_t>(i)];
    if (is_space(c)) {
      ++i;
      continue;
    }
    if (c == ';') break;
    if (c == '(') {
      const int start = i;
      ++i;
      while (i < n && text[static_cast<std::size_t>(i)] != ')') {
        if (text[static_cast<std::size_t>(i)] == '(') fail(col(i), "nested comment");
        ++i;
      }
      if (i >= n) fail(col(start), "unterminated comment");
      ++i;
      continue;
    }
    const char L = upper(c);
    const int wcol = col(i);
    if (L == '#') fail(wcol, "parameters ('#') are not supported");
    if (L == '[') fail(wcol, "expressions ('[') are not supported");
    if (L == 'O') fail(wcol, "O-words (subroutines, loops, conditionals) are not supported");
    if (L < 'A' || L > 'Z') fail(wcol, std::string("unexpected character '") + c + "'");
    static constexpr std::string_view kKnown = "GMFSTHPNXYZIJKRQDL";
    if (kKnown.find(L) == std::string_view::npos) {
      if (std::string_view("ABCUVW").find(L) != std::string_view::npos)
        fail(wcol, std::string("axis ") + L + " is not configured (contourd has X Y Z)");
      fail(wcol, std::string("word '") + L + "' is not supported");
    }
    ++i;
    // Number: optional spaces anywhere, sign, digits, one point.
    std::string num;
    bool digits = false;
    bool point = false;
    while (i < n) {
      const char d = text[static_cast<std::size_t>(i)];
      if (is_space(d)) {
        ++i;
        continue;
      }
      if ((d == '+' || d == '-') && num.empty()) {
        num += d;
      } else if (d >= '0' && d <= '9') {
        num += d;
        digits = true;
      } else if (d == '.' && !point) {
        num += d;
        point = true;
      } else {
        break;
      }
      ++i;
    }
    if (i < n && (text[static_cast<std::size_t>(i)] == '#' || text[static_cast<std::size_t>(i)] == '[') && !digits)
      fail(col(i), std::string(text[static_cast<std::size_t>(i)] == '#' ? "parameters ('#')" : "expressions ('[')") +
                       " are not supported");
    if (!digits) fail(wcol, std::string("word '") + L + "' has no number");
    double v = 0.0;
    const char* b = num.data();
    if (*b == '+') ++b;
    auto r = std::from_chars(b, num.data() + num.size(), v);
    if (r.ec != std::errc() || !std::isfinite(v)) fail(wcol, std::string("bad number for '") + L + "'");
    // No word of a real program exceeds 1e9 (mm, mm/min, rpm, s); bigger values only overflow the
    // planner's arithmetic downstream (fuzz regression gcode_fuzz/regression-1).
    if (std::abs(v) > 1e9) fail(wcol, std::string("number for '") + L + "' out of range (|value| > 1e9)");
    if (L != 'G' && L != 'M') {
      for (const auto& w : words_)
        if (w.letter == L) fail(wcol, std::string("word '") + L + "' appears twice on the line");
    }
    words_.push_back({L, v, wcol});
  }
  if (words_.empty()) return;
  content_seen_ = true;
  execute(words_, out);
}

void GcodeParser::execute(const std::vector<Word>& words, std::vector<Block>& out) {
  // Collect G and M codes by modal group.
  std::array<int, 14> g{};
  std::array<int, 14> gcol{};
  g.fill(-1);
  std::array<int, 9> m{};
  std::array<int, 9> mcol{};
  m.fill(-1);
  const Word* w_of[26] = {};
  for (const auto& w : words) {
    if (w.letter == 'G') {
      const double r = std::round(w.value * 10.0);
      // Range first: casting an out-of-range double to int is undefined (fuzz regression-2).
      if (!(r >= 0.0 && r <= 10000.0) || std::abs(w.value * 10.0 - r) > 1e-6)
        fail(w.column, "bad G code " + fmt_num(w.value));
      const int g10 = static_cast<int>(r);
      const int grp = g_group(g10);
      if (grp < 0) fail(w.column, unsupported_g(g10));
      auto gi = static_cast<std::size_t>(grp);
      if (g[gi] >= 0)
        fail(w.column, g_name(g10) + " and " + g_name(g[gi]) + " are in the same modal group");
      g[gi] = g10;
      gcol[gi] = w.column;
    } else if (w.letter == 'M') {
      if (w.value != std::floor(w.value) || w.value < 0 || w.value > 1e6) fail(w.column, "bad M code " + fmt_num(w.value));
      const int mc = static_cast<int>(w.value);
      const int grp = m_group(mc);
      if (grp < 0) fail(w.column, "M" + std::to_string(mc) + " is not supported");
      auto mi = static_cast<std::size_t>(grp);
      // M7 and M8 may share a line (both coolants on).
      if (m[mi] >= 0 && !(grp == 8 && mc != 9 && m[mi] != 9))
        fail(w.column, "M" + std::to_string(mc) + " and M" + std::to_string(m[mi]) + " are in the same modal group");
      if (grp == 8 && m[mi] >= 0) {
        mist_ = flood_ = true;
      }
      m[mi] = mc;
      mcol[mi] = w.column;
    } else {
      w_of[w.letter - 'A'] = &w;
    }
  }
  auto word = [&](char l) { return w_of[l - 'A']; };
  for (const char l : {'D', 'L'}) {
    if (const Word* w = word(l)) fail(w->column, std::string("word '") + l + "' is not supported");
  }
  const Word* wq = word('Q');
  if (wq != nullptr) {
    if (g[13] == 640) fail(wq->column, "G64 Q (naive CAM detector) is not supported");
    fail(wq->column, "word 'Q' is only used by unsupported codes");
  }
  // Axis words and whether this line moves.
  const Word* ax[3] = {word('X'), word('Y'), word('Z')};
  const bool has_axes = ax[0] || ax[1] || ax[2];

  // Order of execution (RS274/NGC 3.8).
  if (g[5] == 940) { /* G94: the only feed mode */ }
  if (const Word* f = word('F')) {
    if (f->value < 0) fail(f->column, "negative feed");
    feed_mm_min_ = f->value * units_;
    if (g[6] == 200) feed_mm_min_ = f->value * 25.4;
    if (g[6] == 210) feed_mm_min_ = f->value;
  }
  if (const Word* s = word('S')) {
    if (s->value < 0) fail(s->column, "negative spindle speed");
    rpm_ = s->value;
  }
  if (const Word* t = word('T')) {
    if (t->value < 0 || t->value != std::floor(t->value)) fail(t->column, "T must be a non-negative integer");
    selected_tool_ = static_cast<int>(t->value);
  }
  if (m[6] == 6) {
    Block b = base_block();
    b.kind = BlockKind::kToolChange;
    b.seg = PathSegment::line(pos_, pos_);
    b.message = "manual tool change: insert tool " + std::to_string(selected_tool_) + ", then resume";
    tool_ = selected_tool_;
    b.tool = tool_;
    out.push_back(b);
  }
  if (m[7] == 3) spindle_ = SpindleDir::kCw;
  if (m[7] == 4) spindle_ = SpindleDir::kCcw;
  if (m[7] == 5) spindle_ = SpindleDir::kOff;
  if (m[8] == 7) mist_ = true;
  if (m[8] == 8) flood_ = true;
  if (m[8] == 9) mist_ = flood_ = false;
  const Word* wp = word('P');
  if (g[0] == 40) {
    if (wp == nullptr) fail(gcol[0], "G4 needs P (dwell seconds)");
    if (wp->value < 0) fail(wp->column, "negative dwell");
    Block b = base_block();
    b.kind = BlockKind::kDwell;
    b.seg = PathSegment::line(pos_, pos_);
    b.dwell_s = wp->value;
    out.push_back(b);
  }
  if (g[2] == 170) plane_ = Plane::kXY;
  if (g[2] == 180) plane_ = Plane::kZX;
  if (g[2] == 190) plane_ = Plane::kYZ;
  if (g[6] == 200) units_ = 25.4;
  if (g[6] == 210) units_ = 1.0;
  if (g[8] == 490) tool_length_mm_ = 0.0;
  const Word* wh = word('H');
  if (wh != nullptr && g[8] != 430) fail(wh->column, "H word without G43");
  if (g[8] == 430) {
    int h = tool_;
    if (wh != nullptr) {
      if (wh->value < 0 || wh->value != std::floor(wh->value)) fail(wh->column, "H must be a non-negative integer");
      h = static_cast<int>(wh->value);
    }
    auto it = std::find_if(setup_.tools.begin(), setup_.tools.end(),
                           [h](const ToolEntry& e) { return e.number == h; });
    if (it == setup_.tools.end())
      fail(wh ? wh->column : gcol[8], "G43: tool " + std::to_string(h) + " is not in the tool table (program.tools)");
    tool_length_mm_ = it->length_mm;
  }
  if (g[12] >= 0) work_ = (g[12] - 540) / 10;
  if (g[13] == 610 || g[13] == 611) blend_ = BlendMode::kExactStop;
  if (g[13] == 640) {
    if (wp != nullptr) {
      if (wp->value <= 0) fail(wp->column, "G64 P tolerance must be > 0");
      blend_ = BlendMode::kLimited;
      tolerance_mm_ = wp->value * units_;
    } else {
      blend_ = BlendMode::kFull;
    }
  }
  if (g[3] == 900) absolute_ = true;
  if (g[3] == 910) absolute_ = false;
  if (g[4] == 901) arc_absolute_ = true;
  if (g[4] == 911) arc_absolute_ = false;
  if (wp != nullptr && g[0] != 40 && g[13] != 640 && !(g[1] == 20 || g[1] == 30 || ((g[1] < 0) && (motion_ == 20 || motion_ == 30) && has_axes)))
    fail(wp->column, "P word without G4, G64 or an arc");

  if (g[1] == 800) {
    if (has_axes) fail(gcol[1], "G80 with axis words");
    motion_ = -1;
  } else if (g[1] >= 0) {
    motion_ = g[1];
  }
  const Eigen::Vector3d off = offset_mm();
  auto target_from_words = [&](bool machine) {
    Eigen::Vector3d prog = pos_ - (machine ? Eigen::Vector3d::Zero() : off);
    for (int a = 0; a < 3; ++a) {
      if (ax[a] == nullptr) continue;
      const double v = ax[a]->value * units_;
      prog[a] = (absolute_ || machine) ? v : prog[a] + v;
    }
    return Eigen::Vector3d(prog + (machine ? Eigen::Vector3d::Zero() : off));
  };
  auto emit_line = [&](const Eigen::Vector3d& to, bool rapid) {
    Block b = base_block();
    b.kind = BlockKind::kMotion;
    b.rapid = rapid;
    b.feed_mm_min = rapid ? setup_.rapid_mm_min : feed_mm_min_;
    b.seg = PathSegment::line(pos_, to);
    out.push_back(b);
    pos_ = to;
  };
  for (const char l : {'I', 'J', 'K', 'R'}) {
    const Word* w = word(l);
    if (w != nullptr && !((g[1] == 20 || g[1] == 30) || (g[1] < 0 && (motion_ == 20 || motion_ == 30))))
      fail(w->column, std::string("word '") + l + "' without G2/G3");
  }

  if (g[0] == 280 || g[0] == 300) {
    const Eigen::Vector3d ref = g[0] == 280 ? setup_.g28_mm : setup_.g30_mm;
    if (has_axes) {
      emit_line(target_from_words(false), true);
      Eigen::Vector3d to = pos_;
      for (int a = 0; a < 3; ++a)
        if (ax[a] != nullptr) to[a] = ref[a];
      emit_line(to, true);
    } else {
      emit_line(ref, true);
    }
  } else if (g[0] == 530) {
    if (!(motion_ == 0 || motion_ == 10)) fail(gcol[0], "G53 needs G0 or G1");
    if (!absolute_) fail(gcol[0], "G53 is not allowed with G91");
    if (motion_ == 10 && feed_mm_min_ <= 0) fail(gcol[0], "G1 without feed: no F word programmed yet");
    if (has_axes) emit_line(target_from_words(true), motion_ == 0);
  } else if (has_axes || (motion_ == 20 || motion_ == 30 ? (word('I') || word('J') || word('K') || word('R')) && g[1] >= 0 : false)) {
    if (motion_ < 0) fail(ax[0] ? ax[0]->column : (ax[1] ? ax[1]->column : (ax[2] ? ax[2]->column : 1)), "axis words without a motion mode (G0/G1/G2/G3)");
    const int mcol_motion = g[1] >= 0 ? gcol[1] : 1;
    if (motion_ != 0 && feed_mm_min_ <= 0)
      fail(word('F') ? word('F')->column : mcol_motion, g_name(motion_) + " without feed: no F word programmed yet");
    const Eigen::Vector3d to = target_from_words(false);
    if (motion_ == 0 || motion_ == 10) {
      emit_line(to, motion_ == 0);
    } else {
      const PlaneAxes pa = plane_axes(plane_);
      const char in_plane[3] = {"IJK"[pa.a], "IJK"[pa.b], "IJK"[pa.n]};
      const Word* wr = word('R');
      const Word* wi = word(in_plane[0]);
      const Word* wj = word(in_plane[1]);
      if (const Word* wn = word(in_plane[2]))
        fail(wn->column, std::string("word '") + in_plane[2] + "' is not in the arc plane");
      PathSegment s;
      s.kind = PathSegment::Kind::kArc;
      s.start = pos_;
      s.end = to;
      s.plane = plane_;
      s.ccw = motion_ == 30;
      if (wp != nullptr) {
        if (wp->value < 1 || wp->value != std::floor(wp->value)) fail(wp->column, "arc P (turns) must be an integer >= 1");
        s.turns = static_cast<int>(wp->value) - 1;
      }
      const double ca = pos_[pa.a], cb = pos_[pa.b];
      const double ea = to[pa.a], eb = to[pa.b];
      const int acol = mcol_motion;
      if (wr != nullptr) {
        if (wi || wj) fail(wr->column, "arc with both R and I/J/K");
        const double rr = wr->value * units_;
        const double dx = ea - ca, dy = eb - cb;
        const double d = std::hypot(dx, dy);
        if (d < 1e-9) fail(wr->column, "R-form arc with start == end (full circle needs I/J/K)");
        if (std::abs(rr) < 1e-9) fail(wr->column, "zero-radius arc");
        const double half = d / 2.0;
        double h2 = rr * rr - half * half;
        if (h2 < 0) {
          if (half - std::abs(rr) > std::max(setup_.arc_tolerance_mm, 1e-3 * std::abs(rr)))
            fail(wr->column, "arc radius " + fmt_num(std::abs(rr)) + " mm is less than half the chord " + fmt_num(half) + " mm");
          h2 = 0.0;
        }
        const double h = std::sqrt(h2);
        // Centre left of the chord for a minor CCW arc; R < 0 asks for the major arc.
        double side = s.ccw ? 1.0 : -1.0;
        if (rr < 0) side = -side;
        s.center[pa.a] = ca + dx / 2.0 - side * h * dy / d;
        s.center[pa.b] = cb + dy / 2.0 + side * h * dx / d;
        s.center[pa.n] = pos_[pa.n];
      } else {
        if (!wi && !wj) fail(acol, "arc needs R or I/J/K");
        double ci = wi ? wi->value * units_ : 0.0;
        double cj = wj ? wj->value * units_ : 0.0;
        if (arc_absolute_) {
          ci = wi ? ci + off[pa.a] : ca;
          cj = wj ? cj + off[pa.b] : cb;
        } else {
          ci += ca;
          cj += cb;
        }
        s.center[pa.a] = ci;
        s.center[pa.b] = cj;
        s.center[pa.n] = pos_[pa.n];
        const double r0 = std::hypot(ca - ci, cb - cj);
        const double r1 = std::hypot(ea - ci, eb - cj);
        if (r0 < 1e-9 || r1 < 1e-9) fail(acol, "zero-radius arc");
        if (std::abs(r0 - r1) > std::max(setup_.arc_tolerance_mm, 1e-3 * r0))
          fail(acol, "arc radius mismatch: start radius " + fmt_num(r0) + " mm, end radius " + fmt_num(r1) + " mm");
      }
      Block b = base_block();
      b.kind = BlockKind::kMotion;
      b.seg = s;
      out.push_back(b);
      pos_ = to;
    }
  }
  if (m[4] == 0 || m[4] == 1) {
    Block b = base_block();
    b.kind = m[4] == 0 ? BlockKind::kProgramStop : BlockKind::kOptionalStop;
    b.seg = PathSegment::line(pos_, pos_);
    b.message = m[4] == 0 ? "program stop (M0): resume to continue" : "optional stop (M1)";
    out.push_back(b);
  }
  if (m[4] == 2 || m[4] == 30) {
    Block b = base_block();
    b.kind = BlockKind::kEnd;
    b.seg = PathSegment::line(pos_, pos_);
    out.push_back(b);
    ended_ = true;
  }
  (void)mcol;
}

void GcodeParser::finish(std::vector<Block>& out) {
  if (ended_) return;
  ended_ = true;
  Block b = base_block();
  b.kind = BlockKind::kEnd;
  b.seg = PathSegment::line(pos_, pos_);
  out.push_back(b);
}

}  // namespace contour::control
