// Driver and block execution of the RS274/NGC interpreter (LinuxCNC 2.9 semantics, see
// gcode_interp.hpp). Order of execution within a line follows LinuxCNC's execute_block:
// comment, feed mode, F, S, T, M (tool change, spindle, coolant, user M), G (dwell, plane, units,
// cutter comp, tool length offset, coordinate system, path control, distance modes, retract mode,
// group 0, G92.x, motion), stops.
#include "control/gcode_interp.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace contour::control::gcode_detail {

namespace {
constexpr double kMmPerInch = 25.4;
constexpr double kRadiusToleranceInch = 0.00005;                      // RADIUS_TOLERANCE_INCH
constexpr double kRadiusToleranceMm = kRadiusToleranceInch * kMmPerInch;  // RADIUS_TOLERANCE_MM
constexpr double kSpiralRelTolerance = 0.001;
constexpr double kTiny = 1e-12;
constexpr int kMaxLineChars = 252;  // LinuxCNC LINELEN 255: fgets of 254 incl. '\n' is "too long"

void rotate(double& x, double& y, double theta_deg) {
  const double t = theta_deg * (std::numbers::pi / 180.0);
  const double xx = x * std::cos(t) - y * std::sin(t);
  const double yy = x * std::sin(t) + y * std::cos(t);
  x = xx;
  y = yy;
}

std::string fmt(double v) { return format_fixed(v, 4); }

bool is_cycle(int motion) { return motion == g::k73 || (motion >= g::k81 && motion <= g::k89); }
}  // namespace

Interpreter::Interpreter(ProgramSetup setup, MachineContext machine, std::string file_name)
    : setup_(std::move(setup)), pos_mm_(setup_.start_mm) {
  params_ = machine.parameters;
  params_.resize(kParameterCount, 0.0);
  persistent_ = machine.persistent;
  // Index 0 is the spindle, 1..n the tools in table order (LinuxCNC non-random tool changer).
  tool_table_.resize(1);
  tool_table_[0].number = 0;
  for (const auto& t : machine.tools) tool_table_.push_back(t);
  if (machine.tool_in_spindle > 0) {
    for (std::size_t i = 1; i < tool_table_.size(); ++i) {
      if (tool_table_[i].number == machine.tool_in_spindle) {
        tool_table_[0] = tool_table_[i];
        current_pocket_ = static_cast<int>(i);
        canon_tool_ = machine.tool_in_spindle;
        break;
      }
    }
  }
  sources_.push_back(Source{std::move(file_name), {}, 1, true, false, false});
  frames_.emplace_back();
  init_named_parameters();
  params_[kParamDebug] = 1.0;  // LinuxCNC's init enables (DEBUG,...) output
  // LinuxCNC's init: active system, its origin and rotation, the G92 offset if applied.
  origin_index_ = static_cast<int>(params_[kParamCoordSystem] + 0.0001);
  if (origin_index_ < 1 || origin_index_ > 9) {
    origin_index_ = 1;
    params_[kParamCoordSystem] = 1.0;
  }
  load_origin(origin_index_);
  if (params_[kParamG92Applied] != 0.0) {
    for (int i = 0; i < 3; ++i) axis_off_[i] = user_to_program(params_[static_cast<std::size_t>(kParamG92 + i)]);
  }
  canon_g5x(origin_index_, origin_[0], origin_[1], origin_[2]);
  canon_g92(axis_off_[0], axis_off_[1], axis_off_[2]);
  canon_rotation(rotation_xy_);
  const Eigen::Vector3d p = from_machine(pos_mm_);
  for (int i = 0; i < 3; ++i) cur_[i] = prog_[i] = p[i];
  set_tool_parameters();
  switch (setup_.default_blend) {
    case BlendMode::kExactStop: control_mode_ = 1; break;
    case BlendMode::kFull: control_mode_ = 0; control_tolerance_ = 0.0; break;
    case BlendMode::kLimited: control_mode_ = 0; control_tolerance_ = setup_.default_tolerance_mm; break;
  }
  suppress_ = setup_.run_from_line > 0;
}

void Interpreter::load_origin(int system) {
  const std::size_t k = static_cast<std::size_t>(5200 + 20 * system);
  for (std::size_t i = 0; i < 3; ++i) origin_[i] = user_to_program(params_[k + 1 + i]);
  rotation_xy_ = params_[k + 10];
}

double Interpreter::user_to_program(double v) const { return units_ == Units::kInch ? v / kMmPerInch : v; }
double Interpreter::program_to_user(double v) const { return units_ == Units::kInch ? v * kMmPerInch : v; }

void Interpreter::fail(int column, const std::string& msg) const {
  const Source& s = sources_[static_cast<std::size_t>(cur_source_)];
  throw GcodeError(s.name, sequence_, column < 1 ? 1 : column, msg);
}

int Interpreter::word_col(char letter) const {
  const WordVal& w = blk_[letter];
  return w.set ? w.col : 1;
}

void Interpreter::fail_word(char letter, const std::string& msg) const { fail(word_col(letter), msg); }

const std::string& Interpreter::source_name(int id) const {
  return sources_.at(static_cast<std::size_t>(id)).name;
}

std::vector<Message> Interpreter::take_messages() {
  std::vector<Message> m;
  m.swap(messages_);
  return m;
}

// ---------------------------------------------------------------- driver

void Interpreter::push_line(std::string_view text, std::vector<Block>& out) {
  out_ = &out;
  ++pushed_lines_;
  if (ended_) return;
  if (!text.empty() && text.back() == '\n') text.remove_suffix(1);
  sources_[0].lines.emplace_back(text);
  run(out);
}

void Interpreter::finish(std::vector<Block>& out) {
  out_ = &out;
  sources_[0].eof = true;
  if (ended_) return;
  run(out);
}

void Interpreter::run(std::vector<Block>& out) {
  out_ = &out;
  while (!ended_) {
    Source& s = sources_[static_cast<std::size_t>(cur_source_)];
    if (!s.has(cur_line_)) {
      if (s.streaming && !s.eof) break;
      if (s.mdi) break;
      at_end_of_source();
      continue;
    }
    step_line(s, cur_line_);
    trim_main();
  }
}

// End of a source without M2/M30/'%': LinuxCNC's read_text errors at EOF; contourd ends the
// program when nothing is open and require_program_end is off.
void Interpreter::at_end_of_source() {
  const Source& s = sources_[static_cast<std::size_t>(cur_source_)];
  sequence_ = s.end_line() - 1;
  if (skipping_to_sub_on_)
    fail(1, "end of file " + s.name + " while looking for o<" + skipping_to_sub_ + "> (called at line " +
                std::to_string(skipping_start_) + ")");
  if (skipping_) fail(1, "end of file " + s.name + " inside o" + skipping_o_ + " (started at line " +
                             std::to_string(skipping_start_) + "): its end was not found");
  if (defining_sub_) fail(1, "end of file inside the definition of o<" + sub_name_ + ">");
  if (frames_.size() > 1) fail(1, "end of file inside subroutine o<" + frames_.back().sub_name + ">");
  if (setup_.require_program_end || cur_source_ != 0) {
    fail(1, percent_flag_ ? "file ended without the closing '%'" : "file ended without M2, M30 or '%'");
  }
  end_program_block();
}

void Interpreter::end_program_block() {
  ended_ = true;
  if (!qc_.empty()) dequeue_canons();
  Block b = base_block();
  b.kind = BlockKind::kEnd;
  b.seg = PathSegment::line(pos_mm_, pos_mm_);
  emit(std::move(b));
}

