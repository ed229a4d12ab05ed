#include "tools/contourctl/gains.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "config/config.hpp"

namespace contour::ctl {

using nlohmann::json;

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

double parse_number(const std::string& item, const std::string& key) {
  try {
    std::size_t used = 0;
    const double v = std::stod(item, &used);
    if (used != item.size() || !std::isfinite(v)) throw std::invalid_argument(item);
    return v;
  } catch (const std::exception&) {
    throw std::invalid_argument("gains set: '" + item + "' is not a number (key " + key + ")");
  }
}

json parse_values(const std::string& v, const std::string& key) {
  json vals = json::array();
  std::stringstream ss(v);
  std::string item;
  while (std::getline(ss, item, ',')) vals.push_back(parse_number(item, key));
  if (vals.empty()) throw std::invalid_argument("gains set: no value for key " + key);
  return vals.size() == 1 ? vals[0] : vals;
}

std::string canonical_axis_key(const std::string& k) {
  if (k == "kp") return "kp";
  if (k == "ki" || k == "ki_per_s") return "ki_per_s";
  if (k == "kd" || k == "kd_s") return "kd_s";
  if (k == "ff") return "ff";
  return {};
}

std::string canonical_coupling_key(const std::string& k) {
  if (k == "cp") return "cp";
  if (k == "ci" || k == "ci_per_s") return "ci_per_s";
  if (k == "cd" || k == "cd_s") return "cd_s";
  if (k == "enable") return "coupling";
  return {};
}

}  // namespace

json gains_set_request(const std::vector<std::string>& assignments, const json& current) {
  json set = json::object();
  for (const auto& kv : assignments) {
    const auto eq = kv.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw std::invalid_argument("gains set expects key=value, got '" + kv + "'");
    }
    const std::string key = lower(kv.substr(0, eq));
    const std::string v = kv.substr(eq + 1);
    auto boolean = [&](const std::string& k) {
      if (v != "true" && v != "false")
        throw std::invalid_argument("gains set: " + k + " must be true or false");
      return v == "true";
    };
    if (key.rfind("axis.", 0) == 0) {
      const auto dot = key.find('.', 5);
      if (dot == std::string::npos) {
        throw std::invalid_argument("gains set: '" + key +
                                    "': expected axis.<x|y|z|index>.<kp|ki_per_s|kd_s|ff>");
      }
      const std::string ax = key.substr(5, dot - 5);
      const std::string field = canonical_axis_key(key.substr(dot + 1));
      if (field.empty()) {
        throw std::invalid_argument("gains set: '" + key +
                                    "': unknown axis gain (kp, ki_per_s, kd_s, ff)");
      }
      // Axis letters follow the configured order X, Y, Z (status does not report axis names).
      int index = -1;
      if (ax == "x" || ax == "y" || ax == "z")
        index = ax == "x" ? 0 : ax == "y" ? 1 : 2;
      else if (ax.size() == 1 && std::isdigit(static_cast<unsigned char>(ax[0])))
        index = ax[0] - '0';
      const json& cur = set.contains(field) ? set[field] : current.value(field, json());
      if (!cur.is_array())
        throw std::invalid_argument("gains set: the daemon reported no '" + field + "' array");
      if (index < 0 || index >= static_cast<int>(cur.size())) {
        throw std::invalid_argument("gains set: '" + key + "': no axis '" + ax +
                                    "' (the machine has " + std::to_string(cur.size()) + " axes)");
      }
      json arr = cur;
      arr[static_cast<std::size_t>(index)] = parse_number(v, key);
      set[field] = arr;
      continue;
    }
    if (key.rfind("coupling.", 0) == 0) {
      const std::string field = canonical_coupling_key(key.substr(9));
      if (field.empty()) {
        throw std::invalid_argument("gains set: '" + key +
                                    "': unknown coupling gain (cp, ci_per_s, cd_s, enable)");
      }
      if (field == "coupling")
        set[field] = boolean(key);
      else
        set[field] = parse_number(v, key);
      continue;
    }
    if (key == "coupling") {
      set["coupling"] = boolean(key);
      continue;
    }
    // Plain daemon keys (kp, ki_per_s, kd_s, ff, cp, ci_per_s, cd_s), as before; the daemon
    // validates names and ranges.
    const std::string ak = canonical_axis_key(key);
    const std::string ck = canonical_coupling_key(key);
    const std::string k = !ak.empty() ? ak : (!ck.empty() && ck != "coupling" ? ck : key);
    set[k] = parse_values(v, key);
  }
  if (set.empty()) throw std::invalid_argument("gains set needs key=value pairs");
  return set;
}

