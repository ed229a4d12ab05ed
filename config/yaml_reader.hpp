#pragma once
// Validating YAML reader shared by every config section.
//
// A Section wraps one YAML map and a dotted key path ("machine.axes[1].limits"). Each accessor
// marks its key as known and range-checks the value; problems are collected (not thrown) in a
// Diagnostics object as "file:line:column: key.path: message", so a user sees every error of a
// file at once. When a Section is finished (finish() or destructor), keys never read are reported
// as unknown. Diagnostics::throw_if_any() raises one ConfigError holding all messages; contourd
// exits 78 (EX_CONFIG) on it.
#include <yaml-cpp/yaml.h>

#include <limits>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace contour::config {

class ConfigError : public std::runtime_error {
 public:
  explicit ConfigError(std::vector<std::string> errors);
  [[nodiscard]] const std::vector<std::string>& errors() const { return errors_; }

 private:
  std::vector<std::string> errors_;
};

class Diagnostics {
 public:
  explicit Diagnostics(std::string file) : file_(std::move(file)) {}
  void error(const YAML::Node& at, const std::string& path, const std::string& message);
  void error(const YAML::Mark& at, const std::string& path, const std::string& message);
  [[nodiscard]] const std::vector<std::string>& errors() const { return errors_; }
  [[nodiscard]] const std::string& file() const { return file_; }
  void throw_if_any() const;

 private:
  std::string file_;
  std::vector<std::string> errors_;
};

class Section {
 public:
  static constexpr double kInf = std::numeric_limits<double>::infinity();

  // node may be undefined/null: then every optional key takes its default and required keys fail.
  Section(YAML::Node node, std::string path, Diagnostics& diag);
  ~Section();
  Section(Section&& other) noexcept;
  Section(const Section&) = delete;
  Section& operator=(const Section&) = delete;
  Section& operator=(Section&&) = delete;

  [[nodiscard]] bool has(const std::string& key) const;
  [[nodiscard]] bool present() const { return node_.IsDefined() && !node_.IsNull(); }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] Diagnostics& diag() { return *diag_; }
  [[nodiscard]] const YAML::Node& node() const { return node_; }

  // Numbers: optional with default, or required. Range is inclusive.
  double number(const std::string& key, double def, double min = -kInf, double max = kInf);
  double required_number(const std::string& key, double min = -kInf, double max = kInf);
  long integer(const std::string& key, long def, long min = std::numeric_limits<long>::min(),
               long max = std::numeric_limits<long>::max());
  long required_integer(const std::string& key, long min = std::numeric_limits<long>::min(),
                        long max = std::numeric_limits<long>::max());
  bool boolean(const std::string& key, bool def);
  std::string string(const std::string& key, const std::string& def);
  std::string required_string(const std::string& key);
  // String that must be one of `allowed`.
  std::string choice(const std::string& key, const std::string& def,
                     const std::vector<std::string>& allowed);
  std::vector<double> numbers(const std::string& key, std::size_t min_count = 0,
                              std::size_t max_count = 64);

  // Sub-map (may be absent: then a Section over an undefined node).
  Section child(const std::string& key);
  // Sequence of maps.
  std::vector<Section> list(const std::string& key);
  // Marks a key as known without reading it (for keys parsed elsewhere).
  void accept(const std::string& key);
  // Reports an error at this key (or at the section when the key is absent).
  void error(const std::string& key, const std::string& message);

  // Reports unknown keys; called by the destructor if not called before.
  void finish();

 private:
  std::optional<YAML::Node> get(const std::string& key, const char* what);
  std::string key_path(const std::string& key) const;

  YAML::Node node_;
  std::string path_;
  Diagnostics* diag_;
  std::set<std::string> used_;
  bool finished_ = false;
  bool type_ok_ = true;
};

// Loads a YAML file; parse errors become a ConfigError naming file:line:column.
YAML::Node load_yaml_file(const std::string& path);
YAML::Node load_yaml_string(const std::string& text, const std::string& name);

}  // namespace contour::config
