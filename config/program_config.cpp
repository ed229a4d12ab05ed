#include "config/program_config.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace contour::config {

namespace {
std::array<double, 3> vec3(Section& s, const std::string& key) {
  std::array<double, 3> v{};
  if (!s.has(key)) {
    s.accept(key);
    return v;
  }
  const auto n = s.numbers(key, 3, 3);
  for (std::size_t i = 0; i < 3 && i < n.size(); ++i) v[i] = n[i];
  return v;
}

std::vector<std::string> subroutine_dirs(Section& s) {
  std::vector<std::string> dirs;
  const std::string key = "subroutine_path";
  s.accept(key);
  if (!s.has(key)) return dirs;
  const YAML::Node n = s.node()[key];
  std::vector<YAML::Node> items;
  if (n.IsScalar()) {
    items.push_back(n);
  } else if (n.IsSequence()) {
    for (const auto& i : n) items.push_back(i);
  } else {
    s.error(key, "expected a directory or a list of directories");
    return dirs;
  }
  for (const auto& i : items) {
    if (!i.IsScalar()) {
      s.error(key, "expected a directory name");
      continue;
    }
    const std::string d = i.as<std::string>();
    std::error_code ec;
    if (d.empty() || d[0] != '/') {
      s.error(key, "'" + d + "' is not an absolute path");
    } else if (!std::filesystem::is_directory(d, ec)) {
      s.error(key, "'" + d + "' is not a directory");
    } else {
      dirs.push_back(d);
    }
  }
  return dirs;
}
}  // namespace

ProgramConfig parse_program(Section& s) {
  ProgramConfig c;
  {
    Section w = s.child("work_offsets");
    static const char* kNames[6] = {"G54", "G55", "G56", "G57", "G58", "G59"};
    for (std::size_t i = 0; i < 6; ++i) c.work_offsets_mm[i] = vec3(w, kNames[i]);
    w.finish();
  }
  for (auto& t : s.list("tools")) {
    control::ToolEntry e;
    e.number = static_cast<int>(t.required_integer("number", 0, 99999));
    e.length_mm = t.required_number("length_mm", -1000.0, 1000.0);
    for (const auto& o : c.tools)
      if (o.number == e.number) t.error("number", "tool " + std::to_string(e.number) + " is defined twice");
    c.tools.push_back(e);
    t.finish();
  }
  c.g28_mm = vec3(s, "g28_mm");
  c.g30_mm = vec3(s, "g30_mm");
  c.start_mm = vec3(s, "start_mm");
  c.rapid_mm_min = s.number("rapid_mm_min", c.rapid_mm_min, 1.0, 1e6);
  c.arc_tolerance_mm = s.number("arc_tolerance_mm", c.arc_tolerance_mm, 1e-6, 1.0);
  c.arc_tolerance_inch = s.number("arc_tolerance_inch", c.arc_tolerance_inch, 4e-8, 0.04);
  c.subroutine_path = subroutine_dirs(s);
  c.require_program_end = s.boolean("require_program_end", c.require_program_end);
  c.block_delete = s.boolean("block_delete", c.block_delete);
  c.var_file = s.string("var_file", "");
  if (s.has("var_file") && c.var_file.empty()) s.error("var_file", "must be a file name");
  c.tool_table = s.string("tool_table", "");
  if (s.has("tool_table") && c.tool_table.empty()) s.error("tool_table", "must be a file name");
  if (!c.tool_table.empty() && !c.tools.empty()) {
    s.error("tools", "give the tool table either here or in tool_table (the .tbl file is the tool "
                     "table, as in LinuxCNC), not both");
  }
  s.finish();
  return c;
}

control::ProgramSetup to_program_setup(const ProgramConfig& p, const InterpolatorConfig& i) {
  control::ProgramSetup st;
  auto v = [](const std::array<double, 3>& a) { return Eigen::Vector3d(a[0], a[1], a[2]); };
  for (std::size_t k = 0; k < 6; ++k) st.work_offsets_mm[k] = v(p.work_offsets_mm[k]);
  st.tools = p.tools;
  st.g28_mm = v(p.g28_mm);
  st.g30_mm = v(p.g30_mm);
  st.start_mm = v(p.start_mm);
  st.rapid_mm_min = p.rapid_mm_min;
  st.block_delete = p.block_delete;
  st.arc_tolerance_mm = p.arc_tolerance_mm;
  st.arc_tolerance_inch = p.arc_tolerance_inch;
  st.default_blend = i.blend;
  st.default_tolerance_mm = i.tolerance_um * 1e-3;
  st.require_program_end = p.require_program_end;
  if (!p.subroutine_path.empty()) st.load_subroutine = make_subroutine_loader(p.subroutine_path);
  return st;
}

std::function<std::optional<std::string>(const std::string&)> make_subroutine_loader(
    std::vector<std::string> dirs) {
  return [dirs = std::move(dirs)](const std::string& name) -> std::optional<std::string> {
    const std::string file = name + ".ngc";
    // Names come from the program: a path in them must not reach outside the directories.
    if (file.find('/') != std::string::npos || name.empty() || name[0] == '.') return std::nullopt;
    const auto read = [](const std::filesystem::path& p) -> std::optional<std::string> {
      std::ifstream in(p, std::ios::binary);
      if (!in) return std::nullopt;
      std::ostringstream ss;
      ss << in.rdbuf();
      return ss.str();
    };
    for (const auto& d : dirs) {
      std::error_code ec;
      const std::filesystem::path direct = std::filesystem::path(d) / file;
      if (std::filesystem::is_regular_file(direct, ec)) return read(direct);
      for (std::filesystem::recursive_directory_iterator it(d, ec), end; !ec && it != end; it.increment(ec)) {
        if (it->is_regular_file(ec) && it->path().filename() == file) return read(it->path());
      }
    }
    return std::nullopt;
  };
}

}  // namespace contour::config