std::string format_gains(const json& g) {
  std::ostringstream o;
  o << "law: " << g.value("law", std::string("?")) << "   (generation " << g.value("generation", 0)
    << ", active since cycle " << g.value("active_since_cycle", 0) << ")\n";
  const char* names[] = {"X", "Y", "Z"};
  const std::size_t axes = g.contains("kp") ? g["kp"].size() : 0;
  o << "axis      kp  ki_per_s      kd_s        ff\n";
  for (std::size_t i = 0; i < axes; ++i) {
    char b[128];
    std::snprintf(b, sizeof b, "%-4s %7.4g %9.4g %9.4g %9.4g\n", i < 3 ? names[i] : "?",
                  g["kp"][i].get<double>(), g["ki_per_s"][i].get<double>(),
                  g["kd_s"][i].get<double>(), g["ff"][i].get<double>());
    o << b;
  }
  char b[160];
  std::snprintf(b, sizeof b, "coupling: %s   cp %.6g   ci_per_s %.6g   cd_s %.6g\n",
                g.value("coupling", false) ? "on" : "off", g.value("cp", 0.0),
                g.value("ci_per_s", 0.0), g.value("cd_s", 0.0));
  o << b;
  return o.str();
}

// ---- gains save: text-level edit of the YAML file ----
namespace {

std::string num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.10g", v);
  return b;
}

std::string arr3(const json& a) {
  std::vector<double> v;
  for (const auto& x : a) v.push_back(x.get<double>());
  while (!v.empty() && v.size() < 3) v.push_back(v.back());  // config keys are per 3 axes
  std::string s = "[";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + num(v[i]);
  return s + "]";
}

int indent_of(const std::string& l) {
  std::size_t i = 0;
  while (i < l.size() && l[i] == ' ') ++i;
  return static_cast<int>(i);
}

bool blank_or_comment(const std::string& l) {
  const auto p = l.find_first_not_of(" \t");
  return p == std::string::npos || l[p] == '#';
}

// Offset where the value's trailing comment starts (a '#' after whitespace, outside brackets and
// quotes), or npos.
std::size_t comment_pos(const std::string& l, std::size_t from) {
  int depth = 0;
  char quote = 0;
  for (std::size_t i = from; i < l.size(); ++i) {
    const char c = l[i];
    if (quote != 0) {
      if (c == quote) quote = 0;
      continue;
    }
    if (c == '"' || c == '\'')
      quote = c;
    else if (c == '[' || c == '{')
      ++depth;
    else if (c == ']' || c == '}')
      --depth;
    else if (c == '#' && depth <= 0 && i > 0 && (l[i - 1] == ' ' || l[i - 1] == '\t'))
      return i;
  }
  return std::string::npos;
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(" \t");
  if (a == std::string::npos) return {};
  const auto b = s.find_last_not_of(" \t");
  return s.substr(a, b - a + 1);
}

struct Block {
  std::size_t begin = 0;  // first line after the key line
  std::size_t end = 0;    // one past the last line of the block
  int child_indent = -1;  // -1: no children yet
};