void Interpreter::step_line(const Source& src, int line_no) {
  const int src_id = cur_source_;
  sequence_ = line_no;
  cur_line_ = line_no + 1;
  const std::string& text = src.at(line_no);
  if (setup_.max_executed_lines > 0 && ++executed_lines_ > setup_.max_executed_lines)
    fail(1, "program executed more than " + std::to_string(setup_.max_executed_lines) + " lines (a loop that does not end?)");
  // After M6/M61 LinuxCNC re-reads the position from the machine before reading the next line:
  // the program position becomes where the machine is (after G40 that is the compensated point).
  if (toolchange_refresh_) {
    toolchange_refresh_ = false;
    const Eigen::Vector3d p = from_machine(pos_mm_);
    for (int i = 0; i < 3; ++i) cur_[i] = prog_[i] = p[i];
  }
  if (static_cast<int>(text.size()) > kMaxLineChars)
    fail(kMaxLineChars + 1, "line too long: " + std::to_string(text.size()) + " characters, at most " +
                                std::to_string(kMaxLineChars));
  // '%' tape markers: the first non-blank line of the program opens it (LinuxCNC's open()).
  if (src_id == 0 && !percent_seen_content_) {
    std::string_view t = text;
    while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
    while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
    if (t.empty()) return;
    percent_seen_content_ = true;
    if (t == "%") {
      percent_flag_ = true;
      return;
    }
  }
  normalize(text);
  if (line_ == "%" && percent_flag_) {
    end_program_block();
    return;
  }
  line_length_ = (line_.empty() || (line_[0] == '/' && setup_.block_delete)) ? 0 : static_cast<int>(line_.size());
  for (int i = 0; i < 3; ++i) params_[static_cast<std::size_t>(kParamPosition + i)] = cur_[i];
  // Run from line: from the first line at or after the start line of the program itself.
  if (suppress_ && src_id == 0 && frames_.size() == 1 && line_no >= setup_.run_from_line) {
    suppress_ = false;
    resume_state_ = modal_state();
    resume_state_->line = line_no;
  }
  if (line_length_ != 0) {
    read_items();
    if (!skipping_) {
      enhance_block();
      check_items();
    }
  } else {
    blk_.reset();
  }
  execute_line();
}

// Main-program lines before the earliest line a jump back may reach are dropped.
void Interpreter::trim_main() {
  Source& m = sources_[0];
  int low = cur_source_ == 0 ? cur_line_ : m.end_line();
  for (std::size_t f = 1; f < frames_.size(); ++f)
    if (frames_[f].return_source == 0) low = std::min(low, frames_[f].return_line);
  if (defining_sub_ && defining_line_ > 0) low = std::min(low, defining_line_);
  for (const auto& [name, lab] : offset_map_) {
    if (lab.source != 0) continue;
    if (lab.type == OType::kWhile || lab.type == OType::kDo || lab.type == OType::kRepeat) {
      if (lab.end_line == 0 || (cur_source_ == 0 && cur_line_ <= lab.end_line) || cur_source_ != 0)
        low = std::min(low, lab.line);
    } else if (lab.type == OType::kSub && frames_.size() > 1) {
      low = std::min(low, lab.line);  // a sub of the main program being executed before its end
    }
  }
  const int drop = low - m.first_line;
  if (drop > 0 && static_cast<std::size_t>(drop) <= m.lines.size()) {
    m.lines.erase(m.lines.begin(), m.lines.begin() + drop);
    m.first_line += drop;
  }
}

void Interpreter::mdi(std::string_view text, std::vector<Block>& out) {
  out_ = &out;
  ended_ = false;
  Source s;
  s.name = "<mdi>";
  s.lines.emplace_back(text);
  s.mdi = true;
  sources_.push_back(std::move(s));
  const int id = static_cast<int>(sources_.size()) - 1;
  const int saved_source = cur_source_;
  const int saved_line = cur_line_;
  cur_source_ = id;
  cur_line_ = 1;
  try {
    step_line(sources_[static_cast<std::size_t>(id)], 1);
    // A call runs the whole subroutine now (LinuxCNC's MDI loop).
    while (frames_.size() > 1 && !ended_) {
      Source& cs = sources_[static_cast<std::size_t>(cur_source_)];
      if (!cs.has(cur_line_)) at_end_of_source();
      else step_line(cs, cur_line_);
    }
    if (skipping_ || defining_sub_) fail(1, "O-word control flow needs a program file (not MDI)");
  } catch (...) {
    frames_.resize(1);
    skipping_ = skipping_to_sub_on_ = defining_sub_ = false;
    cur_source_ = saved_source;
    cur_line_ = saved_line;
    sources_.pop_back();
    throw;
  }
  if (!qc_.empty() && comp_side_ == CompSide::kOff) dequeue_canons();
  cur_source_ = saved_source;
  cur_line_ = saved_line;
  sources_.pop_back();
  ended_ = false;
}

void Interpreter::set_position_mm(const Eigen::Vector3d& machine_mm) {
  pos_mm_ = machine_mm;
  const Eigen::Vector3d p = from_machine(machine_mm);
  for (int i = 0; i < 3; ++i) cur_[i] = prog_[i] = p[i];
}

MachineContext Interpreter::machine() const {
  MachineContext m;
  m.parameters = params_;
  m.persistent = persistent_;
  m.tools.assign(tool_table_.begin() + 1, tool_table_.end());
  m.tool_in_spindle = tool_table_[0].number > 0 ? tool_table_[0].number : 0;
  return m;
}

ModalState Interpreter::modal_state() const {
  ModalState s;
  s.line = sequence_;
  s.position_mm = pos_mm_;
  s.program_position = Eigen::Vector3d(cur_[0], cur_[1], cur_[2]);
  s.motion_mode = motion_mode_;
  s.plane = plane_ == 1 ? 17 : plane_ == 3 ? 18 : 19;
  s.metric = units_ == Units::kMm;
  s.absolute = absolute_;
  s.ijk_absolute = ijk_absolute_;
  s.coord_system = origin_index_;
  s.work_offset_mm = g5x_mm_;
  s.g92_offset_mm = g92_mm_;
  s.tool_offset_mm = tlo_mm_;
  s.xy_rotation_deg = rot_deg_;
  s.feed_mm_min = canon_feed_mm_min_;
  s.spindle = canon_spindle_;
  s.spindle_rpm = canon_rpm_;
  s.mist = canon_mist_;
  s.flood = canon_flood_;
  s.tool = canon_tool_;
  s.selected_tool = selected_tool_;
  const Block b = base_block();
  s.blend = b.blend;
  s.tolerance_mm = b.tolerance_mm;
  s.cutter_comp = comp_side_ != CompSide::kOff;
  s.retract_r_plane = retract_r_plane_;
  return s;
}

// ---------------------------------------------------------------- execution

void Interpreter::execute_line() {
  if (blk_.o_present) {
    convert_control_functions();
    return;
  }
  if (skipping_) return;
  for (const auto& [k, v] : blk_.param_sets) params_[static_cast<std::size_t>(k)] = v;
  for (const auto& [name, v] : blk_.named_sets) store_named(name, v, 1);
  if (line_length_ != 0) execute_block();
}

