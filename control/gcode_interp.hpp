#pragma once
// Internal: the RS274/NGC interpreter behind GcodeParser (control/gcode.hpp). Not part of the
// public API; included only by control/gcode*.cpp and white-box tests.
//
// It reproduces LinuxCNC 2.9's interpreter (rs274ngc) semantics: lines are read, normalised
// (spaces removed, lower case outside comments), parsed into a LineBlock whose values are
// evaluated at read time ([expressions], #parameters), then executed in LinuxCNC's order of
// execution. Positions are kept in program coordinates and program units like LinuxCNC's
// `_setup`; the canonical layer (canon_*) converts to machine mm with the offsets in effect
// (G5x, G92, XY rotation, tool length offset), as LinuxCNC's emccanon does, and emits Blocks.
//
// Control flow (O-words) follows LinuxCNC's model: a position (source, line index), "skipping"
// to a label, an offset map of labels, a call stack. The main program is a streaming source: the
// caller pushes lines; lines are kept only while a jump back may need them (active loops, call
// returns, a subroutine being defined), so a program without loops and subroutines runs in
// constant memory. Subroutine bodies of the main program are copied to their own source when
// their definition ends; subroutine files come from ProgramSetup::load_subroutine.
#include <Eigen/Core>
#include <array>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "control/gcode.hpp"