class YamlText {
 public:
  YamlText(const std::string& text, std::string name) : name_(std::move(name)) {
    std::stringstream ss(text);
    std::string l;
    while (std::getline(ss, l)) lines_.push_back(l);
    trailing_newline_ = !text.empty() && text.back() == '\n';
  }
  std::string str() const {
    std::string s;
    for (std::size_t i = 0; i < lines_.size(); ++i) {
      s += lines_[i];
      if (i + 1 < lines_.size() || trailing_newline_) s += '\n';
    }
    return s;
  }
  // Line index of `key:` at exactly `indent` within [begin, end), or npos.
  std::size_t find_key(const std::string& key, int indent, std::size_t begin,
                       std::size_t end) const {
    for (std::size_t i = begin; i < end && i < lines_.size(); ++i) {
      if (blank_or_comment(lines_[i]) || indent_of(lines_[i]) != indent) continue;
      const std::string rest = lines_[i].substr(static_cast<std::size_t>(indent));
      if (rest.rfind(key + ":", 0) == 0) return i;
    }
    return std::string::npos;
  }
  Block block_of(std::size_t key_line) const {
    const int ind = indent_of(lines_[key_line]);
    Block b;
    b.begin = key_line + 1;
    b.end = b.begin;
    for (std::size_t i = b.begin; i < lines_.size(); ++i) {
      if (blank_or_comment(lines_[i])) continue;
      if (indent_of(lines_[i]) <= ind) break;
      if (b.child_indent < 0) b.child_indent = indent_of(lines_[i]);
      b.end = i + 1;
    }
    return b;
  }
  // The value text of a key line (without the trailing comment).
  std::string value_of(std::size_t line) const {
    const std::string& l = lines_[line];
    const auto colon = l.find(':');
    const auto c = comment_pos(l, colon + 1);
    return trim(l.substr(colon + 1, c == std::string::npos ? std::string::npos : c - colon - 1));
  }
  void set_value(std::size_t line, const std::string& value) {
    std::string& l = lines_[line];
    const auto colon = l.find(':');
    const auto c = comment_pos(l, colon + 1);
    std::string comment;
    if (c != std::string::npos) {
      // Keep the comment's column when the new value fits before it.
      const std::size_t want = colon + 2 + value.size() + 1;
      comment = (c >= want ? std::string(c - (colon + 2 + value.size()), ' ') : std::string("  ")) +
                l.substr(c);
    }
    l = l.substr(0, colon + 1) + " " + value + comment;
  }
  void insert(std::size_t at, const std::string& line) {
    lines_.insert(lines_.begin() + static_cast<std::ptrdiff_t>(at), line);
  }
  const std::string& line(std::size_t i) const { return lines_[i]; }
  std::size_t size() const { return lines_.size(); }
  [[noreturn]] void fail(std::size_t line, const std::string& what) const {
    throw std::runtime_error(name_ + ":" + std::to_string(line + 1) + ": " + what);
  }
  const std::string& name() const { return name_; }

 private:
  std::string name_;
  std::vector<std::string> lines_;
  bool trailing_newline_ = true;
};

// Splits a flow map body "a: 1, b: [1, 2]" at top-level commas into (key, value) pairs.
std::vector<std::pair<std::string, std::string>> split_flow_map(const std::string& body) {
  std::vector<std::pair<std::string, std::string>> out;
  int depth = 0;
  std::string cur;
  auto flush = [&]() {
    const std::string t = trim(cur);
    cur.clear();
    if (t.empty()) return;
    const auto colon = t.find(':');
    if (colon == std::string::npos)
      throw std::runtime_error("flow map entry without ':' ('" + t + "')");
    out.emplace_back(trim(t.substr(0, colon)), trim(t.substr(colon + 1)));
  };
  for (char c : body) {
    if (c == '[' || c == '{') ++depth;
    if (c == ']' || c == '}') --depth;
    if (c == ',' && depth == 0) {
      flush();
      continue;
    }
    cur += c;
  }
  flush();
  return out;
}

// Sets `key: value` entries in the mapping at line `map_line` (block or flow style); adds missing
// keys (block: after the last child; flow: appended inside the braces).
void set_in_mapping(YamlText& y, std::size_t map_line,
                    const std::vector<std::pair<std::string, std::string>>& kvs) {
  const std::string v = y.value_of(map_line);
  if (!v.empty() && v.front() == '{') {
    if (v.back() != '}')
      y.fail(map_line, "flow mapping spread over several lines: edit it by hand");
    auto entries = split_flow_map(v.substr(1, v.size() - 2));
    for (const auto& [k, val] : kvs) {
      bool found = false;
      for (auto& e : entries) {
        if (e.first == k) {
          e.second = val;
          found = true;
        }
      }
      if (!found) entries.emplace_back(k, val);
    }
    std::string s = "{";
    for (std::size_t i = 0; i < entries.size(); ++i)
      s += (i ? ", " : "") + entries[i].first + ": " + entries[i].second;
    y.set_value(map_line, s + "}");
    return;
  }
  if (!v.empty()) y.fail(map_line, "expected a mapping here, found '" + v + "'");
  for (const auto& [k, val] : kvs) {
    const Block b = y.block_of(map_line);
    const int ind = b.child_indent >= 0 ? b.child_indent : indent_of(y.line(map_line)) + 2;
    const std::size_t at = y.find_key(k, ind, b.begin, b.end);
    if (at != std::string::npos) {
      const std::string old = y.value_of(at);
      if (old.empty() || old.front() == '-')
        y.fail(at, "'" + k + "' is not a single-line value: edit it by hand");
      y.set_value(at, val);
    } else {
      y.insert(b.child_indent >= 0 ? b.end : map_line + 1,
               std::string(static_cast<std::size_t>(ind), ' ') + k + ": " + val);
    }
  }
}