void Interpreter::execute_block() {
  if (!blk_.comment.empty()) convert_comment(blk_.comment, blk_.comment_col);
  if (blk_.g_modes[gm::kSpindleMode] != -1) {
    // G97 (RPM mode) is the only spindle mode: nothing to change.
  }
  if (blk_.g_modes[gm::kFeedMode] != -1) {
    // G94: LinuxCNC resets the feed rate to 0 when the feed mode is (re)selected.
    feed_rate_ = 0.0;
    enqueue_feed_rate(0.0);
  }
  if (blk_['f'].set) {
    feed_rate_ = blk_['f'].v;
    enqueue_feed_rate(blk_['f'].v);
  }
  if (blk_['s'].set) {
    enqueue_speed(blk_['s'].v);
    speed_ = blk_['s'].v;
  }
  if (blk_['t'].set) convert_tool_select();
  convert_m();
  convert_g();
  if (blk_.m_modes[4] != -1) convert_stop();
}

void Interpreter::convert_comment(const std::string& comment, int col) {
  std::size_t m = 0;
  while (m < comment.size() && std::isspace(static_cast<unsigned char>(comment[m]))) ++m;
  std::string lc;
  for (std::size_t k = m; k < comment.size(); ++k)
    lc += static_cast<char>(std::tolower(static_cast<unsigned char>(comment[k])));
  const auto starts = [&](std::string_view p) { return lc.compare(0, p.size(), p) == 0; };
  const std::string body = comment.substr(m);
  if (starts("msg,")) {
    canon_message(body.substr(4));
    return;
  }
  const auto add = [&](Message::Kind k, const std::string& t) {
    if (suppress_) return;
    messages_.push_back(Message{k, sequence_, sources_[static_cast<std::size_t>(cur_source_)].name, t, out_->size()});
  };
  if (starts("debug,")) {
    const std::string e = expand_debug(body.substr(6), col);
    if (params_[kParamDebug] > 0.0) add(Message::Kind::kDebug, e);
    return;
  }
  if (starts("print,")) {
    add(Message::Kind::kPrint, expand_debug(body.substr(6), col));
    return;
  }
  if (starts("log,")) {
    add(Message::Kind::kLog, expand_debug(body.substr(4), col));
    return;
  }
  if (starts("logopen,") || starts("logappend,") || lc == "logclose") return;  // log files: host's
  if (starts("abort,")) fail(col, "program aborted: " + expand_debug(body.substr(6), col));
  if (starts("py,") || starts("pyrun,") || starts("pyreload"))
    fail(col, "embedded Python (" + body.substr(0, body.find(',')) + ") is not supported");
}

// (DEBUG,...) expansion: #n and #<name> by value, %d %f %.Nf formats (LinuxCNC's rules).
std::string Interpreter::expand_debug(const std::string& text, int col) const {
  std::string out;
  int decimals = 6;  // "%lf"
  std::size_t i = 0;
  const std::size_t n = text.size();
  while (i < n) {
    const char c = text[i];
    if (c == '%') {
      ++i;
      if (i < n && text[i] == 'd') {
        decimals = 0;  // "%d" prints "%.0f"
        ++i;
      } else if (i < n && text[i] == 'f') {
        decimals = 4;
        ++i;
      } else if (i < n && text[i] == '.') {
        if (i + 2 < n && std::isdigit(static_cast<unsigned char>(text[i + 1])) && text[i + 2] == 'f') {
          decimals = text[i + 1] - '0';
          i += 3;
        } else {
          out += '.';
          ++i;
        }
      } else {
        out += '%';
      }
    } else if (c == '#') {
      ++i;
      if (i >= n) fail(col, "named parameter not terminated in comment");
      bool found = false;
      double value = 0.0;
      if (std::isdigit(static_cast<unsigned char>(text[i]))) {
        std::size_t j = i;
        while (j < n && std::isdigit(static_cast<unsigned char>(text[j]))) ++j;
        const long k = std::strtol(text.substr(i, j - i).c_str(), nullptr, 10);
        i = j;
        if (k >= 0 && k < kParameterCount) {
          value = params_[static_cast<std::size_t>(k)];
          found = true;
        }
      } else if (text[i] == '<') {
        ++i;
        std::string name;
        while (i < n && text[i] != '>' && text[i] != ')') {
          if (!std::isspace(static_cast<unsigned char>(text[i])))
            name += static_cast<char>(std::tolower(static_cast<unsigned char>(text[i])));
          ++i;
        }
        if (i >= n || text[i] != '>') fail(col, "named parameter not terminated in comment");
        ++i;
        found = find_named(name, value);
      } else {
        out += '#';
        continue;
      }
      if (found) {
        if (std::abs(value) < 0.0001) value = 0.0;
        const std::string v = format_fixed(value, decimals);
        out += v.size() >= 30 ? "######" : v;
      } else {
        out += "######";
      }
    } else {
      out += c;
      ++i;
    }
  }
  return out;
}

void Interpreter::convert_tool_select() {
  const int idx = find_tool_index(blk_.t_number, blk_['t'].col);
  selected_pocket_ = idx;
  selected_tool_ = blk_.t_number;
}

int Interpreter::find_tool_index(int toolno, int col) const {
  if (toolno == 0) return 0;
  for (std::size_t i = 1; i < tool_table_.size(); ++i)
    if (tool_table_[i].number == toolno) return static_cast<int>(i);
  fail(col, "tool " + std::to_string(toolno) + " is not in the tool table");
}

void Interpreter::set_tool_parameters() {
  const ToolData& t = tool_table_[0];
  std::array<double, 14> v{};
  if (t.number > 0) {
    v[0] = t.number;
    for (std::size_t i = 0; i < 9; ++i) v[i + 1] = t.offset[i];
    v[10] = t.diameter_mm;
    v[11] = t.front_angle_deg;
    v[12] = t.back_angle_deg;
    v[13] = t.orientation;
  }
  for (std::size_t i = 0; i < 14; ++i) params_[kParamToolNumber + i] = v[i];
}

void Interpreter::convert_m() {
  const int m6 = blk_.m_modes[6];
  if (m6 == 6) {
    convert_tool_change();
  } else if (m6 == 61) {
    const int col = blk_.m_cols[6];
    const int toolno = static_cast<int>(std::nearbyint(std::clamp(blk_.q_number, -2e9, 2e9)));
    if (toolno < 0) fail(col, "M61 needs a non-negative Q word (the tool number)");
    const int idx = find_tool_index(toolno, col);
    current_pocket_ = idx;
    tool_table_[0] = idx == 0 ? ToolData{} : tool_table_[static_cast<std::size_t>(idx)];
    canon_set_tool_number(toolno);
    set_tool_parameters();
    toolchange_refresh_ = true;
  }
  const int m7 = blk_.m_modes[7];
  if (m7 == 3) {
    enqueue_spindle(SpindleDir::kCw);
    spindle_ = SpindleDir::kCw;
  } else if (m7 == 4) {
    enqueue_spindle(SpindleDir::kCcw);
    spindle_ = SpindleDir::kCcw;
  } else if (m7 == 5) {
    spindle_ = SpindleDir::kOff;
    enqueue_spindle(SpindleDir::kOff);
  }
  const int m8 = blk_.m_modes[8];
  if (m8 == 7) {
    enqueue_mist(true);
    mist_ = true;
  } else if (m8 == 8) {
    enqueue_flood(true);
    flood_ = true;
  } else if (m8 == 9) {
    enqueue_mist(false);
    mist_ = false;
    enqueue_flood(false);
    flood_ = false;
  }
  if (blk_.m_modes[10] != -1) enqueue_user_m(blk_.m_modes[10], blk_.p_number, blk_.q_number);
}

