#include "tools/contour-web/scope.hpp"

#include <charconv>
#include <cmath>
#include <limits>

namespace contour::web {

using nlohmann::json;

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

enum Sig : int {
  kTrueError, kModelError, kFerrX, kFerrY, kFerrZ, kFerr, kPathVelocity, kOverride, kForce,
  kForceOverride, kSpindle, kLateness, kRefX, kRefY, kRefZ, kActX, kActY, kActZ, kProgress,
  kInProgram, kCount
};

double num(const json& j, const char* key) {
  auto it = j.find(key);
  if (it == j.end() || !it->is_number()) return kNaN;
  return it->get<double>();
}

bool vec3(const json& j, const char* key, std::array<double, 3>& v) {
  auto it = j.find(key);
  if (it == j.end() || !it->is_array() || it->size() < 1) return false;
  for (std::size_t i = 0; i < 3; ++i) {
    v[i] = i < it->size() && (*it)[i].is_number() ? (*it)[i].get<double>() : 0.0;
  }
  return true;
}

void append_fixed(std::string& out, double v, int decimals) {
  if (!std::isfinite(v)) {
    out += "null";
    return;
  }
  char buf[64];
  auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, decimals);
  if (r.ec != std::errc()) {
    out += "null";
    return;
  }
  // Trim trailing zeros of the fraction ("1.2500" -> "1.25", "3.000" -> "3").
  char* end = r.ptr;
  if (decimals > 0) {
    while (end > buf && end[-1] == '0') --end;
    if (end > buf && end[-1] == '.') --end;
  }
  if (end - buf == 2 && buf[0] == '-' && buf[1] == '0') {
    out += '0';
    return;
  }
  out.append(buf, end);
}

void append_uint(std::string& out, std::uint64_t v) {
  char buf[24];
  auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}
}  // namespace

const std::vector<SignalInfo>& scope_signals() {
  static const std::vector<SignalInfo> s = {
      {"true_error_um", "um", 3, "contour error: distance to the planned path (contourd's writer)"},
      {"model_error_um", "um", 3, "contour error of the RT model (|eps|)"},
      {"ferr_x_um", "um", 2, "following error X (reference - measured)"},
      {"ferr_y_um", "um", 2, "following error Y"},
      {"ferr_z_um", "um", 2, "following error Z"},
      {"ferr_um", "um", 2, "following error, norm"},
      {"path_velocity_mm_min", "mm/min", 1, "reference path velocity (from consecutive samples)"},
      {"override_pct", "%", 2, "feed override applied"},
      {"force_n", "N", 2, "cutting force (filtered resultant)"},
      {"force_override", "", 4, "force channel feed factor"},
      {"spindle_rpm", "rpm", 1, "spindle speed command"},
      {"lateness_us", "us", 1, "loop wake-up lateness (when contourd sends it)"},
      {"ref_x_mm", "mm", 4, "reference X"},
      {"ref_y_mm", "mm", 4, "reference Y"},
      {"ref_z_mm", "mm", 4, "reference Z"},
      {"act_x_mm", "mm", 4, "measured X"},
      {"act_y_mm", "mm", 4, "measured Y"},
      {"act_z_mm", "mm", 4, "measured Z"},
      {"progress_mm", "mm", 4, "path progress"},
      {"in_program", "", 0, "1 while a program runs or holds"},
  };
  return s;
}

int signal_index(const std::string& name) {
  const auto& s = scope_signals();
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (name == s[i].name) return static_cast<int>(i);
  }
  return -1;
}

void ScopeDecoder::decode(const json& line, ScopeBlock& out) {
  if (out.columns.size() != static_cast<std::size_t>(kCount)) out.columns.resize(kCount);
  if (auto it = line.find("samples"); it != line.end() && it->is_array()) {
    const std::uint64_t d = line.value("dropped", std::uint64_t{0});
    const std::uint64_t s = line.value("source_dropped", std::uint64_t{0});
    out.daemon_dropped = d + s;
    for (const auto& smp : *it) add(smp, out, 1.0, false);
  } else {
    add(line, out, 1e3, true);  // an older contourd: one sample per event, eps in mm
  }
  out.gaps = gaps_;
}