// Line of the `index`-th item of the block list machine.axes, the end of its lines and the
// indent of its keys. Fails (file:line) on a flow list or a list the edit cannot follow.
struct ListItem {
  std::size_t line = 0;
  std::size_t end = 0;  // one past its last non-blank line
  int key_indent = 0;
};

ListItem axis_item(const YamlText& y, std::size_t index) {
  const std::size_t m = y.find_key("machine", 0, 0, y.size());
  if (m == std::string::npos) throw std::runtime_error(y.name() + ": no machine: section");
  const Block mb = y.block_of(m);
  if (mb.child_indent < 0) y.fail(m, "'machine' is not a block mapping: edit it by hand");
  const std::size_t al = y.find_key("axes", mb.child_indent, mb.begin, mb.end);
  if (al == std::string::npos) y.fail(m, "no machine.axes list");
  if (!y.value_of(al).empty()) y.fail(al, "'axes' is a flow list: write it as a block to save a drive model");
  const Block ab = y.block_of(al);
  std::vector<std::size_t> items;
  for (std::size_t i = ab.begin; i < ab.end; ++i) {
    if (blank_or_comment(y.line(i)) || indent_of(y.line(i)) != ab.child_indent) continue;
    if (y.line(i).compare(static_cast<std::size_t>(ab.child_indent), 2, "- ") != 0) {
      y.fail(i, "expected a list item ('- ') under machine.axes");
    }
    items.push_back(i);
  }
  if (index >= items.size()) y.fail(al, "machine.axes has no item " + std::to_string(index));
  ListItem it;
  it.line = items[index];
  const std::size_t next = index + 1 < items.size() ? items[index + 1] : ab.end;
  it.end = it.line + 1;
  for (std::size_t i = it.line + 1; i < next; ++i) {
    if (!blank_or_comment(y.line(i))) it.end = i + 1;
  }
  const std::string& l = y.line(it.line);
  const std::size_t key_col = l.find_first_not_of(' ', static_cast<std::size_t>(ab.child_indent) + 1);
  if (key_col == std::string::npos || l[key_col] == '#') {
    y.fail(it.line, "machine.axes item with its keys on the following lines: edit it by hand, or "
                    "use --no-identified");
  }
  it.key_indent = static_cast<int>(key_col);
  if (l[key_col] == '{') {
    y.fail(it.line, "machine.axes item in flow style ('- {...}'): write it as a block mapping to save "
                    "a drive model, or use --no-identified");
  }
  return it;
}

// Sets `key: {kvs}` in the axis item (the mapping's other entries stay; added when missing).
void set_in_axis(YamlText& y, std::size_t index, const std::string& key,
                 const std::vector<std::pair<std::string, std::string>>& kvs) {
  const ListItem it = axis_item(y, index);
  std::size_t at = std::string::npos;
  if (y.line(it.line).compare(static_cast<std::size_t>(it.key_indent), key.size() + 1, key + ":") == 0) {
    y.fail(it.line, "'" + key + "' on the list item's first line: edit it by hand");
  }
  at = y.find_key(key, it.key_indent, it.line + 1, it.end);
  if (at != std::string::npos) {
    set_in_mapping(y, at, kvs);
    return;
  }
  std::string s = "{";
  for (std::size_t i = 0; i < kvs.size(); ++i) s += (i ? ", " : "") + kvs[i].first + ": " + kvs[i].second;
  y.insert(it.end, std::string(static_cast<std::size_t>(it.key_indent), ' ') + key + ": " + s + "}");
}

}  // namespace