void Interpreter::convert_tool_change() {
  const int col = blk_.m_cols[6];
  if (selected_pocket_ < 0) fail(col, "M6 without a tool selected (T word)");
  if (comp_side_ != CompSide::kOff) fail(col, "cannot change tools with cutter radius compensation on");
  // LinuxCNC stops the spindle before a tool change (TOOL_CHANGE_WITH_SPINDLE_ON off).
  spindle_ = SpindleDir::kOff;
  canon_spindle(SpindleDir::kOff);
  const ToolData t = selected_pocket_ == 0 ? ToolData{} : tool_table_[static_cast<std::size_t>(selected_pocket_)];
  canon_change_tool(selected_pocket_ == 0 ? 0 : t.number);
  current_pocket_ = selected_pocket_;
  tool_table_[0] = t;
  set_tool_parameters();
  toolchange_refresh_ = true;
}

void Interpreter::convert_g() {
  const auto& gm = blk_.g_modes;
  if (gm[gm::kModal0] == g::k4) enqueue_dwell(blk_.p_number);
  if (gm[gm::kPlane] != -1) convert_set_plane(gm[gm::kPlane]);
  if (gm[gm::kUnits] != -1) convert_length_units(gm[gm::kUnits]);
  if (gm[gm::kCutterComp] != -1) convert_cutter_compensation(gm[gm::kCutterComp]);
  if (gm[gm::kToolOffset] != -1) convert_tool_length_offset(gm[gm::kToolOffset]);
  if (gm[gm::kCoordSystem] != -1) convert_coordinate_system(gm[gm::kCoordSystem]);
  if (gm[gm::kControl] != -1) convert_control_mode(gm[gm::kControl]);
  if (gm[gm::kDistance] != -1) convert_distance_mode(gm[gm::kDistance]);
  if (gm[gm::kIjkDistance] != -1) ijk_absolute_ = gm[gm::kIjkDistance] == g::k90_1;
  if (gm[gm::kRetract] != -1) {
    if (comp_side_ != CompSide::kOff)
      fail(blk_.g_cols[gm::kRetract], "cannot change the retract mode with cutter radius compensation on");
    retract_r_plane_ = gm[gm::kRetract] == g::k99;
  }
  if (gm[gm::kModal0] != -1) convert_modal_0(gm[gm::kModal0]);
  if (gm[gm::kG92Applied] != -1) convert_axis_offsets(gm[gm::kG92Applied]);
  if (blk_.motion_to_be != -1) convert_motion(blk_.motion_to_be);
}

void Interpreter::convert_set_plane(int code) {
  const int col = blk_.g_cols[gm::kPlane];
  const int p = code == g::k17 ? 1 : code == g::k18 ? 3 : 2;
  if (comp_side_ != CompSide::kOff && p != plane_)
    fail(col, "cannot change planes with cutter radius compensation on");
  if (comp_side_ != CompSide::kOff && code == g::k19)
    fail(col, "cutter radius compensation only in the XY (G17) or XZ (G18) plane");
  canon_select_plane(p);
  plane_ = p;
}

void Interpreter::convert_length_units(int code) {
  const Units u = code == g::k20 ? Units::kInch : Units::kMm;
  if (u == units_) return;
  const double k = u == Units::kInch ? 1.0 / kMmPerInch : kMmPerInch;
  units_ = u;
  for (int i = 0; i < 3; ++i) {
    cur_[i] *= k;
    prog_[i] *= k;
    axis_off_[i] *= k;
    origin_[i] *= k;
  }
  qc_scale(k);
  comp_radius_ *= k;
  // The canonical layer keeps the tool offset and the feed in machine units: re-read them.
  const double unit = u == Units::kInch ? kMmPerInch : 1.0;
  for (int i = 0; i < 3; ++i) tool_off_[i] = tlo_mm_[i] / unit;
  feed_rate_ = canon_feed_mm_min_ / unit;
}

void Interpreter::convert_cutter_compensation(int code) {
  if (code == g::k40) {
    convert_cutter_compensation_off();
  } else {
    convert_cutter_compensation_on((code == g::k41 || code == g::k41_1) ? CompSide::kLeft : CompSide::kRight);
  }
}

void Interpreter::convert_cutter_compensation_off() {
  if (comp_side_ != CompSide::kOff && comp_radius_ > 0.0 && !comp_firstmove_) {
    double cx = 0, cy = 0, cz = 0;
    comp_get_current(cx, cy, cz);
    move_endpoint_and_flush(cx, cy);
    dequeue_canons();
    for (int i = 0; i < 3; ++i) cur_[i] = prog_[i];
    arc_not_allowed_ = true;
  }
  comp_side_ = CompSide::kOff;
  comp_firstmove_ = true;
}

void Interpreter::convert_cutter_compensation_on(CompSide side) {
  const int code = blk_.g_modes[gm::kCutterComp];
  const int col = blk_.g_cols[gm::kCutterComp];
  const std::string gname = code == g::k41 ? "G41" : code == g::k42 ? "G42" : code == g::k41_1 ? "G41.1" : "G42.1";
  if (plane_ != 1 && plane_ != 3) fail(col, "cutter radius compensation only in the XY (G17) or XZ (G18) plane");
  if (comp_side_ != CompSide::kOff) fail(col, "cannot turn cutter radius compensation on when it is on");
  double radius = 0.0;
  int orientation = 0;
  if (code == g::k41_1 || code == g::k42_1) {
    if (!blk_['d'].set) fail(col, gname + " needs a D word (the tool diameter)");
    radius = blk_.d_number / 2.0;
    if (blk_.l_number != -1) {
      if (plane_ != 3) fail(word_col('l'), gname + " with an L word needs the G18 plane");
      orientation = blk_.l_number;
    }
  } else {
    int idx = 0;
    if (blk_['d'].set) {
      const int tool = static_cast<int>(blk_.d_number + 0.5);
      if (!(std::abs(tool - blk_.d_number) < 0.0001)) fail_word('d', gname + " needs D to be a whole number");
      if (tool < 0) fail_word('d', "negative D word");
      idx = find_tool_index(tool, word_col('d'));
    }
    const ToolData& t = tool_table_[static_cast<std::size_t>(idx)];
    radius = user_to_program(t.diameter_mm) / 2.0;
    orientation = t.orientation;
    if (plane_ != 3 && orientation != 0 && orientation != 9)
      fail(col, gname + " with a lathe tool needs the G18 plane");
  }
  if (radius < 0.0) {
    radius = -radius;
    side = side == CompSide::kRight ? CompSide::kLeft : CompSide::kRight;
  }
  comp_radius_ = radius;
  comp_orientation_ = orientation;
  comp_side_ = side;
}