void ScopeDecoder::add(const json& s, ScopeBlock& out, double eps_scale, bool eps_in_mm) {
  if (!s.is_object() || !s.contains("cycle") || !s["cycle"].is_number_unsigned()) {
    ++malformed_;
    return;
  }
  std::array<double, 3> ref{}, act{}, eps{};
  if (!vec3(s, "ref_mm", ref) || !vec3(s, "act_mm", act)) {
    ++malformed_;
    return;
  }
  const bool has_eps = eps_in_mm ? vec3(s, "eps_mm", eps) : vec3(s, "eps_um", eps);
  const std::uint64_t cycle = s["cycle"].get<std::uint64_t>();
  double t_s = num(s, "t_s");
  if (!std::isfinite(t_s)) t_s = static_cast<double>(cycle) * 1e-3;
  double v = kNaN;
  if (have_prev_ && cycle > prev_cycle_) {
    if (cycle != prev_cycle_ + 1) gaps_ += cycle - prev_cycle_ - 1;
    const double dt = t_s - prev_t_s_;
    if (dt > 0.0) {
      const double dx = ref[0] - prev_ref_[0], dy = ref[1] - prev_ref_[1], dz = ref[2] - prev_ref_[2];
      v = std::sqrt(dx * dx + dy * dy + dz * dz) / dt * 60.0;
    }
  }
  have_prev_ = true;
  prev_cycle_ = cycle;
  prev_t_s_ = t_s;
  prev_ref_ = ref;

  auto& c = out.columns;
  out.cycle.push_back(cycle);
  out.job.push_back(s.value("job", std::uint64_t{0}));
  out.line.push_back(s.contains("line") && s["line"].is_number() ? s["line"].get<int>() : 0);
  double model = num(s, "model_error_um");
  if (!std::isfinite(model) && has_eps) {
    model = eps_scale * std::sqrt(eps[0] * eps[0] + eps[1] * eps[1] + eps[2] * eps[2]);
  }
  const double fx = (ref[0] - act[0]) * 1e3, fy = (ref[1] - act[1]) * 1e3, fz = (ref[2] - act[2]) * 1e3;
  const double ovr = num(s, "override");
  const bool in_prog = s.value("in_program", false);
  c[kTrueError].push_back(num(s, "true_error_um"));
  c[kModelError].push_back(model);
  c[kFerrX].push_back(fx);
  c[kFerrY].push_back(fy);
  c[kFerrZ].push_back(fz);
  c[kFerr].push_back(std::sqrt(fx * fx + fy * fy + fz * fz));
  c[kPathVelocity].push_back(v);
  c[kOverride].push_back(std::isfinite(ovr) ? ovr * 100.0 : kNaN);
  c[kForce].push_back(num(s, s.contains("force_n") ? "force_n" : "force_N"));
  c[kForceOverride].push_back(num(s, "force_override"));
  c[kSpindle].push_back(num(s, "spindle_rpm"));
  c[kLateness].push_back(num(s, "lateness_us"));
  c[kRefX].push_back(ref[0]);
  c[kRefY].push_back(ref[1]);
  c[kRefZ].push_back(ref[2]);
  c[kActX].push_back(act[0]);
  c[kActY].push_back(act[1]);
  c[kActZ].push_back(act[2]);
  c[kProgress].push_back(num(s, "progress_mm"));
  c[kInProgram].push_back(in_prog ? 1.0 : 0.0);
}

std::string scope_message(const ScopeBlock& b, const std::vector<int>& signals,
                          std::uint32_t decimation, std::uint64_t client_dropped,
                          std::size_t* samples) {
  const std::uint32_t dec = decimation == 0 ? 1 : decimation;
  std::vector<std::size_t> rows;
  rows.reserve(b.size());
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (b.cycle[i] % dec == 0) rows.push_back(i);
  }
  *samples = rows.size();
  if (rows.empty()) return "";
  const auto& info = scope_signals();
  std::string out;
  out.reserve(128 + rows.size() * (24 + 10 * signals.size()));
  out += R"({"jsonrpc":"2.0","method":"notify_scope","params":{"cycle":[)";
  for (std::size_t k = 0; k < rows.size(); ++k) {
    if (k) out += ',';
    append_uint(out, b.cycle[rows[k]]);
  }
  out += R"(],"job":[)";
  for (std::size_t k = 0; k < rows.size(); ++k) {
    if (k) out += ',';
    append_uint(out, b.job[rows[k]]);
  }
  out += R"(],"line":[)";
  for (std::size_t k = 0; k < rows.size(); ++k) {
    if (k) out += ',';
    append_fixed(out, b.line[rows[k]], 0);
  }
  out += R"(],"signals":{)";
  for (std::size_t n = 0; n < signals.size(); ++n) {
    const int si = signals[n];
    if (n) out += ',';
    out += '"';
    out += info[static_cast<std::size_t>(si)].name;
    out += "\":[";
    const auto& col = b.columns[static_cast<std::size_t>(si)];
    for (std::size_t k = 0; k < rows.size(); ++k) {
      if (k) out += ',';
      append_fixed(out, col[rows[k]], info[static_cast<std::size_t>(si)].decimals);
    }
    out += ']';
  }
  out += R"(},"decimation":)";
  append_uint(out, dec);
  out += R"(,"dropped":)";
  append_uint(out, client_dropped);
  out += R"(,"daemon_dropped":)";
  append_uint(out, b.daemon_dropped);
  out += R"(,"gaps":)";
  append_uint(out, b.gaps);
  out += "}}";
  return out;
}

}  // namespace contour::web
