#pragma once
// Streaming RS274/NGC interpreter, LinuxCNC 2.9 dialect (issues 3, 18, 19). control/GCODE.md lists
// the supported words, every deliberate refusal and the conformance figures against LinuxCNC's own
// interpreter.
//
// The caller pushes the program line by line (no I/O here: control/ is pure; subroutine files come
// through ProgramSetup::load_subroutine); each line yields zero or more Blocks in machine
// coordinates of the controlled point (mm, mm/min, s). A program without loops and subroutines
// streams in constant memory (a 1,000,000-line CAM program runs through a bounded planner window);
// loops and subroutines keep only the lines a jump back can reach.
//
// Semantics are LinuxCNC's wherever RS274/NGC defines them: order of execution within a line,
// modal groups, expressions and parameters read at read time, O-word control flow, canned cycles
// expanded into moves as LinuxCNC's interpreter emits them, cutter radius compensation with its
// entry/exit rules and gouge errors, G5x/G92/G43 offsets applied like LinuxCNC's canonical layer:
//   machine = R(rotation) (program + G92) + G5x + tool length offset.
// Conventions stated because dialects differ:
//   - The first motion starts from ProgramSetup::start_mm (machine coordinates).
//   - Rapids carry ProgramSetup::rapid_mm_min as their feed.
//   - A full circle (start == end, `G2 I.5 J.5`) is one arc segment of one full turn; P<n> adds
//     n-1 turns (PathSegment::turns); helices end at the programmed normal-axis value.
//   - M100..M199 (user M-codes) come as a BlockKind::kDwell of 0 s with user_m set (a barrier for
//     the planner; the daemon hands user_m, user_p, user_q to the machine logic).
//   - (MSG,...), (DEBUG,...), (PRINT,...), (LOG,...) are messages (take_messages()), not motion.
//   - Without ProgramSetup::require_program_end, end of input without M2/M30/'%' ends the program
//     (LinuxCNC rejects that file; the conformance suite sets the flag).
// Rejected with GcodeError("file:line:column: message") naming the word, never ignored: see
// control/GCODE.md (G33, G76, G5.x, G93, G95, G96, G38.x, G7/G8, G70-G72, G74/G84/G86-G88, M19,
// M48-M53, M60, M62-M68, M70-M73, M98/M99, A/B/C/U/V/W axes, ...).
#include <Eigen/Core>
#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "control/gcode_machine.hpp"
#include "control/path.hpp"