namespace contour::control::gcode_detail {

enum class Units { kMm, kInch };
enum class CompSide { kOff = 0, kRight = 1, kLeft = 2 };
enum class OType {
  kNone,
  kSub,
  kEndsub,
  kCall,
  kDo,
  kWhile,
  kIf,
  kElseif,
  kElse,
  kEndif,
  kBreak,
  kContinue,
  kEndwhile,
  kReturn,
  kRepeat,
  kEndrepeat
};

inline constexpr int kSubParams = 30;   // #1..#30 subroutine arguments
inline constexpr int kMaxCallLevel = 10; // LinuxCNC INTERP_SUB_ROUTINE_LEVELS

// G codes x10 (G2 = 20, G59.3 = 593), as LinuxCNC numbers them.
namespace g {
inline constexpr int k0 = 0, k1 = 10, k2 = 20, k3 = 30, k4 = 40, k10 = 100, k17 = 170, k18 = 180,
                     k19 = 190, k20 = 200, k21 = 210, k28 = 280, k28_1 = 281, k30 = 300,
                     k30_1 = 301, k40 = 400, k41 = 410, k41_1 = 411, k42 = 420, k42_1 = 421,
                     k43 = 430, k43_1 = 431, k43_2 = 432, k49 = 490, k52 = 520, k53 = 530,
                     k54 = 540, k59_3 = 593, k61 = 610, k61_1 = 611, k64 = 640, k73 = 730,
                     k80 = 800, k81 = 810, k82 = 820, k83 = 830, k85 = 850, k89 = 890, k90 = 900,
                     k90_1 = 901, k91 = 910, k91_1 = 911, k92 = 920, k92_1 = 921, k92_2 = 922,
                     k92_3 = 923, k94 = 940, k97 = 970, k98 = 980, k99 = 990;
}  // namespace g

// Modal group indices (LinuxCNC GM_*).
namespace gm {
inline constexpr int kModal0 = 0, kMotion = 1, kPlane = 2, kDistance = 3, kIjkDistance = 4,
                     kFeedMode = 5, kUnits = 6, kCutterComp = 7, kToolOffset = 8, kRetract = 10,
                     kCoordSystem = 12, kControl = 13, kSpindleMode = 14, kG92Applied = 16;
}  // namespace gm

// One word read from a line: value (evaluated), and its column in the original text.
struct WordVal {
  bool set = false;
  double v = 0.0;
  int col = 0;
};

// A line after reading (LinuxCNC's block_struct).
struct LineBlock {
  std::array<WordVal, 26> w{};  // letters a..z (g, m, n, o, p, q, l, h, t, d kept apart below)
  std::array<int, 17> g_modes{};
  std::array<int, 17> g_cols{};
  std::array<int, 11> m_modes{};
  std::array<int, 11> m_cols{};
  int m_count = 0;
  bool user_m = false;
  double p_number = -1.0;  // LinuxCNC keeps -1 for "no P" and tests that value
  double q_number = -1.0;
  int l_number = -1;
  int h_number = -1;
  int t_number = 0;
  double d_number = 0.0;
  WordVal radius;  // '@' polar radius
  WordVal theta;   // '^' polar angle (deg)
  int motion_to_be = -1;
  std::string comment;  // the last comment of the line (LinuxCNC keeps only that one)
  int comment_col = 0;
  OType o_type = OType::kNone;
  bool o_present = false;
  std::string o_name;
  int o_col = 0;
  int param_cnt = 0;
  std::array<double, kSubParams> params{};
  std::vector<std::pair<int, double>> param_sets;          // #n=value on this line
  std::vector<std::pair<std::string, double>> named_sets;  // #<name>=value
  [[nodiscard]] const WordVal& operator[](char c) const { return w[static_cast<std::size_t>(c - 'a')]; }
  WordVal& operator[](char c) { return w[static_cast<std::size_t>(c - 'a')]; }
  void reset();
};

// A source of lines: the main program (streaming), a subroutine file, a copied subroutine body,
// or an MDI command. lines[i] has line number first_line + i.
struct Source {
  std::string name;
  std::vector<std::string> lines;
  int first_line = 1;  // line number of lines[0]
  bool streaming = false;
  bool eof = false;
  bool mdi = false;
  [[nodiscard]] int end_line() const { return first_line + static_cast<int>(lines.size()); }
  [[nodiscard]] bool has(int line) const { return line >= first_line && line < end_line(); }
  [[nodiscard]] const std::string& at(int line) const {
    return lines[static_cast<std::size_t>(line - first_line)];
  }
};

// A label in the offset map (LinuxCNC's `offset`): where its O-line is.
struct Label {
  OType type = OType::kNone;
  int source = 0;
  int line = 0;  // line number of the O-line
  int repeat_count = -1;
  int end_line = 0;  // loops in the main source: line of the matching end, once read
};

struct NamedParam {
  double value = 0.0;
  bool readonly = false;
  int lookup = -1;  // predefined (#<_x>, ...): computed on read
};

struct CallFrame {
  std::string sub_name;
  int return_source = 0;
  int return_line = 0;  // next line to read after return
  std::array<double, kSubParams> saved_params{};
  std::map<std::string, NamedParam> locals;
};

// A canonical call held back by cutter compensation (LinuxCNC's interp queue).
struct Queued {
  enum class Type { kFeed, kTraverse, kArc, kFeedRate, kDwell, kSpindle, kSpeed, kMist, kFlood,
                    kUserM, kMessage };
  Type type = Type::kFeed;
  int line = 0;
  int source = 0;
  // straight: direction d*, end x y z (program coordinates of the comp plane, see canon_queue)
  double dx = 0, dy = 0, dz = 0, x = 0, y = 0, z = 0;
  // arc
  double end1 = 0, end2 = 0, center1 = 0, center2 = 0, end3 = 0, original_turns = 0;
  int turn = 0;
  double value = 0, value2 = 0;
  int ivalue = 0;
  std::string text;
};

class Interpreter {
 public:
  Interpreter(ProgramSetup setup, MachineContext machine, std::string file_name);

  // Streaming main program.
  void push_line(std::string_view text, std::vector<Block>& out);
  void finish(std::vector<Block>& out);
  void set_block_delete(bool on) { setup_.block_delete = on; }
  // One MDI command (no program file): executes it now, with the current modal state.
  void mdi(std::string_view text, std::vector<Block>& out);
  void set_position_mm(const Eigen::Vector3d& machine_mm);

