#pragma once
// Machine context of the G-code interpreter (issues 18 and 19): what LinuxCNC keeps in its numbered
// parameters (the `.var` file) and its tool table (the `.tbl` file), and the pure text functions
// that read and write both formats so the daemon can persist them atomically.
//
// Units: the context is in machine units, mm (contourd is a metric machine): work offsets, G92
// offset, G28/G30 positions, tool offsets and diameters in mm; rotations and tool angles in degrees.
// The interpreter converts to program units (G20/G21) where LinuxCNC does (USER_TO_PROGRAM_LEN).
//
// Numbered parameters where LinuxCNC keeps them (RS274/NGC and LinuxCNC 2.9 documentation):
//   5161-5169 G28 position X Y Z A B C U V W       5181-5189 G30 position
//   5210 G92 offset applied (1/0)                  5211-5219 G92 offset X..W
//   5220 active coordinate system 1..9 (G54..G59.3)
//   5221-5230 G54 X..W and R (XY rotation, deg); 5241-5250 G55; ... 5381-5390 G59.3 (stride 20)
//   5400-5413 tool in spindle: number, offsets X..W, diameter, front/back angle, orientation
//   5420-5428 current position (program coordinates)   5599 (DEBUG,...) output enabled
// The `.var` file holds the parameters LinuxCNC requires (G28/G30, G92, coordinate systems) plus
// any other parameter the file already had: `persistent` records that set.
//
// Errors: parse_var_file / parse_tool_table throw MachineFileError("file:line: message").
// Not RT (allocates).
#include <Eigen/Core>
#include <array>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace contour::control {

inline constexpr int kParameterCount = 5602;  // numbered parameters #1..#5601 (LinuxCNC 2.9)
inline constexpr int kParamG28 = 5161;
inline constexpr int kParamG30 = 5181;
inline constexpr int kParamG92Applied = 5210;
inline constexpr int kParamG92 = 5211;
inline constexpr int kParamCoordSystem = 5220;
inline constexpr int kParamG54 = 5221;  // system n (1..9) starts at 5201 + 20 n
inline constexpr int kParamToolNumber = 5400;
inline constexpr int kParamPosition = 5420;
inline constexpr int kParamDebug = 5599;

// One tool-table line, LinuxCNC `.tbl` fields: T P D X Y Z A B C U V W I J Q ;comment.
struct ToolData {
  int number = 0;                   // T
  int pocket = 0;                   // P
  std::array<double, 9> offset{};   // X Y Z (mm) A B C (deg) U V W (mm)
  double diameter_mm = 0.0;         // D
  double front_angle_deg = 0.0;     // I
  double back_angle_deg = 0.0;      // J
  int orientation = 0;              // Q (lathe tools; 0 = mill)
  std::string comment;              // text after ';'
  [[nodiscard]] double length_mm() const { return offset[2]; }
};

class MachineFileError : public std::runtime_error {
 public:
  MachineFileError(const std::string& file, int line, const std::string& message);
  [[nodiscard]] int line() const { return line_; }

 private:
  int line_;
};

// What the interpreter reads at start and may change while running (G10, G28.1, G30.1, G92,
// G54..G59.3, M6/M61). The daemon owns it: it loads it from its files, hands it to GcodeParser,
// reads it back (GcodeParser::machine()) and persists it when `changed` says so.
struct MachineContext {
  MachineContext();

  std::vector<double> parameters;  // [0, kParameterCount); [0] unused
  std::set<int> persistent;        // numbers written to the .var file (see above)
  std::vector<ToolData> tools;     // tool table in file order (LinuxCNC index 1..n)
  int tool_in_spindle = 0;         // tool number, 0 = empty spindle

  // Offsets as vectors (mm), coordinate systems 1..9 = G54..G59.3.
  [[nodiscard]] Eigen::Vector3d work_offset_mm(int system) const;
  void set_work_offset_mm(int system, const Eigen::Vector3d& v);
  [[nodiscard]] double work_rotation_deg(int system) const;
  [[nodiscard]] int active_system() const;  // 1..9
  [[nodiscard]] Eigen::Vector3d g92_offset_mm() const;
  [[nodiscard]] bool g92_applied() const;
  [[nodiscard]] Eigen::Vector3d g28_mm() const;
  [[nodiscard]] Eigen::Vector3d g30_mm() const;
  void set_g28_mm(const Eigen::Vector3d& v);
  void set_g30_mm(const Eigen::Vector3d& v);
  [[nodiscard]] const ToolData* find_tool(int number) const;
};

// Parameters LinuxCNC always writes to the .var file (5161..5390, its _required_parameters).
[[nodiscard]] const std::vector<int>& required_parameters();

// printf's "%.<decimals>f" without <cstdio> (control/ stays free of stdio): fixed notation,
// rounded to nearest. Used by the text formats and the interpreter's messages.
[[nodiscard]] std::string format_fixed(double v, int decimals);

// `.var` text: one "number value" pair per line, numbers strictly increasing (LinuxCNC refuses a
// file out of order), 1 <= number < kParameterCount. Blank lines are allowed; anything else is an
// error naming the line.
[[nodiscard]] std::map<int, double> parse_var_file(std::string_view text, const std::string& file);
// Applies a parsed .var file: listed parameters take their value (and become persistent); the
// required parameters not listed are zero, as LinuxCNC reads them.
void apply_var_file(MachineContext& m, const std::map<int, double>& vars);
// LinuxCNC's format ("%d\t%f" per line): required parameters plus the persistent ones.
[[nodiscard]] std::string format_var_file(const MachineContext& m);

// `.tbl` text. Lines are split at ';' (the rest is the comment); fields are single letters with a
// number, separated by spaces or tabs; T is required and unique. Lines starting with ';' and
// blank lines are skipped. Unknown letters and bad numbers are errors naming file:line.
[[nodiscard]] std::vector<ToolData> parse_tool_table(std::string_view text, const std::string& file);
// LinuxCNC's format: "T%-3d P%-3d" then the non-zero fields as " D%+f" ... " Q%d", then " ;comment".
[[nodiscard]] std::string format_tool_table(const std::vector<ToolData>& tools);

}  // namespace contour::control