namespace contour::control {

namespace gcode_detail {
class Interpreter;
}

enum class BlendMode { kExactStop, kFull, kLimited };  // G61/G61.1, G64, G64 P<tol>
enum class SpindleDir { kOff, kCw, kCcw };

enum class BlockKind {
  kMotion,        // seg is a line (G0/G1/G28/G30/G53/canned cycle) or an arc (G2/G3)
  kDwell,         // G4 (and G82/G89 bottom dwell): stop, wait dwell_s; user_m != 0: M100..M199
  kProgramStop,   // M0: hold until resumed
  kOptionalStop,  // M1: hold if optional stop is on
  kToolChange,    // T.. M6: manual tool change, hold with message until resumed
  kEnd            // M2/M30/closing '%'/end of input
};

struct Block {
  BlockKind kind = BlockKind::kMotion;
  int line = 0;  // source line, 1-based, in source `source` (0 = the program itself)
  PathSegment seg;
  bool rapid = false;
  double feed_mm_min = 0.0;  // rapids: ProgramSetup::rapid_mm_min
  double dwell_s = 0.0;
  BlendMode blend = BlendMode::kFull;
  double tolerance_mm = 0.0;  // for kLimited
  SpindleDir spindle = SpindleDir::kOff;
  double spindle_rpm = 0.0;
  bool mist = false;    // M7
  bool flood = false;   // M8
  int tool = 0;         // tool in the spindle (kToolChange: the tool to load)
  std::string message;  // holds
  // Added for issues 18/19 (defaults keep older consumers working):
  int source = 0;                                           // GcodeParser::source_name(source)
  int coord_system = 1;                                     // 1..9 = G54..G59.3
  Eigen::Vector3d work_offset_mm = Eigen::Vector3d::Zero();  // G5x origin (machine)
  Eigen::Vector3d g92_offset_mm = Eigen::Vector3d::Zero();   // G92/G52 offset
  Eigen::Vector3d tool_offset_mm = Eigen::Vector3d::Zero();  // G43 tool length offset (X Y Z)
  double xy_rotation_deg = 0.0;                              // G10 L2 R rotation of the system
  int user_m = 0;                                           // 100..199 for a user M-code
  double user_p = -1.0;                                     // its P and Q, -1 when absent
  double user_q = -1.0;                                     //   (as LinuxCNC passes them)
};

// Program (work) coordinates of a machine point under a block's offsets.
[[nodiscard]] Eigen::Vector3d work_coordinates(const Block& b, const Eigen::Vector3d& machine_mm);

struct ToolEntry {
  int number = 0;
  double length_mm = 0.0;
};

// Everything the parser needs from the `program:` config section (config/program_config.hpp).
struct ProgramSetup {
  std::array<Eigen::Vector3d, 6> work_offsets_mm{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                                 Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                                 Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  std::vector<ToolEntry> tools;
  Eigen::Vector3d g28_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d g30_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d start_mm = Eigen::Vector3d::Zero();
  double rapid_mm_min = 5000.0;
  // LinuxCNC's CENTER_ARC_RADIUS_TOLERANCE_MM / _INCH: an IJK arc is refused when its end radius
  // differs from its start radius by more than 100x this, or by more than this and 0.1 %.
  double arc_tolerance_mm = 0.028284271247461903;
  double arc_tolerance_inch = 0.0028284271247461905;
  BlendMode default_blend = BlendMode::kLimited;
  double default_tolerance_mm = 0.05;
  // Issues 18/19:
  // Offsets, G28/G30 positions and the tool table. When set, it replaces work_offsets_mm, tools,
  // g28_mm and g30_mm (which are then ignored).
  std::optional<MachineContext> machine;
  // Subroutine files: `o<name> call` of a subroutine not defined in the program asks for
  // "<name>.ngc" (name in lower case, as LinuxCNC reads it); the callback returns its text or
  // nullopt. Unset: no subroutine files.
  std::function<std::optional<std::string>(const std::string& name)> load_subroutine;
  bool block_delete = false;          // '/' switch: on = lines starting with '/' are skipped
  bool require_program_end = false;   // end of input without M2/M30/'%' is an error (LinuxCNC)
  int run_from_line = 0;              // > 0: emit nothing before this line (see resume_state())
  // > 0: refuse a program once it has executed this many lines (loops that never end; the fuzz
  // harness sets it). 0: no limit, as LinuxCNC.
  long max_executed_lines = 0;
};

// A message from the program: (MSG,...), (DEBUG,...) with #parameters expanded, (PRINT,...),
// (LOG,...).
struct Message {
  enum class Kind { kMsg, kDebug, kPrint, kLog };
  Kind kind = Kind::kMsg;
  int line = 0;
  std::string source;
  std::string text;
  // Where it falls in the block stream: the number of blocks already in `out` when the message
  // was produced, in the parse_line/finish/mdi call that produced it (show it when the block at
  // that index starts; LinuxCNC issues a message before the moves of its line).
  std::size_t out_index = 0;
};

// The interpreter's state at a point of the program: for run-from-line (the state at the start
// line, so the daemon can approach safely), MDI status and preview.
struct ModalState {
  int line = 0;
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();  // machine coordinates
  Eigen::Vector3d program_position = Eigen::Vector3d::Zero();  // program units and coordinates
  int motion_mode = -1;  // G code x10: 0, 10, 20, 30, 73, 81.., 800 (G80)
  int plane = 17;        // 17, 18, 19
  bool metric = true;    // G21
  bool absolute = true;  // G90
  bool ijk_absolute = false;  // G90.1
  int coord_system = 1;       // 1..9 = G54..G59.3
  Eigen::Vector3d work_offset_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d g92_offset_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d tool_offset_mm = Eigen::Vector3d::Zero();
  double xy_rotation_deg = 0.0;
  double feed_mm_min = 0.0;
  SpindleDir spindle = SpindleDir::kOff;
  double spindle_rpm = 0.0;
  bool mist = false;
  bool flood = false;
  int tool = 0;           // tool in the spindle
  int selected_tool = -1; // last T word
  BlendMode blend = BlendMode::kFull;
  double tolerance_mm = 0.0;
  bool cutter_comp = false;
  bool retract_r_plane = false;  // G99
};

class GcodeError : public std::runtime_error {
 public:
  GcodeError(const std::string& file, int line, int column, const std::string& message);
  [[nodiscard]] int line() const { return line_; }
  [[nodiscard]] int column() const { return column_; }

