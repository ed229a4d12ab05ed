#pragma once
// Streaming RS274/NGC parser (LinuxCNC dialect subset, issue 3).
//
// The caller pushes the program line by line (no I/O here: control/ is pure); each line yields zero
// or more Blocks in machine coordinates (mm, mm/min, s). Memory is O(1) in the program length, so a
// 1,000,000-line program streams through a bounded planner window.
//
// Supported: G0 G1 G2 G3 (IJK and R forms, full circles, helical, P turns) G4 (P seconds) G17 G18
// G19 G20 G21 G28 G30 G40 G43 H G49 G53 G54..G59 G61 G61.1 G64 [P tol] G80 G90 G91 G90.1 G91.1
// G94, F S T H N, M0 M1 M2 M30 M3 M4 M5 M6 M7 M8 M9, comments "( )" and ";", '%' tape markers,
// blank lines, any case and spacing (spaces inside numbers too, as RS274 allows).
// Conventions (stated because dialects differ):
//   - G53 moves to machine coordinates of the controlled point, ignoring work AND tool offsets;
//     it needs G0 or G1 on the line (or modal) and G90.
//   - G28/G30 without axis words: rapid to the YAML reference position (all axes). With axis
//     words: rapid to that intermediate point, then the named axes to the reference position.
//   - G43 without H uses the tool in the spindle; H must be in the YAML tool table.
//   - The first motion block starts from ProgramSetup::start_mm (machine coordinates).
//   - Lines after M2/M30 or the closing '%' are not parsed.
// Rejected at parse time with GcodeError("file:line:column: message"), never ignored: O-words,
// '#' parameters, '[' expressions, block delete '/', G41/G42, canned cycles G81..G89, G98/G99,
// G10, G92, G93/G95, G64 Q, A/B/C/U/V/W axes, unknown G/M codes and letters, two words of one
// modal group, repeated words, G1 without feed, arc radius mismatch (> max(arc_tolerance_mm,
// 0.1% of the radius)), zero-radius arcs, R-form full circles, IJK words outside the plane.
#include <Eigen/Core>
#include <array>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "control/path.hpp"

namespace contour::control {

enum class BlendMode { kExactStop, kFull, kLimited };  // G61, G64, G64 P<tol>
enum class SpindleDir { kOff, kCw, kCcw };

enum class BlockKind {
  kMotion,        // seg is a line (G0/G1/G28/G30/G53) or an arc (G2/G3)
  kDwell,         // G4: stop, wait dwell_s
  kProgramStop,   // M0: hold until resumed
  kOptionalStop,  // M1: hold if optional stop is on
  kToolChange,    // T.. M6: manual tool change, hold with message until resumed
  kEnd            // M2/M30/closing '%'/end of input
};

struct Block {
  BlockKind kind = BlockKind::kMotion;
  int line = 0;  // source line, 1-based
  PathSegment seg;
  bool rapid = false;
  double feed_mm_min = 0.0;  // rapids: ProgramSetup::rapid_mm_min
  double dwell_s = 0.0;
  BlendMode blend = BlendMode::kFull;
  double tolerance_mm = 0.0;  // for kLimited
  SpindleDir spindle = SpindleDir::kOff;
  double spindle_rpm = 0.0;
  bool mist = false;   // M7
  bool flood = false;  // M8
  int tool = 0;        // tool in the spindle
  std::string message;  // holds
};

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
  double arc_tolerance_mm = 0.002;  // LinuxCNC's absolute end-radius tolerance
  BlendMode default_blend = BlendMode::kLimited;
  double default_tolerance_mm = 0.05;
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

  // Parses the next line (newline stripped or not). Appends the blocks it produces to `out`.
  // Throws GcodeError naming file:line:column. Not RT (allocates).
  void parse_line(std::string_view text, std::vector<Block>& out);
  // End of input; appends a kEnd block if the program did not end itself.
  void finish(std::vector<Block>& out);

  [[nodiscard]] bool ended() const { return ended_; }
  [[nodiscard]] int line_number() const { return line_; }
  [[nodiscard]] const Eigen::Vector3d& position_mm() const { return pos_; }

 private:
  struct Word {
    char letter;
    double value;
    int column;
  };
  [[noreturn]] void fail(int column, const std::string& msg) const;
  void execute(const std::vector<Word>& words, std::vector<Block>& out);
  Eigen::Vector3d offset_mm() const;
  Block base_block() const;

  ProgramSetup setup_;
  std::string file_;
  int line_ = 0;
  bool ended_ = false;
  int percent_count_ = 0;
  bool content_seen_ = false;
  std::vector<Word> words_;  // reused per line

  // Modal state.
  Eigen::Vector3d pos_;       // machine coordinates of the controlled point
  int motion_ = -1;           // G code x10 (0, 10, 20, 30), -1 = none yet
  Plane plane_ = Plane::kXY;
  double units_ = 1.0;        // mm per program unit
  bool absolute_ = true;
  bool arc_absolute_ = false;
  int work_ = 0;              // G54 + work_
  double tool_length_mm_ = 0.0;
  double feed_mm_min_ = 0.0;
  BlendMode blend_;
  double tolerance_mm_;
  SpindleDir spindle_ = SpindleDir::kOff;
  double rpm_ = 0.0;
  bool mist_ = false;
  bool flood_ = false;
  int tool_ = 0;
  int selected_tool_ = 0;
};

}  // namespace contour::control