std::string config_with_gains(const std::string& text, const std::string& name, const json& g) {
  const std::string law = g.at("law").get<std::string>();
  const bool coupling = g.at("coupling").get<bool>();
  if (law == "pid" && coupling) {
    throw std::runtime_error(
        "gains save: PID with the coupling controller cannot be expressed in the config "
        "(controller: p | pid | ccc)");
  }
  const auto& ff = g.at("ff");
  for (const auto& x : ff) {
    if (x.get<double>() != ff[0].get<double>()) {
      throw std::runtime_error(
          "gains save: per-axis ff differs between axes; the config has one "
          "control.feed_forward: set equal values first");
    }
  }
  YamlText y(text, name);
  std::size_t ctl = y.find_key("control", 0, 0, y.size());
  if (ctl == std::string::npos) {
    y.insert(y.size(), "control:");
    ctl = y.size() - 1;
  }
  if (!y.value_of(ctl).empty())
    y.fail(ctl, "'control' is a flow mapping: write it as a block to use gains save");
  std::vector<std::pair<std::string, std::string>> top{
      {"controller", law == "pid" ? "pid" : (coupling ? "ccc" : "p")}};
  {
    // feed_forward only when the file has it or it differs from the loader's default (0).
    const Block b = y.block_of(ctl);
    const bool present = b.child_indent >= 0 && y.find_key("feed_forward", b.child_indent, b.begin,
                                                           b.end) != std::string::npos;
    if (present || ff[0].get<double>() != 0.0)
      top.emplace_back("feed_forward", num(ff[0].get<double>()));
  }
  if (law != "pid") top.emplace_back("kp", arr3(g.at("kp")));
  set_in_mapping(y, ctl, top);
  auto child_map = [&](const std::string& key) {
    const Block b = y.block_of(ctl);
    std::size_t at = y.find_key(key, b.child_indent, b.begin, b.end);
    if (at == std::string::npos) {
      y.insert(b.end, std::string(static_cast<std::size_t>(b.child_indent), ' ') + key + ": {}");
      at = b.end;
    }
    return at;
  };
  if (law == "pid") {
    set_in_mapping(y, child_map("pid"),
                   {{"kp", arr3(g.at("kp"))},
                    {"ki_per_s", arr3(g.at("ki_per_s"))},
                    {"kd_s", arr3(g.at("kd_s"))}});
  }
  set_in_mapping(y, child_map("coupling"),
                 {{"cp", num(g.at("cp").get<double>())},
                  {"ci_per_s", num(g.at("ci_per_s").get<double>())},
                  {"cd_s", num(g.at("cd_s").get<double>())}});
  // Drive models measured by `identify` (the reply's "identified": axis name -> model): the model
  // the controller uses (machine.axes[].sim) becomes the measured one, and the measurement is
  // recorded beside it (machine.axes[].identified) for the start-up check.
  std::vector<std::pair<std::size_t, json>> models;
  if (g.contains("identified") && g["identified"].is_object() && !g["identified"].empty()) {
    config::Config before;
    try {
      before = config::load_config_string(text, name);
    } catch (const std::exception& e) {
      throw std::runtime_error("gains save: " + name + " does not load as it is:\n" + e.what());
    }
    for (const auto& [axis, m] : g["identified"].items()) {
      std::size_t idx = before.machine.axes.size();
      for (std::size_t i = 0; i < before.machine.axes.size(); ++i) {
        if (before.machine.axes[i].name == axis) idx = i;
      }
      if (idx == before.machine.axes.size()) {
        throw std::runtime_error("gains save: axis " + axis + " was identified but " + name +
                                 " has no such axis");
      }
      models.emplace_back(idx, m);
      const std::string k = num(m.at("gain_per_s").get<double>());
      const std::string t = num(m.at("tau_ms").get<double>());
      const std::string d = std::to_string(m.at("delay_cycles").get<int>());
      set_in_axis(y, idx, "sim", {{"gain_per_s", k}, {"tau_ms", t}, {"delay_cycles", d}});
      set_in_axis(y, idx, "identified",
                  {{"gain_per_s", k}, {"tau_ms", t}, {"delay_cycles", d},
                   {"date", "\"" + m.value("date", std::string()) + "\""}});
    }
  }
  const std::string out = y.str();
  // Validate and read back: the file must load and give exactly the active gains.
  config::Config c;
  try {
    c = config::load_config_string(out, name);
  } catch (const std::exception& e) {
    throw std::runtime_error(
        "gains save: the edited config does not validate (nothing written):\n" +
        std::string(e.what()));
  }
  auto near = [](double a, double b) {
    return std::abs(a - b) <= 1e-9 * std::max(1.0, std::abs(b));
  };
  bool ok = near(c.control.coupling.cp, g["cp"].get<double>()) &&
            near(c.control.coupling.ci_per_s, g["ci_per_s"].get<double>()) &&
            near(c.control.coupling.cd_s, g["cd_s"].get<double>()) &&
            near(c.control.feed_forward, ff[0].get<double>());
  for (std::size_t i = 0; i < g["kp"].size() && i < 3; ++i) {
    ok = ok && near(law == "pid" ? c.control.pid_kp[i] : c.control.kp[i], g["kp"][i].get<double>());
    if (law == "pid") {
      ok = ok && near(c.control.pid_ki_per_s[i], g["ki_per_s"][i].get<double>()) &&
           near(c.control.pid_kd_s[i], g["kd_s"][i].get<double>());
    }
  }
  for (const auto& [idx, m] : models) {
    const auto& ax = c.machine.axes[idx];
    ok = ok && near(ax.drive.gain_per_s, m["gain_per_s"].get<double>()) &&
         near(ax.drive.tau_s * 1e3, m["tau_ms"].get<double>()) &&
         ax.drive.delay_cycles == m["delay_cycles"].get<int>() && ax.identified.present &&
         ax.identified.delay_cycles == ax.drive.delay_cycles;
  }
  if (!ok)
    throw std::runtime_error(
        "gains save: internal error: the edited config reads back different gains or drive models");
  return out;
}