  [[nodiscard]] bool ended() const { return ended_; }
  [[nodiscard]] int line_number() const { return pushed_lines_; }
  [[nodiscard]] const Eigen::Vector3d& position_mm() const { return pos_mm_; }
  [[nodiscard]] MachineContext machine() const;
  [[nodiscard]] bool machine_changed() const { return machine_changed_; }
  [[nodiscard]] ModalState modal_state() const;
  [[nodiscard]] const std::optional<ModalState>& resume_state() const { return resume_state_; }
  std::vector<Message> take_messages();
  [[nodiscard]] const std::string& source_name(int id) const;
  [[nodiscard]] std::size_t retained_lines() const {
    std::size_t n = 0;
    for (const auto& s : sources_) n += s.lines.size();
    return n;
  }

 private:
  // ---- driver (gcode_interp.cpp)
  void run(std::vector<Block>& out);
  void step_line(const Source& src, int line_no);
  void at_end_of_source();
  void end_program_block();
  [[noreturn]] void fail(int column, const std::string& msg) const;
  [[noreturn]] void fail_word(char letter, const std::string& msg) const;
  int word_col(char letter) const;
  void trim_main();

  // ---- reading (gcode_read.cpp)
  void normalize(std::string_view raw);
  void read_items();
  void read_one_item(int& i);
  void read_o(int& i);
  double read_real_value(int& i);
  double read_real_expression(int& i);
  double read_real_number(int& i);
  double read_parameter(int& i, bool check_exists);
  double read_unary(int& i);
  int read_integer_value(int& i);
  int read_operation(int& i);
  std::string read_name(int& i);
  void read_parameter_setting(int& i);
  void read_g(int& i);
  void read_m(int& i);
  int read_n_number(int& i);
  [[nodiscard]] int col_at(int i) const;
  void enhance_block();
  void check_items();
  void check_g_codes();
  void check_other_codes();
  // parameters
  double param_get(int index, int col) const;
  bool find_named(const std::string& name, double& value) const;
  double lookup_predefined(int which) const;
  void add_named(const std::string& name);
  void store_named(const std::string& name, double value, int col);
  void init_named_parameters();

  // ---- execution (gcode_interp.cpp)
  void execute_line();
  void execute_block();
  void convert_comment(const std::string& comment, int col);
  std::string expand_debug(const std::string& text, int col) const;
  void convert_m();
  void convert_g();
  void convert_stop();
  void convert_tool_select();
  void convert_tool_change();
  void convert_set_plane(int code);
  void convert_length_units(int code);
  void convert_cutter_compensation(int code);
  void convert_cutter_compensation_off();
  void convert_cutter_compensation_on(CompSide side);
  void convert_tool_length_offset(int code);
  void convert_coordinate_system(int code);
  void convert_control_mode(int code);
  void convert_distance_mode(int code);
  void convert_modal_0(int code);
  void convert_setup();       // G10 L2 / L20
  void convert_setup_tool();  // G10 L1 / L10 / L11
  void convert_axis_offsets(int code);
  void convert_home(int code);
  void convert_savehome(int code);
  void convert_motion(int motion);
  void convert_straight(int move);
  void convert_arc(int move);
  void arc_data_r(int move, double cx, double cy, double ex, double ey, double radius, int p,
                  double& ccx, double& ccy, int& turn, double tolerance, int col);
  void arc_data_ijk(int move, double cx, double cy, double ex, double ey, bool abs, double i,
                    double j, int p, double& ccx, double& ccy, int& turn, double rtol, double stol,
                    int col);
  void find_ends(double& x, double& y, double& z);
  void find_relative(double x1, double y1, double z1, double& x2, double& y2, double& z2) const;
  void find_current_in_system(int system, double& x, double& y, double& z, bool with_tlo) const;
  int find_tool_index(int toolno, int col) const;
  void set_tool_parameters();
  [[nodiscard]] double user_to_program(double v) const;
  [[nodiscard]] double program_to_user(double v) const;
  void load_origin(int system);

