#pragma once
// Test helpers for config validation: collect the messages of a ConfigError, search them.
#include <string>
#include <vector>

#include "config/config.hpp"

namespace contour::test {

// A machine section for tests of other sections (a configuration without `machine:` is an error,
// issue 16). Appended at the end so that the line numbers of the text before it stay as written.
inline constexpr const char* kMachineYaml = "\nmachine:\n  axes: [{name: X}, {name: Y}, {name: Z}]\n";

// Runs f (a loader call) and returns the ConfigError's messages; empty when it loaded fine.
template <class F>
std::vector<std::string> config_errors_of(F&& f) {
  try {
    f();
  } catch (const contour::config::ConfigError& e) {
    return e.errors();
  }
  return {};
}

// Messages of load_config_string(yaml, name).
inline std::vector<std::string> config_errors(const std::string& yaml,
                                              const std::string& name = "test.yaml") {
  return config_errors_of([&] { contour::config::load_config_string(yaml, name); });
}

inline bool any_contains(const std::vector<std::string>& v, const std::string& s) {
  for (const auto& e : v) {
    if (e.find(s) != std::string::npos) return true;
  }
  return false;
}

}  // namespace contour::test
