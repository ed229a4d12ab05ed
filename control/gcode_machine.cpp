#include "control/gcode_machine.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <system_error>

namespace contour::control {

namespace {
bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

std::string_view trim(std::string_view s) {
  while (!s.empty() && is_blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_blank(s.back())) s.remove_suffix(1);
  return s;
}

// Whole-token number parse; false on trailing garbage or non-finite values.
bool parse_double(std::string_view s, double& out) {
  if (s.empty()) return false;
  const char* b = s.data();
  const char* e = s.data() + s.size();
  if (*b == '+') ++b;
  auto r = std::from_chars(b, e, out);
  return r.ec == std::errc() && r.ptr == e && std::isfinite(out);
}

bool parse_int(std::string_view s, int& out) {
  if (s.empty()) return false;
  const char* b = s.data();
  const char* e = s.data() + s.size();
  if (*b == '+') ++b;
  auto r = std::from_chars(b, e, out);
  return r.ec == std::errc() && r.ptr == e;
}

// Splits `text` into lines; calls f(line_number, line) for each.
template <typename F>
void for_each_line(std::string_view text, F&& f) {
  int n = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t nl = text.find('\n', pos);
    if (nl == std::string_view::npos) nl = text.size();
    f(++n, text.substr(pos, nl - pos));
    pos = nl + 1;
  }
}
}  // namespace

MachineFileError::MachineFileError(const std::string& file, int line, const std::string& message)
    : std::runtime_error(file + ":" + std::to_string(line) + ": " + message), line_(line) {}

MachineContext::MachineContext() : parameters(kParameterCount, 0.0) {
  for (int p : required_parameters()) persistent.insert(p);
  parameters[kParamCoordSystem] = 1.0;
}

Eigen::Vector3d MachineContext::work_offset_mm(int system) const {
  const int k = 5201 + 20 * system;
  return {parameters[static_cast<std::size_t>(k)], parameters[static_cast<std::size_t>(k + 1)],
          parameters[static_cast<std::size_t>(k + 2)]};
}

void MachineContext::set_work_offset_mm(int system, const Eigen::Vector3d& v) {
  const int k = 5201 + 20 * system;
  for (int i = 0; i < 3; ++i) parameters[static_cast<std::size_t>(k + i)] = v[i];
}

double MachineContext::work_rotation_deg(int system) const {
  return parameters[static_cast<std::size_t>(5210 + 20 * system)];
}

int MachineContext::active_system() const {
  const int s = static_cast<int>(parameters[kParamCoordSystem] + 0.0001);
  return (s < 1 || s > 9) ? 1 : s;
}

Eigen::Vector3d MachineContext::g92_offset_mm() const {
  return {parameters[kParamG92], parameters[kParamG92 + 1], parameters[kParamG92 + 2]};
}

bool MachineContext::g92_applied() const { return parameters[kParamG92Applied] != 0.0; }

Eigen::Vector3d MachineContext::g28_mm() const {
  return {parameters[kParamG28], parameters[kParamG28 + 1], parameters[kParamG28 + 2]};
}

Eigen::Vector3d MachineContext::g30_mm() const {
  return {parameters[kParamG30], parameters[kParamG30 + 1], parameters[kParamG30 + 2]};
}

void MachineContext::set_g28_mm(const Eigen::Vector3d& v) {
  for (int i = 0; i < 3; ++i) parameters[static_cast<std::size_t>(kParamG28 + i)] = v[i];
}

void MachineContext::set_g30_mm(const Eigen::Vector3d& v) {
  for (int i = 0; i < 3; ++i) parameters[static_cast<std::size_t>(kParamG30 + i)] = v[i];
}

const ToolData* MachineContext::find_tool(int number) const {
  for (const auto& t : tools)
    if (t.number == number) return &t;
  return nullptr;
}

const std::vector<int>& required_parameters() {
  static const std::vector<int> kRequired = [] {
    std::vector<int> v;
    for (int i = 5161; i <= 5169; ++i) v.push_back(i);
    for (int i = 5181; i <= 5189; ++i) v.push_back(i);
    for (int i = 5210; i <= 5219; ++i) v.push_back(i);
    for (int s = 0; s <= 9; ++s) {
      const int base = 5220 + 20 * s;  // 5220 (active system), then each system's X..W and R
      if (s == 0) {
        v.push_back(base);
        continue;
      }
      for (int i = 1; i <= 10; ++i) v.push_back(5200 + 20 * s + i);
    }
    std::sort(v.begin(), v.end());
    return v;
  }();
  return kRequired;
}

std::map<int, double> parse_var_file(std::string_view text, const std::string& file) {
  std::map<int, double> out;
  int last = 0;
  for_each_line(text, [&](int n, std::string_view raw) {
    const std::string_view line = trim(raw);
    if (line.empty()) return;
    std::size_t sp = 0;
    while (sp < line.size() && !is_blank(line[sp])) ++sp;
    const std::string_view num = line.substr(0, sp);
    const std::string_view val = trim(line.substr(sp));
    int k = 0;
    double v = 0.0;
    if (!parse_int(num, k) || !parse_double(val, v))
      throw MachineFileError(file, n, "expected '<parameter number> <value>', got '" + std::string(line) + "'");
    if (k < 1 || k >= kParameterCount)
      throw MachineFileError(file, n, "parameter number " + std::to_string(k) + " out of range 1.." +
                                          std::to_string(kParameterCount - 1));
    if (k <= last)
      throw MachineFileError(file, n, "parameter " + std::to_string(k) + " out of order (after " +
                                          std::to_string(last) + "): numbers must increase");
    last = k;
    out[k] = v;
  });
  return out;
}

