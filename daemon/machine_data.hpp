#pragma once
// The interpreter's machine context as the daemon owns it (issue 18): work offsets G54..G59.3,
// G92, G28/G30 positions (LinuxCNC's `.var` parameter file) and the tool table (LinuxCNC `.tbl`),
// loaded at start-up and written atomically (tmp + fsync + rename) whenever a program, MDI or a
// socket command changes them.
//
// Sources, in order: the `program:` section's work_offsets / g28_mm / g30_mm / tools; then the
// .var file when it exists (it wins over the YAML values; a missing .var file is created at the
// first change); the .tbl file when configured (it is the tool table, as in LinuxCNC: config
// refuses `program.tools` together with `program.tool_table`).
// Units: mm (machine coordinates). Thread-safe (one mutex); not RT (allocates, does file I/O).
// Errors: the constructor throws MachineDataError("file:line: message") for a bad file;
// commit()/set_tools() throw MachineDataError when a file cannot be written (the in-memory state
// is then unchanged).
#include <Eigen/Core>
#include <cstdint>
#include <mutex>
#include <stdexcept>
#include <string>

#include "config/program_config.hpp"
#include "control/gcode_machine.hpp"

namespace contour::daemon {

class MachineDataError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes `text` to `path` atomically: path.tmp.<pid>, fsync, rename, fsync of the directory.
void write_file_atomic(const std::string& path, const std::string& text);

class MachineData {
 public:
  // var_path / tbl_path: absolute or empty (no persistence of that part).
  MachineData(const config::ProgramConfig& p, std::string var_path, std::string tbl_path);

  [[nodiscard]] control::MachineContext snapshot() const;
  // Tool length offset (mm, X Y Z) the last program or MDI block left active (G43/G49).
  [[nodiscard]] Eigen::Vector3d tool_offset_mm() const;
  // Bumped by every commit: the MDI interpreter is rebuilt when another path changed the context.
  [[nodiscard]] std::uint64_t generation() const;

  // Replaces the context and writes the .var (and the .tbl when its tools changed).
  void commit(const control::MachineContext& m, const Eigen::Vector3d& tool_offset_mm);
  void commit(const control::MachineContext& m);
  // G43/G49 from MDI: the tool length offset only (nothing persisted; generation unchanged).
  void set_tool_offset_mm(const Eigen::Vector3d& v);

  [[nodiscard]] const std::string& var_path() const { return var_path_; }
  [[nodiscard]] const std::string& tbl_path() const { return tbl_path_; }

 private:
  void write_locked(const control::MachineContext& m, bool tools_changed) const;

  mutable std::mutex mu_;
  control::MachineContext m_;
  Eigen::Vector3d tool_offset_mm_ = Eigen::Vector3d::Zero();
  std::uint64_t generation_ = 0;
  std::string var_path_;
  std::string tbl_path_;
};

// A path of the `program:` section: ${VAR:-default} expanded, relative to the config file's
// directory; "" stays "".
[[nodiscard]] std::string resolve_config_path(const std::string& config_file, const std::string& p);

// "G54".."G59.3" for 1..9; 0 for an unknown name.
[[nodiscard]] int coord_system_index(const std::string& name);
[[nodiscard]] const char* coord_system_name(int system);

}  // namespace contour::daemon