void Interpreter::convert_tool_length_offset(int code) {
  const int col = blk_.g_cols[gm::kToolOffset];
  if (comp_side_ != CompSide::kOff) fail(col, "cannot change the tool offset with cutter radius compensation on");
  double off[3] = {0, 0, 0};
  const auto from_table = [&](int idx) {
    const ToolData& t = tool_table_[static_cast<std::size_t>(idx)];
    for (std::size_t i = 0; i < 3; ++i) off[i] = user_to_program(t.offset[i]);
  };
  if (code == g::k49) {
  } else if (code == g::k43) {
    from_table(blk_['h'].set ? find_tool_index(blk_.h_number, word_col('h')) : 0);
  } else if (code == g::k43_1) {
    for (int i = 0; i < 3; ++i) off[i] = tool_off_[i];
    if (blk_['x'].set) off[0] = blk_['x'].v;
    if (blk_['y'].set) off[1] = blk_['y'].v;
    if (blk_['z'].set) off[2] = blk_['z'].v;
  } else {  // G43.2: add an offset to the current one
    const bool axes = blk_['x'].set || blk_['y'].set || blk_['z'].set;
    if (blk_['h'].set && axes) fail(col, "G43.2 with both H and axis words");
    if (!blk_['h'].set && !axes) fail(col, "G43.2 without H or axis words");
    // LinuxCNC looks H up even when it is absent (-1): G43.2 with axis words fails there too.
    const int idx = find_tool_index(blk_.h_number, blk_['h'].set ? word_col('h') : col);
    for (int i = 0; i < 3; ++i) off[i] = tool_off_[i];
    if (blk_['h'].set) {
      const ToolData& t = tool_table_[static_cast<std::size_t>(idx)];
      for (std::size_t i = 0; i < 3; ++i) off[i] += user_to_program(t.offset[i]);
    } else {
      if (blk_['x'].set) off[0] += blk_['x'].v;
      if (blk_['y'].set) off[1] += blk_['y'].v;
      if (blk_['z'].set) off[2] += blk_['z'].v;
    }
  }
  canon_tool_offset(off[0], off[1], off[2]);
  double dx = tool_off_[0] - off[0];
  double dy = tool_off_[1] - off[1];
  rotate(dx, dy, -rotation_xy_);
  cur_[0] += dx;
  cur_[1] += dy;
  cur_[2] += tool_off_[2] - off[2];
  for (int i = 0; i < 3; ++i) tool_off_[i] = off[i];
}

void Interpreter::find_current_in_system(int system, double& x, double& y, double& z, bool with_tlo) const {
  x = cur_[0] + axis_off_[0];
  y = cur_[1] + axis_off_[1];
  z = cur_[2] + axis_off_[2];
  rotate(x, y, rotation_xy_);
  x += origin_[0];
  y += origin_[1];
  z += origin_[2];
  if (with_tlo) {
    x += tool_off_[0];
    y += tool_off_[1];
    z += tool_off_[2];
  }
  const std::size_t k = static_cast<std::size_t>(5200 + 20 * system);
  x -= user_to_program(params_[k + 1]);
  y -= user_to_program(params_[k + 2]);
  z -= user_to_program(params_[k + 3]);
  rotate(x, y, -params_[k + 10]);
  if (params_[kParamG92Applied] != 0.0) {
    x -= user_to_program(params_[kParamG92]);
    y -= user_to_program(params_[kParamG92 + 1]);
    z -= user_to_program(params_[kParamG92 + 2]);
  }
}

void Interpreter::convert_coordinate_system(int code) {
  const int col = blk_.g_cols[gm::kCoordSystem];
  if (comp_side_ != CompSide::kOff) fail(col, "cannot change coordinate systems with cutter radius compensation on");
  const int origin = code < g::k59_3 - 3 ? (code - g::k54) / 10 + 1 : code == 590 ? 6 : code - 584;
  if (origin == origin_index_) return;
  find_current_in_system(origin, cur_[0], cur_[1], cur_[2], false);
  origin_index_ = origin;
  params_[kParamCoordSystem] = origin;
  persistent_.insert(kParamCoordSystem);
  machine_changed_ = true;
  load_origin(origin);
  canon_g5x(origin, origin_[0], origin_[1], origin_[2]);
  canon_g92(axis_off_[0], axis_off_[1], axis_off_[2]);
  canon_rotation(rotation_xy_);
}

void Interpreter::convert_control_mode(int code) {
  const int col = blk_.g_cols[gm::kControl];
  if (comp_side_ != CompSide::kOff) fail(col, "cannot change the path control mode with cutter radius compensation on");
  if (code == g::k61) {
    control_mode_ = 1;
  } else if (code == g::k61_1) {
    control_mode_ = 2;
  } else {
    control_mode_ = 0;
    // G64 P: tolerance in program units; without P (or P0) no tolerance (blend freely).
    control_tolerance_ = blk_.p_number >= 0 ? program_to_user(blk_.p_number) : 0.0;
  }
}

void Interpreter::convert_distance_mode(int code) { absolute_ = code == g::k90; }

void Interpreter::convert_modal_0(int code) {
  if (code == g::k10) {
    if (blk_.l_number == 1 || blk_.l_number == 10 || blk_.l_number == 11) convert_setup_tool();
    else convert_setup();
  } else if (code == g::k28 || code == g::k30) {
    convert_home(code);
  } else if (code == g::k28_1 || code == g::k30_1) {
    convert_savehome(code);
  } else if (code == g::k52 || code == g::k92) {
    convert_axis_offsets(code);
  }
}

// G10 L2 / L20 P<system> [R<rotation>] X Y Z: set a coordinate system's origin (L2: to the
// values, L20: so the current point reads the values).
void Interpreter::convert_setup() {
  const int col = blk_.g_cols[gm::kModal0];
  if (blk_['i'].set || blk_['j'].set) fail(col, "I and J are not allowed with G10 L2/L20");
  int p = static_cast<int>(blk_.p_number + 0.0001);
  if (p == 0) p = origin_index_;
  if (comp_side_ != CompSide::kOff && p == origin_index_)
    fail(col, "cannot change the active coordinate system with cutter radius compensation on");
  const std::size_t k = static_cast<std::size_t>(5200 + 20 * p);
  double cx = 0, cy = 0, cz = 0;
  find_current_in_system(p, cx, cy, cz, false);
  double r = 0.0;
  if (blk_['r'].set) {
    if (blk_.l_number == 20) fail(word_col('r'), "R is not allowed with G10 L20");
    r = blk_['r'].v;
    params_[k + 10] = r;
  } else {
    r = params_[k + 10];
  }
  double x = 0, y = 0, z = 0;
  if (blk_.l_number == 20) {
    double oldx = cx, oldy = cy;
    x = cx;
    y = cy;
    if (blk_['x'].set) x = blk_['x'].v;
    if (blk_['y'].set) y = blk_['y'].v;
    rotate(oldx, oldy, r);
    rotate(x, y, r);
    x = oldx + user_to_program(params_[k + 1]) - x;
    y = oldy + user_to_program(params_[k + 2]) - y;
    params_[k + 1] = program_to_user(x);
    params_[k + 2] = program_to_user(y);
    if (p == origin_index_) {
      rotate(cur_[0], cur_[1], rotation_xy_);
      rotation_xy_ = 0.0;
    }
  } else {
    if (blk_['x'].set) {
      x = blk_['x'].v;
      params_[k + 1] = program_to_user(x);
    } else {
      x = user_to_program(params_[k + 1]);
    }
    if (blk_['y'].set) {
      y = blk_['y'].v;
      params_[k + 2] = program_to_user(y);
    } else {
      y = user_to_program(params_[k + 2]);
    }
  }
  if (blk_['z'].set) {
    z = blk_['z'].v;
    if (blk_.l_number == 20) z = cz + user_to_program(params_[k + 3]) - z;
    params_[k + 3] = program_to_user(z);
  } else {
    z = user_to_program(params_[k + 3]);
  }
  for (std::size_t i = 1; i <= 10; ++i) persistent_.insert(static_cast<int>(k + i));
  machine_changed_ = true;
  if (p == origin_index_) {
    rotate(cur_[0], cur_[1], rotation_xy_);
    cur_[0] += origin_[0];
    cur_[1] += origin_[1];
    cur_[2] += origin_[2];
    origin_[0] = x;
    origin_[1] = y;
    origin_[2] = z;
    cur_[0] -= x;
    cur_[1] -= y;
    cur_[2] -= z;
    canon_g5x(p, x, y, z);
    rotate(cur_[0], cur_[1], -r);
    rotation_xy_ = r;
    canon_rotation(r);
  }
}