void apply_var_file(MachineContext& m, const std::map<int, double>& vars) {
  for (int p : required_parameters()) m.parameters[static_cast<std::size_t>(p)] = 0.0;
  for (const auto& [k, v] : vars) {
    m.parameters[static_cast<std::size_t>(k)] = v;
    m.persistent.insert(k);
  }
  const int s = static_cast<int>(m.parameters[kParamCoordSystem] + 0.0001);
  if (s < 1 || s > 9) m.parameters[kParamCoordSystem] = 1.0;  // as LinuxCNC's init does
}

std::string format_fixed(double v, int decimals) {
  char buf[400];  // fixed notation of any finite double with <= 9 decimals fits
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, decimals);
  if (r.ec != std::errc()) return std::isnan(v) ? "nan" : (v < 0 ? "-inf" : "inf");
  return std::string(buf, r.ptr);
}

std::string format_var_file(const MachineContext& m) {
  std::string out;
  for (int k : m.persistent) {
    if (k < 1 || k >= kParameterCount) continue;
    out += std::to_string(k);
    out += '\t';
    out += format_fixed(m.parameters[static_cast<std::size_t>(k)], 6);
    out += '\n';
  }
  return out;
}

std::vector<ToolData> parse_tool_table(std::string_view text, const std::string& file) {
  std::vector<ToolData> out;
  for_each_line(text, [&](int n, std::string_view raw) {
    std::string_view line = raw;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    const std::size_t semi = line.find(';');
    const std::string_view fields = trim(line.substr(0, semi));
    if (fields.empty()) return;  // blank or comment-only line
    ToolData t;
    if (semi != std::string_view::npos) t.comment = std::string(line.substr(semi + 1));
    bool has_t = false;
    std::set<char> seen;
    std::size_t i = 0;
    while (i < fields.size()) {
      while (i < fields.size() && is_blank(fields[i])) ++i;
      std::size_t j = i;
      while (j < fields.size() && !is_blank(fields[j])) ++j;
      const std::string_view tok = fields.substr(i, j - i);
      i = j;
      if (tok.empty()) continue;
      const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(tok[0])));
      const std::string_view num = tok.substr(1);
      if (!seen.insert(letter).second)
        throw MachineFileError(file, n, std::string("field ") + letter + " appears twice");
      const auto bad = [&] {
        return MachineFileError(file, n, "bad value in field '" + std::string(tok) + "'");
      };
      double v = 0.0;
      int iv = 0;
      switch (letter) {
        case 'T':
          if (!parse_int(num, iv) || iv < 0) throw bad();
          t.number = iv;
          has_t = true;
          break;
        case 'P':
          if (!parse_int(num, iv) || iv < 0) throw bad();
          t.pocket = iv;
          break;
        case 'Q':
          if (!parse_int(num, iv) || iv < 0 || iv > 9) throw bad();
          t.orientation = iv;
          break;
        case 'D':
        case 'I':
        case 'J':
        case 'X':
        case 'Y':
        case 'Z':
        case 'A':
        case 'B':
        case 'C':
        case 'U':
        case 'V':
        case 'W': {
          if (!parse_double(num, v)) throw bad();
          static constexpr std::string_view kAxes = "XYZABCUVW";
          if (letter == 'D') t.diameter_mm = v;
          else if (letter == 'I') t.front_angle_deg = v;
          else if (letter == 'J') t.back_angle_deg = v;
          else t.offset[kAxes.find(letter)] = v;
          break;
        }
        default:
          throw MachineFileError(file, n, "unknown field '" + std::string(tok) +
                                              "' (tool table fields: T P D X Y Z A B C U V W I J Q)");
      }
    }
    if (!has_t) throw MachineFileError(file, n, "tool line without T (tool number)");
    for (const auto& o : out)
      if (o.number == t.number)
        throw MachineFileError(file, n, "tool " + std::to_string(t.number) + " is listed twice");
    out.push_back(std::move(t));
  });
  return out;
}

std::string format_tool_table(const std::vector<ToolData>& tools) {
  std::string out;
  const auto left3 = [](int v) {  // "%-3d"
    std::string s = std::to_string(v);
    if (s.size() < 3) s.append(3 - s.size(), ' ');
    return s;
  };
  for (const auto& t : tools) {
    out += 'T';
    out += left3(t.number);
    out += " P";
    out += left3(t.pocket);
    const auto item = [&](double v, char letter) {  // " %c%+f"
      if (v == 0.0) return;
      out += ' ';
      out += letter;
      if (!std::signbit(v)) out += '+';
      out += format_fixed(v, 6);
    };
    item(t.diameter_mm, 'D');
    static constexpr char kAxes[] = "XYZABCUVW";
    for (std::size_t i = 0; i < 9; ++i) item(t.offset[i], kAxes[i]);
    item(t.front_angle_deg, 'I');
    item(t.back_angle_deg, 'J');
    if (t.orientation != 0) {
      out += " Q";
      out += std::to_string(t.orientation);
    }
    out += " ;";
    out += t.comment;
    out += '\n';
  }
  return out;
}

}  // namespace contour::control