  // ---- canned cycles (gcode_cycles.cpp)
  void convert_cycle(int motion);
  void convert_cycle_plane(int motion);
  void cycle_feed(int plane, double a, double b, double c);
  void cycle_traverse(int plane, double a, double b, double c);

  // ---- cutter compensation (gcode_comp.cpp)
  void comp_get_current(double& x, double& y, double& z) const;
  void comp_set_current(double x, double y, double z);
  void comp_get_programmed(double& x, double& y, double& z) const;
  void comp_set_programmed(double x, double y, double z);
  void convert_straight_comp1(int move, double px, double py, double pz);
  void convert_straight_comp2(int move, double px, double py, double pz);
  void convert_arc_comp1(int move, double ex, double ey, double ez, double ox, double oy);
  void convert_arc_comp2(int move, double ex, double ey, double ez, double ox, double oy);
  void enqueue_straight(bool feed, double dx, double dy, double dz, double x, double y, double z);
  void enqueue_arc(double original_turns, double e1, double e2, double c1, double c2, int turn,
                   double e3);
  void move_endpoint_and_flush(double x, double y);
  void dequeue_canons();
  void set_endpoint(double x, double y);
  void qc_scale(double k);
  double find_turn(double x1, double y1, double cx, double cy, int turn, double x2, double y2) const;

  // ---- O-words (gcode_oword.cpp)
  void convert_control_functions();
  void control_save_offset();
  Label* control_find_oword(const std::string& name);
  void control_back_to(const std::string& name);
  void execute_call();
  void execute_return();
  void jump_to(int source, int line);
  int load_sub_file(const std::string& name);

  // ---- canonical calls -> Blocks (gcode_canon.cpp)
  [[nodiscard]] Eigen::Vector3d to_machine(double x, double y, double z) const;
  [[nodiscard]] Eigen::Vector3d from_machine(const Eigen::Vector3d& m) const;
  Block base_block() const;
  void canon_straight(bool feed, int line, double x, double y, double z);
  void canon_arc(int line, double fe, double se, double fc, double sc, int rotation, double ae);
  // Line and source the next emitted Block carries (dequeued calls keep theirs); -1 = current.
  int emit_line_ = -1;
  int emit_source_ = -1;
  void canon_dwell(double seconds);
  void canon_set_feed_rate(double rate);
  void canon_spindle(SpindleDir dir);
  void canon_speed(double rpm);
  void canon_mist(bool on);
  void canon_flood(bool on);
  void canon_g5x(int index, double x, double y, double z);
  void canon_g92(double x, double y, double z);
  void canon_rotation(double deg);
  void canon_tool_offset(double x, double y, double z);
  void canon_change_tool(int tool_number);
  void canon_set_tool_number(int tool_number);
  void canon_stop(BlockKind kind, const std::string& message);
  void canon_user_m(int m, double p, double q);
  void canon_message(const std::string& text);
  void canon_select_plane(int plane);
  void emit(Block b);
  // queue-aware wrappers (LinuxCNC enqueue_*): hold while the comp queue is not empty
  void enqueue_feed_rate(double f);
  void enqueue_dwell(double t);
  void enqueue_spindle(SpindleDir d);
  void enqueue_speed(double s);
  void enqueue_mist(bool on);
  void enqueue_flood(bool on);
  void enqueue_user_m(int m, double p, double q);

  // ---- configuration
  ProgramSetup setup_;
  std::vector<ToolData> tool_table_;  // index 0 = spindle, 1..n = tools (LinuxCNC non-random)
  std::vector<double> params_;
  std::set<int> persistent_;
  bool machine_changed_ = false;

