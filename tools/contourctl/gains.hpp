#pragma once
// contourctl gains: user key syntax -> the daemon's `gains set` object, and `gains save`.
//
// Keys (user -> daemon, daemon/commands.cpp cmd_gains):
//   axis.<x|y|z|index>.kp | .ki_per_s (.ki) | .kd_s (.kd) | .ff  -> kp / ki_per_s / kd_s / ff [i]
//   kp=0.6 or kp=0.6,0.6,0.6 (all axes)                          -> kp (as before)
//   coupling.cp | .ci_per_s (.ci) | .cd_s (.cd)                  -> cp / ci_per_s / cd_s
//   coupling=true|false, coupling.enable=true|false              -> coupling
// Per-axis keys need the current arrays (`gains get`) to fill the other axes.
//
// gains save: the active gains are written back INTO the YAML config file, editing only the
// values of the gain keys under `control:` as text, so comments, order and layout survive
// (yaml-cpp's emitter drops comments, and the config loader has no include/overrides key).
// Mapping (config/control_config.cpp): law p -> control.kp and controller: ccc (coupling on) or
// p (off); law pid -> control.pid.{kp,ki_per_s,kd_s} and controller: pid (the config cannot
// express PID + coupling: refused); ff (equal on all axes) -> control.feed_forward;
// cp/ci_per_s/cd_s -> control.coupling.*. The result is validated with the config loader and
// read back before anything is written; the old file is kept as FILE.bak.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace contour::ctl {

// Throws std::invalid_argument naming the bad key or value.
nlohmann::json gains_set_request(const std::vector<std::string>& assignments,
                                 const nlohmann::json& current);

// Returns the new config text for `gains` (a `gains get` reply); throws std::runtime_error naming
// the file and line when the edit cannot be made or the result does not validate.
std::string config_with_gains(const std::string& config_text, const std::string& config_name,
                              const nlohmann::json& gains);

// Human-readable table of a `gains get` reply.
std::string format_gains(const nlohmann::json& gains);

// Replaces `path` by `text` atomically, keeping the owner, group and mode of `like` (the file being
// replaced, or the config it was made from): a temporary file in the same directory gets them
// (fchown/fchmod), is written and fsync'ed, renamed over `path`, and the directory fsync'ed. A
// config like -rw-r----- root:daemon stays so (never world-readable). Throws std::runtime_error
// naming the file; on any error `path` is unchanged and the temporary file removed.
void write_file_like(const std::string& path, const std::string& text, const std::string& like);

}  // namespace contour::ctl