// G10 L1 / L10 / L11 P<tool>: set a tool-table entry (L1 directly, L10/L11 so the current point
// reads the values in the current system / in G59.3).
void Interpreter::convert_setup_tool() {
  const int col = blk_.g_cols[gm::kModal0];
  const int toolno = static_cast<int>(blk_.p_number + 0.5);
  const int idx = find_tool_index(toolno, word_col('p'));
  if (idx == 0) fail(word_col('p'), "G10 L" + std::to_string(blk_.l_number) + " needs P to be a tool in the table");
  if (!(blk_['x'].set || blk_['y'].set || blk_['z'].set || blk_['r'].set || blk_.q_number != -1.0 ||
        blk_['i'].set || blk_['j'].set))
    fail(col, "G10 L" + std::to_string(blk_.l_number) + " without offsets has no effect");
  ToolData& t = tool_table_[static_cast<std::size_t>(idx)];
  if (blk_.l_number == 1) {
    if (blk_['x'].set) t.offset[0] = program_to_user(blk_['x'].v);
    if (blk_['y'].set) t.offset[1] = program_to_user(blk_['y'].v);
    if (blk_['z'].set) t.offset[2] = program_to_user(blk_['z'].v);
  } else {
    const bool to_fixture = blk_.l_number == 11;
    const int dest = to_fixture ? 9 : origin_index_;
    double tx = 0, ty = 0, tz = 0;
    find_current_in_system(dest, tx, ty, tz, true);
    if (to_fixture && params_[kParamG92Applied] != 0.0) {
      tx += user_to_program(params_[kParamG92]);
      ty += user_to_program(params_[kParamG92 + 1]);
      tz += user_to_program(params_[kParamG92 + 2]);
    }
    const double rot = params_[static_cast<std::size_t>(5210 + dest * 20)];
    if (blk_['x'].set && blk_['y'].set) {
      tx -= blk_['x'].v;
      ty -= blk_['y'].v;
      rotate(tx, ty, rot);
      t.offset[0] = program_to_user(tx);
      t.offset[1] = program_to_user(ty);
    } else if (blk_['x'].set) {
      double ox = user_to_program(t.offset[0]), oy = user_to_program(t.offset[1]);
      rotate(ox, oy, -rot);
      ox = 0;
      rotate(ox, oy, rot);
      tx -= blk_['x'].v;
      ty = 0;
      rotate(tx, ty, rot);
      t.offset[0] = program_to_user(tx + ox);
      t.offset[1] = program_to_user(ty + oy);
    } else if (blk_['y'].set) {
      double ox = user_to_program(t.offset[0]), oy = user_to_program(t.offset[1]);
      rotate(ox, oy, -rot);
      oy = 0;
      rotate(ox, oy, rot);
      ty -= blk_['y'].v;
      tx = 0;
      rotate(tx, ty, rot);
      t.offset[0] = program_to_user(tx + ox);
      t.offset[1] = program_to_user(ty + oy);
    }
    if (blk_['z'].set) t.offset[2] = program_to_user(tz - blk_['z'].v);
  }
  if (blk_['r'].set) t.diameter_mm = program_to_user(blk_['r'].v) * 2.0;
  if (blk_['i'].set) t.front_angle_deg = blk_['i'].v;
  if (blk_['j'].set) t.back_angle_deg = blk_['j'].v;
  if (blk_.q_number != -1.0) {
    const int q = static_cast<int>(blk_.q_number + 0.5);
    if (!(std::abs(q - blk_.q_number) < 0.0001)) fail_word('q', "Q (tool orientation) in G10 is not an integer");
    if (q > 9) fail_word('q', "invalid tool orientation (Q 0..9)");
    t.orientation = q;
  }
  if (current_pocket_ == idx) tool_table_[0] = t;
  set_tool_parameters();
  machine_changed_ = true;
}

void Interpreter::convert_axis_offsets(int code) {
  const int col = blk_.g_cols[code >= g::k92_1 ? gm::kG92Applied : gm::kModal0];
  if (comp_side_ != CompSide::kOff) fail(col, "cannot change axis offsets with cutter radius compensation on");
  machine_changed_ = true;
  if (code == g::k52 || code == g::k92) {
    params_[kParamG92Applied] = 1.0;
    for (int a = 0; a < 3; ++a) {
      const WordVal& w = blk_[static_cast<char>('x' + a)];
      if (!w.set) continue;
      if (code == g::k52) {
        cur_[a] += axis_off_[a] - w.v;
        axis_off_[a] = w.v;
      } else {
        axis_off_[a] = cur_[a] + axis_off_[a] - w.v;
        cur_[a] = w.v;
      }
    }
    canon_g92(axis_off_[0], axis_off_[1], axis_off_[2]);
    for (int a = 0; a < 3; ++a) params_[static_cast<std::size_t>(kParamG92 + a)] = program_to_user(axis_off_[a]);
  } else if (code == g::k92_1 || code == g::k92_2) {
    params_[kParamG92Applied] = 0.0;
    for (int a = 0; a < 3; ++a) {
      cur_[a] += axis_off_[a];
      axis_off_[a] = 0.0;
    }
    canon_g92(0, 0, 0);
    if (code == g::k92_1)
      for (int a = 0; a < 9; ++a) params_[static_cast<std::size_t>(kParamG92 + a)] = 0.0;
  } else {  // G92.3: restore the stored offset
    params_[kParamG92Applied] = 1.0;
    for (int a = 0; a < 3; ++a) {
      const double v = user_to_program(params_[static_cast<std::size_t>(kParamG92 + a)]);
      cur_[a] = cur_[a] + axis_off_[a] - v;
      axis_off_[a] = v;
    }
    canon_g92(axis_off_[0], axis_off_[1], axis_off_[2]);
  }
}

void Interpreter::find_relative(double x1, double y1, double z1, double& x2, double& y2, double& z2) const {
  x2 = x1 - origin_[0] - tool_off_[0];
  y2 = y1 - origin_[1] - tool_off_[1];
  rotate(x2, y2, -rotation_xy_);
  x2 -= axis_off_[0];
  y2 -= axis_off_[1];
  z2 = z1 - origin_[2] - axis_off_[2] - tool_off_[2];
}

// G28 / G30 [X Y Z]: rapid to the intermediate point (if any axis words), then the named axes (or
// all) to the stored position (#5161.. / #5181.., machine coordinates).
void Interpreter::convert_home(int code) {
  const int col = blk_.g_cols[gm::kModal0];
  double ex = 0, ey = 0, ez = 0;
  find_ends(ex, ey, ez);
  if (comp_side_ != CompSide::kOff) fail(col, "cannot use G28 or G30 with cutter radius compensation on");
  canon_straight(false, sequence_, ex, ey, ez);
  cur_[0] = ex;
  cur_[1] = ey;
  cur_[2] = ez;
  const int base = code == g::k28 ? kParamG28 : kParamG30;
  double hx = 0, hy = 0, hz = 0;
  find_relative(user_to_program(params_[static_cast<std::size_t>(base)]),
                user_to_program(params_[static_cast<std::size_t>(base + 1)]),
                user_to_program(params_[static_cast<std::size_t>(base + 2)]), hx, hy, hz);
  const bool any = blk_['x'].set || blk_['y'].set || blk_['z'].set;
  if (blk_['x'].set || !any) ex = hx;
  if (blk_['y'].set || !any) ey = hy;
  if (blk_['z'].set || !any) ez = hz;
  canon_straight(false, sequence_, ex, ey, ez);
  cur_[0] = ex;
  cur_[1] = ey;
  cur_[2] = ez;
}