void write_file_like(const std::string& path, const std::string& text, const std::string& like) {
  auto fail = [&](const std::string& what) {
    return std::runtime_error(path + ": " + what + " (" + std::strerror(errno) + "); nothing changed");
  };
  struct stat st {};
  if (::stat(like.c_str(), &st) != 0) {
    throw std::runtime_error(like + ": cannot stat (" + std::string(std::strerror(errno)) + ")");
  }
  const std::filesystem::path p(path);
  std::string tmpl =
      (p.parent_path().empty() ? std::filesystem::path(".") : p.parent_path()).string() + "/." +
      p.filename().string() + ".XXXXXX";
  const int fd = ::mkstemp(tmpl.data());
  if (fd < 0) throw fail("cannot create a temporary file in its directory");
  bool ok = false;
  std::string why;
  do {
    // Owner and group first (fchown may clear set-id bits), then the mode.
    if ((st.st_uid != ::geteuid() || st.st_gid != ::getegid()) &&
        ::fchown(fd, st.st_uid, st.st_gid) != 0) {
      why = "cannot keep owner:group " + std::to_string(st.st_uid) + ":" + std::to_string(st.st_gid) +
            " of " + like;
      break;
    }
    if (::fchmod(fd, st.st_mode & 07777) != 0) {
      why = "cannot keep the mode of " + like;
      break;
    }
    std::size_t off = 0;
    while (off < text.size()) {
      const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      off += static_cast<std::size_t>(n);
    }
    if (off != text.size()) {
      why = "cannot write";
      break;
    }
    if (::fsync(fd) != 0) {
      why = "cannot fsync";
      break;
    }
    ok = true;
  } while (false);
  const int saved_errno = errno;
  if (::close(fd) != 0 && ok) {
    ok = false;
    why = "cannot close";
  }
  if (ok && ::rename(tmpl.c_str(), path.c_str()) != 0) {
    ok = false;
    why = "cannot rename the temporary file over it";
  }
  if (!ok) {
    const int e = errno != 0 ? errno : saved_errno;
    ::unlink(tmpl.c_str());
    errno = e;
    throw fail(why);
  }
  // The rename itself survives a power loss only once the directory is on disk.
  const int dfd = ::open(tmpl.substr(0, tmpl.rfind('/')).c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace contour::ctl