 private:
  int line_;
  int column_;
};

class GcodeParser {
 public:
  explicit GcodeParser(ProgramSetup setup, std::string file_name = "<program>");
  ~GcodeParser();
  GcodeParser(GcodeParser&&) noexcept;
  GcodeParser& operator=(GcodeParser&&) noexcept;
  GcodeParser(const GcodeParser&) = delete;
  GcodeParser& operator=(const GcodeParser&) = delete;

  // Parses the next line (newline stripped or not). Appends the blocks it produces to `out`.
  // Throws GcodeError naming file:line:column. Not RT (allocates).
  void parse_line(std::string_view text, std::vector<Block>& out);
  // End of input; appends a kEnd block if the program did not end itself (or throws with
  // ProgramSetup::require_program_end, or when a subroutine/loop/if is still open).
  void finish(std::vector<Block>& out);
  // The block delete switch ('/'), live: applies from the next line read (LinuxCNC's switch acts
  // on the lines the interpreter reads after it is flipped).
  void set_block_delete(bool on);

  [[nodiscard]] bool ended() const;
  [[nodiscard]] int line_number() const;
  [[nodiscard]] const Eigen::Vector3d& position_mm() const;

  // MDI (issue 18): one command line executed now with the modal state left by earlier calls;
  // `o<name> call` of subroutine files works, other O-words need a program. M2/M30 reset the
  // modal state as in a program and leave the interpreter usable. Call set_position_mm() first
  // with the machine's actual position.
  void mdi(std::string_view text, std::vector<Block>& out);
  void set_position_mm(const Eigen::Vector3d& machine_mm);

  // Offsets, G28/G30 positions, tool table and tool in spindle as the program left them, and
  // whether G10, G28.1, G30.1, G92.x, G54..G59.3, M6 or M61 changed them since construction (the
  // daemon persists machine() when this is true).
  [[nodiscard]] MachineContext machine() const;
  [[nodiscard]] bool machine_changed() const;

  [[nodiscard]] ModalState modal_state() const;
  // With ProgramSetup::run_from_line: the state when the start line was reached (set once the
  // line has been executed up to its first motion); nullopt before.
  [[nodiscard]] const std::optional<ModalState>& resume_state() const;
  // Messages since the last call, in program order.
  std::vector<Message> take_messages();
  [[nodiscard]] const std::string& source_name(int source) const;
  // Program lines held in memory (for jumps back: loops, calls, subroutine bodies); stays small
  // for a program without loops and subroutines however long it is.
  [[nodiscard]] std::size_t retained_lines() const;

 private:
  std::unique_ptr<gcode_detail::Interpreter> impl_;
};

// Axis-aligned box, mm.
struct Extents {
  Eigen::Vector3d min_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d max_mm = Eigen::Vector3d::Zero();
  bool empty = true;
  void add(const Eigen::Vector3d& p);
};

// Preview (issue 18): extents of a program in machine and work coordinates (arcs included at
// their extreme points), tools used, blocks. Feed the Blocks of a whole program to add().
struct ProgramPreview {
  Extents machine;
  Extents work;
  std::set<int> tools;           // tools loaded by M6 (and the spindle's tool at the first motion)
  std::size_t motion_blocks = 0;
  std::size_t blocks = 0;
  double feed_length_mm = 0.0;
  double rapid_length_mm = 0.0;
  double feed_time_s = 0.0;      // sum of feed moves' length / feed (no acceleration)
  void add(const Block& b);
};

// Adds a segment's bounding box to `e` (lines: end points; arcs and helices: the extreme points
// of the swept angle in the plane, the end points along the normal).
void segment_extents(const PathSegment& s, Extents& e);

}  // namespace contour::control