void Interpreter::convert_savehome(int code) {
  if (comp_side_ != CompSide::kOff)
    fail(blk_.g_cols[gm::kModal0], "cannot set a reference point with cutter radius compensation on");
  double x = cur_[0] + axis_off_[0];
  double y = cur_[1] + axis_off_[1];
  rotate(x, y, rotation_xy_);
  const int base = code == g::k28_1 ? kParamG28 : kParamG30;
  params_[static_cast<std::size_t>(base)] = program_to_user(x + tool_off_[0] + origin_[0]);
  params_[static_cast<std::size_t>(base + 1)] = program_to_user(y + tool_off_[1] + origin_[1]);
  params_[static_cast<std::size_t>(base + 2)] = program_to_user(cur_[2] + tool_off_[2] + origin_[2] + axis_off_[2]);
  for (int i = 3; i < 9; ++i) params_[static_cast<std::size_t>(base + i)] = 0.0;
  machine_changed_ = true;
}

void Interpreter::convert_stop() {
  const int m = blk_.m_modes[4];
  double cx = 0, cy = 0, cz = 0;
  comp_get_current(cx, cy, cz);
  move_endpoint_and_flush(cx, cy);
  dequeue_canons();
  if (m == 0) {
    canon_stop(BlockKind::kProgramStop, "program stop (M0): resume to continue");
    return;
  }
  if (m == 1) {
    canon_stop(BlockKind::kOptionalStop, "optional stop (M1)");
    return;
  }
  // M2 / M30: LinuxCNC resets the modal state (G54, G17, G90, G94, feed 0, spindle and coolant off,
  // cutter comp off, motion mode G1) and ends the program.
  rotate(cur_[0], cur_[1], rotation_xy_);
  for (int i = 0; i < 3; ++i) cur_[i] += origin_[i];
  origin_index_ = 1;
  params_[kParamCoordSystem] = 1.0;
  load_origin(1);
  for (int i = 0; i < 3; ++i) cur_[i] -= origin_[i];
  rotate(cur_[0], cur_[1], -rotation_xy_);
  canon_g5x(1, origin_[0], origin_[1], origin_[2]);
  canon_rotation(rotation_xy_);
  if (plane_ != 1) {
    canon_select_plane(1);
    plane_ = 1;
  }
  absolute_ = true;
  feed_rate_ = blk_['f'].set ? blk_['f'].v : 0.0;
  canon_set_feed_rate(0.0);
  comp_side_ = CompSide::kOff;
  comp_firstmove_ = true;
  canon_spindle(SpindleDir::kOff);
  spindle_ = SpindleDir::kOff;
  motion_mode_ = g::k1;
  if (mist_) {
    canon_mist(false);
    mist_ = false;
  }
  if (flood_) {
    canon_flood(false);
    flood_ = false;
  }
  frames_.resize(1);
  offset_map_.clear();
  skipping_ = skipping_to_sub_on_ = defining_sub_ = false;
  end_program_block();
}

// ---------------------------------------------------------------- motion

void Interpreter::convert_motion(int motion) {
  if (!is_cycle(motion)) cycle_il_flag_ = false;
  if (motion == g::k0 || motion == g::k1) {
    convert_straight(motion);
  } else if (motion == g::k2 || motion == g::k3) {
    convert_arc(motion);
  } else if (motion == g::k80) {
    motion_mode_ = g::k80;
  } else {
    convert_cycle(motion);
  }
}

// LinuxCNC's find_ends: the end point of this line's motion in program coordinates.
void Interpreter::find_ends(double& px, double& py, double& pz) {
  const bool middle = !comp_firstmove_;
  const bool comp = comp_side_ != CompSide::kOff;
  const WordVal& X = blk_['x'];
  const WordVal& Y = blk_['y'];
  const WordVal& Z = blk_['z'];
  const double d2r = std::numbers::pi / 180.0;
  if (blk_.g_modes[gm::kModal0] == g::k53) {
    if (blk_.radius.set || blk_.theta.set) fail(blk_.g_cols[gm::kModal0], "polar coordinates are not allowed with G53");
    double cx = cur_[0] + axis_off_[0];
    double cy = cur_[1] + axis_off_[1];
    rotate(cx, cy, rotation_xy_);
    px = X.set ? X.v - origin_[0] - tool_off_[0] : cx;
    py = Y.set ? Y.v - origin_[1] - tool_off_[1] : cy;
    rotate(px, py, -rotation_xy_);
    px -= axis_off_[0];
    py -= axis_off_[1];
    pz = Z.set ? Z.v - origin_[2] - axis_off_[2] - tool_off_[2] : cur_[2];
  } else if (absolute_) {
    px = X.set ? X.v : ((comp && middle) ? prog_[0] : cur_[0]);
    py = Y.set ? Y.v : ((comp && middle && plane_ == 1) ? prog_[1] : cur_[1]);
    if (blk_.radius.set && blk_.theta.set) {
      px = blk_.radius.v * std::cos(d2r * blk_.theta.v);
      py = blk_.radius.v * std::sin(d2r * blk_.theta.v);
    } else if (blk_.radius.set) {
      if (py == 0 && px == 0) fail(blk_.radius.col, "polar radius without an angle at the origin");
      const double t = std::atan2(py, px);
      px = blk_.radius.v * std::cos(t);
      py = blk_.radius.v * std::sin(t);
    } else if (blk_.theta.set) {
      const double r = std::hypot(py, px);
      px = r * std::cos(d2r * blk_.theta.v);
      py = r * std::sin(d2r * blk_.theta.v);
    }
    pz = Z.set ? Z.v : ((comp && middle && plane_ == 3) ? prog_[2] : cur_[2]);
  } else {
    px = (comp && middle) ? prog_[0] : cur_[0];
    if (X.set) px += X.v;
    py = (comp && middle && plane_ == 1) ? prog_[1] : cur_[1];
    if (Y.set) py += Y.v;
    if (blk_.radius.set) {
      if (py == 0 && px == 0) fail(blk_.radius.col, "incremental polar motion is indeterminate at the origin");
      const double t = std::atan2(py, px);
      const double r = std::hypot(py, px) + blk_.radius.v;
      px = r * std::cos(t);
      py = r * std::sin(t);
    }
    if (blk_.theta.set) {
      if (py == 0 && px == 0) fail(blk_.theta.col, "incremental polar motion is indeterminate at the origin");
      const double t = std::atan2(py, px) + d2r * blk_.theta.v;
      const double r = std::hypot(py, px);
      px = r * std::cos(t);
      py = r * std::sin(t);
    }
    pz = (comp && middle && plane_ == 3) ? prog_[2] : cur_[2];
    if (Z.set) pz += Z.v;
  }
}