  // ---- sources and control flow
  std::vector<Source> sources_;  // [0] = main program
  int cur_source_ = 0;
  int cur_line_ = 1;      // next line number to read in cur_source_
  int sequence_ = 0;      // line number of the line being executed
  int pushed_lines_ = 0;  // main program lines pushed so far
  long executed_lines_ = 0;
  bool percent_seen_content_ = false;
  bool percent_flag_ = false;
  std::map<std::string, Label> offset_map_;
  std::vector<CallFrame> frames_;  // frames_[0] = top level (globals live there)
  std::string skipping_o_;
  bool skipping_ = false;
  std::string skipping_to_sub_;
  bool skipping_to_sub_on_ = false;
  int skipping_start_ = 0;
  bool defining_sub_ = false;
  std::string sub_name_;  // the sub being defined (call level 0)
  int defining_line_ = 0;
  bool executed_if_ = false;
  bool doing_break_ = false;
  bool doing_continue_ = false;
  double test_value_ = 0.0;
  double return_value_ = 0.0;
  bool value_returned_ = false;
  bool ended_ = false;

  // ---- the line being processed
  std::string raw_;
  std::string line_;       // normalised
  std::vector<int> cols_;  // column (1-based) in raw_ of each character of line_
  LineBlock blk_;
  int line_length_ = 0;

  // ---- modal state (program units unless stated)
  Units units_ = Units::kMm;
  double cur_[3] = {0, 0, 0};   // current position, program coordinates
  double prog_[3] = {0, 0, 0};  // programmed (uncompensated) position under cutter comp
  double origin_[3] = {0, 0, 0};
  double axis_off_[3] = {0, 0, 0};
  double tool_off_[3] = {0, 0, 0};
  double rotation_xy_ = 0.0;  // deg
  int origin_index_ = 1;
  int plane_ = 1;  // 1 XY, 2 YZ, 3 XZ (LinuxCNC CANON_PLANE_*)
  bool absolute_ = true;
  bool ijk_absolute_ = false;
  int motion_mode_ = g::k80;
  double feed_rate_ = 0.0;
  double speed_ = 0.0;
  SpindleDir spindle_ = SpindleDir::kOff;
  bool mist_ = false;
  bool flood_ = false;
  int control_mode_ = 0;  // 0 continuous (G64), 1 exact path (G61), 2 exact stop (G61.1)
  double control_tolerance_ = 0.0;
  bool retract_r_plane_ = true;  // G99 (LinuxCNC starts in R_PLANE); false = G98, old Z
  double cycle_r_ = 0, cycle_cc_ = 0, cycle_il_ = 0, cycle_p_ = 0, cycle_q_ = 0;
  bool cycle_il_flag_ = false;
  CompSide comp_side_ = CompSide::kOff;
  double comp_radius_ = 0.0;
  int comp_orientation_ = 0;
  bool comp_firstmove_ = true;
  bool arc_not_allowed_ = false;
  int current_pocket_ = 0;
  int selected_pocket_ = 0;  // LinuxCNC reads the prepared pocket at start: 0, so M6 without T unloads
  int selected_tool_ = -1;
  bool toolchange_refresh_ = false;  // re-read the position at the next line (LinuxCNC read_inputs)

  // ---- cutter compensation queue
  std::vector<Queued> qc_;
  double endpoint_[2] = {0, 0};
  bool endpoint_valid_ = false;

  // ---- canonical state (what Blocks carry), machine mm
  Eigen::Vector3d pos_mm_;
  Eigen::Vector3d g5x_mm_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d g92_mm_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d tlo_mm_ = Eigen::Vector3d::Zero();
  double rot_deg_ = 0.0;
  int canon_plane_ = 1;
  int canon_system_ = 1;
  double canon_feed_mm_min_ = 0.0;
  SpindleDir canon_spindle_ = SpindleDir::kOff;
  double canon_rpm_ = 0.0;
  bool canon_mist_ = false;
  bool canon_flood_ = false;
  int canon_tool_ = 0;
  bool in_cycle_ = false;  // canned-cycle moves run in exact path mode (LinuxCNC)
  std::vector<Block>* out_ = nullptr;
  std::vector<Message> messages_;
  bool suppress_ = false;  // run-from-line: before the start line nothing is emitted
  std::optional<ModalState> resume_state_;
};

}  // namespace contour::control::gcode_detail
