#pragma once
// config/sim.yaml's text for tests that write a modified copy of it somewhere else (a temporary
// directory, a string loaded without a file). sim.yaml ends with the example machine logic (the
// `plc:` section, issue 20), whose program files are relative to config/: every variant here
// makes them absolute, so the copy loads from any directory.
//
//   SimPlc::kExample           the machine logic as shipped (M6 runs the carousel sequence)
//   SimPlc::kManualToolChange  the same logic with plc.tool_change disabled: M6 pauses for a
//                              manual tool change (issue 18's pause), everything else as shipped
//   SimPlc::kNone              no plc: section at all (a test that adds its own)
//
// A variant whose anchor text is no longer in sim.yaml throws, naming it: a test never runs on a
// config other than the one it says.
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace contour::test {

enum class SimPlc { kExample, kManualToolChange, kNone };

inline std::string sim_yaml(SimPlc plc = SimPlc::kExample) {
  const std::string dir = std::string(CONTOUR_SOURCE_DIR) + "/config/";
  std::ifstream in(dir + "sim.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string y = ss.str();
  if (y.empty()) throw std::runtime_error("sim_yaml: cannot read " + dir + "sim.yaml");
  const auto section = y.find("\nplc:\n");
  if (section == std::string::npos) throw std::runtime_error("sim_yaml: config/sim.yaml has no plc: section");
  if (plc == SimPlc::kNone) {
    // The plc: section is the file's last; its comment block goes with it.
    auto cut = section;
    while (cut > 0) {
      const auto prev = y.rfind('\n', cut - 1);
      const auto line_start = prev == std::string::npos ? 0 : prev + 1;
      if (y.compare(line_start, 1, "#") != 0) break;
      cut = prev == std::string::npos ? 0 : prev;
    }
    return y.substr(0, cut + 1);
  }
  if (plc == SimPlc::kManualToolChange) {
    const std::string from = "tool_change: {enabled: true";
    const auto at = y.find(from, section);
    if (at == std::string::npos) throw std::runtime_error("sim_yaml: no '" + from + "' in config/sim.yaml");
    y.replace(at, from.size(), "tool_change: {enabled: false");
  }
  for (auto at = y.find("{file: plc/", section); at != std::string::npos; at = y.find("{file: plc/", at)) {
    y.replace(at, 7, "{file: " + dir);
    at += 7 + dir.size();
  }
  return y;
}

// sim_yaml(plc) written to `path` (the caller's temporary directory); returns path.
inline std::string write_sim_yaml(const std::string& path, SimPlc plc = SimPlc::kExample,
                                  const std::string& append = "") {
  std::ofstream out(path);
  out << sim_yaml(plc) << append;
  if (!out) throw std::runtime_error("write_sim_yaml: cannot write " + path);
  return path;
}

}  // namespace contour::test