void Interpreter::convert_straight(int move) {
  const int col = blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1;
  arc_not_allowed_ = false;
  if (move == g::k1 && feed_rate_ == 0.0)
    fail(blk_['f'].set ? blk_['f'].col : col, "G1 with zero feed rate (no F word programmed)");
  motion_mode_ = move;
  double ex = 0, ey = 0, ez = 0;
  find_ends(ex, ey, ez);
  if (comp_side_ != CompSide::kOff && comp_radius_ > 0.0) {
    if (blk_.g_modes[gm::kModal0] == g::k53)
      fail(blk_.g_cols[gm::kModal0], "cannot use G53 with cutter radius compensation on");
    if (plane_ == 3) {
      if (comp_firstmove_) convert_straight_comp1(move, ez, ex, ey);
      else convert_straight_comp2(move, ez, ex, ey);
    } else {
      if (comp_firstmove_) convert_straight_comp1(move, ex, ey, ez);
      else convert_straight_comp2(move, ex, ey, ez);
    }
    return;
  }
  canon_straight(move == g::k1, sequence_, ex, ey, ez);
  cur_[0] = ex;
  cur_[1] = ey;
  cur_[2] = ez;
}

void Interpreter::convert_arc(int move) {
  const int col = blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1;
  if (arc_not_allowed_) fail(col, "the move right after turning cutter compensation off must be straight, not an arc");
  const bool ijk = blk_['i'].set || blk_['j'].set || blk_['k'].set;
  const bool first = comp_firstmove_;
  if (!blk_['r'].set && !ijk) fail(col, "arc needs R or I/J/K words");
  if (blk_['r'].set && ijk) fail(word_col('r'), "arc with both R and I/J/K words");
  if (feed_rate_ == 0.0) fail(blk_['f'].set ? blk_['f'].col : col, "arc with zero feed rate (no F word programmed)");
  double& i_number = blk_['i'].v;
  double& j_number = blk_['j'].v;
  double& k_number = blk_['k'].v;
  if (ijk) {
    const auto missing = [&](char c) {
      if (ijk_absolute_) fail(col, std::string(1, static_cast<char>(c - 32)) + " word missing in an absolute-centre (G90.1) arc");
      blk_[c].v = 0.0;
    };
    if (plane_ == 1) {
      if (blk_['k'].set) fail_word('k', "K word in an arc in the XY (G17) plane");
      if (!blk_['i'].set) missing('i');
      else if (!blk_['j'].set) missing('j');
    } else if (plane_ == 2) {
      if (blk_['i'].set) fail_word('i', "I word in an arc in the YZ (G19) plane");
      if (!blk_['j'].set) missing('j');
      else if (!blk_['k'].set) missing('k');
    } else {
      if (blk_['j'].set) fail_word('j', "J word in an arc in the XZ (G18) plane");
      if (!blk_['i'].set) missing('i');
      else if (!blk_['k'].set) missing('k');
    }
  } else {
    const bool has = plane_ == 1 ? (blk_['x'].set || blk_['y'].set || blk_.radius.set || blk_.theta.set)
                     : plane_ == 2 ? (blk_['y'].set || blk_['z'].set)
                                   : (blk_['x'].set || blk_['z'].set);
    if (!has) fail(word_col('r'), "R-format arc needs end-point words in the plane (a full circle needs I/J/K)");
  }
  double ex = 0, ey = 0, ez = 0;
  find_ends(ex, ey, ez);
  motion_mode_ = move;
  const double spiral = units_ == Units::kInch ? setup_.arc_tolerance_inch : setup_.arc_tolerance_mm;
  const double rtol = units_ == Units::kInch ? kRadiusToleranceInch : kRadiusToleranceMm;
  const int p = blk_['p'].set ? static_cast<int>(std::nearbyint(blk_.p_number)) : 1;
  const auto arc2 = [&](double& c1, double& c2, double& c3, double e1, double e2, double e3, double o1, double o2) {
    double cc1 = 0, cc2 = 0;
    int turn = 0;
    if (blk_['r'].set) arc_data_r(move, c1, c2, e1, e2, blk_['r'].v, p, cc1, cc2, turn, rtol, word_col('r'));
    else arc_data_ijk(move, c1, c2, e1, e2, ijk_absolute_, o1, o2, p, cc1, cc2, turn, rtol, spiral, col);
    canon_arc(sequence_, e1, e2, cc1, cc2, turn, e3);
    c1 = e1;
    c2 = e2;
    c3 = e3;
  };
  if (plane_ == 1) {
    if (comp_side_ == CompSide::kOff || comp_radius_ == 0.0) arc2(cur_[0], cur_[1], cur_[2], ex, ey, ez, i_number, j_number);
    else if (first) convert_arc_comp1(move, ex, ey, ez, i_number, j_number);
    else convert_arc_comp2(move, ex, ey, ez, i_number, j_number);
  } else if (plane_ == 3) {
    if (comp_side_ == CompSide::kOff || comp_radius_ == 0.0) arc2(cur_[2], cur_[0], cur_[1], ez, ex, ey, k_number, i_number);
    else if (first) convert_arc_comp1(move, ez, ex, ey, k_number, i_number);
    else convert_arc_comp2(move, ez, ex, ey, k_number, i_number);
  } else {
    arc2(cur_[1], cur_[2], cur_[0], ey, ez, ex, j_number, k_number);
  }
}

void Interpreter::arc_data_r(int move, double cx, double cy, double ex, double ey, double radius, int p,
                             double& ccx, double& ccy, int& turn, double tolerance, int col) {
  if (ex == cx && ey == cy) fail(col, "R-format arc with its end point at its start point (a full circle needs I/J/K)");
  const double abs_r = std::abs(radius);
  const double mx = (ex + cx) / 2.0;
  const double my = (ey + cy) / 2.0;
  double half = std::hypot(mx - ex, my - ey);
  if (half - abs_r > tolerance)
    fail(col, "arc radius " + fmt(abs_r) + " too small to reach the end point (half chord " + fmt(half) + ")");
  if (half / abs_r > 1.0 - kTiny) half = abs_r;
  const double dir = std::atan2(ey - cy, ex - cx);
  constexpr long double kHalfPiL = 1.570796326794896619231321691639751442L;  // LinuxCNC's M_PI_2l
  const double theta = static_cast<double>(((move == g::k2 && radius > 0) || (move == g::k3 && radius < 0))
                                               ? dir - kHalfPiL
                                               : dir + kHalfPiL);
  const double turn2 = std::asin(half / abs_r);
  const double offset = abs_r * std::cos(turn2);
  ccx = mx + offset * std::cos(theta);
  ccy = my + offset * std::sin(theta);
  turn = move == g::k2 ? -p : p;
}

void Interpreter::arc_data_ijk(int move, double cx, double cy, double ex, double ey, bool abs, double i,
                               double j, int p, double& ccx, double& ccy, int& turn, double rtol,
                               double stol, int col) {
  ccx = abs ? i : cx + i;
  ccy = abs ? j : cy + j;
  const double r1 = std::hypot(ccx - cx, ccy - cy);
  const double r2 = std::hypot(ccx - ex, ccy - ey);
  if (r1 < rtol || r2 < rtol)
    fail(col, "zero-radius arc (start radius " + fmt(r1) + ", end radius " + fmt(r2) + ")");
  const double abs_err = std::abs(r1 - r2);
  const double rel_err = abs_err / std::max(r1, r2);
  if (abs_err > stol * 100.0 || (rel_err > kSpiralRelTolerance && abs_err > stol))
    fail(col, "arc end radius differs from its start radius: start " + fmt(r1) + ", end " + fmt(r2) +
                  " (difference " + fmt(abs_err) + ")");
  turn = move == g::k2 ? -p : p;
}

}  // namespace contour::control::gcode_detail
