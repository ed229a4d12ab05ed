#include "config/yaml_reader.hpp"

#include <cmath>
#include <functional>
#include <sstream>

namespace contour::config {

namespace {
std::string join(const std::vector<std::string>& v) {
  std::string out;
  for (const auto& s : v) {
    if (!out.empty()) out += '\n';
    out += s;
  }
  return out;
}
}  // namespace

ConfigError::ConfigError(std::vector<std::string> errors)
    : std::runtime_error(join(errors)), errors_(std::move(errors)) {}

void Diagnostics::error(const YAML::Mark& at, const std::string& path, const std::string& message) {
  std::ostringstream os;
  os << file_;
  if (!at.is_null()) os << ':' << at.line + 1 << ':' << at.column + 1;
  os << ": " << (path.empty() ? "(root)" : path) << ": " << message;
  errors_.push_back(os.str());
}

void Diagnostics::error(const YAML::Node& at, const std::string& path, const std::string& message) {
  error(at.IsDefined() ? at.Mark() : YAML::Mark::null_mark(), path, message);
}

void Diagnostics::throw_if_any() const {
  if (!errors_.empty()) throw ConfigError(errors_);
}

Section::Section(YAML::Node node, std::string path, Diagnostics& diag)
    : node_(std::move(node)), path_(std::move(path)), diag_(&diag) {
  if (node_.IsDefined() && !node_.IsNull() && !node_.IsMap()) {
    diag_->error(node_, path_, "expected a map of keys");
    type_ok_ = false;
  }
}

Section::Section(Section&& other) noexcept
    : node_(std::move(other.node_)),
      path_(std::move(other.path_)),
      diag_(other.diag_),
      used_(std::move(other.used_)),
      finished_(other.finished_),
      type_ok_(other.type_ok_) {
  other.finished_ = true;
}

Section::~Section() {
  try {
    finish();
  } catch (...) {
  }
}

std::string Section::key_path(const std::string& key) const {
  return path_.empty() ? key : path_ + "." + key;
}

bool Section::has(const std::string& key) const {
  return type_ok_ && node_.IsMap() && node_[key].IsDefined() && !node_[key].IsNull();
}

std::optional<YAML::Node> Section::get(const std::string& key, const char* what) {
  used_.insert(key);
  if (!has(key)) return std::nullopt;
  YAML::Node n = node_[key];
  if (!n.IsScalar()) {
    diag_->error(n, key_path(key), std::string("expected ") + what);
    return std::nullopt;
  }
  return n;
}

void Section::error(const std::string& key, const std::string& message) {
  if (has(key)) {
    diag_->error(node_[key], key_path(key), message);
  } else {
    diag_->error(node_, key.empty() ? path_ : key_path(key), message);
  }
}

double Section::number(const std::string& key, double def, double min, double max) {
  auto n = get(key, "a number");
  if (!n) return def;
  double v = 0.0;
  try {
    v = n->as<double>();
  } catch (const YAML::Exception&) {
    diag_->error(*n, key_path(key), "expected a number, got '" + n->Scalar() + "'");
    return def;
  }
  if (!std::isfinite(v)) {
    diag_->error(*n, key_path(key), "must be finite");
    return def;
  }
  if (v < min || v > max) {
    std::ostringstream os;
    os << "value " << v << " out of range [" << min << ", " << max << "]";
    diag_->error(*n, key_path(key), os.str());
    return def;
  }
  return v;
}

double Section::required_number(const std::string& key, double min, double max) {
  if (!has(key)) {
    used_.insert(key);
    diag_->error(node_, key_path(key), "required key is missing");
    return std::isfinite(min) ? min : 0.0;
  }
  return number(key, std::isfinite(min) ? min : 0.0, min, max);
}

long Section::integer(const std::string& key, long def, long min, long max) {
  auto n = get(key, "an integer");
  if (!n) return def;
  long v = 0;
  try {
    v = n->as<long>();
  } catch (const YAML::Exception&) {
    diag_->error(*n, key_path(key), "expected an integer, got '" + n->Scalar() + "'");
    return def;
  }
  if (v < min || v > max) {
    std::ostringstream os;
    os << "value " << v << " out of range [" << min << ", " << max << "]";
    diag_->error(*n, key_path(key), os.str());
    return def;
  }
  return v;
}

long Section::required_integer(const std::string& key, long min, long max) {
  if (!has(key)) {
    used_.insert(key);
    diag_->error(node_, key_path(key), "required key is missing");
    return min;
  }
  return integer(key, min, min, max);
}

bool Section::boolean(const std::string& key, bool def) {
  auto n = get(key, "true or false");
  if (!n) return def;
  try {
    return n->as<bool>();
  } catch (const YAML::Exception&) {
    diag_->error(*n, key_path(key), "expected true or false, got '" + n->Scalar() + "'");
    return def;
  }
}

std::string Section::string(const std::string& key, const std::string& def) {
  auto n = get(key, "a string");
  if (!n) return def;
  return n->Scalar();
}

std::string Section::required_string(const std::string& key) {
  if (!has(key)) {
    used_.insert(key);
    diag_->error(node_, key_path(key), "required key is missing");
    return {};
  }
  return string(key, {});
}

std::string Section::choice(const std::string& key, const std::string& def,
                            const std::vector<std::string>& allowed) {
  std::string v = string(key, def);
  for (const auto& a : allowed) {
    if (a == v) return v;
  }
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  error(key, "'" + v + "' is not one of: " + list);
  return def;
}

std::vector<double> Section::numbers(const std::string& key, std::size_t min_count,
                                     std::size_t max_count) {
  used_.insert(key);
  std::vector<double> out;
  if (!has(key)) {
    if (min_count > 0) diag_->error(node_, key_path(key), "required key is missing");
    return out;
  }
  YAML::Node n = node_[key];
  if (!n.IsSequence()) {
    diag_->error(n, key_path(key), "expected a list of numbers");
    return out;
  }
  if (n.size() < min_count || n.size() > max_count) {
    std::ostringstream os;
    os << "expected " << min_count << ".." << max_count << " numbers, got " << n.size();
    diag_->error(n, key_path(key), os.str());
  }
  for (std::size_t i = 0; i < n.size(); ++i) {
    try {
      const double v = n[i].as<double>();
      if (!std::isfinite(v)) throw YAML::Exception(n[i].Mark(), "not finite");
      out.push_back(v);
    } catch (const YAML::Exception&) {
      diag_->error(n[i], key_path(key) + "[" + std::to_string(i) + "]", "expected a finite number");
    }
  }
  return out;
}

Section Section::child(const std::string& key) {
  used_.insert(key);
  if (!has(key)) return Section(YAML::Node(YAML::NodeType::Undefined), key_path(key), *diag_);
  return Section(node_[key], key_path(key), *diag_);
}

std::vector<Section> Section::list(const std::string& key) {
  used_.insert(key);
  std::vector<Section> out;
  if (!has(key)) return out;
  YAML::Node n = node_[key];
  if (!n.IsSequence()) {
    diag_->error(n, key_path(key), "expected a list");
    return out;
  }
  out.reserve(n.size());
  for (std::size_t i = 0; i < n.size(); ++i) {
    out.emplace_back(n[i], key_path(key) + "[" + std::to_string(i) + "]", *diag_);
  }
  return out;
}

void Section::accept(const std::string& key) { used_.insert(key); }

void Section::finish() {
  if (finished_) return;
  finished_ = true;
  if (!type_ok_ || !node_.IsMap()) return;
  for (auto it = node_.begin(); it != node_.end(); ++it) {
    const std::string k = it->first.Scalar();
    if (used_.count(k) == 0) diag_->error(it->first, key_path(k), "unknown key");
  }
}

namespace {
YAML::Node wrap_parse(const std::string& name, const std::function<YAML::Node()>& f) {
  try {
    return f();
  } catch (const YAML::BadFile&) {
    throw ConfigError({name + ": cannot open file"});
  } catch (const YAML::Exception& e) {
    std::ostringstream os;
    os << name;
    if (!e.mark.is_null()) os << ':' << e.mark.line + 1 << ':' << e.mark.column + 1;
    os << ": YAML syntax error: " << e.msg;
    throw ConfigError({os.str()});
  }
}
}  // namespace

YAML::Node load_yaml_file(const std::string& path) {
  return wrap_parse(path, [&] { return YAML::LoadFile(path); });
}

YAML::Node load_yaml_string(const std::string& text, const std::string& name) {
  return wrap_parse(name, [&] { return YAML::Load(text); });
}

}  // namespace contour::config
